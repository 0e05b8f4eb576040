"""The executor's hold brings a moving arm to rest without turning it back (control/stopping.py).

Sampled through the simulated joint_trajectory_controller's blend (sim/cell/trajectory.py: from the measured
position and velocity into the hold's one point, as ros2_controllers' trajectory.cpp does)."""
import numpy as np
import pytest

from defgg_ros.control.stopping import HOLD_ACCELERATION_SHARE, HOLD_BLEND_S, MAX_STATE_AGE_S, stopping_hold
from defgg_ros.control.trajectories import arm_limits
from defgg_ros.sim.cell.trajectory import TrajectoryTracker, make_waypoints

pytestmark = pytest.mark.unit

LIMITS = arm_limits("panda", 1.0)
Q0 = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.8])


def _blend(q_measured, qd_measured, q_hold, duration_s, steps=2001):
    """Desired positions and velocities of the controller from the hold's receipt (t = 0) to its end."""
    tracker = TrajectoryTracker(q_measured)
    zeros = np.zeros(7)
    tracker.replace(make_waypoints([(duration_s, q_hold, zeros, zeros)], 7), 0.0, q_measured, qd_measured, 0.0)
    samples = [tracker.sample(t) for t in np.linspace(0.0, duration_s, steps)]
    return np.array([q for q, _ in samples]), np.array([qd for _, qd in samples])


def _turned_back_rad(q, qd0):
    progress = (q - q[0]) * np.sign(qd0)
    return float(np.max(progress.max(axis=0) - progress[-1]))


@pytest.mark.parametrize("qd0", [np.array([0.87, -0.4, 0.2, 0.6, -0.1, 0.3, 0.0]),
                                 np.array([2.0, 2.0, 2.0, 2.0, 2.5, 2.5, 2.5])])
def test_the_blend_to_the_hold_slows_every_joint_to_rest_without_turning_back(qd0):
    q_hold, duration_s = stopping_hold(Q0, qd0, 0.0, LIMITS.qdd_max_radps2)
    q, qd = _blend(Q0, qd0, q_hold, duration_s)
    assert np.all(qd * np.sign(qd0) >= -1e-9), "a joint turned back"
    assert np.allclose(qd[-1], 0.0, atol=1e-9) and np.allclose(q[-1], q_hold)
    deceleration = np.abs(np.diff(qd, axis=0)) / (duration_s / (len(qd) - 1))
    assert np.all(deceleration.max(axis=0) <= HOLD_ACCELERATION_SHARE * LIMITS.qdd_max_radps2 * 1.01)
    assert duration_s >= HOLD_BLEND_S


def test_a_hold_at_the_measured_position_pulls_a_moving_arm_back():
    """What the executor sent before: the point at the last joint state, which the arm has already passed."""
    qd0 = np.array([0.87, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    state_age_s = 0.033
    q_now = Q0 + qd0 * state_age_s                   # where the arm is when the hold arrives
    q, _ = _blend(q_now, qd0, Q0, HOLD_BLEND_S)
    assert _turned_back_rad(q, qd0) > 0.03           # ~30 mrad back, as measured in the cell
    q_hold, duration_s = stopping_hold(Q0, qd0, state_age_s, LIMITS.qdd_max_radps2)
    q, _ = _blend(q_now, qd0, q_hold, duration_s)
    assert _turned_back_rad(q, qd0) < 1e-9


def test_a_stop_while_the_arm_speeds_up_carries_the_acceleration_on():
    """A state 33 ms old of an arm accelerating at 7.5 rad/s^2: it is faster when the hold arrives than the state
    says, and a point sized from the stale velocity turned it back 4 mrad."""
    qd0, qdd0, age_s = np.array([0.30, 0, 0, 0, 0, 0, 0]), np.array([7.5, 0, 0, 0, 0, 0, 0]), 0.033
    q_now, qd_now = Q0 + qd0 * age_s + 0.5 * qdd0 * age_s**2, qd0 + qdd0 * age_s
    stale, stale_s = stopping_hold(Q0, qd0, age_s, LIMITS.qdd_max_radps2)
    q, _ = _blend(q_now, qd_now, stale, stale_s)
    assert _turned_back_rad(q, qd_now) > 1e-3
    q_hold, duration_s = stopping_hold(Q0, qd0, age_s, LIMITS.qdd_max_radps2, qdd_radps2=qdd0)
    q, qd = _blend(q_now, qd_now, q_hold, duration_s)
    assert _turned_back_rad(q, qd_now) < 1e-9 and np.all(qd[:, 0] >= -1e-9)


def test_near_a_joint_limit_the_arm_stops_sooner_at_the_limit_never_past_it():
    """Clipping the point to the range kept the blend's time: the arm ran past the limit and came back."""
    q_start = Q0.copy()
    q_start[0] = LIMITS.q_max_rad[0] - 0.02
    qd0 = np.array([1.0, 0, 0, 0, 0, 0, 0])
    q_hold, duration_s = stopping_hold(q_start, qd0, 0.0, LIMITS.qdd_max_radps2, LIMITS.q_min_rad,
                                       LIMITS.q_max_rad)
    q, qd = _blend(q_start, qd0, q_hold, duration_s)
    assert q[:, 0].max() <= LIMITS.q_max_rad[0] + 1e-9
    assert np.all(qd[:, 0] >= -1e-9) and duration_s < HOLD_BLEND_S


def test_the_state_is_carried_on_for_its_age_at_most_so_long_and_an_unknown_velocity_holds_in_place():
    qd0 = np.full(7, 0.5)
    near, duration_s = stopping_hold(Q0, qd0, 0.05, LIMITS.qdd_max_radps2)
    stale, _ = stopping_hold(Q0, qd0, 5.0, LIMITS.qdd_max_radps2)
    at_most, _ = stopping_hold(Q0, qd0, MAX_STATE_AGE_S, LIMITS.qdd_max_radps2)
    assert duration_s > HOLD_BLEND_S        # 0.5 rad/s on joint 2 (7.5 rad/s^2): longer than the shortest blend
    assert np.allclose(near - Q0, qd0 * (0.05 + duration_s / 2))
    assert np.allclose(stale, at_most)
    # a velocity estimator without its baseline yet gives NaN: the hold is where the arm was, never no hold
    in_place, _ = stopping_hold(Q0, np.full(7, np.nan), 0.02, LIMITS.qdd_max_radps2,
                                qdd_radps2=np.full(7, np.nan))
    assert np.allclose(in_place, Q0)
    with pytest.raises(ValueError, match="finite joint positions"):
        stopping_hold(np.full(7, np.nan), qd0, 0.0, LIMITS.qdd_max_radps2)
