"""The grasp force/width rule: monotone in log E, clipped, clear errors."""
import math

import pytest

from defgg_ros.constants import GRIPPER_MAX_FORCE_N, GRIPPER_MAX_WIDTH_M, TRAINING_YOUNGS_MODULI_PA
from defgg_ros.control.gripper_rule import (
    MISSED_WIDTH_M,
    GripperRuleError,
    grasp_command,
    grasp_force_n,
)
from defgg_ros.sim.protocol import LEGACY, PROTOCOLS


def test_force_is_the_training_labels_force_growing_with_log_modulus():
    forces = [grasp_force_n(e) for e in TRAINING_YOUNGS_MODULI_PA]
    assert forces == sorted(forces) and len(set(forces)) == len(forces)
    # the legacy labels' trials closed with these forces (mass plays no part in that protocol's rule)
    assert forces == [PROTOCOLS[LEGACY].finger_force_n(e, mass_kg=0.1) for e in TRAINING_YOUNGS_MODULI_PA]
    assert all(0 < f <= GRIPPER_MAX_FORCE_N for f in forces)
    # Linear in log10(E): the geometric midpoint gets the mean force.
    midpoint = math.sqrt(2e4 * 2e9)
    assert grasp_force_n(midpoint) == pytest.approx(0.5 * (forces[0] + forces[-1]))
    assert grasp_command(2e4, 0.04).force_n == pytest.approx(forces[0])


def test_command_window_accepts_anything_but_empty_fingers():
    command = grasp_command(2e5, 0.04)
    assert command.pre_open_width_m > command.width_m == pytest.approx(0.04)
    assert command.width_m - command.epsilon_inner_m == pytest.approx(MISSED_WIDTH_M)
    assert command.width_m + command.epsilon_outer_m == pytest.approx(command.pre_open_width_m)
    assert command.pre_open_width_m <= GRIPPER_MAX_WIDTH_M
    assert grasp_command(2e4, 0.04).speed_mps < grasp_command(2e9, 0.04).speed_mps


def test_the_hand_opens_10_mm_wider_than_the_grasp_not_fully():
    """Opened fully (80 mm) for a 32 mm grasp, a finger came down 2.6 cm beyond the grasp's pads: onto a ring's
    far tube or a neighbour in a bin. 10 mm wider: the training trials' start; never beyond the hand."""
    assert grasp_command(2e5, 0.032).pre_open_width_m == pytest.approx(0.042)
    assert grasp_command(2e5, 0.075).pre_open_width_m == pytest.approx(GRIPPER_MAX_WIDTH_M)
    assert grasp_command(2e5, GRIPPER_MAX_WIDTH_M).epsilon_outer_m == 0.0


@pytest.mark.parametrize("modulus, width, message", [
    (float("nan"), 0.04, "Young's modulus"),
    (-5.0, 0.04, "Young's modulus"),
    (2e5, 0.0, "positive"),
    (2e5, 0.09, "maximum opening"),
    (2e5, float("inf"), "positive"),
])
def test_bad_inputs_raise(modulus, width, message):
    with pytest.raises(GripperRuleError, match=message):
        grasp_command(modulus, width)


def test_a_grasp_that_carries_its_labels_force_is_closed_with_it():
    """Grasp.finger_force_n > 0 (a defgraspsim model's FOS*m*g/mu): that force, within the hand's rating;
    0: the modulus rule; anything else refused."""
    assert grasp_command(2e9, 0.04, finger_force_n=0.65).force_n == pytest.approx(0.65)
    assert grasp_command(2e9, 0.04, finger_force_n=0.0).force_n == grasp_force_n(2e9)
    assert grasp_command(2e9, 0.04, finger_force_n=500.0).force_n == GRIPPER_MAX_FORCE_N
    assert grasp_command(2e4, 0.04, finger_force_n=0.65).speed_mps < grasp_command(2e9, 0.04, 0.65).speed_mps
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(GripperRuleError, match="grasp force"):
            grasp_command(2e5, 0.04, finger_force_n=bad)
