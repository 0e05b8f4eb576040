"""executor_node against the real fake_panda_driver (PyBullet) over DDS, on sim time.

A rigid 5 cm box (sim_bringup/scenes/rigid_box.yaml) is picked and placed in
the bin; a cancel during the descent leaves the arm stopped above the grasp;
a driver that dies mid-trajectory aborts the goal within the watchdog time,
and a restarted driver is served again.
"""
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.msg import Grasp
from geometry_msgs.msg import PoseArray
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from support.executor_goals import send_goal, stop_driver_processes

from defgg_ros.constants import OBJECT_DENSITY_KG_M3, PANDA_READY_Q_RAD
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.poses import matrix_to_quaternion, top_down_pose
from defgg_ros.grip_force import LabelGripRule
from defgg_ros.nodes.executor_node import ExecutorNode
from defgg_ros.ros import qos, topics
from defgg_ros.ros.action import ActionClient
from defgg_ros.ros.executor import ThreadedExecutor

SCENE = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes" / "rigid_box.yaml"
BOX_XY_M, BOX_YAW_RAD, BOX_SIZE_M = (0.5, 0.05), 0.3, 0.05   # as in rigid_box.yaml
BIN_XY_M, BIN_INNER_M = (0.35, -0.45), 0.32   # the scenes' bin (test/control/test_bin_slots.py)
WATCHDOG_S = 2.0
TIMEOUT_S = 90.0
KIN = PandaKinematics()


def box_grasp() -> Grasp:
    """Top-down grasp across the box on its top face (as Def-GG-CNN gives it), fingers along a face normal."""
    xyz = (BOX_XY_M[0], BOX_XY_M[1], BOX_SIZE_M)
    msg = Grasp()
    msg.pose_base.header.frame_id = topics.BASE_FRAME
    pose = msg.pose_base.pose
    pose.position.x, pose.position.y, pose.position.z = xyz
    qx, qy, qz, qw = matrix_to_quaternion(top_down_pose(xyz, BOX_YAW_RAD)[:3, :3])
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = qx, qy, qz, qw
    msg.width_m, msg.youngs_modulus_pa = 0.07, 2e9
    return msg


@pytest.fixture
def cell(rclpy_context):
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    ex = ThreadedExecutor(num_threads=8, context=rclpy_context)
    drivers, processes = [], []

    def start_driver(own_process=False):
        """The driver in the test's executor, or (own_process) in its own context + executor
        thread: a separate DDS participant, like a restarted driver process."""
        context = rclpy_context
        if own_process:
            context = Context()
            rclpy.init(context=context)
        driver = FakePandaDriver(context=context, parameter_overrides=[
            Parameter("scene_file", value=str(SCENE)),
            # Real time, as deployed (the default). Unthrottled, the simulator ran ahead of this
            # process's busy executor: trajectories started late in sim time ("arm did not reach the
            # descend target") and a cancel landed after the whole descent ("canceled during close").
            # No camera needed here; a render holds the sim thread for 0.1-1 s.
            Parameter("depth_rate_hz", value=0.01)])
        drivers.append(driver)
        if not own_process:
            ex.add_node(driver)
            return driver
        own = ThreadedExecutor(num_threads=4, context=context)
        own.add_node(driver)
        thread = threading.Thread(target=own.spin, daemon=True)
        thread.start()
        processes.append((context, own, driver, thread))
        return driver

    def kill_driver(driver):
        driver.shutdown()
        ex.remove_node(driver)
        driver.destroy_node()
        drivers.remove(driver)

    start_driver()
    executor_node = ExecutorNode(context=rclpy_context, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("watchdog_timeout_s", value=WATCHDOG_S),
        Parameter("server_wait_s", value=10.0),
        # A slow guarded descent (43 mm in ~4 s of sim time) leaves the cancel test time to land
        # mid-descent even when the simulator runs faster than real time on a busy machine.
        Parameter("descent_speed_mps", value=0.01)])
    probe = Node("executor_e2e_probe", context=rclpy_context)
    seen = {"joints": [], "poses": []}
    probe.create_subscription(JointState, topics.JOINT_STATES, seen["joints"].append, qos.STATE)
    probe.create_subscription(PoseArray, "/fake_panda/object_poses", seen["poses"].append, qos.STATE)
    client = ActionClient(probe, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
    ex.add_node(executor_node)
    ex.add_node(probe)
    yield ex, executor_node, client, seen, start_driver, kill_driver
    for driver in list(drivers):
        driver.shutdown()
    for node in list(ex.get_nodes()):
        ex.remove_node(node)
        node.destroy_node()
    ex.shutdown(timeout_sec=2.0)
    stop_driver_processes(processes)


def send(ex, spin, client, goal, feedback=None):
    return send_goal(ex, spin, client, goal, feedback, timeout_s=10.0)


def fresh_state(ex, spin, executor_node):
    before = executor_node._last_state[1] if executor_node._last_state else -1.0
    spin(ex, lambda: executor_node._last_state is not None and executor_node._last_state[1] > before,
         TIMEOUT_S, "joint states from the driver")


# The box (125 g) as a defgraspsim model's grasp carries it: FOS(2e9) * m * g / 0.7 / 2 a finger.
LABEL_FINGER_FORCE_N = LabelGripRule("defgraspsim", 0.7).finger_force_n(2e9, BOX_SIZE_M ** 3 * OBJECT_DENSITY_KG_M3)


@pytest.mark.parametrize("finger_force_n", [0.0, LABEL_FINGER_FORCE_N], ids=["modulus_rule", "labels_force"])
def test_pick_of_a_rigid_box_into_the_bin(cell, spin, finger_force_n):
    """With the executor's modulus rule (4.5 N a finger at 2e9 Pa) and with the force a defgraspsim model's grasp
    carries (1.69 N): gravity on, the transfer's accelerations, the box still ends in the bin."""
    ex, executor_node, client, seen, _, _ = cell
    fresh_state(ex, spin, executor_node)
    grasp = box_grasp()
    grasp.finger_force_n = finger_force_n
    handle = send(ex, spin, client, PickAndPlace.Goal(grasp=grasp))
    assert handle.accepted
    result = spin(ex, handle.get_result_async(), TIMEOUT_S, "pick-and-place result").result
    assert result.success, result.failure_reason
    assert result.gripper_force_n == pytest.approx(finger_force_n or 4.5)
    assert result.phase_reached == "done"
    assert result.held_after_lift and result.held_after_transfer
    # The fingers stopped on the 5 cm box (a little less: contact penetration).
    assert result.gripper_width_closed_m == pytest.approx(BOX_SIZE_M, abs=0.005)
    # The box ends up inside the bin, resting on its floor.
    spin(ex, lambda: seen["poses"] and abs(seen["poses"][-1].poses[0].position.z - BOX_SIZE_M / 2) < 0.01,
         TIMEOUT_S, "the box to come to rest")
    box = seen["poses"][-1].poses[0].position
    assert abs(box.x - BIN_XY_M[0]) < BIN_INNER_M / 2 and abs(box.y - BIN_XY_M[1]) < BIN_INNER_M / 2


def test_cancel_mid_descent_stops_the_arm(cell, spin):
    ex, executor_node, client, seen, _, _ = cell
    fresh_state(ex, spin, executor_node)
    feedback = []
    handle = send(ex, spin, client, PickAndPlace.Goal(grasp=box_grasp()),
                  feedback=lambda f: feedback.append(f.feedback))
    pregrasp_z = BOX_SIZE_M + 0.025

    def descending():  # judged from the arm itself: commands reach a busy simulator late
        if not seen["joints"]:   # best effort depth 1: none may have arrived yet after fresh_state
            return False
        tcp_z = KIN.fk(np.array(seen["joints"][-1].position[:7]))[2, 3]
        return feedback and feedback[-1].phase == "descend" and tcp_z < pregrasp_z - 0.005

    spin(ex, descending, TIMEOUT_S, "the descent to be under way")
    canceled_at = len(seen["joints"])
    spin(ex, handle.cancel_goal_async(), 10.0, "cancel response")
    response = spin(ex, handle.get_result_async(), TIMEOUT_S, "canceled result")
    assert response.status == 5  # STATUS_CANCELED
    assert "canceled during descend" in response.result.failure_reason
    # Then it recovered (issue 27.1): back at the observation pose, at rest, and the result says so.
    assert response.result.arm_state == "observation_pose", response.result.recovery
    assert "moved to the observation pose" in response.result.recovery
    # Reported at rest, so every joint state from the result on shows the arm still (issue 27.4).
    after_result = len(seen["joints"])
    spin(ex, lambda: len(seen["joints"]) > after_result + 20, 10.0, "joint states after the result")
    for state in seen["joints"][after_result:]:
        assert np.max(np.abs(np.array(state.position[:7]) - PANDA_READY_Q_RAD)) < 0.05
        assert np.max(np.abs(state.velocity[:7])) < 0.02, state.velocity
    # Where the stop brought it to rest first, before the recovery moved it.
    last = next(j for j in seen["joints"][canceled_at:] if np.max(np.abs(j.velocity[:7])) < 0.02)
    # Stopped below the pre-grasp (25 mm above the top face) and no lower than the grasp (18 mm below
    # it): on a loaded machine the cancel may land after the descent reached the grasp pose, so the
    # grasp height itself is allowed. What must not happen is what follows the descent: close or lift.
    tcp_z = KIN.fk(np.array(last.position[:7]))[2, 3]
    assert BOX_SIZE_M - 0.018 - 0.002 < tcp_z < pregrasp_z - 0.005
    assert sum(last.position[7:9]) > BOX_SIZE_M + 0.01, "the gripper closed after the cancel"


def test_driver_killed_mid_trajectory_aborts_then_serves_again(cell, spin):
    ex, executor_node, client, seen, start_driver, kill_driver = cell
    fresh_state(ex, spin, executor_node)
    feedback = []
    handle = send(ex, spin, client, PickAndPlace.Goal(grasp=box_grasp()),
                  feedback=lambda f: feedback.append(f.feedback))
    spin(ex, lambda: feedback and feedback[-1].phase == "pre_grasp" and feedback[-1].phase_progress > 0.2,
         TIMEOUT_S, "the arm moving to the pre-grasp")
    kill_driver(next(n for n in ex.get_nodes() if n.get_name() == "fake_panda_driver"))
    response = spin(ex, handle.get_result_async(), WATCHDOG_S + 3.0, "abort after the driver died")
    assert response.status == 6  # STATUS_ABORTED
    assert "driver silent" in response.result.failure_reason
    start_driver(own_process=True)
    fresh_state(ex, spin, executor_node)
    spin(ex, lambda: executor_node._move_client.server_is_ready() and executor_node._grasp_client.server_is_ready(),
         20.0, "the restarted driver's gripper actions (discovery)")
    feedback.clear()
    again = send(ex, spin, client, PickAndPlace.Goal(grasp=box_grasp()), feedback=lambda f: feedback.append(f.feedback))
    assert again.accepted
    spin(ex, lambda: feedback and feedback[-1].phase_progress > 0.1, TIMEOUT_S, "the new goal moving the arm")
    spin(ex, again.cancel_goal_async(), 10.0, "cancel response")
    assert spin(ex, again.get_result_async(), TIMEOUT_S, "canceled result").status == 5



@pytest.mark.parametrize("hold", ["accepted", "refused"])
def test_a_stop_while_a_goal_is_in_flight_preempts_it_and_cancels_only_if_refused(cell, spin, hold):
    """The exit stop (a hold) sent while the last trajectory goal's acceptance is still on its way: goals from one
    client reach the joint_trajectory_controller in the order sent, so the hold preempts that goal there. The
    executor canceled the late goal once accepted, and a cancel that reached the controller before the hold made it
    hold the measured position at once; the hold behind it then set the arm moving again (stop, then go). No cancel
    now. A hold the controller refuses (here: unknown joint names) leaves the cancel as the way to stop that goal.
    Either way the arm ends at rest where it was."""
    from defgg_ros.control.trajectories import arm_limits, plan_joint_motion
    from defgg_ros.nodes.executor_messages import hold_trajectory_msg
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    ex, executor_node, _, _, _, _ = cell
    driver = next(n for n in ex.get_nodes() if isinstance(n, FakePandaDriver))
    spin(ex, executor_node._arm_client.server_is_ready, TIMEOUT_S, "the arm's trajectory action")
    fresh_state(ex, spin, executor_node)
    q0 = executor_node._last_state[0].q_rad.copy()
    if hold == "refused":
        executor_node._stopping_hold = lambda: hold_trajectory_msg(q0, "base", [f"joint_{i}" for i in range(7)])
    with executor_node._lock:    # as the exit stop can meet a goal the sequence has just sent
        executor_node._send_arm(plan_joint_motion(q0, q0 + np.array([0.3, 0, 0, 0, 0, 0, 0]),
                                                  arm_limits("panda", 0.1)))
        executor_node._hold_arm()
    answered = lambda: getattr(executor_node, "_hold_answer", "") != "pending"   # noqa: E731 - (old code: no such state)
    spin(ex, lambda: executor_node._arm_goals_unanswered == 0 and answered(), TIMEOUT_S, "both goals answered")
    fresh_state(ex, spin, executor_node)
    spin(ex, lambda: np.abs(executor_node._last_state[0].qd_radps).max() < 0.01, TIMEOUT_S, "the arm at rest")
    settled_s = time.monotonic() + 1.0   # a cancel sent on a goal response reaches the controller within this
    spin(ex, lambda: time.monotonic() > settled_s, 10.0, "a second more")
    assert driver.arm.cancel_requests == (hold == "refused"), "a cancel went out beside an accepted hold"
    assert executor_node._hold_answer == hold
    q = executor_node._last_state[0].q_rad
    # An accepted hold preempts the goal at the controller at once. A refused one stops it only by the cancel sent
    # after the refusal, two round trips later: under the full suite's load the arm had moved 0.090 rad by then
    # (2 of 5 runs over the 0.03 rad bound both cases had, 2026-12-03); a stop that never came leaves all 0.3 rad.
    bound_rad = 0.03 if hold == "accepted" else 0.15
    assert np.abs(q - q0).max() < bound_rad, f"the arm moved {np.abs(q - q0).max():.3f} rad (the move: 0.3 rad)"


def test_a_reflex_in_the_descent_ends_the_pick_as_a_robot_error_and_only_the_recovery_brings_the_cell_back(
        cell, spin):
    """A descent onto the box's top with the executor's contact guard off (contact_force_threshold_n 1000 N) and the
    driver's reflex at 15 N: franka_ros2 deactivates the arm's controllers, the pick ends at once as a robot error
    with no stop and no recovery sent (each would be refused), a new goal is refused until a person recovers the
    robot, and then the cell picks again."""
    from rclpy.parameter import Parameter as RosParameter
    from support.robot_recovery import RecoveryClient

    ex, executor_node, client, _, _, _ = cell
    driver = next(node for node in ex.get_nodes() if node.get_name() == "fake_panda_driver")
    driver.controller_manager.reflex_force_n = 15.0
    executor_node.set_parameters([RosParameter("contact_force_threshold_n", value=1000.0)])
    recovery = RecoveryClient(executor_node, ex, spin)
    fresh_state(ex, spin, executor_node)
    onto_the_top = box_grasp()
    onto_the_top.width_m = 0.01   # the fingers open to 1 cm above a 5 cm box: they land on its top face

    result = spin(ex, send(ex, spin, client, PickAndPlace.Goal(grasp=onto_the_top)).get_result_async(), TIMEOUT_S,
                  "the pick's result").result
    assert driver.controller_manager.reflexes == 1
    assert not result.success and result.failure_reason.startswith("robot error"), result.failure_reason
    assert "error_recovery" in result.failure_reason   # it says how to recover
    assert (result.phase_reached, result.arm_state, result.recovery) == ("descend", "robot_error", "")
    assert driver.arm.rejected_while_inactive == 0, "the executor sent goals to the deactivated controller"

    refused = spin(ex, send(ex, spin, client, PickAndPlace.Goal(grasp=box_grasp())).get_result_async(), TIMEOUT_S,
                   "the refusal").result
    assert not refused.success and "recover the robot first" in refused.failure_reason, refused.failure_reason
    assert refused.arm_state == "robot_error"
    assert driver.arm.rejected_while_inactive == 0

    recovery.recover()   # the controller holds where the arm is: pressed on the box, it springs back a little
    executor_node.set_parameters([RosParameter("contact_force_threshold_n", value=10.0)])
    fresh_state(ex, spin, executor_node)
    spin(ex, lambda: np.abs(executor_node._last_state[0].qd_radps).max() < 0.005, TIMEOUT_S, "the arm at rest")
    again = spin(ex, send(ex, spin, client, PickAndPlace.Goal(grasp=box_grasp())).get_result_async(), TIMEOUT_S,
                 "the pick after the recovery").result
    assert again.success, again.failure_reason
    assert driver.controller_manager.reflexes == 1
