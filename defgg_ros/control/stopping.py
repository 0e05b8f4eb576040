"""Where a hold puts a moving arm to rest without turning it back (pure; the executor's stop sends it).

A joint_trajectory_controller takes a new goal from the arm's measured position and velocity (ros2_controllers
jazzy, trajectory.cpp; docs/franka_contract.md), preempting the running one, and blends into the goal's one point
(zero velocity and acceleration) over the point's time_from_start T: with the start's acceleration 0, a quintic.
A point at the arm's position plus velocity x T/2 makes that blend a monotone deceleration to rest, velocity
v0 (1 - 3s^2 + 2s^3) with s = t/T, peak deceleration 1.5 v0/T (a point closer than 0.4 v0 T would turn the
arm back before the end). Where the arm is when the hold arrives: the last joint state carried on for its age
with its velocity and acceleration (a stop while the arm speeds up: its velocity then is higher than measured).
A point at the last measured position instead (the hold before 2026-12-01) lay behind a moving arm, which was
pulled back to it (lift 5.5 mrad, transfer 18.3 mrad in the simulated cell).
"""
import numpy as np

HOLD_BLEND_S = 0.1                 # the shortest blend to rest (s)
HOLD_ACCELERATION_SHARE = 0.5      # the blend's peak deceleration at most this share of a joint's limit
MAX_STATE_AGE_S = 0.1              # a joint state older than this is carried on for this long at most
PEAK_DECELERATION_FACTOR = 1.5     # the quintic blend's peak deceleration over v0 / T
MIN_BLEND_S = 0.01                 # shortest blend a joint limit may force (s)


def stopping_hold(q_rad, qd_radps, state_age_s: float, qdd_max_radps2, q_min_rad=None, q_max_rad=None,
                  qdd_radps2=None):
    """(hold position (rad), blend duration T (s)) for an arm measured at (q_rad, qd_radps[, qdd_radps2])
    state_age_s ago. T is the longer of HOLD_BLEND_S and what keeps the peak deceleration within
    HOLD_ACCELERATION_SHARE of each joint's limit, shortened where a joint would run past its range (given
    q_min_rad, q_max_rad): there the arm stops at the limit, harder. A non-finite velocity or acceleration (an
    estimator without a baseline yet) counts as 0: the hold is then at the carried-on position."""
    q = np.asarray(q_rad, dtype=float)
    if not np.all(np.isfinite(q)):
        raise ValueError(f"stopping_hold needs finite joint positions, got {q}")
    qd = np.nan_to_num(np.asarray(qd_radps, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
    limit = np.asarray(qdd_max_radps2, dtype=float)
    qdd = np.zeros_like(q) if qdd_radps2 is None else np.clip(
        np.nan_to_num(np.asarray(qdd_radps2, dtype=float), nan=0.0, posinf=0.0, neginf=0.0), -limit, limit)
    age_s = min(max(float(state_age_s), 0.0), MAX_STATE_AGE_S) if np.isfinite(state_age_s) else 0.0
    q_now, v_now = q + qd * age_s + 0.5 * qdd * age_s**2, qd + qdd * age_s
    duration_s = max(HOLD_BLEND_S, float(np.max(PEAK_DECELERATION_FACTOR * np.abs(v_now)
                                                / (HOLD_ACCELERATION_SHARE * limit))))
    if q_min_rad is not None and q_max_rad is not None:
        room = np.where(v_now > 0, np.asarray(q_max_rad) - q_now, q_now - np.asarray(q_min_rad))
        moving = np.abs(v_now) > 1e-9
        if np.any(moving):
            fits_s = 2.0 * np.maximum(room[moving], 0.0) / np.abs(v_now[moving])
            duration_s = max(MIN_BLEND_S, min(duration_s, float(np.min(fits_s))))
    return q_now + v_now * duration_s / 2.0, duration_s
