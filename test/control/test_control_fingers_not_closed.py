"""A grasp whose fingers stop where they opened to is a finger on the object, not a held object."""
from support.control_fake_robot import FakeRobot, World, run

from defgg_ros.control.gripper_rule import pre_grasp_opening_m
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import NOT_CLOSED_TOLERANCE_M, PickPlaceSequence
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget, SequenceConfig

GRASP = GraspTarget(position_m=(0.5, 0.05, 0.05), yaw_rad=0.4, width_m=0.04, youngs_modulus_pa=2e9)
PLACE = PlaceTarget(position_m=(0.35, -0.45, 0.12))
OPENED_M = pre_grasp_opening_m(GRASP.width_m)     # 50 mm: the hand opens 10 mm wider than the grasp


def pick_with_fingers_stopping_at(width_m):
    kin = PandaKinematics()
    sequence = PickPlaceSequence(kin, SequenceConfig(watchdog_timeout_s=0.5), GRASP, PLACE)
    run(sequence, FakeRobot(kin, World(object_width_m=width_m)))
    return sequence.outcome


def test_fingers_blocked_at_the_pre_grasp_opening_fail_at_the_close_with_the_reason():
    outcome = pick_with_fingers_stopping_at(OPENED_M - NOT_CLOSED_TOLERANCE_M / 2)
    assert not outcome.success and outcome.phase_reached == "close"
    assert "did not close" in outcome.failure_reason and "on the object" in outcome.failure_reason
    assert not outcome.held_after_lift


def test_a_wide_object_that_the_fingers_did_close_on_is_picked():
    outcome = pick_with_fingers_stopping_at(OPENED_M - 2 * NOT_CLOSED_TOLERANCE_M)
    assert outcome.success, outcome.failure_reason
