"""The simulated driver's arm controller: ros2_controllers' joint_trajectory_controller as franka_ros2 runs it.

Its JointTrajectory topic and FollowJointTrajectory action (docs/franka_contract.md, "The arm's trajectory
controller"): a trajectory is validated as the controller validates it, starts at its stamp (0: on receipt) and
blends from the measured position and velocity (sim/cell/trajectory.py); every control period of the sim thread the
running one is checked against the active tolerances (sim/cell/tolerances.py). A goal succeeds once, after the end
time, every joint is inside its goal tolerance (velocity below `stopped_velocity_tolerance`), and aborts with
PATH_TOLERANCE_VIOLATED / GOAL_TOLERANCE_VIOLATED (the arm then holds where it is); a newer goal preempts it
(INVALID_GOAL), a cancel holds the arm. A goal's tolerances stay active for later topic trajectories, as on the
controller. Deactivated (a robot error: fake_franka_errors.py) it aborts the running goal, holds, rejects goals and
drops topic trajectories until it is activated again, when it holds where the arm is.

Goals start in the order they arrive, at acceptance (the controller's goal_accepted_callback): the action server's
requests are handled one at a time (its own mutually exclusive callback group) and the trajectory starts in the
accepted callback; only the waiting for a verdict runs as the goal's execute task. Threads: ROS callbacks start
trajectories and wait for their verdicts; `control_period` runs in the sim thread with
the driver's lock held. Nothing here reads the ROS clock: sim time is the cell's.
"""
import threading
import time

from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import seconds_to_stamp
from defgg_ros.sim.cell.tolerances import (
    FLOAT32_EPSILON,
    GOAL_VIOLATED,
    PATH_VIOLATED,
    SUCCEEDED,
    TrajectoryMonitor,
    default_tolerances,
    goal_tolerances,
)
from defgg_ros.sim.cell.trajectory import TrajectoryError, make_waypoints

FEEDBACK_PERIOD_S = 1 / 20.0  # FollowJointTrajectory feedback while a goal runs (wall clock): action_monitor_rate
# How often a canceled goal looks whether rclpy has marked it canceling (it does so once _on_cancel returned; wall s).
CANCEL_POLL_S = 0.002
# A trajectory stamped further than this ahead of sim time is likely a wall-clock stamp from a node without
# use_sim_time: the controller waits for it as it would for any stamp, and the log says why the arm does not move.
MAX_STAMP_OFFSET_S = 1.0
PREEMPTED_TEXT = "Current goal preempted by new incoming action."   # the controller's preempt_active_goal
DEACTIVATED_TEXT = topics.CONTROLLER_DEACTIVATED_TEXT   # on_deactivate, INVALID_GOAL
INACTIVE_TEXT = "Can't accept new action goals. Controller is not running."   # goal_received_callback
SHUTTING_DOWN_TEXT = "the simulated controller is shutting down"
RESULT_CODES = {SUCCEEDED: FollowJointTrajectory.Result.SUCCESSFUL,
                PATH_VIOLATED: FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED,
                GOAL_VIOLATED: FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED}


def _seconds(duration) -> float:
    return duration.sec + duration.nanosec * 1e-9


def _joint_tolerances(msgs) -> list:
    return [(m.name, m.position, m.velocity, m.acceleration) for m in msgs]



class FakeArmController:
    """`<robot_type>_arm_controller` of the simulated driver (which owns the lock, the cell and the sim thread)."""

    def __init__(self, driver, joint_names, callback_group):
        self._driver, self._joints = driver, tuple(joint_names)
        self._lock, self._cell, cfg = driver._lock, driver.cell, driver.cfg
        self._logger = driver.get_logger()
        self.defaults = default_tolerances(len(self._joints), cfg["arm_path_tolerance_rad"],
                                           cfg["arm_goal_tolerance_rad"], cfg["arm_stopped_velocity_tolerance_radps"],
                                           cfg["arm_goal_time_s"])
        self._active = self.defaults      # the last goal's tolerances (the controller keeps them for the topic too)
        self._monitor = TrajectoryMonitor(self._joints)
        self._goal_id = 0                 # id of the newest goal
        self._running_goal = None         # id of the goal the running trajectory answers; None: no goal
        self._verdicts = {}               # goal id -> Verdict, set by the sim thread
        self._started = {}                # goal uuid -> (goal id or None, error text): set at acceptance
        self._goal_ids = {}               # goal uuid -> goal id, while its execute task runs
        self._canceled_running = set()    # goal ids canceled while they ran (the arm then held)
        self._deactivated_running = set()  # goal ids aborted by a deactivation while they ran
        self.active = True                # the controller's lifecycle state is active (not inactive)
        self.rejected_while_inactive = 0  # goals rejected because it was inactive
        # Notified (lock held) when a goal's standing changes: a verdict, a cancel, a preempt, a hold. A goal's task
        # sleeps on it instead of waking every control period (1 kHz): with a goal running, the driver's capacity went
        # from 0.84-0.95 to 1.22-1.39 x real time with the tracker's caches (bench/bench_franka_rates.py --moving).
        self._goal_changed = threading.Condition(self._lock)
        self._goal_events = 0             # how many times it was notified
        driver.create_subscription(JointTrajectory, cfg["joint_trajectory_topic"], self._on_trajectory, qos.COMMAND,
                                   callback_group=callback_group)
        ActionServer(driver, FollowJointTrajectory, cfg["arm_trajectory_action"], execute_callback=self._execute,
                     callback_group=MutuallyExclusiveCallbackGroup(), goal_callback=self._on_goal,
                     handle_accepted_callback=self._on_accepted, cancel_callback=self._on_cancel)
        self.cancel_requests = 0          # cancel requests received (the controller logs each one)

    # ---- the sim thread (lock held) ------------------------------------------
    def control_period(self, now_s: float) -> None:
        """The controller's checks of this period: a verdict ends the running goal; a violation holds the arm."""
        if not self._monitor.running or not self.active:
            return
        joints = self._cell.joint_state()
        q_desired, qd_desired = self._cell.tracker.sample(now_s)
        n = len(self._joints)
        verdict = self._monitor.check(now_s, joints.positions[:n], joints.velocities[:n], q_desired, qd_desired)
        if verdict is None:
            return
        if verdict.outcome != SUCCEEDED:   # the controller holds the position it measures now
            self._hold()
            self._logger.warning(f"{verdict.text}: {verdict.details}; holding position")
        if self._running_goal is not None:
            self._verdicts[self._running_goal] = verdict
            self._running_goal = None
            self._goals_changed()
            self._monitor.hold()

    def hold_for_exit(self) -> None:
        """Hold the arm where it is (lock held); a running goal ends, as preempted."""
        self._running_goal = None
        self._hold()
        self._goals_changed()

    def deactivate(self) -> None:
        """on_deactivate (lock held): the running goal aborts (INVALID_GOAL, DEACTIVATED_TEXT), the command holds the
        measured position, and goals and topic trajectories are refused until activate()."""
        if self._running_goal is not None:
            self._deactivated_running.add(self._running_goal)
            self._running_goal = None
        self.active = False
        self._hold()
        self._goals_changed()

    def activate(self) -> None:
        """on_activate (lock held): hold the measured position (set_hold_position) and take goals again."""
        self.active = True
        self._hold()

    def _hold(self) -> None:
        self._cell.command_trajectory([])
        self._monitor.hold()

    def _goals_changed(self) -> None:
        """Wake the goals' tasks (lock held)."""
        self._goal_events += 1
        self._goal_changed.notify_all()

    # ---- commands (ROS threads) ------------------------------------------
    def _start(self, points, stamp, tolerances, goal_id=None) -> None:
        """Replace the running trajectory (lock held); raises TrajectoryError/ValueError on a malformed one."""
        start_s = self._start_time_s(stamp)
        self._cell.command_trajectory(points, start_s)
        if goal_id is not None:
            self._active, self._running_goal = tolerances, goal_id
            self._goals_changed()   # the goal it preempts ends
        self._monitor.start(self._cell.tracker.end_time_s(), self._active)

    def _on_trajectory(self, msg: JointTrajectory):
        if not self.active:   # subscriber_is_active_ false: the controller drops it without a word
            return
        if not msg.points:   # the joint_trajectory_controller drops it ("Empty trajectory received"): no stop
            self._logger.error("rejected joint trajectory: Empty trajectory received (it does not stop the arm)")
            return
        try:
            points = self._trajectory_points(msg)
            self._check_not_over(msg)
            with self._lock:
                self._start(points, msg.header.stamp, None)
        except (TrajectoryError, ValueError) as exc:
            self._logger.error(f"rejected joint trajectory: {exc}")

    def _on_goal(self, goal) -> GoalResponse:
        """Reject what the joint_trajectory_controller rejects (validate_trajectory_msg): no points, unknown or
        missing joints, times not strictly increasing, sizes that do not match; every goal while inactive."""
        if not self.active:
            self.rejected_while_inactive += 1
            self._logger.error(INACTIVE_TEXT)
            return GoalResponse.REJECT
        try:
            if not goal.trajectory.points:
                raise TrajectoryError("the trajectory has no points")
            make_waypoints(self._trajectory_points(goal.trajectory), len(self._joints))
            self._check_not_over(goal.trajectory)
        except (TrajectoryError, ValueError) as exc:
            self._logger.error(f"rejected FollowJointTrajectory goal: {exc}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle) -> CancelResponse:
        """goal_cancelled_callback: a cancel for the running goal holds the measured position at once and ends it
        canceled; for any other goal (one already preempted) it changes nothing."""
        self.cancel_requests += 1
        self._logger.info("Got request to cancel goal")   # the controller's line
        goal_id = self._goal_ids.get(bytes(goal_handle.goal_id.uuid))
        with self._lock:
            if goal_id is not None and self._running_goal == goal_id:
                self._running_goal = None
                self._canceled_running.add(goal_id)
                if self._driver._running:
                    self._hold()
                self._goals_changed()
        return CancelResponse.ACCEPT

    def _on_accepted(self, goal_handle) -> None:
        """goal_accepted_callback: the trajectory replaces the running one now, in the order goals arrive; then the
        goal's execute task waits for its verdict."""
        request = goal_handle.request
        tolerances, why = goal_tolerances(self.defaults, self._joints, _joint_tolerances(request.path_tolerance),
                                          _joint_tolerances(request.goal_tolerance),
                                          _seconds(request.goal_time_tolerance))
        if why:
            self._logger.error(why)
        goal_id, error = None, ""
        try:
            points = self._trajectory_points(request.trajectory)
            with self._lock:
                if not self._driver._running:   # accepted as the driver shut down: its simulation is gone
                    raise ValueError(SHUTTING_DOWN_TEXT)
                if not self.active:   # deactivated between the goal's check and its acceptance
                    raise ValueError(DEACTIVATED_TEXT)
                self._goal_id += 1
                goal_id = self._goal_id
                self._start(points, request.trajectory.header.stamp, tolerances, goal_id)
        except (TrajectoryError, ValueError) as exc:
            error = str(exc)
        except Exception as exc:  # noqa: BLE001 - the goal must still end (rclpy guarded the execute callback)
            error = f"the simulated controller failed: {exc!r}"
            self._logger.error(error)
        finally:
            self._started[bytes(goal_handle.goal_id.uuid)] = (goal_id, error)
            if goal_id is not None:
                self._goal_ids[bytes(goal_handle.goal_id.uuid)] = goal_id
            goal_handle.execute()

    def _execute(self, goal_handle):
        """Follow the goal's trajectory (started at acceptance) in sim time until the sim thread's verdict; a newer
        goal preempts it, a cancel holds the arm."""
        result = FollowJointTrajectory.Result()
        uuid = bytes(goal_handle.goal_id.uuid)
        goal_id, error = self._started.pop(uuid, (None, SHUTTING_DOWN_TEXT))
        if goal_id is None:
            result.error_code, result.error_string = FollowJointTrajectory.Result.INVALID_GOAL, error
            goal_handle.abort()
            return result
        try:
            return self._follow(goal_handle, goal_id, result)
        finally:
            self._goal_ids.pop(uuid, None)
            self._canceled_running.discard(goal_id)
            self._deactivated_running.discard(goal_id)

    def _follow(self, goal_handle, goal_id: int, result):
        next_feedback = 0.0
        while True:
            with self._lock:
                verdict = self._verdicts.pop(goal_id, None)
                running = self._running_goal == goal_id
                deactivated = goal_id in self._deactivated_running
                seen_events = self._goal_events
            if verdict is not None:
                result.error_code, result.error_string = RESULT_CODES[verdict.outcome], verdict.text
                if verdict.outcome == SUCCEEDED:
                    goal_handle.succeed()
                else:
                    goal_handle.abort()
                return result
            canceled = goal_id in self._canceled_running   # _on_cancel held the arm
            if deactivated:
                result.error_code, result.error_string = FollowJointTrajectory.Result.INVALID_GOAL, DEACTIVATED_TEXT
                goal_handle.abort()
                return result
            if canceled:
                if goal_handle.is_cancel_requested:   # rclpy marks it canceling once _on_cancel has returned
                    goal_handle.canceled()
                    return result
            elif not running:
                result.error_code, result.error_string = FollowJointTrajectory.Result.INVALID_GOAL, PREEMPTED_TEXT
                goal_handle.abort()
                return result
            if not self._driver._running:   # a goal can only be canceled on request: aborted, saying why
                with self._lock:
                    if self._running_goal == goal_id:
                        self._running_goal = None   # no hold: the simulation is (being) closed
                result.error_code, result.error_string = FollowJointTrajectory.Result.INVALID_GOAL, SHUTTING_DOWN_TEXT
                goal_handle.abort()
                return result
            if time.monotonic() >= next_feedback:
                next_feedback = time.monotonic() + FEEDBACK_PERIOD_S
                goal_handle.publish_feedback(self._feedback())
            wait_s = CANCEL_POLL_S if canceled else max(0.0, next_feedback - time.monotonic())
            with self._lock:
                if self._goal_events == seen_events:   # nothing changed since the look above
                    self._goal_changed.wait(wait_s)

    def _feedback(self):
        with self._lock:
            now_s = self._cell.time_s
            joints = self._cell.joint_state()
            q_des, qd_des = self._cell.tracker.sample(now_s)
        n = len(self._joints)
        header = Header()
        header.stamp = seconds_to_stamp(now_s)   # the controller sets the stamp only
        feedback = FollowJointTrajectory.Feedback(header=header, joint_names=list(self._joints))
        q, qd = joints.positions[:n], joints.velocities[:n]
        feedback.actual = JointTrajectoryPoint(positions=q.tolist(), velocities=qd.tolist())
        feedback.desired = JointTrajectoryPoint(positions=[float(v) for v in q_des],
                                                velocities=[float(v) for v in qd_des])
        feedback.error = JointTrajectoryPoint(positions=[float(d - a) for d, a in zip(q_des, q)],
                                              velocities=[float(d - a) for d, a in zip(qd_des, qd)])
        return feedback

    def _trajectory_points(self, msg: JointTrajectory) -> list:
        """(t, q, qd, qdd) in the simulated arm's joint order; JointTrajectory joint names in any order."""
        if not msg.points:
            return []
        names = list(msg.joint_names)
        unknown = [n for n in names if n not in self._joints]
        missing = [n for n in self._joints if n not in names]
        if missing or unknown:
            raise TrajectoryError(f"joint_names lack {missing} / have unknown {unknown} (got {names}; this arm is "
                                  f"robot_type {self._driver.cfg['robot_type']}: {list(self._joints)})")
        order = [names.index(n) for n in self._joints]

        def pick(values):
            return [values[i] for i in order] if len(values) == len(names) else None

        # allow_nonzero_velocity_at_trajectory_end: false (the controller's default): the last point must be still.
        moving = [n for n, v in zip(names, msg.points[-1].velocities) if abs(v) > FLOAT32_EPSILON]
        if moving:
            raise TrajectoryError(f"velocity of the last trajectory point is not zero for {moving} (the "
                                  "joint_trajectory_controller rejects such a trajectory)")
        return [(_seconds(pt.time_from_start), pick(pt.positions), pick(pt.velocities), pick(pt.accelerations))
                for pt in msg.points]

    def _check_not_over(self, msg: JointTrajectory) -> None:
        """validate_trajectory_msg: a trajectory with a start time (stamp != 0) that ends before now is refused
        ("Received trajectory with non-zero start time (<s>) that ends in the past (<s>)"); one that started in the
        past but ends later is taken and sampled from its stamp, so the arm is pulled to where it is due by now."""
        start_s = _seconds(msg.header.stamp)
        end_s = start_s + _seconds(msg.points[-1].time_from_start)
        if start_s != 0.0 and end_s < self._cell.time_s:
            raise TrajectoryError(f"Received trajectory with non-zero start time ({start_s:f}) that ends in the past "
                                  f"({end_s:f}); sim time {self._cell.time_s:.3f} s")

    def _start_time_s(self, stamp) -> float:
        stamp_s = _seconds(stamp)
        if stamp_s == 0.0:
            return self._cell.time_s
        if stamp_s - self._cell.time_s > MAX_STAMP_OFFSET_S:
            self._logger.warning(
                f"trajectory stamp {stamp_s:.3f} s is {stamp_s - self._cell.time_s:.1f} s ahead of sim time "
                f"{self._cell.time_s:.3f} s: the arm waits for it (is the sender running with use_sim_time?)",
                throttle_duration_sec=5.0)
        return stamp_s
