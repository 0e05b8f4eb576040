"""Joint trajectory tracking in sim time, like ros2_control's joint_trajectory_controller.

A trajectory is a list of waypoints (time from start, positions[, velocities
[, accelerations]]). Between waypoints it is interpolated: linear when only
positions are given, cubic Hermite with velocities, quintic with velocities
and accelerations. When the first waypoint lies after the time the trajectory
is received, the segment from the measured state then (position and velocity,
acceleration 0: interpolate_from_desired_state false, the controller's
default; ros2_controllers jazzy, joint_trajectory_controller.cpp `update` and
trajectory.cpp `set_point_before_trajectory_msg`) is interpolated too. After
the last waypoint the last position is held. Pure numpy; no rclpy, no PyBullet.
"""
from dataclasses import dataclass

import numpy as np


class TrajectoryError(ValueError):
    """A commanded trajectory is malformed (sizes, times, non-finite values)."""


@dataclass(frozen=True)
class Waypoint:
    time_from_start_s: float
    positions: np.ndarray
    velocities: np.ndarray | None = None
    accelerations: np.ndarray | None = None


def _check_vector(values, n_joints: int, what: str):
    if values is None or len(values) == 0:
        return None
    arr = np.asarray(values, dtype=float)
    if arr.shape != (n_joints,):
        raise TrajectoryError(f"{what} has {arr.size} values, expected {n_joints}")
    if not np.all(np.isfinite(arr)):
        raise TrajectoryError(f"{what} holds non-finite values: {arr.tolist()}")
    return arr


def make_waypoints(points, n_joints: int) -> list:
    """Validate (time_s, positions, velocities, accelerations) tuples into Waypoints."""
    out = []
    last_t = -np.inf
    for i, (t_s, q, qd, qdd) in enumerate(points):
        if not np.isfinite(t_s) or t_s < 0:
            raise TrajectoryError(f"point {i}: time_from_start {t_s} must be finite and >= 0")
        if t_s <= last_t:
            raise TrajectoryError(f"point {i}: time_from_start {t_s} s is not after the previous {last_t} s")
        positions = _check_vector(q, n_joints, f"point {i} positions")
        if positions is None:
            raise TrajectoryError(f"point {i} has no positions")
        out.append(Waypoint(float(t_s), positions, _check_vector(qd, n_joints, f"point {i} velocities"),
                            _check_vector(qdd, n_joints, f"point {i} accelerations")))
        last_t = t_s
    return out


def _segment(t, t0, t1, a: Waypoint, b: Waypoint, quintic):
    """Position and velocity at t within the segment a -> b (times t0 < t1); quintic: the segment's
    _quintic_coefficients when it is one (_is_quintic), else None."""
    dt = t1 - t0
    s = np.clip((t - t0) / dt, 0.0, 1.0)
    if quintic is not None:
        c0, c1, c2, c3, c4, c5 = quintic
        q = c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))))
        qd = c1 + s * (2 * c2 + s * (3 * c3 + s * (4 * c4 + s * 5 * c5)))
        return q, qd / dt
    if a.velocities is None or b.velocities is None:
        q = a.positions + s * (b.positions - a.positions)
        return q, (b.positions - a.positions) / dt
    return _hermite3(s, dt, a.positions, a.velocities, b.positions, b.velocities)


def _is_quintic(a: Waypoint, b: Waypoint) -> bool:
    """Both ends give velocities and accelerations: the segment is the quintic through them."""
    return all(v is not None for v in (a.velocities, a.accelerations, b.velocities, b.accelerations))


def _hermite3(s, dt, q0, v0, q1, v1):
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    q = h00 * q0 + h10 * dt * v0 + h01 * q1 + h11 * dt * v1
    qd = (d00 * q0 + d10 * dt * v0 + d01 * q1 + d11 * dt * v1) / dt
    return q, qd


def _quintic_coefficients(dt, a: Waypoint, b: Waypoint) -> tuple:
    """Quintic with matching position, velocity and acceleration at both ends, in the normalised time s:
    the coefficients c0..c5 of q(s) = sum c_k s^k."""
    q0, v0, a0 = a.positions, a.velocities * dt, a.accelerations * dt**2
    q1, v1, a1 = b.positions, b.velocities * dt, b.accelerations * dt**2
    c3 = 10 * (q1 - q0) - 6 * v0 - 4 * v1 - 1.5 * a0 + 0.5 * a1
    c4 = -15 * (q1 - q0) + 8 * v0 + 7 * v1 + 1.5 * a0 - a1
    c5 = 6 * (q1 - q0) - 3 * v0 - 3 * v1 - 0.5 * a0 + 0.5 * a1
    return q0, v0, a0 / 2, c3, c4, c5


class TrajectoryTracker:
    """Desired joint state over sim time for the active trajectory."""

    def __init__(self, initial_q):
        self._hold_q = np.asarray(initial_q, dtype=float).copy()
        self._n = self._hold_q.size
        self._start_s = 0.0
        self._points: list = []
        self._sampled = (None, None)   # (time_s, (q, qd)) of the last sample: the sim step and the controller's
        # check of one period ask for the same time
        self._quintics = {}            # segment index -> _quintic_coefficients, or None: not a quintic segment
        self._times_s = np.empty(0)    # the points' times from start

    @property
    def n_joints(self) -> int:
        return self._n

    def hold(self, q) -> None:
        """Stop following any trajectory and hold q."""
        self._hold_q = np.asarray(q, dtype=float).copy()
        self._points = []
        self._sampled = (None, None)

    def replace(self, waypoints: list, start_time_s: float, current_q, current_qd=None,
                now_s: float | None = None) -> None:
        """Follow a new trajectory from start_time_s, received at now_s (default: start_time_s) with the arm
        measured at (current_q, current_qd; None = at rest); an empty one holds current_q.

        Like joint_trajectory_controller: when the first waypoint is still ahead at now_s, the trajectory blends
        into it from the measured position and velocity at now_s, with the first waypoint's kind of interpolation
        (linear without its velocities: the measured velocity is then unused)."""
        if not waypoints:
            self.hold(current_q)
            return
        now_s = float(start_time_s if now_s is None else now_s)
        first = waypoints[0]
        if now_s < start_time_s + first.time_from_start_s:
            qd = np.zeros(self._n) if current_qd is None else np.asarray(current_qd, dtype=float).copy()
            start = Waypoint(now_s - float(start_time_s), np.asarray(current_q, dtype=float).copy(),
                             qd if first.velocities is not None else None,
                             np.zeros(self._n) if first.accelerations is not None else None)
            waypoints = [start] + list(waypoints)
        self._points = list(waypoints)
        self._times_s = np.array([point.time_from_start_s for point in self._points])
        self._start_s = float(start_time_s)
        self._sampled, self._quintics = (None, None), {}
        self._hold_q = self._points[-1].positions.copy()

    def end_time_s(self) -> float | None:
        """Sim time of the last waypoint; None while holding."""
        return self._start_s + self._points[-1].time_from_start_s if self._points else None

    def is_active(self, time_s: float) -> bool:
        return bool(self._points) and time_s - self._start_s < self._points[-1].time_from_start_s

    def sample(self, time_s: float):
        """(positions, velocities) desired at sim time time_s (arrays of the caller's own)."""
        if self._sampled[0] != time_s:
            self._sampled = (time_s, self._sample(time_s))
        q, qd = self._sampled[1]
        return q.copy(), qd.copy()

    def _sample(self, time_s: float):
        if not self._points:
            return self._hold_q.copy(), np.zeros(self._n)
        t = time_s - self._start_s
        pts = self._points
        if t <= pts[0].time_from_start_s:
            first = pts[0]
            return first.positions.copy(), np.zeros(self._n) if first.velocities is None else first.velocities.copy()
        if t >= pts[-1].time_from_start_s:
            return pts[-1].positions.copy(), np.zeros(self._n)
        times = self._times_s
        i = int(np.searchsorted(times, t, side="right")) - 1
        a, b = pts[i], pts[i + 1]
        if i not in self._quintics:
            self._quintics[i] = _quintic_coefficients(times[i + 1] - times[i], a, b) if _is_quintic(a, b) else None
        return _segment(t, times[i], times[i + 1], a, b, self._quintics[i])
