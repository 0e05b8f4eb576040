"""executor_node over real DDS against the small in-test driver node of test/support/executor_cell.py
(a real rclpy node, not a mock of the executor)."""
import time

import numpy as np
import pytest
from defgg_interfaces.action import PickAndPlace
from rclpy.parameter import Parameter
from support.executor_cell import (
    FAST,
    GRASP_XYZ,
    KIN,
    grasp_msg,
    result_of,
    send,
    wait_driver_ready,
)

from defgg_ros.grasping.geometry import tcp_height_m
from defgg_ros.nodes.executor_node import PARAMETERS, ExecutorNode
from defgg_ros.ros import topics


def test_pick_and_place_with_contact_on_the_way_down(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    driver = start_driver(object_width_m=0.04, contact_height_m=GRASP_XYZ[2] + 0.01)
    wait_driver_ready(ex, spin, node)
    phases = []
    handle = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()),
                  feedback=lambda f: phases.append(f.feedback.phase))
    assert handle.accepted
    response = result_of(ex, spin, handle)
    result = response.result
    assert result.success, result.failure_reason
    assert result.phase_reached == "done"
    assert list(dict.fromkeys(phases)) == ["pre_grasp", "descend", "close", "lift", "transfer", "place", "retreat",
                                          "done"]
    # The descent ended at the contact, before the grasp depth (how far past the first touch
    # depends on scheduling in this busy process; the fake-clock tests pin the distance down).
    assert result.contact_detected
    assert node._config.grasp_height_rule == "half_height"
    grasp_tcp_z = tcp_height_m(GRASP_XYZ[2], node._config.table_z_m)
    assert grasp_tcp_z + 0.002 < result.contact_height_m < GRASP_XYZ[2] + 0.01
    assert result.gripper_width_closed_m == pytest.approx(0.04)
    assert result.held_after_lift and result.held_after_transfer
    assert result.grasp_used.width_m == pytest.approx(0.05)
    # The arm ends above the bin's first free slot (no place pose: the bin), fingers open; the slot is used now.
    tcp = KIN.fk(driver.q)[:3, 3]
    assert tcp[:2] == pytest.approx(node._bin.centres[0], abs=2e-3)
    assert driver.width_m > 0.04
    assert node._bin.used == 1 and node._bin.next_free() == 1


@pytest.mark.parametrize("plan_grasp", [False, True], ids=["given_grasp", "plan_grasp"])
def test_a_goal_sent_before_the_drivers_first_joint_state_waits_for_it(executor_cell, spin, plan_grasp):
    """A goal sent as soon as the driver's actions are up, before its first joint state (CI, 2026-12-01: a cell
    just brought up, the simulated driver busy with its first frame): the executor waits up to server_wait_s for
    the first joint state and wrench instead of refusing the goal ('no joint states ... (none since start)')."""
    ex, node, client, start_driver = executor_cell
    started_s = time.monotonic()
    spin(ex, lambda: time.monotonic() - started_s > FAST["watchdog_timeout_s"] + 0.5, 10.0, "the executor to age")
    driver = start_driver(object_width_m=0.04, states_after_s=4.0)   # < server_wait_s (10 s)
    handle = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg(), plan_grasp=plan_grasp))
    assert handle.accepted and node._joint_watch.last_s is None   # nothing heard yet when the goal came
    result = result_of(ex, spin, handle, timeout_s=60.0).result
    assert driver.trajectory_msgs or plan_grasp, result.failure_reason
    if not plan_grasp:
        assert result.success, result.failure_reason
    else:   # no grasp service in this cell: the goal gets as far as asking it
        assert "driver silent" not in result.failure_reason and "no joint states" not in result.failure_reason
        assert "not planning with the arm in the camera's view" not in result.failure_reason, result.failure_reason


def test_busy_goal_is_rejected_and_cancel_stops_the_arm(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    # Without recovery the arm stays where the cancel stopped it (with it, a cancel landing late on a
    # loaded machine is more than observation_tolerance_rad from the start and the arm goes back).
    node.set_parameters([Parameter("recover_after_failure", value=False)])
    first = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    assert first.accepted
    second = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    assert not second.accepted
    spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 10.0, "the arm moving towards the pre-grasp")
    spin(ex, first.cancel_goal_async(), 5.0, "cancel response")
    response = result_of(ex, spin, first)
    assert response.status == 5  # GoalStatus.STATUS_CANCELED
    assert "canceled during pre_grasp" in response.result.failure_reason
    assert response.result.arm_state == "at_rest" and response.result.recovery == ""
    assert np.max(np.abs(driver.qd)) < 0.02
    assert not KIN.fk(driver.q)[:3, 3] == pytest.approx(KIN.fk(node._kin.q_ready_rad)[:3, 3], abs=1e-3)


def test_a_stop_leads_by_the_latency_of_the_controllers_answers(executor_cell, spin):
    """A controller that answers trajectory goals 0.14 s after they arrive (a loaded machine): the stop that a cancel
    sends is stamped to start STOP_LEAD_LATENCY_FACTOR (1.5) x that after the last joint state, not STOP_LEAD_S
    (0.15 s), so it does not arrive after its own start and pull the arm back.

    A cancel the executor handles after the first motion's planned end (0.84 s; a starved machine) stops no motion
    and sends no trajectory (pick_place._fail): that attempt says nothing of the lead, and it is tried again from the
    start pose (at most 3 times). The full suite once waited 10 s for a stop that could not come (2026-12-03)."""
    from defgg_ros.control.pick_place import MAX_STOP_LEAD_S, STOP_LEAD_LATENCY_FACTOR, STOP_LEAD_S

    answer_s = 0.14
    ex, node, client, start_driver = executor_cell
    driver = start_driver(arm_goal_answer_s=answer_s)
    start_q = driver.q.copy()
    wait_driver_ready(ex, spin, node)
    node.set_parameters([Parameter("recover_after_failure", value=False)])
    for _attempt in range(3):
        driver.q, driver.qd = start_q.copy(), np.zeros(7)   # the in-test arm back at the start, at rest
        goal = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
        spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 20.0, "the arm moving towards the pre-grasp")
        sent, state_s = len(driver.trajectory_msgs), driver.last_state_stamp_s
        spin(ex, goal.cancel_goal_async(), 5.0, "cancel response")
        result = goal.get_result_async()
        spin(ex, lambda sent=sent, result=result: len(driver.trajectory_msgs) > sent or result.done(), 10.0,
             "the stop trajectory (or the result of a cancel that came after the motion)")
        stopped = len(driver.trajectory_msgs) > sent
        assert result_of(ex, spin, goal).status == 5  # GoalStatus.STATUS_CANCELED
        if stopped:
            break
    else:
        raise AssertionError("three cancels in a row came after the first motion's end: no stop to check")
    stamp = driver.trajectory_msgs[sent].header.stamp
    lead_s = stamp.sec + 1e-9 * stamp.nanosec - state_s
    # lead_s counts from a state taken before the cancel, so it is at least the lead (0.21 s here, 0.26 measured);
    # with the old bound (-0.05) a lead fixed at STOP_LEAD_S passed too (0.164 measured, 2026-12-03)
    assert MAX_STOP_LEAD_S + 0.05 >= lead_s >= answer_s * STOP_LEAD_LATENCY_FACTOR - 0.02 > STOP_LEAD_S, lead_s


def test_the_stop_on_the_way_out_is_planned_on_a_joint_state_that_came_after_the_signal(executor_cell, spin):
    """An executor starved of the CPU for 0.4 s (a loaded machine) while the arm moves, then asked to stop (SIGTERM:
    run_node calls stop_for_exit): the stop must start after it reaches the controller. Planned at once on
    the old state, its stamp came from a stale clock (the state's stamp plus at most 0.1 s) and lay in the past on
    arrival; the simulated controller then pulled the arm back to where the stale state had seen it."""
    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 20.0, "the arm moving towards the pre-grasp")
    # 0.4 s in which this executor runs nothing; the driver, as if in its own process, moves and publishes on
    starved_until = time.monotonic() + 0.4
    while time.monotonic() < starved_until:
        driver.step()
        time.sleep(0.01)
    sent, asked_s = len(driver.trajectory_msgs), driver.now_s()
    assert node.stop_for_exit(lambda timeout_s: ex.spin_once(timeout_sec=timeout_s)) == ""
    stamp = driver.trajectory_msgs[sent].header.stamp
    # Not before it was asked for (so not in the past on arrival); a zero stamp is the controller's "start on
    # receipt", never in the past: the one-point hold, sent when the sequence has no stop to plan (seen once in
    # the full suite, 2026-12-03; why the sequence had none then was not established).
    stamp_s = stamp.sec + 1e-9 * stamp.nanosec
    assert stamp_s == 0.0 or stamp_s > asked_s, stamp_s


def test_without_a_fresh_joint_state_the_stop_on_the_way_out_is_a_cancel(executor_cell, spin):
    """The driver's joint states stop coming (0.6 s) while the arm moves, then the executor is asked to stop: no
    stop can be stamped on the controller's clock from a state that old, so the goal is canceled (the controller
    holds where the arm is) and no trajectory goes out."""
    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 20.0, "the arm moving towards the pre-grasp")
    driver.states_from_s = time.monotonic() + 0.6
    silent_until = time.monotonic() + 0.3
    spin(ex, lambda: time.monotonic() > silent_until, 5.0, "0.3 s without joint states")
    sent, running = len(driver.trajectory_msgs), driver.arm_goal
    assert running is not None
    assert node.stop_for_exit(lambda timeout_s: ex.spin_once(timeout_sec=timeout_s)) == ""
    assert len(driver.trajectory_msgs) == sent
    assert running[0].is_cancel_requested or running[1].result() == "canceled"


def test_a_cancel_while_the_fingers_close_opens_the_hand_and_recovers(executor_cell, spin):
    """The grasp goal, not canceled by the gripper, is preempted by the recovery's opening and answers after it was
    sent: that late result must not be read as the opening's (it was: "the hand did not open: preempted by a newer
    gripper command", the arm left over the table; issue 48)."""
    ex, node, client, start_driver = executor_cell
    driver = start_driver(object_width_m=0.0)   # nothing between the fingers: they close all the way, slowly
    wait_driver_ready(ex, spin, node)
    phases = []
    handle = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()), feedback=lambda f: phases.append(
        f.feedback.phase))
    spin(ex, lambda: "close" in phases and driver.gripper is not None, 30.0, "the fingers closing")
    spin(ex, handle.cancel_goal_async(), 5.0, "cancel response")
    response = result_of(ex, spin, handle)
    assert response.status == 5 and "canceled during close" in response.result.failure_reason, \
        response.result.failure_reason
    assert "opened the hand" in response.result.recovery and "did not open" not in response.result.recovery, \
        response.result.recovery
    assert response.result.arm_state == "observation_pose"


def test_a_full_bin_refuses_goals_until_it_is_reset(executor_cell, spin, call):
    """Every slot used: a goal with no place pose is refused before the arm moves, naming the reset service; after
    defgg/reset_bin the next one goes to the first slot (issue 48)."""
    from rclpy.node import Node
    from std_srvs.srv import Trigger

    ex, node, client, start_driver = executor_cell
    driver = start_driver(object_width_m=0.04)
    wait_driver_ready(ex, spin, node)
    for index in range(len(node._bin.centres)):
        node._bin.mark_used(index)
    refused = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg())))
    assert refused.status == 6 and "the bin is full" in refused.result.failure_reason
    assert "/defgg/reset_bin" in refused.result.failure_reason and len(driver.trajectory_msgs) == 0
    caller = Node("reset_bin_caller", context=node.context)
    ex.add_node(caller)
    answer = call(ex, caller.create_client(Trigger, "defgg/reset_bin"), Trigger.Request(), 10.0, "reset_bin")
    assert answer.success and answer.message.startswith(f"{len(node._bin.centres)} of")
    done = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg())))
    assert done.result.success, done.result.failure_reason
    assert KIN.fk(driver.q)[:2, 3] == pytest.approx(node._bin.centres[0], abs=2e-3)


def test_driver_killed_mid_trajectory_aborts_then_serves_again(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    handle = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 10.0, "the arm moving")
    ex.remove_node(driver)
    driver.destroy_node()
    response = result_of(ex, spin, handle, timeout_s=FAST["watchdog_timeout_s"] + 2.0)
    assert response.status == 6
    assert "driver silent" in response.result.failure_reason
    assert response.result.phase_reached == "pre_grasp"
    # The driver comes back: a new goal is accepted and runs.
    silent_since_s = node._last_state[1]
    start_driver(own_process=True)
    spin(ex, lambda: node._last_state[1] > silent_since_s, 30.0, "joint states from the restarted driver")
    # Action discovery of a new process can take tens of seconds on a loaded 2-core machine.
    spin(ex, lambda: node._move_client.server_is_ready() and node._grasp_client.server_is_ready()
         and node._arm_client.server_is_ready(), 60.0, "the restarted driver's arm and gripper actions (discovery)")
    again = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    assert again.accepted
    spin(ex, lambda: np.max(np.abs(node._last_state[0].qd_radps)) > 0.05, 30.0,   # 10 s: missed at a load of 8
         "the restarted driver moving the arm for the new goal")
    spin(ex, again.cancel_goal_async(), 5.0, "cancel response")
    assert result_of(ex, spin, again).status == 5


def test_bad_goals_are_aborted_with_a_reason_and_the_node_keeps_serving(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    start_driver()
    wait_driver_ready(ex, spin, node)
    node.set_parameters([Parameter("server_wait_s", value=1.0)])  # the grasp service never comes
    nan_grasp = grasp_msg()
    nan_grasp.pose_base.pose.position.x = float("nan")
    bad_radii = grasp_msg()
    bad_radii.contact_radii_m = [0.02, float("nan")]
    bad_lines = grasp_msg()
    bad_lines.contact_radii_m, bad_lines.contact_line_lengths_m = [0.02, 0.03], [0.0, -0.01]
    cases = [
        (PickAndPlace.Goal(grasp=nan_grasp), "bad grasp pose"),
        (PickAndPlace.Goal(grasp=bad_radii), "contact_radii_m must be empty (flat or not known) or two radii > 0 m"),
        (PickAndPlace.Goal(grasp=bad_lines), "contact_line_lengths_m must be empty (point contacts) or two lengths"),
        (PickAndPlace.Goal(grasp=grasp_msg(xyz=(1.3, 0.0, 0.05))), "grasp outside the workspace"),
        (PickAndPlace.Goal(grasp=grasp_msg(width_m=0.2)), "maximum opening"),
        (PickAndPlace.Goal(grasp=grasp_msg(finger_force_n=-1.0)), "finger_force_n"),
        (PickAndPlace.Goal(plan_grasp=True), "grasp service"),
    ]
    place = PickAndPlace.Goal(grasp=grasp_msg())
    place.place_pose.header.frame_id = topics.BASE_FRAME
    place.place_pose.pose.position.x, place.place_pose.pose.position.y = 0.0, -1.4
    cases.append((place, "place pose unreachable"))
    for goal, reason in cases:
        handle = send(ex, client, spin, goal)
        assert handle.accepted
        response = result_of(ex, spin, handle, timeout_s=10.0)
        assert response.status == 6  # GoalStatus.STATUS_ABORTED
        assert reason in response.result.failure_reason
        assert not response.result.success


def test_shipped_overrides_name_known_parameters_and_load(rclpy_context):
    from pathlib import Path

    import yaml

    path = Path(__file__).resolve().parents[2] / "sim_bringup" / "config" / "executor_node.yaml"
    overrides = yaml.safe_load(path.read_text())["/**/executor_node"]["ros__parameters"] or {}
    assert set(overrides) <= set(PARAMETERS)
    node = ExecutorNode(context=rclpy_context, cli_args=["--ros-args", "--params-file", str(path)])
    try:
        for name, spec in PARAMETERS.items():
            assert node.get_parameter(name).value == overrides.get(name, spec.default), name
    finally:
        node.destroy_node()


def test_invalid_parameters_refuse_to_start(rclpy_context):
    with pytest.raises(ValueError, match="limits_scale"):
        ExecutorNode(context=rclpy_context, parameter_overrides=[Parameter("limits_scale", value=1.5)])
    with pytest.raises(ValueError, match="grasp_height_rule"):
        ExecutorNode(context=rclpy_context, parameter_overrides=[Parameter("grasp_height_rule", value="middle")])
    # an FR3 planned within the Panda's ranges and accelerations
    with pytest.raises(ValueError, match="robot_type fr3 with joint_limits panda: set joint_limits: fr3 or leave"):
        ExecutorNode(context=rclpy_context, parameter_overrides=[Parameter("robot_type", value="fr3"),
                                                                 Parameter("joint_limits", value="panda")])
    # franka_ros2 on Jazzy has no "panda" robot type (the Panda is fer): refused by the schema, naming the choices
    with pytest.raises(ValueError, match="robot_type.*fer.*fr3"):
        ExecutorNode(context=rclpy_context, parameter_overrides=[Parameter("robot_type", value="panda")])


NEAR_BASE_XYZ, NEAR_BASE_YAW = (0.277, -0.048, 0.036), -1.49   # its straight lift runs out of reach


def _ranked_grasp_service(ex, context):
    """A real PlanGrasp server node: the best grasp is one the sequence refuses (near the base), the second
    the reachable GRASP_XYZ; it answers top_k grasps, stamped now (a frame taken at the observation pose)."""
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.node import Node

    server = Node("ranked_grasp_service", context=context)
    asked = []

    def plan(request, response):
        asked.append(request.top_k)
        ranked = [grasp_msg(xyz=NEAR_BASE_XYZ, yaw=NEAR_BASE_YAW), grasp_msg()][:max(1, request.top_k)]
        for grasp in ranked:
            grasp.header.stamp = server.get_clock().now().to_msg()
        response.success, response.grasps = True, ranked
        return response

    server.create_service(PlanGrasp, topics.PLAN_GRASP_SERVICE, plan)
    ex.add_node(server)
    return asked


@pytest.mark.parametrize("alternatives", [5, 1])
def test_a_planned_grasp_the_arm_cannot_make_gives_way_to_the_next_ranked_one(executor_cell, spin, alternatives):
    ex, node, client, start_driver = executor_cell
    start_driver(object_width_m=0.04)
    wait_driver_ready(ex, spin, node)
    node.set_parameters([Parameter("plan_grasp_alternatives", value=alternatives)])
    asked = _ranked_grasp_service(ex, node.context)
    handle = send(ex, client, spin, PickAndPlace.Goal(plan_grasp=True))
    assert handle.accepted
    result = result_of(ex, spin, handle, timeout_s=60.0).result
    if alternatives == 1:   # as before alternatives: the best grasp's refusal, before the arm moved
        assert asked == [1] and not result.success and result.phase_reached == "pre_grasp"
        assert "its straight lift cannot be made" in result.failure_reason
        return
    assert asked == [1, 5]
    assert result.success, result.failure_reason
    assert result.grasp_used.pose_base.pose.position.x == pytest.approx(GRASP_XYZ[0])


def _peak_limit_ratio(trajectory_msgs) -> float:
    from defgg_ros.constants import PANDA_QD_MAX_RADPS, PANDA_QDD_MAX_RADPS2

    ratios = [0.0]
    for msg in trajectory_msgs:
        for point in msg.points:
            ratios.append(float(np.max(np.abs(point.velocities) / np.array(PANDA_QD_MAX_RADPS))))
            ratios.append(float(np.max(np.abs(point.accelerations) / np.array(PANDA_QDD_MAX_RADPS2))))
    return max(ratios)


def test_a_parameter_set_at_runtime_takes_effect_from_the_next_goal(executor_cell, spin):
    """`ros2 param set executor_node limits_scale 0.3` must slow the next pick (it was accepted and ignored)."""
    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    assert result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))).result.success
    fast = _peak_limit_ratio(driver.trajectory_msgs)
    assert fast > 0.5, fast                       # at limits_scale 1.0 the motions reach far beyond 0.3
    assert node.set_parameters([Parameter("limits_scale", value=0.3)])[0].successful
    driver.trajectory_msgs.clear()
    assert result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))).result.success
    assert 0.0 < _peak_limit_ratio(driver.trajectory_msgs) <= 0.3 * (1 + 1e-3)


def test_without_an_external_wrench_the_pick_is_refused_before_the_arm_moves(executor_cell, spin):
    """A wrong wrench topic or a dead broadcaster would leave the descent's contact guard reading zeros."""
    import time

    from geometry_msgs.msg import WrenchStamped

    from defgg_ros.ros import qos

    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    driver.destroy_publisher(driver.wrench_pub)      # the broadcaster goes quiet (or publishes elsewhere)
    driver.wrench_pub = driver.create_publisher(WrenchStamped, "elsewhere/external_wrench", qos.STATE)
    quiet_since = time.monotonic()
    spin(ex, lambda: time.monotonic() - quiet_since > FAST["watchdog_timeout_s"] + 0.5, 10.0, "the wrench to age")
    driver.trajectory_msgs.clear()
    response = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg())), timeout_s=20.0)
    reason = response.result.failure_reason
    assert response.status == 6 and "no external wrench" in reason and "contact guard would be blind" in reason
    # which topic, and what the graph shows about it (issue 46): here nobody publishes it any more
    assert "no message on /franka_robot_state_broadcaster/external_wrench_in_base_frame" in reason
    assert "no publisher on the graph" in reason
    assert driver.trajectory_msgs == []                # refused before any motion


def test_joint_states_without_velocities_get_them_from_the_positions(rclpy_context):
    """A driver that publishes positions only: zeros would make a moving arm read as at rest."""
    from sensor_msgs.msg import JointState

    from defgg_ros.constants import PANDA_READY_Q_RAD

    node = ExecutorNode(context=rclpy_context)
    try:
        q = np.array(PANDA_READY_Q_RAD)
        for k, t_ns in enumerate((1_000_000_000, 1_010_000_000)):
            msg = JointState(name=list(topics.robot_names()["joints"]), position=(q + 0.002 * k).tolist())
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
            node._on_joint_state(msg)
            if k == 0:   # one message: not known to be still
                assert np.all(np.isnan(node._last_state[0].qd_radps))
        np.testing.assert_allclose(node._last_state[0].qd_radps, 0.2, rtol=1e-6)   # 2 mrad in 10 ms
    finally:
        node.destroy_node()


def test_a_pick_against_a_driver_without_velocities_and_with_position_noise(executor_cell, spin):
    # Every arrival waits for rest, and without velocities the executor estimates them from positions: 2e-5 rad of
    # noise differenced over one 10 ms period would already read as ~0.003 rad/s, at 1 kHz as ~0.03 (over the
    # 0.02 rad/s rest threshold); the estimate uses a baseline of at least 5 ms (control/velocity_estimate.py).
    ex, node, client, start_driver = executor_cell
    start_driver(object_width_m=0.04, publish_velocities=False, position_noise_rad=2e-5)
    wait_driver_ready(ex, spin, node)
    response = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg())))
    assert response.result.success, response.result.failure_reason



def test_a_robot_clock_that_jumps_back_aborts_the_goal(rclpy_context, spin):
    """A restarted simulator starts its /clock at 0 again while a goal runs: the goal is aborted at once, naming
    the jump (it waited until the clock came back to where it was: 300 s unanswered in the safety soak; issue 48)."""
    from builtin_interfaces.msg import Time
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock
    from support.executor_cell import InTestDriver

    from defgg_ros.ros.action import ActionClient, destroy_actions
    from defgg_ros.ros.executor import ThreadedExecutor

    ex = ThreadedExecutor(num_threads=8, context=rclpy_context)
    clock_node = Node("test_sim_clock", context=rclpy_context)
    publisher = clock_node.create_publisher(Clock, "/clock", 10)
    sim = {"s": 1000.0}

    def tick():
        sim["s"] += 0.01
        publisher.publish(Clock(clock=Time(sec=int(sim["s"]), nanosec=int(sim["s"] % 1 * 1e9))))

    clock_node.create_timer(0.01, tick)
    driver = InTestDriver(rclpy_context, object_width_m=0.04)
    node = ExecutorNode(context=rclpy_context, parameter_overrides=[
        Parameter(k, value=v) for k, v in FAST.items()] + [Parameter("use_sim_time", value=True)])
    client_node = Node("clock_jump_client", context=rclpy_context)
    client = ActionClient(client_node, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
    for n in (clock_node, driver, node, client_node):
        ex.add_node(n)
    try:
        wait_driver_ready(ex, spin, node)
        spin(ex, lambda: node.get_clock().now().nanoseconds > 900e9, 10.0, "the executor on the test's /clock")
        progress = []
        handle = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()), feedback=lambda f: progress.append(
            f.feedback.phase_progress))
        # The driver must hold the pick's first trajectory before the count: on CI the executor's feedback said
        # 0.11 of the way while the driver had not yet run the goal it accepted, and that trajectory arrived after
        # the count, as if sent after the restart.
        spin(ex, lambda: driver.trajectory_msgs and progress and progress[-1] > 0.1, 20.0, "the arm moving")
        sent_before = len(driver.trajectory_msgs)
        sim["s"] = 5.0   # the simulator restarted
        response = result_of(ex, spin, handle, timeout_s=10.0)
        assert response.status == 6 and "robot clock jumped back" in response.result.failure_reason, \
            response.result.failure_reason
        # No hold at the position measured before the restart: the new controller holds its own state, and a
        # hold there sent the restarted simulated arm back to the old pose at 30 rad/s (safety soak).
        assert len(driver.trajectory_msgs) == sent_before, driver.trajectory_msgs[sent_before:]
    finally:
        for n in list(ex.get_nodes()):
            ex.remove_node(n)
            destroy_actions(n)
            n.destroy_node()
        ex.shutdown(timeout_sec=2.0)
