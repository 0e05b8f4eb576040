"""The executor node's inputs: the arm's joint states, the fingers' width, the external wrench, and their silence.

Every franka topic is read best effort, depth 1 (docs/franka_contract.md); a silent topic is named in the log
with what the graph shows (TopicWatch), and a goal is refused while joint states or the wrench are missing.
"""
import dataclasses
import math
import time

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import JointState

from defgg_ros.nodes.executor_messages import ROBOT_ERROR, GoalError, joint_state_to_arm
from defgg_ros.nodes.topic_watch import TopicWatch
from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import stamp_to_ns
from defgg_ros.ros.latest_reader import LatestMessageReader

# How often the input topics' silence is checked (wall clock, s).
INPUT_CHECK_PERIOD_S = 1.0
# A finger width source older than this gives way to the next one (wall clock, s). franka_gripper publishes at
# 15 Hz; the simulated one at 15 Hz of sim time, and its clock stalls up to ~2 s while a frame renders: a shorter
# limit handed the width to the MoveIt launch's constant 0.0 in joint_states meanwhile.
FINGER_SOURCE_FRESH_S = 3.0
# How often a goal waiting for the first input message looks again (wall clock, s).
FIRST_INPUT_POLL_S = 0.05

class RobotInputs:
    """Joint states, the fingers and the external wrench in (mixed into ExecutorNode)."""

    def _subscribe_inputs(self, p: dict) -> None:
        """Every franka topic is read best effort, depth 1 (qos.ROBOT_STATE_READ): that matches franka's
        best-effort broadcaster topics and its reliable joint states alike (docs/franka_contract.md)."""
        read, group = qos.ROBOT_STATE_READ, self._group
        self._joint_watch = TopicWatch(self, p["joint_states_topic"], read)
        self._wrench_watch = TopicWatch(self, p["external_wrench_topic"], read)
        self._arm_topic_watch = None   # the arm's own joint states, subscribed when joint_states has no publisher
        self.create_subscription(JointState, p["joint_states_topic"], self._on_joint_state, read, callback_group=group)
        # 1 kHz on a Franka: taken at the control ticks and input checks, not handed to a callback (LatestMessageReader)
        self._wrench_reader = LatestMessageReader(self, WrenchStamped, p["external_wrench_topic"], read, "wrench")
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
        self._take_wrench()
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
            state = dataclasses.replace(state, gripper_width_m=self._gripper_width_m(), stamp_s=stamp_ns * 1e-9)
            if len(msg.velocity) != len(msg.name):   # a driver without velocities: zeros would read "at rest"
                qd = self._velocity_estimate.update(state.q_rad, stamp_ns * 1e-9)
                state = dataclasses.replace(state, qd_radps=qd)
            self._last_state = (state, time.monotonic())
            self._last_acceleration = self._acceleration_estimate.update(state.qd_radps, stamp_ns * 1e-9)
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

    def _take_wrench(self) -> None:
        """The newest external wrench, if one came since the last take (lock not held): the force the contact
        guards read, when it arrived, and the wrench topic heard then."""
        taken = self._wrench_reader.take()
        if taken is None:
            return
        msg, age_s = taken
        force = np.array([msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z])
        if not np.all(np.isfinite(force)):
            return
        arrived_s = time.monotonic() - age_s
        with self._lock:
            self._wrench_watch.heard(arrived_s)
            self._last_force, self._last_force_wall_s = force, arrived_s
            if self._sequence is not None:
                self._sequence.on_force(force, self._last_force_wall_s)

    def _wait_for_first_inputs(self, timeout_s: float) -> None:
        """A goal that comes before the first joint state, wrench or (use_sim_time) clock message, right after
        the cell started (discovery, a controller still coming up, a simulated driver rendering its first frame),
        waits up to timeout_s for them; _check_inputs then judges. An input heard before and silent now is not
        waited for: its driver stopped. (CI, 2026-12-01: a goal sent as soon as the bringup was ready found no
        joint state 3.3 s after the executor started and was refused, though the driver was up.)"""
        deadline_s = time.monotonic() + timeout_s
        self._take_wrench()
        while time.monotonic() < deadline_s and (any(w.last_s is None for w in self._input_watches())
                                                 or self._waiting_for_sim_clock()):
            if self._shutdown.wait(FIRST_INPUT_POLL_S):
                raise GoalError("executor is shutting down")
            self._take_wrench()

    def _waiting_for_sim_clock(self) -> bool:
        """use_sim_time and no /clock message yet: the robot clock reads 0, and a sequence started on it would
        see its first tick jump to the simulator's time."""
        return bool(self.get_parameter("use_sim_time").value) and self.get_clock().now().nanoseconds == 0

    def _check_inputs(self, p: dict) -> None:
        """GoalError unless joint states and an external wrench arrived within watchdog_timeout_s, saying which
        topic is silent and what the graph shows (TopicWatch.diagnosis). Without the wrench the descent would
        read zeros and descend blind into the object or the table (a wrong topic, a QoS mismatch, a dead
        broadcaster); without joint states nothing can be planned from where the arm is."""
        timeout_s = float(p["watchdog_timeout_s"])
        self._take_wrench()
        joints = self._joint_states_diagnosis(timeout_s)
        if joints:
            raise GoalError(f"no joint states: {joints}")
        if self._waiting_for_sim_clock():
            raise GoalError("no clock: use_sim_time is true and no message arrived on /clock (is the simulator "
                            "publishing it, in this ROS domain?)")
        with self._lock:
            robot_error = self._in_robot_error()
        if robot_error:
            raise GoalError(f"{ROBOT_ERROR} {time.monotonic() - self._robot_error_wall_s:.0f} s ago, and "
                            f"franka_robot_state_broadcaster has been quiet since: recover the robot first "
                            f"({topics.RECOVERY_STEPS}; docs/real_cell.md)")
        if self._wrench_watch.silent_s() > timeout_s:
            raise GoalError(f"no external wrench, the descent's contact guard would be blind: "
                            f"{self._wrench_watch.diagnosis()}; check franka_robot_state_broadcaster (inactive "
                            "after a robot error: ros2 control list_controllers)")

    def _in_robot_error(self) -> bool:
        """Lock held: the arm's controller was deactivated under a goal and no wrench came since (the robot state
        broadcaster, deactivated with it, publishes again once the robot is recovered)."""
        since_s = self._robot_error_wall_s
        return since_s is not None and (self._last_force_wall_s is None or self._last_force_wall_s < since_s)

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
