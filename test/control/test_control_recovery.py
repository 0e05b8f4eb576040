"""Recovery after a failure or cancel, and "stop means stopped" (issue 27.1, 27.4), on a fake clock.

The arm must end at the observation pose (hand opened first when it holds nothing, the held object
placed first when it holds one) and say so; a stop must wait until the arm is at rest, or report
that it did not as a failure of its own.
"""
import numpy as np
import pytest
from support.control_fake_robot import GRASP, PLACE, RECOVERING_CONFIG, TICK_S, FakeRobot, World, run

from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import ObservationMove, PickPlaceSequence
from defgg_ros.control.sequence_types import (
    ArmState,
    MoveGripper,
    SendTrajectory,
    SequenceConfig,
)
from defgg_ros.control.trajectories import tcp_peak_acceleration_mps2

pytestmark = pytest.mark.unit

OBSERVE_Q = np.array(PANDA_READY_Q_RAD)
CONFIG = RECOVERING_CONFIG


@pytest.fixture(scope="module")
def kin():
    return PandaKinematics()


def finish(sequence, robot, max_s=120.0):
    while not sequence.finished and robot.sim_s < max_s:
        robot.step(sequence)
    assert sequence.finished, f"still in {sequence.phase}"


def commands_after(robot, index):
    return robot.sent[index:]


def at_observation(robot):
    return float(np.max(np.abs(robot.q - OBSERVE_Q))) < CONFIG.arrival_joint_atol_rad


def test_cancel_mid_descend_opens_lifts_and_ends_at_the_observation_pose(kin):
    sequence, robot = PickPlaceSequence(kin, CONFIG, GRASP, PLACE), FakeRobot(kin, World())
    run(sequence, robot, until=lambda r, s: s.phase == "descend" and s.feedback(r.sim_s).phase_progress > 0.5)
    robot.width_m = 0.03  # the hand partly closed (say, a finger caught): it must open before rising
    stopped_at = len(robot.sent)
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    tcp_at_cancel = kin.fk(robot.q)[:3, 3]
    finish(sequence, robot)
    out = sequence.outcome
    assert out.canceled and not out.success
    assert out.phase_reached == "descend" and "canceled during descend" in out.failure_reason
    assert out.arm_state == "observation_pose" and at_observation(robot)
    assert "opened the hand" in out.recovery and "moved to the observation pose" in out.recovery
    # Order: the jerk-limited stop, the hand opens, then the motions (first straight up).
    after = commands_after(robot, stopped_at)
    kinds = [type(c).__name__ for c in after]
    assert kinds[:4] == ["SendTrajectory", "MoveGripper", "SendTrajectory", "SendTrajectory"], kinds
    lift = after[2].trajectory
    start_tcp, end_tcp = kin.fk(lift.q_rad[0])[:3, 3], kin.fk(lift.final_q_rad)[:3, 3]
    assert end_tcp[:2] == pytest.approx(start_tcp[:2], abs=2e-3)
    assert end_tcp[2] - start_tcp[2] == pytest.approx(CONFIG.observation_lift_m, abs=2e-3)
    assert start_tcp == pytest.approx(tcp_at_cancel, abs=0.02)


def test_missed_grasp_opens_the_hand_before_leaving(kin):
    sequence, robot = PickPlaceSequence(kin, CONFIG, GRASP, PLACE), FakeRobot(kin, World(object_width_m=None))
    run(sequence, robot, max_s=120.0)
    out = sequence.outcome
    assert "missed" in out.failure_reason and out.phase_reached == "close"
    assert out.arm_state == "observation_pose" and at_observation(robot)
    opened = [c for c in robot.sent if isinstance(c, MoveGripper)]
    assert opened[-1].width_m > 0.05 and robot.width_m == pytest.approx(opened[-1].width_m)


def test_a_grasp_that_fails_long_after_the_descent_still_recovers(kin):
    # The stop's rest timeout counts from the stop, not from the end of the last motion: a soft
    # object's slow squeeze (the simulated hand's 5 s grasp timeout) once ended such picks with
    # "the arm did not come to rest ... 0.000 rad/s" and no recovery (demo, 2026-11-28).
    delay_s = CONFIG.stop_timeout_s + 1.0
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE)
    robot = FakeRobot(kin, World(object_width_m=None, gripper_report_delay_s=delay_s))
    run(sequence, robot, max_s=120.0)
    out = sequence.outcome
    assert out.failure_reason.startswith("missed"), out.failure_reason
    assert out.arm_state == "observation_pose" and at_observation(robot)


def test_an_object_held_at_a_cancel_is_placed_before_the_arm_leaves(kin):
    sequence, robot = PickPlaceSequence(kin, CONFIG, GRASP, PLACE), FakeRobot(kin, World(object_width_m=0.045))
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and s.feedback(r.sim_s).phase_progress > 0.3)
    sent_before_cancel = len(robot.sent)
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    releases = []
    while not sequence.finished and robot.sim_s < 120:
        before = len(robot.sent)
        robot.step(sequence)
        for c in robot.sent[before:]:
            if isinstance(c, MoveGripper):
                releases.append(kin.fk(robot.q)[:3, 3])
    out = sequence.outcome
    assert out.canceled and out.phase_reached == "transfer" and not out.held_after_transfer
    assert out.recovery.startswith("carried the held object"), out.recovery
    # The carry holds the object like the transfer: slowed down to the same TCP acceleration cap.
    stop, carry = [c.trajectory for c in robot.sent[sent_before_cancel:] if isinstance(c, SendTrajectory)][:2]
    assert tcp_peak_acceleration_mps2(kin, carry) <= CONFIG.transfer_max_tcp_accel_mps2 * 1.001
    assert "released it there" in out.recovery
    (release_tcp,) = releases  # opened once, at the place pose
    assert release_tcp == pytest.approx(PLACE.position_m, abs=3e-3)
    assert out.arm_state == "observation_pose" and at_observation(robot)


def test_an_object_dropped_while_carried_back_ends_as_a_recovery_holding_nothing(kin):
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE)
    robot = FakeRobot(kin, World(object_width_m=0.045, slip_at_phase="recover"))
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and s.feedback(r.sim_s).phase_progress > 0.3)
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    finish(sequence, robot)
    out = sequence.outcome
    assert "stopped: object dropped during recover" in out.recovery, out.recovery
    assert "opened the hand" in out.recovery and out.recovery.endswith("moved to the observation pose")
    assert out.arm_state == "observation_pose" and at_observation(robot)


def test_a_dropped_object_is_not_carried_on(kin):
    sequence, robot = PickPlaceSequence(kin, CONFIG, GRASP, PLACE), FakeRobot(kin, World(slip_at_phase="transfer"))
    run(sequence, robot, max_s=120.0)
    out = sequence.outcome
    assert "dropped during transfer" in out.failure_reason
    assert "carried" not in out.recovery and out.arm_state == "observation_pose"


def test_without_an_observation_pose_the_arm_stays_where_it_stopped(kin):
    config = SequenceConfig(watchdog_timeout_s=0.5)
    sequence, robot = PickPlaceSequence(kin, config, GRASP, PLACE), FakeRobot(kin, World(object_width_m=None))
    run(sequence, robot)
    assert sequence.outcome.arm_state == "at_rest" and sequence.outcome.recovery == ""
    assert not at_observation(robot)


def test_driver_silent_during_recovery_reports_an_unknown_arm_state(kin):
    sequence, robot = PickPlaceSequence(kin, CONFIG, GRASP, PLACE), FakeRobot(kin, World(object_width_m=None))
    run(sequence, robot, until=lambda r, s: s.recovering and s.feedback(r.sim_s).phase == "recover"
        and r.trajectory is not None and r.sim_s - r.trajectory_start_s > 0.2)
    robot.world.silent = True
    finish(sequence, robot)
    out = sequence.outcome
    assert out.arm_state == "unknown" and "driver silent" in out.recovery
    assert "missed" in out.failure_reason


class SwayingRobot(FakeRobot):
    """After the stop trajectory ends the first joint keeps swinging for `sway_s` (reported joint
    speed 0.2 cos(2 pi t) rad/s, through zero twice a second), as an arm ringing after a hard stop."""

    def __init__(self, *args, sway_s: float, **kwargs):
        super().__init__(*args, **kwargs)
        self.sway_s, self.sway_from_s = sway_s, None

    def cancel(self, sequence):
        self.apply(sequence.cancel(self.sim_s, self.sim_s), sequence)
        self.sway_from_s = self.trajectory_start_s + self.trajectory.duration_s

    def step(self, sequence):
        report = sequence.on_joint_state

        def swaying(state, wall_s):
            t = self.sim_s - (self.sway_from_s if self.sway_from_s is not None else np.inf)
            if 0.0 <= t < self.sway_s:
                qd = state.qd_radps.copy()
                qd[0] = 0.2 * np.cos(2 * np.pi * t)
                state = ArmState(state.q_rad, qd, state.gripper_width_m)
            report(state, wall_s)

        sequence.on_joint_state = swaying
        try:
            super().step(sequence)
        finally:
            del sequence.on_joint_state


@pytest.mark.parametrize("sway_s", [1.5, 10.0])
def test_a_stop_ends_only_at_rest_or_says_it_did_not(kin, sway_s):
    config = SequenceConfig(watchdog_timeout_s=0.5)  # no recovery: the stop alone
    sequence = PickPlaceSequence(kin, config, GRASP, PLACE)
    robot = SwayingRobot(kin, World(), sway_s=sway_s)
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and s.feedback(r.sim_s).phase_progress > 0.4)
    robot.cancel(sequence)
    finish(sequence, robot)
    out = sequence.outcome
    sway_ends_s = robot.sway_from_s + sway_s
    if sway_s < config.stop_timeout_s:
        # Ended after the swinging stopped (not at one of its zero crossings), at rest.
        assert robot.sim_s >= sway_ends_s + config.rest_hold_s - 2 * TICK_S
        assert out.arm_state == "at_rest" and out.failure_reason == "canceled during transfer"
    else:
        assert robot.sim_s < sway_ends_s
        assert out.arm_state == "moving"
        assert out.failure_reason.startswith("the arm did not come to rest"), out.failure_reason
        assert "canceled during transfer" in out.failure_reason


def test_an_arm_that_keeps_moving_is_not_recovered(kin):
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE)
    robot = SwayingRobot(kin, World(), sway_s=30.0)
    run(sequence, robot, until=lambda r, s: s.phase == "descend" and s.feedback(r.sim_s).phase_progress > 0.5)
    n = len(robot.sent)
    robot.cancel(sequence)
    finish(sequence, robot)
    assert sequence.outcome.arm_state == "moving" and sequence.outcome.recovery == ""
    assert len([c for c in robot.sent[n:] if isinstance(c, SendTrajectory)]) == 1  # the stop only


def test_observation_move_from_over_the_table(kin):
    over_table = PickPlaceSequence(kin, CONFIG, GRASP, PLACE)
    robot = FakeRobot(kin, World())
    run(over_table, robot, until=lambda r, s: s.phase == "close")
    move = ObservationMove(kin, CONFIG)
    robot.sent.clear()
    run(move, robot)
    assert move.outcome.success and move.outcome.arm_state == "observation_pose" and at_observation(robot)
    assert not any(isinstance(c, MoveGripper) for c in robot.sent)  # the hand is left alone
    again = ObservationMove(kin, CONFIG)
    robot.sent.clear()
    run(again, robot)
    assert again.outcome.success and robot.sent == []


def test_observation_watch_clears_only_frames_taken_after_the_arm_arrived():
    from defgg_ros.control.observation import ObservationWatch, arm_state_of

    watch = ObservationWatch(OBSERVE_Q, 0.05)
    away = OBSERVE_Q + np.array([0.3, 0, 0, 0, 0, 0, 0])
    watch.update(away, 10.0)
    assert not watch.at_observation() and not watch.frame_is_clear(10.0)
    watch.update(OBSERVE_Q + 0.01, 12.0)
    watch.update(OBSERVE_Q, 13.0)
    assert watch.since_s == 12.0
    assert not watch.frame_is_clear(11.9) and watch.frame_is_clear(12.0)
    watch.update(away, 14.0)  # left again: no frame is clear until it is back
    assert not watch.frame_is_clear(15.0)
    assert arm_state_of(OBSERVE_Q, np.zeros(7), OBSERVE_Q, 0.05, 0.02) == "observation_pose"
    assert arm_state_of(away, np.zeros(7), OBSERVE_Q, 0.05, 0.02) == "at_rest"
    assert arm_state_of(away, np.full(7, 0.1), OBSERVE_Q, 0.05, 0.02) == "moving"
    assert arm_state_of(OBSERVE_Q, np.full(7, np.nan), OBSERVE_Q, 0.05, 0.02) == "moving"   # speed unknown
    assert arm_state_of(None, None, OBSERVE_Q, 0.05, 0.02) == "unknown"


def test_fingers_pushed_open_while_carrying_is_a_lost_object_not_a_success(kin):
    sequence, robot = PickPlaceSequence(kin, CONFIG, GRASP, PLACE), FakeRobot(kin, World(object_width_m=0.045))
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and s.feedback(r.sim_s).phase_progress > 0.3)
    robot.width_m = 0.075  # the fingers spring open mid-transfer (the simulated cell did: 51 -> 79 mm)
    finish(sequence, robot)
    out = sequence.outcome
    assert not out.success and not out.held_after_transfer
    assert out.failure_reason.startswith("object lost during transfer: the fingers opened from 45.0 mm to 75.0 mm")
    assert "carried" not in out.recovery and out.arm_state == "observation_pose"


def test_a_cancel_during_a_failures_stop_is_kept_and_no_recovery_follows(kin):
    # The action forwards one cancel: arriving while the failure's stop runs, it used to be dropped, and
    # the lift and move to the observation pose then ran with no way to stop them through the action.
    sequence, robot = PickPlaceSequence(kin, CONFIG, GRASP, PLACE), FakeRobot(kin, World(object_width_m=None))
    run(sequence, robot, until=lambda r, s: s.outcome.failure_reason != "")
    assert "missed" in sequence.outcome.failure_reason and not sequence.finished
    sent = len(robot.sent)
    assert sequence.cancel(robot.sim_s, robot.sim_s) == []       # already stopping: nothing new to send
    finish(sequence, robot)
    out = sequence.outcome
    assert out.canceled and not out.success and "missed" in out.failure_reason
    assert "canceled during the stop: no recovery" in out.recovery
    assert not any(isinstance(c, SendTrajectory) for c in robot.sent[sent:])   # no recovery motion
    assert not at_observation(robot)
