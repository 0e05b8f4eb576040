"""The demo's ROS side: one client node that talks to the running cell.

The cell's calls (PlanGrasp, SetStiffness, PickAndPlace) go through the one cell client
(defgg_ros/ros/cell_client.py); this adds what only the simulated cell offers: the scene and
ground-truth object poses, fresh depth frames on request, direct arm and gripper moves.
Every wait spins the node's own executor in the calling thread until its answer is there
(bounded by a timeout; CellCallError says what did not answer). Spinning where the request is
sent avoids rclpy's race in which an action goal response arriving before the client registered
the request is dropped ("Ignoring unexpected goal response"), seen with a background spin thread.
"""
import json
import time

import numpy as np
import rclpy
from builtin_interfaces.msg import Duration
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.srv import PlanGrasp
from franka_msgs.action import Move
from geometry_msgs.msg import PoseArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.ros import qos, topics
from defgg_ros.ros.action import ActionClient, ResultTimeout, destroy_actions, result_of_goal
from defgg_ros.ros.cell_client import CellCallError, CellClient
from defgg_ros.ros.conversions import stamp_to_ns
from defgg_ros.ros.service import ServiceTimeout, call_idempotent

# The simulated cell runs the default robot type (fer: the Panda).
ARM_JOINTS = topics.robot_names()["joints"]


class DemoClient:
    def __init__(self, check_alive=None):
        """check_alive(): raises when a node of the cell died (the bringup's), checked while any call waits, so a
        dead executor or driver ends the wait at once instead of after its whole timeout."""
        self._check_alive = check_alive or (lambda: None)
        self._context = Context()
        rclpy.init(context=self._context)
        self.node = Node("defgg_demo", context=self._context)
        self._scene = None
        self._poses = None
        self._depth = {}            # stamp ns -> (Image, wall time received)
        self._info = {}             # stamp ns -> CameraInfo
        n = self.node
        n.create_subscription(String, topics.FAKE_SCENE, self._on_scene, qos.LATCHED)
        n.create_subscription(PoseArray, topics.FAKE_OBJECT_POSES, self._on_poses, qos.STATE)
        # Reliable: the driver publishes camera frames reliably and the demo must not lose one.
        n.create_subscription(Image, topics.DEPTH_IMAGE, self._on_depth, qos.IMAGE_PUBLISH)
        n.create_subscription(CameraInfo, topics.DEPTH_CAMERA_INFO, self._on_info, qos.IMAGE_PUBLISH)
        self.capture_client = n.create_client(Trigger, topics.FAKE_CAPTURE_SERVICE)
        self._joints = None
        n.create_subscription(JointState, topics.JOINT_STATES, self._on_joints, qos.ROBOT_STATE_READ)
        self._trajectory_pub = n.create_publisher(JointTrajectory, topics.JOINT_TRAJECTORY, qos.COMMAND)
        self.gripper_move_client = ActionClient(n, Move, topics.GRIPPER_MOVE_ACTION)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(n)
        self.cell = CellClient(n, spin_until=self._spin_until)

    # ---- subscriptions -----------------------------------------------------
    def _store(self, setter):
        setter()

    def _on_scene(self, msg):
        self._store(lambda: setattr(self, "_scene", json.loads(msg.data)))

    def _on_poses(self, msg):
        poses = [(p.position.x, p.position.y, p.position.z) for p in msg.poses]
        self._store(lambda: setattr(self, "_poses", (poses, time.monotonic())))

    def _on_joints(self, msg):
        by_name = dict(zip(msg.name, msg.position))
        if all(n in by_name for n in ARM_JOINTS):
            self._joints = (np.array([by_name[n] for n in ARM_JOINTS]), time.monotonic())

    def arm_positions(self, timeout_s=30.0) -> np.ndarray:
        asked = time.monotonic()
        self._wait(lambda: self._joints is not None and self._joints[1] > asked, timeout_s, "joint states")
        return self._joints[0].copy()

    def move_arm(self, waypoints, tolerance_rad=0.02, timeout_s=120.0) -> None:
        """Send [(time_from_start_s, q)] to the arm and wait until it is at the last q."""
        msg = JointTrajectory(joint_names=list(ARM_JOINTS))
        for t_s, q in waypoints:
            sec, nanosec = divmod(int(round(t_s * 1e9)), 1_000_000_000)
            msg.points.append(JointTrajectoryPoint(positions=[float(v) for v in q],
                                                   time_from_start=Duration(sec=sec, nanosec=nanosec)))
        self._wait(lambda: self._trajectory_pub.get_subscription_count() > 0, timeout_s, "the arm's trajectory topic")
        self._trajectory_pub.publish(msg)
        goal = np.asarray(waypoints[-1][1])
        self._wait(lambda: np.abs(self.arm_positions() - goal).max() < tolerance_rad, timeout_s,
                   "the arm to reach the observation pose")

    def open_gripper(self, timeout_s=60.0):
        """Open the hand fully (franka_msgs Move); returns its result."""
        self._wait(self.gripper_move_client.server_is_ready, timeout_s, "the gripper move action")
        handle = self._wait_future(self.gripper_move_client.send_goal_async(
            Move.Goal(width=GRIPPER_MAX_WIDTH_M, speed=0.1)), timeout_s, "the gripper goal response")
        try:
            return result_of_goal(handle, timeout_s, "the gripper result", self._spin_until).result
        except ResultTimeout as exc:
            raise CellCallError(str(exc)) from None

    def _on_depth(self, msg):
        def put():
            self._depth[stamp_to_ns(msg.header.stamp)] = (msg, time.monotonic())
            for old in sorted(self._depth)[:-5]:
                del self._depth[old]
        self._store(put)

    def _on_info(self, msg):
        def put():
            self._info[stamp_to_ns(msg.header.stamp)] = msg
            for old in sorted(self._info)[:-5]:
                del self._info[old]
        self._store(put)

    def _wait(self, predicate, timeout_s, what):
        if not self._spin_until(predicate, timeout_s):
            raise CellCallError(f"timed out after {timeout_s:.0f} s waiting for {what}")

    def _spin_until(self, predicate, timeout_s) -> bool:
        """Spin until predicate() holds (True) or `timeout_s` passes (False)."""
        deadline = time.monotonic() + timeout_s
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            self._check_alive()
            self._executor.spin_once(timeout_sec=min(0.1, remaining))
        return True

    def _wait_future(self, future, timeout_s, what):
        self._wait(future.done, timeout_s, what)
        return future.result()

    # ---- queries -----------------------------------------------------------
    def scene(self, timeout_s=30.0) -> dict:
        self._wait(lambda: self._scene is not None, timeout_s, f"the scene on {topics.FAKE_SCENE}")
        return self._scene

    def object_positions(self, timeout_s=30.0) -> list:
        """Ground-truth object positions (base frame) from a message received after this call."""
        asked = time.monotonic()
        self._wait(lambda: self._poses is not None and self._poses[1] > asked, timeout_s,
                   f"object poses on {topics.FAKE_OBJECT_POSES}")
        return list(self._poses[0])

    def fresh_frame(self, after_wall_s: float, timeout_s=60.0):
        """(depth Image, CameraInfo) of one stamp, received after `after_wall_s` (time.monotonic()).

        Asks the driver to render now (its periodic frames come every 0.5 s of
        sim time, which is many wall seconds while soft objects are simulated).
        """
        self._call(self.capture_client, Trigger.Request(), timeout_s, "capture_depth")
        def ready():
            return any(t > after_wall_s and s in self._info for s, (_, t) in self._depth.items())

        self._wait(ready, timeout_s, f"a new depth frame + camera_info on {topics.DEPTH_IMAGE}")
        stamp = max(s for s, (_, t) in self._depth.items() if t > after_wall_s and s in self._info)
        return self._depth[stamp][0], self._info[stamp]

    # ---- calls -----------------------------------------------------------------
    def _call(self, client, request, timeout_s, what):
        self._wait(client.service_is_ready, timeout_s, f"the {what} service")
        # capture_depth is idempotent: re-sent while unanswered (defgg_ros/ros/service.py).
        try:
            return call_idempotent(client, request, timeout_s, f"the answer of {what}", wait_until=self._spin_until)
        except (ServiceTimeout, RuntimeError) as error:
            raise CellCallError(str(error)) from None

    def set_stiffness(self, objects, default_youngs_modulus_pa=0.0, timeout_s=30.0):
        return self.cell.set_stiffness(objects, default_youngs_modulus_pa, timeout_s)

    def plan(self, request: PlanGrasp.Request, timeout_s=60.0):
        return self.cell.plan(request, timeout_s)

    def perceive(self, depth, camera_info, objects=(), timeout_s=60.0):
        return self.cell.perceive(depth, camera_info, objects, timeout_s)

    def pick(self, goal: PickAndPlace.Goal, on_feedback=None, timeout_s=600.0):
        """Send a PickAndPlace goal and wait for its result (PickAndPlace.Result)."""
        return self.cell.pick(goal, on_feedback, timeout_s)

    def close(self):
        self._executor.shutdown(timeout_sec=2.0)
        destroy_actions(self.node)
        self.node.destroy_node()
        self._context.try_shutdown()
