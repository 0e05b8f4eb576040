"""Jerk-limited joint trajectories with Ruckig, sampled for a JointTrajectory.

Three kinds of motion, all planned offline (`Ruckig.calculate`) and sampled
at a fixed period so every point can be checked against the limits before
anything is sent to the robot:
- `plan_joint_motion`: rest-to-rest (or from a moving state) point-to-point;
- `plan_line`: a straight TCP line at fixed orientation (descend, lift):
  dense warm-started IK along the line, then a 1-D Ruckig profile on the
  arc length whose limits are derived from the joints' path derivatives;
- `plan_stop`: the jerk-limited stop to zero velocity from any state
  (Ruckig's velocity interface).
"""
import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Synchronization, Trajectory

from defgg_ros.constants import (
    ARM_JOINT_LIMITS,
    ARM_MODELS,
    ARM_VELOCITY_ENVELOPES,
)
from defgg_ros.control.kinematics import (
    MIN_LINK_HEIGHT_ABOVE_TABLE_M,
    MIN_TCP_HEIGHT_ABOVE_TABLE_M,
    KinematicsError,
    PandaKinematics,
)

# Fraction of Franka's published velocity/acceleration/jerk limits we plan
# with: the datasheet values are the hardware's reflex limits, and the
# tracking controller needs headroom above the plan.
LIMITS_SAFETY_SCALE = 0.4
# Joint trajectory sampling period (the driver interpolates between points).
SAMPLE_DT_S = 0.02
# Sampled values may exceed a limit by this relative amount (float rounding
# and finite differences), nothing more.
LIMIT_RTOL = 1e-6
JOINT_ATOL = 1e-6  # rad, position limit slack in checks
# Passing a via point: the slowest joint goes through at this fraction of its velocity limit.
VIA_SPEED_FRACTION = 0.5
# Straight lines: IK grid spacing and the largest joint jump allowed between
# neighbouring grid points (a larger one means a branch switch/singularity).
LINE_GRID_STEP_M = 0.005
LINE_MAX_JOINT_STEP_RAD = 0.1
LINE_FINE_SUBSTEPS = 10       # a grid step whose joints jump more is walked again in this many steps
LINE_IK_ATOL_M = 1e-7
LINE_IK_ATOL_RAD = 1e-6
# A line the grid's limits let run too fast is re-timed at most this often, each time this much slower than
# the measured overshoot asks for (the new profile's shape differs a little from a pure time scaling).
LINE_RETIMING_TRIES = 4
LINE_RETIMING_MARGIN = 1.05
# The TCP may leave the commanded line by at most this much.
LINE_DEVIATION_ATOL_M = 1e-4
# Cartesian caps of line motions (guarded descent must be slow enough for
# the contact check to stop the arm before it presses hard).
DEFAULT_LINE_SPEED_MPS = 0.05
LINE_MAX_ACCELERATION_MPS2 = 0.5
LINE_MAX_JERK_MPS3 = 5.0
# Frames that are allowed at/below the table: the base sits on it, and
# panda_grasptarget is a virtual link of the URDF 1.6 mm below the TCP.
TABLE_EXEMPT_FRAMES = frozenset({"universe", "panda_link0", "panda_grasptarget"})


class TrajectoryError(KinematicsError):
    """A motion that cannot be planned, or a plan that breaks a limit."""


@dataclass(frozen=True)
class JointLimits:
    q_min_rad: np.ndarray
    q_max_rad: np.ndarray
    qd_max_radps: np.ndarray
    qdd_max_radps2: np.ndarray
    qddd_max_radps3: np.ndarray
    # The robot's position-dependent velocity bound (constants.FR3_VELOCITY_ENVELOPE rows), or None. Not scaled:
    # it is where the controller aborts, and the plan keeps to the scaled constant bounds besides.
    velocity_envelope: np.ndarray | None = None


def envelope_velocity_bounds(envelope: np.ndarray, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) velocity bounds (rad/s) at joint positions q_rad (shape (..., 7)) under `envelope`."""
    v_max, offset, k, q_upper, q_lower = envelope.T
    upper = np.minimum(v_max, np.maximum(0.0, -offset + np.sqrt(np.maximum(0.0, k * (q_upper - q_rad)))))
    lower = np.maximum(-v_max, np.minimum(0.0, offset - np.sqrt(np.maximum(0.0, k * (q_rad - q_lower)))))
    return lower, upper


def arm_limits(arm: str = "panda", scale: float = LIMITS_SAFETY_SCALE) -> JointLimits:
    """The arm model's limits (panda or fr3) with velocity/acceleration/jerk scaled by `scale` in (0, 1]."""
    if arm not in ARM_JOINT_LIMITS:
        raise ValueError(f"unknown arm model {arm!r}; known: {', '.join(ARM_MODELS)}")
    if not 0.0 < scale <= 1.0:
        raise ValueError(f"limits scale must be in (0, 1], got {scale}")
    q_min, q_max, qd, qdd, qddd = (np.array(v) for v in ARM_JOINT_LIMITS[arm])
    envelope = ARM_VELOCITY_ENVELOPES.get(arm)
    return JointLimits(q_min, q_max, scale * qd, scale * qdd, scale * qddd,
                       None if envelope is None else np.array(envelope, dtype=float))


def panda_limits(scale: float = LIMITS_SAFETY_SCALE) -> JointLimits:
    """The Panda's limits with velocity/acceleration/jerk scaled by `scale` in (0, 1]."""
    return arm_limits("panda", scale)


@dataclass(frozen=True)
class SampledTrajectory:
    """Joint trajectory sampled in time; rows are samples, columns the 7 joints."""

    times_s: np.ndarray
    q_rad: np.ndarray
    qd_radps: np.ndarray
    qdd_radps2: np.ndarray

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])

    @property
    def final_q_rad(self) -> np.ndarray:
        return self.q_rad[-1]

    def state_at(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, qdd) at time t, interpolated linearly between samples, held outside."""
        t = min(max(t_s, 0.0), self.duration_s)
        i = int(np.clip(np.searchsorted(self.times_s, t, side="right") - 1, 0, len(self.times_s) - 1))
        if i == len(self.times_s) - 1:
            return self.q_rad[i].copy(), self.qd_radps[i].copy(), self.qdd_radps2[i].copy()
        w = (t - self.times_s[i]) / (self.times_s[i + 1] - self.times_s[i])
        lerp = lambda a: (1 - w) * a[i] + w * a[i + 1]  # noqa: E731
        return lerp(self.q_rad), lerp(self.qd_radps), lerp(self.qdd_radps2)


def matched_state(trajectory: SampledTrajectory, q_measured_rad) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, qd, qdd) to continue from: the measured position with the commanded velocity and
    acceleration of the sample nearest to it.

    Matching by position rather than by clock keeps a stop continuous even
    when the command reached the robot late (message latency, a simulator
    running faster than real time).
    """
    q = np.asarray(q_measured_rad, dtype=float)
    k = nearest_sample(trajectory, q)
    return q.copy(), trajectory.qd_radps[k].copy(), trajectory.qdd_radps2[k].copy()


def nearest_sample(trajectory: SampledTrajectory, q_rad) -> int:
    """Index of the sample nearest q_rad (the largest joint difference)."""
    return int(np.argmin(np.max(np.abs(trajectory.q_rad - np.asarray(q_rad, dtype=float)), axis=1)))


def hold(q_rad) -> SampledTrajectory:
    """A one-point trajectory: stay at q."""
    q = np.asarray(q_rad, dtype=float).reshape(1, 7)
    zeros = np.zeros_like(q)
    return SampledTrajectory(np.zeros(1), q, zeros, zeros.copy())


def _sample_times(duration_s: float, dt_s: float) -> np.ndarray:
    if duration_s <= 0:
        return np.zeros(1)
    times = np.arange(0.0, duration_s, dt_s)
    # End exactly at the duration without a sliver of an interval before it.
    if len(times) > 1 and duration_s - times[-1] < 0.5 * dt_s:
        times = times[:-1]
    return np.append(times, duration_s)


def _calculate(inp: InputParameter, what: str) -> Trajectory:
    trajectory = Trajectory(inp.degrees_of_freedom)
    result = Ruckig(inp.degrees_of_freedom).calculate(inp, trajectory)
    if result not in (Result.Working, Result.Finished):
        raise TrajectoryError(f"Ruckig could not plan the {what}: {result.name}")
    return trajectory


def _sample_ruckig(trajectory: Trajectory, dt_s: float) -> SampledTrajectory:
    times = _sample_times(trajectory.duration, dt_s)
    samples = [trajectory.at_time(float(t)) for t in times]
    q, qd, qdd = (np.array([s[k] for s in samples], dtype=float) for k in range(3))
    return SampledTrajectory(times, q, qd, qdd)


def _joint_input(limits: JointLimits, q_start, qd_start, qdd_start) -> InputParameter:
    inp = InputParameter(7)
    inp.current_position = np.asarray(q_start, dtype=float).tolist()
    # A state marginally outside the (scaled) limits is Ruckig-invalid; a
    # measured state can be, so bring it inside.
    inp.current_velocity = np.clip(qd_start, -limits.qd_max_radps, limits.qd_max_radps).tolist()
    inp.current_acceleration = np.clip(qdd_start, -limits.qdd_max_radps2, limits.qdd_max_radps2).tolist()
    inp.max_velocity = limits.qd_max_radps.tolist()
    inp.max_acceleration = limits.qdd_max_radps2.tolist()
    inp.max_jerk = limits.qddd_max_radps3.tolist()
    return inp


def _check_joints(name: str, q_rad, limits: JointLimits) -> np.ndarray:
    q = np.asarray(q_rad, dtype=float)
    if q.shape != (7,) or not np.all(np.isfinite(q)):
        raise TrajectoryError(f"joint motion {name} must be 7 finite values, got {q.tolist()}")
    if np.any(q < limits.q_min_rad - JOINT_ATOL) or np.any(q > limits.q_max_rad + JOINT_ATOL):
        raise TrajectoryError(f"joint motion {name} is outside the joint limits: {np.round(q, 4).tolist()}")
    return q


def plan_joint_motion(q_start, q_goal, limits: JointLimits, qd_start=None, qdd_start=None,
                      dt_s: float = SAMPLE_DT_S) -> SampledTrajectory:
    """Time-optimal jerk-limited motion from a state to rest at q_goal."""
    q0 = _check_joints("start", q_start, limits)
    q1 = _check_joints("goal", q_goal, limits)
    zeros = np.zeros(7)
    inp = _joint_input(limits, q0, zeros if qd_start is None else qd_start, zeros if qdd_start is None else qdd_start)
    inp.target_position = q1.tolist()
    inp.target_velocity = zeros.tolist()
    inp.target_acceleration = zeros.tolist()
    return _sample_ruckig(_calculate(inp, "joint motion"), dt_s)


def _plan_to_state(q_start, qd_start, q_goal, qd_goal, limits: JointLimits) -> Trajectory:
    inp = _joint_input(limits, q_start, qd_start, np.zeros(7))
    inp.target_position = np.asarray(q_goal, dtype=float).tolist()
    inp.target_velocity = np.asarray(qd_goal, dtype=float).tolist()
    inp.target_acceleration = np.zeros(7).tolist()
    return _calculate(inp, "joint motion through a via point")


def via_velocity(q_start, q_via, q_goal, limits: JointLimits, fraction: float = VIA_SPEED_FRACTION) -> np.ndarray:
    """Joint velocity to pass q_via with: along the overall motion, zero for joints that turn back there."""
    q0, q1, q2 = (np.asarray(q, dtype=float) for q in (q_start, q_via, q_goal))
    through = (q1 - q0) * (q2 - q1) > 0
    total = q2 - q0
    # Scaled so the joint needing the longest time at full speed passes at `fraction` of its limit.
    reference_time_s = float(np.max(np.abs(total) / limits.qd_max_radps))
    if reference_time_s <= 0:
        return np.zeros(7)
    return np.where(through, fraction * total / reference_time_s, 0.0)


def plan_joint_via(q_start, q_via, q_goal, limits: JointLimits, dt_s: float = SAMPLE_DT_S,
                   fraction: float = VIA_SPEED_FRACTION) -> SampledTrajectory:
    """Rest -> through q_via without stopping -> rest at q_goal (two Ruckig segments joined at the via)."""
    q_start, q_via, q_goal = (_check_joints(name, q, limits) for name, q in
                              (("start", q_start), ("via", q_via), ("goal", q_goal)))
    v_via = via_velocity(q_start, q_via, q_goal, limits, fraction)
    first = _plan_to_state(q_start, np.zeros(7), q_via, v_via, limits)
    second = _plan_to_state(q_via, v_via, q_goal, np.zeros(7), limits)
    a, b = _sample_ruckig(first, dt_s), _sample_ruckig(second, dt_s)
    # The via sample ends the first part and starts the second: keep it once.
    return SampledTrajectory(np.concatenate([a.times_s, b.times_s[1:] + a.duration_s]),
                             np.vstack([a.q_rad, b.q_rad[1:]]), np.vstack([a.qd_radps, b.qd_radps[1:]]),
                             np.vstack([a.qdd_radps2, b.qdd_radps2[1:]]))


def plan_stop(q_rad, qd_radps, qdd_radps2, limits: JointLimits, dt_s: float = SAMPLE_DT_S,
              synchronized: bool = True) -> SampledTrajectory:
    """Jerk-limited stop: brings velocity and acceleration to zero as fast as the limits allow.

    synchronized: every joint comes to rest at the same time (the TCP keeps roughly to its path); False:
    each joint brakes as hard as it may, so each travels the least (the stop of last resort)."""
    inp = _joint_input(limits, q_rad, qd_radps, qdd_radps2)
    inp.control_interface = ControlInterface.Velocity
    inp.target_velocity = np.zeros(7).tolist()
    inp.target_acceleration = np.zeros(7).tolist()
    if not synchronized:
        inp.synchronization = Synchronization.No
    return _sample_ruckig(_calculate(inp, "stop"), dt_s)


def plan_checked_stop(q_rad, qd_radps, qdd_radps2, limits: JointLimits, kin: PandaKinematics, table_z_m: float,
                      dt_s: float = SAMPLE_DT_S) -> tuple[SampledTrajectory, str]:
    """The stop to send and "" when it passes check_trajectory; else the stop of last resort and why it fails.

    A stop is sent whatever the check says (standing still is not on offer), but it is checked like every
    other motion: the synchronised stop first; where it would leave a joint's range or go below the table,
    the unsynchronised one (each joint travels the least); when neither passes, the latter, with the
    breach, for the caller to report."""
    synced = plan_stop(q_rad, qd_radps, qdd_radps2, limits, dt_s)
    try:
        check_trajectory(synced, limits, kin, table_z_m)
        return synced, ""
    except TrajectoryError as first:
        shortest = plan_stop(q_rad, qd_radps, qdd_radps2, limits, dt_s, synchronized=False)
        try:
            check_trajectory(shortest, limits, kin, table_z_m)
            return shortest, ""
        except TrajectoryError as error:
            return shortest, f"the stop itself fails its check ({error}; synchronised: {first})"


# --- straight TCP lines ------------------------------------------------------
def _line_grid(kin: PandaKinematics, q_start: np.ndarray, start_M: np.ndarray, direction: np.ndarray,
               length_m: float) -> tuple[np.ndarray, np.ndarray]:
    n = max(4, math.ceil(length_m / LINE_GRID_STEP_M) + 1)
    s_grid = np.linspace(0.0, length_m, n)
    q_grid = [q_start]
    for s_before, s in zip(s_grid[:-1], s_grid[1:]):
        q = _line_ik(kin, start_M, direction, s, q_grid[-1])
        if float(np.max(np.abs(q - q_grid[-1]))) > LINE_MAX_JOINT_STEP_RAD:
            q = _walk_finely(kin, start_M, direction, s_before, s, q_grid[-1])
        q_grid.append(q)
    return s_grid, np.array(q_grid)


def _line_ik(kin: PandaKinematics, start_M: np.ndarray, direction: np.ndarray, s: float, seed) -> np.ndarray:
    target = start_M.copy()
    target[:3, 3] += s * direction
    try:
        return kin.ik(target, seed, restarts=0, pos_atol_m=LINE_IK_ATOL_M, rot_atol_rad=LINE_IK_ATOL_RAD).q_rad
    except KinematicsError as error:
        raise TrajectoryError(f"straight line leaves the reachable workspace after {s * 1000:.0f} mm: "
                              f"{error}") from error


def _walk_finely(kin: PandaKinematics, start_M, direction, s_from: float, s_to: float, q_from) -> np.ndarray:
    """q at s_to, reached from q_from in LINE_FINE_SUBSTEPS steps. A joint that turns fast but steadily (a
    grasp near the base: 0.04 rad per mm at every step size) takes a tenth of the jump a step; a branch flip
    or a joint limit keeps its whole jump in one step, and that is refused."""
    q = np.asarray(q_from, dtype=float)
    for s in np.linspace(s_from, s_to, LINE_FINE_SUBSTEPS + 1)[1:]:
        q_next = _line_ik(kin, start_M, direction, s, q)
        step = float(np.max(np.abs(q_next - q)))
        if step > LINE_MAX_JOINT_STEP_RAD / 2:
            substep_mm = (s_to - s_from) / LINE_FINE_SUBSTEPS * 1000
            raise TrajectoryError(f"straight line passes near a singularity or joint limit after {s * 1000:.1f} "
                                  f"mm (joint jump {step:.3f} rad in {substep_mm:.1f} mm)")
        q = q_next
    return q


def _path_limits(s_grid: np.ndarray, q_grid: np.ndarray, limits: JointLimits,
                 max_speed_mps: float) -> tuple[float, float, float]:
    """Arc-length velocity/acceleration/jerk limits that keep every joint within its limits.

    qd = q' v, qdd = q'' v^2 + q' a, qddd = q''' v^3 + 3 q'' v a + q' j (primes:
    d/ds); each term gets its share of the joint's budget.
    """
    h = s_grid[1] - s_grid[0]
    tiny = 1e-12
    d1 = np.max(np.abs(np.diff(q_grid, 1, axis=0)), axis=0) / h + tiny
    d2 = np.max(np.abs(np.diff(q_grid, 2, axis=0)), axis=0) / h**2 + tiny
    d3 = np.max(np.abs(np.diff(q_grid, 3, axis=0)), axis=0) / h**3 + tiny
    qd, qdd, qddd = limits.qd_max_radps, limits.qdd_max_radps2, limits.qddd_max_radps3
    v = min(max_speed_mps, float(np.min(qd / d1)), float(np.min(np.sqrt(0.5 * qdd / d2))),
            float(np.min(np.cbrt(qddd / 3.0 / d3))))
    a = min(LINE_MAX_ACCELERATION_MPS2, float(np.min(0.5 * qdd / d1)), float(np.min(qddd / 3.0 / (3.0 * d2 * v))))
    j = min(LINE_MAX_JERK_MPS3, float(np.min(qddd / 3.0 / d1)))
    return v, a, j


def _finite_differences(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    if len(times) < 3:
        return np.zeros_like(values)
    return np.gradient(values, times, axis=0)


def plan_line(kin: PandaKinematics, q_start, displacement_m, limits: JointLimits,
              max_speed_mps: float = DEFAULT_LINE_SPEED_MPS, dt_s: float = SAMPLE_DT_S) -> SampledTrajectory:
    """Straight TCP line by `displacement_m` (base frame) at constant orientation, from rest to rest."""
    q0 = np.asarray(q_start, dtype=float)
    d = np.asarray(displacement_m, dtype=float)
    if d.shape != (3,) or not np.all(np.isfinite(d)):
        raise TrajectoryError(f"line displacement must be 3 finite values, got {d.tolist()}")
    if not max_speed_mps > 0:
        raise TrajectoryError(f"line speed must be positive, got {max_speed_mps}")
    length = float(np.linalg.norm(d))
    if length < LINE_IK_ATOL_M:
        return hold(q0)
    start_M = kin.fk(q0)
    direction = d / length
    s_grid, q_grid = _line_grid(kin, q0, start_M, direction, length)
    v, a, j = _path_limits(s_grid, q_grid, limits, max_speed_mps)
    for _ in range(LINE_RETIMING_TRIES):
        line = _sample_line(kin, q0, start_M, direction, length, (v, a, j), dt_s)
        # The path limits come from the grid's finite differences, which can miss how fast the joints turn
        # between grid points near a singularity (a grasp 0.33 m from the base overshot the acceleration
        # limit 2x): then the same line, slowed by the factor that brings every ratio within its limit.
        slower = _slowdown_factor(line, limits)
        if slower <= 1.0 + LIMIT_RTOL:
            return line
        slower *= LINE_RETIMING_MARGIN
        v, a, j = v / slower, a / slower ** 2, j / slower ** 3
    return line   # still too fast: check_trajectory reports by how much


def _sample_line(kin: PandaKinematics, q0, start_M, direction, length: float, vaj: tuple,
                 dt_s: float) -> SampledTrajectory:
    """The line under a Ruckig profile of path velocity, acceleration and jerk limits vaj, sampled every dt_s."""
    inp = InputParameter(1)
    inp.current_position, inp.target_position = [0.0], [length]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [vaj[0]], [vaj[1]], [vaj[2]]
    profile = _calculate(inp, "straight line")
    times = _sample_times(profile.duration, dt_s)
    q = [q0]
    for t in times[1:]:
        target = start_M.copy()
        target[:3, 3] += profile.at_time(float(t))[0][0] * direction
        q.append(kin.ik(target, q[-1], restarts=0, pos_atol_m=LINE_IK_ATOL_M, rot_atol_rad=LINE_IK_ATOL_RAD).q_rad)
    q = np.array(q)
    qd = _finite_differences(times, q)
    qdd = _finite_differences(times, qd)
    # The profile starts and ends at rest; finite differences blur that.
    qd[[0, -1]] = 0.0
    qdd[[0, -1]] = 0.0
    return SampledTrajectory(times, q, qd, qdd)


def _slowdown_factor(trajectory: SampledTrajectory, limits: JointLimits) -> float:
    """A time scale k that brings every sample within the limits. A smooth path's accelerations fall as 1/k^2
    and its jerks as 1/k^3, but where the joint path kinks (near a singularity) the sampled acceleration of the
    kink falls only as 1/k (measured: 2.03 -> 1.59 for k = 1.5), so k is the largest ratio itself."""
    return max(_limit_ratios(trajectory, limits).values())


# --- checks ------------------------------------------------------------------
def _limit_ratios(trajectory: SampledTrajectory, limits: JointLimits) -> dict:
    """Largest |velocity|, |acceleration| and |jerk| (from the accelerations' differences) over their limits."""
    qd, qdd, t = trajectory.qd_radps, trajectory.qdd_radps2, trajectory.times_s
    qddd = np.diff(qdd, axis=0) / np.diff(t)[:, None] if len(t) > 1 else np.zeros((1, 7))
    return {name: float(np.max(np.abs(values) / limit))
            for name, values, limit in (("velocity", qd, limits.qd_max_radps),
                                        ("acceleration", qdd, limits.qdd_max_radps2),
                                        ("jerk", qddd, limits.qddd_max_radps3))}


def scaled_in_time(limits: JointLimits, factor: float) -> JointLimits:
    """Limits for the same motions `factor` (>= 1) times slower: velocity / factor, acceleration / factor^2,
    jerk / factor^3 (a time-optimal plan within them is the original slowed down: every acceleration of
    the arm, the TCP's included, falls by factor^2). Ranges and the velocity envelope stay."""
    if not factor >= 1.0:
        raise ValueError(f"time factor must be >= 1, got {factor}")
    return dataclasses.replace(limits, qd_max_radps=limits.qd_max_radps / factor,
                               qdd_max_radps2=limits.qdd_max_radps2 / factor ** 2,
                               qddd_max_radps3=limits.qddd_max_radps3 / factor ** 3)


def tcp_peak_acceleration_mps2(kin: PandaKinematics, trajectory: SampledTrajectory) -> float:
    """Largest linear acceleration of the TCP over the trajectory (second differences of its FK positions)."""
    if len(trajectory.times_s) < 3:
        return 0.0
    p = np.array([kin.fk(q)[:3, 3] for q in trajectory.q_rad])
    dt = np.diff(trajectory.times_s)
    v = np.diff(p, axis=0) / dt[:, None]
    a = np.diff(v, axis=0) / (0.5 * (dt[1:] + dt[:-1]))[:, None]
    return float(np.max(np.linalg.norm(a, axis=1)))


def _check_envelope(trajectory: SampledTrajectory, envelope: np.ndarray) -> None:
    """TrajectoryError where a joint moves faster than the position-dependent bound allows there."""
    q, qd = trajectory.q_rad, trajectory.qd_radps
    lower, upper = envelope_velocity_bounds(envelope, q)
    excess = np.maximum(qd - upper, lower - qd)
    if np.max(excess) > JOINT_ATOL:
        k, joint = np.unravel_index(int(np.argmax(excess)), excess.shape)
        bound = upper[k, joint] if qd[k, joint] > 0 else lower[k, joint]
        raise TrajectoryError(
            f"joint {joint + 1} moves at {qd[k, joint]:.3f} rad/s at {q[k, joint]:.4f} rad "
            f"(t={trajectory.times_s[k]:.2f} s), beyond the {bound:.3f} rad/s the arm's controller allows "
            "that near the end of its range")


@dataclass(frozen=True)
class LimitReport:
    """Largest |value| / limit over the trajectory, per quantity (<= 1 is within)."""

    velocity_ratio: float
    acceleration_ratio: float
    jerk_ratio: float
    min_tcp_height_m: float
    min_link_height_m: float


def check_trajectory(trajectory: SampledTrajectory, limits: JointLimits, kin: PandaKinematics,
                     table_z_m: float) -> LimitReport:
    """TrajectoryError if any sample breaks a joint limit or goes below the table; else the margins."""
    q, qd, qdd, t = trajectory.q_rad, trajectory.qd_radps, trajectory.qdd_radps2, trajectory.times_s
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd)) and np.all(np.isfinite(qdd))):
        raise TrajectoryError("trajectory has non-finite samples")
    below = q < limits.q_min_rad - JOINT_ATOL
    above = q > limits.q_max_rad + JOINT_ATOL
    if np.any(below | above):
        k, joint = np.argwhere(below | above)[0]
        raise TrajectoryError(f"joint {joint + 1} at {q[k, joint]:.4f} rad leaves its limits at t={t[k]:.2f} s")
    ratios = _limit_ratios(trajectory, limits)
    for name, ratio in ratios.items():
        if ratio > 1.0 + LIMIT_RTOL:
            raise TrajectoryError(f"{name} reaches {ratio:.3f} x its limit")
    if limits.velocity_envelope is not None:
        _check_envelope(trajectory, limits.velocity_envelope)
    tcp_min, link_min = math.inf, math.inf
    for qk in q:
        tcp_z, link_z = kin.lowest_heights_m(qk, TABLE_EXEMPT_FRAMES)
        tcp_min, link_min = min(tcp_min, tcp_z), min(link_min, link_z)
    if tcp_min < table_z_m + MIN_TCP_HEIGHT_ABOVE_TABLE_M - JOINT_ATOL:
        raise TrajectoryError(f"TCP goes down to {tcp_min:.4f} m, below the table at {table_z_m:.3f} m + clearance")
    if link_min < table_z_m + MIN_LINK_HEIGHT_ABOVE_TABLE_M:
        raise TrajectoryError(f"a link of the arm goes down to {link_min:.4f} m, below the table at {table_z_m:.3f} m")
    return LimitReport(ratios["velocity"], ratios["acceleration"], ratios["jerk"], tcp_min, link_min)
