"""One pick of the cell experiment through the real node graph (issue 49 item 3).

Per pick: a one-object scene (the object at the pick's pose) is written, the simulated cell is brought up
(fake_panda_driver, segmentation, grasp inference, executor: every node a process, real DDS, a private
domain), the segmentation node is told the case's modulus (SetStiffness, the default for every object), a
fresh frame is perceived (Perceive) and planned on (PlanGrasp), and the executor carries out the best grasp
(PickAndPlace: pre-grasp, guarded descent to contact, close, lift, transfer, place into the bin). The cell is
torn down after every pick, so each pick starts from the same state and the three stiffness inputs meet the
same object at the same pose (a paired comparison).

Success is the paper's rule: picked and moved to the goal without dropping = the executor held the object
after the transfer and the object's ground-truth centroid is in the bin once the cell is still.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.srv import PlanGrasp
from geometry_msgs.msg import PoseStamped

from defgg_ros.bringup.demo_client import DemoClient
from defgg_ros.bringup.demo_geometry import bin_place_xy, in_bin, release_tcp_z
from defgg_ros.bringup.node_set import load_node_set
from defgg_ros.bringup.supervisor import Bringup, BringupError
from defgg_ros.demo import executor_params
from defgg_ros.grip_force import LabelGripRule
from defgg_ros.model.checkpoint import load_checkpoint

DRIVER, INFERENCE, EXECUTOR = "fake_panda_driver", "grasp_inference_node", "executor_node"
# The executor's wall-clock guards (no joint states for watchdog_timeout_s, an input silent for silent_topic_s;
# defaults 2 and 3 s) guard a real robot. With an FEM object in the hand the simulated cell runs at 2-6 % of real
# time on the shared 2 cores (measured: common_ball, 196 nodes), so one 30 Hz joint state is 0.5-2 s of wall time
# apart and a loaded moment aborted a lift as "driver silent" (2026-11-29). Raised for the simulated experiment.
SIMULATION_WALL_GUARDS_S = {"watchdog_timeout_s": 60.0, "silent_topic_s": 60.0}
# The demo scene's camera, table and bin (sim_bringup/scenes/demo.yaml): the cell the demo runs.
CELL_LAYOUT = {
    "base_T_camera": {"xyz": [0.5, 0.0, 0.40], "quat_xyzw": [1.0, 0.0, 0.0, 0.0]},
    "table": {"size_m": [1.2, 1.2, 0.05], "center_xy_m": [0.45, -0.1]},
    "bin": {"center_xy_m": [0.35, -0.45], "inner_size_m": [0.22, 0.22, 0.06]},
}
# Once the executor is done, the object must be still this long before its position is read (it may roll).
SETTLE_S, SETTLE_TIMEOUT_S, STILL_M = 1.0, 20.0, 0.002


@dataclass(frozen=True)
class PickSetup:
    """What one pick needs: the scene object (as a scene YAML mapping) and the modulus the segmentation node
    is told; or, with measure_first, nothing told: the executor squeezes the object first (PickAndPlace
    measure_only, docs/squeeze.md) and tells the segmentation node what it measured. grip_youngs_modulus_pa:
    close as for this modulus (force and speed) whatever the input was (a grasp-only case); None: as planned."""
    scene_object: dict
    input_youngs_modulus_pa: float
    measure_first: bool = False
    grip_youngs_modulus_pa: float | None = None


def write_scene(path: Path, scene_object: dict) -> Path:
    """A scene file with the demo's cell layout and this one object."""
    path.parent.mkdir(parents=True, exist_ok=True)
    scene = {"name": path.stem, **CELL_LAYOUT, "objects": [scene_object]}
    path.write_text(yaml.safe_dump(scene, sort_keys=False), encoding="utf-8")
    return path


def _place_pose(grasp_pose, bin_dict: dict, executor_params: dict):
    """The bin's first slot, released just above its floor, the hand turned as at the grasp (as the demo
    places: a transfer that turns the hand about the vertical spun soft blocks out of the fingers)."""

    pose = PoseStamped()
    pose.header.frame_id = executor_params["base_frame"]
    pose.pose.position.x, pose.pose.position.y = bin_place_xy(bin_dict, 0)
    pose.pose.position.z = release_tcp_z(grasp_pose.position.z, bin_dict,
                                         float(executor_params["place_position_m"][2]))
    pose.pose.orientation = grasp_pose.orientation
    return pose


def _plan(client, record: dict):
    """Perceive a fresh frame and plan on it; the best grasp on the object, or None (record says why)."""

    depth, info = client.fresh_frame(time.monotonic())
    perceived = client.perceive(depth, info)
    if not perceived.success:
        record["failure_reason"] = f"Perceive: {perceived.message}"
        return None
    record["perceived_moduli_pa"] = [o.stiffness.youngs_modulus_pa for o in perceived.perceived.objects]
    response = client.plan(PlanGrasp.Request(depth=depth, camera_info=info, perceived=perceived.perceived,
                                             top_k=1))
    if not response.success or not response.grasps:
        record["failure_reason"] = f"PlanGrasp: {response.message or 'no grasp'}"
        return None
    grasp = response.grasps[0]
    record["grasp"] = grasp_record(grasp)
    return grasp


def grasp_record(grasp) -> dict:
    """A Grasp message as the record keeps it (JSON)."""
    p = grasp.pose_base.pose.position
    return {"x_m": p.x, "y_m": p.y, "z_m": p.z, "angle_rad": grasp.angle_rad, "width_m": grasp.width_m,
            "quality": grasp.quality, "youngs_modulus_pa": grasp.youngs_modulus_pa,
            "finger_force_n": grasp.finger_force_n, "estimated_mass_kg": grasp.estimated_mass_kg,
            # a squeeze on this grasp: Hertz on these radii, the flat law when empty, the line-contact law where
            # a line length is > 0 (docs/squeeze.md)
            "contact_radii_m": [float(r) for r in grasp.contact_radii_m],
            "contact_line_lengths_m": [float(v) for v in grasp.contact_line_lengths_m]}


def grip_as(grasp, youngs_modulus_pa: float, model_path: Path, record: dict) -> None:
    """Make the planned grasp close as for `youngs_modulus_pa`: the modulus it carries (the executor's closing
    speed) and its force by the model's label rule on the plan's mass estimate (what the inference node
    computes for a grasp planned with that modulus: planning/grip_estimate.py)."""
    rule = LabelGripRule.from_meta(load_checkpoint(model_path).get("meta"))
    grasp.finger_force_n = rule.grasp_finger_force_n(youngs_modulus_pa, grasp.estimated_mass_kg)
    grasp.youngs_modulus_pa = float(youngs_modulus_pa)
    record["grip"] = {"youngs_modulus_pa": grasp.youngs_modulus_pa, "finger_force_n": grasp.finger_force_n}


def _settled_position(client) -> np.ndarray:
    """The object's ground-truth centroid once it moved less than STILL_M for SETTLE_S (or at the timeout)."""
    deadline = time.monotonic() + SETTLE_TIMEOUT_S
    previous = np.array(client.object_positions()[0])
    still_since = time.monotonic()
    while time.monotonic() < deadline and time.monotonic() - still_since < SETTLE_S:
        now = np.array(client.object_positions()[0])
        if np.abs(now - previous).max() > STILL_M:
            still_since = time.monotonic()
        previous = now
    return previous


def _execute(client, grasp, record: dict, executor_params: dict, pick_timeout_s: float) -> None:

    scene = client.scene()
    goal = PickAndPlace.Goal(plan_grasp=False, grasp=grasp,
                             place_pose=_place_pose(grasp.pose_base.pose, scene["bin"], executor_params))
    result = client.pick(goal, timeout_s=pick_timeout_s)
    record.update(executor_success=bool(result.success), phase_reached=result.phase_reached,
                  failure_reason=result.failure_reason, contact_detected=bool(result.contact_detected),
                  held_after_lift=bool(result.held_after_lift),
                  held_after_transfer=bool(result.held_after_transfer),
                  gripper_force_n=result.gripper_force_n, gripper_width_closed_m=result.gripper_width_closed_m,
                  sim_duration_s=result.duration_s)


def _json_number(value: float) -> float | None:
    """A float for a JSON record: null for inf / NaN (a rigid reading's upper bound), which JSON cannot hold."""
    return float(value) if math.isfinite(value) else None


def _measure(client, record: dict, timeout_s: float) -> None:
    """Measure first: a measure_only goal on the planned grasp (descend, squeeze, open, back to the observation
    pose); the executor sends the estimate to the segmentation node. A failed measurement leaves the node's
    default in force and the pick goes on (as a cell would)."""

    result = client.pick(PickAndPlace.Goal(plan_grasp=True, measure_only=True), timeout_s=timeout_s)
    record["squeeze"] = {
        "success": bool(result.success), "failure_reason": result.failure_reason,
        "measured_youngs_modulus_pa": _json_number(result.measured_youngs_modulus_pa),
        "low_pa": _json_number(result.measured_modulus_low_pa),
        "high_pa": _json_number(result.measured_modulus_high_pa),   # a rigid reading has no upper bound: inf
        "rigid": bool(result.measured_rigid), "sent_pa": result.stiffness_sent_pa,
        "contact_law": result.measured_contact_law,      # flat, hertz, hertz-line or section (docs/squeeze.md)
        "update": result.stiffness_update, "forces_n": list(result.squeeze_forces_n),
        "widths_m": list(result.squeeze_widths_m), "sim_duration_s": result.duration_s,
        # the executor plans its own grasp for the squeeze (records before contact_law: its contacts said the law)
        "grasp": grasp_record(result.grasp_used)}


def run_pick(setup: PickSetup, scene_path: Path, model_path: Path, log, ready_timeout_s: float = 300.0,
             pick_timeout_s: float = 1800.0) -> dict:
    """Bring the cell up on a one-object scene, pick the object with the case's stiffness input, tear down.

    Returns the pick's record fields (success by the paper's rule). Raises BringupError / CellCallError when
    the cell itself failed (a node died, a call timed out): no outcome to record then.
    """

    write_scene(scene_path, setup.scene_object)
    overrides = {DRIVER: {"scene_file": str(scene_path.resolve()), "max_real_time_factor": 0.0},
                 INFERENCE: {"model_path": str(Path(model_path).resolve())},
                 EXECUTOR: dict(SIMULATION_WALL_GUARDS_S)}
    node_set = load_node_set("sim_cell")
    record = {"executor_success": False, "held_after_transfer": False, "phase_reached": "not started",
              "failure_reason": "", "grasp": None}
    started = time.monotonic()
    with Bringup(node_set, overrides, out=log) as cell:
        record["bringup_wall_s"] = round(cell.wait_ready(ready_timeout_s), 1)
        client = DemoClient()
        try:
            record["start_position_m"] = [round(float(c), 4) for c in client.object_positions()[0]]
            if setup.measure_first:
                _measure(client, record, pick_timeout_s)
                # the squeeze may move the object: the pick's pose is where it lies now, not the pose it shares
                record["squeeze"]["position_after_m"] = [round(float(c), 4) for c in client.object_positions()[0]]
            else:
                client.set_stiffness([], default_youngs_modulus_pa=setup.input_youngs_modulus_pa)
            grasp = _plan(client, record)
            if grasp is not None and setup.grip_youngs_modulus_pa:
                grip_as(grasp, setup.grip_youngs_modulus_pa, model_path, record)
            if grasp is not None:
                _execute(client, grasp, record, executor_params(node_set), pick_timeout_s)
            position = _settled_position(client)
            record["final_position_m"] = [round(float(c), 4) for c in position]
            record["in_bin"] = in_bin(position, client.scene()["bin"])
        finally:
            client.close()
        dead = cell.failed_node()
        if dead is not None:
            raise BringupError(dead.describe())
    record["success"] = bool(record["held_after_transfer"] and record["in_bin"])
    record["wall_s"] = round(time.monotonic() - started, 1)
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in record.items()}
