"""executor_node's message translations (no DDS needed): trajectories, joint states, goals."""
import math

import numpy as np
import pytest
from defgg_interfaces.msg import Grasp
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState

from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control.poses import matrix_to_quaternion, top_down_pose
from defgg_ros.control.trajectories import SampledTrajectory
from defgg_ros.nodes.executor_node import (
    GoalError,
    grasp_target,
    joint_state_to_arm,
    place_target,
    trajectory_to_msg,
)
from defgg_ros.ros import topics

NAMES = topics.robot_names()   # the default robot type: fer
BASE = NAMES["base_frame"]
ARM_JOINTS, FINGER_JOINTS = NAMES["joints"], NAMES["fingers"]


def test_trajectory_times_survive_the_split_into_seconds_and_nanoseconds():
    times = np.array([0.0, 0.5, 0.9999999999, 1.0, 1.9999999996, 2.25])
    q = np.tile(PANDA_READY_Q_RAD, (len(times), 1))
    msg = trajectory_to_msg(SampledTrajectory(times, q, np.zeros_like(q), np.zeros_like(q)), BASE)
    stamps = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points]
    assert stamps == pytest.approx(times, abs=1e-9)
    assert all(0 <= p.time_from_start.nanosec < 1_000_000_000 for p in msg.points)
    assert msg.joint_names == list(ARM_JOINTS)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 0)  # start on receipt
    assert len(msg.points[0].velocities) == 7 and len(msg.points[0].accelerations) == 7


def test_joint_state_in_any_order_with_fingers():
    names = list(reversed(ARM_JOINTS)) + list(FINGER_JOINTS)
    positions = list(reversed(range(7))) + [0.01, 0.015]
    state = joint_state_to_arm(JointState(name=names, position=[float(p) for p in positions],
                                          velocity=[0.1] * 9))
    assert state.q_rad == pytest.approx(np.arange(7))
    assert state.qd_radps == pytest.approx(np.full(7, 0.1))
    assert state.gripper_width_m == pytest.approx(0.025)


def test_joint_state_without_arm_joints_or_fingers():
    with pytest.raises(GoalError, match="lacks"):
        joint_state_to_arm(JointState(name=["fer_joint1"], position=[0.0]))
    state = joint_state_to_arm(JointState(name=list(ARM_JOINTS), position=[0.0] * 7))
    assert math.isnan(state.gripper_width_m) and not np.any(state.qd_radps)


def grasp(frame=BASE, yaw=0.7, z=0.05, modulus=2e5):
    msg = Grasp()
    msg.pose_base.header.frame_id = frame
    msg.pose_base.pose.position.x, msg.pose_base.pose.position.y, msg.pose_base.pose.position.z = 0.5, 0.1, z
    q = matrix_to_quaternion(top_down_pose([0.5, 0.1, z], yaw)[:3, :3])
    o = msg.pose_base.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)
    msg.width_m, msg.youngs_modulus_pa = 0.04, modulus
    return msg


def test_grasp_target_from_a_grasp_message():
    target = grasp_target(grasp(), BASE, default_modulus_pa=2e6)
    assert target.position_m == pytest.approx((0.5, 0.1, 0.05))
    assert target.yaw_rad == pytest.approx(0.7)
    assert target.youngs_modulus_pa == 2e5
    # A grasp computed without stiffness input carries 0 Pa: the default applies.
    assert grasp_target(grasp(modulus=0.0), BASE, default_modulus_pa=2e6).youngs_modulus_pa == 2e6
    # The force its model's labels used travels with the grasp (0: the executor's modulus rule).
    assert target.finger_force_n == 0.0
    msg = grasp()
    msg.finger_force_n = 0.8
    assert grasp_target(msg, BASE, 2e6).finger_force_n == 0.8


def test_the_grasps_contact_radii_reach_the_target():
    """Grasp.contact_radii_m (one per pad, -closing side first) becomes GraspTarget.contact_radii_m; empty: ()."""
    assert grasp_target(grasp(), BASE, 2e6).contact_radii_m == ()
    msg = grasp()
    msg.contact_radii_m = [0.021, 0.034]
    assert grasp_target(msg, BASE, 2e6).contact_radii_m == pytest.approx((0.021, 0.034))


@pytest.mark.parametrize("radii", [[0.02], [0.02, 0.03, 0.04], [0.02, -0.01], [0.02, float("nan")], [0.0, 0.02],
                                   [float("inf"), 0.02]])
def test_bad_contact_radii_refuse_the_goal_saying_why(radii):
    msg = grasp()
    msg.contact_radii_m = radii
    with pytest.raises(GoalError, match="contact_radii_m must be empty .* or two radii > 0 m, one per pad"):
        grasp_target(msg, BASE, 2e6)


def test_the_grasps_contact_line_lengths_reach_the_target():
    """Grasp.contact_line_lengths_m (per pad: 0 a point contact, > 0 a line contact) becomes
    GraspTarget.contact_line_lengths_m beside the radii; empty: () (all point contacts)."""
    msg = grasp()
    msg.contact_radii_m = [0.021, 0.034]
    assert grasp_target(msg, BASE, 2e6).contact_line_lengths_m == ()
    msg.contact_line_lengths_m = [0.0, 0.018]
    target = grasp_target(msg, BASE, 2e6)
    assert target.contact_line_lengths_m == pytest.approx((0.0, 0.018))
    assert target.contact_radii_m == pytest.approx((0.021, 0.034))


def test_the_grasps_section_reaches_the_target_as_rows_of_heights():
    """Grasp.section_* (the squeeze's section law) becomes GraspTarget.section_cell_m and section_heights_m, one
    tuple per row; empty: not perceived."""
    msg = grasp()
    assert grasp_target(msg, BASE, 2e6).section_heights_m == ()
    msg.section_cell_m, msg.section_rows, msg.section_heights_m = 0.003, 2, [0.0, 0.03, 0.03, 0.03, 0.03, 0.0]
    target = grasp_target(msg, BASE, 2e6)
    assert target.section_cell_m == 0.003
    assert np.allclose(target.section_heights_m, [[0.0, 0.03, 0.03], [0.03, 0.03, 0.0]])


@pytest.mark.parametrize("cell_m, rows, heights, message", [
    (0.003, 4, [0.03] * 6, r"6 heights must fill section_rows \(4\) rows"),
    (0.003, 0, [0.03] * 6, r"section_rows \(0\)"),
    (0.0, 2, [0.03] * 6, r"section_cell_m \(0.0\) > 0 m wide"),
    (float("nan"), 2, [0.03] * 6, "section_cell_m"),
    (0.003, 2, [0.03, -0.01, 0.0, 0.0, 0.0, 0.0], "finite heights >= 0 m"),
    (0.003, 2, [0.03, float("inf"), 0.0, 0.0, 0.0, 0.0], "finite heights >= 0 m"),
    (0.003, 2, [0.0] * 6, "some > 0"),
])
def test_a_bad_section_refuses_the_goal_saying_why(cell_m, rows, heights, message):
    msg = grasp()
    msg.section_cell_m, msg.section_rows, msg.section_heights_m = cell_m, rows, heights
    with pytest.raises(GoalError, match=message):
        grasp_target(msg, BASE, 2e6)


@pytest.mark.parametrize("radii, lengths, message", [
    ([0.02, 0.03], [0.01], "contact_line_lengths_m must be empty .* or two lengths >= 0 m, one per pad, got .0.01.$"),
    ([0.02, 0.03], [0.01, 0.02, 0.0], "two lengths >= 0 m, one per pad"),
    ([0.02, 0.03], [0.01, -0.001], "two lengths >= 0 m, one per pad, got .0.01, -0.001."),
    ([0.02, 0.03], [float("nan"), 0.01], "two lengths >= 0 m, one per pad"),
    ([0.02, 0.03], [0.0, float("inf")], "two lengths >= 0 m, one per pad"),
    ([], [0.0, 0.018], r"contact_line_lengths_m \[0.0, 0.018\] needs two contact_radii_m \(one per pad\), got \[\]"),
])
def test_bad_contact_line_lengths_refuse_the_goal_saying_why(radii, lengths, message):
    msg = grasp()
    msg.contact_radii_m, msg.contact_line_lengths_m = radii, lengths
    with pytest.raises(GoalError, match=message):
        grasp_target(msg, BASE, 2e6)


@pytest.mark.parametrize("mutate, message", [
    (lambda g: setattr(g.pose_base.header, "frame_id", "camera_depth_optical_frame"), "expected 'fer_link0'"),
    (lambda g: setattr(g.pose_base.pose.orientation, "w", 7.0), "bad grasp pose"),
    (lambda g: setattr(g.pose_base.pose.position, "z", float("inf")), "bad grasp pose"),
    (lambda g: setattr(g, "finger_force_n", -2.0), "finger_force_n"),
    (lambda g: setattr(g, "finger_force_n", float("nan")), "finger_force_n"),
])
def test_bad_grasp_messages(mutate, message):
    msg = grasp()
    mutate(msg)
    with pytest.raises(GoalError, match=message):
        grasp_target(msg, BASE, 2e6)


def test_tilted_grasp_is_refused():
    msg = grasp()
    o = msg.pose_base.pose.orientation
    o.x, o.y, o.z, o.w = 0.0, 0.0, 0.0, 1.0  # z up: not a top-down grasp
    with pytest.raises(GoalError, match="tilted"):
        grasp_target(msg, BASE, 2e6)


def test_place_target_defaults_and_overrides():
    default = place_target(PoseStamped(), BASE, [0.35, -0.45, 0.12], 0.0)
    assert default.position_m == pytest.approx((0.35, -0.45, 0.12))
    given = PoseStamped()
    given.header.frame_id = BASE
    given.pose.position.x, given.pose.position.y, given.pose.position.z = 0.4, -0.3, 0.1
    given.pose.orientation.w = 1.0  # identity: position only
    assert place_target(given, BASE, [0.35, -0.45, 0.12], 0.2).position_m == pytest.approx((0.4, -0.3, 0.1))
    o = given.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in matrix_to_quaternion(top_down_pose([0, 0, 0], -0.5)[:3, :3]))
    assert place_target(given, BASE, [0.35, -0.45, 0.12], 0.2).yaw_rad == pytest.approx(-0.5)
    given.header.frame_id = "world"
    with pytest.raises(GoalError, match="frame"):
        place_target(given, BASE, [0.35, -0.45, 0.12], 0.0)
