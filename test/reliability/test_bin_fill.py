"""Eight picks in a row into the shipped cell's bin with an empty place_pose (issue 48.2).

The simulated driver (PyBullet, sim time) with eight rigid blocks and the executor, as processes; each goal takes
the block's top-down grasp and no place pose, so the executor chooses the bin's next free slot and lowers into it
guarded by the contact force. After each pick every block placed so far must stand inside the bin on its floor
(none on another, none knocked out) and the force of the lowering over its value at the lowering's start must
never exceed the executor's contact threshold.

Before issue 48 every such goal went to one point: the second block landed on the first and the third pick's
lowering pushed into the stack with 33.4 N and knocked blocks out of the bin.
"""
import numpy as np
import pytest
import yaml
from defgg_interfaces.action import PickAndPlace
from geometry_msgs.msg import PoseArray
from rclpy.node import Node
from support.cell_sets import STARVED_WATCHDOG_S, driver_and_executor_set
from support.executor_cell import grasp_msg

from defgg_ros.bringup.supervisor import Bringup
from defgg_ros.ros import qos, topics
from defgg_ros.ros.action import ActionClient
from defgg_ros.ros.parameters import defaults

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(900)]

BLOCK_M = 0.045
# Two rows of four under the camera, 10 cm apart (the open fingers need 4 cm either side of a block).
BLOCKS_XY_M = [(x, y) for y in (0.07, 0.19) for x in (0.36, 0.46, 0.56, 0.66)]
PICK_TIMEOUT_S = 240.0
EXECUTOR = defaults("executor_node")
# The shipped cell's bin (sim_bringup/scenes/*.yaml, the executor's default bin_inner_m: 32 cm, 3 x 3 slots at the
# default pitch and wall margin; test/control/test_bin_slots.py checks they agree). Before issue 48 it was 20 cm,
# 2 x 2 slots: the fingers opening beside a 4.5 cm block reach 41.5 mm from its centre.
_X_MIN, _X_MAX, _Y_MIN, _Y_MAX = EXECUTOR["bin_inner_m"]
BIN_XY_M, BIN_INNER_M = ((_X_MIN + _X_MAX) / 2, (_Y_MIN + _Y_MAX) / 2), _X_MAX - _X_MIN


def _scene(tmp_path):
    scene = {"name": "eight_blocks", "base_T_camera": {"xyz": [0.5, 0.0, 0.40], "quat_xyzw": [1.0, 0.0, 0.0, 0.0]},
             "table": {"size_m": [1.2, 1.2, 0.05], "center_xy_m": [0.45, -0.1]},
             "bin": {"center_xy_m": list(BIN_XY_M), "inner_size_m": [BIN_INNER_M, BIN_INNER_M, 0.06]},
             "objects": [{"name": f"block_{i}", "shape": "box", "size_m": [BLOCK_M] * 3, "position_xy_m": list(xy),
                          "yaw_rad": 0.0, "youngs_modulus_pa": 2.0e9, "mass_kg": 0.09}
                         for i, xy in enumerate(BLOCKS_XY_M)]}
    path = tmp_path / "eight_blocks.yaml"
    path.write_text(yaml.safe_dump(scene))
    return path


def _in_bin(position) -> bool:
    return (abs(position.x - BIN_XY_M[0]) < BIN_INNER_M / 2 and abs(position.y - BIN_XY_M[1]) < BIN_INNER_M / 2
            and position.z < BLOCK_M)   # standing on the floor, not on another block (centre at 22.5 mm)


def test_eight_picks_with_no_place_pose_fill_the_bin_without_collisions(tmp_path, executor, spin):
    log_path = tmp_path / "cell.log"
    poses, report = [], []
    threshold_n = EXECUTOR["contact_force_threshold_n"]
    with open(log_path, "w") as log, Bringup(driver_and_executor_set(
            tmp_path, _scene(tmp_path), {"watchdog_timeout_s": STARVED_WATCHDOG_S}), out=log) as bringup:
        bringup.wait_ready(180.0)
        probe = Node("bin_fill_probe", context=executor.context)
        probe.create_subscription(PoseArray, topics.FAKE_OBJECT_POSES, poses.append, qos.STATE)
        client = ActionClient(probe, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
        executor.add_node(probe)
        spin(executor, client.server_is_ready, 60.0, "the pick-and-place action server")
        for index, (x, y) in enumerate(BLOCKS_XY_M):
            feedback = []
            goal = PickAndPlace.Goal(grasp=grasp_msg((x, y, BLOCK_M), 0.0, BLOCK_M + 0.02))   # place_pose empty
            handle = spin(executor, client.send_goal_async(goal, feedback_callback=lambda f, into=feedback: into.append(
                f.feedback)), 30.0, "the goal response")
            assert handle.accepted
            response = spin(executor, handle.get_result_async(), PICK_TIMEOUT_S, f"pick {index}")
            tail = log_path.read_text()[-3000:]
            assert response.result.success, (index, response.result.failure_reason, tail)
            seen = len(poses)
            spin(executor, lambda seen=seen: len(poses) > seen + 2, 30.0, "object poses after the pick")
            placed = [poses[-1].poses[i].position for i in range(index + 1)]
            place_forces = [f.external_force_n for f in feedback if f.phase == "place"]
            contact_n = max(place_forces) - place_forces[0] if place_forces else float("nan")
            report.append((index, contact_n, [(round(p.x, 3), round(p.y, 3), round(p.z, 3)) for p in placed]))
            print(f"pick {index}: in {response.result.duration_s:.1f} s (sim); place force rise {contact_n:.2f} N; "
                  f"block at ({placed[-1].x:.3f}, {placed[-1].y:.3f}, {placed[-1].z:.3f})", flush=True)
            outside = [i for i, p in enumerate(placed) if not _in_bin(p)]
            assert not outside, (f"after pick {index} blocks {outside} are not on the bin's floor", report, tail)
            assert contact_n <= threshold_n, (f"pick {index} pushed with {contact_n:.1f} N", report)
        executor.remove_node(probe)
    final = np.array([[p.x, p.y] for p in (poses[-1].poses[i].position for i in range(len(BLOCKS_XY_M)))])
    gaps = [np.linalg.norm(final[i] - final[j]) for i in range(len(final)) for j in range(i)]
    print(f"closest two blocks in the bin: {min(gaps) * 1000:.0f} mm apart", flush=True)
