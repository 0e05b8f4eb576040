"""The main demo and the whole simulated cell end to end (all four nodes as processes, real DDS).

1. Picks from ground truth: a rigid and a soft box, each grasped at its centre
   across its width through PickAndPlace; both must end up in the bin. This
   checks the cell (driver, executor, gripper, physics) independent of how
   good the shipped network is.
2. `defgg-demo` on a one-object scene: the network plans, the executor picks;
   the outputs exist and what the executor reports agrees with the ground truth.
"""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.ros import topics

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "sim_bringup" / "scenes"
PICK_TIMEOUT_S = 240.0


def _grasp_from_ground_truth(obj, position):
    from defgg_interfaces.msg import Grasp

    from defgg_ros.perception.geometry import matrix_to_quaternion_xyzw

    yaw = obj["yaw_rad"]
    c, s = math.cos(yaw), math.sin(yaw)
    # x: fingers close along the box's x edge; z: pointing down (approach).
    rotation = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    grasp = Grasp()
    grasp.pose_base.header.frame_id = topics.BASE_FRAME
    grasp.pose_base.pose.position.x, grasp.pose_base.pose.position.y = float(position[0]), float(position[1])
    grasp.pose_base.pose.position.z = float(obj["size_m"][2])  # the visible top surface
    q = matrix_to_quaternion_xyzw(rotation)
    o = grasp.pose_base.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)
    grasp.width_m = float(obj["size_m"][0])
    grasp.quality = 1.0
    grasp.youngs_modulus_pa = float(obj["youngs_modulus_pa"])
    grasp.object_id = -1
    return grasp


def test_rigid_and_soft_objects_are_picked_into_the_bin(tmp_path):
    from defgg_interfaces.action import PickAndPlace

    from defgg_ros.bringup.demo_client import DemoClient
    from defgg_ros.bringup.demo_geometry import in_bin
    from defgg_ros.bringup.node_set import load_node_set
    from defgg_ros.bringup.supervisor import Bringup

    overrides = {"fake_panda_driver": {"scene_file": str(SCENES / "pick_pair.yaml"), "max_real_time_factor": 0.0},
                 # The Panda's full limits and brisker lines: the same sequence in less sim time.
                 "executor_node": {"limits_scale": 1.0, "line_speed_mps": 0.25, "descent_speed_mps": 0.05}}
    log_path = tmp_path / "cell.log"
    with open(log_path, "w") as log, Bringup(load_node_set("sim_cell"), overrides, out=log) as cell:
        cell.wait_ready(120.0)
        client = DemoClient()
        try:
            scene = client.scene()
            for index, obj in enumerate(scene["objects"]):
                grasp = _grasp_from_ground_truth(obj, client.object_positions()[index])
                phases = []
                result = client.pick(PickAndPlace.Goal(plan_grasp=False, grasp=grasp),
                                     lambda f, seen=phases: seen.append(f.phase) if f.phase not in seen else None,
                                     timeout_s=PICK_TIMEOUT_S)
                assert result.success, (f"{obj['name']}: {result.phase_reached} (phases {phases}): "
                                        f"{result.failure_reason}\n" + log_path.read_text()[-3000:])
                assert result.held_after_transfer
                assert result.gripper_width_closed_m == pytest.approx(obj["size_m"][0], abs=0.012)
                position = client.object_positions()[index]
                assert in_bin(position, scene["bin"]), f"{obj['name']} ended at {position}, not in the bin"
            assert cell.failed_node() is None
        finally:
            client.close()


def test_demo_cli_writes_its_outputs_and_agrees_with_the_ground_truth(tmp_path):
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "defgg_ros.demo", "--scene", str(SCENES / "rigid_box.yaml"),
                           "--out", str(out)], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # Isolation by default (issue 27.6): the first line names a private domain, localhost-only discovery.
    first = proc.stdout.splitlines()[0]
    assert first.startswith("defgg-demo: ROS domain ") and "(private" in first and "localhost only" in first, first
    assert "wooden_block" in proc.stdout and "phase reached" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    (row,) = summary["objects"]
    assert row["name"] == "wooden_block" and row["youngs_modulus_pa"] == 2e9
    assert row["phase_reached"] != "not started", row
    assert 0.0 <= row["quality"] <= 1.0 and 0.0 < row["grasp_width_m"] <= 0.08 + 1e-6
    # The object is in the bin, and the executor's verdict agrees with the simulator's ground truth.
    assert row["in_bin"], row
    assert row["success"] and row["held_after_transfer"], row
    assert (out / "grasps.png").stat().st_size > 10_000
    assert "[fake_panda_driver]" in (out / "cell.log").read_text()


def test_demo_refuses_missing_files(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "defgg_ros.demo", "--scene", str(tmp_path / "none.yaml"),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 2 and "does not exist" in proc.stderr


def test_demo_refuses_unknown_objects_and_bad_scenes_before_the_cell_starts(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("objects: [{name: a}, {name: a}]\n")
    for extra, says in ((["--objects", "sponge,nosuch"], "--objects ['nosuch'] not in the scene (it has sponge"),
                        (["--scene", str(bad)], "scene: "), (["--max-rtf", "-1"], "--max-rtf must be >= 0"),
                        (["--pick-timeout", "0"], "--pick-timeout must be > 0 s")):
        proc = subprocess.run([sys.executable, "-m", "defgg_ros.demo", "--out", str(tmp_path / "o"), *extra],
                              capture_output=True, text=True, timeout=60, cwd=ROOT)
        assert proc.returncode == 2 and says in proc.stderr, proc.stderr
        assert not (tmp_path / "o").exists()          # nothing started, nothing written
