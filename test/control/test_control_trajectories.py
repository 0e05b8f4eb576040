"""Ruckig trajectories: every sample within the Panda's limits and above the table."""
import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from defgg_ros.constants import PANDA_QD_MAX_RADPS, PANDA_QDD_MAX_RADPS2, PREGRASP_HEIGHT_M
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.trajectories import (
    LINE_DEVIATION_ATOL_M,
    TrajectoryError,
    check_trajectory,
    hold,
    matched_state,
    panda_limits,
    plan_checked_stop,
    plan_joint_motion,
    plan_joint_via,
    plan_line,
    plan_stop,
    via_velocity,
)

KIN = PandaKinematics()
LIMITS = panda_limits()
TABLE_Z_M = 0.0


def independent_limit_check(trajectory, limits):
    """Recompute the limits from the samples, without check_trajectory's code."""
    q, qd, qdd, t = trajectory.q_rad, trajectory.qd_radps, trajectory.qdd_radps2, trajectory.times_s
    assert np.all(q >= limits.q_min_rad - 1e-9) and np.all(q <= limits.q_max_rad + 1e-9)
    assert np.all(np.abs(qd) <= limits.qd_max_radps * (1 + 1e-6))
    assert np.all(np.abs(qdd) <= limits.qdd_max_radps2 * (1 + 1e-6))
    if len(t) > 1:
        jerk = np.diff(qdd, axis=0) / np.diff(t)[:, None]
        assert np.all(np.abs(jerk) <= limits.qddd_max_radps3 * (1 + 1e-6))
    # Positions and velocities agree (the samples describe one motion).
    if len(t) > 2:
        velocity_from_positions = np.diff(q, axis=0) / np.diff(t)[:, None]
        mean_velocity = 0.5 * (qd[1:] + qd[:-1])
        assert np.abs(velocity_from_positions - mean_velocity).max() < 0.05
    for qk in q:
        assert KIN.fk(qk)[2, 3] >= TABLE_Z_M


grasps = st.tuples(st.floats(0.3, 0.65), st.floats(-0.3, 0.3), st.floats(0.01, 0.25), st.floats(-3.1, 3.1))


# derandomize: the same 12 examples on every run, so CI is reproducible; the two grasps random search found
# near the base (x ~ 0.33 m, z ~ 2 cm) are pinned in test_grasps_near_the_base_plan_within_limits below.
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
@given(grasp=grasps, stop_fraction=st.floats(0.05, 0.95))
def test_grasp_motions_respect_all_limits_and_stay_above_the_table(grasp, stop_fraction):
    x, y, z, yaw = grasp
    pregrasp, _ = KIN.top_down_ik([x, y, z + PREGRASP_HEIGHT_M], yaw, KIN.q_ready_rad)
    approach = plan_joint_motion(KIN.q_ready_rad, pregrasp.q_rad, LIMITS)
    descent = plan_line(KIN, pregrasp.q_rad, [0.0, 0.0, -PREGRASP_HEIGHT_M], LIMITS)
    lift = plan_line(KIN, descent.final_q_rad, [0.0, 0.0, 0.15], LIMITS, max_speed_mps=0.1)
    q, qd, qdd = approach.state_at(stop_fraction * approach.duration_s)
    stop = plan_stop(q, qd, qdd, LIMITS)
    for trajectory in (approach, descent, lift, stop):
        check_trajectory(trajectory, LIMITS, KIN, TABLE_Z_M)
        independent_limit_check(trajectory, LIMITS)
    assert approach.final_q_rad == pytest.approx(pregrasp.q_rad, abs=1e-9)
    assert np.allclose(stop.qd_radps[-1], 0.0, atol=1e-9)
    # The descent is a straight vertical line at the grasp orientation.
    start = KIN.fk(pregrasp.q_rad)
    for qk in descent.q_rad:
        tcp = KIN.fk(qk)
        assert tcp[:2, 3] == pytest.approx(start[:2, 3], abs=LINE_DEVIATION_ATOL_M)
        assert np.abs(tcp[:3, :3] - start[:3, :3]).max() < 1e-4
    assert KIN.fk(descent.final_q_rad)[2, 3] == pytest.approx(z, abs=1e-5)


def test_check_trajectory_catches_a_too_fast_trajectory():
    q_goal = np.array(KIN.q_ready_rad) + 0.5
    trajectory = plan_joint_motion(KIN.q_ready_rad, q_goal, LIMITS)
    report = check_trajectory(trajectory, LIMITS, KIN, TABLE_Z_M)
    assert report.velocity_ratio == pytest.approx(1.0, abs=1e-3)
    # The same samples played twice as fast: velocity x2.
    fast = dataclasses.replace(trajectory, times_s=trajectory.times_s / 2, qd_radps=trajectory.qd_radps * 2,
                               qdd_radps2=trajectory.qdd_radps2 * 4)
    with pytest.raises(TrajectoryError, match="velocity reaches 2.000 x"):
        check_trajectory(fast, LIMITS, KIN, TABLE_Z_M)


def test_check_trajectory_catches_going_below_the_table():
    q = KIN.top_down_ik([0.5, 0.0, 0.02], 0.0)[0].q_rad
    with pytest.raises(TrajectoryError, match="below the table"):
        check_trajectory(hold(q), LIMITS, KIN, table_z_m=0.05)


def test_line_through_the_table_is_refused_by_the_check():
    q = KIN.top_down_ik([0.5, 0.0, 0.03], 0.0)[0].q_rad
    line = plan_line(KIN, q, [0.0, 0.0, -0.05], LIMITS)
    with pytest.raises(TrajectoryError, match="TCP goes down to"):
        check_trajectory(line, LIMITS, KIN, TABLE_Z_M)


def test_line_out_of_reach_fails_with_a_reason():
    q = KIN.top_down_ik([0.6, 0.0, 0.1], 0.0)[0].q_rad
    with pytest.raises(TrajectoryError, match="leaves the reachable workspace|near a singularity"):
        plan_line(KIN, q, [0.6, 0.0, 0.0], LIMITS)


def test_stop_from_full_speed_is_jerk_limited():
    qd = np.array(PANDA_QD_MAX_RADPS) * 0.4 * np.array([1, -1, 1, -1, 1, -1, 1])
    qdd = np.array(PANDA_QDD_MAX_RADPS2) * 0.1
    stop = plan_stop(KIN.q_ready_rad, qd, qdd, LIMITS)
    independent_limit_check(stop, LIMITS)
    assert stop.duration_s > 0.1
    assert np.allclose(stop.qd_radps[-1], 0.0, atol=1e-9) and np.allclose(stop.qdd_radps2[-1], 0.0, atol=1e-9)


@pytest.mark.parametrize("gap_rad, sent, breach", [(0.03, "synchronised", False), (0.01, "shortest", False),
                                                    (0.005, "shortest", True)])
def test_a_stop_is_checked_and_near_a_range_end_each_joint_brakes_hardest(gap_rad, sent, breach):
    # joint 7 fast (a long stop), joint 1 slow towards its upper end: synchronised, joint 1 brakes over the
    # whole stop and travels 19 mm of angle; braking on its own, 8 mm
    q = np.array(KIN.q_ready_rad, dtype=float)
    q[0] = LIMITS.q_max_rad[0] - gap_rad
    qd = np.zeros(7)
    qd[0], qd[6] = 0.3, 0.95 * LIMITS.qd_max_radps[6]
    synced = plan_stop(q, qd, np.zeros(7), LIMITS)
    shortest = plan_stop(q, qd, np.zeros(7), LIMITS, synchronized=False)
    assert shortest.q_rad[-1, 0] - q[0] < synced.q_rad[-1, 0] - q[0]
    stop, why = plan_checked_stop(q, qd, np.zeros(7), LIMITS, KIN, TABLE_Z_M)
    expected = synced if sent == "synchronised" else shortest
    np.testing.assert_allclose(stop.q_rad, expected.q_rad)
    assert bool(why) == breach and (not breach or "joint 1" in why)
    if not breach:
        check_trajectory(stop, LIMITS, KIN, TABLE_Z_M)
    assert np.allclose(stop.qd_radps[-1], 0.0, atol=1e-9)       # a stop is sent either way, and it stops


def test_bad_inputs():
    with pytest.raises(ValueError):
        panda_limits(1.5)
    with pytest.raises(ValueError):
        panda_limits(0.0)
    with pytest.raises(TrajectoryError, match="outside the joint limits"):
        plan_joint_motion(KIN.q_ready_rad, np.full(7, 3.5), LIMITS)
    with pytest.raises(TrajectoryError, match="finite"):
        plan_joint_motion(KIN.q_ready_rad, np.full(7, np.nan), LIMITS)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grasp=grasps, via=st.tuples(st.floats(0.3, 0.55), st.floats(-0.35, 0.0), st.floats(0.2, 0.35)))
def test_transfer_through_a_via_point_passes_it_moving_and_respects_limits(grasp, via):
    x, y, z, yaw = grasp
    lifted, used_yaw = KIN.top_down_ik([x, y, z + 0.15], yaw, KIN.q_ready_rad)
    q_via = KIN.top_down_ik(via, used_yaw, lifted.q_rad)[0].q_rad
    q_goal = KIN.top_down_ik([0.35, -0.45, 0.22], used_yaw, q_via)[0].q_rad
    through = plan_joint_via(lifted.q_rad, q_via, q_goal, LIMITS)
    check_trajectory(through, LIMITS, KIN, TABLE_Z_M)
    independent_limit_check(through, LIMITS)
    closest = int(np.argmin(np.abs(through.q_rad - q_via).max(axis=1)))
    assert np.abs(through.q_rad[closest] - q_via).max() < 1e-9
    expected = via_velocity(lifted.q_rad, q_via, q_goal, LIMITS)
    assert through.qd_radps[closest] == pytest.approx(expected, abs=1e-9)
    assert through.final_q_rad == pytest.approx(q_goal, abs=1e-9)
    assert np.allclose(through.qd_radps[-1], 0.0)


def test_via_velocity_is_zero_for_joints_that_turn_back():
    q0, q1, q2 = np.zeros(7), np.full(7, 0.5), np.array([1.0, 0.2, 1.0, 0.5, 1.0, 1.0, 1.0])
    v = via_velocity(q0, q1, q2, LIMITS)
    assert v[1] == 0.0 and v[3] == 0.0
    assert np.all(v[[0, 2, 4, 5, 6]] > 0)
    assert np.all(np.abs(v) <= 0.5 * LIMITS.qd_max_radps + 1e-12)


def test_matched_state_continues_from_the_measured_position_of_a_late_arm():
    motion = plan_joint_motion(KIN.q_ready_rad, np.array(KIN.q_ready_rad) + 0.4, LIMITS)
    # The arm is where the plan was 0.3 s ago (the command arrived late).
    q_late, qd_late, qdd_late = motion.state_at(0.3)
    q, qd, qdd = matched_state(motion, q_late)
    assert q == pytest.approx(q_late)
    assert qd == pytest.approx(qd_late, abs=0.05) and qdd == pytest.approx(qdd_late, abs=0.5)
    stop = plan_stop(q, qd, qdd, LIMITS)
    assert stop.q_rad[0] == pytest.approx(q_late)
    independent_limit_check(stop, LIMITS)


# Found 2026-11-26 by random search, planned since 2026-11-27: one descent's grid missed how fast a joint
# turns between grid points (acceleration 2.03x its limit; now re-timed), the other's lift turns a joint
# 0.04 rad per mm at every step size (refused as a singularity; now walked finely).
@pytest.mark.parametrize("grasp", [(0.3359375, 0.0, 0.0234375, 0.0), (0.328125, 0.0, 0.015625, 0.5)])
def test_grasps_near_the_base_plan_within_limits(grasp):
    test_grasp_motions_respect_all_limits_and_stay_above_the_table.hypothesis.inner_test(grasp=grasp, stop_fraction=0.5)
