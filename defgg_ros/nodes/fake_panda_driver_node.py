"""fake_panda_driver: the simulated Panda + RealSense cell as ROS interfaces.

A thin adapter over `defgg_ros.sim.cell.sim_cell.SimCell` (PyBullet). It serves franka_ros2 3.x's contract as
a real cell started with franka_bringup's franka.launch.py (load_gripper:=true) and a
JointTrajectoryController would, QoS and rates included (docs/franka_contract.md), plus
realsense2_camera's depth + camera_info (stamped with the capture time and published depth_capture_latency_s
later, as a real camera's frames arrive after their exposure): the merged `joint_states` (joint_state_publisher, 30 Hz),
`franka/joint_states` (joint_state_broadcaster, arm only), `franka_gripper/joint_states` (fingers only,
depth 1) and franka_gripper's franka_msgs/action/{Grasp, Move, Homing}, its `gripper_action` (GripperCommand) and
`stop` (fake_gripper_interfaces.py), franka_robot_state_broadcaster's
convenience topics (external wrench, current pose, measured joint states; best effort, depth 1), the
arm's `<robot_type>_arm_controller` (control_msgs/action/FollowJointTrajectory and its JointTrajectory
topic, with the controller's tolerances and ends of a goal: fake_arm_controller.py), a reflex above
`reflex_force_n` and franka_ros2's error recovery (the controller manager's services, fake_franka_errors.py), and
the static frames of a
calibrated cell on /tf_static (the calibration base -> camera_link, then realsense2_camera's camera_link ->
camera_depth_frame -> camera_depth_optical_frame, and robot_state_publisher's franka_description root `base` ->
base); plus sim time on /clock and ground truth (fake_panda/object_poses, fake_panda/scene).
Names follow robot_type (fer = the Panda, or fr3; the simulated arm is a Panda either way);
joint_state_fingers reproduces the MoveIt launch's merged joint states.

Threads: one sim thread owns PyBullet, advances sim time in control periods
and publishes; ROS callbacks (trajectory, gripper goals) hand commands to it
under a lock. The sim thread never reads the ROS clock, because it is the
clock. It is throttled to at most `max_real_time_factor` and, like a real arm, never catches up: time the
simulation lost on a busy machine stays lost (`SimPacer`).
"""
import collections
import json
import threading
import time

import numpy as np
from franka_msgs.action import Grasp, Homing, Move
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, WrenchStamped
from rclpy._rclpy_pybind11 import RCLError
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header, String
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage

from defgg_ros.constants import CAMERA_HEIGHT_PX, CAMERA_WIDTH_PX, GRIPPER_MAX_WIDTH_M
from defgg_ros.nodes.fake_arm_controller import FakeArmController
from defgg_ros.nodes.fake_franka_errors import REFLEX_WINDOW_S, FakeControllerManager
from defgg_ros.nodes.fake_gripper_interfaces import serve_gripper_interfaces
from defgg_ros.nodes.node_main import run_node
from defgg_ros.ros import qos, realsense_frames, topics
from defgg_ros.ros.action import destroy_actions
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info, numpy_to_image, seconds_to_stamp
from defgg_ros.ros.parameters import declare_parameters, load_schema
from defgg_ros.ros.share import demo_scene_file
from defgg_ros.ros.tf import transform_msg
from defgg_ros.rotations import quaternion_xyzw_to_matrix
from defgg_ros.sim.cell.camera import DepthNoise, color_camera_matrix
from defgg_ros.sim.cell.gripper import GripperCommandError
from defgg_ros.sim.cell.sim_cell import CellSettings, SimCell
from defgg_ros.sim.scene_spec import SceneError, load_scene, scene_warnings

SCENE_TOPIC = topics.FAKE_SCENE
OBJECT_POSES_TOPIC = topics.FAKE_OBJECT_POSES
CAPTURE_SERVICE = topics.FAKE_CAPTURE_SERVICE
HOMING_SPEED_MPS = 0.1        # franka_gripper's default speed
# On SIGINT/SIGTERM (stop_for_exit) the driver holds its own arm and keeps stepping and publishing until every arm
# joint has been slower than EXIT_STILL_RADPS for EXIT_REST_S (wall clock), at most EXIT_STOP_TIMEOUT_S: under
# `ros2 launch` every process gets the signal at once, and the executor's own stop needs joint states to confirm.
EXIT_STILL_RADPS = 0.01
EXIT_REST_S = 0.5
EXIT_STOP_TIMEOUT_S = 3.0
# realsense2_camera stamps each stream's frames with that stream's own capture time (enable_sync off, its default):
# a depth frame and the colour frame taken with it never carry the same stamp. The simulated colour frame is
# stamped one control period later, so a reader pairing them by exact stamp fails here as on the real camera.
COLOR_STAMP_LAG_S = 1e-3


# Names, types, defaults and bounds: defgg_ros/ros/params/fake_panda_driver.yaml.
PARAMETERS = load_schema("fake_panda_driver")


class SimPacer:
    """How long the sim thread sleeps so that sim time runs at most `max_real_time_factor` times wall time.

    Paced from an anchor that moves forward when the simulation falls behind by more than MAX_LAG_S: the
    lost time is never made up in a burst. A cumulative pace (the anchor fixed at start-up) ran the arm
    at the simulation's capacity (2-5x real time) after every stall on a busy machine, so 0.5 s of sim
    time passed in 0.1-0.2 s of wall time while the executor, starved of the same CPU, had not yet reacted
    (CI 2026-11-29: the arm moved 0.73 s of sim time after SIGTERM). A real arm loses no time, so nothing
    downstream may count on sim time racing ahead of the wall clock.
    """
    MAX_LAG_S = 0.02

    def __init__(self, max_real_time_factor: float, wall_s: float, sim_s: float):
        self.rtf = max_real_time_factor
        self.anchor = (wall_s, sim_s)

    def ahead_s(self, wall_s: float, sim_s: float) -> float:
        """Seconds (wall) the simulation is ahead of its pace at sim time sim_s; <= 0: step on."""
        if self.rtf <= 0:
            return 0.0   # unthrottled
        wall0, sim0 = self.anchor
        ahead_s = wall0 + (sim_s - sim0) / self.rtf - wall_s
        if ahead_s < -self.MAX_LAG_S:
            self.anchor = (wall_s, sim_s)   # behind: the lost time stays lost
            return 0.0
        return ahead_s


class FakePandaDriver(Node):
    def __init__(self, **kwargs):
        super().__init__("fake_panda_driver", **kwargs)
        declare_parameters(self)  # a value outside its schema raises ParameterError here
        self.cfg = {name: self.get_parameter(name).value for name in PARAMETERS}
        self._check_parameters()
        scene_path = self.cfg["scene_file"] or str(demo_scene_file())
        settings = CellSettings(
            depth_noise=DepthNoise(self.cfg["depth_noise_coeff_per_m"], self.cfg["depth_dropout_fraction"],
                                   self.cfg["depth_drop_edges"]),
            seed=int(self.cfg["seed"]), gui=bool(self.cfg["gui"]),
            soft_always_active=bool(self.cfg["soft_always_active"]))
        self.cell = SimCell(load_scene(scene_path), settings)
        self.get_logger().info(
            f"scene {scene_path}: {len(self.cell.scene.objects)} objects "
            f"({sum(o.is_soft for o in self.cell.scene.objects)} soft), "
            f"{'deformable' if self.cell.scene.has_soft_objects else 'rigid'} world, "
            f"step {self.cell.time_step_s * 1e3:.2f} ms, {'GUI' if settings.gui else 'headless'}")
        for warning in scene_warnings(self.cell.scene):
            self.get_logger().warning(f"scene {scene_path}: {warning}")
        self._lock = threading.Lock()
        self._waiters = {}           # gripper token -> [threading.Event, GripperOutcome | None]
        names = topics.robot_names(self.cfg["robot_type"])  # ValueError on an unknown robot_type
        self._arm_joints, self._finger_joints = names["joints"], names["fingers"]
        for key, name in (("base_frame", "base_frame"), ("arm_trajectory_action", "trajectory_action"),
                          ("joint_trajectory_topic", "trajectory_topic")):
            self.cfg[key] = self.cfg[key] or names[name]   # '' = the robot type's name
        # realsense2_camera's frames, named from camera_name as it names them (ValueError on '')
        self._camera_frames = realsense_frames.frame_ids(self.cfg["camera_name"])
        self._capture_requested = False
        self._gripper_fingers_m = None     # each finger's position in the gripper's last joint state
        self._reported_off_table = set()   # object names already reported as off the table
        self._running = True
        self._create_interfaces()
        self._thread = threading.Thread(target=self._sim_loop, name="sim", daemon=True)
        self._thread.start()

    def _check_parameters(self):
        for name in ("robot_state_rate_hz", "joint_state_rate_hz", "gripper_state_rate_hz", "clock_rate_hz",
                     "depth_rate_hz", "object_pose_rate_hz"):
            if not self.cfg[name] > 0:
                raise ValueError(f"parameter {name} must be > 0, got {self.cfg[name]}")
        if self.cfg["max_real_time_factor"] < 0:
            raise ValueError(f"max_real_time_factor must be >= 0, got {self.cfg['max_real_time_factor']}")

    def _create_interfaces(self):
        cfg, group = self.cfg, ReentrantCallbackGroup()
        self.pub_clock = self.create_publisher(Clock, topics.CLOCK, qos.STATE)
        # franka_ros2's publishers with their QoS (docs/franka_contract.md).
        self.pub_joints = self.create_publisher(JointState, cfg["joint_states_topic"], qos.JOINT_STATE_PUBLISHER)
        self.pub_arm_joints = self.create_publisher(JointState, cfg["arm_joint_states_topic"],
                                                    qos.FRANKA_SYSTEM_DEFAULT)
        self.pub_gripper_joints = self.create_publisher(JointState, cfg["gripper_joint_states_topic"],
                                                        qos.GRIPPER_STATE)
        self.pub_wrench = self.create_publisher(WrenchStamped, cfg["external_wrench_topic"], qos.FRANKA_CONVENIENCE)
        self.pub_pose = self.create_publisher(PoseStamped, topics.CURRENT_POSE, qos.FRANKA_CONVENIENCE)
        self.pub_measured = self.create_publisher(JointState, topics.MEASURED_JOINT_STATES, qos.FRANKA_CONVENIENCE)
        # realsense2_camera's publishers with their QoS (ros/qos.py REALSENSE_*)
        self.pub_depth = self.create_publisher(Image, cfg["depth_topic"], qos.REALSENSE_IMAGE)
        self.pub_info = self.create_publisher(CameraInfo, cfg["camera_info_topic"], qos.REALSENSE_CAMERA_INFO)
        self.pub_color = self.create_publisher(Image, cfg["color_topic"], qos.REALSENSE_IMAGE)
        self.pub_color_info = self.create_publisher(CameraInfo, cfg["color_camera_info_topic"],
                                                    qos.REALSENSE_CAMERA_INFO)
        self.pub_poses = self.create_publisher(PoseArray, OBJECT_POSES_TOPIC, qos.STATE)
        self.pub_scene = self.create_publisher(String, SCENE_TOPIC, qos.LATCHED)
        self.pub_scene.publish(String(data=json.dumps(self._scene_description())))
        # The arm's joint_trajectory_controller: the action (what the executor uses) and its topic.
        self.arm = FakeArmController(self, self._arm_joints, group)
        self.controller_manager = FakeControllerManager(self, self.arm, _controller_name(cfg["arm_trajectory_action"]),
                                                        group)
        self._last_arm_state = None   # what joint_state_publisher last received from joint_state_broadcaster
        self.create_service(Trigger, CAPTURE_SERVICE, self._on_capture, callback_group=group)
        for action_type, name, execute in ((Move, cfg["gripper_move_action"], self._execute_move),
                                           (Grasp, cfg["gripper_grasp_action"], self._execute_grasp),
                                           (Homing, cfg["gripper_homing_action"], self._execute_homing)):
            ActionServer(self, action_type, name, execute_callback=execute, callback_group=group,
                         goal_callback=lambda _goal: GoalResponse.ACCEPT,
                         cancel_callback=lambda _goal: CancelResponse.ACCEPT)
        serve_gripper_interfaces(self, group)  # franka_gripper's gripper_action (GripperCommand) and stop
        # The static frames of a calibrated cell (latched): the calibration, realsense2_camera's own, and
        # robot_state_publisher's fixed joint from franka_description's root link to the base.
        self.pub_tf_static = self.create_publisher(TFMessage, topics.TF_STATIC, qos.LATCHED)
        self.pub_tf_static.publish(TFMessage(transforms=self._static_transforms()))

    def _static_transforms(self) -> list:
        """/tf_static (stamp 0: valid at all times): base_frame -> <camera_name>_link (the hand-eye calibration, from
        the scene's camera pose) -> <camera_name>_depth_frame -> <camera_name>_depth_optical_frame (and the colour
        pair with publish_color) as realsense2_camera publishes them (ros/realsense_frames.py), and `base` ->
        base_frame (robot_state_publisher: franka_description's root link, the frame of current_pose and the wrench)."""
        base_T_optical = np.eye(4)
        base_T_optical[:3, :3] = quaternion_xyzw_to_matrix(self.cell.scene.base_quat_camera_xyzw)
        base_T_optical[:3, 3] = self.cell.scene.base_xyz_camera_m
        tree = realsense_frames.calibrated_camera_tree(self.cfg["base_frame"], base_T_optical, self.cfg["camera_name"],
                                                       with_color=bool(self.cfg["publish_color"]))
        if self.cfg["base_frame"] != topics.FRANKA_STATE_FRAME:
            tree.append((topics.FRANKA_STATE_FRAME, self.cfg["base_frame"], np.eye(4)))
        return [transform_msg(parent, child, matrix) for parent, child, matrix in tree]

    def _scene_description(self) -> dict:
        scene = self.cell.scene.to_json_dict()
        scene["objects_simulated_as"] = ["soft" if o.is_soft else "rigid" for o in self.cell.scene.objects]
        scene["camera_k"] = self.cell.camera_k.tolist()
        scene["base_frame"] = self.cfg["base_frame"]
        return scene

    # ---- commands (ROS threads) ------------------------------------------
    def _on_capture(self, _request, response):
        self._capture_requested = True
        response.success, response.message = True, "a depth frame will be rendered in the next control period"
        return response

    def _execute_move(self, goal_handle):
        g = goal_handle.request
        return self._run_gripper(goal_handle, Move, lambda: self.cell.gripper_move(g.width, g.speed))

    def _execute_grasp(self, goal_handle):
        g = goal_handle.request
        return self._run_gripper(goal_handle, Grasp, lambda: self.cell.gripper_grasp(
            g.width, g.epsilon.inner, g.epsilon.outer, g.speed, g.force))

    def _execute_homing(self, goal_handle):
        """franka_gripper's homing opens fully to calibrate; the simulated fingers need no calibration."""
        return self._run_gripper(goal_handle, Homing,
                                 lambda: self.cell.gripper_move(GRIPPER_MAX_WIDTH_M, HOMING_SPEED_MPS))

    def _run_gripper(self, goal_handle, action_type, start):
        """franka_msgs result (success, error) and feedback (current_width) of one gripper goal."""
        result = action_type.Result()
        try:
            with self._lock:
                token = start()
                waiter = self._waiters[token] = [threading.Event(), None]
        except GripperCommandError as exc:
            result.success, result.error = False, str(exc)
            goal_handle.abort()
            return result
        while not waiter[0].wait(0.05):
            if goal_handle.is_cancel_requested or not self._running:
                with self._lock:  # franka_gripper's cancel: Gripper::stop, the grasp's force let go
                    self.cell.gripper_stop()
                    self._waiters.pop(token, None)
                if goal_handle.is_cancel_requested:
                    result.success, result.error = False, "canceled"
                    goal_handle.canceled()
                else:   # shutting down: a goal ends canceled only on request (rclpy refuses it otherwise)
                    result.success, result.error = False, "the simulated gripper is shutting down"
                    goal_handle.abort()
                return result
            goal_handle.publish_feedback(action_type.Feedback(current_width=self.cell.gripper_width_m()))
        outcome = waiter[1]
        # franka_gripper: a grasp outside its band is grasp() returning false, an abort with no error text.
        result.success, result.error = outcome.success, "" if outcome.outside_band else outcome.error
        if outcome.outside_band:
            self.get_logger().info(f"grasp failed: {outcome.error}")
        if outcome.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    # ---- the sim thread ------------------------------------------------------
    def _sim_loop(self):
        period_s = 1.0 / self.cfg["robot_state_rate_hz"]
        schedule = _Schedule({"clock": min(self.cfg["clock_rate_hz"], self.cfg["robot_state_rate_hz"]),
                              "joints": self.cfg["joint_state_rate_hz"], "gripper": self.cfg["gripper_state_rate_hz"]})
        next_depth_s = next_pose_s = 0.0
        in_transit = collections.deque()    # (publish at s, captured at s, frame): depth_capture_latency_s
        wall0 = time.monotonic()
        pacer = SimPacer(self.cfg["max_real_time_factor"], wall0, self.cell.time_s)
        self._log_mark = (wall0, self.cell.time_s)
        next_log = wall0 + min(2.0, self.cfg["rtf_log_period_s"])  # a first figure soon after start-up
        publish_failures = 0
        while self._running and self.context.ok():
            with self._lock:
                outcomes = self.cell.advance(period_s)
                now_s = self.cell.time_s
                self.arm.control_period(now_s)   # the trajectory controller's checks of this period
                joints, (force, torque) = self.cell.joint_state(), self.cell.external_wrench()
                self.controller_manager.check_reflex(force)
                # current_pose: libfranka's O_T_EE, the Franka Hand's TCP (only computed for a reader)
                tcp = self.cell.hand_tcp_pose() if is_read(self.pub_pose) else None
                periodic = now_s >= next_depth_s and (self.cfg["render_while_moving"] or not self.cell.moving(now_s))
                render = periodic or self._capture_requested
                frame = self.cell.render_depth(self.cfg["publish_color"]) if render else None
                poses = self.cell.object_poses() if now_s >= next_pose_s else None
            self._finish_gripper(outcomes)
            if frame is not None:
                self._capture_requested = False
                next_depth_s = now_s + 1.0 / self.cfg["depth_rate_hz"]
                in_transit.append((now_s + self.cfg["depth_capture_latency_s"], now_s, frame))
            if poses is not None:
                next_pose_s = now_s + 1.0 / self.cfg["object_pose_rate_hz"]
            try:
                self._publish_state(now_s, joints, force, torque, tcp, schedule.due(now_s))
                while in_transit and in_transit[0][0] <= now_s:   # captured at stamp_s, arriving now
                    _, stamp_s, captured = in_transit.popleft()
                    self._publish_frame(stamp_s, *captured)
                if poses is not None:
                    self._publish_poses(now_s, poses)
                    self._report_objects_off_the_table(poses)
            except RCLError as error:
                if not self.context.ok():
                    break  # Ctrl-C shut the context down under us: stop quietly
                # A failed publish (rmw "cannot publish data", seen once at start-up on a machine at a load of 15)
                # must not end the simulation: the thread died and the driver stayed up with nothing published.
                publish_failures += 1
                self.get_logger().warning(f"publishing failed ({publish_failures} times so far): {error}; "
                                          "the simulation goes on", throttle_duration_sec=5.0)
            ahead_s = pacer.ahead_s(time.monotonic(), now_s)
            if ahead_s > 0:
                time.sleep(ahead_s)  # pacing the simulation to wall time, not waiting for a message
            if time.monotonic() >= next_log:
                next_log = time.monotonic() + self.cfg["rtf_log_period_s"]
                self._log_rtf(now_s)

    def _log_rtf(self, now_s):
        """Real-time factor since the last log, and what the simulation alone could do (capacity)."""
        wall_then, sim_then = self._log_mark
        wall_now = time.monotonic()
        self._log_mark = (wall_now, now_s)
        rtf = (now_s - sim_then) / max(wall_now - wall_then, 1e-9)
        active = self.cell.active_soft_objects()
        manager = self.controller_manager
        with self._lock:   # how near the reflex the contacts came (a real cell's reflexes fire on such peaks)
            peak_n, raw_n = manager.peak_force_n, manager.peak_raw_force_n
            manager.peak_force_n = manager.peak_raw_force_n = 0.0
        self.get_logger().info(f"sim time {now_s:.1f} s, real-time factor {rtf:.2f} "
                               f"(simulation capacity {self.cell.real_time_factor():.2f}), peak external force "
                               f"{peak_n:.1f} N over {REFLEX_WINDOW_S * 1e3:g} ms, {raw_n:.1f} N in a step (reflex at "
                               f"{self.cfg['reflex_force_n']:g} N)"
                               f"{', FEM active: ' + ', '.join(active) if active else ''}")

    def _report_objects_off_the_table(self, poses):
        """Once per object: one that left the table will not come back (the demo's 2026-11-28 rubber block
        ended 12 km under it), and whoever watches the cell should hear it when it happens."""
        for name, xyz in self.cell.objects_off_the_table(poses):
            if name not in self._reported_off_table:
                self._reported_off_table.add(name)
                self.get_logger().error(f"object {name} left the table: at ({xyz[0]:.2f}, {xyz[1]:.2f}, "
                                        f"{xyz[2]:.2f}) m, under its top (fallen off an edge, or its simulation "
                                        f"failed); it stays in the scene")

    def _finish_gripper(self, outcomes):
        for token, outcome in outcomes:
            waiter = self._waiters.pop(token, None)
            if waiter is not None:
                waiter[1] = outcome
                waiter[0].set()

    def _stamp(self, now_s, frame_id):
        header = Header(frame_id=frame_id)
        header.stamp = seconds_to_stamp(now_s)
        return header

    def _publish_state(self, now_s, joints, force, torque, tcp, due):
        """What franka_ros2 publishes in one control period: the broadcasters every period, /clock, the merged
        joint states and the gripper's at their own rates (`due`: the names of those whose turn it is). Frame ids as
        franka_ros2 stamps them (docs/franka_contract.md, "Frames"): the robot state broadcaster's the URDF's root link
        `base`, joint_state_broadcaster's `base_link`, joint_state_publisher's and franka_gripper's none."""
        header = self._stamp(now_s, topics.FRANKA_STATE_FRAME)
        if "clock" in due:
            self.pub_clock.publish(Clock(clock=header.stamp))
        broadcasters = self.controller_manager   # after a robot error both are inactive: their topics go quiet
        arm = JointState(header=self._stamp(now_s, topics.JOINT_STATE_BROADCASTER_FRAME), name=list(self._arm_joints),
                         position=joints.positions[:7].tolist(), velocity=joints.velocities[:7].tolist(),
                         effort=joints.efforts[:7].tolist())
        if broadcasters.publishes(topics.JOINT_STATE_BROADCASTER):
            self.pub_arm_joints.publish(arm)   # transient local: always, so a late joiner's first state is fresh
            self._last_arm_state = arm
        robot_state = broadcasters.publishes(topics.ROBOT_STATE_BROADCASTER)
        if robot_state and is_read(self.pub_measured):
            self.pub_measured.publish(JointState(header=header, name=arm.name, position=arm.position,
                                                 velocity=arm.velocity, effort=arm.effort))
        if robot_state and is_read(self.pub_wrench):
            self.pub_wrench.publish(franka_wrench_msg(header, force, torque))
        if robot_state and tcp is not None:
            pose = PoseStamped(header=header)
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in tcp[0])
            o = pose.pose.orientation
            o.x, o.y, o.z, o.w = (float(v) for v in tcp[1])
            self.pub_pose.publish(pose)
        if "gripper" in due:
            # franka_gripper: each finger at half the width, velocity and effort 0 (gripper_action_server.cpp)
            half_m = float(joints.positions[7] + joints.positions[8]) / 2.0
            self._gripper_fingers_m = half_m
            self.pub_gripper_joints.publish(JointState(
                header=self._stamp(now_s, ""), name=list(self._finger_joints), position=[half_m, half_m],
                velocity=[0.0, 0.0], effort=[0.0, 0.0]))
        if "joints" in due and self._last_arm_state is not None:   # the arm's last state, stamped now
            self.pub_joints.publish(self._merged_joint_state(self._stamp(now_s, ""), self._last_arm_state))

    def _merged_joint_state(self, header, arm: JointState) -> JointState:
        """joint_state_publisher's merge: the arm's latest state plus the fingers as joint_state_fingers says
        (from_gripper: the gripper's last message; urdf_default: 0.0, the URDF default nobody updates), stamped
        `header` (joint_state_publisher sets only the stamp: frame_id '')."""
        mode = self.cfg["joint_state_fingers"]
        if mode == "none" or (mode == "from_gripper" and self._gripper_fingers_m is None):
            return JointState(header=header, name=arm.name, position=arm.position, velocity=arm.velocity,
                              effort=arm.effort)
        finger_m = self._gripper_fingers_m if mode == "from_gripper" else 0.0
        return JointState(header=header, name=[*arm.name, *self._finger_joints],
                          position=[*arm.position, finger_m, finger_m], velocity=[*arm.velocity, 0.0, 0.0],
                          effort=[*arm.effort, 0.0, 0.0])

    def _publish_frame(self, now_s, depth_m, _object_mask, rgb):
        # realsense2_camera stamps each stream's image and camera_info with that stream's optical frame
        header = self._stamp(now_s, self._camera_frames["depth_optical"])
        self.pub_depth.publish(depth_metres_to_msg(depth_m, "16UC1", header))
        self.pub_info.publish(make_camera_info(self.cell.camera_k, CAMERA_WIDTH_PX, CAMERA_HEIGHT_PX, header))
        if rgb is not None:
            color_header = self._stamp(now_s + COLOR_STAMP_LAG_S, self._camera_frames["color_optical"])
            self.pub_color.publish(numpy_to_image(rgb, "rgb8", color_header))
            self.pub_color_info.publish(make_camera_info(color_camera_matrix(), CAMERA_WIDTH_PX, CAMERA_HEIGHT_PX,
                                                         color_header))

    def _publish_poses(self, now_s, poses):
        msg = PoseArray(header=self._stamp(now_s, self.cfg["base_frame"]))
        for xyz, quat in poses:
            pose = Pose()
            pose.position.x, pose.position.y, pose.position.z = (float(v) for v in xyz)
            pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = (float(v) for v in quat)
            msg.poses.append(pose)
        self.pub_poses.publish(msg)

    def shutdown(self):
        self._running = False
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        with self._lock:
            self.cell.close()

    def stop_for_exit(self, spin_once) -> str:
        """On a stop signal (run_node, stops_hardware), before anything is torn down: this process is the simulated
        arm's controller, so it holds the arm where it is (as a cancel does), then keeps simulating and publishing
        (spin_once serves the executor's cancel and hold goals meanwhile) until the arm has been at rest for
        EXIT_REST_S. '' when it was, else why not (the process then exits 1)."""
        with self._lock:
            self.arm.hold_for_exit()     # a running trajectory goal ends, as preempted
        started, still_since, speed = time.monotonic(), None, float("inf")
        while time.monotonic() - started < EXIT_STOP_TIMEOUT_S and self._thread.is_alive():
            spin_once(0.01)
            with self._lock:
                speed = float(max(abs(v) for v in self.cell.joint_state().velocities[:len(self._arm_joints)]))
            now = time.monotonic()
            if speed >= EXIT_STILL_RADPS:
                still_since = None
            elif still_since is None:
                still_since = now
            elif now - still_since >= EXIT_REST_S:
                self.get_logger().info(f"stopping: the simulated arm is held at rest ({now - started:.2f} s)")
                return ""
        return (f"the simulated arm did not come to rest within {EXIT_STOP_TIMEOUT_S:.0f} s of its hold "
                f"(joints at up to {speed:.3f} rad/s)")

    def destroy_node(self):
        self.shutdown()  # the simulation thread first: it publishes through this node
        destroy_actions(self)  # the gripper actions must vanish with the driver (see destroy_actions)
        return super().destroy_node()


def _controller_name(trajectory_action: str) -> str:
    """The controller's name in its action's name (`<controller>/follow_joint_trajectory`)."""
    parts = trajectory_action.strip("/").split("/")
    return parts[-2] if len(parts) > 1 else parts[0]


class _Schedule:
    """Which of several rates (per second of sim time) are due in the control period ending at a time."""

    def __init__(self, rates_hz: dict):
        self._period_s = {name: 1.0 / rate for name, rate in rates_hz.items()}
        self._next_s = dict.fromkeys(rates_hz, 0.0)

    def due(self, now_s: float) -> set:
        names = {name for name, next_s in self._next_s.items() if now_s >= next_s - 1e-9}
        for name in names:   # from the slot, not from now: the rate holds when the period does not divide it
            next_s = self._next_s[name] + self._period_s[name]
            self._next_s[name] = next_s if next_s > now_s else now_s + self._period_s[name]
        return names


def is_read(convenience_publisher) -> bool:
    """Does anyone read this best-effort, volatile broadcaster topic? One that nobody reads is not published:
    no reader can tell (a volatile topic keeps nothing for a late joiner; a new reader gets the next period's
    message), and at 1 kHz each message costs the sim thread ~0.1 ms of a 1 ms period (docs/franka_contract.md)."""
    return convenience_publisher.get_subscription_count() > 0


def franka_wrench_msg(header, force_on_hand_n, torque_on_hand_nm) -> WrenchStamped:
    """The cell's contact wrench on the hand as franka_robot_state_broadcaster publishes O_F_ext_hat_K: the wrench
    the robot applies to the environment (libfranka: "forces applied by the robot to the environment are
    positive"), the negative of the contacts' on the hand. Pressing on the table reads Fz < 0, a held object's
    weight Fz > 0 (docs/franka_contract.md)."""
    wrench = WrenchStamped(header=header)
    f, t = wrench.wrench.force, wrench.wrench.torque
    f.x, f.y, f.z = (-float(v) for v in force_on_hand_n)
    t.x, t.y, t.z = (-float(v) for v in torque_on_hand_nm)
    return wrench


def main(args=None):
    run_node("fake_panda_driver", FakePandaDriver, startup_errors=(SceneError, ValueError), threads=4, args=args,
             stops_hardware=True)


if __name__ == "__main__":
    main()
