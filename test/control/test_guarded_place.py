"""The guarded place into the bin and the recovery's drop zone (issue 48.2, 48.3), on a fake clock.

A bin target (lower_to_contact) is lowered into at place_lowering_speed_mps until the force rises over the
contact threshold (something under the object) or the object's bottom is place_release_clearance_m above the
table; the hand opens there, only place_release_opening_m wider than it closed. A recovery holding the object puts
it down in the drop zone (recovery_drop_xy_m) the same guarded way, where the arm can pick it again.
"""
import numpy as np
import pytest
from support.control_fake_robot import FakeRobot, World, run

from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import RELEASE_RELIEF_LIFT_M, PickPlaceSequence
from defgg_ros.control.sequence_types import GraspTarget, MoveGripper, PlaceTarget, SequenceConfig

pytestmark = pytest.mark.unit

GRASP = GraspTarget(position_m=(0.5, 0.05, 0.05), yaw_rad=0.4, width_m=0.05, youngs_modulus_pa=2e9)
BIN = PlaceTarget(position_m=(0.35, -0.45, 0.12), lower_to_contact=True)
CONFIG = SequenceConfig(watchdog_timeout_s=0.5, observation_q_rad=tuple(PANDA_READY_Q_RAD))


@pytest.fixture(scope="module")
def kin():
    return PandaKinematics()


def _releases(kin, robot, sequence, max_s=120.0):
    """Step to the end; the TCP position and the width of every MoveGripper sent after the grasp."""
    releases = []
    while not sequence.finished and robot.sim_s < max_s:
        before = len(robot.sent)
        robot.step(sequence)
        releases += [(kin.fk(robot.q)[:3, 3], c.width_m) for c in robot.sent[before:] if isinstance(c, MoveGripper)]
    assert sequence.finished
    return releases


def test_the_bin_lowering_stops_on_contact_and_releases_there(kin):
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, BIN)
    run(sequence, robot, until=lambda r, s: s.phase == "place")
    robot.world.contact_height_m = 0.09   # a block already in the slot: the held one meets it at TCP z 9 cm
    (tcp, width), = _releases(kin, robot, sequence)
    out = sequence.outcome
    assert out.success, out.failure_reason
    assert sequence.released_at_place and sequence.place_contact_z_m == pytest.approx(0.09, abs=0.005)
    # stopped within a few mm of the touch (the jerk-limited stop at 5 cm/s), not pushed on to the floor
    assert 0.09 - 0.005 < tcp[2] < 0.09 and np.allclose(tcp[:2], BIN.position_m[:2], atol=3e-3)
    assert width == pytest.approx(out.gripper_width_closed_m + CONFIG.place_release_opening_m)


def test_a_free_bin_lowering_puts_the_object_on_the_floor(kin):
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, BIN)
    run(sequence, robot, until=lambda r, s: s.phase == "place")
    (tcp, _), = _releases(kin, robot, sequence)
    out = sequence.outcome
    assert out.success and not np.isfinite(sequence.place_contact_z_m)
    # the object's bottom (as far under the TCP as the TCP was above the table at the grasp) 1 cm above the floor
    assert tcp[2] == pytest.approx(out.contact_height_m + CONFIG.place_release_clearance_m, abs=2e-3)
    assert tcp[2] < BIN.position_m[2] - 0.05   # well below the old release height (12 cm: a 9 cm drop)


def test_a_goals_place_pose_is_still_released_where_it_says(kin):
    place = PlaceTarget(position_m=(0.35, -0.45, 0.12))
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, place)
    run(sequence, robot, until=lambda r, s: s.phase == "place")
    (tcp, _), = _releases(kin, robot, sequence)
    assert sequence.outcome.success and tcp == pytest.approx(place.position_m, abs=3e-3)


def test_a_goals_place_pose_is_guarded_too_it_stops_and_releases_on_contact(kin):
    """A goal's own pose too low (the object meets the surface 3 cm above it): the lowering stops on the force
    and releases there (it pushed on to the pose: 100 N against the 10 N threshold in the fake cell)."""
    place = PlaceTarget(position_m=(0.35, -0.45, 0.06))
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, place)
    run(sequence, robot, until=lambda r, s: s.phase == "place")
    robot.world.contact_height_m = 0.09
    (tcp, _), = _releases(kin, robot, sequence)
    assert sequence.outcome.success, sequence.outcome.failure_reason
    assert sequence.place_contact_z_m == pytest.approx(0.09, abs=0.005)
    assert 0.09 - 0.01 < tcp[2] < 0.09                      # stopped near the touch (0.1 m/s), not pressed to 6 cm


@pytest.mark.parametrize("drop_xy", [(0.40, 0.0), None], ids=["drop_zone", "no_drop_zone"])
def test_a_recovery_holding_the_object_puts_it_down_in_the_drop_zone(kin, drop_xy):
    config = SequenceConfig(watchdog_timeout_s=0.5, observation_q_rad=tuple(PANDA_READY_Q_RAD),
                            recovery_drop_xy_m=drop_xy)
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, config, GRASP, BIN)
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and s.feedback(r.sim_s).phase_progress > 0.3)
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    (tcp, _), = _releases(kin, robot, sequence)
    out = sequence.outcome
    assert out.canceled and "released it there" in out.recovery, out.recovery
    where = drop_xy if drop_xy is not None else BIN.position_m[:2]
    assert np.allclose(tcp[:2], where, atol=3e-3), (tcp, out.recovery)
    assert tcp[2] == pytest.approx(out.contact_height_m + config.place_release_clearance_m, abs=2e-3)
    assert out.arm_state == "observation_pose"


def test_a_recovery_put_down_stops_on_what_is_below(kin):
    config = SequenceConfig(watchdog_timeout_s=0.5, observation_q_rad=tuple(PANDA_READY_Q_RAD),
                            recovery_drop_xy_m=(0.40, 0.0))
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, config, GRASP, BIN)
    run(sequence, robot, until=lambda r, s: s.phase == "transfer" and s.feedback(r.sim_s).phase_progress > 0.3)
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    robot.world.contact_height_m = 0.08
    (tcp, _), = _releases(kin, robot, sequence)
    assert "touched down" in sequence.outcome.recovery and 0.075 < tcp[2] < 0.08, sequence.outcome.recovery


def test_a_cancel_after_the_release_does_not_open_the_hand_further(kin):
    """The hand opened only place_release_opening_m wider than closed: a cancel in the retreat must not open it to
    the full width beside the bin's wall or a neighbour (the soak saw 'fingers blocked at 76.6 mm' end the
    recovery over the bin); it lifts and goes to the observation pose."""
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, BIN)
    run(sequence, robot, until=lambda r, s: s.phase == "retreat" and s.feedback(r.sim_s).phase_progress > 0.2)
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    assert _releases(kin, robot, sequence) == []
    out = sequence.outcome
    assert out.canceled and "opened the hand" not in out.recovery and out.arm_state == "observation_pose", out.recovery


@pytest.mark.parametrize("blocked_above_m", [0.005, 0.03])
def test_a_release_blocked_on_the_floor_lifts_the_hand_and_opens_again(kin, blocked_above_m):
    """Finger tips pressed on the bin's floor (a touch-down stopped late): the opening fingers drag on it and stop.
    The hand lifts RELEASE_RELIEF_LIFT_M and opens again; blocked still after that (a wall beside the fingers),
    the place fails and says so."""
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, BIN)
    run(sequence, robot, until=lambda r, s: s.phase == "place")
    robot.world.contact_height_m = 0.09
    robot.world.open_blocked_below_tcp_z_m = 0.09 + blocked_above_m
    releases = _releases(kin, robot, sequence)
    out = sequence.outcome
    if blocked_above_m < RELEASE_RELIEF_LIFT_M:
        assert out.success, out.failure_reason
        assert "release blocked" in out.recovery and len(releases) == 2
        assert releases[1][0][2] == pytest.approx(releases[0][0][2] + RELEASE_RELIEF_LIFT_M, abs=1e-3)
        assert robot.width_m == pytest.approx(out.gripper_width_closed_m + CONFIG.place_release_opening_m)
    else:
        assert not out.success and "again after lifting" in out.failure_reason, out.failure_reason
        assert [w for _, w in releases[:2]] == [releases[0][1]] * 2


def test_a_rejected_release_fails_at_once_without_lifting(kin):
    """Only fingers that stopped short of the release width were blocked: a rejected opening (the gripper's
    server gone, no width) fails the place where it is, and the arm does not move for a second try."""
    robot = FakeRobot(kin, World(object_width_m=0.045))
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, BIN)
    run(sequence, robot, until=lambda r, s: s.phase == "place")
    robot.world.opening_rejected = True
    releases = _releases(kin, robot, sequence)
    out = sequence.outcome
    assert not out.success and "gripper goal rejected" in out.failure_reason, out.failure_reason
    assert "again after lifting" not in out.failure_reason and "release blocked" not in out.recovery
    assert len(releases) == 1
