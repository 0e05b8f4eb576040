"""Grip force rules of the trial protocols (pure arithmetic; docs/dataset.md, "Trial protocols").

Below the cores: the trials (sim.trial) label with these forces; a model's weights record which rule made
their labels (LabelGripRule) and the cell grasps with that rule (the inference node computes the force,
control.gripper_rule applies it), so none of them has to import another.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

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


class GripRuleError(ValueError):
    """A label grip rule, mass or modulus the rule cannot work with."""


LABEL_GRIP_PROTOCOLS = ("legacy", "defgraspsim")


@dataclass(frozen=True)
class LabelGripRule:
    """How hard the fingers squeezed in a model's training labels (the weights' meta "label_grip_rule").

    A grasp quality is the probability that the grasp holds when closed with the labels' force, so the
    executor should close with it. legacy: grasp_force_n(E), nothing else needed. defgraspsim: half of
    FOS * m * g / friction, so the object's mass must be known (the cell estimates it: perception).
    Weights trained before the rule was recorded are legacy (from_meta).
    """

    protocol: str = "legacy"
    friction: float | None = None      # defgraspsim: the mu of FOS*m*g/mu

    def __post_init__(self):
        if self.protocol not in LABEL_GRIP_PROTOCOLS:
            raise GripRuleError(f"unknown label grip protocol {self.protocol!r}; known: "
                                f"{', '.join(LABEL_GRIP_PROTOCOLS)}")
        if self.protocol == "defgraspsim" and not (
                isinstance(self.friction, (int, float)) and math.isfinite(self.friction) and self.friction > 0):
            raise GripRuleError(f"the defgraspsim grip rule needs a friction > 0, got {self.friction!r}")

    @property
    def needs_mass(self) -> bool:
        return self.protocol == "defgraspsim"

    def finger_force_n(self, youngs_modulus_pa: float, mass_kg: float | None = None) -> float:
        """The labels' force per finger (N) for an object of modulus E (its softest part) and mass."""
        e = float(youngs_modulus_pa)
        if not (math.isfinite(e) and e > 0):
            raise GripRuleError(f"Young's modulus must be a positive number of Pa, got {youngs_modulus_pa!r}")
        if not self.needs_mass:
            return grasp_force_n(e)
        if mass_kg is None or not (math.isfinite(mass_kg) and mass_kg > 0):
            raise GripRuleError(f"the defgraspsim grip rule needs the object's mass, got {mass_kg!r}")
        return defgraspsim_finger_force_n(e, float(mass_kg), float(self.friction))

    def grasp_finger_force_n(self, youngs_modulus_pa: float, mass_kg: float) -> float:
        """The force a Grasp message carries (Grasp.finger_force_n): the labels' force where the rule needs a
        mass and one is known; 0 otherwise (the legacy rule, or no mass: the executor's force of the modulus)."""
        return self.finger_force_n(youngs_modulus_pa, mass_kg) if self.needs_mass and mass_kg > 0 else 0.0

    def to_meta(self) -> dict:
        return {"protocol": self.protocol, "friction": self.friction}

    @classmethod
    def from_meta(cls, meta: dict | None) -> LabelGripRule:
        """The rule a checkpoint's meta records ("label_grip_rule"); legacy when it records none."""
        rule = (meta or {}).get("label_grip_rule")
        if rule is None:
            return cls()
        if not isinstance(rule, dict):
            raise GripRuleError(f"label_grip_rule must be a mapping, got {type(rule).__name__}")
        return cls(rule.get("protocol", "legacy"), rule.get("friction"))
