"""The simulated driver's robot errors over real DDS, as franka_ros2 3.x (v3.3.0+) handles an FCI error
(docs/franka_contract.md, "Robot errors"): a reflex deactivates the hardware and every controller on it, and only
the three recovery steps, in order, bring the arm back.

The arm presses the hand into the table with a trajectory goal (no executor, no contact guard) until the external
force passes the driver's reflex_force_n.
"""
import time
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter

from defgg_ros.ros import qos, topics

pytestmark = pytest.mark.ros

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"
ARM_JOINTS = topics.robot_names()["joints"]
ARM_CONTROLLER = topics.robot_names("fer")["arm_controller"]
TIMEOUT_S = 60.0
REFLEX_FORCE_N = 15.0
QUIET_S = 0.5          # wall time the broadcasters' topics must stay quiet after the error


@pytest.fixture
def driver(executor, rclpy_context):
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    node = FakePandaDriver(context=rclpy_context, parameter_overrides=[
        Parameter("scene_file", value=str(SCENES / "rigid_box.yaml")),
        Parameter("reflex_force_n", value=REFLEX_FORCE_N)])
    executor.add_node(node)
    yield node
    node.shutdown()


class _Listener:
    """The client side: the arm's action, the recovery (support/robot_recovery.py), what the broadcasters publish."""

    def __init__(self, executor, rclpy_context, spin):
        from control_msgs.action import FollowJointTrajectory
        from geometry_msgs.msg import WrenchStamped
        from rclpy.node import Node
        from sensor_msgs.msg import JointState
        from support.robot_recovery import RecoveryClient

        from defgg_ros.ros.action import ActionClient

        self.executor, self.spin = executor, spin
        self.node = Node("robot_error_test_client", context=rclpy_context)
        executor.add_node(self.node)
        self.arm = ActionClient(self.node, FollowJointTrajectory, topics.ARM_TRAJECTORY_ACTION)
        self.recovery = RecoveryClient(self.node, executor, spin, ARM_CONTROLLER)
        self.received = {"arm": [], "wrench": [], "merged": []}
        for name, msg_type, topic in (("arm", JointState, topics.ARM_JOINT_STATES),
                                      ("wrench", WrenchStamped, topics.EXTERNAL_WRENCH),
                                      ("merged", JointState, topics.JOINT_STATES)):
            self.node.create_subscription(msg_type, topic, lambda msg, n=name: self.received[n].append(
                (time.monotonic(), msg)), qos.ROBOT_STATE_READ)
        spin(executor, self.arm.server_is_ready, TIMEOUT_S, "the arm's action")

    def goal_handle(self, goal):
        return self.spin(self.executor, self.arm.send_goal_async(goal), TIMEOUT_S, "the goal's answer")

    def result(self, handle):
        return self.spin(self.executor, handle.get_result_async(), TIMEOUT_S, "the goal's result").result

    def since(self, name: str, wall_s: float) -> list:
        return [msg for t, msg in self.received[name] if t > wall_s]

    def wait(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        self.spin(self.executor, lambda: time.monotonic() >= end, seconds + TIMEOUT_S, f"{seconds} s")


def _goal(q_from, q_to, duration_s: float):
    """A two-point FollowJointTrajectory goal from q_from to q_to, at rest at both ends."""
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    still = [0.0] * len(ARM_JOINTS)
    sec, nanosec = divmod(int(duration_s * 1e9), 1_000_000_000)
    msg = JointTrajectory(joint_names=list(ARM_JOINTS), points=[
        JointTrajectoryPoint(positions=[float(v) for v in q_from], velocities=still, time_from_start=Duration()),
        JointTrajectoryPoint(positions=[float(v) for v in q_to], velocities=still,
                             time_from_start=Duration(sec=sec, nanosec=nanosec))])
    return FollowJointTrajectory.Goal(trajectory=msg)


def _arm_q(driver) -> np.ndarray:
    with driver._lock:
        return driver.cell.joint_state().positions[:7].copy()


def _into_the_table(q_now):
    """Joint positions that put the hand's TCP 3 cm under the table top below where it is now."""
    from defgg_ros.control.kinematics import PandaKinematics

    kinematics = PandaKinematics()
    tcp = kinematics.fk(q_now)[:3, 3]
    solution, _ = kinematics.top_down_ik([tcp[0], tcp[1], -0.03], 0.0, q_now)
    return solution.q_rad


def test_a_reflex_deactivates_the_controllers_and_only_the_recovery_in_order_brings_them_back(
        executor, rclpy_context, driver, spin):
    from control_msgs.action import FollowJointTrajectory

    from defgg_ros.nodes.fake_arm_controller import DEACTIVATED_TEXT

    cell = _Listener(executor, rclpy_context, spin)
    recovery = cell.recovery
    everything = {topics.JOINT_STATE_BROADCASTER, topics.ROBOT_STATE_BROADCASTER, ARM_CONTROLLER}
    assert recovery.controller_states() == dict.fromkeys(everything, "active")
    q_start = _arm_q(driver)

    # The press: the goal is aborted as the trajectory controller's deactivation aborts it.
    result = cell.result(cell.goal_handle(_goal(q_start, _into_the_table(q_start), 3.0)))
    stopped_wall_s = time.monotonic()
    assert (result.error_code, result.error_string) == (FollowJointTrajectory.Result.INVALID_GOAL, DEACTIVATED_TEXT)
    assert driver.controller_manager.reflexes == 1
    assert recovery.controller_states() == dict.fromkeys(everything, "inactive")

    # The broadcasters are quiet; joint_state_publisher repeats the arm's last state with new stamps.
    cell.wait(QUIET_S)
    assert not cell.since("arm", stopped_wall_s + 0.05), "franka/joint_states went on after the error"
    assert not cell.since("wrench", stopped_wall_s + 0.05), "the external wrench went on after the error"
    merged = cell.since("merged", stopped_wall_s + 0.05)
    assert len(merged) >= 5, f"joint_states: {len(merged)} messages in {QUIET_S} s after the error"
    arm_positions = {tuple(m.position[:len(ARM_JOINTS)]) for m in merged}   # the fingers are franka_gripper's
    assert len(arm_positions) == 1, "joint_states' arm positions changed without joint_state_broadcaster"
    assert len({(m.header.stamp.sec, m.header.stamp.nanosec) for m in merged}) == len(merged)

    # An inactive controller rejects goals; the recovery out of order is refused, step by step.
    assert not cell.goal_handle(_goal(_arm_q(driver), q_start, 2.0)).accepted
    assert driver.arm.rejected_while_inactive == 1
    assert not recovery.activate_controllers().ok   # the hardware is unconfigured
    assert not recovery.activate_hardware().ok      # the robot is still in error
    assert recovery.controller_states() == dict.fromkeys(everything, "inactive")

    # In order: error recovery, the hardware, the controllers; then the arm takes goals and moves again.
    recovery.clear_error()
    answer = recovery.activate_hardware()
    assert answer.ok and answer.state.label == "active"
    assert recovery.activate_controllers().ok
    assert recovery.controller_states() == dict.fromkeys(everything, "active")
    back = cell.result(cell.goal_handle(_goal(_arm_q(driver), q_start, 2.0)))
    assert back.error_code == FollowJointTrajectory.Result.SUCCESSFUL, back.error_string
    np.testing.assert_allclose(_arm_q(driver), q_start, atol=0.01)
    assert cell.since("arm", time.monotonic() - 0.5), "franka/joint_states did not resume"
    assert driver.controller_manager.reflexes == 1
