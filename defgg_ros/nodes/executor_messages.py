"""The executor node's messages: goals and grasps in, trajectories out, results back (ROS types <-> the sequence's).

Conversions only: the node (executor_node.py) calls them; the sequence (control/pick_place.py) never sees a
message. Every error is a GoalError whose text says what is wrong with the goal.
"""
import math

import numpy as np
from builtin_interfaces.msg import Duration
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from defgg_ros.constants import ARM_MODELS
from defgg_ros.control.poses import PoseError, top_down_yaw
from defgg_ros.control.sequence_types import ArmState, GraspTarget, PlaceTarget
from defgg_ros.control.stopping import HOLD_BLEND_S
from defgg_ros.perception.table_pose import TABLE_FRAME_ID
from defgg_ros.ros import topics
from defgg_ros.ros.conversions import ConversionError, transform_from_pose

# A trajectory goal aborted with the joint_trajectory_controller's deactivation text: franka_ros2 deactivates every
# controller on the arm's hardware on an FCI error (docs/franka_contract.md, "Robot errors").
ROBOT_ERROR = ("robot error: the arm's trajectory controller was deactivated under a goal (franka_ros2 does so on an "
               "FCI error such as a collision reflex; the robot stopped itself)")


class GoalError(ValueError):
    """A goal the executor cannot work with (the message says why)."""


class RobotRestarted(GoalError):
    """The robot clock went back during a goal: the driver (a simulator) restarted and its goals are gone."""


# The default robot type's names (the functions below are called with the node's own).
DEFAULT_NAMES = topics.robot_names()


def trajectory_to_msg(trajectory, frame_id: str, joint_names=DEFAULT_NAMES["joints"],
                      start_s: float | None = None) -> JointTrajectory:
    """The trajectory (arm joints 1..7 in order) for a joint_trajectory_controller; stamp 0 = start on receipt,
    else start_s (robot time, s)."""
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    if start_s is not None:
        sec, nanosec = divmod(int(round(start_s * 1e9)), 1_000_000_000)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    msg.joint_names = list(joint_names)
    for t, q, qd, qdd in zip(trajectory.times_s, trajectory.q_rad, trajectory.qd_radps, trajectory.qdd_radps2):
        # Split whole nanoseconds, so rounding can never carry into a wrong second.
        sec, nanosec = divmod(int(round(float(t) * 1e9)), 1_000_000_000)
        msg.points.append(JointTrajectoryPoint(
            positions=q.tolist(), velocities=qd.tolist(), accelerations=qdd.tolist(),
            time_from_start=Duration(sec=sec, nanosec=nanosec)))
    return msg


def hold_trajectory_msg(q_rad, frame_id: str, joint_names=DEFAULT_NAMES["joints"],
                        duration_s: float = HOLD_BLEND_S) -> JointTrajectory:
    """One point at q_rad, zero velocity and acceleration, duration_s after receipt: 'come to rest there' for a
    joint_trajectory_controller, which blends into it from its measured state (control/stopping.py says where)."""
    sec, nanosec = divmod(int(round(duration_s * 1e9)), 1_000_000_000)
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.joint_names = list(joint_names)
    msg.points.append(JointTrajectoryPoint(positions=[float(v) for v in q_rad], velocities=[0.0] * len(q_rad),
                                           accelerations=[0.0] * len(q_rad),
                                           time_from_start=Duration(sec=sec, nanosec=nanosec)))
    return msg


def joint_state_to_arm(msg: JointState, joint_names=DEFAULT_NAMES["joints"],
                       finger_names=DEFAULT_NAMES["fingers"]) -> ArmState:
    """Arm joints 1..7 (any order, other joints ignored) and the finger width (NaN without both fingers)."""
    index = {name: i for i, name in enumerate(msg.name)}
    missing = [n for n in joint_names if n not in index]
    if missing:
        raise GoalError(f"joint state lacks {missing}")
    q = np.array([msg.position[index[n]] for n in joint_names])
    has_velocity = len(msg.velocity) == len(msg.name)
    qd = np.array([msg.velocity[index[n]] for n in joint_names]) if has_velocity else np.zeros(7)
    fingers = [msg.position[index[n]] for n in finger_names if n in index]
    width = float(sum(fingers)) if len(fingers) == 2 else float("nan")
    return ArmState(q, qd, width)


def grasp_target(grasp, base_frame: str, default_modulus_pa: float) -> GraspTarget:
    frame = grasp.pose_base.header.frame_id
    if frame == TABLE_FRAME_ID:
        raise GoalError(f"grasp pose is in frame '{frame}', expected '{base_frame}': perception has no camera pose "
                        f"(nothing on TF from {base_frame} to the camera, base_T_camera not set), so it planned in a "
                        "table frame estimated from the depth; publish the hand-eye calibration on /tf_static")
    if frame not in ("", base_frame):
        raise GoalError(f"grasp pose is in frame '{frame}', expected '{base_frame}'")
    try:
        base_M_tcp = transform_from_pose(grasp.pose_base.pose)
        yaw = top_down_yaw(base_M_tcp)
    except (ConversionError, PoseError) as error:
        raise GoalError(f"bad grasp pose: {error}") from error
    modulus = grasp.youngs_modulus_pa if grasp.youngs_modulus_pa > 0 else default_modulus_pa
    force = float(grasp.finger_force_n)
    if not math.isfinite(force) or force < 0.0:
        raise GoalError(f"grasp finger_force_n must be >= 0 N (0: the modulus rule), got {force}")
    radii = contact_radii_m(grasp)
    cell_m, heights = section_heights_m(grasp)
    return GraspTarget(tuple(base_M_tcp[:3, 3]), yaw, float(grasp.width_m), float(modulus), force, radii,
                       contact_line_lengths_m(grasp, radii), cell_m, heights)


def section_heights_m(grasp) -> tuple[float, tuple]:
    """Grasp.section_* checked: (cell m, rows of heights m) or (0.0, ()) when empty or the field is missing."""
    values = tuple(float(v) for v in getattr(grasp, "section_heights_m", ()))
    if not values:
        return 0.0, ()
    cell_m, rows = float(grasp.section_cell_m), int(grasp.section_rows)
    if not (math.isfinite(cell_m) and cell_m > 0.0) or rows <= 0 or len(values) % rows:
        raise GoalError(f"grasp section: {len(values)} heights must fill section_rows ({rows}) rows of cells "
                        f"section_cell_m ({cell_m}) > 0 m wide")
    if not all(math.isfinite(v) and v >= 0.0 for v in values) or not any(values):
        raise GoalError("grasp section_heights_m must be finite heights >= 0 m (0: not the object), some > 0")
    width = len(values) // rows
    return cell_m, tuple(values[i * width:(i + 1) * width] for i in range(rows))


def contact_radii_m(grasp) -> tuple:
    """Grasp.contact_radii_m checked: () or one radius > 0 m per pad (two); a grasp without the field: ()."""
    radii = tuple(float(r) for r in getattr(grasp, "contact_radii_m", ()))
    if radii and (len(radii) != 2 or not all(math.isfinite(r) and r > 0.0 for r in radii)):
        raise GoalError(f"grasp contact_radii_m must be empty (flat or not known) or two radii > 0 m, one per pad, "
                        f"got {list(radii)}")
    return radii


def contact_line_lengths_m(grasp, radii: tuple) -> tuple:
    """Grasp.contact_line_lengths_m checked: () (all point contacts) or one length >= 0 m per pad (two; 0: a point
    contact), and then two contact radii (the curved direction's); a grasp without the field: ()."""
    lengths = tuple(float(v) for v in getattr(grasp, "contact_line_lengths_m", ()))
    if lengths and (len(lengths) != 2 or not all(math.isfinite(v) and v >= 0.0 for v in lengths)):
        raise GoalError("grasp contact_line_lengths_m must be empty (point contacts) or two lengths >= 0 m, one per "
                        f"pad, got {list(lengths)}")
    if lengths and len(radii) != 2:
        raise GoalError(f"grasp contact_line_lengths_m {list(lengths)} needs two contact_radii_m (one per pad), "
                        f"got {list(radii)}")
    return lengths


def place_target(pose_stamped, base_frame: str, default_position, default_yaw: float | None) -> PlaceTarget:
    """Place pose of a goal; an empty frame_id means the configured bin.

    The orientation is a top-down TCP orientation; an identity (or all-zero)
    quaternion means 'position only' and keeps the default yaw (None: the grasp's).
    """
    frame = pose_stamped.header.frame_id
    if frame == "":
        return PlaceTarget(tuple(default_position), default_yaw)
    if frame != base_frame:
        raise GoalError(f"place pose is in frame '{frame}', expected '{base_frame}'")
    p, o = pose_stamped.pose.position, pose_stamped.pose.orientation
    position = (p.x, p.y, p.z)
    if not all(math.isfinite(v) for v in position):
        raise GoalError(f"place position has non-finite values: {position}")
    if (o.x, o.y, o.z) == (0.0, 0.0, 0.0) and o.w in (0.0, 1.0):
        return PlaceTarget(position, default_yaw)
    try:
        return PlaceTarget(position, top_down_yaw(transform_from_pose(pose_stamped.pose)))
    except (ConversionError, PoseError) as error:
        raise GoalError(f"bad place pose: {error}") from error


def check_arm_limits(robot_type: str, joint_limits: str) -> str:
    """The joint limits to plan within: robot_type's ('' = those); ValueError when a robot is planned with
    another arm's limits (an FR3 planned with the Panda's ranges and, above limits_scale 0.5, accelerations
    and jerks the FR3 does not allow) or robot_type is unknown."""
    own = topics.robot_names(robot_type)["joint_limits"]
    if joint_limits and joint_limits != own:
        raise ValueError(f"robot_type {robot_type} with joint_limits {joint_limits}: set joint_limits: {own} or "
                         "leave it empty (sim_bringup/config/real_cell/<robot>.yaml)")
    if own not in ARM_MODELS:
        raise ValueError(f"no joint limits known for robot_type {robot_type} (known: {', '.join(ARM_MODELS)})")
    return own


# The result fields the sequence's Outcome carries under the same names.
OUTCOME_FIELDS = ("success", "failure_reason", "phase_reached", "contact_detected", "contact_height_m",
                  "gripper_width_closed_m", "gripper_force_n", "held_after_lift", "held_after_transfer", "duration_s",
                  "arm_state", "recovery")


def copy_outcome(result, outcome) -> None:
    """The sequence's Outcome into a PickAndPlace result."""
    for name in OUTCOME_FIELDS:
        setattr(result, name, getattr(outcome, name))


def copy_squeeze(result, sequence):
    """A squeeze's readings and estimate into a PickAndPlace result; the estimate (None: the goal ended before it)."""
    result.squeeze_forces_n = [r.force_n for r in sequence.squeeze_readings]
    result.squeeze_widths_m = [r.width_m for r in sequence.squeeze_readings]
    estimate = sequence.squeeze_estimate
    if estimate is None:
        result.stiffness_update = "not measured: the goal ended before the squeeze was done"
        return None
    result.stiffness_measured, result.measured_rigid = True, estimate.rigid
    result.measured_contact_law = estimate.contact_law
    result.measured_youngs_modulus_pa = estimate.youngs_modulus_pa
    result.stiffness_lower_bound = estimate.lower_bound
    result.measured_modulus_low_pa, result.measured_modulus_high_pa = estimate.low_pa, estimate.high_pa
    result.squeeze_stiffness_npm = estimate.stiffness_npm
    return estimate
