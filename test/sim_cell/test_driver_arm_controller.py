"""The simulated driver's arm controller over real DDS: when a FollowJointTrajectory goal ends, and how a new
trajectory starts, as ros2_controllers' joint_trajectory_controller (jazzy) does under franka_ros2
(docs/franka_contract.md, "The arm's trajectory controller").

The driver runs in this process, so a test reads the simulated arm itself (under the driver's lock) at the moment
a result arrives.
"""
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter

from defgg_ros.ros import topics

pytestmark = pytest.mark.ros

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"
ARM_JOINTS = topics.robot_names()["joints"]
TIMEOUT_S = 60.0
JOINT7_UPPER_RAD = 2.9671   # the simulated Panda's joint 7 limit (PyBullet stops the joint there)
PREEMPTED = "Current goal preempted by new incoming action."   # preempt_active_goal's text


def _driver(executor, rclpy_context, max_real_time_factor):
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    node = FakePandaDriver(context=rclpy_context, parameter_overrides=[
        Parameter("scene_file", value=str(SCENES / "rigid_box.yaml")),
        Parameter("max_real_time_factor", value=max_real_time_factor)])
    executor.add_node(node)
    return node


@pytest.fixture
def client(executor, rclpy_context):
    from rclpy.node import Node

    node = Node("arm_controller_test_client", context=rclpy_context)
    executor.add_node(node)
    return node


def _duration(seconds: float):
    from builtin_interfaces.msg import Duration

    sec, nanosec = divmod(int(round(seconds * 1e9)), 1_000_000_000)
    return Duration(sec=sec, nanosec=nanosec)


def _arm(driver):
    """(sim time, q, qd) of the simulated arm now."""
    with driver._lock:
        state = driver.cell.joint_state()
        return driver.cell.time_s, state.positions[:7].copy(), state.velocities[:7].copy()


def _goal(points, stamp_s=0.0, **fields):
    """A FollowJointTrajectory goal through (t, q[, qd, qdd]) points; fields: the goal's tolerances."""
    from control_msgs.action import FollowJointTrajectory
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.ros.conversions import seconds_to_stamp

    msg = JointTrajectory(joint_names=list(ARM_JOINTS))
    msg.header.stamp = seconds_to_stamp(stamp_s)
    for t, *values in points:
        q, qd, qdd = (list(values) + [None, None])[:3]
        msg.points.append(JointTrajectoryPoint(
            positions=[float(v) for v in q], velocities=[] if qd is None else [float(v) for v in qd],
            accelerations=[] if qdd is None else [float(v) for v in qdd], time_from_start=_duration(t)))
    return FollowJointTrajectory.Goal(trajectory=msg, **fields)


def _run(executor, spin, arm, goal, on_result=None, feedback=None):
    handle = spin(executor, arm.send_goal_async(goal, feedback_callback=feedback), TIMEOUT_S, "acceptance")
    assert handle.accepted
    future = handle.get_result_async()
    if on_result is not None:
        future.add_done_callback(on_result)
    return handle, future


def _action(client, executor, spin):
    from control_msgs.action import FollowJointTrajectory

    from defgg_ros.ros.action import ActionClient

    arm = ActionClient(client, FollowJointTrajectory, topics.ARM_TRAJECTORY_ACTION)
    spin(executor, arm.server_is_ready, TIMEOUT_S, "the arm's trajectory action")
    return arm


def test_a_goal_succeeds_only_once_the_arm_has_stopped_after_the_end_time(executor, rclpy_context, client, spin):
    """A positions-only trajectory ends at full speed (the controller interpolates linearly): at its end time the
    arm still moves at ~1 rad/s and stops some tens of ms later. The goal's success comes only then (every joint
    below stopped_velocity_tolerance, 0.01 rad/s); the driver reported it at the end time before 2026-12-01.
    The driver runs at a tenth of real time, so the result's delivery (ms of wall time) is a fraction of a ms
    of sim time."""
    from control_msgs.action import FollowJointTrajectory

    driver = _driver(executor, rclpy_context, 0.1)
    try:
        arm = _action(client, executor, spin)
        now_s, q0, _ = _arm(driver)
        start_s, duration_s = now_s + 0.05, 0.2
        at_result = []
        _, future = _run(executor, spin, arm, _goal([(0.0, q0), (duration_s, q0 + 0.2)], stamp_s=start_s),
                         on_result=lambda _f: at_result.append(_arm(driver)))
        result = spin(executor, future, TIMEOUT_S, "the goal's result").result
        spin(executor, lambda: at_result, TIMEOUT_S, "the result's callback")
        assert result.error_code == FollowJointTrajectory.Result.SUCCESSFUL, result.error_string
        (result_s, q, qd), end_s = at_result[0], start_s + duration_s
        assert np.abs(qd).max() <= 0.01, f"success reported with the arm at {np.abs(qd).max():.3f} rad/s"
        assert result_s > end_s + 0.01, f"success {result_s - end_s:.4f} s after the end time: the arm was moving"
        assert result.error_string == "Goal successfully reached!"
        np.testing.assert_allclose(q, q0 + 0.2, atol=0.005)
    finally:
        driver.shutdown()


def test_a_goal_tolerance_that_cannot_be_met_aborts_with_goal_tolerance_violated(executor, rclpy_context, client,
                                                                                 spin):
    """Joint 7 sent beyond its limit stops there (as at an obstacle): 0.23 rad outside a goal_tolerance of 0.01 rad
    it cannot meet, so goal_time_tolerance (0.3 s) after the end time the goal aborts with GOAL_TOLERANCE_VIOLATED
    (-5) and the controller's text, and the arm holds where it is (it reported success before 2026-12-01)."""
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointTolerance

    driver = _driver(executor, rclpy_context, 0.0)
    try:
        arm = _action(client, executor, spin)
        now_s, q0, _ = _arm(driver)
        goal_q = q0.copy()
        goal_q[6] = JOINT7_UPPER_RAD + 0.23
        at_result = []
        goal = _goal([(1.0, goal_q)], stamp_s=now_s,
                     goal_tolerance=[JointTolerance(name=ARM_JOINTS[6], position=0.01)],
                     goal_time_tolerance=_duration(0.3))
        _, future = _run(executor, spin, arm, goal, on_result=lambda _f: at_result.append(_arm(driver)))
        result = spin(executor, future, TIMEOUT_S, "the goal's result").result
        spin(executor, lambda: at_result, TIMEOUT_S, "the result's callback")
        assert result.error_code == FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED, (result.error_code,
                                                                                          result.error_string)
        assert result.error_string.startswith("Aborted due to goal_time_tolerance exceeding by 0.3")
        result_s, q, _ = at_result[0]
        assert result_s >= now_s + 1.3
        assert q[6] == pytest.approx(JOINT7_UPPER_RAD, abs=0.01)
    finally:
        driver.shutdown()


def test_a_path_tolerance_violation_aborts_with_path_tolerance_violated_and_holds(executor, rclpy_context, client,
                                                                                  spin):
    """Joint 1 commanded from rest straight to 2 rad/s (positions only) lags ~11 mrad behind for the first tens of
    ms: a path_tolerance of 5 mrad aborts the goal with PATH_TOLERANCE_VIOLATED (-4) and the arm holds where it
    is, far short of the goal (it went on to the goal and succeeded before 2026-12-01)."""
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointTolerance

    driver = _driver(executor, rclpy_context, 0.0)
    try:
        arm = _action(client, executor, spin)
        now_s, q0, _ = _arm(driver)
        goal_q = q0.copy()
        goal_q[0] += 1.0
        goal = _goal([(0.0, q0), (0.5, goal_q)], stamp_s=now_s,
                     path_tolerance=[JointTolerance(name=ARM_JOINTS[0], position=0.005)])
        _, future = _run(executor, spin, arm, goal)
        result = spin(executor, future, TIMEOUT_S, "the goal's result").result
        assert result.error_code == FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED, (result.error_code,
                                                                                          result.error_string)
        assert result.error_string == "Aborted due to path tolerance violation"
        spin(executor, lambda: _arm(driver)[0] > now_s + 1.0, TIMEOUT_S, "1 s of sim time")
        _, q, qd = _arm(driver)
        assert np.abs(qd).max() < 0.01 and q[0] - q0[0] < 0.2, (q[0] - q0[0], np.abs(qd).max())
    finally:
        driver.shutdown()


def test_a_replacing_goal_starts_from_the_measured_velocity(executor, rclpy_context, client, spin):
    """A goal sent while joint 1 moves at ~1.9 rad/s, its first point 0.3 s ahead: the controller blends into it
    from the measured position and velocity, so the arm carries on at its speed. Before 2026-12-01 the driver
    blended from rest: the arm braked to ~0 within tens of ms and then sped up again."""
    from control_msgs.action import FollowJointTrajectory
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from defgg_ros.ros.conversions import stamp_to_ns

    driver = _driver(executor, rclpy_context, 0.2)
    try:
        trace = []    # (sim time, joint 1 velocity) at 1 kHz of sim time
        client.create_subscription(
            JointState, topics.ARM_JOINT_STATES,
            lambda m: trace.append((stamp_to_ns(m.header.stamp) * 1e-9, m.velocity[0])),
            QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000, reliability=ReliabilityPolicy.RELIABLE))
        arm = _action(client, executor, spin)
        _, q0, _ = _arm(driver)
        z = np.zeros(7)
        goal_q = q0.copy()
        goal_q[0] += 1.0
        _, first = _run(executor, spin, arm, _goal([(0.0, q0, z, z), (1.0, goal_q, z, z)]))   # quintic
        spin(executor, lambda: _arm(driver)[2][0] > 1.8, TIMEOUT_S, "joint 1 near its top speed")
        feedback = []
        _, second = _run(executor, spin, arm, _goal([(0.3, goal_q, z, z)]), feedback=feedback.append)
        result = spin(executor, second, TIMEOUT_S, "the second goal's result").result
        assert result.error_code == FollowJointTrajectory.Result.SUCCESSFUL, result.error_string
        replaced_s = stamp_to_ns(feedback[0].feedback.header.stamp) * 1e-9   # sim time soon after it started
        spin(executor, lambda: trace and trace[-1][0] > replaced_s + 0.1, TIMEOUT_S, "joint states after it")
        times, speeds = np.array(trace).T
        at = speeds[np.argmin(np.abs(times - replaced_s))]
        window = speeds[(times >= replaced_s - 0.005) & (times <= replaced_s + 0.05)]
        assert len(window) > 20
        assert at > 1.5 and window.min() > 0.8 * at, f"joint 1 at {at:.2f} rad/s fell to {window.min():.2f}"
        preempted = spin(executor, first, TIMEOUT_S, "the first goal's result").result
        assert preempted.error_code == FollowJointTrajectory.Result.INVALID_GOAL
        assert preempted.error_string == "Current goal preempted by new incoming action."
    finally:
        driver.shutdown()


def test_a_goal_whose_times_do_not_increase_is_rejected_not_accepted_then_aborted(executor, rclpy_context, client,
                                                                                   spin):
    """joint_trajectory_controller's validate_trajectory_msg refuses it at the goal request ("not strictly
    increasing"); ours accepted it and aborted it when it started."""
    driver = _driver(executor, rclpy_context, 0.0)
    arm = _action(client, executor, spin)
    _, q, _ = _arm(driver)
    goal = _goal([(0.5, q), (0.5, q)])
    handle = spin(executor, arm.send_goal_async(goal), TIMEOUT_S, "the goal response")
    assert not handle.accepted
    driver.destroy_node()


def test_a_goal_running_when_the_driver_shuts_down_is_aborted_saying_so(executor, rclpy_context, client, spin):
    """A goal can be ended canceled only after a cancel request; the shutdown ended it canceled anyway, which rclpy
    refuses ("invalid transition from state EXECUTING with event CANCELED") with an error in the log."""
    from action_msgs.msg import GoalStatus

    driver = _driver(executor, rclpy_context, 0.1)
    arm = _action(client, executor, spin)
    _, q0, _ = _arm(driver)
    feedback = []
    handle, future = _run(executor, spin, arm, _goal([(5.0, q0 + 0.3)]), feedback=feedback.append)
    spin(executor, lambda: feedback, TIMEOUT_S, "the goal running (its feedback)")
    driver.shutdown()
    response = spin(executor, future, TIMEOUT_S, "the goal's result")
    assert response.status == GoalStatus.STATUS_ABORTED
    assert response.result.error_string == "the simulated controller is shutting down"


def test_goals_sent_back_to_back_run_in_the_order_sent(executor, rclpy_context, client, spin):
    """The joint_trajectory_controller starts a goal's trajectory in its goal_accepted_callback, goals handled one
    at a time in the order they arrive: of two goals sent back to back, the second preempts the first. The executor's
    stop relies on it (a hold sent after a goal still in flight needs no cancel of that goal). The driver started a
    trajectory in its execute task after converting it, two goals' tasks on different threads: of a long move (2,000
    points) and a one-point hold sent after it, the hold started first and the move, converted later, preempted it
    and ran to its end (3 of 3 runs on the old driver). 10 pairs: a move of joint 1 by 0.3 rad over 5 s, then a
    hold where the arm is."""
    from control_msgs.action import FollowJointTrajectory

    driver = _driver(executor, rclpy_context, 1.0)
    try:
        arm = _action(client, executor, spin)
        for pair in range(10):
            _, q0, _ = _arm(driver)
            move_points = [(t, q0 + 0.3 * t / 5.0) for t in np.linspace(0.0025, 5.0, 2000)]
            move, hold = arm.send_goal_async(_goal(move_points)), arm.send_goal_async(_goal([(0.1, q0)]))
            handles = [spin(executor, future, TIMEOUT_S, "acceptance") for future in (move, hold)]
            assert all(handle.accepted for handle in handles)
            moved, held = (spin(executor, handle.get_result_async(), TIMEOUT_S, "a result").result
                           for handle in handles)
            assert moved.error_string == PREEMPTED, f"pair {pair}: the move ended '{moved.error_string}'"
            assert held.error_code == FollowJointTrajectory.Result.SUCCESSFUL, (pair, held.error_string)
            _, q, qd = _arm(driver)
            assert np.abs(q - q0).max() < 0.005 and np.abs(qd).max() < 0.01, f"pair {pair}: the move ran"
    finally:
        driver.shutdown()


def test_feedback_comes_at_the_controllers_action_monitor_rate(executor, rclpy_context, client, spin):
    """joint_trajectory_controller sends a running goal's feedback at `action_monitor_rate`, 20 Hz by default
    (franka_ros2 leaves it); the driver sent it at 10 Hz. Median interval over a 1.5 s goal, wall clock."""
    import time

    driver = _driver(executor, rclpy_context, 1.0)
    try:
        arm = _action(client, executor, spin)
        _, q0, _ = _arm(driver)
        arrivals = []
        _, future = _run(executor, spin, arm, _goal([(1.5, q0 + 0.1)]),
                         feedback=lambda _f: arrivals.append(time.monotonic()))
        spin(executor, future, TIMEOUT_S, "the goal's result")
        intervals_s = np.diff(arrivals)
        assert len(intervals_s) >= 10, f"{len(arrivals)} feedback messages"
        assert 0.04 <= np.median(intervals_s) <= 0.065, f"median interval {np.median(intervals_s):.3f} s"
    finally:
        driver.shutdown()


def test_a_trajectory_that_ends_before_it_arrives_is_refused_and_the_arm_stays(executor, rclpy_context, client, spin):
    """validate_trajectory_msg refuses a trajectory with a start time that ends in the past, as a goal and on the
    topic, so a stop stamped on a stale clock and delivered late does not move the arm. The driver took such a
    trajectory when its stamp was over 1 s old and started it on receipt: the arm went to its first point, where
    the sender had seen the arm long before (a stop planned 0.6 s late pulled the arm back 1.1 rad, 33 rad/s)."""
    from trajectory_msgs.msg import JointTrajectory

    from defgg_ros.ros import qos

    driver = _driver(executor, rclpy_context, 0.0)
    try:
        arm = _action(client, executor, spin)
        spin(executor, lambda: _arm(driver)[0] > 3.0, TIMEOUT_S, "3 s of sim time")
        now_s, q0, _ = _arm(driver)
        away = q0 + 0.3
        for ago_s in (0.6, 2.5):   # within and beyond the 1 s the driver used to treat as a wall-clock stamp
            handle = spin(executor, arm.send_goal_async(_goal([(0.0, away), (0.5, away)], stamp_s=now_s - ago_s)),
                          TIMEOUT_S, "the goal response")
            assert not handle.accepted, ago_s
        pub = client.create_publisher(JointTrajectory, topics.JOINT_TRAJECTORY, qos.COMMAND)
        spin(executor, lambda: pub.get_subscription_count() > 0, TIMEOUT_S, "driver subscribed")
        pub.publish(_goal([(0.0, away), (0.5, away)], stamp_s=_arm(driver)[0] - 2.5).trajectory)
        later_s = _arm(driver)[0] + 1.0
        spin(executor, lambda: _arm(driver)[0] > later_s, TIMEOUT_S, "1 s of sim time after the topic message")
        assert np.max(np.abs(_arm(driver)[1] - q0)) < 1e-3
        # one that started in the past but ends later is taken, sampled from its stamp
        handle, result = _run(executor, spin, arm, _goal([(0.0, q0), (1.0, away)], stamp_s=_arm(driver)[0] - 0.5))
        sent_s = _arm(driver)[0]
        spin(executor, result, TIMEOUT_S, "its result")
        ended_s, q_end, _ = _arm(driver)
        assert np.max(np.abs(q_end - away)) < 0.03   # stopped there (joint 2 settles under gravity)
        assert ended_s - sent_s < 0.9                 # half of it was over when it arrived
    finally:
        driver.shutdown()
