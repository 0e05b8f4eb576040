"""What a dataset header (dataset.json's "generator") says about how its labels were made.

Shared by the generator (datagen) and the card (card), which must not import each other.
"""
from __future__ import annotations

from defgg_ros.sim.protocol import TrialProtocol
from defgg_ros.sim.trial_settings import TrialSettings


def effective_trial_settings(overrides: dict) -> dict:
    """Every stored field of the generator's settings (TrialSettings.fast()) with these overrides."""
    return TrialSettings.fast().with_fields(**overrides).to_record()


def recorded_trial_settings(generator: dict) -> TrialSettings:
    """The trial settings a dataset header's generator section records (TrialSettings.from_generator_header);
    a synthetic dataset's header names a string: the default settings."""
    return TrialSettings.from_generator_header(generator if isinstance(generator, dict) else {})


def recorded_protocol(generator: dict) -> TrialProtocol:
    """The trial protocol a dataset header records (a header without one: legacy)."""
    return recorded_trial_settings(generator).protocol


def recorded_grasp_height(generator: dict) -> str:
    """The candidates' height rule a dataset header's generator settings record (a header without one: its
    candidates sat at the contacts' height)."""
    return generator.get("grasp_height", "contacts")


def protocol_summary(settings: dict) -> str:
    """One line naming a stored protocol setting's rules, friction and material (dataset cards, evaluation
    reports)."""
    return TrialProtocol.from_setting(settings).summary()


def label_grip_rule(generator: dict) -> dict:
    """The grip force rule of a dataset's labels (grip_force.LabelGripRule's meta form): legacy, or
    defgraspsim with the friction its force used (as the trials did)."""
    generator = generator if isinstance(generator, dict) else {}     # synthetic datasets name a string
    return recorded_protocol(generator).label_grip_rule().to_meta()
