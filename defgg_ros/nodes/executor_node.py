"""executor_node: the PickAndPlace action server, a thin adapter over the pure sequence.

All decisions live in `defgg_ros.control.pick_place.PickPlaceSequence`; this node holds the parameters and the
ROS side: goals and grasps in, FollowJointTrajectory goals to the arm's joint_trajectory_controller and
franka_msgs Move/Grasp goals to franka_ros2's gripper node out (docs/real_cell.md), joint states / external
wrench / gripper results back into the sequence, feedback and results to the client. Its parts:
executor_inputs.py (topics in), executor_arm.py (goals out, the stop on exit), executor_planning.py (the grasp),
executor_messages.py (conversions), executor_stiffness.py (a squeeze's modulus to the segmentation node);
control/executor_settings.py turns the parameters into the sequence's configuration.

Threads: the action's execute callback runs the control loop (wall-clock
period, so the driver watchdog fires even when sim time has stopped) in a
reentrant callback group on a multi-threaded executor; subscriptions and
action-client callbacks feed the sequence under one lock. One goal at a
time: goals arriving while busy are rejected (the reason is logged).
"""
import dataclasses
import threading
import time

import numpy as np
from control_msgs.action import FollowJointTrajectory
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.srv import PlanGrasp
from franka_msgs.action import Grasp, Move
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from std_srvs.srv import Trigger

from defgg_ros.control.bin_slots import BinArea, BinFull, BinSlots
from defgg_ros.control.executor_settings import recovery_drop_xy, sequence_config  # noqa: F401 - re-exported
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.observation import ObservationWatch, arm_state_of
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import ArmState, PlaceTarget
from defgg_ros.control.squeeze_phase import planning_modulus_pa
from defgg_ros.control.velocity_estimate import PositionVelocityEstimator
from defgg_ros.nodes.executor_arm import ArmCommands
from defgg_ros.nodes.executor_inputs import RobotInputs
from defgg_ros.nodes.executor_messages import (  # noqa: F401 - the conversions' names, re-exported for callers
    GoalError,
    RobotRestarted,
    check_arm_limits,
    copy_outcome,
    copy_squeeze,
    grasp_target,
    hold_trajectory_msg,
    joint_state_to_arm,
    place_target,
    trajectory_to_msg,
)
from defgg_ros.nodes.executor_planning import GraspPlanning
from defgg_ros.nodes.executor_stiffness import StiffnessUpdater
from defgg_ros.nodes.node_main import run_node
from defgg_ros.ros import topics
from defgg_ros.ros.action import ActionClient, destroy_actions
from defgg_ros.ros.diagnostics import NodeDiagnostics
from defgg_ros.ros.parameters import declare_parameters, load_schema

# Names, types, defaults and bounds: defgg_ros/ros/params/executor_node.yaml.
PARAMETERS = load_schema("executor_node")
# The robot clock going back by more than this during a goal aborts it (s): see ExecutorNode._check_clock. Over
# 1 s: the simulated driver's stamps read 1 s back for single messages (its sec/nanosec split turns x.9999999997
# into x.0, not x+1.0), which 0.5 s took for a restart 50 times in a 5-minute soak.
CLOCK_JUMP_BACK_S = 2.0


class ExecutorNode(RobotInputs, ArmCommands, GraspPlanning, Node):
    # The parameters as the sequence's configuration (benches and tests call it on the class).
    _sequence_config = staticmethod(sequence_config)

    def __init__(self, **kwargs):
        super().__init__("executor_node", **kwargs)
        declare_parameters(self)  # a value outside its schema raises ParameterError here
        p = self._params()
        self._config = sequence_config(p)  # invalid start-up parameters raise here
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
        self._gripper_canceled_serial = 0   # the newest goal a CancelGripper was for (canceled once accepted)
        self._last_state: tuple[ArmState, float] | None = None
        self._velocity_estimate = PositionVelocityEstimator()   # for drivers without velocities
        # the arm's acceleration (the same difference, of the velocities): a stop carries the last state on with it
        self._acceleration_estimate = PositionVelocityEstimator()
        self._last_acceleration = None
        self._last_force = np.zeros(3)
        self._last_force_wall_s = None   # when the last external wrench arrived (monotonic)
        self._robot_error_wall_s = None  # when the arm's controller was deactivated under a goal (monotonic)
        names = topics.robot_names(p["robot_type"])
        self._arm_joints, self._finger_joints = names["joints"], names["fingers"]
        self._finger_widths = {}    # finger width source -> (width m, monotonic s): see _gripper_width_m
        self._arm_goal = None       # handle of the running FollowJointTrajectory goal
        self._arm_goal_serial = 0   # the newest goal sent; a result of an older one is ignored
        self._held_serial = -1      # _arm_goal_serial when the arm was last told to hold
        self._hold_answer = "none"  # that hold: "none" (not sent), "pending", "accepted" or "refused"
        self._hold_sent_s = 0.0     # when it was sent (monotonic)
        self._goals_the_hold_stops = []   # goals sent before it that may run until it is accepted
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
        config = sequence_config(p)
        with self._lock:
            self._config = config
            self._watch.retarget(p["observation_q_rad"], p["observation_tolerance_rad"])

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
        self._wrench_reader.destroy()
        return super().destroy_node()

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
            if goal_handle.request.plan_grasp:   # the observation move comes first: the arm must be ready for it
                self._ready_to_move(self._params())
                moved = self._observe_before_planning(goal_handle)
                if moved is not None and not moved.success:
                    return self._finish(goal_handle, moved, result)
            result.grasp_used = grasp = self._resolve_grasp(goal_handle.request)
            p = self._params()
            place = self._place_for(goal_handle.request, p)
            sequence = self._sequence_for(grasp, place, p, self._squeeze_for(goal_handle.request, p))
            if goal_handle.request.plan_grasp and p["plan_grasp_alternatives"] > 1:
                result.grasp_used, sequence = self._reachable_alternative(grasp, sequence, place, p)
            self._ready_to_move(p)
            return self._run(goal_handle, sequence, result)
        except (GoalError, ValueError) as error:
            with self._lock:   # raised while a sequence drove the arm (shutdown, a stop it could not plan):
                driving = self._sequence is not None   # its motion must not run on unwatched
                if isinstance(error, RobotRestarted):
                    # The restarted controller holds its own state; a hold at the position measured before the
                    # restart would send the new arm there at once (30 rad/s in the safety soak's simulator).
                    self._last_state = None
                if driving and not self._shutdown.is_set():
                    self._hold_arm()   # on shutdown its owner stops the arm (stop_for_exit: on a fresh state)
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

    def _ready_to_move(self, p: dict) -> None:
        """GoalError unless the arm's and the gripper's actions are up and joint states, the wrench and (with
        use_sim_time) the clock arrive; right after start each is waited for up to server_wait_s."""
        self._wait_for_servers(p["server_wait_s"])
        self._wait_for_first_inputs(p["server_wait_s"])
        self._check_inputs(p)

    def _abort(self, goal_handle, result, reason: str, started: float):
        result.success, result.failure_reason = False, reason
        result.phase_reached = result.phase_reached or "pre_grasp"
        result.duration_s = time.monotonic() - started
        with self._lock:  # the arm did not move for this goal (or a bug stopped it): say how it is now
            state = self._last_state[0] if self._last_state is not None else None
            robot_error = self._in_robot_error()
        result.arm_state = "robot_error" if robot_error else arm_state_of(
            state.q_rad if state else None, state.qd_radps if state else None, self._watch.observation_q_rad,
            self._config.observation_tolerance_rad, self._config.still_speed_radps)
        self.get_logger().warning(f"pick-and-place aborted: {reason}")
        goal_handle.abort()
        return result

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
        estimate = copy_squeeze(result, sequence)
        if estimate is None:
            return
        if sequence.outcome.held_after_lift:   # entries are by image region: it would stay where the object was
            result.stiffness_update = "not sent: the object was picked up from where it was measured"
            self.get_logger().info(f"squeeze: {estimate.describe()}; {result.stiffness_update}")
            return
        modulus_pa = planning_modulus_pa(estimate)
        result.stiffness_update = self._stiffness.tell(result.grasp_used, modulus_pa,
                                                       float(self._params()["stiffness_update_timeout_s"]))
        if result.stiffness_update.startswith("sent"):
            result.stiffness_sent_pa = modulus_pa
            with self._lock:   # the next plan_grasp goal plans on a frame perceived with the measurement
                self._watch.frames_from(self._clocks()[0])
        note = f" ({sequence.section_note})" if sequence.section_note else ""
        self.get_logger().info(f"squeeze: {estimate.describe()}{note}; {result.stiffness_update}")

    def _drive(self, goal_handle, sequence: PickPlaceSequence) -> None:
        """Run the control loop until the sequence finishes (a cancel request goes to the sequence)."""
        period = float(self._params()["control_period_s"])
        self._take_wrench()
        with self._lock:
            if self._shutdown.is_set():   # the exit's stop found nothing moving: nothing may start after it
                raise GoalError("executor is shutting down")
            self._sequence = sequence
            if self._last_state is not None:
                sequence.on_joint_state(*self._last_state)
            sequence.on_force(self._last_force, self._last_force_wall_s)
            if goal_handle.is_cancel_requested:   # canceled while the goal was planned: nothing moves
                sequence.cancel_unstarted(self._clocks()[0])
                return
            self._carry_out(sequence, sequence.start(*self._clocks()))
        cancel_sent = False
        robot_s = self._clocks()[0]
        while not sequence.finished:
            if self._shutdown.wait(period):
                raise GoalError("executor is shutting down")
            self._take_wrench()   # the newest, for this tick's contact guards
            with self._lock:
                if self._shutdown.is_set():   # the exit's hold went out while this waited for the lock
                    raise GoalError("executor is shutting down")
                # One reading, checked, for everything this tick sends: a clock read again after the check could
                # already be the restarted simulator's.
                clocks = self._clocks()
                robot_s = self._check_clock(robot_s, clocks[0])
                if goal_handle.is_cancel_requested and not cancel_sent:
                    cancel_sent = True
                    self._carry_out(sequence, sequence.cancel(*clocks))
                self._carry_out(sequence, sequence.tick(*clocks))
                feedback = sequence.feedback(clocks[0])
            goal_handle.publish_feedback(PickAndPlace.Feedback(
                phase=feedback.phase, phase_progress=feedback.phase_progress,
                gripper_width_m=feedback.gripper_width_m, external_force_n=feedback.external_force_n))

    @staticmethod
    def _check_clock(before_s: float, now_s: float) -> float:
        """now_s, the robot clock; GoalError when it went back more than CLOCK_JUMP_BACK_S since before_s. A restarted
        simulator starts its /clock at 0 again: every motion and gripper wait of the sequence counts on the robot
        clock and would wait until it came back to where it was (the safety soak's goal hung 300 s, unanswered),
        while the new driver knows nothing of the goals the old one ran."""
        if now_s < before_s - CLOCK_JUMP_BACK_S:
            raise RobotRestarted(f"the robot clock jumped back from {before_s:.1f} s to {now_s:.1f} s (a restarted "
                            "driver or simulator): its trajectory and gripper goals are gone")
        return now_s

    def _finish(self, goal_handle, outcome, result):
        copy_outcome(result, outcome)
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


def main(args=None):
    run_node("executor_node", ExecutorNode, startup_errors=(ValueError, OSError), threads=4, args=args,
             stops_hardware=True)


if __name__ == "__main__":
    main()
