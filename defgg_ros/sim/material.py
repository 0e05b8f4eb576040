"""The materials a grasp trial's object and pads are made of (no PyBullet here: dataset cards, the evaluation's
reports and the trial protocol read them without loading the engine; the physics core applies them)."""
from __future__ import annotations

from dataclasses import dataclass

# Every body's own friction coefficient unless a material says otherwise (the tables, the bin, legacy pads).
DEFAULT_FRICTION = 0.8


@dataclass(frozen=True)
class Material:
    """How a trial's object and the pads meet: each body's own friction (Bullet multiplies the two in a contact)
    and Poisson's ratio (None: the object's own, constants.POISSON_RATIO)."""
    finger_friction: float
    object_friction: float
    poisson_ratio: float | None

    def __post_init__(self):
        if not 0.0 < self.object_friction <= 2.0:
            raise ValueError(f"object_friction must be in (0, 2], got {self.object_friction}")
        if self.poisson_ratio is not None and not 0.0 <= self.poisson_ratio < 0.5:
            raise ValueError(f"poisson_ratio must be in [0, 0.5), got {self.poisson_ratio}")

    @property
    def effective_friction(self) -> float:
        return self.finger_friction * self.object_friction

    def facts(self) -> dict:
        """finger_friction, object_friction, effective_friction (their product) and poisson_ratio (as recorded
        per trial)."""
        return {"finger_friction": self.finger_friction, "object_friction": self.object_friction,
                "poisson_ratio": self.poisson_ratio, "effective_friction": self.effective_friction}


# legacy: fem_v1-v4's; defgraspsim: DefGraspSim's (mu 0.7, nu 0.3), the pads at 1.0 so the contact's coefficient
# is the object's.
MATERIALS = {
    "legacy": Material(DEFAULT_FRICTION, DEFAULT_FRICTION, None),
    "defgraspsim": Material(1.0, 0.7, 0.3),
}
