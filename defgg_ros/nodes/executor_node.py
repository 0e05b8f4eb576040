"""executor_node: the PickAndPlace action server, a thin adapter over the pure sequence.

All decisions live in `defgg_ros.control.pick_place.PickPlaceSequence`; this
node only translates: goals and grasps in, FollowJointTrajectory goals to
the arm's joint_trajectory_controller and franka_msgs Move/Grasp goals to
franka_ros2's gripper node (docs/real_cell.md) and
gripper action goals out, joint states / external wrench / gripper results
back into the sequence, feedback and results to the client.

Threads: the action's execute callback runs the control loop (wall-clock
period, so the driver watchdog fires even when sim time has stopped) in a
reentrant callback group on a multi-threaded executor; subscriptions and
action-client callbacks feed the sequence under one lock. One goal at a
time: goals arriving while busy are rejected (the reason is logged).
"""
import dataclasses
import functools
import math
import threading
import time

import numpy as np
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.srv import PlanGrasp
from franka_msgs.action import Grasp, Move
from franka_msgs.msg import GraspEpsilon
from geometry_msgs.msg import WrenchStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from defgg_ros.constants import ARM_MODELS
from defgg_ros.control.bin_slots import BinArea, BinFull, BinSlots, check_drop_xy, default_drop_xy
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.observation import ObservationWatch, arm_state_of, max_joint_speed_radps
from defgg_ros.control.pick_place import ObservationMove, PickPlaceSequence
from defgg_ros.control.poses import PoseError, top_down_yaw
from defgg_ros.control.sequence_types import (
    ArmState,
    CancelGripper,
    GraspGripper,
    GraspTarget,
    MoveGripper,
    PlaceTarget,
    SendTrajectory,
    SequenceConfig,
    SqueezeRequest,
)
from defgg_ros.control.squeeze_phase import planning_modulus_pa
from defgg_ros.control.velocity_estimate import PositionVelocityEstimator
from defgg_ros.nodes import qos
from defgg_ros.nodes.conversions import ConversionError, stamp_to_ns, transform_from_pose
from defgg_ros.nodes.executor_stiffness import StiffnessUpdater
from defgg_ros.nodes.node_main import run_node
from defgg_ros.nodes.topic_watch import TopicWatch
from defgg_ros.ros import topics
from defgg_ros.ros.action import ActionClient, destroy_actions
from defgg_ros.ros.diagnostics import NodeDiagnostics
from defgg_ros.ros.parameters import declare_parameters, load_schema
from defgg_ros.ros.service import ServiceTimeout, call_idempotent

# Names, types, defaults and bounds: defgg_ros/ros/params/executor_node.yaml.
PARAMETERS = load_schema("executor_node")
# How often the input topics' silence is checked (wall clock, s).
INPUT_CHECK_PERIOD_S = 1.0
# A finger width source older than this gives way to the next one (wall clock, s). franka_gripper publishes at
# 15 Hz; the simulated one at 15 Hz of sim time, and its clock stalls up to ~2 s while a frame renders: a shorter
# limit handed the width to the MoveIt launch's constant 0.0 in joint_states meanwhile.
FINGER_SOURCE_FRESH_S = 3.0


class GoalError(ValueError):
    """A goal the executor cannot work with (the message says why)."""


class RobotRestarted(GoalError):
    """The robot clock went back during a goal: the driver (a simulator) restarted and its goals are gone."""


# The default robot type's names (the functions below are called with the node's own).
DEFAULT_NAMES = topics.robot_names()


def trajectory_to_msg(trajectory, frame_id: str, joint_names=DEFAULT_NAMES["joints"]) -> JointTrajectory:
    """The trajectory (arm joints 1..7 in order) for a joint_trajectory_controller; stamp 0 = start on receipt."""
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.joint_names = list(joint_names)
    for t, q, qd, qdd in zip(trajectory.times_s, trajectory.q_rad, trajectory.qd_radps, trajectory.qdd_radps2):
        # Split whole nanoseconds, so rounding can never carry into a wrong second.
        sec, nanosec = divmod(int(round(float(t) * 1e9)), 1_000_000_000)
        msg.points.append(JointTrajectoryPoint(
            positions=q.tolist(), velocities=qd.tolist(), accelerations=qdd.tolist(),
            time_from_start=Duration(sec=sec, nanosec=nanosec)))
    return msg


# A hold trajectory reaches the measured position this long after it is received: the controller blends into it
# from its current state, so the arm is brought to rest within this time without a step in the command (s).
HOLD_BLEND_S = 0.1
# The robot clock going back by more than this during a goal aborts it (s): see ExecutorNode._check_clock. Over
# 1 s: the simulated driver's stamps read 1 s back for single messages (its sec/nanosec split turns x.9999999997
# into x.0, not x+1.0), which 0.5 s took for a restart 50 times in a 5-minute soak.
CLOCK_JUMP_BACK_S = 2.0


def hold_trajectory_msg(q_rad, frame_id: str, joint_names=DEFAULT_NAMES["joints"]) -> JointTrajectory:
    """One point at q_rad, zero velocity, HOLD_BLEND_S after receipt: 'stay here' for a joint_trajectory_controller."""
    sec, nanosec = divmod(int(round(HOLD_BLEND_S * 1e9)), 1_000_000_000)
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.joint_names = list(joint_names)
    msg.points.append(JointTrajectoryPoint(positions=[float(v) for v in q_rad], velocities=[0.0] * len(q_rad),
                                           accelerations=[0.0] * len(q_rad),
                                           time_from_start=Duration(sec=sec, nanosec=nanosec)))
    return msg


class _RestWatch:
    """Joint states newer than since_s (monotonic) showing every joint slower than still_radps for hold_s."""

    def __init__(self, still_radps: float, hold_s: float, since_s: float):
        self.still_radps, self.hold_s, self.since_s = still_radps, hold_s, since_s
        self.still_since_s = None
        self.last_speed_radps = None
        self.confirmed = False

    def update(self, last_state) -> None:
        if last_state is None or last_state[1] <= self.since_s or self.confirmed:
            return
        state, wall_s = last_state
        self.last_speed_radps = max_joint_speed_radps(state.qd_radps)
        if self.last_speed_radps >= self.still_radps:
            self.still_since_s = None
        elif self.still_since_s is None:
            self.still_since_s = wall_s
        elif wall_s - self.still_since_s >= self.hold_s:
            self.confirmed = True

    def describe(self) -> str:
        if self.last_speed_radps is None:
            return "no joint states arrived after the stop"
        return f"joints still at up to {self.last_speed_radps:.3f} rad/s"


def recovery_drop_xy(p: dict) -> tuple:
    """The recovery's put-down point (x, y): recovery_drop_xy_m, or at [0, 0] the point of workspace_box_m nearest
    the observation pose's TCP, away from the base (ValueError: outside the box or inside the keep-out)."""
    box, keep_out = p["workspace_box_m"], float(p["base_keep_out_radius_m"])
    if any(float(v) != 0.0 for v in p["recovery_drop_xy_m"]):
        return check_drop_xy(p["recovery_drop_xy_m"], box, keep_out)
    return default_drop_xy(_tcp_xy_m(tuple(float(v) for v in p["observation_q_rad"])), box, keep_out)


@functools.lru_cache(maxsize=4)
def _tcp_xy_m(q_rad: tuple) -> tuple:
    return tuple(float(v) for v in PandaKinematics().fk(np.asarray(q_rad))[:2, 3])


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
    return GraspTarget(tuple(base_M_tcp[:3, 3]), yaw, float(grasp.width_m), float(modulus), force)


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


class ExecutorNode(Node):
    def __init__(self, **kwargs):
        super().__init__("executor_node", **kwargs)
        declare_parameters(self)  # a value outside its schema raises ParameterError here
        p = self._params()
        self._config = self._sequence_config(p)  # invalid start-up parameters raise here
        # Since when the arm rests at the observation pose: plan_grasp goals plan only on later frames.
        self._watch = ObservationWatch(p["observation_q_rad"], p["observation_tolerance_rad"])
        self._kin = PandaKinematics(arm=p["joint_limits"])   # plans within that arm's joint ranges
        self._group = ReentrantCallbackGroup()
        self._lock = threading.Lock()
        self._shutdown = threading.Event()
        self._busy = False
        self._sequence: PickPlaceSequence | None = None
        self._gripper_goal = None
        self._gripper_serial = 0     # the newest gripper goal sent; only its result counts
        self._last_state: tuple[ArmState, float] | None = None
        self._velocity_estimate = PositionVelocityEstimator()   # for drivers without velocities
        self._last_force = np.zeros(3)
        self._last_force_wall_s = None   # when the last external wrench arrived (monotonic)
        names = topics.robot_names(p["robot_type"])
        self._arm_joints, self._finger_joints = names["joints"], names["fingers"]
        self._finger_widths = {}    # finger width source -> (width m, monotonic s): see _gripper_width_m
        self._arm_goal = None       # handle of the running FollowJointTrajectory goal
        self._arm_goal_serial = 0   # the newest goal sent; a result of an older one is ignored
        self._held_serial = -1      # _arm_goal_serial when the arm was last told to hold
        self._arm_goals_unanswered = 0   # trajectory goals sent whose acceptance has not come back yet
        self._gripper_feedback_width_m = float("nan")
        self._arm_client = ActionClient(self, FollowJointTrajectory, p["arm_trajectory_action"],
                                        callback_group=self._group)
        self._subscribe_inputs(p)
        self._move_client = ActionClient(self, Move, p["gripper_move_action"], callback_group=self._group)
        self._grasp_client = ActionClient(self, Grasp, p["gripper_grasp_action"], callback_group=self._group)
        self._plan_client = self.create_client(PlanGrasp, p["plan_grasp_service"], callback_group=self._group)
        self._server = ActionServer(self, PickAndPlace, p["action_name"], self._execute, callback_group=self._group,
                                    goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT)
        self._set_up_bin(p)
        self._stiffness = StiffnessUpdater(self, p["set_stiffness_service"], p["stiffness_assignments_topic"],
                                           self._group)
        # /diagnostics at 1 Hz (ros/diagnostics.py), like every cell node: whether a goal is running.
        self.diagnostics = NodeDiagnostics(self, lambda: {"busy": self._busy})

    def _params(self) -> dict:
        """The parameters, with the names left empty filled in from robot_type (ValueError: unknown type, or
        joint limits of another arm)."""
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        names = topics.robot_names(p["robot_type"])
        p["joint_limits"] = check_arm_limits(p["robot_type"], p["joint_limits"])
        p["base_frame"] = p["base_frame"] or names["base_frame"]
        p["arm_trajectory_action"] = p["arm_trajectory_action"] or names["trajectory_action"]
        return p

    def _take_parameters(self) -> None:
        """Each goal runs on the parameters as they are when it starts (`ros2 param set executor_node
        limits_scale 0.2` slows the next pick); a combination the sequence refuses aborts that goal
        (ValueError) and keeps the previous one."""
        p = self._params()
        config = self._sequence_config(p)
        with self._lock:
            self._config = config
            self._watch.retarget(p["observation_q_rad"], p["observation_tolerance_rad"])

    @staticmethod
    def _sequence_config(p: dict) -> SequenceConfig:
        if len(p["place_position_m"]) != 3:
            raise ValueError(f"place_position_m must have 3 values, got {p['place_position_m']}")
        via = tuple(float(v) for v in p["transfer_via_position_m"]) if p["use_transfer_via"] else None
        config = SequenceConfig(
            table_z_m=float(p["table_z_m"]), limits_scale=float(p["limits_scale"]),
            pregrasp_height_m=float(p["pregrasp_height_m"]), descent_speed_mps=float(p["descent_speed_mps"]),
            grasp_depth_below_surface_m=float(p["grasp_depth_below_surface_m"]),
            grasp_height_rule=str(p["grasp_height_rule"]),
            line_speed_mps=float(p["line_speed_mps"]), lift_height_m=float(p["lift_height_m"]),
            place_approach_height_m=float(p["place_approach_height_m"]),
            contact_force_threshold_n=float(p["contact_force_threshold_n"]),
            watchdog_timeout_s=float(p["watchdog_timeout_s"]),
            arrival_joint_atol_rad=float(p["arrival_joint_atol_rad"]),
            settle_timeout_s=float(p["settle_timeout_s"]), gripper_timeout_s=float(p["gripper_timeout_s"]),
            slip_width_fraction=float(p["slip_width_fraction"]), sample_dt_s=float(p["trajectory_sample_dt_s"]),
            transfer_via_position_m=via, still_speed_radps=float(p["still_speed_radps"]),
            transfer_max_tcp_accel_mps2=float(p["transfer_max_tcp_accel_mps2"]) or None,
            rest_hold_s=float(p["rest_hold_s"]), stop_timeout_s=float(p["stop_timeout_s"]),
            observation_q_rad=tuple(float(v) for v in p["observation_q_rad"]) if p["recover_after_failure"] else None,
            observation_lift_m=float(p["observation_lift_m"]),
            observation_tolerance_rad=float(p["observation_tolerance_rad"]),
            place_lowering_speed_mps=float(p["place_lowering_speed_mps"]),
            place_release_clearance_m=float(p["place_release_clearance_m"]),
            place_release_opening_m=float(p["place_release_opening_m"]),
            recovery_drop_xy_m=recovery_drop_xy(p))
        config.validate()
        return config

    # --- the bin ------------------------------------------------------------
    def _set_up_bin(self, p: dict) -> None:
        """The bin's slots (remembered across goals) and the service that frees them."""
        self._bin = BinSlots(BinArea.from_list(p["bin_inner_m"], p["bin_slot_pitch_m"],   # ValueError: bad area
                                               p["bin_wall_margin_m"]))
        x, y = (float(v) for v in p["place_position_m"][:2])
        if not self._bin.area.contains(x, y):
            raise ValueError(f"place_position_m ({x:.3f}, {y:.3f}) is outside bin_inner_m {list(p['bin_inner_m'])}")
        self._goal_slot = None   # the slot the running goal places into
        self.create_service(Trigger, p["reset_bin_service"], self._on_reset_bin, callback_group=self._group)

    def _on_reset_bin(self, _request, response):
        with self._lock:
            freed = self._bin.reset()
        response.success, response.message = True, f"{freed} of {len(self._bin.centres)} bin slots freed"
        self.get_logger().info(f"bin emptied: {response.message}")
        return response

    def _place_for(self, request, p: dict) -> PlaceTarget:
        """The goal's place pose, or (empty frame_id) the bin's first free slot, lowered into until contact."""
        place = place_target(request.place_pose, p["base_frame"], p["place_position_m"],
                             None if p["place_keep_grasp_yaw"] else p["place_yaw_rad"])
        self._goal_slot = None
        if request.place_pose.header.frame_id != "" or request.measure_only:   # measure only: never placed
            return place
        with self._lock:
            try:
                slot = self._bin.next_free()
            except BinFull as full:
                raise GoalError(f"{full}: empty it, then call {self.resolve_service_name(p['reset_bin_service'])}")\
                    from None
        self._goal_slot = slot
        x, y = self._bin.centres[slot]
        return dataclasses.replace(place, position_m=(x, y, float(p["place_position_m"][2])), lower_to_contact=True)

    def destroy_node(self):
        self._shutdown.set()  # ends a running control loop
        with self._lock:   # torn down without stop_for_exit (an in-process owner): still command the stop
            self._hold_arm()
        destroy_actions(self)
        return super().destroy_node()

    # --- stopping on the way out ---------------------------------------------
    def stop_for_exit(self, spin_once) -> str:
        """Before the process tears anything down (run_node calls this on SIGINT/SIGTERM or a callback's
        exception): end the control loop, cancel the trajectory goal and command a hold at the measured
        position, then keep spinning (spin_once(timeout_s)) until joint states confirm the arm at rest and the
        running goal is answered. Returns '' when the arm is confirmed at rest (or this node never moved it),
        else why not (the process then exits 1)."""
        p = self._params()
        timeout_s, hold_s = float(p["exit_stop_timeout_s"]), float(p["rest_hold_s"])
        started = time.monotonic()
        self._shutdown.set()
        with self._lock:
            moving = self._arm_may_move()
            self._hold_arm()
        if not moving:
            self.get_logger().info("stopping: no trajectory of this executor's is running")
            return ""
        rest = _RestWatch(float(p["still_speed_radps"]), hold_s, since_s=started)
        deadline = started + timeout_s
        while time.monotonic() < deadline and not (rest.confirmed and not self._busy):
            spin_once(0.01)
            with self._lock:
                rest.update(self._last_state)
        took = time.monotonic() - started
        if rest.confirmed:
            self.get_logger().info(f"stopping: the arm is at rest ({took:.2f} s after the stop was commanded)")
            return ""
        return (f"could not confirm that the arm stopped within {timeout_s:.1f} s: {rest.describe()}; "
                "check the arm")

    # --- inputs -------------------------------------------------------------
    def _subscribe_inputs(self, p: dict) -> None:
        """Every franka topic is read best effort, depth 1 (qos.ROBOT_STATE_READ): that matches franka's
        best-effort broadcaster topics and its reliable joint states alike (docs/franka_contract.md)."""
        read, group = qos.ROBOT_STATE_READ, self._group
        self._joint_watch = TopicWatch(self, p["joint_states_topic"], read)
        self._wrench_watch = TopicWatch(self, p["external_wrench_topic"], read)
        self._arm_topic_watch = None   # the arm's own joint states, subscribed when joint_states has no publisher
        self.create_subscription(JointState, p["joint_states_topic"], self._on_joint_state, read, callback_group=group)
        self.create_subscription(WrenchStamped, p["external_wrench_topic"], self._on_wrench, read, callback_group=group)
        self.create_subscription(JointState, p["gripper_joint_states_topic"], self._on_gripper_joint_state, read,
                                 callback_group=group)
        self._input_warned_at_s = {}   # topic -> silence (s) at which it is reported next (doubling)
        steady = Clock(clock_type=ClockType.STEADY_TIME)   # a stopped sim clock must not stop the check
        self.create_timer(INPUT_CHECK_PERIOD_S, self._watch_inputs, callback_group=group, clock=steady)

    def _input_watches(self) -> list:
        return [w for w in (self._joint_watch, self._arm_topic_watch, self._wrench_watch) if w is not None]

    def _watch_inputs(self) -> None:
        """Say in the log which input topic is silent and why (TopicWatch.diagnosis); read the arm from
        arm_joint_states_topic when joint_states_topic has no publisher and that one has."""
        p = self._params()
        silent_limit_s = float(p["silent_topic_s"])
        if (self._arm_topic_watch is None and self._joint_watch.silent_s() >= silent_limit_s
                and not self._joint_watch.publishers()):
            candidate = TopicWatch(self, p["arm_joint_states_topic"], qos.ROBOT_STATE_READ)
            if candidate.publishers():
                self.get_logger().warning(
                    f"{self._joint_watch.resolved} has no publisher: reading the arm from {candidate.resolved} "
                    f"(the finger width from {p['gripper_joint_states_topic']} or the gripper's action feedback)")
                self._arm_topic_watch = candidate
                self.create_subscription(JointState, p["arm_joint_states_topic"], self._on_joint_state,
                                         qos.ROBOT_STATE_READ, callback_group=self._group)
        for watch in self._input_watches():
            silent_s = watch.silent_s()
            if silent_s < silent_limit_s:
                self._input_warned_at_s.pop(watch.topic, None)
                continue
            if silent_s >= self._input_warned_at_s.get(watch.topic, silent_limit_s):
                self.get_logger().warning(watch.diagnosis())
                self._input_warned_at_s[watch.topic] = silent_s * 2.0

    def _joint_states_diagnosis(self, timeout_s: float) -> str:
        """'' when the arm's joint states arrived within timeout_s, else why not (TopicWatch.diagnosis)."""
        watches = [w for w in (self._joint_watch, self._arm_topic_watch) if w is not None]
        if any(w.silent_s() <= timeout_s for w in watches):
            return ""
        return "; ".join(w.diagnosis() for w in watches)

    def _on_joint_state(self, msg: JointState):
        try:
            state = joint_state_to_arm(msg, self._arm_joints, self._finger_joints)
        except (GoalError, IndexError) as error:
            self.get_logger().warning(f"ignoring joint state: {error}", throttle_duration_sec=2.0)
            return
        stamp_ns = stamp_to_ns(msg.header.stamp) or self.get_clock().now().nanoseconds
        with self._lock:
            for watch in self._input_watches():
                if watch is not self._wrench_watch:
                    watch.heard()   # either arm topic: the fallback's subscription shares this callback
            if math.isfinite(state.gripper_width_m):
                self._finger_widths["joint_states"] = (state.gripper_width_m, time.monotonic())
            state = dataclasses.replace(state, gripper_width_m=self._gripper_width_m())
            if len(msg.velocity) != len(msg.name):   # a driver without velocities: zeros would read "at rest"
                qd = self._velocity_estimate.update(state.q_rad, stamp_ns * 1e-9)
                state = dataclasses.replace(state, qd_radps=qd)
            self._last_state = (state, time.monotonic())
            self._watch.update(state.q_rad, stamp_ns * 1e-9)
            if self._sequence is not None:
                self._sequence.on_joint_state(state, self._last_state[1])

    def _on_gripper_joint_state(self, msg: JointState):
        """franka_gripper's own joint states: the two fingers, each at half the width."""
        index = {name: i for i, name in enumerate(msg.name)}
        if not all(n in index and index[n] < len(msg.position) for n in self._finger_joints):
            self.get_logger().warning(f"ignoring gripper joint state: it lacks {list(self._finger_joints)} "
                                      f"(got {list(msg.name)})", throttle_duration_sec=5.0)
            return
        width_m = float(sum(msg.position[index[n]] for n in self._finger_joints))
        if math.isfinite(width_m):
            with self._lock:
                self._finger_widths["gripper"] = (width_m, time.monotonic())

    def _on_wrench(self, msg: WrenchStamped):
        force = np.array([msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z])
        if not np.all(np.isfinite(force)):
            return
        with self._lock:
            self._wrench_watch.heard()
            self._last_force, self._last_force_wall_s = force, time.monotonic()
            if self._sequence is not None:
                self._sequence.on_force(force)

    # --- goals --------------------------------------------------------------
    def _on_goal(self, goal) -> GoalResponse:
        with self._lock:
            if self._busy:
                self.get_logger().warning("rejecting pick-and-place goal: busy with another goal")
                return GoalResponse.REJECT
            self._busy = True
        return GoalResponse.ACCEPT

    def _execute(self, goal_handle):
        started = time.monotonic()
        result = PickAndPlace.Result()
        try:
            self._take_parameters()
            if goal_handle.request.plan_grasp:
                moved = self._observe_before_planning(goal_handle)
                if moved is not None and not moved.success:
                    return self._finish(goal_handle, moved, result)
            result.grasp_used = grasp = self._resolve_grasp(goal_handle.request)
            p = self._params()
            place = self._place_for(goal_handle.request, p)
            sequence = self._sequence_for(grasp, place, p, self._squeeze_for(goal_handle.request, p))
            if goal_handle.request.plan_grasp and p["plan_grasp_alternatives"] > 1:
                result.grasp_used, sequence = self._reachable_alternative(grasp, sequence, place, p)
            self._wait_for_servers(p["server_wait_s"])
            self._check_inputs(p)
            return self._run(goal_handle, sequence, result)
        except (GoalError, ValueError) as error:
            with self._lock:   # raised while a sequence drove the arm (shutdown, a stop it could not plan):
                driving = self._sequence is not None   # its motion must not run on unwatched
                if isinstance(error, RobotRestarted):
                    # The restarted controller holds its own state; a hold at the position measured before the
                    # restart would send the new arm there at once (30 rad/s in the safety soak's simulator).
                    self._last_state = None
                if driving:
                    self._hold_arm()
            if driving:
                self._wait_for_rest()
            return self._abort(goal_handle, result, str(error), started)
        except Exception as error:  # noqa: BLE001 - a bug must not take the action server down
            self.get_logger().error(f"pick-and-place failed unexpectedly: {error!r}")
            with self._lock:
                self._hold_arm()
            self._wait_for_rest()
            return self._abort(goal_handle, result, f"internal error: {error!r}", started)
        finally:
            with self._lock:
                self._sequence, self._busy = None, False

    def _wait_for_rest(self) -> None:
        """After a hold: answer only once joint states show the arm at rest (at most stop_timeout_s, wall clock;
        the result's arm_state then says 'moving'), so no motion follows a terminal result."""
        config = self._config
        rest = _RestWatch(config.still_speed_radps, config.rest_hold_s, since_s=time.monotonic())
        deadline = time.monotonic() + config.stop_timeout_s
        while not rest.confirmed and time.monotonic() < deadline:
            time.sleep(0.01)
            with self._lock:
                rest.update(self._last_state)

    def _abort(self, goal_handle, result, reason: str, started: float):
        result.success, result.failure_reason = False, reason
        result.phase_reached = result.phase_reached or "pre_grasp"
        result.duration_s = time.monotonic() - started
        with self._lock:  # the arm did not move for this goal (or a bug stopped it): say how it is now
            state = self._last_state[0] if self._last_state is not None else None
        result.arm_state = arm_state_of(state.q_rad if state else None, state.qd_radps if state else None,
                                        self._watch.observation_q_rad, self._config.observation_tolerance_rad,
                                        self._config.still_speed_radps)
        self.get_logger().warning(f"pick-and-place aborted: {reason}")
        goal_handle.abort()
        return result

    def _check_inputs(self, p: dict) -> None:
        """GoalError unless joint states and an external wrench arrived within watchdog_timeout_s, saying which
        topic is silent and what the graph shows (TopicWatch.diagnosis). Without the wrench the descent would
        read zeros and descend blind into the object or the table (a wrong topic, a QoS mismatch, a dead
        broadcaster); without joint states nothing can be planned from where the arm is."""
        timeout_s = float(p["watchdog_timeout_s"])
        joints = self._joint_states_diagnosis(timeout_s)
        if joints:
            raise GoalError(f"no joint states: {joints}")
        if self._wrench_watch.silent_s() > timeout_s:
            raise GoalError(f"no external wrench, the descent's contact guard would be blind: "
                            f"{self._wrench_watch.diagnosis()}; check franka_robot_state_broadcaster")

    def _sequence_for(self, grasp, place, p: dict, squeeze: SqueezeRequest | None = None) -> PickPlaceSequence:
        return PickPlaceSequence(self._kin, self._config,
                                 grasp_target(grasp, p["base_frame"], p["default_youngs_modulus_pa"]), place, squeeze)

    @staticmethod
    def _squeeze_for(request, p: dict) -> SqueezeRequest | None:
        """The goal's squeeze (measure_stiffness, measure_only), or None."""
        if not (request.measure_stiffness or request.measure_only):
            return None
        return SqueezeRequest(only=bool(request.measure_only),
                              width_resolution_m=float(p["squeeze_width_resolution_m"]),
                              settle_s=float(p["squeeze_settle_s"]), speed_mps=float(p["squeeze_speed_mps"]))

    def _reachable_alternative(self, grasp, sequence: PickPlaceSequence, place, p: dict):
        """(grasp, sequence) to run: the planned best grasp, unless the sequence would refuse it before the arm
        moves (near the base its straight lift can run out of reach); then the first of the service's
        plan_grasp_alternatives ranked grasps that can be made. If none can, the best one (its refusal is the
        goal's result, as without alternatives)."""
        with self._lock:
            q_now = self._last_state[0].q_rad if self._last_state is not None else None
        reason = "" if q_now is None else sequence.plan_failure(q_now)
        if not reason:
            return grasp, sequence
        count = int(p["plan_grasp_alternatives"])
        self.get_logger().info(f"best grasp would be refused ({reason}); asking for {count} ranked grasps")
        for rank, candidate in enumerate(self._planned_grasps(count), start=1):
            try:
                other = self._sequence_for(candidate, place, p, sequence.squeeze_request)
            except (GoalError, ValueError):
                continue
            if not other.plan_failure(q_now):
                self.get_logger().info(f"picking ranked grasp {rank} of {count} instead")
                return candidate, other
        return grasp, sequence

    def _resolve_grasp(self, request):
        if not request.plan_grasp:
            return request.grasp
        return self._planned_grasps(1)[0]

    def _planned_grasps(self, top_k: int) -> list:
        """The grasp service's top_k grasps (best first, at least one) on a frame taken while the arm rested at
        the observation pose."""
        p = self._params()
        if not self._plan_client.wait_for_service(timeout_sec=p["server_wait_s"]):
            raise GoalError(f"grasp service {p['plan_grasp_service']} is not available")
        # Only a grasp from a frame taken while the arm rested at the observation pose: an older frame
        # may show the arm (after a cancel it stood over the table), and a grasp on it lands on the hand.
        deadline = time.monotonic() + float(p["fresh_frame_timeout_s"])
        while True:
            try:  # planning on the latest frame is idempotent: re-sent while unanswered (ros_service.py)
                response = call_idempotent(self._plan_client, PlanGrasp.Request(top_k=top_k),
                                           p["plan_grasp_timeout_s"], "grasp service")
            except (ServiceTimeout, RuntimeError) as error:
                raise GoalError(str(error)) from None
            grasp = response.grasps[0] if response.success and response.grasps else None
            frame_s = stamp_to_ns(grasp.header.stamp) * 1e-9 if grasp is not None else None
            with self._lock:
                clear = frame_s is not None and self._watch.frame_is_clear(frame_s)
                arrived_s = self._watch.since_s
            if clear:
                return list(response.grasps)
            if arrived_s is None:
                raise GoalError("not planning: the arm left the observation pose, so it may be in the camera's view")
            if time.monotonic() >= deadline:
                if grasp is not None:
                    raise GoalError(f"not planning on a view with the arm in it: no camera frame taken after the "
                                    f"arm reached the observation pose within {p['fresh_frame_timeout_s']:.0f} s "
                                    f"(newest frame {arrived_s - frame_s:.1f} s older)")
                raise GoalError(f"grasp planning failed: {response.message or 'no grasp returned'}")
            if self._shutdown.wait(0.5):  # the camera's next frame is on its way (each try runs the network)
                raise GoalError("executor is shutting down")

    def _observe_before_planning(self, goal_handle):
        """Bring the arm to the observation pose unless it rests there; the move's outcome (None: no move)."""
        with self._lock:
            if self._watch.at_observation():
                return None
        config = dataclasses.replace(self._config, observation_q_rad=tuple(self._watch.observation_q_rad))
        move = ObservationMove(self._kin, config)
        self._drive(goal_handle, move)
        if not move.outcome.success and not move.outcome.canceled:
            reason = move.outcome.failure_reason
            move.outcome.failure_reason = f"not planning with the arm in the camera's view: {reason}"
        return move.outcome

    def _wait_for_servers(self, timeout_s: float):
        for client, name in ((self._arm_client, "arm_trajectory_action"), (self._move_client, "gripper_move_action"),
                             (self._grasp_client, "gripper_grasp_action")):
            if not client.wait_for_server(timeout_sec=timeout_s):
                raise GoalError(f"action server {self.resolve_topic_name(self._params()[name])} is not available")

    # --- the control loop ---------------------------------------------------
    def _clocks(self) -> tuple[float, float]:
        return self.get_clock().now().nanoseconds * 1e-9, time.monotonic()

    def _run(self, goal_handle, sequence: PickPlaceSequence, result):
        try:
            self._drive(goal_handle, sequence)
        finally:   # the hand opened in the slot: an object lies there now (even if the run failed later)
            if self._goal_slot is not None and sequence.released_at_place:
                with self._lock:
                    self._bin.mark_used(self._goal_slot)
        if sequence.squeeze_requested:
            self._report_squeeze(sequence, result)
        return self._finish(goal_handle, sequence.outcome, result)

    def _report_squeeze(self, sequence: PickPlaceSequence, result) -> None:
        """The squeeze's readings and estimate into the result; the estimate to the segmentation node."""
        result.squeeze_forces_n = [r.force_n for r in sequence.squeeze_readings]
        result.squeeze_widths_m = [r.width_m for r in sequence.squeeze_readings]
        estimate = sequence.squeeze_estimate
        if estimate is None:
            result.stiffness_update = "not measured: the goal ended before the squeeze was done"
            return
        result.stiffness_measured, result.measured_rigid = True, estimate.rigid
        result.measured_youngs_modulus_pa = estimate.youngs_modulus_pa
        result.stiffness_lower_bound = estimate.lower_bound
        result.measured_modulus_low_pa, result.measured_modulus_high_pa = estimate.low_pa, estimate.high_pa
        result.squeeze_stiffness_npm = estimate.stiffness_npm
        modulus_pa = planning_modulus_pa(estimate)
        result.stiffness_update = self._stiffness.tell(result.grasp_used, modulus_pa,
                                                       float(self._params()["stiffness_update_timeout_s"]))
        if result.stiffness_update.startswith("sent"):
            result.stiffness_sent_pa = modulus_pa
            with self._lock:   # the next plan_grasp goal plans on a frame perceived with the measurement
                self._watch.frames_from(self._clocks()[0])
        self.get_logger().info(f"squeeze: {estimate.describe()}; {result.stiffness_update}")

    def _drive(self, goal_handle, sequence: PickPlaceSequence) -> None:
        """Run the control loop until the sequence finishes (a cancel request goes to the sequence)."""
        period = float(self._params()["control_period_s"])
        with self._lock:
            self._sequence = sequence
            if self._last_state is not None:
                sequence.on_joint_state(*self._last_state)
            sequence.on_force(self._last_force)
            self._carry_out(sequence, sequence.start(*self._clocks()))
        cancel_sent = False
        robot_s = self._clocks()[0]
        while not sequence.finished:
            if self._shutdown.wait(period):
                raise GoalError("executor is shutting down")
            robot_s = self._check_clock(robot_s)
            with self._lock:
                if goal_handle.is_cancel_requested and not cancel_sent:
                    cancel_sent = True
                    self._carry_out(sequence, sequence.cancel(*self._clocks()))
                self._carry_out(sequence, sequence.tick(*self._clocks()))
                feedback = sequence.feedback(self._clocks()[0])
            goal_handle.publish_feedback(PickAndPlace.Feedback(
                phase=feedback.phase, phase_progress=feedback.phase_progress,
                gripper_width_m=feedback.gripper_width_m, external_force_n=feedback.external_force_n))

    def _check_clock(self, before_s: float) -> float:
        """The robot clock now; GoalError when it went back more than CLOCK_JUMP_BACK_S since before_s. A restarted
        simulator starts its /clock at 0 again: every motion and gripper wait of the sequence counts on the robot
        clock and would wait until it came back to where it was (the safety soak's goal hung 300 s, unanswered),
        while the new driver knows nothing of the goals the old one ran."""
        now_s = self._clocks()[0]
        if now_s < before_s - CLOCK_JUMP_BACK_S:
            raise RobotRestarted(f"the robot clock jumped back from {before_s:.1f} s to {now_s:.1f} s (a restarted "
                            "driver or simulator): its trajectory and gripper goals are gone")
        return now_s

    def _finish(self, goal_handle, outcome, result):
        for field in ("success", "failure_reason", "phase_reached", "contact_detected", "contact_height_m",
                      "gripper_width_closed_m", "gripper_force_n", "held_after_lift", "held_after_transfer",
                      "duration_s", "arm_state", "recovery"):
            setattr(result, field, getattr(outcome, field))
        if outcome.success:
            goal_handle.succeed()
        elif outcome.canceled:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        # Two call sites on purpose: rclpy refuses to change the severity of
        # one logging call site between calls.
        summary = f"(phase {outcome.phase_reached}, {outcome.duration_s:.1f} s, arm {outcome.arm_state}" + (
            f"; recovery: {outcome.recovery})" if outcome.recovery else ")")
        if outcome.success:
            self.get_logger().info(f"pick-and-place done {summary}")
        else:
            self.get_logger().warning(f"pick-and-place ended: {outcome.failure_reason} {summary}")
        return result

    def _carry_out(self, sequence: PickPlaceSequence, commands):
        """Execute the sequence's commands (called with the lock held)."""
        for command in commands:
            if isinstance(command, SendTrajectory):
                self._send_arm(command.trajectory)
            elif isinstance(command, MoveGripper):
                goal = Move.Goal(width=command.width_m, speed=command.speed_mps)
                self._send_gripper(sequence, self._move_client, goal)
            elif isinstance(command, GraspGripper):
                c = command.command
                epsilon = GraspEpsilon(inner=c.epsilon_inner_m, outer=c.epsilon_outer_m)
                goal = Grasp.Goal(width=c.width_m, epsilon=epsilon, speed=c.speed_mps, force=c.force_n)
                self._send_gripper(sequence, self._grasp_client, goal)
            elif isinstance(command, CancelGripper) and self._gripper_goal is not None:
                self._gripper_goal.cancel_goal_async()
                self._gripper_goal = None

    def _send_arm(self, trajectory) -> None:
        """Send a trajectory as a FollowJointTrajectory goal (lock held); it replaces the running one.

        The joint_trajectory_controller starts a goal stamped 0 on receipt and blends it from where the
        arm is, so each new command replaces the previous goal there. The sequence watches the joint
        states for arrival; a rejected or aborted goal is logged here (the sequence then fails on its
        settle timeout, naming the phase).
        """
        self._arm_goal_serial += 1
        serial = self._arm_goal_serial
        goal = FollowJointTrajectory.Goal(
            trajectory=trajectory_to_msg(trajectory, self._params()["base_frame"], self._arm_joints))

        def on_result(future):
            result = future.result().result
            with self._lock:
                if serial == self._arm_goal_serial:
                    self._arm_goal = None   # ended: nothing left to cancel
            if serial == self._arm_goal_serial and result.error_code != FollowJointTrajectory.Result.SUCCESSFUL:
                self.get_logger().error(f"arm trajectory failed (error_code {result.error_code}): "
                                        f"{result.error_string}")

        def on_goal(future):
            handle = future.result()
            with self._lock:
                self._arm_goals_unanswered -= 1
            if not handle.accepted:
                self.get_logger().error("the arm's trajectory controller rejected a trajectory goal")
                return
            with self._lock:
                if serial == self._arm_goal_serial:
                    self._arm_goal = handle
                elif self._held_serial == self._arm_goal_serial:
                    handle.cancel_goal_async()  # accepted after a stop was requested: it must not run
            handle.get_result_async().add_done_callback(on_result)

        self._arm_goals_unanswered += 1
        self._arm_client.send_goal_async(goal).add_done_callback(on_goal)

    def _arm_may_move(self) -> bool:
        """Could a trajectory of this node's still move the arm (lock held)? A goal runs, a sent one is not yet
        answered, or a sequence drives the arm."""
        return self._sequence is not None or self._arm_goal is not None or self._arm_goals_unanswered > 0

    def _hold_arm(self) -> None:
        """Stop the arm where it is (lock held): cancel the running goal (joint_trajectory_controller then holds its
        current state) and, as a second command that does not depend on the cancel being answered, send a one-point
        trajectory at the measured position (an empty trajectory is refused by the controller). Only when this node
        has a goal that may still move the arm; a failed send is logged, never raised: the caller is on its way out.
        Tried and dropped (2026-11-29, simulated arm, transfer): the hold sent before the cancel, at the measured
        position carried on for the state's age (or further, to a 0.1 s deceleration's end): the simulated
        controller starts a new trajectory from rest, and the arm then moved at 3.5-4.2 rad/s after the signal."""
        moving = self._arm_may_move()
        self._arm_goal_serial += 1
        self._held_serial = self._arm_goal_serial
        try:
            if self._arm_goal is not None:
                self._arm_goal.cancel_goal_async()
                self._arm_goal = None
            if moving and self._last_state is not None:
                hold = hold_trajectory_msg(self._last_state[0].q_rad, self._params()["base_frame"], self._arm_joints)
                self._arm_client.send_goal_async(FollowJointTrajectory.Goal(trajectory=hold))
        except Exception as error:  # noqa: BLE001 - rclpy raises RCLError/InvalidHandle once torn down
            self.get_logger().error(f"could not command the arm to stop: {error!r}")

    def _gripper_width_m(self) -> float:
        """The finger width now (lock held), from the first source that has spoken within FINGER_SOURCE_FRESH_S:
        franka_gripper's own joint states, then the fingers in the merged joint states (under franka_ros2's
        MoveIt launch these stay at the URDF default 0.0 m, so they come second), else the gripper action's
        last feedback (franka_msgs results carry no width). NaN when none has."""
        now_s = time.monotonic()
        for source in ("gripper", "joint_states"):
            width_m, heard_s = self._finger_widths.get(source, (None, -math.inf))
            if now_s - heard_s <= FINGER_SOURCE_FRESH_S:
                return width_m
        return self._gripper_feedback_width_m

    def _send_gripper(self, sequence: PickPlaceSequence, client: ActionClient, goal):
        # Only the newest gripper goal answers the sequence: the result of one canceled or preempted before (a
        # cancel during close, then the recovery's opening) came after the next was sent and read as its failure
        # ("the hand did not open: preempted by a newer gripper command"; the arm stayed over the table).
        self._gripper_serial += 1
        serial = self._gripper_serial

        def newest() -> bool:   # lock held
            return self._sequence is sequence and serial == self._gripper_serial

        def on_feedback(feedback_msg):
            self._gripper_feedback_width_m = float(feedback_msg.feedback.current_width)

        def on_result(future):
            result = future.result().result
            with self._lock:
                if newest():  # a late result of an earlier goal must not leak in
                    sequence.on_gripper_result(result.success, self._gripper_width_m(), result.error)

        def on_goal(future):
            handle = future.result()
            if not handle.accepted:
                with self._lock:
                    if newest():
                        sequence.on_gripper_result(False, float("nan"), "gripper goal rejected")
                return
            with self._lock:
                self._gripper_goal = handle
            handle.get_result_async().add_done_callback(on_result)

        client.send_goal_async(goal, feedback_callback=on_feedback).add_done_callback(on_goal)


def main(args=None):
    run_node("executor_node", ExecutorNode, startup_errors=(ValueError, OSError), threads=4, args=args,
             stops_hardware=True)


if __name__ == "__main__":
    main()
