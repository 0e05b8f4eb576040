"""Grip force rules of the trial protocols (pure arithmetic; docs/dataset.md, "Trial protocols").

Below the cores: the trials (sim.trial) label with these forces and the executor (control.gripper_rule)
grasps with the legacy one, so neither has to import the other.
"""
from __future__ import annotations

import math

from defgg_ros.constants import GRAVITY_MPS2, GRIPPER_MAX_FORCE_N

# legacy (fem_v1-v4): 2 N at E = 2e4 Pa plus 0.5 N per decade of E a finger, as DefGraspSim grew the force
# with log E: soft objects are squeezed gently, stiff ones firmly. 2 N was the FEM probe's force.
FORCE_AT_SOFTEST_N = 2.0
FORCE_PER_DECADE_N = 0.5
FORCE_REFERENCE_E_PA = 2e4


def grasp_force_n(youngs_modulus_pa: float) -> float:
    """The legacy protocol's force per finger (N), independent of the object's mass."""
    decades = math.log10(max(youngs_modulus_pa, FORCE_REFERENCE_E_PA) / FORCE_REFERENCE_E_PA)
    return float(min(FORCE_AT_SOFTEST_N + FORCE_PER_DECADE_N * decades, GRIPPER_MAX_FORCE_N))


def factor_of_safety(youngs_modulus_pa: float) -> float:
    """DefGraspSim's FOS = 1 + log10(E) / 10 (1.43 at 2e4 Pa ... 1.93 at 2e9 Pa)."""
    return 1.0 + math.log10(youngs_modulus_pa) / 10.0


def defgraspsim_finger_force_n(youngs_modulus_pa: float, mass_kg: float, friction: float) -> float:
    """Force per finger (N) of the defgraspsim protocol: half of FOS * m * g / mu, capped at the hand's."""
    total = factor_of_safety(youngs_modulus_pa) * mass_kg * GRAVITY_MPS2 / friction
    return float(min(total / 2.0, GRIPPER_MAX_FORCE_N))
