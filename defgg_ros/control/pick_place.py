"""The pick-and-place sequence of the paper's real-robot test, as a pure state machine.

pre_grasp (PREGRASP_HEIGHT_M above the grasp, gripper opened) -> descend in a
straight line until the grasp pose OR contact (external force above a
threshold: jerk-limited stop there) -> close (force/width from the modulus,
see gripper_rule) -> lift -> transfer (a joint motion at the planning limits:
real accelerations on the grasp) -> place (straight down at the goal, open)
-> retreat (straight up) -> done.

Stop means stopped: a failure or cancel stops the arm (jerk-limited) and the
run ends only once every joint is slower than still_speed_radps for
rest_hold_s, or, after stop_timeout_s, as a failure of its own ("the arm did
not come to rest"). Then, with an observation pose configured, the arm is
recovered before the run ends (phase "recover"): holding an object (failed in
lift/transfer/place) it is carried to the place pose and released; otherwise
the hand opens (an object under it stays where it is), the TCP rises straight
up and a joint motion ends at the observation pose, out of the camera's view.
A failure during recovery stops there. Outcome.arm_state says where the arm
was left, Outcome.recovery what the recovery did.

No ROS and no wall clock inside: the owner feeds events (joint states,
external force, gripper results) and calls `tick(sim_s, wall_s)`; the
machine answers with commands (trajectories, gripper goals). Motion progress
runs on the robot's clock (`sim_s`: sim time in simulation); the driver
watchdog runs on `wall_s`, because a dead simulator stops sim time. It counts
only the time the owner was ticking: a gap between two ticks longer than
OWN_STALL_S is the owner's own stall (its process stopped or starved), not
the driver's silence.
Every way of ending carries a reason a person can read.
"""

import math
from collections import deque

import numpy as np

from defgg_ros.control.gripper_rule import MISSED_WIDTH_M, NOT_CLOSED_TOLERANCE_M, OPENING_SPEED_MPS, grasp_command
from defgg_ros.control.kinematics import (
    MIN_TCP_HEIGHT_ABOVE_TABLE_M,
    KinematicsError,
    PandaKinematics,
    WorkspaceError,
    check_workspace,
)
from defgg_ros.control.observation import at_pose, max_joint_speed_radps
from defgg_ros.control.poses import finite_array, top_down_pose, top_down_yaw
from defgg_ros.control.sequence_types import (
    RECOVER_PHASE,
    ArmState,
    CancelGripper,
    Feedback,
    GraspGripper,
    GraspTarget,
    MoveGripper,
    Outcome,
    PlaceTarget,
    SendTrajectory,
    SequenceConfig,
    SequenceFailure,
    SqueezeRequest,
    _Motion,
    _Observed,
    _Pending,
    _Plan,
)
from defgg_ros.control.squeeze_phase import SqueezePhase
from defgg_ros.control.stopping import MAX_STATE_AGE_S  # a joint state carried on to now at most this long
from defgg_ros.control.trajectories import (
    arm_limits,
    check_trajectory,
    matched_state,
    nearest_sample,
    plan_checked_stop,
    plan_joint_motion,
    plan_joint_via,
    plan_line,
    scaled_in_time,
    tcp_peak_acceleration_mps2,
)
from defgg_ros.grasping.geometry import tcp_height_m

# Defaults of SequenceConfig.still_speed_radps / stop_timeout_s (kept for importers).
STILL_SPEED_RADPS = SequenceConfig.still_speed_radps
STOP_TIMEOUT_S = SequenceConfig.stop_timeout_s
# Grasps predicted a little below the table top (depth noise on thin
# objects) are raised to this TCP height (fingertips TABLE_CLEARANCE_M above the table, as tcp_height_m's
# floor; 5 mm until 2026-11-28, the fingertips 2 mm into the table); further below is a bad grasp.
GRASP_MIN_HEIGHT_ABOVE_TABLE_M = MIN_TCP_HEIGHT_ABOVE_TABLE_M
GRASP_BELOW_TABLE_TOLERANCE_M = 0.02
# A held object's fingers may creep (a soft object relaxing); opening further than this means it is gone.
OPENED_WIDTH_TOLERANCE_M = 0.010
# plan_failure's plan is reused by start() when the arm is still where it was checked (an arm at rest reads
# within this of itself): the plan depends only on the start configuration (IK seeds from it).
CHECKED_PLAN_REUSE_TOLERANCE_RAD = 1e-3
# A transfer over transfer_max_tcp_accel_mps2 is planned again this much slower than the overshoot asks for,
# at most this often (Ruckig's plan within time-scaled limits is the time-scaled plan; the margin covers sampling).
TRANSFER_RETIMING_MARGIN = 1.02
TRANSFER_RETIMING_TRIES = 3
# The place lowering watches the hold until the held object's bottom (assumed on the table at the grasp) comes
# this close to the table: touching down pushes an object up between the fingers, which can read as a drop.
TOUCHDOWN_MARGIN_M = 0.02
# A stop starts this far ahead along the commanded motion, stamped to start then (_stop_motion): longer than a
# goal's usual latency to the controller (under load in the simulated cell up to ~0.13 s of robot time).
STOP_LEAD_S = 0.15
# ... or, when the arm's goals were answered later than that, the longest round trip (send to the controller's
# acceptance, robot time) of the last STOP_LEAD_WINDOW goals times STOP_LEAD_LATENCY_FACTOR, at most MAX_STOP_LEAD_S:
# the full suite at a load of 8 on 2 cores once had a stop arrive ~0.13 s after its fixed lead, and the controller
# sampling into a stop already behind the arm turned a joint back 2.6 mrad (2026-12-02). A short window: a pick's
# first goal is answered 0.9-2.3 s late on a loaded machine (the action's first use), and with a window of 10 it set
# the lead of every stop of the pick (2026-12-03). The cap keeps lead plus deceleration (0.05 s in the lift, up to
# 0.24 s at transfer speed) within the 0.5 s in which a stop must have the arm at rest (issue 48): with 0.3 s the
# loaded CI had the arm at 0.13 rad/s 0.5 s after a SIGINT in the lift.
STOP_LEAD_WINDOW = 3
STOP_LEAD_LATENCY_FACTOR = 1.5
MAX_STOP_LEAD_S = 0.25
# An arm further than this from the commanded path (a contact holds it) does not follow it: stop from where it is.
FOLLOWING_TOLERANCE_RAD = 0.02
# A gap between two ticks longer than this is the owner's own stall, not silence of the driver (the owner ticks
# every control period, 10 ms): a cell whose processes were all suspended for a minute (SIGSTOP) aborted its
# pick as "driver silent" on resume, before the first joint state after the pause could arrive (2026-11-29).
OWN_STALL_S = 0.5
# A release blocked at the place (the fingers could not open) is tried once more after lifting the hand this far:
# a touch-down stopped late (an executor starved of CPU: one replay in CI, 2026-12-01) pressed the object, and
# the finger tips with it, on the floor, and the floor's friction held the fingers ('fingers blocked at 47.5 mm
# before reaching 57.1 mm'). Lifted off, the opening fingers no longer drag on it; a neighbour or a wall beside
# the fingers blocks them again and the place fails as before.
RELEASE_RELIEF_LIFT_M = 0.01
# Only an opening whose fingers stopped more than this short of the release width counts as blocked.
RELEASE_SHORT_TOLERANCE_M = 0.001


def _finite(name: str, values) -> np.ndarray:
    return finite_array(name, values, SequenceFailure)


class PickPlaceSequence(SqueezePhase):
    """One pick-and-place run; create a new one per goal (squeeze: measure the stiffness after the descent)."""

    def __init__(self, kin: PandaKinematics, config: SequenceConfig, grasp: GraspTarget | None,
                 place: PlaceTarget | None, squeeze: SqueezeRequest | None = None):
        config.validate()
        self._init_squeeze(squeeze)
        self._kin, self._cfg, self._grasp, self._place = kin, config, grasp, place
        self._start_section_job()
        self._limits = arm_limits(kin.arm, config.limits_scale)   # the kinematics' arm model
        self._obs = _Observed()
        self._pending = _Pending()
        self._motion: _Motion | None = None
        self._plan: _Plan | None = None
        self._checked: tuple[np.ndarray, _Plan] | None = None   # (q it was planned from, plan_failure's plan)
        self._phase = "idle"
        self._placed_open_sent = False
        self._release_relief: str | None = None   # None, "lifting", "reopened": RELEASE_RELIEF_LIFT_M
        self._goal_latencies_s = deque(maxlen=STOP_LEAD_WINDOW)   # the last arm goals' round trips (robot time)
        self.released_at_place = False          # the hand opened at the goal's place target (not in a recovery)
        self.place_contact_z_m = float("nan")   # TCP height where a guarded lowering touched down (nan: it did not)
        self._drop_M: np.ndarray | None = None  # a recovery's put-down pose (recovery_drop_xy_m), once planned
        self._guarded_lowering = False           # a recovery's lowering runs: stop on contact
        self._stopping = False
        self._cancel_after_stop = False   # canceled while a failure's stop ran: no recovery after it
        self._wrench_lost = False         # the wrench went quiet: no recovery (its guarded lowering would be blind)
        self._robot_error: str | None = None   # why the arm's controller was deactivated: on_robot_error
        self._stop_began_s = 0.0
        self._still_since_s: float | None = None
        self._rest_confirmed_s: float | None = None   # when _arrived last found the arm at rest
        self._failed_phase = ""
        self._recovering = False
        self._recovery_steps: list = []
        self._recovery_log: list = []
        self._step_name, self._awaiting, self._holding_step = "", "motion", False
        self._start_s = 0.0
        self.outcome = Outcome()
        self.finished = False

    # --- events -----------------------------------------------------------
    def on_joint_state(self, state: ArmState, wall_s: float) -> None:
        self._obs.state = state
        self._obs.state_wall_s = wall_s
        self._obs.own_stall_s = 0.0

    def on_force(self, force_xyz_n, wall_s: float | None = None) -> None:
        """The external force; wall_s (monotonic) when it arrived: then the watchdog also fails a run whose
        wrench went quiet (the contact guards would read its last value for ever)."""
        self._obs.force_n = np.asarray(force_xyz_n, dtype=float)
        if wall_s is not None:
            self._obs.force_wall_s, self._obs.own_stall_force_s = wall_s, 0.0

    def on_robot_error(self, reason: str) -> None:
        """A robot error deactivated the arm's trajectory controller (franka_ros2's answer to a reflex): nothing the
        run sends can move the arm, so the next tick ends it without a stop or a recovery (each would be refused)."""
        if self._robot_error is None:
            self._robot_error = reason

    def robot_now_s(self, wall_s: float) -> float:
        """The controller's clock now: the last joint state's stamp plus its age (at most MAX_STATE_AGE_S); nan
        without a stamped state."""
        state = self._obs.state
        if state is None or not np.isfinite(state.stamp_s):
            return float("nan")
        return state.stamp_s + min(max(wall_s - self._obs.state_wall_s, 0.0), MAX_STATE_AGE_S)

    def on_goal_answered(self, latency_s: float) -> None:
        """An arm goal's round trip from send to the controller's answer (robot time: robot_now_s at both ends)."""
        if math.isfinite(latency_s) and latency_s >= 0.0:
            self._goal_latencies_s.append(float(latency_s))

    @property
    def stop_lead_s(self) -> float:
        """How far ahead along the commanded motion a stop starts: STOP_LEAD_S, or the recent goals' latency."""
        latency_s = max(self._goal_latencies_s, default=0.0) * STOP_LEAD_LATENCY_FACTOR
        return min(max(STOP_LEAD_S, latency_s), MAX_STOP_LEAD_S)

    def on_gripper_result(self, success: bool, width_m: float, error: str = "") -> None:
        if self._pending.gripper:
            self._pending.gripper = False
            self._pending.gripper_result = (bool(success), float(width_m), error)

    @property
    def phase(self) -> str:
        return self._phase

    def plan_failure(self, q_now) -> str:
        """Why this pick would be refused before the arm moves from q_now ("" if it would not): the checks
        start() makes (workspace, IK, the straight descent and lift, the place pose), run alone."""
        q_now = np.asarray(q_now, dtype=float)
        try:
            self._checked = (q_now.copy(), self._make_plan(q_now))
        except (SequenceFailure, KinematicsError, ValueError) as error:
            return str(error)
        return ""

    def feedback(self, sim_s: float) -> Feedback:
        state = self._obs.state
        return Feedback(self._phase, self._progress(sim_s), state.gripper_width_m if state else float("nan"),
                        float(np.linalg.norm(self._obs.force_n)))

    # --- driving ----------------------------------------------------------
    def start(self, sim_s: float, wall_s: float) -> list:
        self._start_s = sim_s
        return self._guarded(self._start, sim_s, wall_s)

    def cancel_unstarted(self, sim_s: float) -> None:
        """End as canceled without moving anything: the cancel came before start()."""
        self._start_s = sim_s
        self.outcome.canceled = True
        self.outcome.failure_reason = "canceled before the arm moved"
        self._finish(sim_s, self._rest_state() if self._obs.state is not None else "unknown")

    def tick(self, sim_s: float, wall_s: float) -> list:
        if self.finished:
            return []
        if self._robot_error is not None:
            return self._end_on_robot_error(sim_s)
        if self._stopping:
            return self._tick_stopping(sim_s, wall_s)
        if self._recovering:
            return self._guarded(self._tick_recover, sim_s, wall_s)
        handlers = {"pre_grasp": self._tick_pre_grasp, "descend": self._tick_descend, "close": self._tick_close,
                    "lift": self._tick_lift, "squeeze": self._tick_squeeze,
                    "transfer": self._tick_transfer, "place": self._tick_place,
                    "retreat": self._tick_retreat}
        return self._guarded(handlers[self._phase], sim_s, wall_s)

    def cancel(self, sim_s: float, wall_s: float) -> list:
        """Stop the arm (jerk-limited) and end as canceled once it is still (then recover, unless recovering).
        During a failure's stop the arm is already stopping: the cancel is kept, and no recovery (or no more
        of it) follows the stop; the action forwards only one cancel, so it must not be lost."""
        if self.finished:
            return []
        if self._robot_error is not None:   # no stop to send: the next tick ends the run
            self.outcome.canceled = True
            return []
        if self._stopping:
            if not self.outcome.success:
                self.outcome.canceled = self._cancel_after_stop = True
            return []
        self.outcome.canceled = True
        return self._fail(f"canceled during {self._phase}", sim_s)

    @property
    def recovering(self) -> bool:
        return self._recovering

    @property
    def release_sent(self) -> bool:
        """The hand was told to let the object go (at the place, or in a recovery): from here on it may leave."""
        return self._placed_open_sent

    def _guarded(self, handler, sim_s: float, wall_s: float) -> list:
        try:
            self._watchdog(wall_s)
            self._check_wrench(wall_s)
            return handler(sim_s)
        except _DriverSilent as silent:
            return self._fail(str(silent), sim_s, wait_for_stop=False)
        except (SequenceFailure, KinematicsError, ValueError) as error:
            return self._fail(str(error), sim_s)

    def _watchdog(self, wall_s: float) -> None:
        obs = self._obs
        if obs.last_tick_wall_s is not None and wall_s - obs.last_tick_wall_s > OWN_STALL_S:
            obs.own_stall_s += wall_s - obs.last_tick_wall_s
            obs.own_stall_force_s += wall_s - obs.last_tick_wall_s
        obs.last_tick_wall_s = wall_s
        age = wall_s - obs.state_wall_s - obs.own_stall_s
        if self._obs.state is None:
            raise _DriverSilent("driver silent: no joint states received")
        if age > self._cfg.watchdog_timeout_s:
            raise _DriverSilent(f"driver silent: no joint states for {age:.1f} s "
                                f"(watchdog {self._cfg.watchdog_timeout_s:.1f} s)")

    def _check_wrench(self, wall_s: float) -> None:
        """SequenceFailure when the wrench is older than the watchdog (after _watchdog: its stall counted). Not
        while a failure's stop runs: that needs joint states only; a recovery after it is refused here too."""
        obs = self._obs
        if obs.force_wall_s is None:
            return
        force_age = wall_s - obs.force_wall_s - obs.own_stall_force_s
        if force_age > self._cfg.watchdog_timeout_s:   # joint states still come: stop and wait for rest
            self._wrench_lost = True
            raise SequenceFailure(f"no external wrench for {force_age:.1f} s (watchdog "
                                  f"{self._cfg.watchdog_timeout_s:.1f} s): the contact guards would be blind")

    # --- planning before the arm moves --------------------------------------
    def _start(self, sim_s: float) -> list:
        speed = self._max_speed_radps()      # every motion is planned from rest (inf: not known yet, let pass)
        if math.isfinite(speed) and speed >= self._cfg.still_speed_radps:   # refused: nothing sent, no recovery
            self.outcome.failure_reason = (f"the arm is moving ({speed:.3f} rad/s, still below "
                                           f"{self._cfg.still_speed_radps:g}): wait until it is at rest")
            self._finish(sim_s, "moving")
            return []
        self._phase = "pre_grasp"
        self._plan = self._checked_plan(self._obs.state.q_rad) or self._make_plan(self._obs.state.q_rad)
        commands = [MoveGripper(self._plan.gripper.pre_open_width_m, OPENING_SPEED_MPS)]
        self._pending.gripper, self._pending.gripper_sent_s = True, sim_s
        motion = plan_joint_motion(self._obs.state.q_rad, self._plan.pregrasp_q, self._limits,
                                   dt_s=self._cfg.sample_dt_s)
        return commands + self._send(motion, sim_s)

    def _grasp_positions(self) -> tuple[np.ndarray, np.ndarray]:
        """(pre-grasp, grasp) TCP positions: PREGRASP above the surface point, the grasp below it
        by the configured grasp_height_rule."""
        surface = _finite("grasp position", self._grasp.position_m).copy()
        floor = self._cfg.table_z_m + GRASP_MIN_HEIGHT_ABOVE_TABLE_M
        if surface[2] < self._cfg.table_z_m - GRASP_BELOW_TABLE_TOLERANCE_M:
            raise WorkspaceError(f"grasp outside the workspace: {surface[2]:.3f} m is below the table "
                                 f"at {self._cfg.table_z_m:.3f} m")
        grasp = surface.copy()
        if self._cfg.grasp_height_rule == "half_height":
            grasp[2] = max(tcp_height_m(surface[2], self._cfg.table_z_m), floor)
        else:
            grasp[2] = max(surface[2] - self._cfg.grasp_depth_below_surface_m, floor)
        pregrasp = surface.copy()
        pregrasp[2] = max(surface[2], floor) + self._cfg.pregrasp_height_m
        return pregrasp, grasp

    def _checked_plan(self, q_now) -> _Plan | None:
        """plan_failure's plan if the arm has not moved since (saves planning the pick twice per goal)."""
        if self._checked is None:
            return None
        q_checked, plan = self._checked
        moved_rad = np.max(np.abs(np.asarray(q_now, dtype=float) - q_checked))
        return plan if moved_rad <= CHECKED_PLAN_REUSE_TOLERANCE_RAD else None

    def _make_plan(self, q_now: np.ndarray) -> _Plan:
        pregrasp_p, grasp_p = self._grasp_positions()
        _finite("grasp yaw", self._grasp.yaw_rad)
        try:
            check_workspace(grasp_p, self._cfg.table_z_m)
            check_workspace(pregrasp_p, self._cfg.table_z_m)
            pregrasp, yaw = self._kin.top_down_ik(pregrasp_p, self._grasp.yaw_rad, q_now)
            grasp_M = top_down_pose(grasp_p, yaw)
            self._kin.ik(grasp_M, pregrasp.q_rad)
        except KinematicsError as error:
            raise SequenceFailure(f"grasp outside the workspace: {error}") from error
        self._check_straight_lines(pregrasp.q_rad, grasp_p, self._cfg.descent_speed_mps, self._cfg.lift_height_m,
                                   ("descent", "lift"), "grasp outside the workspace")
        place_p = _finite("place position", self._place.position_m)
        approach_p = place_p + [0.0, 0.0, self._cfg.place_approach_height_m]
        if self._place.lower_to_contact:   # as far down as the object's bottom on the bin's floor (its lowest)
            place_p = place_p.copy()
            place_p[2] = min(place_p[2], grasp_p[2] + self._cfg.place_release_clearance_m)
        try:
            check_workspace(place_p, self._cfg.table_z_m)
            check_workspace(approach_p, self._cfg.table_z_m)
            wanted_yaw = yaw if self._place.yaw_rad is None else _finite("place yaw", self._place.yaw_rad)
            approach, place_yaw = self._kin.top_down_ik(approach_p, wanted_yaw, pregrasp.q_rad)
            place_M = top_down_pose(place_p, place_yaw)
            self._kin.ik(place_M, approach.q_rad)
        except KinematicsError as error:
            raise SequenceFailure(f"place pose unreachable: {error}") from error
        # the lowering into the bin and the retreat up are straight lines too: found out after the grasp,
        # the pick would fail holding the object (and the recovery would try the same lowering)
        self._check_straight_lines(approach.q_rad, place_p, self._place_speed_mps(),
                                   float(approach_p[2] - place_p[2]), ("lowering", "retreat"),
                                   "place pose unreachable")
        gripper = grasp_command(self._grasp.youngs_modulus_pa, self._grasp.width_m, self._grasp.finger_force_n)
        return _Plan(pregrasp.q_rad, grasp_M, approach.q_rad, place_M, gripper, top_down_pose(approach_p, place_yaw))

    def _place_speed_mps(self) -> float:
        return self._cfg.place_lowering_speed_mps if self._place.lower_to_contact else self._cfg.line_speed_mps

    def _check_straight_lines(self, above_q: np.ndarray, target_p: np.ndarray, down_speed_mps: float,
                              up_m: float, names: tuple, failure: str) -> None:
        """Refuse, before the arm moves, a grasp (or place) whose way down from above_q to target_p or back up by
        up_m cannot be a straight line: close to the base, a 15 cm vertical lift can run a joint into its limit,
        and finding that out after the fingers closed costs the pick (19 of 200 random grasps at x 0.22-0.45 m,
        1-5 cm high: bench/bench_reach_near_base.py)."""
        line = names[0]
        try:
            down = plan_line(self._kin, above_q, target_p - self._kin.fk(above_q)[:3, 3], self._limits,
                             down_speed_mps, self._cfg.sample_dt_s)
            check_trajectory(down, self._limits, self._kin, self._cfg.table_z_m)
            line = names[1]
            up = plan_line(self._kin, down.final_q_rad, [0.0, 0.0, up_m], self._limits, self._cfg.line_speed_mps,
                           self._cfg.sample_dt_s)
            check_trajectory(up, self._limits, self._kin, self._cfg.table_z_m)
        except KinematicsError as error:
            raise SequenceFailure(f"{failure}: its straight {line} cannot be made: {error}") from error

    # --- motions ------------------------------------------------------------
    def _send(self, trajectory, sim_s: float, guarded_stop: bool = False, start_s: float | None = None) -> list:
        """Command the trajectory: on receipt (its clock from sim_s), or from start_s (robot time) when given."""
        if not guarded_stop:
            check_trajectory(trajectory, self._limits, self._kin, self._cfg.table_z_m)
        self._motion = _Motion(trajectory, sim_s if start_s is None else start_s, guarded_stop, start_s)
        self._still_since_s = None
        return [SendTrajectory(trajectory, start_s)]

    def _line_to(self, target_p: np.ndarray, speed_mps: float, sim_s: float) -> list:
        q = self._obs.state.q_rad
        displacement = np.asarray(target_p, dtype=float) - self._kin.fk(q)[:3, 3]
        return self._send(plan_line(self._kin, q, displacement, self._limits, speed_mps, self._cfg.sample_dt_s), sim_s)

    def _line_up(self, height_m: float, sim_s: float) -> list:
        target = self._kin.fk(self._obs.state.q_rad)[:3, 3] + [0.0, 0.0, height_m]
        return self._line_to(target, self._cfg.line_speed_mps, sim_s)

    def _stop_motion(self, sim_s: float, at_once: bool = False) -> list:
        """Stop the running motion (_planned_stop) and end this motion once the arm is still."""
        stop, start_s, breach = self._planned_stop(at_once)
        if breach:
            self._recovery_log.append(breach)   # in Outcome.recovery: the operator must hear of it
        return self._send(stop, sim_s, guarded_stop=True, start_s=start_s)

    def stop_now(self):
        """(stop trajectory, start_s robot time or None: on receipt) that stops the running motion as a cancel
        would, for the owner's own stop (the executor on its way out); None without a motion or a joint state.
        The sequence does not change."""
        m = self._motion
        if m is None or self._obs.state is None:
            return None
        if m.guarded_stop:   # a stop runs: the same again if it was stamped (continuous), else the owner's own hold
            return (m.trajectory, m.stamped_start_s) if m.stamped_start_s is not None else None
        stop, start_s, _ = self._planned_stop(at_once=False)
        return stop, start_s

    def _planned_stop(self, at_once: bool):
        """(jerk-limited stop, start_s, breach) (checked: plan_checked_stop). While the arm follows the commanded
        motion: from that motion's state stop_lead_s from now, stamped to start then, so the controller blends
        from wherever the arm is at receipt into it (however late the goal arrives, up to the lead); a stop planned
        from the last joint state and started on receipt began behind the moving arm by the state's age and the
        goal's latency, and the controller pulled the arm back to it (a cancel in a transfer: up to 51 mrad back,
        3.4 rad/s). A stop on contact (at_once: every lead is more press), or an arm not following the command
        (held by a contact, or a stop already running): from the measured position with the commanded velocity
        there (matched_state), on receipt (start_s None)."""
        m, state = self._motion, self._obs.state
        ahead = None if at_once or m.guarded_stop else self._state_ahead()
        if ahead is None:
            (q, qd, qdd), start_s = matched_state(m.trajectory, state.q_rad), None
        else:
            (q, qd, qdd), start_s = ahead
        stop, breach = plan_checked_stop(q, qd, qdd, self._limits, self._kin, self._cfg.table_z_m,
                                         self._cfg.sample_dt_s)
        return stop, start_s, breach

    def _state_ahead(self):
        """((q, qd, qdd), robot time) of the commanded motion's first sample stop_lead_s or more from now, on the
        controller's clock for that motion: the last joint state's stamp minus the time of the sample nearest it
        (the motion started when the goal arrived, not when it was sent). None when the arm does not follow the
        motion (further than FOLLOWING_TOLERANCE_RAD from its nearest sample) or the state has no stamp. Every time
        is the controller's (the state's stamp), so an offset between its clock and ours does not matter."""
        traj, state, obs = self._motion.trajectory, self._obs.state, self._obs
        nearest = nearest_sample(traj, state.q_rad)
        if not np.isfinite(state.stamp_s) or \
                np.max(np.abs(traj.q_rad[nearest] - state.q_rad)) > FOLLOWING_TOLERANCE_RAD:
            return None   # no stamp, or an arm off its path: at once
        # The controller's now: the state's stamp plus how long ago it arrived (never our clock, which may differ).
        controller_now_s = self.robot_now_s(obs.last_tick_wall_s or obs.state_wall_s)
        # between samples: the offset along the commanded velocity there (samples are sample_dt_s apart)
        speed2 = float(traj.qd_radps[nearest] @ traj.qd_radps[nearest])
        between_s = float((state.q_rad - traj.q_rad[nearest]) @ traj.qd_radps[nearest]) / speed2 if speed2 > 1e-12 \
            else 0.0
        started_s = state.stamp_s - (traj.times_s[nearest] + np.clip(between_s, -self._cfg.sample_dt_s,
                                                                     self._cfg.sample_dt_s))
        lead_s = self.stop_lead_s
        k = int(np.searchsorted(traj.times_s, controller_now_s + lead_s - started_s))
        if k >= len(traj.times_s):   # the motion ends within the lead: at rest at its end
            return (traj.q_rad[-1].copy(), np.zeros(7), np.zeros(7)), max(started_s + traj.duration_s,
                                                                           controller_now_s + lead_s)
        return (traj.q_rad[k].copy(), traj.qd_radps[k].copy(), traj.qdd_radps2[k].copy()), started_s + traj.times_s[k]

    def _arrived(self, sim_s: float) -> bool:
        m, state = self._motion, self._obs.state
        elapsed = sim_s - m.start_s
        if elapsed < m.trajectory.duration_s:
            return False
        if m.guarded_stop:
            still = self._at_rest(sim_s)
            if not still and elapsed > m.trajectory.duration_s + self._cfg.settle_timeout_s:
                raise SequenceFailure(f"arm did not come to rest during {self._phase}")
            if still:
                self._rest_confirmed_s = sim_s
            return still
        # At the target *and at rest*: the next motion starts from this state with zero velocity, so a state
        # taken while the arm still moved (a late joint state: 5-16 mrad behind in the ROS cell at RTF 3)
        # would make the next trajectory start behind the arm, a jump that jerked a held block out of the hand.
        error = float(np.max(np.abs(state.q_rad - m.trajectory.final_q_rad)))
        still = self._at_rest(sim_s)
        if error <= self._cfg.arrival_joint_atol_rad and still:
            self._rest_confirmed_s = sim_s
            return True
        moving = self._still_since_s is None       # slow now but not yet for rest_hold_s: wait for it
        if elapsed > m.trajectory.duration_s + self._cfg.settle_timeout_s and (
                error > self._cfg.arrival_joint_atol_rad or moving):
            how = f"joint error {error:.3f} rad" if error > self._cfg.arrival_joint_atol_rad else (
                f"not at rest: fastest joint {self._max_speed_radps():.3f} rad/s")
            raise SequenceFailure(f"arm did not reach the {self._phase} target {self._cfg.settle_timeout_s:.1f} s "
                                  f"after the trajectory ended ({how})")
        return False

    def _tcp_z_m(self) -> float:
        """The TCP's height (base frame) in the last joint state."""
        return float(self._kin.fk(self._obs.state.q_rad)[2, 3])

    def _max_speed_radps(self) -> float:
        """The fastest joint's speed; inf when unknown (no state, or a velocity not yet estimated: NaN)."""
        state = self._obs.state
        return max_joint_speed_radps(state.qd_radps if state is not None else None)

    def _at_rest(self, sim_s: float) -> bool:
        """Every joint slower than still_speed_radps, continuously for rest_hold_s (robot clock).

        One slow sample is not rest: a swinging joint passes through zero speed.
        """
        if self._max_speed_radps() >= self._cfg.still_speed_radps:
            self._still_since_s = None
            return False
        if self._still_since_s is None:
            self._still_since_s = sim_s
        return sim_s - self._still_since_s >= self._cfg.rest_hold_s - 1e-9

    def _at_observation(self) -> bool:
        q_obs, state = self._cfg.observation_q_rad, self._obs.state
        if q_obs is None or state is None:
            return False
        return at_pose(state.q_rad, q_obs, self._cfg.observation_tolerance_rad)

    def _rest_state(self) -> str:
        return "observation_pose" if self._at_observation() else "at_rest"

    def _motion_active(self, sim_s: float) -> bool:
        return self._motion is not None and sim_s - self._motion.start_s < self._motion.trajectory.duration_s

    def _progress(self, sim_s: float) -> float:
        if self._phase in ("close", "squeeze") or (self._phase == "place" and self._placed_open_sent):
            return 0.5 if self._pending.gripper else 1.0
        if self._motion is None or self._motion.trajectory.duration_s <= 0:
            return 0.0
        return float(min(1.0, max(0.0, (sim_s - self._motion.start_s) / self._motion.trajectory.duration_s)))

    # --- gripper ------------------------------------------------------------
    def _gripper_result(self, sim_s: float, what: str):
        """The finished gripper command's (success, width, error), or None while it runs."""
        if self._pending.gripper:
            if sim_s - self._pending.gripper_sent_s > self._cfg.gripper_timeout_s:
                raise SequenceFailure(f"gripper did not finish {what} within {self._cfg.gripper_timeout_s:.1f} s")
            return None
        return self._pending.gripper_result

    def _send_gripper(self, command, sim_s: float) -> list:
        self._pending.gripper, self._pending.gripper_sent_s, self._pending.gripper_result = True, sim_s, None
        return [command]

    def _check_held(self) -> None:
        width = self._obs.state.gripper_width_m
        closed = self.outcome.gripper_width_closed_m
        threshold = max(MISSED_WIDTH_M, self._cfg.slip_width_fraction * closed)
        if width < threshold:
            raise SequenceFailure(f"object dropped during {self._phase}: the gripper width fell from "
                                  f"{closed * 1000:.1f} mm to {width * 1000:.1f} mm (slipped out)")
        if width > closed + OPENED_WIDTH_TOLERANCE_M:
            # Force-closed fingers do not open by themselves: something pushed them apart, and the
            # object is gone (seen in the simulated cell: 51 -> 79 mm mid-transfer, the block flung
            # off, yet reported "held after transfer").
            raise SequenceFailure(f"object lost during {self._phase}: the fingers opened from "
                                  f"{closed * 1000:.1f} mm to {width * 1000:.1f} mm")

    # --- phases ---------------------------------------------------------------
    def _tick_pre_grasp(self, sim_s: float) -> list:
        result = self._gripper_result(sim_s, "opening")
        if result is not None and not result[0]:
            raise SequenceFailure(f"gripper could not open to {self._plan.gripper.pre_open_width_m * 1000:.0f} mm: "
                                  f"{result[2]}")
        if result is None or not self._arrived(sim_s):
            return []
        self._phase = "descend"
        self._obs.force_bias_n = self._obs.force_n.copy()
        return self._line_to(self._plan.grasp_M[:3, 3], self._cfg.descent_speed_mps, sim_s)

    def _tick_descend(self, sim_s: float) -> list:
        force = float(np.linalg.norm(self._obs.force_n - self._obs.force_bias_n))
        if not self._motion.guarded_stop and force > self._cfg.contact_force_threshold_n:
            self.outcome.contact_detected = True
            return self._stop_motion(sim_s, at_once=True)
        if not self._arrived(sim_s):
            return []
        self.outcome.contact_height_m = self._tcp_z_m()
        if self._squeeze is not None:
            return self._begin_squeeze(sim_s)
        self._phase = "close"
        return self._send_gripper(GraspGripper(self._plan.gripper), sim_s)

    def _tick_close(self, sim_s: float) -> list:
        result = self._gripper_result(sim_s, "the grasp")
        if result is None:
            return []
        success, width, error = result
        self.outcome.gripper_width_closed_m = width
        self.outcome.gripper_force_n = self._plan.gripper.force_n
        if width < MISSED_WIDTH_M:
            raise SequenceFailure(f"missed: the fingers closed to {width * 1000:.1f} mm with nothing between them")
        self._check_closed(width)
        if not success:   # franka_gripper says why only when libfranka threw: a grasp outside its band says nothing
            g = self._plan.gripper
            raise SequenceFailure(f"gripper grasp failed: the fingers stopped at {width * 1000:.1f} mm, the grasp "
                                  f"accepts {(g.width_m - g.epsilon_inner_m) * 1000:.1f}-"
                                  f"{(g.width_m + g.epsilon_outer_m) * 1000:.1f} mm"
                                  + (f" ({error})" if error else ""))
        self._phase = "lift"
        return self._line_up(self._cfg.lift_height_m, sim_s)

    def _check_closed(self, width_m: float, where: str = "") -> None:
        """SequenceFailure when the fingers stopped where they opened to: a finger rests on the object (a squeeze
        would read it rigid, a pick fail later as a slip)."""
        opened = self._plan.gripper.pre_open_width_m
        if width_m > opened - NOT_CLOSED_TOLERANCE_M:
            raise SequenceFailure(f"the fingers did not close{where}: they stopped at {width_m * 1000:.1f} mm, where "
                                  f"they opened to ({opened * 1000:.1f} mm); a finger is on the object, not beside it")

    def _tick_lift(self, sim_s: float) -> list:
        self._check_held()
        if not self._arrived(sim_s):
            return []
        self.outcome.held_after_lift = True
        self._phase = "transfer"
        return self._send(self._transfer_motion(self._obs.state.q_rad), sim_s)

    def _transfer_motion(self, q: np.ndarray):
        """Holding the object, from q to above the place pose (through the via position when it passes)."""
        target = self._place_approach_target(q)
        q_via = None
        if self._cfg.transfer_via_position_m is not None:
            try:
                via_M = self._kin.fk(q)
                via_M[:3, 3] = self._cfg.transfer_via_position_m
                q_via = self._kin.ik(via_M, q, restarts=0).q_rad
            except KinematicsError:
                pass    # a via the arm cannot reach from here must not cost the pick: go straight instead

        def plan(limits):
            direct = plan_joint_motion(q, target, limits, dt_s=self._cfg.sample_dt_s)
            if q_via is None:
                return direct
            try:
                through = plan_joint_via(q, q_via, target, limits, dt_s=self._cfg.sample_dt_s)
                check_trajectory(through, self._limits, self._kin, self._cfg.table_z_m)
                return through
            except KinematicsError:   # a via motion that breaks a limit: straight instead
                return direct

        return self._held_motion(plan)

    def _place_approach_target(self, q: np.ndarray) -> np.ndarray:
        """Joints above the place pose, seeded from q for a short motion; the pre-planned solution is the fallback."""
        approach_M = self._plan.place_approach_M.copy()
        try:
            return self._kin.ik(approach_M, q, restarts=0).q_rad
        except KinematicsError:
            return self._plan.place_approach_q

    def _held_motion(self, plan):
        """plan(limits), slowed down in time (at most TRANSFER_RETIMING_TRIES times) until the TCP accelerates at
        most transfer_max_tcp_accel_mps2: the grip force of the labels' rule holds the object against only
        (FOS - 1) g more, 0.43 g at 2e4 Pa (a 126 g block held with 1.44 N a finger was flung off a ~6 m/s^2
        transfer in the simulated cell, 2026-11-28)."""
        motion = plan(self._limits)
        cap, factor = self._cfg.transfer_max_tcp_accel_mps2, 1.0
        for _ in range(TRANSFER_RETIMING_TRIES):
            peak = tcp_peak_acceleration_mps2(self._kin, motion)
            if cap is None or peak <= cap:
                break
            factor *= math.sqrt(peak / cap) * TRANSFER_RETIMING_MARGIN   # on top of the slow-down so far
            motion = plan(scaled_in_time(self._limits, factor))
        return motion

    def _tick_transfer(self, sim_s: float) -> list:
        self._check_held()
        if not self._arrived(sim_s):
            return []
        self.outcome.held_after_transfer = True
        self._phase = "place"
        self._obs.force_bias_n = self._obs.force_n.copy()   # the held object's weight is not contact
        if not self._place.lower_to_contact:   # a goal's own pose: lowered to it, but never pressed into anything
            return self._line_to(self._plan.place_M[:3, 3], self._cfg.line_speed_mps, sim_s)
        return self._line_to(self._release_point(self._plan.place_M[:3, 3]), self._cfg.place_lowering_speed_mps,
                             sim_s)

    def _release_point(self, lowest_p) -> np.ndarray:
        """Where a guarded lowering ends unless it touches something first: the held object's bottom (as far
        below the TCP as the TCP was above the table where the descent stopped) place_release_clearance_m above
        the table; never below lowest_p."""
        point = np.array(lowest_p, dtype=float)
        hang_top_m = self.outcome.contact_height_m
        if math.isfinite(hang_top_m):
            point[2] = max(point[2], hang_top_m + self._cfg.place_release_clearance_m)
        return point

    def _touched(self) -> bool:
        """A guarded lowering met something: the force (less its bias at the lowering's start) over the
        threshold while the lowering itself (not yet its stop) runs."""
        if self._motion is None or self._motion.guarded_stop:
            return False
        force = float(np.linalg.norm(self._obs.force_n - self._obs.force_bias_n))
        return force > self._cfg.contact_force_threshold_n

    def _may_touch_down(self) -> bool:
        """Could the held object's bottom be within TOUCHDOWN_MARGIN_M of the table (or a bin floor on it)? Its
        bottom hangs as far below the TCP as the TCP was above the table where the descent stopped."""
        hang_m = self.outcome.contact_height_m - self._cfg.table_z_m
        return self._tcp_z_m() - hang_m < self._cfg.table_z_m + TOUCHDOWN_MARGIN_M

    def _tick_place(self, sim_s: float) -> list:
        if self._release_relief == "lifting":
            if not self._arrived(sim_s):
                return []
            self._release_relief = "reopened"
            return self._send_gripper(MoveGripper(self._release_width_m(), OPENING_SPEED_MPS), sim_s)
        if not self._placed_open_sent and self._touched():
            self.place_contact_z_m = self._tcp_z_m()   # the object stands on something: release it here
            return self._stop_motion(sim_s, at_once=True)
        if not self._placed_open_sent:
            # Held while lowering: an object lost late in the transfer shows only now (force-closed fingers
            # close on nothing at 20-50 mm/s), and one lost in the lowering may be outside the bin.
            if not self._may_touch_down():
                self._check_held()
            if not self._arrived(sim_s):
                return []
            self._placed_open_sent = self.released_at_place = True
            return self._send_gripper(MoveGripper(self._release_width_m(), OPENING_SPEED_MPS), sim_s)
        result = self._gripper_result(sim_s, "opening at the place pose")
        if result is None:
            return []
        if not result[0]:
            reason = result[2] or "no reason given"
            if not self._fingers_stopped_short(result[1]):   # rejected, or no width: lifting would not help
                raise SequenceFailure(f"gripper could not release the object: {reason}")
            return self._relieve_blocked_release(reason, sim_s)
        self._phase = "retreat"
        return self._line_up(max(0.0, float(self._plan.place_approach_M[2, 3]) - self._tcp_z_m()), sim_s)

    def _fingers_stopped_short(self, width_m: float) -> bool:
        """A failed opening whose fingers stopped short of the release width: something held them (a rejected goal
        or one that never ran reports no width, nan)."""
        return math.isfinite(width_m) and width_m < self._release_width_m() - RELEASE_SHORT_TOLERANCE_M

    def _relieve_blocked_release(self, reason: str, sim_s: float) -> list:
        """The first blocked release lifts the hand RELEASE_RELIEF_LIFT_M and opens again; a second one fails."""
        if self._release_relief is not None:
            raise SequenceFailure(f"gripper could not release the object: {reason} (again after lifting "
                                  f"{RELEASE_RELIEF_LIFT_M * 1000:.0f} mm)")
        self._release_relief = "lifting"
        self._recovery_log.append(f"release blocked ({reason}): lifted {RELEASE_RELIEF_LIFT_M * 1000:.0f} mm "
                                  "and opened again")
        return self._line_up(RELEASE_RELIEF_LIFT_M, sim_s)

    def _tick_retreat(self, sim_s: float) -> list:
        if not self._arrived(sim_s):
            return []
        self._phase = "done"
        self.outcome.success = True
        return self._settle(sim_s)

    # --- endings --------------------------------------------------------------
    def _fail(self, reason: str, sim_s: float, wait_for_stop: bool = True) -> list:
        """Stop the arm; the run ends once it is at rest (or recovers first: _tick_stopping)."""
        if self._returning:   # measure only, on the way back: the goal's own failure
            self._end_way_back_on_failure()
        if self._recovering and self._holding_step and not self._holds_object():
            # The carried object fell out: from here on it is a recovery holding nothing.
            self._recovery_log.append(f"stopped: {reason}")
            self._recovery_steps = [self._step_open, self._step_lift, self._step_observe]
        elif self._recovering:  # the original reason stays; the recovery ends here
            self._recovery_log.append(f"stopped: {reason}")
            self._recovery_steps = []
        else:
            self.outcome.failure_reason = reason
            self._failed_phase = self._phase
        commands = [CancelGripper()] if self._pending.gripper else []
        self._pending.gripper = False
        if self._motion_active(sim_s):
            commands += self._stop_motion(sim_s)
        if not wait_for_stop:
            self._finish(sim_s, "unknown")
        elif self._motion is None and not self._needs_recovery():
            # Nothing was commanded and nothing to recover: the arm is as the goal found it.
            self._finish(sim_s, self._rest_state() if self._max_speed_radps() < self._cfg.still_speed_radps
                         else "moving")
        else:
            self._stopping, self._stop_began_s, self._still_since_s = True, sim_s, None
        return commands

    def _end_on_robot_error(self, sim_s: float) -> list:
        """End at once, sending nothing (on_robot_error); a failure or recovery under way keeps its reason."""
        reason = self._robot_error
        if self._recovering:
            self._recovery_log.append(f"stopped: {reason}")
        elif self._stopping and self.outcome.failure_reason:
            self.outcome.failure_reason += f"; then {reason}"
        else:
            self.outcome.failure_reason = reason
            self._failed_phase = self._phase
        self._finish(sim_s, "robot_error")
        return []

    def _needs_recovery(self) -> bool:
        return (not self._recovering and not self.outcome.success and self._cfg.observation_q_rad is not None
                and self._obs.state is not None and not self._at_observation() and not self._cancel_after_stop
                and not self._wrench_lost)

    def _tick_stopping(self, sim_s: float, wall_s: float) -> list:
        try:
            self._watchdog(wall_s)
        except _DriverSilent as silent:
            if self._recovering:
                self._recovery_log.append(f"then {silent}")
            elif not self.outcome.success:
                self.outcome.failure_reason += f"; then {silent}"
            self._finish(sim_s, "unknown")
            return []
        m = self._motion
        # A motion that ended long before the stop (a grasp that failed seconds after the descent) must
        # not eat the rest timeout: it counts from whichever is later.
        stop_ends_s = self._stop_began_s if m is None else max(m.start_s + m.trajectory.duration_s,
                                                               self._stop_began_s)
        if sim_s >= stop_ends_s and self._at_rest(sim_s):
            self._stopping = False
            if self._cancel_after_stop and (self._recovery_steps or not self._recovering):
                self._recovery_log.append("canceled during the stop: no recovery")
            if self._needs_recovery():
                return self._guarded(self._begin_recovery, sim_s, wall_s)
            if self._recovering and self._recovery_steps and not self._cancel_after_stop:  # after a dropped object
                return self._guarded(self._next_recovery_step, sim_s, wall_s)
            self._finish(sim_s, self._rest_state())
        elif sim_s > stop_ends_s + self._cfg.stop_timeout_s:
            # Its own failure: whoever gets the result must know the arm may still be moving.
            not_at_rest = (f"the arm did not come to rest: joints still at up to {self._max_speed_radps():.3f} rad/s "
                           f"{self._cfg.stop_timeout_s:.1f} s after the stop")
            if self._recovering:
                self._recovery_log.append(not_at_rest)
            elif not self.outcome.success:
                self.outcome.failure_reason = f"{not_at_rest} (stopped because: {self.outcome.failure_reason})"
            self._finish(sim_s, "moving")
        return []

    # --- recovery: back to the observation pose after a failure or cancel ---------------
    def _holds_object(self) -> bool:
        """Failed while carrying (lift/transfer/place before the release) with the object still held."""
        closed, state = self.outcome.gripper_width_closed_m, self._obs.state
        if self._plan is None or state is None or not math.isfinite(closed) or self._placed_open_sent:
            return False
        if self._failed_phase not in ("lift", "transfer", "place"):
            return False
        width = state.gripper_width_m
        return max(MISSED_WIDTH_M, self._cfg.slip_width_fraction * closed) <= width <= closed + OPENED_WIDTH_TOLERANCE_M

    def _begin_recovery(self, sim_s: float) -> list:
        self._recovering, self._phase = True, RECOVER_PHASE
        if self._holds_object():
            self._recovery_steps = [self._step_carry, self._step_lower, self._step_release, self._step_retreat,
                                    self._step_observe]
        else:
            self._recovery_steps = [self._step_open, self._step_lift, self._step_observe]
        return self._next_recovery_step(sim_s)

    def _next_recovery_step(self, sim_s: float) -> list:
        while self._recovery_steps:
            step = self._recovery_steps.pop(0)
            self._holding_step = False
            commands = step(sim_s)
            if commands:
                return commands
        return self._settle(sim_s)

    def _settle(self, sim_s: float) -> list:
        """End once the arm is at rest (a run may end without a final arrival: recovery steps that moved nothing,
        so rest is checked here too). An arrival in this very tick already saw rest_hold_s of rest: that rest
        counts, so the run ends without waiting it again."""
        rested = self._rest_confirmed_s == sim_s
        self._stopping, self._stop_began_s = True, sim_s
        self._still_since_s = self._still_since_s if rested else None
        return []

    def _tick_recover(self, sim_s: float) -> list:
        if self._awaiting == "gripper":
            result = self._gripper_result(sim_s, self._step_name)
            if result is None:
                return []
            if not result[0]:
                raise SequenceFailure(f"the hand did not open: {result[2] or 'no reason given'}")
        else:
            if self._guarded_lowering and self._touched():
                self._recovery_log.append(f"touched down at TCP z {self._tcp_z_m():.3f} m")
                return self._stop_motion(sim_s, at_once=True)
            if self._holding_step:
                self._check_held()
            if not self._arrived(sim_s):
                return []
        self._guarded_lowering = False
        self._recovery_log.append(self._step_name)
        return self._next_recovery_step(sim_s)

    def _recovery_motion(self, name: str, commands: list, holding: bool = False) -> list:
        self._step_name, self._awaiting, self._holding_step = name, "motion", holding
        return commands

    def _step_open(self, sim_s: float) -> list:
        if self._plan is None:  # nothing was grasped in this run: leave the hand as it is
            return []
        if self._placed_open_sent:   # released already (only place_release_opening_m wide: opening on in the bin
            return []                # pushed the wall, "fingers blocked at 76.6 mm", and the recovery stopped there)
        width = self._plan.gripper.pre_open_width_m
        if self._obs.state.gripper_width_m >= width - NOT_CLOSED_TOLERANCE_M:
            return []
        self._step_name, self._awaiting = f"opened the hand to {width * 1000:.0f} mm", "gripper"
        return self._send_gripper(MoveGripper(width, OPENING_SPEED_MPS), sim_s)

    def _step_lift(self, sim_s: float) -> list:
        z_now = self._tcp_z_m()
        z_observe = float(self._kin.fk(np.asarray(self._cfg.observation_q_rad))[2, 3])
        lift = min(self._cfg.observation_lift_m, max(0.0, z_observe - z_now))
        if lift < 0.005:
            return []
        try:
            commands = self._line_up(lift, sim_s)
        except KinematicsError as error:  # then the joint motion alone (checked against the table)
            self._recovery_log.append(f"no straight lift from here ({error})")
            return []
        return self._recovery_motion(f"lifted the hand {lift * 100:.0f} cm", commands)

    def _step_observe(self, sim_s: float) -> list:
        if self._at_observation():
            return []
        motion = plan_joint_motion(self._obs.state.q_rad, np.asarray(self._cfg.observation_q_rad, dtype=float),
                                   self._limits, dt_s=self._cfg.sample_dt_s)
        return self._recovery_motion("moved to the observation pose", self._send(motion, sim_s))

    def _step_carry(self, sim_s: float) -> list:
        q = self._obs.state.q_rad
        # A direct motion from wherever the stop left the arm: over the drop zone (recovery_drop_xy_m), where
        # the arm can pick the object again, else (none configured, or out of reach) over the place pose.
        target, where = self._drop_approach_target(q), "the drop zone"
        if target is None:
            target, where = self._place_approach_target(q), "the place pose"
        # Holding the object, like the transfer: slowed down the same way.
        motion = self._held_motion(lambda limits: plan_joint_motion(q, target, limits, dt_s=self._cfg.sample_dt_s))
        return self._recovery_motion(f"carried the held object over {where}", self._send(motion, sim_s), True)

    def _drop_approach_target(self, q: np.ndarray) -> np.ndarray | None:
        """Joints above the drop zone (and self._drop_M, the put-down pose), or None without one in reach."""
        if self._cfg.recovery_drop_xy_m is None:
            return None
        x, y = (float(v) for v in self._cfg.recovery_drop_xy_m)
        drop_p = self._release_point([x, y, self._cfg.table_z_m + MIN_TCP_HEIGHT_ABOVE_TABLE_M])
        approach_p = drop_p + [0.0, 0.0, self._cfg.place_approach_height_m]
        try:
            check_workspace(drop_p, self._cfg.table_z_m)
            approach, yaw = self._kin.top_down_ik(approach_p, top_down_yaw(self._kin.fk(q)), q)
            self._kin.ik(top_down_pose(drop_p, yaw), approach.q_rad)
        except (KinematicsError, ValueError) as error:
            self._recovery_log.append(f"drop zone ({x:.2f}, {y:.2f}) out of reach ({error})")
            return None
        self._drop_M = top_down_pose(drop_p, yaw)
        return approach.q_rad

    def _step_lower(self, sim_s: float) -> list:
        # Not watched for a slip: this lowering follows a failure, where the object may sit anywhere in the
        # hand, so its bottom's height is unknown; touching down pushes it up between the fingers, which
        # would read as a drop (the pick's own place lowering is watched down to TOUCHDOWN_MARGIN_M).
        # Guarded instead: it stops where the object meets the table or whatever stands there.
        if self._drop_M is not None:
            target, where = self._drop_M[:3, 3], "the drop zone"
        else:
            target, where = self._release_point(self._plan.place_M[:3, 3]), "the place pose"
        self._obs.force_bias_n = self._obs.force_n.copy()
        self._guarded_lowering = True
        commands = self._line_to(target, self._cfg.place_lowering_speed_mps, sim_s)
        return self._recovery_motion(f"lowered it at {where}", commands)

    def _step_release(self, sim_s: float) -> list:
        self._placed_open_sent = True
        self._step_name, self._awaiting = "released it there", "gripper"
        return self._send_gripper(MoveGripper(self._release_width_m(), OPENING_SPEED_MPS), sim_s)

    def _release_width_m(self) -> float:
        """How far the hand opens to let the object go: place_release_opening_m wider than it closed on it (at most
        the pre-grasp opening). Opened fully, a finger reaches 4 cm from the object's centre and pushes whatever
        stands beside it: a neighbour in the bin, or the bin's wall ('fingers blocked at 47 mm')."""
        opened = self._plan.gripper.pre_open_width_m
        closed = self.outcome.gripper_width_closed_m
        if not math.isfinite(closed):
            return opened
        return min(opened, closed + self._cfg.place_release_opening_m)

    def _step_retreat(self, sim_s: float) -> list:
        return self._recovery_motion("retreated up", self._line_up(self._cfg.place_approach_height_m, sim_s))

    def _finish(self, sim_s: float, arm_state: str) -> None:
        self._squeeze_outcome()
        phase = self._failed_phase or self._phase
        self.outcome.phase_reached = phase if phase not in ("idle", RECOVER_PHASE) else "pre_grasp"
        self.outcome.duration_s = max(0.0, sim_s - self._start_s)
        self.outcome.arm_state = arm_state
        self.outcome.recovery = "; ".join(self._recovery_log)
        self._stopping = False
        self.finished = True


class ObservationMove(PickPlaceSequence):
    """Bring the arm to config.observation_q_rad before a camera frame is planned on.

    TCP straight up by observation_lift_m (when below the observation pose), then a
    joint motion; the hand is left as it is. Succeeds at the observation pose; any
    failure stops the arm as in a pick (same events, commands and outcome).
    """

    def __init__(self, kin: PandaKinematics, config: SequenceConfig):
        if config.observation_q_rad is None:
            raise ValueError("ObservationMove needs config.observation_q_rad")
        super().__init__(kin, config, None, None)

    def _start(self, sim_s: float) -> list:
        self._recovering, self._phase = True, RECOVER_PHASE
        self._recovery_steps = [self._step_lift, self._step_observe]
        return self._next_recovery_step(sim_s)

    def _finish(self, sim_s: float, arm_state: str) -> None:
        super()._finish(sim_s, arm_state)
        self.outcome.success = arm_state == "observation_pose" and not self.outcome.canceled
        if not self.outcome.success and not self.outcome.failure_reason:
            self.outcome.failure_reason = (f"could not bring the arm to the observation pose: "
                                           f"{self.outcome.recovery or arm_state}")


class _DriverSilent(SequenceFailure):
    """No joint states: there is nobody to wait for, end at once."""
