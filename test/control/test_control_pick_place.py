"""PickPlaceSequence on a fake clock: happy path and every way it can end badly."""
import dataclasses
import math

import numpy as np
import pytest
from support.control_fake_robot import RECOVERING_CONFIG, FakeRobot, World, run

from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import (
    ArmState,
    CancelGripper,
    GraspGripper,
    GraspTarget,
    MoveGripper,
    PlaceTarget,
    SendTrajectory,
    SequenceConfig,
)
from defgg_ros.control.trajectories import arm_limits, plan_joint_motion, scaled_in_time, tcp_peak_acceleration_mps2
from defgg_ros.grasping.geometry import tcp_height_m

# The network's grasp point is on the object's top surface, here a 5 cm tall object.
GRASP = GraspTarget(position_m=(0.5, 0.05, 0.05), yaw_rad=0.4, width_m=0.05, youngs_modulus_pa=2e9)
PLACE = PlaceTarget(position_m=(0.35, -0.45, 0.12))
CONFIG = SequenceConfig(watchdog_timeout_s=0.5)
# The default grasp_height_rule, half_height: half the height seen at the grasp point.
GRASP_TCP_Z_M = tcp_height_m(GRASP.position_m[2], CONFIG.table_z_m)


@pytest.fixture(scope="module")
def kin():
    return PandaKinematics()


def make(kin, grasp=GRASP, place=PLACE, config=CONFIG):
    return PickPlaceSequence(kin, config, grasp, place)


def phases_of(robot):
    return [type(c).__name__ for c in robot.sent]


def test_happy_path_reaches_every_phase_and_places(kin):
    sequence, robot = make(kin), None
    robot = FakeRobot(kin, World(object_width_m=0.045))
    seen = []
    run(sequence, robot, until=lambda r, s: seen.append(s.phase) and False)
    out = sequence.outcome
    assert out.success, out.failure_reason
    assert out.failure_reason == ""
    assert out.phase_reached == "done"
    # "done" while the arm settles: the run ends only once it is at rest.
    assert list(dict.fromkeys(seen)) == ["pre_grasp", "descend", "close", "lift", "transfer", "place", "retreat",
                                         "done"]
    assert out.arm_state == "at_rest"
    assert not out.contact_detected
    assert out.contact_height_m == pytest.approx(GRASP_TCP_Z_M, abs=1e-3)
    assert out.gripper_width_closed_m == pytest.approx(0.045)
    assert out.gripper_force_n > 0
    assert out.held_after_lift and out.held_after_transfer
    # Released where asked, with the fingers opened again.
    tcp = kin.fk(robot.q)[:3, 3]
    assert tcp[:2] == pytest.approx(PLACE.position_m[:2], abs=1e-3)
    assert tcp[2] == pytest.approx(PLACE.position_m[2] + CONFIG.place_approach_height_m, abs=1e-3)
    assert isinstance(robot.sent[-2], MoveGripper) and robot.sent[-2].width_m > 0.045
    assert out.duration_s > 0


def test_a_grasp_that_carries_its_labels_force_is_closed_with_it_and_the_outcome_says_so(kin):
    """A defgraspsim model's grasp carries FOS*m*g/mu per finger (Grasp.finger_force_n): the hand closes with
    that, not with the modulus rule's 4.5 N for 2e9 Pa."""
    from dataclasses import replace

    sequence = make(kin, grasp=replace(GRASP, finger_force_n=1.3))
    robot = FakeRobot(kin, World(object_width_m=0.045))
    run(sequence, robot, until=lambda r, s: False)
    (close,) = [c for c in robot.sent if isinstance(c, GraspGripper)]
    assert close.command.force_n == 1.3 and sequence.outcome.gripper_force_n == 1.3
    assert sequence.outcome.success, sequence.outcome.failure_reason


def test_pre_grasp_is_25_mm_above_the_grasp_point_with_fingers_closing_along_the_grasp_axis(kin):
    sequence, robot = make(kin), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "descend")
    tcp = kin.fk(robot.q)
    assert tcp[:3, 3] == pytest.approx(np.add(GRASP.position_m, [0, 0, 0.025]), abs=1e-3)
    closing_axis = tcp[:3, 0]
    assert abs(closing_axis @ [math.cos(GRASP.yaw_rad), math.sin(GRASP.yaw_rad), 0.0]) == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize("place_yaw_rad, expected_yaw_rad", [(None, GRASP.yaw_rad), (0.0, 0.0), (-1.0, -1.0)])
def test_place_yaw_is_the_grasp_s_when_none_else_as_asked(kin, place_yaw_rad, expected_yaw_rad):
    """None keeps the wrist's yaw from grasp to release (a turn spins a lightly held object)."""
    place = PlaceTarget(PLACE.position_m, place_yaw_rad)
    sequence, robot = make(kin, place=place), FakeRobot(kin, World(object_width_m=0.045))
    run(sequence, robot, until=lambda r, s: s.phase == "retreat")
    closing_axis = kin.fk(robot.q)[:3, 0]
    expected = [math.cos(expected_yaw_rad), math.sin(expected_yaw_rad), 0.0]
    assert abs(closing_axis @ expected) == pytest.approx(1.0, abs=1e-4)


def test_contact_during_descent_stops_the_descent_there(kin):
    surface_z = GRASP_TCP_Z_M + 0.012
    sequence, robot = make(kin), FakeRobot(kin, World(contact_height_m=surface_z))
    run(sequence, robot, until=lambda r, s: s.phase == "close")
    out = sequence.outcome
    assert out.contact_detected
    # Stopped within a few mm of first touch: threshold / stiffness + stopping distance.
    assert surface_z - 0.006 < out.contact_height_m < surface_z
    assert any(isinstance(c, GraspGripper) for c in robot.sent)
    assert np.max(np.abs(robot.qd)) < 0.02


def test_missed_grasp_fails_with_a_reason(kin):
    sequence, robot = make(kin), FakeRobot(kin, World(object_width_m=None))
    run(sequence, robot)
    out = sequence.outcome
    assert not out.success and not out.canceled
    assert out.phase_reached == "close"
    assert "missed" in out.failure_reason
    assert out.gripper_width_closed_m < 0.004


@pytest.mark.parametrize("phase", ["lift", "transfer"])
def test_slip_is_detected_in_the_phase_it_happens(kin, phase):
    sequence, robot = make(kin), FakeRobot(kin, World(slip_at_phase=phase))
    run(sequence, robot)
    out = sequence.outcome
    assert not out.success
    assert out.phase_reached == phase
    assert f"dropped during {phase}" in out.failure_reason
    assert out.held_after_lift == (phase == "transfer")
    assert not out.held_after_transfer


def test_an_object_lost_in_the_place_lowering_is_reported_not_released(kin):
    # The lowering to the release pose did not check the hold: a drop there (or late in the transfer) was
    # reported as a pick done, wherever the object fell.
    sequence = make(kin)
    run(sequence, FakeRobot(kin, World(slip_at_phase="place", slip_closing_mps=0.05)))
    out = sequence.outcome
    assert not out.success and out.phase_reached == "place" and out.held_after_transfer
    assert "dropped during place" in out.failure_reason, out.failure_reason


@pytest.mark.parametrize("bottom_at_slip_m, reported", [(0.05, True), (0.012, False)])
def test_the_place_lowering_watches_the_hold_until_the_object_may_touch_down(kin, bottom_at_slip_m, reported):
    # Placed low (its bottom ends 5 mm above the table): a width that falls while the bottom is 5 cm up is a
    # drop; within TOUCHDOWN_MARGIN_M of the table it is the object pushed up between the fingers by touching
    # down, which must not fail a pick that put it down (the bottom hangs GRASP_TCP_Z_M below the TCP).
    place = PlaceTarget((0.35, -0.45, GRASP_TCP_Z_M + 0.005))
    world = World(slip_at_phase="place", slip_closing_mps=0.2, slip_below_tcp_z_m=GRASP_TCP_Z_M + bottom_at_slip_m)
    sequence = make(kin, place=place)
    run(sequence, FakeRobot(kin, world))
    out = sequence.outcome
    assert out.held_after_transfer
    if reported:
        assert not out.success and "dropped during place" in out.failure_reason, out.failure_reason
    else:
        assert out.success, out.failure_reason


def test_a_drop_early_in_the_slowed_transfer_is_seen_before_the_place(kin):
    """Force-closed fingers close only at their grasp speed once the object is gone: at 25 mm/s the width
    crosses the slip threshold (50 -> 25 mm) 1.0 s after the drop. The unslowed transfer (0.82 s here) ends
    before that, and the drop went unseen until the release: the simulated cell, 2026-11-28, reported a pick
    done with the block flung onto the table. The slowed transfer (1.22 s) sees it; the place lowering, which
    checks the hold too, sees the unslowed one's."""
    outcomes = {}
    for cap in (None, 3.0):
        world = World(slip_at_phase="transfer", slip_closing_mps=0.025)
        sequence = make(kin, config=dataclasses.replace(CONFIG, transfer_max_tcp_accel_mps2=cap))
        run(sequence, FakeRobot(kin, world))
        outcomes[cap] = sequence.outcome
    unslowed = outcomes[None]                  # the transfer was over too soon; the place lowering sees it
    assert unslowed.held_after_transfer and not unslowed.success
    assert unslowed.phase_reached == "place" and "dropped during place" in unslowed.failure_reason
    out = outcomes[3.0]
    assert not out.success and out.phase_reached == "transfer"
    assert "dropped during transfer" in out.failure_reason and not out.held_after_transfer


@pytest.mark.parametrize("cap_mps2", [None, 3.0, 1.5])
def test_the_transfer_is_slowed_until_the_tcp_accelerates_at_most_the_cap(kin, cap_mps2):
    """The labels' grip force holds only (FOS - 1) g more than the weight; an unslowed transfer reaches ~7 m/s^2."""
    config = dataclasses.replace(CONFIG, transfer_max_tcp_accel_mps2=cap_mps2)
    sequence, robot = make(kin, config=config), FakeRobot(kin, World())
    transfers = []
    run(sequence, robot, until=lambda r, s: transfers.append(r.trajectory) if s.phase == "transfer" else False)
    transfer = transfers[-1]
    peak = tcp_peak_acceleration_mps2(kin, transfer)
    if cap_mps2 is None:
        assert peak > 5.0            # what the joint limits alone give this transfer
    else:
        assert cap_mps2 * 0.8 < peak <= cap_mps2 * 1.001
    run_until_finished(sequence, robot)
    assert sequence.outcome.success, sequence.outcome.failure_reason


def test_slower_limits_in_time_slow_every_acceleration_by_the_square(kin):
    start, goal = np.array(kin.q_ready_rad), np.array(kin.q_ready_rad) + [0.6, 0.3, -0.4, 0.3, 0.5, -0.2, 0.8]
    limits = arm_limits("panda", 0.4)
    fast = plan_joint_motion(start, goal, limits)
    slow = plan_joint_motion(start, goal, scaled_in_time(limits, 2.0))
    assert slow.duration_s == pytest.approx(2.0 * fast.duration_s, rel=0.02)
    assert tcp_peak_acceleration_mps2(kin, slow) == pytest.approx(tcp_peak_acceleration_mps2(kin, fast) / 4, rel=0.05)
    with pytest.raises(ValueError, match="time factor must be >= 1"):
        scaled_in_time(limits, 0.5)


def test_driver_silent_aborts_within_the_watchdog_time(kin):
    sequence, robot = make(kin), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "lift")
    silent_since = robot.sim_s
    robot.world.silent = True
    run_until_finished(sequence, robot)
    out = sequence.outcome
    assert "driver silent" in out.failure_reason
    assert out.phase_reached == "lift"
    assert robot.sim_s - silent_since <= CONFIG.watchdog_timeout_s + 0.05


@pytest.mark.parametrize("phase", ["pre_grasp", "descend", "transfer"])
def test_a_wrench_that_goes_quiet_stops_the_run_within_the_watchdog_time(kin, phase):
    """Joint states go on, the wrench stops: every contact guard would read its last value for ever (the descent
    and a place ran to their planned end, blind). The run stops once the wrench is older than the watchdog."""
    # with an observation pose: the stop must not lead into a recovery (whose guarded lowering is blind too)
    sequence, robot = make(kin, config=RECOVERING_CONFIG), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == phase)
    quiet_since = robot.sim_s
    robot.world.wrench_silent = True
    while "no external wrench" not in sequence.outcome.failure_reason and not sequence.finished:
        robot.step(sequence)
    assert robot.sim_s - quiet_since <= CONFIG.watchdog_timeout_s + 0.05
    run_until_finished(sequence, robot)             # the stop waits for rest (joint states still come)
    out = sequence.outcome
    assert "no external wrench" in out.failure_reason and not out.success and out.arm_state == "at_rest"
    assert out.recovery == "" and sequence.finished


@pytest.mark.parametrize("phase", ["descend", "transfer"])
def test_a_robot_error_ends_the_run_at_once_and_sends_nothing(kin, phase):
    """A robot error deactivated the arm's controller mid-run (franka_ros2's answer to a reflex): it refuses every
    goal, so the run ends at its next tick with no stop, no recovery (an object held stays held) and no command on a
    cancel; the arm's state says so."""
    sequence, robot = make(kin, config=RECOVERING_CONFIG), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == phase and s._motion_active(r.sim_s))
    sequence.on_robot_error("robot error: the controller was deactivated")
    assert sequence.cancel(robot.sim_s, robot.wall_s) == []
    assert sequence.tick(robot.sim_s, robot.wall_s) == []
    out = sequence.outcome
    assert sequence.finished and out.failure_reason == "robot error: the controller was deactivated"
    assert (out.arm_state, out.phase_reached, out.recovery) == ("robot_error", phase, "")


def test_a_robot_error_during_a_recovery_keeps_the_failure_and_ends_the_recovery(kin):
    sequence, robot = make(kin, config=RECOVERING_CONFIG), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "descend" and s._motion_active(r.sim_s))
    robot.apply(sequence.cancel(robot.sim_s, robot.wall_s), sequence)
    while not (sequence.recovering and sequence._motion_active(robot.sim_s)) and robot.sim_s < 60.0:
        robot.step(sequence)
    sequence.on_robot_error("robot error")
    assert sequence.tick(robot.sim_s, robot.wall_s) == []
    out = sequence.outcome
    assert sequence.finished and out.failure_reason == "canceled during descend" and out.arm_state == "robot_error"
    assert out.recovery.endswith("stopped: robot error"), out.recovery


def test_a_goal_is_refused_while_the_arm_still_moves_and_a_cancel_before_the_start_moves_nothing(kin):
    """Every motion is planned from rest: a goal after a result that left the arm moving would start its first
    trajectory behind the arm. A cancel that came while the goal was planned ends it without a command."""
    sequence, robot = make(kin), FakeRobot(kin, World())
    robot.qd[1] = 0.2
    sequence.on_joint_state(ArmState(robot.q.copy(), robot.qd.copy(), robot.width_m), 0.0)
    sequence.on_force([0.0, 0.0, 0.0], 0.0)
    assert sequence.start(0.0, 0.0) == []                   # nothing sent, no recovery either
    assert "the arm is moving" in sequence.outcome.failure_reason and sequence.finished
    assert sequence.outcome.arm_state == "moving"
    canceled = make(kin)
    canceled.on_joint_state(ArmState(robot.q.copy(), np.zeros(7), robot.width_m), 0.0)
    canceled.cancel_unstarted(0.0)
    out = canceled.outcome
    assert canceled.finished and out.canceled and not out.success and out.arm_state in ("at_rest", "observation_pose")


def test_a_grasp_outside_its_band_says_where_the_fingers_stopped_without_the_grippers_words(kin):
    """franka_gripper aborts a grasp that stopped outside [width - eps_inner, width + eps_outer] with no error text
    (libfranka's grasp() returned false): the failure names the width and the band itself ("no reason given")."""
    sequence, robot = make(kin), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "close" and r.gripper is not None)
    robot.gripper = None
    sequence.on_gripper_result(False, 0.03, "")
    run_until_finished(sequence, robot)
    reason = sequence.outcome.failure_reason
    assert "the fingers stopped at 30.0 mm, the grasp accepts" in reason and "no reason" not in reason


def test_a_stall_of_the_owner_itself_is_not_a_silent_driver(kin):
    """The whole cell suspended for 60 s (SIGSTOP of every process): the executor's first tick after the pause
    comes before the driver's first joint state after it; the pick goes on (it aborted "driver silent: no joint
    states for 60 s" before), and a driver that stays silent afterwards is still caught."""
    sequence, robot = make(kin), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "lift")
    robot.wall_ahead_s = 60.0   # everything stopped for 60 s: the wall clock moved on, sim time did not
    robot.apply(sequence.tick(robot.sim_s, robot.wall_s), sequence)
    assert not sequence.finished, sequence.outcome.failure_reason
    run_until_finished(sequence, robot)
    assert sequence.outcome.success, sequence.outcome.failure_reason

    sequence, robot = make(kin), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "lift")
    robot.wall_ahead_s = 60.0   # everything stopped for 60 s: the wall clock moved on, sim time did not
    robot.apply(sequence.tick(robot.sim_s, robot.wall_s), sequence)
    robot.world.silent = True
    silent_since = robot.sim_s
    run_until_finished(sequence, robot)
    assert "driver silent" in sequence.outcome.failure_reason
    assert robot.sim_s - silent_since <= CONFIG.watchdog_timeout_s + 0.05


def test_no_joint_states_at_all_fails_at_start(kin):
    sequence = make(kin)
    commands = sequence.start(0.0, 0.0)
    assert sequence.finished and commands == []
    assert "no joint states" in sequence.outcome.failure_reason


def test_cancel_mid_transfer_stops_jerk_limited_and_leaves_the_arm_still(kin):
    sequence, robot = make(kin), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and s.feedback(r.sim_s).phase_progress > 0.4)
    assert np.max(np.abs(robot.qd)) > 0.1, "should be moving when canceled"
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    stop = robot.sent[-1]
    assert isinstance(stop, SendTrajectory) and stop.trajectory.duration_s > 0
    assert np.allclose(stop.trajectory.qd_radps[-1], 0.0)
    # jerk-limited: from the samples, within the configured scale of the arm's jerk limits
    from defgg_ros.control.trajectories import panda_limits

    t = stop.trajectory
    jerk = np.diff(t.qdd_radps2, axis=0) / np.diff(t.times_s)[:, None]
    assert np.all(np.abs(jerk) <= panda_limits(CONFIG.limits_scale).qddd_max_radps3 * (1 + 1e-6))
    run_until_finished(sequence, robot)
    out = sequence.outcome
    assert out.canceled and not out.success
    assert "canceled during transfer" in out.failure_reason
    assert np.max(np.abs(robot.qd)) < 0.02


def test_cancel_while_closing_cancels_the_gripper(kin):
    sequence, robot = make(kin), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "close")
    commands = sequence.cancel(robot.sim_s, robot.sim_s)
    assert any(isinstance(c, CancelGripper) for c in commands)
    robot.apply(commands, sequence)
    run_until_finished(sequence, robot)
    assert sequence.outcome.canceled and sequence.outcome.phase_reached == "close"


@pytest.mark.parametrize("grasp, place, reason", [
    (GraspTarget((1.2, 0.0, 0.05), 0.0, 0.05, 2e9), PLACE, "grasp outside the workspace"),
    (GraspTarget((0.5, 0.0, -0.2), 0.0, 0.05, 2e9), PLACE, "below the table"),
    (GraspTarget((0.05, 0.0, 0.05), 0.0, 0.05, 2e9), PLACE, "too close"),
    (GraspTarget((float("nan"), 0.0, 0.05), 0.0, 0.05, 2e9), PLACE, "non-finite"),
    (GRASP, PlaceTarget((0.0, -1.5, 0.1)), "place pose unreachable"),
    (GraspTarget((0.5, 0.0, 0.05), 0.0, 0.2, 2e9), PLACE, "maximum opening"),
    (GraspTarget((0.5, 0.0, 0.05), 0.0, 0.05, -1.0), PLACE, "Young's modulus"),
    # Reachable, but close to the base a 15 cm straight lift runs the arm out of reach: refused before it
    # moves, not after the fingers closed (bench/bench_reach_near_base.py).
    (GraspTarget((0.277, -0.048, 0.036), -1.49, 0.04, 2e9), PLACE, "its straight lift cannot be made"),
])
def test_bad_goals_fail_before_the_arm_moves(kin, grasp, place, reason):
    sequence, robot = make(kin, grasp, place), FakeRobot(kin, World())
    run(sequence, robot)
    assert not sequence.outcome.success
    assert reason in sequence.outcome.failure_reason
    assert not any(isinstance(c, SendTrajectory) for c in robot.sent)


def test_arm_that_does_not_follow_fails_after_the_settle_timeout(kin):
    sequence, robot = make(kin), FakeRobot(kin, World())
    robot.trajectory = None
    original_apply = robot.apply

    def ignore_trajectories(commands, seq):
        original_apply([c for c in commands if not isinstance(c, SendTrajectory)], seq)
    robot.apply = ignore_trajectories
    run(sequence, robot)
    assert "did not reach the pre_grasp target" in sequence.outcome.failure_reason


def test_feedback_reports_phase_width_and_force(kin):
    sequence, robot = make(kin), FakeRobot(kin, World(contact_height_m=GRASP_TCP_Z_M + 0.01))
    run(sequence, robot, until=lambda r, s: s.phase == "close")
    feedback = sequence.feedback(robot.sim_s)
    assert feedback.phase == "close"
    assert 0.0 <= feedback.phase_progress <= 1.0
    assert feedback.gripper_width_m == pytest.approx(robot.width_m)
    assert feedback.external_force_n > CONFIG.contact_force_threshold_n


def run_until_finished(sequence, robot, max_s: float = 30.0):
    end = robot.sim_s + max_s
    while not sequence.finished and robot.sim_s < end:
        robot.step(sequence)
    assert sequence.finished


def test_transfer_passes_the_via_point_without_stopping(kin):
    via = (0.45, -0.2, 0.3)
    config = SequenceConfig(watchdog_timeout_s=0.5, transfer_via_position_m=via)
    sequence, robot = make(kin, config=config), FakeRobot(kin, World())
    closest = []

    def watch(r, s):
        if s.phase == "transfer":
            closest.append((float(np.linalg.norm(kin.fk(r.q)[:3, 3] - via)), float(np.abs(r.qd).max())))
        return False
    run(sequence, robot, until=watch)
    assert sequence.outcome.success, sequence.outcome.failure_reason
    distance, speed = min(closest)
    assert distance < 0.01 and speed > 0.2


@pytest.mark.parametrize("rule, lowest_tcp_z_m", [
    # fingertips (7 mm below the TCP) 3 mm above the table under either rule: tcp_height_m's floor and
    # pick_place.GRASP_MIN_HEIGHT_ABOVE_TABLE_M (below_surface's was 5 mm: fingertips 2 mm into the table)
    ("below_surface", 0.010),
    ("half_height", 0.010),
])
def test_grasp_on_a_thin_object_stops_above_the_table(kin, rule, lowest_tcp_z_m):
    thin = GraspTarget(position_m=(0.5, 0.05, 0.008), yaw_rad=0.0, width_m=0.03, youngs_modulus_pa=2e5)
    config = SequenceConfig(watchdog_timeout_s=0.5, grasp_height_rule=rule)
    sequence, robot = make(kin, grasp=thin, config=config), FakeRobot(kin, World(object_width_m=0.02))
    run(sequence, robot, until=lambda r, s: s.phase == "close")
    assert sequence.outcome.contact_height_m == pytest.approx(lowest_tcp_z_m, abs=1e-4)
    tcp_heights = [kin.fk(q)[2, 3] for c in robot.sent if isinstance(c, SendTrajectory) for q in c.trajectory.q_rad]
    assert min(tcp_heights) >= lowest_tcp_z_m - 1e-4


@pytest.mark.parametrize("table_z_m", [0.0, 0.1])
def test_half_height_rule_grasps_where_the_simulated_evaluation_does(kin, table_z_m):
    """grasp_height_rule half_height: the TCP stops at half the object height above the table, the
    height the evaluation and executor-height training data grasp at (grasping.geometry.tcp_height_m)."""
    tall = GraspTarget(position_m=(0.5, 0.05, table_z_m + 0.08), yaw_rad=0.4, width_m=0.05,
                       youngs_modulus_pa=2e5)
    config = SequenceConfig(watchdog_timeout_s=0.5, table_z_m=table_z_m, grasp_height_rule="half_height")
    sequence, robot = make(kin, grasp=tall, config=config), FakeRobot(kin, World(object_width_m=0.045))
    run(sequence, robot, until=lambda r, s: s.phase == "close")
    assert not sequence.outcome.contact_detected
    assert sequence.outcome.contact_height_m == pytest.approx(table_z_m + 0.04, abs=1e-3)
    assert sequence.outcome.contact_height_m == pytest.approx(tcp_height_m(tall.position_m[2], table_z_m), abs=1e-3)
    # below_surface on the same grasp goes one finger pad below the surface instead.
    below = SequenceConfig(watchdog_timeout_s=0.5, table_z_m=table_z_m, grasp_height_rule="below_surface")
    sequence, robot = make(kin, grasp=tall, config=below), FakeRobot(kin, World(object_width_m=0.045))
    run(sequence, robot, until=lambda r, s: s.phase == "close")
    assert sequence.outcome.contact_height_m == pytest.approx(tall.position_m[2] - below.grasp_depth_below_surface_m,
                                                              abs=1e-3)


def test_unknown_grasp_height_rule_is_refused():
    with pytest.raises(ValueError, match="grasp_height_rule"):
        SequenceConfig(grasp_height_rule="middle").validate()


def test_plan_failure_says_why_start_would_refuse_without_moving_the_arm(kin):
    assert make(kin).plan_failure(kin.q_ready_rad) == ""
    near_base = make(kin, grasp=GraspTarget((0.277, -0.048, 0.036), -1.49, 0.04, 2e9))
    assert "its straight lift cannot be made" in near_base.plan_failure(kin.q_ready_rad)
    assert near_base.phase == "idle" and not near_base.finished


def test_a_place_whose_straight_lowering_cannot_be_made_is_refused_before_the_grasp(kin):
    # IK reaches the place pose and the approach above it, but not the straight line between (near the base):
    # found out after the grasp, the pick failed holding the object (10 of 150 random places near the base)
    place = PlaceTarget(position_m=(0.278, -0.046, 0.052), yaw_rad=-0.54)
    sequence, robot = make(kin, place=place), FakeRobot(kin, World())
    assert "place pose unreachable: its straight lowering cannot be made" in sequence.plan_failure(kin.q_ready_rad)
    run(sequence, robot, max_s=10.0)
    assert sequence.finished and "straight lowering" in sequence.outcome.failure_reason
    assert not any(isinstance(c, SendTrajectory) for c in robot.sent)   # the arm never moved


class _CountingKinematics:
    """The real kinematics, counting top-down IK solves (one per pre-grasp and one per place approach)."""

    def __init__(self, kin):
        self._kin, self.top_down_solves = kin, 0

    def top_down_ik(self, *args, **kwargs):
        self.top_down_solves += 1
        return self._kin.top_down_ik(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._kin, name)


@pytest.mark.parametrize("moved_rad, solves_at_start", [(0.0, 0), (0.05, 2)])
def test_start_reuses_the_checked_plan_only_while_the_arm_rests_where_it_was_checked(kin, moved_rad, solves_at_start):
    counting = _CountingKinematics(kin)
    sequence = make(counting)
    assert sequence.plan_failure(kin.q_ready_rad) == ""
    checked = counting.top_down_solves
    q_start = np.array(kin.q_ready_rad) + [moved_rad, 0, 0, 0, 0, 0, 0]
    robot = FakeRobot(kin, World(), q0=q_start)
    run(sequence, robot, until=lambda r, s: s.phase == "descend")
    assert counting.top_down_solves - checked == solves_at_start


def test_the_rest_the_retreat_arrival_waited_for_is_not_waited_for_again(kin):
    """Arrival already needs rest_hold_s of rest: the run ends on the next tick, not rest_hold_s later."""
    sequence, robot = make(kin), FakeRobot(kin, World(object_width_m=0.045))
    done_at = []
    run(sequence, robot, until=lambda r, s: s.phase == "done" and not done_at and done_at.append(r.sim_s) and False)
    assert sequence.outcome.success and sequence.outcome.arm_state == "at_rest"
    ticks_after_done = round((robot.sim_s - done_at[0]) / 0.01)
    assert ticks_after_done <= 1, f"ended {ticks_after_done} ticks after the arrival at rest"


def _mid_transfer(kin):
    sequence, robot = make(kin), FakeRobot(kin, World(object_width_m=0.045))
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and r.sim_s - r.trajectory_start_s > 0.3)
    return sequence, robot


def test_a_cancel_stops_from_a_lead_along_the_commanded_motion_stamped_on_its_clock(kin):
    """The controller takes a new goal from the measured state: a stop planned from the last joint state and started
    on receipt began behind the moving arm by the state's age and the goal's latency. The stop starts STOP_LEAD_S
    ahead along the commanded motion, at the time the joint state's stamp puts it on the controller's clock."""
    from defgg_ros.control.pick_place import STOP_LEAD_S

    sequence, robot = _mid_transfer(kin)
    motion, age_s, latency_s = robot.trajectory, 0.03, 0.02   # the transfer started `latency_s` after it was sent
    started_s = robot.trajectory_start_s + latency_s
    stamp_s = robot.sim_s - age_s
    q, qd, _ = motion.state_at(stamp_s - started_s)
    sequence.on_joint_state(ArmState(q, qd, robot.width_m, stamp_s), robot.wall_s)
    (stop,) = [c for c in sequence.cancel(robot.sim_s, robot.wall_s) if isinstance(c, SendTrajectory)]
    # on the controller's clock: the state's stamp (it arrived just now), plus the lead, at the next sample
    assert stop.start_s == pytest.approx(stamp_s + STOP_LEAD_S, abs=0.011)
    q_then, qd_then, _ = motion.state_at(stop.start_s - started_s)
    np.testing.assert_allclose(stop.trajectory.q_rad[0], q_then, atol=2e-4)   # where the arm will be then
    np.testing.assert_allclose(stop.trajectory.qd_radps[0], qd_then, atol=2e-2)


def test_the_stop_leads_by_the_arm_goals_measured_latency_when_that_is_longer(kin):
    """Goals answered 0.14 s after they were sent (a loaded machine): a stop led by STOP_LEAD_S alone would arrive
    after the time it is stamped for and the controller would sample straight into it, behind the arm. The lead is
    STOP_LEAD_LATENCY_FACTOR times the longest recent round trip, capped at MAX_STOP_LEAD_S; STOP_LEAD_S stays the
    least."""
    from defgg_ros.control.pick_place import MAX_STOP_LEAD_S, STOP_LEAD_LATENCY_FACTOR, STOP_LEAD_S, STOP_LEAD_WINDOW

    for latencies_s, lead_s in (([0.05], STOP_LEAD_S), ([0.05, 0.14, 0.1], 0.14 * STOP_LEAD_LATENCY_FACTOR),
                                ([2.0], MAX_STOP_LEAD_S), ([0.25] + [0.01] * STOP_LEAD_WINDOW, STOP_LEAD_S)):
        sequence, robot = _mid_transfer(kin)
        for latency_s in latencies_s:
            sequence.on_goal_answered(latency_s)
        sequence.on_goal_answered(float("nan"))   # no stamped state at one end: not a measurement
        q, qd, _ = robot.trajectory.state_at(robot.sim_s - robot.trajectory_start_s)
        sequence.on_joint_state(ArmState(q, qd, robot.width_m, robot.sim_s), robot.wall_s)
        (stop,) = [c for c in sequence.cancel(robot.sim_s, robot.wall_s) if isinstance(c, SendTrajectory)]
        assert sequence.stop_lead_s == pytest.approx(lead_s)
        assert robot.sim_s + lead_s <= stop.start_s <= robot.sim_s + lead_s + CONFIG.sample_dt_s + 1e-9, latencies_s
        q_then, _, _ = robot.trajectory.state_at(stop.start_s - robot.trajectory_start_s)
        np.testing.assert_allclose(stop.trajectory.q_rad[0], q_then, atol=2e-4)


def test_the_stop_is_stamped_on_the_controllers_clock_whatever_ours_reads(kin):
    """A controller whose clock runs 0.3 s ahead of ours: a stop stamped from our clock plus the lead lay in the
    controller's past (it then samples straight into the stop and pulls the arm back). Every time is taken from
    the joint state's stamp."""
    from defgg_ros.control.pick_place import STOP_LEAD_S

    sequence, robot = _mid_transfer(kin)
    ahead_s, started_s = 0.3, robot.trajectory_start_s      # the controller's clock - ours
    q, qd, _ = robot.trajectory.state_at(robot.sim_s - started_s)
    stamp_s = robot.sim_s + ahead_s
    sequence.on_joint_state(ArmState(q, qd, robot.width_m, stamp_s), robot.wall_s)
    (stop,) = [c for c in sequence.cancel(robot.sim_s, robot.wall_s) if isinstance(c, SendTrajectory)]
    assert stop.start_s == pytest.approx(stamp_s + STOP_LEAD_S, abs=0.011)
    q_then, _, _ = robot.trajectory.state_at(stop.start_s - ahead_s - started_s)
    np.testing.assert_allclose(stop.trajectory.q_rad[0], q_then, atol=2e-4)


def test_a_state_without_a_stamp_stops_at_once_and_the_owners_stop_repeats_a_stamped_stop(kin):
    sequence, robot = _mid_transfer(kin)
    q, qd = robot.q.copy(), robot.qd.copy()
    sequence.on_joint_state(ArmState(q, qd, robot.width_m), robot.wall_s)    # no stamp (NaN)
    (stop,) = [c for c in sequence.cancel(robot.sim_s, robot.wall_s) if isinstance(c, SendTrajectory)]
    assert stop.start_s is None
    np.testing.assert_allclose(stop.trajectory.q_rad[0], q)   # from the measured position, on receipt
    assert sequence.stop_now() is None             # a stop on receipt runs: the owner's own hold

    sequence, robot = _mid_transfer(kin)
    sequence.on_joint_state(ArmState(robot.q.copy(), robot.qd.copy(), robot.width_m, robot.sim_s), robot.wall_s)
    (stop,) = [c for c in sequence.cancel(robot.sim_s, robot.wall_s) if isinstance(c, SendTrajectory)]
    again = sequence.stop_now()            # the executor's exit during that stop: the same stop
    assert again is not None and again[1] == stop.start_s and again[0] is stop.trajectory
