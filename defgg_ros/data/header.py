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
