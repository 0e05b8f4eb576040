"""What a dataset header (dataset.json's "generator") says about how its labels were made.

Shared by the generator (datagen) and the card (card), which must not import each other.
"""
from __future__ import annotations

from dataclasses import asdict, replace


def effective_trial_settings(overrides: dict, legacy: bool = False) -> dict:
    """Every TrialSettings field of the generator's protocol with these overrides (legacy: the
    pre-2026-11-24 lift, the pre-2026-11-25 confident stop and the pre-2026-11-26 protocol)."""
    from defgg_ros.sim.trial import (
        LEGACY_CONFIDENT_SETTINGS,
        LEGACY_LIFT_SETTINGS,
        LEGACY_PROTOCOL_SETTINGS,
        TrialSettings,
    )

    base = TrialSettings.fast()
    if legacy:
        base = replace(base, **LEGACY_LIFT_SETTINGS, **LEGACY_CONFIDENT_SETTINGS, **LEGACY_PROTOCOL_SETTINGS)
    return asdict(replace(base, **overrides))


def recorded_grasp_height(generator: dict) -> str:
    """The candidates' height rule a dataset header's generator settings record (headers before
    2026-11-26 lack it: their candidates sat at the contacts' height)."""
    return generator.get("grasp_height", "contacts")


def recorded_protocol(generator: dict) -> str:
    """The trial protocol a dataset header records (headers before 2026-11-26 lack it: legacy)."""
    return (generator.get("trial_settings") or {}).get("protocol", "legacy")


def _trial_settings(settings: dict):
    """sim.trial.TrialSettings of recorded settings (fields it does not know are dropped)."""
    from defgg_ros.sim.trial import TrialSettings

    return TrialSettings(**{k: v for k, v in settings.items() if k in TrialSettings.__dataclass_fields__})


def protocol_summary(settings: dict) -> str:
    """One line naming a recorded protocol's rules, friction and material (dataset cards, evaluation reports)."""
    from defgg_ros.sim.trial import PROTOCOL_DEFGRASPSIM

    material = _trial_settings(settings).material()
    nu = material["poisson_ratio"]
    nu_text = f"nu {nu}" if nu is not None else "nu of the object (0.4)"
    if settings["protocol"] == PROTOCOL_DEFGRASPSIM:
        hold = ("locked after it (soft bodies; the rigid stand-in held with F/2)"
                if settings.get("finger_hold") == "lock" else "held with F/2 each after it")
        mu = settings.get("grip_force_friction")
        force_mu = f" with mu {mu} (not the contact's)" if mu else ""
        rule = (f"**defgraspsim** (zero gravity after settling, grip force FOS*m*g/mu{force_mu} split over the "
                f"fingers, table moved away for the pickup, fingers {hold}, lost when either finger has no contact)")
    else:
        rule = ("**legacy** (gravity on, 2 N + 0.5 N per decade a finger, fingers force-held, lost when both fingers "
                "let go or the centroid moved 20 mm)")
    return f"{rule}, effective friction {material['effective_friction']:.2f}, Neo-Hookean FEM, {nu_text}"


def label_grip_rule(generator: dict) -> dict:
    """The grip force rule of a dataset's labels (grip_force.LabelGripRule's meta form): legacy, or
    defgraspsim with the friction its force used (TrialSettings.grip_force_mu, as the trials did)."""
    from defgg_ros.grip_force import LabelGripRule
    from defgg_ros.sim.trial import PROTOCOL_DEFGRASPSIM

    generator = generator if isinstance(generator, dict) else {}     # synthetic datasets name a string
    if recorded_protocol(generator) != PROTOCOL_DEFGRASPSIM:
        return LabelGripRule().to_meta()
    mu = _trial_settings(generator.get("trial_settings") or {}).grip_force_mu()
    return LabelGripRule(PROTOCOL_DEFGRASPSIM, float(mu)).to_meta()
