"""The executor node's test cell: a small in-test driver node and a fixture that wires it to a real
ExecutorNode over real DDS (used by test/nodes/test_executor_node.py and test/reliability/test_pick_faults.py).

The driver is a real rclpy node (not a mock of the executor) serving the real cell's contract: it
publishes joint_states by following the trajectory of the latest control_msgs FollowJointTrajectory
goal in wall time (a newer goal replaces it, a cancel holds the arm), serves franka_ros2's gripper
actions franka_msgs Move and Grasp (fingers move at the commanded speed and stop on an object of a
given width) and publishes an external wrench that rises when the TCP goes below a contact height.
Every trajectory goal it receives is kept in `trajectory_msgs` (what the executor put on the wire).
Killing it = destroying it. Run as `python -m support.executor_cell` (from test/) it is the restarted
driver process.
"""
import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from control_msgs.action import FollowJointTrajectory
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.msg import Grasp
from franka_msgs.action import Grasp as GripperGrasp
from franka_msgs.action import Move as GripperMove
from geometry_msgs.msg import WrenchStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import JointState

from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.poses import matrix_to_quaternion, top_down_pose
from defgg_ros.nodes.executor_node import ExecutorNode
from defgg_ros.ros import qos, topics
from defgg_ros.ros.action import ActionClient, destroy_actions
from defgg_ros.ros.executor import ThreadedExecutor
from support.executor_goals import send_goal

TEST_ROOT = Path(__file__).resolve().parents[1]

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

NAMES = topics.robot_names()   # the default robot type's (fer)


class InTestDriver(Node):
    def __init__(self, context, object_width_m=0.04, contact_height_m=-1.0, q0=PANDA_READY_Q_RAD,
                 publish_velocities=True, position_noise_rad=0.0, states_after_s=0.0, arm_goal_answer_s=0.0):
        super().__init__("in_test_driver", context=context)
        # joint states and the wrench start this long after the action servers (a driver still coming up); a test
        # sets states_from_s (monotonic) later to silence them for a while
        self.states_from_s = time.monotonic() + states_after_s
        self.publish_velocities, self.position_noise_rad = publish_velocities, position_noise_rad
        self.arm_goal_answer_s = arm_goal_answer_s   # a trajectory goal is answered this long after it arrives
        self.last_state_stamp_s = float("nan")
        self._rng = np.random.default_rng(0)
        self.object_width_m, self.contact_height_m = object_width_m, contact_height_m
        self.kin = PandaKinematics()  # its own: one pinocchio Data is not for sharing across threads
        self.q, self.qd = np.array(q0, dtype=float), np.zeros(7)
        self.width_m = 0.0
        self.points, self.started_s = None, 0.0
        self.gripper = None  # (target_width, speed, future)
        self.trajectory_msgs = []  # every trajectory goal received, in order
        self.arm_goal = None       # (goal handle, Future of its outcome) of the running trajectory goal
        group = ReentrantCallbackGroup()
        self.joint_pub = self.create_publisher(JointState, topics.JOINT_STATES, qos.STATE)
        # as franka_robot_state_broadcaster (>= 3.3.0) offers it: best effort, depth 1
        self.wrench_pub = self.create_publisher(WrenchStamped, topics.EXTERNAL_WRENCH, qos.FRANKA_CONVENIENCE)
        ActionServer(self, FollowJointTrajectory, topics.ARM_TRAJECTORY_ACTION, self.on_follow, callback_group=group,
                     goal_callback=self._answer_arm_goal, cancel_callback=lambda _goal: CancelResponse.ACCEPT)
        ActionServer(self, GripperMove, topics.GRIPPER_MOVE_ACTION, self.on_move, callback_group=group)
        ActionServer(self, GripperGrasp, topics.GRIPPER_GRASP_ACTION, self.on_grasp, callback_group=group)
        self.create_timer(DRIVER_PERIOD_S, self.step)

    def destroy_node(self):
        # rclpy's destroy_node leaves action servers alive (and advertised) until garbage collection:
        # a "killed" driver whose gripper actions stay in the graph is not what a dead process looks like.
        destroy_actions(self)
        super().destroy_node()

    def _answer_arm_goal(self, _goal) -> GoalResponse:
        time.sleep(self.arm_goal_answer_s)   # a loaded machine: the goal's answer (and its start) come late
        return GoalResponse.ACCEPT

    def now_s(self):
        return self.get_clock().now().nanoseconds * 1e-9

    async def on_follow(self, goal_handle):
        """A joint_trajectory_controller's goal: replaces the running one; canceled = hold where the arm is."""
        msg = goal_handle.request.trajectory
        self.trajectory_msgs.append(msg)
        result = FollowJointTrajectory.Result()
        if list(msg.joint_names) != list(NAMES["joints"]) or not msg.points:
            result.error_code, result.error_string = FollowJointTrajectory.Result.INVALID_JOINTS, "bad joints"
            goal_handle.abort()
            return result
        if self.arm_goal is not None:
            self.arm_goal[1].set_result("replaced")
        future = Future()
        self.arm_goal = (goal_handle, future)
        times = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
        self.points = (times, np.array([p.positions for p in msg.points]), np.array([p.velocities for p in msg.points]))
        self.started_s = self.now_s()
        outcome = await future
        if outcome == "done":
            goal_handle.succeed()
        elif outcome == "canceled":
            goal_handle.canceled()
        else:
            result.error_string = "replaced by a newer goal"
            goal_handle.abort()
        return result

    def step_arm(self):
        if self.arm_goal is not None and self.arm_goal[0].is_cancel_requested:
            self.points, self.qd = None, np.zeros(7)  # hold
            self.arm_goal[1].set_result("canceled")
            self.arm_goal = None
        if self.points is not None:
            times, q, qd = self.points
            t = min(self.now_s() - self.started_s, times[-1])
            self.q = np.array([np.interp(t, times, q[:, j]) for j in range(7)])
            self.qd = np.array([np.interp(t, times, qd[:, j]) for j in range(7)]) if t < times[-1] else np.zeros(7)
            if t >= times[-1] and self.arm_goal is not None:
                self.arm_goal[1].set_result("done")
                self.arm_goal = None

    def step(self):
        self.step_arm()
        self.step_gripper()
        if time.monotonic() < self.states_from_s:
            return
        stamp = self.get_clock().now().to_msg()
        state = JointState(name=list(NAMES["joints"]) + list(NAMES["fingers"]))
        state.header.stamp = stamp
        self.last_state_stamp_s = stamp.sec + 1e-9 * stamp.nanosec
        noise = self.position_noise_rad * self._rng.standard_normal(7)
        state.position = (self.q + noise).tolist() + [self.width_m / 2] * 2
        state.velocity = self.qd.tolist() + [0.0, 0.0] if self.publish_velocities else []
        state.effort = [0.0] * 9
        self.joint_pub.publish(state)
        wrench = WrenchStamped()
        wrench.header.stamp, wrench.header.frame_id = stamp, topics.FRANKA_STATE_FRAME   # the broadcaster's `base`
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

    def _take_gripper(self, target_width_m, speed_mps) -> Future:
        """The fingers' new command; the one it replaces ends now, preempted (as franka_gripper's and the simulated
        gripper's goals do: their result comes after the newer goal was sent)."""
        if self.gripper is not None:
            self.gripper[2].set_result(None)
        future = Future()
        self.gripper = (target_width_m, speed_mps, future)
        return future

    async def on_move(self, goal_handle):
        width = await self._take_gripper(goal_handle.request.width, goal_handle.request.speed)
        if width is None:
            goal_handle.abort()
            return GripperMove.Result(success=False, error="preempted by a newer gripper command")
        goal_handle.succeed()
        return GripperMove.Result(success=abs(width - goal_handle.request.width) < 1e-6)

    async def on_grasp(self, goal_handle):
        width = await self._take_gripper(self.object_width_m or 0.0, goal_handle.request.speed)
        if width is None:
            goal_handle.abort()
            return GripperGrasp.Result(success=False, error="preempted by a newer gripper command")
        request = goal_handle.request
        ok = request.width - request.epsilon.inner <= width <= request.width + request.epsilon.outer
        goal_handle.succeed()
        return GripperGrasp.Result(success=ok, error="" if ok else "fingers stopped outside epsilon")


def grasp_msg(xyz=GRASP_XYZ, yaw=0.3, width_m=0.05, modulus_pa=2e9, finger_force_n=0.0):
    msg = Grasp()
    msg.pose_base.header.frame_id = topics.BASE_FRAME
    pose = msg.pose_base.pose
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in xyz)
    qx, qy, qz, qw = matrix_to_quaternion(top_down_pose(xyz, yaw)[:3, :3])
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = qx, qy, qz, qw
    msg.width_m, msg.youngs_modulus_pa, msg.finger_force_n = width_m, modulus_pa, finger_force_n
    return msg


def run_cell(rclpy_context):
    """Generator behind the `executor_cell` fixture (test/conftest.py): yields (executor, executor_node,
    action client, driver factory); everything destroyed after."""
    ex = ThreadedExecutor(num_threads=8, context=rclpy_context)
    node = ExecutorNode(context=rclpy_context,
                        parameter_overrides=[Parameter(k, value=v) for k, v in FAST.items()])
    client_node = Node("executor_test_client", context=rclpy_context)
    client = ActionClient(client_node, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
    ex.add_node(node)
    ex.add_node(client_node)

    children = []

    def start_driver(own_process=False, **kwargs):
        """A driver in the test's executor, or (own_process) a real driver process (this module run
        with -m), like a restarted driver. (A second rclpy context inside this long-lived pytest
        process was sometimes not discovered by the executor's action clients within 60 s.)"""
        if not own_process:
            driver = InTestDriver(rclpy_context, **kwargs)
            ex.add_node(driver)
            return driver
        assert not kwargs, "the driver process takes the default arguments"
        child = subprocess.Popen([sys.executable, "-m", "support.executor_cell"], cwd=TEST_ROOT,
                                 env=dict(os.environ))
        children.append(child)
        return child

    try:
        yield ex, node, client, start_driver
        for n in list(ex.get_nodes()):
            ex.remove_node(n)
            destroy_actions(n)
            n.destroy_node()
        ex.shutdown(timeout_sec=2.0)
    finally:   # a failing teardown above must not leave a driver process running after the tests
        for child in children:
            child.terminate()
            try:
                child.wait(timeout=10)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()


def send(ex, client, spin, goal, feedback=None):
    return send_goal(ex, spin, client, goal, feedback, timeout_s=5.0)


def result_of(ex, spin, handle, timeout_s=30.0):
    return spin(ex, handle.get_result_async(), timeout_s, "pick-and-place result")


def wait_driver_ready(ex, spin, node):
    spin(ex, lambda: node._last_state is not None, 5.0, "joint states at the executor")


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

    def _terminate(*_):
        # Shutting rclpy down ends the spin; under load it once did not (an orphan kept running after two
        # SIGTERMs), so the process also leaves on its own 3 s later.
        fallback = threading.Timer(3.0, os._exit, (0,))
        fallback.daemon = True      # a spin that ends in time exits at once
        fallback.start()
        rclpy.try_shutdown()

    signal.signal(signal.SIGTERM, _terminate)
    _run_driver_process()
