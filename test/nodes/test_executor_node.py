"""executor_node over real DDS against a small in-test driver node.

The driver here is a real rclpy node (not a mock of the executor): it
publishes /joint_states by following the commanded JointTrajectory in wall
time, serves the two gripper actions (fingers move at the commanded speed and
stop on an object of a given width) and publishes an external wrench that
rises when the TCP goes below a contact height. Killing it = destroying it.
"""
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import rclpy
from defgg_interfaces.action import GripperGrasp, GripperMove, PickAndPlace
from defgg_interfaces.msg import Grasp
from executor_support import send_goal
from geometry_msgs.msg import WrenchStamped
from rclpy.action import ActionServer
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from defgg_ros import topics
from defgg_ros.constants import PANDA_FINGER_JOINT_NAMES, PANDA_JOINT_NAMES, PANDA_READY_Q_RAD
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.poses import matrix_to_quaternion, top_down_pose
from defgg_ros.grasping.geometry import tcp_height_m
from defgg_ros.nodes import qos
from defgg_ros.nodes.executor_node import PARAMETERS, ExecutorNode
from defgg_ros.ros_action import ActionClient, destroy_actions
from defgg_ros.ros_executor import ThreadedExecutor

KIN = PandaKinematics()
DRIVER_PERIOD_S = 0.01
CONTACT_STIFFNESS_N_PER_M = 5000.0
GRASP_XYZ = (0.5, 0.05, 0.03)
FAST = {  # quicker motions than the defaults so a full run takes a few seconds
    "limits_scale": 1.0, "line_speed_mps": 0.25, "descent_speed_mps": 0.05, "lift_height_m": 0.08,
    # 1 s: with 0.5 s a loaded 2-core machine once stalled the in-test driver's 100 Hz joint states
    # for 0.7 s mid-pick ("driver silent").
    "place_approach_height_m": 0.06, "watchdog_timeout_s": 1.0, "server_wait_s": 10.0,
}


class InTestDriver(Node):
    def __init__(self, context, object_width_m=0.04, contact_height_m=-1.0, q0=PANDA_READY_Q_RAD):
        super().__init__("in_test_driver", context=context)
        self.object_width_m, self.contact_height_m = object_width_m, contact_height_m
        self.kin = PandaKinematics()  # its own: one pinocchio Data is not for sharing across threads
        self.q, self.qd = np.array(q0, dtype=float), np.zeros(7)
        self.width_m = 0.0
        self.points, self.started_s = None, 0.0
        self.gripper = None  # (target_width, speed, future)
        self.trajectories_received = 0
        group = ReentrantCallbackGroup()
        self.joint_pub = self.create_publisher(JointState, topics.JOINT_STATES, qos.STATE)
        self.wrench_pub = self.create_publisher(WrenchStamped, topics.EXTERNAL_WRENCH, qos.STATE)
        self.create_subscription(JointTrajectory, topics.JOINT_TRAJECTORY, self.on_trajectory, qos.COMMAND)
        ActionServer(self, GripperMove, topics.GRIPPER_MOVE_ACTION, self.on_move, callback_group=group)
        ActionServer(self, GripperGrasp, topics.GRIPPER_GRASP_ACTION, self.on_grasp, callback_group=group)
        self.create_timer(DRIVER_PERIOD_S, self.step)

    def destroy_node(self):
        # rclpy's destroy_node leaves action servers alive (and advertised) until garbage collection:
        # a "killed" driver whose gripper actions stay in the graph is not what a dead process looks like.
        destroy_actions(self)
        super().destroy_node()

    def now_s(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def on_trajectory(self, msg):
        self.trajectories_received += 1
        if not msg.points:
            self.points = None
            self.qd = np.zeros(7)
            return
        times = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
        self.points = (times, np.array([p.positions for p in msg.points]), np.array([p.velocities for p in msg.points]))
        self.started_s = self.now_s()

    def step(self):
        if self.points is not None:
            times, q, qd = self.points
            t = min(self.now_s() - self.started_s, times[-1])
            self.q = np.array([np.interp(t, times, q[:, j]) for j in range(7)])
            self.qd = np.array([np.interp(t, times, qd[:, j]) for j in range(7)]) if t < times[-1] else np.zeros(7)
        self.step_gripper()
        stamp = self.get_clock().now().to_msg()
        state = JointState(name=list(PANDA_JOINT_NAMES) + list(PANDA_FINGER_JOINT_NAMES))
        state.header.stamp = stamp
        state.position = self.q.tolist() + [self.width_m / 2] * 2
        state.velocity = self.qd.tolist() + [0.0, 0.0]
        state.effort = [0.0] * 9
        self.joint_pub.publish(state)
        wrench = WrenchStamped()
        wrench.header.stamp, wrench.header.frame_id = stamp, topics.BASE_FRAME
        wrench.wrench.force.z = CONTACT_STIFFNESS_N_PER_M * max(0.0, self.contact_height_m - self.kin.fk(self.q)[2, 3])
        self.wrench_pub.publish(wrench)

    def step_gripper(self):
        if self.gripper is None:
            return
        target, speed, future = self.gripper
        step = speed * DRIVER_PERIOD_S
        self.width_m = target if abs(target - self.width_m) <= step else self.width_m + math.copysign(
            step, target - self.width_m)
        if self.width_m == target:
            self.gripper = None
            future.set_result(self.width_m)

    async def on_move(self, goal_handle):
        future = Future()
        self.gripper = (goal_handle.request.width, goal_handle.request.speed, future)
        width = await future
        goal_handle.succeed()
        return GripperMove.Result(success=True, width=width)

    async def on_grasp(self, goal_handle):
        future = Future()
        self.gripper = (self.object_width_m or 0.0, goal_handle.request.speed, future)
        width = await future
        request = goal_handle.request
        ok = request.width - request.epsilon_inner <= width <= request.width + request.epsilon_outer
        goal_handle.succeed()
        return GripperGrasp.Result(success=ok, width=width, error="" if ok else "fingers stopped outside epsilon")


def grasp_msg(xyz=GRASP_XYZ, yaw=0.3, width_m=0.05, modulus_pa=2e9):
    msg = Grasp()
    msg.pose_base.header.frame_id = topics.BASE_FRAME
    pose = msg.pose_base.pose
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in xyz)
    qx, qy, qz, qw = matrix_to_quaternion(top_down_pose(xyz, yaw)[:3, :3])
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = qx, qy, qz, qw
    msg.width_m, msg.youngs_modulus_pa = width_m, modulus_pa
    return msg


@pytest.fixture
def cell(rclpy_context):
    """(executor, executor_node, action client, driver factory); everything destroyed after."""
    ex = ThreadedExecutor(num_threads=8, context=rclpy_context)
    node = ExecutorNode(context=rclpy_context,
                        parameter_overrides=[Parameter(k, value=v) for k, v in FAST.items()])
    client_node = Node("executor_test_client", context=rclpy_context)
    client = ActionClient(client_node, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
    ex.add_node(node)
    ex.add_node(client_node)

    children = []
    trajectories_seen = []   # what the executor sends, seen from the test (the driver process is not ours)
    client_node.create_subscription(JointTrajectory, topics.JOINT_TRAJECTORY, trajectories_seen.append, qos.COMMAND)

    def start_driver(own_process=False, **kwargs):
        """A driver in the test's executor, or (own_process) a real driver process (this file run as
        a script), like a restarted driver. (A second rclpy context inside this long-lived pytest
        process was sometimes not discovered by the executor's action clients within 60 s.)"""
        if not own_process:
            driver = InTestDriver(rclpy_context, **kwargs)
            ex.add_node(driver)
            return driver
        assert not kwargs, "the driver process takes the default arguments"
        trajectories_seen.clear()
        child = subprocess.Popen([sys.executable, __file__], env=dict(os.environ))
        children.append(child)
        return child

    start_driver.trajectories_seen = trajectories_seen

    yield ex, node, client, start_driver
    for n in list(ex.get_nodes()):
        ex.remove_node(n)
        destroy_actions(n)
        n.destroy_node()
    ex.shutdown(timeout_sec=2.0)
    for child in children:
        child.terminate()
        child.wait(timeout=10)


def send(ex, client, spin, goal, feedback=None):
    return send_goal(ex, spin, client, goal, feedback, timeout_s=5.0)


def result_of(ex, spin, handle, timeout_s=30.0):
    return spin(ex, handle.get_result_async(), timeout_s, "pick-and-place result")


def wait_driver_ready(ex, spin, node):
    spin(ex, lambda: node._last_state is not None, 5.0, "joint states at the executor")


def test_pick_and_place_with_contact_on_the_way_down(cell, spin):
    ex, node, client, start_driver = cell
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
    # The arm ends above the configured bin, fingers open.
    tcp = KIN.fk(driver.q)[:3, 3]
    assert tcp[:2] == pytest.approx([0.35, -0.45], abs=2e-3)
    assert driver.width_m > 0.04


def test_busy_goal_is_rejected_and_cancel_stops_the_arm(cell, spin):
    ex, node, client, start_driver = cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    first = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    assert first.accepted
    second = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    assert not second.accepted
    spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 10.0, "the arm moving towards the pre-grasp")
    spin(ex, first.cancel_goal_async(), 5.0, "cancel response")
    response = result_of(ex, spin, first)
    assert response.status == 5  # GoalStatus.STATUS_CANCELED
    assert "canceled during pre_grasp" in response.result.failure_reason
    assert np.max(np.abs(driver.qd)) < 0.02
    assert not KIN.fk(driver.q)[:3, 3] == pytest.approx(KIN.fk(node._kin.q_ready_rad)[:3, 3], abs=1e-3)


def test_driver_killed_mid_trajectory_aborts_then_serves_again(cell, spin):
    ex, node, client, start_driver = cell
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
    spin(ex, lambda: node._move_client.server_is_ready() and node._grasp_client.server_is_ready(), 60.0,
         "the restarted driver's gripper actions (discovery)")
    again = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    assert again.accepted
    spin(ex, lambda: start_driver.trajectories_seen, 5.0, "a trajectory for the new goal")
    spin(ex, again.cancel_goal_async(), 5.0, "cancel response")
    assert result_of(ex, spin, again).status == 5


def test_bad_goals_are_aborted_with_a_reason_and_the_node_keeps_serving(cell, spin):
    ex, node, client, start_driver = cell
    start_driver()
    wait_driver_ready(ex, spin, node)
    node.set_parameters([Parameter("server_wait_s", value=1.0)])  # the grasp service never comes
    nan_grasp = grasp_msg()
    nan_grasp.pose_base.pose.position.x = float("nan")
    cases = [
        (PickAndPlace.Goal(grasp=nan_grasp), "bad grasp pose"),
        (PickAndPlace.Goal(grasp=grasp_msg(xyz=(1.3, 0.0, 0.05))), "grasp outside the workspace"),
        (PickAndPlace.Goal(grasp=grasp_msg(width_m=0.2)), "maximum opening"),
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


def test_shipped_yaml_sets_every_parameter_and_loads(rclpy_context):
    from pathlib import Path

    import yaml

    path = Path(__file__).resolve().parents[2] / "sim_bringup" / "config" / "executor_node.yaml"
    shipped = yaml.safe_load(path.read_text())["executor_node"]["ros__parameters"]
    assert set(shipped) == set(PARAMETERS)
    node = ExecutorNode(context=rclpy_context, cli_args=["--ros-args", "--params-file", str(path)])
    try:
        for name, value in shipped.items():
            assert node.get_parameter(name).value == value
    finally:
        node.destroy_node()


def test_invalid_parameters_refuse_to_start(rclpy_context):
    with pytest.raises(ValueError, match="limits_scale"):
        ExecutorNode(context=rclpy_context, parameter_overrides=[Parameter("limits_scale", value=1.5)])
    with pytest.raises(ValueError, match="grasp_height_rule"):
        ExecutorNode(context=rclpy_context, parameter_overrides=[Parameter("grasp_height_rule", value="middle")])


def _run_driver_process():
    """The restarted driver of test_driver_killed_mid_trajectory_aborts_then_serves_again."""
    rclpy.init()
    driver = InTestDriver(None)
    executor = ThreadedExecutor(num_threads=4)
    executor.add_node(driver)
    try:
        executor.spin()
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    import signal

    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    _run_driver_process()
