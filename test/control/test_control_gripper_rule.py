"""The grasp force/width rule: monotone in log E, clipped, clear errors."""
import math

import pytest

from defgg_ros.constants import GRIPPER_MAX_FORCE_N, GRIPPER_MAX_WIDTH_M, TRAINING_YOUNGS_MODULI_PA
from defgg_ros.control.gripper_rule import (
    MISSED_WIDTH_M,
    RIGID_GRASP_FORCE_N,
    SOFT_GRASP_FORCE_N,
    GripperRuleError,
    grasp_command,
    grasp_force_n,
)


def test_force_grows_with_log_modulus_and_is_clipped():
    forces = [grasp_force_n(e) for e in TRAINING_YOUNGS_MODULI_PA]
    assert forces == sorted(forces) and len(set(forces)) == len(forces)
    assert forces[0] == pytest.approx(SOFT_GRASP_FORCE_N)
    assert forces[-1] == pytest.approx(RIGID_GRASP_FORCE_N)
    assert grasp_force_n(1e3) == pytest.approx(SOFT_GRASP_FORCE_N)
    assert grasp_force_n(1e10) == pytest.approx(RIGID_GRASP_FORCE_N)
    assert RIGID_GRASP_FORCE_N <= GRIPPER_MAX_FORCE_N
    # Linear in log10(E): the geometric midpoint gets the mean force.
    midpoint = math.sqrt(2e4 * 2e9)
    assert grasp_force_n(midpoint) == pytest.approx(0.5 * (SOFT_GRASP_FORCE_N + RIGID_GRASP_FORCE_N))


def test_command_window_accepts_anything_but_empty_fingers():
    command = grasp_command(2e5, 0.04)
    assert command.pre_open_width_m > command.width_m == pytest.approx(0.04)
    assert command.width_m - command.epsilon_inner_m == pytest.approx(MISSED_WIDTH_M)
    assert command.width_m + command.epsilon_outer_m == pytest.approx(command.pre_open_width_m)
    assert command.pre_open_width_m <= GRIPPER_MAX_WIDTH_M
    assert grasp_command(2e4, 0.04).speed_mps < grasp_command(2e9, 0.04).speed_mps


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
