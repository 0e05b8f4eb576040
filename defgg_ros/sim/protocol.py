"""The trial protocol as one value: what a grasp trial does to the object and what its label means
(docs/dataset.md, "Trial protocols"). The generator, the evaluation, the dataset and model cards and the
checkpoints carry it; the trial (sim/trial.py) asks it instead of branching on a name.

legacy: fem_v1-v4's. Gravity on, grip force 2 N + 0.5 N per decade of E a finger, lifted 3 cm, fingers
force-held, lost when both fingers let go or the centroid moved 20 mm in the hand. defgraspsim: the protocol of
the paper's labels (NVlabs/DefGraspSim). Zero gravity once the object has settled, total grip force
FOS * m * g / mu with FOS = 1 + log10(E) / 10, the table moved away for the pickup, fingers held after it
(finger_hold), lost as soon as either finger has no contact. Both label a grasp positive when the held shake
acceleration averaged over 16 directions (each ramped to 50 m/s^2) reaches 25 m/s^2; a failed lift is negative.

Both close the hand with a speed drive (finger_drive "speed": fem_v1-v5's labels), which presses an FEM body with
~1 N whatever force it is given; finger_drive "press" closes as the cell's hand and franka_gripper do
(sim/finger_press.py: on the object each finger pushes with the force).

Stored form: records, headers and checkpoints keep a protocol as the flat setting
{"protocol", "object_friction", "poisson_ratio", "finger_hold", "grip_force_friction"} (None: the named
protocol's own), plus "finger_drive" when it is not "speed" (so the stored form, and the keys made from it, of
everything run before the field stay as they were); from_setting / to_setting convert (a setting without a name
is legacy: it predates the field).
No PyBullet here.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from defgg_ros.constants import GRAVITY_MPS2, SHAKE_ACCEL_LIMIT_MPS2, SHAKE_DIRECTIONS, SHAKE_POSITIVE_THRESHOLD_MPS2
from defgg_ros.grip_force import LabelGripRule, defgraspsim_finger_force_n, grasp_force_n
from defgg_ros.sim.material import MATERIALS, Material

LEGACY, DEFGRASPSIM = "legacy", "defgraspsim"
FINGER_HOLDS = ("force", "lock")
FINGER_DRIVES = ("speed", "press")      # module docstring; "speed" is what every setting without the field ran
GRIP_FORCE_RULES = ("per_decade", "weight_over_friction")   # legacy's 2 N + 0.5 N/decade; FOS*m*g/mu
LOSS_RULES = ("both_fingers_or_20mm", "either_finger")
PICKUPS = ("lift", "table_away")
LOSS_DISTANCE_M = 0.02          # both_fingers_or_20mm: the object moved this far in the hand = no longer held
LABEL_RULE = (f"positive when the held shake acceleration averaged over {SHAKE_DIRECTIONS} directions (each ramped "
              f"to {SHAKE_ACCEL_LIMIT_MPS2:g} m/s^2) reaches {SHAKE_POSITIVE_THRESHOLD_MPS2:g} m/s^2; a failed lift is "
              "negative")
# The fields of the stored form, in the order records have always listed them; OPTIONAL_SETTING_FIELDS appear only
# when they differ from the value they had before they existed.
SETTING_FIELDS = ("protocol", "object_friction", "poisson_ratio", "finger_hold", "grip_force_friction")
OPTIONAL_SETTING_FIELDS = {"finger_drive": "speed"}


@dataclass(frozen=True)
class TrialProtocol:
    name: str
    gravity_during_tests: bool    # False: zero gravity from the squeeze on
    pickup: str                   # PICKUPS: lift the hand, or move the table away (the hand stays)
    grip_force_rule: str          # GRIP_FORCE_RULES
    # FINGER_HOLDS (defgraspsim): "force", each finger keeps pushing with F/2 (it keeps the squeeze DefGraspSim's
    # locked joints keep); "lock", DefGraspSim's joint lock, soft objects only. PyBullet's soft-rigid contact
    # stores no penetration force, so a locked finger keeps only what the object's own compression pushes back:
    # 90 % of F/2 at 2e4 Pa, ~50 % at 2e5, 0 at 2e6 Pa on box_small (bench/bench_finger_lock.py).
    finger_hold: str
    loss_rule: str                # LOSS_RULES
    material: Material
    # weight_over_friction: the mu the rule divides by; None: the contact's effective friction (DefGraspSim's
    # rule: mu * F = FOS * m * g). A value above the contact's squeezes as if it were grippier (pilot b).
    grip_force_friction: float | None = None
    finger_drive: str = "speed"   # FINGER_DRIVES (module docstring)
    label_rule: str = LABEL_RULE

    def __post_init__(self):
        if self.name not in PROTOCOLS_BY_NAME_ORDER:
            raise ValueError(f"unknown trial protocol {self.name!r}; known: {', '.join(PROTOCOLS_BY_NAME_ORDER)}")
        if self.finger_hold not in FINGER_HOLDS:
            raise ValueError(f"finger_hold must be one of {', '.join(FINGER_HOLDS)}, got {self.finger_hold!r}")
        if self.finger_drive not in FINGER_DRIVES:
            raise ValueError(f"finger_drive must be one of {', '.join(FINGER_DRIVES)}, got {self.finger_drive!r}")
        if self.grip_force_friction is not None and not 0.0 < self.grip_force_friction <= 2.0:
            raise ValueError(f"grip_force_friction must be in (0, 2], got {self.grip_force_friction}")
        for value, known in ((self.pickup, PICKUPS), (self.grip_force_rule, GRIP_FORCE_RULES),
                             (self.loss_rule, LOSS_RULES)):
            if value not in known:
                raise ValueError(f"{value!r} is none of {', '.join(known)}")

    # --- what the trial asks ---------------------------------------------------------------------------
    def test_gravity_mps2(self) -> np.ndarray:
        """Gravity from the squeeze on (the shake adds its acceleration to it)."""
        return np.array([0.0, 0.0, -GRAVITY_MPS2]) if self.gravity_during_tests else np.zeros(3)

    def grip_force_mu(self) -> float:
        """The mu of the weight_over_friction rule: its own friction, else the contact's."""
        return self.grip_force_friction or self.material.effective_friction

    def finger_force_n(self, softest_modulus_pa: float, mass_kg: float) -> float:
        """The force each finger closes with on an object of this (softest part's) E and mass."""
        if self.grip_force_rule == "per_decade":
            return grasp_force_n(softest_modulus_pa)
        return defgraspsim_finger_force_n(softest_modulus_pa, mass_kg, self.grip_force_mu())

    def locks_fingers(self, all_parts_soft: bool) -> bool:
        """Lock the finger joints after the pickup: finger_hold "lock" (defgraspsim), on soft objects only. A rigid
        body stores no elastic squeeze: between locked fingers it kept ~1e-4 N and slid off (an artefact), so the
        rigid stand-in stays held with F/2 (bench/bench_finger_lock.py)."""
        return self.finger_hold == "lock" and self.pickup == "table_away" and all_parts_soft   # legacy: force-held

    def held(self, contacts_per_finger, moved_in_hand_m) -> bool:
        """Still held: either_finger needs a contact on both fingers; both_fingers_or_20mm a contact on one and
        the object within LOSS_DISTANCE_M of where the pickup left it in the hand (moved_in_hand_m(): metres,
        only asked when needed)."""
        contacts = np.asarray(contacts_per_finger)
        if self.loss_rule == "either_finger":
            return bool(np.all(contacts > 0))
        return bool(contacts.any()) and moved_in_hand_m() < LOSS_DISTANCE_M

    # --- what cards and checkpoints carry ----------------------------------------------------------------
    def label_grip_rule(self) -> LabelGripRule:
        """The grip rule of the labels this protocol makes (grip_force.LabelGripRule: the executor closes with it)."""
        if self.grip_force_rule == "per_decade":
            return LabelGripRule()
        return LabelGripRule(self.name, float(self.grip_force_mu()))

    def to_setting(self) -> dict:
        """The stored form: the name and what differs from the named protocol (None: its own)."""
        base = PROTOCOLS[self.name]
        own = {"object_friction": self.material.object_friction, "poisson_ratio": self.material.poisson_ratio,
               "finger_hold": self.finger_hold, "grip_force_friction": self.grip_force_friction}
        differs = {"object_friction": own["object_friction"] != base.material.object_friction,
                   "poisson_ratio": own["poisson_ratio"] != base.material.poisson_ratio}
        stored = {"protocol": self.name,
                  "object_friction": own["object_friction"] if differs["object_friction"] else None,
                  "poisson_ratio": own["poisson_ratio"] if differs["poisson_ratio"] else None,
                  "finger_hold": own["finger_hold"], "grip_force_friction": own["grip_force_friction"]}
        if self.finger_drive != OPTIONAL_SETTING_FIELDS["finger_drive"]:
            stored["finger_drive"] = self.finger_drive
        return stored

    @classmethod
    def from_setting(cls, setting: dict) -> TrialProtocol:
        """The protocol a stored setting (or a whole stored settings dict) names; a setting without a name is
        legacy (it predates the field), other fields it lacks are the named protocol's own."""
        name = setting.get("protocol") or LEGACY
        if name not in PROTOCOLS:
            raise ValueError(f"unknown trial protocol {name!r}; known: {', '.join(PROTOCOLS)}")
        protocol = PROTOCOLS[name]
        material = protocol.material
        if setting.get("object_friction") is not None:
            material = replace(material, object_friction=float(setting["object_friction"]))
        if setting.get("poisson_ratio") is not None:
            material = replace(material, poisson_ratio=float(setting["poisson_ratio"]))
        return replace(protocol, material=material, finger_hold=setting.get("finger_hold") or protocol.finger_hold,
                       grip_force_friction=setting.get("grip_force_friction"),
                       finger_drive=setting.get("finger_drive") or OPTIONAL_SETTING_FIELDS["finger_drive"])

    def summary(self) -> str:
        """One line naming the protocol's rules, friction and material (dataset cards, evaluation reports)."""
        nu = self.material.poisson_ratio
        nu_text = f"nu {nu}" if nu is not None else "nu of the object (0.4)"
        if self.name == DEFGRASPSIM:
            hold = ("locked after it (soft bodies; the rigid stand-in held with F/2)"
                    if self.finger_hold == "lock" else "held with F/2 each after it")
            mu = self.grip_force_friction
            force_mu = f" with mu {mu} (not the contact's)" if mu else ""
            rule = (f"**defgraspsim** (zero gravity after settling, grip force FOS*m*g/mu{force_mu} split over the "
                    f"fingers, table moved away for the pickup, fingers {hold}, lost when either finger has no "
                    "contact)")
        else:
            rule = ("**legacy** (gravity on, 2 N + 0.5 N per decade a finger, fingers force-held, lost when both "
                    "fingers let go or the centroid moved 20 mm)")
        if self.finger_drive == "press":
            rule += " with the pressing hand (each finger pushes with its force on the object, as the cell's)"
        return f"{rule}, effective friction {self.material.effective_friction:.2f}, Neo-Hookean FEM, {nu_text}"


PROTOCOLS_BY_NAME_ORDER = (LEGACY, DEFGRASPSIM)
PROTOCOLS = {
    LEGACY: TrialProtocol(LEGACY, gravity_during_tests=True, pickup="lift", grip_force_rule="per_decade",
                          finger_hold="force", loss_rule="both_fingers_or_20mm", material=MATERIALS[LEGACY]),
    DEFGRASPSIM: TrialProtocol(DEFGRASPSIM, gravity_during_tests=False, pickup="table_away",
                               grip_force_rule="weight_over_friction", finger_hold="force", loss_rule="either_finger",
                               material=MATERIALS[DEFGRASPSIM]),
}
# The protocol of new datasets and evaluations (and of the shipped weights' labels, datasets/fem_v5).
DEFAULT_PROTOCOL = PROTOCOLS[DEFGRASPSIM]


def resolve_protocol(requested: str | None = None, recorded: dict | None = None,
                     dataset_setting: dict | None = None) -> TrialProtocol:
    """The one resolver of a run's protocol (defgg-datagen, defgg-eval run and ceiling): a dataset's own setting
    (--protocol-from) wins; else the protocol named on the command line; else the one the folder being resumed
    recorded (a stored settings dict; without a name: legacy); else DEFAULT_PROTOCOL."""
    if dataset_setting is not None:
        return TrialProtocol.from_setting(dataset_setting)
    if requested is not None:
        return TrialProtocol.from_setting({"protocol": requested})
    if recorded is not None:
        return TrialProtocol.from_setting(recorded)
    return DEFAULT_PROTOCOL
