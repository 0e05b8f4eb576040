"""The executor node's commands to the arm and the hand, and its stop before the process exits.

FollowJointTrajectory goals to the arm's joint_trajectory_controller, franka_msgs Move/Grasp goals to
franka_gripper (docs/real_cell.md); a stop that preempts the running goal (the sequence's, else a one-point
hold to rest; a cancel only if refused) on every way out (docs/reliability.md). Only the newest goal of each
kind answers the sequence.
"""
import time

from control_msgs.action import FollowJointTrajectory
from franka_msgs.action import Grasp, Move
from franka_msgs.msg import GraspEpsilon

from defgg_ros.control.observation import RestWatch
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import CancelGripper, GraspGripper, MoveGripper, SendTrajectory
from defgg_ros.control.stopping import MAX_STATE_AGE_S, stopping_hold
from defgg_ros.control.trajectories import arm_limits
from defgg_ros.nodes.executor_messages import ROBOT_ERROR, hold_trajectory_msg, trajectory_to_msg
from defgg_ros.ros import topics
from defgg_ros.ros.action import ActionClient, in_executor

# A hold's acceptance normally comes in milliseconds; one this late is treated as refused (a response can be lost).
HOLD_ANSWER_TIMEOUT_S = 1.0
# The stop on the way out waits this long (wall clock) at most for a joint state taken in after the stop was asked
# for: a process starved of the CPU (a loaded machine) holds a state from before the starvation, the stop planned on
# it is stamped on a stale clock and reaches the controller after its own end (on a loaded 2-core machine, a state
# 0.54 s old: the controller, taking such a stop, pulled the arm back 1.1 rad). Joint states come at 100 Hz or more.
FRESH_STATE_WAIT_S = 0.15


class ArmCommands:
    """Trajectory and gripper goals out, the stop on the way out (mixed into ExecutorNode: its lock, clients and
    the state they guard)."""

    def stop_for_exit(self, spin_once) -> str:
        """Before the process tears anything down (run_node calls this on SIGINT/SIGTERM or a callback's
        exception): end the control loop, command a stop that preempts the trajectory goal and slows the arm to
        rest ahead of it (_hold_arm), then keep spinning (spin_once(timeout_s)) until joint states
        confirm the arm at rest and the running goal is answered. Returns '' when the arm is confirmed at rest
        (or this node never moved it), else why not (the process then exits 1)."""
        p = self._params()
        timeout_s, hold_s = float(p["exit_stop_timeout_s"]), float(p["rest_hold_s"])
        started = time.monotonic()
        self._shutdown.set()
        with self._lock:
            may_move = self._arm_may_move()
        if may_move:
            self._take_in_a_fresh_state(spin_once, started)
        with self._lock:
            moving = self._arm_may_move()
            self._hold_arm()
        if not moving:
            self.get_logger().info("stopping: no trajectory of this executor's is running")
            return ""
        rest = RestWatch(float(p["still_speed_radps"]), hold_s, since_s=started)
        deadline = started + timeout_s
        while time.monotonic() < deadline and not (rest.confirmed and not self._busy and self._stop_answered()):
            spin_once(0.01)
            with self._lock:
                rest.update(self._last_state)
                self._expire_hold_answer()
        took = time.monotonic() - started
        if rest.confirmed:
            self.get_logger().info(f"stopping: the arm is at rest ({took:.2f} s after the stop was commanded)")
            return ""
        return (f"could not confirm that the arm stopped within {timeout_s:.1f} s: {rest.describe()}; "
                "check the arm")

    def _take_in_a_fresh_state(self, spin_once, since_s: float) -> None:
        """Spin until a joint state received after since_s (monotonic) is in, at most FRESH_STATE_WAIT_S; the stop
        is then planned on it. Without one (the driver silent, or this process starved) _stopping_hold finds the last
        one too old and cancels the goal instead."""
        deadline = since_s + FRESH_STATE_WAIT_S
        while not self._fresh_state_since(since_s) and time.monotonic() < deadline:
            spin_once(0.005)
        if not self._fresh_state_since(since_s):
            self.get_logger().warning(f"stopping: no joint state within {FRESH_STATE_WAIT_S:g} s of the request")

    def _fresh_state_since(self, since_s: float) -> bool:
        with self._lock:
            return self._last_state is not None and self._last_state[1] >= since_s

    def _stop_answered(self) -> bool:
        """Every goal sent is answered and the hold accepted, refused or given up on (after HOLD_ANSWER_TIMEOUT_S):
        an arm at rest before a late goal starts is not yet stopped."""
        with self._lock:
            return self._arm_goals_unanswered == 0 and self._hold_answer != "pending"

    def _wait_for_rest(self) -> None:
        """After a hold: answer only once joint states show the arm at rest (at most stop_timeout_s, wall clock;
        the result's arm_state then says 'moving'), so no motion follows a terminal result."""
        config = self._config
        rest = RestWatch(config.still_speed_radps, config.rest_hold_s, since_s=time.monotonic())
        deadline = time.monotonic() + config.stop_timeout_s
        while not (rest.confirmed and self._stop_answered()) and time.monotonic() < deadline:
            time.sleep(0.01)
            with self._lock:
                rest.update(self._last_state)
                self._expire_hold_answer()

    def _carry_out(self, sequence: PickPlaceSequence, commands):
        """Execute the sequence's commands (called with the lock held)."""
        for command in commands:
            if isinstance(command, SendTrajectory):
                self._send_arm(command.trajectory, command.start_s, sequence)
            elif isinstance(command, MoveGripper):
                goal = Move.Goal(width=command.width_m, speed=command.speed_mps)
                self._send_gripper(sequence, self._move_client, goal)
            elif isinstance(command, GraspGripper):
                c = command.command
                epsilon = GraspEpsilon(inner=c.epsilon_inner_m, outer=c.epsilon_outer_m)
                goal = Grasp.Goal(width=c.width_m, epsilon=epsilon, speed=c.speed_mps, force=c.force_n)
                self._send_gripper(sequence, self._grasp_client, goal)
            elif isinstance(command, CancelGripper):
                # The newest goal may not be accepted yet (its handle is not in _gripper_goal): on_goal cancels it.
                self._gripper_canceled_serial = self._gripper_serial
                if self._gripper_goal is not None:
                    self._gripper_goal.cancel_goal_async()
                    self._gripper_goal = None

    def _send_arm(self, trajectory, start_s: float | None = None, sequence: PickPlaceSequence | None = None) -> None:
        """Send a trajectory as a FollowJointTrajectory goal (lock held); it replaces the running one.

        The joint_trajectory_controller starts a goal stamped 0 on receipt (start_s None), else at start_s
        (robot time), and blends it from where the arm is into its first point while that is ahead, so each new
        command replaces the previous goal there. The sequence watches the joint
        states for arrival; a rejected or aborted goal is logged here (the sequence then fails on its
        settle timeout, naming the phase). The sequence that sent it learns the goal's round trip (its stops lead
        by at least that much).
        """
        sent_robot_s = sequence.robot_now_s(time.monotonic()) if sequence is not None else float("nan")
        self._arm_goal_serial += 1
        serial = self._arm_goal_serial
        goal = FollowJointTrajectory.Goal(
            trajectory=trajectory_to_msg(trajectory, self._params()["base_frame"], self._arm_joints, start_s))

        def on_result(future):
            result = future.result().result
            with self._lock:
                if serial == self._arm_goal_serial:
                    self._arm_goal = None   # ended: nothing left to cancel
            if (result.error_code, result.error_string) == (FollowJointTrajectory.Result.INVALID_GOAL,
                                                            topics.CONTROLLER_DEACTIVATED_TEXT):
                self._on_robot_error(sequence)
            elif serial == self._arm_goal_serial and result.error_code != FollowJointTrajectory.Result.SUCCESSFUL:
                self.get_logger().error(f"arm trajectory failed (error_code {result.error_code}): "
                                        f"{result.error_string}")

        def on_goal(future):
            handle = future.result()
            with self._lock:
                self._arm_goals_unanswered -= 1
                if sequence is not None:
                    sequence.on_goal_answered(sequence.robot_now_s(time.monotonic()) - sent_robot_s)
            if not handle.accepted:   # an inactive controller rejects every goal: after a robot error until recovered
                self.get_logger().error("the arm's trajectory controller rejected a trajectory goal (is it active? "
                                        "ros2 control list_controllers)")
                return
            with self._lock:
                if serial == self._arm_goal_serial:
                    self._arm_goal = handle
                elif self._held_serial == self._arm_goal_serial:
                    self._stop_late_goal(handle)   # accepted after a stop was requested: it must not run
            handle.get_result_async().add_done_callback(on_result)

        self._arm_goals_unanswered += 1
        self._arm_client.send_goal_async(goal).add_done_callback(in_executor(self, on_goal))

    def _on_robot_error(self, sequence: PickPlaceSequence | None) -> None:
        """The controller's deactivation aborted a goal of ours: the run ends at once, sending nothing (every goal
        is refused now), and goals are refused until the robot is recovered (_check_inputs)."""
        with self._lock:
            self._robot_error_wall_s = time.monotonic()
            if sequence is not None:
                sequence.on_robot_error(f"{ROBOT_ERROR}; recover it: {topics.RECOVERY_STEPS}")
        self.get_logger().error(f"{ROBOT_ERROR}. Recover it (docs/real_cell.md): {topics.RECOVERY_STEPS}")

    def _arm_may_move(self) -> bool:
        """Could a trajectory of this node's still move the arm (lock held)? A goal runs, a sent one is not yet
        answered, or a sequence drives the arm."""
        return self._sequence is not None or self._arm_goal is not None or self._arm_goals_unanswered > 0

    def _hold_arm(self) -> None:
        """Stop the arm where it is (lock held), only when this node has a goal that may still move it: a one-point
        trajectory to rest (control/stopping.py: ahead of the moving arm, where a smooth deceleration from its
        velocity ends) preempts the running goal, and the controller blends into it from the measured state, so
        the arm slows down and never turns back. No cancel beside it: a cancel makes the controller hold the
        measured position at once (set_hold_position) and the hold would then set the arm moving again (stop, then
        go); the cancel is the fallback when no hold can be made or the controller does not accept it. A failed
        send is logged, never raised: the caller is on its way out."""
        carried = self._goals_the_hold_stops if self._hold_answer == "pending" else []
        moving = self._arm_may_move() or bool(carried)
        self._arm_goal_serial += 1
        self._held_serial = serial = self._arm_goal_serial
        running, self._arm_goal = self._arm_goal, None
        # What the previous hold, still unanswered, was to stop is this one's now: its answer will be stale.
        self._goals_the_hold_stops = [handle for handle in (*carried, running) if handle is not None]
        self._hold_answer = "none"
        try:
            hold = self._stopping_hold() if moving else None
            if hold is None:
                self._cancel_goals_the_hold_stops()
                return
            future = self._arm_client.send_goal_async(FollowJointTrajectory.Goal(trajectory=hold))
            self._hold_answer, self._hold_sent_s = "pending", time.monotonic()
            future.add_done_callback(in_executor(self, lambda answer: self._on_hold_answer(answer, serial)))
        except Exception as error:  # noqa: BLE001 - rclpy raises RCLError/InvalidHandle once torn down
            self.get_logger().error(f"could not command the arm to stop: {error!r}")
            self._hold_answer = "none"
            self._cancel_goals_the_hold_stops()

    def _stop_late_goal(self, handle) -> None:
        """A trajectory goal sent before the stop and accepted after it (lock held). Goals from this client reach
        the controller in the order sent, so a hold sent after it preempts it there: no cancel then, since a cancel
        that reached the controller first would make it hold the measured position at once and the hold behind it
        would set the arm moving again (stop, then go). Canceled when no hold went out or the controller refused
        it; kept with the hold's other goals while its answer is pending."""
        if self._hold_answer == "pending":
            self._goals_the_hold_stops.append(handle)
        elif self._hold_answer != "accepted":
            self._cancel_arm_goal(handle)

    def _expire_hold_answer(self) -> None:
        """A hold unanswered after HOLD_ANSWER_TIMEOUT_S (lock held; a response can be lost) counts as refused: the
        goals it was to preempt are canceled."""
        if self._hold_answer == "pending" and time.monotonic() - self._hold_sent_s > HOLD_ANSWER_TIMEOUT_S:
            self.get_logger().error(f"no answer to the hold trajectory within {HOLD_ANSWER_TIMEOUT_S:g} s: "
                                    "canceling the goals it was to preempt")
            self._hold_answer = "refused"
            self._cancel_goals_the_hold_stops()

    def _cancel_goals_the_hold_stops(self) -> None:
        goals, self._goals_the_hold_stops = self._goals_the_hold_stops, []
        for handle in goals:
            self._cancel_arm_goal(handle)

    def _stopping_hold(self):
        """The trajectory that stops the arm (None without a joint state, or without finite positions): the
        running sequence's stop (stamped ahead along its commanded motion: whenever it arrives, the controller
        blends into it from where the arm is), else a one-point hold from the last joint state."""
        if self._last_state is None:
            return None
        age_s = time.monotonic() - self._last_state[1]
        if age_s > MAX_STATE_AGE_S:
            self.get_logger().error(
                f"the newest joint state is {age_s:.2f} s old: a stop planned on it would be stamped on a stale "
                "clock (it could end before it arrives, or pull the arm back to where it was); canceling the arm's "
                "goal instead, so the controller holds where the arm is")
            return None
        frame = self._params()["base_frame"]
        if self._sequence is not None:
            try:
                stop = self._sequence.stop_now()
            except ValueError as error:   # a stop Ruckig or the checks refuse: the one-point hold below instead
                self.get_logger().error(f"the sequence's stop could not be planned: {error}")
                stop = None
            if stop is not None:
                return trajectory_to_msg(stop[0], frame, self._arm_joints, stop[1])
        state = self._last_state[0]
        limits = arm_limits(self._kin.arm, 1.0)
        try:
            q_hold, blend_s = stopping_hold(state.q_rad, state.qd_radps, age_s,
                                            limits.qdd_max_radps2, limits.q_min_rad, limits.q_max_rad,
                                            self._last_acceleration)
        except ValueError as error:
            self.get_logger().error(f"no hold trajectory: {error}")
            return None
        return hold_trajectory_msg(q_hold, frame, self._arm_joints, blend_s)

    def _on_hold_answer(self, future, serial: int) -> None:
        """A hold the controller refused (or could not be asked): cancel the goals it was to preempt instead. An
        older hold's answer changes nothing: the newest hold carries its goals."""
        try:
            accepted = future.result().accepted
        except Exception as error:  # noqa: BLE001 - any failure of the request means no hold
            accepted = False
            self.get_logger().error(f"the hold trajectory was not delivered: {error!r}")
        if not accepted:
            self.get_logger().error("the controller refused the hold trajectory")
        with self._lock:
            if serial != self._held_serial or self._hold_answer != "pending":
                return
            self._hold_answer = "accepted" if accepted else "refused"
            if accepted:
                self._goals_the_hold_stops = []
            else:
                self._cancel_goals_the_hold_stops()

    def _cancel_arm_goal(self, handle) -> None:
        if handle is None:
            return
        try:
            handle.cancel_goal_async()
        except Exception as error:  # noqa: BLE001 - rclpy raises RCLError/InvalidHandle once torn down
            self.get_logger().error(f"could not cancel the arm's goal: {error!r}")

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
                if serial == self._gripper_canceled_serial:   # canceled before it was accepted: cancel it now
                    handle.cancel_goal_async()
                elif serial == self._gripper_serial:           # an older goal accepted late is not the one to cancel
                    self._gripper_goal = handle
            handle.get_result_async().add_done_callback(on_result)

        client.send_goal_async(goal, feedback_callback=on_feedback).add_done_callback(in_executor(self, on_goal))
