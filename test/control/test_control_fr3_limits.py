"""The executor plans within the FR3's limits when its joint_limits parameter says fr3.

Why: the FR3 has the Panda's kinematic structure but other ranges (joint 6 >= 0.5445 rad, joint 4 <= -0.1518 rad)
and lower accelerations (10 rad/s^2) and jerks (5000 rad/s^3) on several joints; a motion planned within the
Panda's limits can leave the FR3's, which its controller refuses or stops with a reflex.
"""
import dataclasses

import numpy as np
import pytest
from support.control_fake_robot import FakeRobot, World, run

from defgg_ros.constants import (
    FR3_GOAL_Q_MAX_RAD,
    FR3_GOAL_Q_MIN_RAD,
    FR3_Q_MAX_RAD,
    FR3_Q_MIN_RAD,
    FR3_QDD_MAX_RADPS2,
    FR3_QDDD_MAX_RADPS3,
    FR3_VELOCITY_ENVELOPE,
)
from defgg_ros.control.kinematics import KinematicsError, PandaKinematics
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget, SendTrajectory, SequenceConfig
from defgg_ros.control.trajectories import (
    TrajectoryError,
    arm_limits,
    check_trajectory,
    envelope_velocity_bounds,
    plan_joint_motion,
)


def test_fr3_kinematics_refuse_the_panda_only_joint_ranges():
    panda, fr3 = PandaKinematics(), PandaKinematics(arm="fr3")
    q = np.array(panda.q_ready_rad)
    q[5] = 0.3                       # joint 6: inside the Panda's range, below the FR3's 0.5445 rad
    assert panda.within_limits(q) and not fr3.within_limits(q)
    assert np.array_equal(fr3.q_min_rad, FR3_GOAL_Q_MIN_RAD) and np.array_equal(fr3.q_max_rad, FR3_GOAL_Q_MAX_RAD)
    with pytest.raises(KinematicsError, match="unknown arm model 'ur5'; known: panda, fr3"):
        PandaKinematics(arm="ur5")


def test_a_joint_motion_keeps_to_the_fr3s_acceleration_jerk_and_ranges():
    panda, fr3 = arm_limits("panda", 1.0), arm_limits("fr3", 1.0)
    start = np.array(PandaKinematics().q_ready_rad)
    goal = start.copy()
    goal[6] -= 2.5                   # joint 7 alone: the Panda allows 20 rad/s^2 there, the FR3 10
    # (and 5.26 rad/s to the Panda's 2.61: the FR3's motion may be the shorter one)
    on_panda, on_fr3 = plan_joint_motion(start, goal, panda), plan_joint_motion(start, goal, fr3)
    assert np.abs(on_panda.qdd_radps2[:, 6]).max() > FR3_QDD_MAX_RADPS2[6] * 1.2
    assert np.abs(on_fr3.qdd_radps2).max() <= FR3_QDD_MAX_RADPS2[6] * (1 + 1e-6)
    jerk = np.diff(on_fr3.qdd_radps2, axis=0) / np.diff(on_fr3.times_s)[:, None]
    assert np.abs(jerk).max() <= FR3_QDDD_MAX_RADPS3[6] * (1 + 1e-6)
    low = start.copy()
    low[5] = 0.3
    with pytest.raises(TrajectoryError):
        plan_joint_motion(start, low, fr3)


def test_no_fr3_goal_the_ik_may_choose_has_a_zero_velocity_bound_towards_its_range_end():
    # The FR3's bound is 0 towards a range end from offset^2/k before it: a goal there (joints 1, 4, 6 had
    # 1.1-7.6 mrad of datasheet range inside it) can never be approached; the IK's range ends where the bound
    # is still above 0 (goals just inside may still need a gentler braking than the plan's: not guaranteed).
    fr3 = PandaKinematics(arm="fr3")
    envelope = np.array(FR3_VELOCITY_ENVELOPE)
    inside = 1e-4
    lower_at_min, _ = envelope_velocity_bounds(envelope, fr3.q_min_rad + inside)
    _, upper_at_max = envelope_velocity_bounds(envelope, fr3.q_max_rad - inside)
    assert np.all(upper_at_max > 0) and np.all(lower_at_min < 0)
    assert np.all(fr3.q_min_rad >= FR3_Q_MIN_RAD) and np.all(fr3.q_max_rad <= FR3_Q_MAX_RAD)
    assert np.max(fr3.q_min_rad - FR3_Q_MIN_RAD) < 0.01     # a cut of mrad, not a narrower arm


def test_an_fr3_at_rest_in_the_cut_band_can_still_move_out_of_it():
    # Only goals avoid the band: an arm standing in it (e.g. after hand guiding) moves away from the range end,
    # which the bound allows; moving into it is refused by the bound.
    limits = arm_limits("fr3", 0.4)
    start = np.array(PandaKinematics().q_ready_rad)
    start[5] = (FR3_Q_MIN_RAD[5] + FR3_GOAL_Q_MIN_RAD[5]) / 2          # joint 6 inside the band
    away = start.copy()
    away[5] = 1.0
    check_trajectory(plan_joint_motion(start, away, limits), limits, PandaKinematics(arm="fr3"), 0.0)
    with pytest.raises(TrajectoryError, match="joint 6 moves at"):
        check_trajectory(plan_joint_motion(away, start, limits), limits, PandaKinematics(arm="fr3"), 0.0)


@pytest.mark.parametrize("arm", ["panda", "fr3"])
def test_a_whole_pick_sends_only_motions_within_its_arms_limits(arm):
    kin = PandaKinematics(arm=arm)
    config = SequenceConfig(limits_scale=0.4, watchdog_timeout_s=0.5)
    sequence = PickPlaceSequence(kin, config, GraspTarget((0.5, 0.05, 0.03), 0.4, 0.04, 2e5),
                                 PlaceTarget((0.35, -0.45, 0.12)))
    robot = FakeRobot(kin, World(object_width_m=0.04))
    run(sequence, robot)
    assert sequence.outcome.success, sequence.outcome.failure_reason
    limits = arm_limits(arm, config.limits_scale)
    trajectories = [c.trajectory for c in robot.sent if isinstance(c, SendTrajectory)]
    assert len(trajectories) >= 5
    for t in trajectories:
        assert np.all(t.q_rad >= limits.q_min_rad - 1e-9) and np.all(t.q_rad <= limits.q_max_rad + 1e-9)
        assert np.all(np.abs(t.qd_radps) <= limits.qd_max_radps * (1 + 1e-6))
        assert np.all(np.abs(t.qdd_radps2) <= limits.qdd_max_radps2 * (1 + 1e-6))
        if len(t.times_s) > 1:
            jerk = np.diff(t.qdd_radps2, axis=0) / np.diff(t.times_s)[:, None]
            assert np.all(np.abs(jerk) <= limits.qddd_max_radps3 * (1 + 1e-6))


def test_the_fr3_velocity_bound_falls_near_the_ends_of_a_joints_range():
    fr3 = arm_limits("fr3", 1.0)
    q = np.tile(np.array(PandaKinematics().q_ready_rad), (3, 1))
    q[:, 0] = (0.0, 2.6, 2.745)      # joint 1 towards its upper end (range end 2.7437 rad)
    q[:, 5] = (1.571, 0.6, 0.55)     # joint 6 towards its lower end (0.5445 rad)
    lower, upper = envelope_velocity_bounds(fr3.velocity_envelope, q)
    # By hand from the rows, e.g. -0.30 + sqrt(12 * (2.7501 - 2.6)) and 0.35 - sqrt(11 * (0.6 - 0.54092)).
    assert upper[:, 0] == pytest.approx([2.62, 1.0420879, 0.0], abs=1e-6)
    assert lower[:, 0] == pytest.approx([-2.62] * 3)
    assert lower[:, 5] == pytest.approx([-3.0161373, -0.4561514, 0.0], abs=1e-6)
    # The robot's own bound whatever limits_scale: it is where the controller aborts (the plan keeps to the
    # scaled constant bounds besides).
    assert np.array_equal(arm_limits("fr3", 0.4).velocity_envelope, fr3.velocity_envelope)
    assert arm_limits("panda", 1.0).velocity_envelope is None


@pytest.mark.parametrize("scale", [1.0, 0.4])
def test_a_motion_braking_late_before_a_range_end_is_refused_on_the_fr3_only(scale):
    kin = PandaKinematics()
    start = np.array(kin.q_ready_rad)
    goal = start.copy()
    start[0], goal[0] = 0.5, 2.74    # joint 1 at full speed until it brakes at 10 rad/s^2 (the bound: 6)
    fr3 = arm_limits("fr3", scale)
    motion = plan_joint_motion(start, goal, fr3)
    with pytest.raises(TrajectoryError, match=r"joint 1 moves at .* near the end of its range"):
        check_trajectory(motion, fr3, kin, table_z_m=0.0)
    check_trajectory(motion, dataclasses.replace(fr3, velocity_envelope=None), kin, table_z_m=0.0)  # the cause
    away = plan_joint_motion(goal, start, fr3)   # leaving the end: the bound is on the way in only
    check_trajectory(away, fr3, kin, table_z_m=0.0)
