"""Where a hold puts a moving arm to rest without turning it back (pure; the executor's stop sends it).

A joint_trajectory_controller takes a new trajectory from the arm's measured position and velocity (ros2_controllers
jazzy, trajectory.cpp; docs/franka_contract.md) and blends into its one point (zero velocity and acceleration) over
the point's time_from_start T. A point at the arm's position plus velocity x T/2 makes that blend a monotone
deceleration to rest: for a cubic (the controller's start state has no acceleration) the velocity falls linearly,
v0 (1 - t/T), peak deceleration v0/T; for a quintic it falls as a smoothstep, peak 1.875 v0/T. A point at the
measured position instead (the hold before 2026-12-01) lies behind a moving arm by its velocity x the state's age
and the blend: the arm was pulled back to where it had been (~30 mrad from 0.87 rad/s in the simulated cell).
"""
import numpy as np

HOLD_BLEND_S = 0.1                 # the shortest blend to rest (s)
HOLD_ACCELERATION_SHARE = 0.5      # the quintic blend's peak deceleration at most this share of a joint's limit
MAX_STATE_AGE_S = 0.1              # a joint state older than this is not carried on (it says little of now)
PEAK_DECELERATION_FACTOR = 1.875   # the smoothstep blend's peak deceleration over v0 / T


def stopping_hold(q_rad, qd_radps, state_age_s: float, qdd_max_radps2, q_min_rad=None, q_max_rad=None):
    """(hold position (rad), blend duration T (s)) for an arm measured at q_rad, qd_radps state_age_s ago.

    The arm is taken to have carried on at its velocity for the state's age (at most MAX_STATE_AGE_S), then to
    stop over T, the longer of HOLD_BLEND_S and what keeps the peak deceleration within HOLD_ACCELERATION_SHARE
    of each joint's limit. The point is clipped to the joint ranges when given."""
    q, qd = np.asarray(q_rad, dtype=float), np.asarray(qd_radps, dtype=float)
    if q.shape != qd.shape or not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        raise ValueError(f"stopping_hold needs finite positions and velocities of one size, got {q}, {qd}")
    age_s = min(max(float(state_age_s), 0.0), MAX_STATE_AGE_S) if np.isfinite(state_age_s) else 0.0
    deceleration = HOLD_ACCELERATION_SHARE * np.asarray(qdd_max_radps2, dtype=float)
    duration_s = max(HOLD_BLEND_S, float(np.max(PEAK_DECELERATION_FACTOR * np.abs(qd) / deceleration)))
    hold = q + qd * (age_s + duration_s / 2.0)
    if q_min_rad is not None and q_max_rad is not None:
        hold = np.clip(hold, q_min_rad, q_max_rad)
    return hold, duration_s
