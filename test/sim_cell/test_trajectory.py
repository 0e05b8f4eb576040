"""Trajectory interpolation in sim time (pure numpy)."""
import numpy as np
import pytest

from defgg_ros.sim.cell.trajectory import TrajectoryError, TrajectoryTracker, make_waypoints

Q0 = np.zeros(7)
Q1 = np.linspace(0.1, 0.7, 7)


def test_linear_interpolation_and_hold_after_the_end():
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints([(0.0, Q0, None, None), (2.0, Q1, None, None)], 7), 10.0, Q0)
    q, qd = tracker.sample(11.0)
    np.testing.assert_allclose(q, Q1 / 2)
    np.testing.assert_allclose(qd, Q1 / 2)
    q, qd = tracker.sample(13.0)
    np.testing.assert_allclose(q, Q1)
    np.testing.assert_allclose(qd, 0.0)
    assert tracker.is_active(11.9) and not tracker.is_active(12.1)


def test_cubic_matches_endpoint_velocities():
    v1 = np.full(7, 0.3)
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints([(0.0, Q0, np.zeros(7), None), (1.0, Q1, v1, None)], 7), 0.0, Q0)
    q, qd = tracker.sample(1.0 - 1e-9)
    np.testing.assert_allclose(q, Q1, atol=1e-6)
    np.testing.assert_allclose(qd, v1, atol=1e-6)
    _, qd0 = tracker.sample(1e-9)
    np.testing.assert_allclose(qd0, 0.0, atol=1e-6)


def test_quintic_is_smooth_and_hits_the_midpoint_of_a_symmetric_move():
    z = np.zeros(7)
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints([(0.0, Q0, z, z), (2.0, Q1, z, z)], 7), 0.0, Q0)
    q, _ = tracker.sample(1.0)
    np.testing.assert_allclose(q, Q1 / 2, atol=1e-9)
    # smooth: the velocity is the position's derivative, starts and ends at rest with no jump in
    # acceleration (after 1 ms it has barely moved: a linear ramp would be at 0.7 rad/s at once)
    ts = np.linspace(0.0, 2.0, 2001)
    samples = [tracker.sample(t) for t in ts]
    qs, qds = np.array([s[0] for s in samples]), np.array([s[1] for s in samples])
    np.testing.assert_allclose(qds, np.gradient(qs, ts, axis=0), atol=2e-3)
    np.testing.assert_allclose(qds[[0, -1]], 0.0, atol=1e-9)
    assert np.abs(qds[1]).max() < 1e-4 and np.abs(qds[-2]).max() < 1e-4
    assert np.all(np.diff(qs, axis=0) >= -1e-12)        # monotone towards Q1, no overshoot


def test_first_point_in_the_future_blends_from_the_current_state():
    current = np.full(7, -0.2)
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints([(1.0, Q1, None, None)], 7), 5.0, current)
    np.testing.assert_allclose(tracker.sample(5.0)[0], current)
    np.testing.assert_allclose(tracker.sample(5.5)[0], (current + Q1) / 2)


def test_empty_trajectory_holds_the_current_position():
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints([(1.0, Q1, None, None)], 7), 0.0, Q0)
    tracker.replace([], 0.4, np.full(7, 0.05))
    np.testing.assert_allclose(tracker.sample(3.0)[0], 0.05)


@pytest.mark.parametrize("points, words", [
    ([(0.0, Q0[:6], None, None)], "expected 7"),
    ([(0.0, [np.nan] * 7, None, None)], "non-finite"),
    ([(1.0, Q0, None, None), (1.0, Q1, None, None)], "not after"),
    ([(-1.0, Q0, None, None)], ">= 0"),
    ([(0.0, [], None, None)], "no positions"),
    ([(0.0, Q0, [0.0] * 3, None)], "velocities"),
])
def test_malformed_points_raise(points, words):
    with pytest.raises(TrajectoryError, match=words):
        make_waypoints(points, 7)


def test_a_new_trajectory_blends_from_the_measured_position_and_velocity():
    """joint_trajectory_controller (interpolate_from_desired_state false): the segment to a first point still ahead
    starts at the state measured on receipt, its velocity included (it started from rest before 2026-12-01)."""
    z = np.zeros(7)
    v = np.full(7, 0.8)
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints([(0.5, Q1, z, z)], 7), 10.0, Q0, v)
    q, qd = tracker.sample(10.0)
    np.testing.assert_allclose(q, Q0)
    np.testing.assert_allclose(qd, v)
    q, qd = tracker.sample(10.001)
    np.testing.assert_allclose(qd, v, atol=0.01)          # continuous: no step to rest
    assert tracker.end_time_s() == pytest.approx(10.5)
    # a stamp ahead of receipt: the blend runs from the receipt (now) to the first point
    tracker.replace(make_waypoints([(0.0, Q1, z, z), (1.0, Q1 + 0.1, z, z)], 7), 11.0, Q0, v, now_s=10.8)
    q, qd = tracker.sample(10.8)
    np.testing.assert_allclose(q, Q0)
    np.testing.assert_allclose(qd, v)
    np.testing.assert_allclose(tracker.sample(11.0)[0], Q1)
    # positions only: the controller interpolates linearly, the measured velocity is not used
    tracker.replace(make_waypoints([(0.5, Q1, None, None)], 7), 0.0, Q0, v)
    np.testing.assert_allclose(tracker.sample(0.25)[1], (Q1 - Q0) / 0.5)


def test_a_sample_at_the_time_just_sampled_follows_a_replaced_or_held_trajectory():
    """The tracker keeps its last sample (the sim step and the controller's check ask for the same time); a new
    trajectory or a hold at that same time must not get the old trajectory's answer."""
    z = np.zeros(7)
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints([(0.0, Q0, z, z), (2.0, Q1, z, z)], 7), 0.0, Q0)
    q_first, _ = tracker.sample(1.0)
    tracker.replace(make_waypoints([(0.0, Q1, z, z), (2.0, -Q1, z, z)], 7), 0.0, Q1)
    np.testing.assert_allclose(tracker.sample(1.0)[0], 0.0, atol=1e-9)
    tracker.hold(Q1 * 3)
    np.testing.assert_allclose(tracker.sample(1.0)[0], Q1 * 3)
    assert not np.allclose(q_first, Q1 * 3)


def test_a_sample_is_the_callers_own_and_repeats_exactly():
    z, v = np.zeros(7), np.full(7, 0.2)
    points = [(0.0, Q0, z, z), (0.7, Q1 / 2, v, z), (1.5, Q1, z, z)]
    tracker = TrajectoryTracker(Q0)
    tracker.replace(make_waypoints(points, 7), 0.0, Q0)
    fresh = TrajectoryTracker(Q0)
    fresh.replace(make_waypoints(points, 7), 0.0, Q0)
    for t in np.linspace(0.0, 1.6, 41):
        q, qd = tracker.sample(t)
        q_again, qd_again = tracker.sample(t)
        np.testing.assert_array_equal(q, q_again)
        np.testing.assert_array_equal(qd, qd_again)
        q += 1.0   # the caller's array: the tracker's next answer must not change
        q_fresh, qd_fresh = fresh.sample(t)
        np.testing.assert_allclose(tracker.sample(t)[0], q_fresh, atol=1e-12)
        np.testing.assert_allclose(qd_again, qd_fresh, atol=1e-12)
