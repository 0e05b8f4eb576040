"""A grasp trial's settings: its protocol (sim.protocol.TrialProtocol: what the label means), how the hand moves,
the generator's early stops and the evaluation's, and their stored (flat) form. No PyBullet here: the dataset
cards, the evaluation's command line and the trainer read and compare settings without loading the engine
(importing sim.trial costs ~0.9 s, this module ~0.1 s)."""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from defgg_ros.constants import SHAKE_ACCEL_LIMIT_MPS2, SHAKE_DIRECTIONS
from defgg_ros.sim.protocol import DEFAULT_PROTOCOL, OPTIONAL_SETTING_FIELDS, SETTING_FIELDS, TrialProtocol

# Confident stop (the surrogate): after k >= CONFIDENT_MIN_DIRECTIONS directions, stop when the
# measured mean is CONFIDENT_MARGIN_MPS2 / sqrt(k) from the threshold (k=3: >= 36.5 or <= 13.5;
# k=4: 35/15; k=8: 32.1/17.9). Tuned on the 402 soft trials of datasets fem_v1 + fem_v2 (every
# measured prefix replayed: 0 labels changed, shake steps -33 %), checked on bench/bench_datagen.py's
# naive sample.
CONFIDENT_MIN_DIRECTIONS = 3
CONFIDENT_MARGIN_MPS2 = 20.0


@dataclass(frozen=True)
class TrialMotion:
    """How the hand moves and the trial's clock (the generator's values unless an evaluation changes them)."""
    close_speed_mps: float = 0.1
    close_settle_s: float = 0.1
    settle_before_s: float = 0.02
    lift_height_m: float = 0.03
    lift_time_s: float = 0.6       # 0.3 s let soft grasps that the probe's 0.6 s lift holds fall out
    hold_time_s: float = 0.2
    shake_ramp_time_s: float = 0.5
    twist_ramp_time_s: float = 0.5
    # None: the twist's angular acceleration ramps one way (the hand spins up to 125 rad/s); a value
    # (rad/s): it oscillates at that angular frequency under the ramped amplitude (the evaluation's).
    twist_oscillation_radps: float | None = None
    check_every_s: float = 0.005
    max_cpu_s: float = 900.0
    time_step_s: float | None = None   # None: world.time_step_for(E), the probe's stable steps
    shake_directions: int = SHAKE_DIRECTIONS   # fewer only in tests


@dataclass(frozen=True)
class GeneratorStops:
    """The label's early stops (module docstring): exact ones, and the confident-stop surrogate (fast())."""
    stop_direction_when_lost: bool = True
    stop_when_label_decided: bool = True
    confident_stop: bool = False       # the validated surrogate (_confidently_decided); on in fast()
    confident_min_directions: int = CONFIDENT_MIN_DIRECTIONS
    confident_margin_mps2: float = CONFIDENT_MARGIN_MPS2


@dataclass(frozen=True)
class EvaluationStops:
    """Evaluation tasks (defgg_ros/evaluation): ramp the shake only to shake_limit_mps2, and stop the remaining
    directions/axes once one is held below *_fail_below_* (the task has failed; skipped ones are stored as 0 and
    flagged unmeasured; None = off, the generator's). shake_stop_when_decided: the evaluation under the label's
    rule reports two outcomes, the mean held >= the threshold and "held in every direction": stop the shake once
    both are certain (the mean as in stop_when_label_decided, and a measured direction below the threshold),
    filling the rest as that stop does, and end a direction's ramp once held at the value that decides both
    (shake_outcome_cap; stored as that lower bound, flagged unmeasured). Exact: neither outcome changes."""
    shake_limit_mps2: float = SHAKE_ACCEL_LIMIT_MPS2
    shake_fail_below_mps2: float | None = None
    shake_stop_when_decided: bool = False
    twist_fail_below_radps2: float | None = None


# The stored (flat) form of TrialSettings: every field by name, in the order records have always listed them.
# Records, headers and evaluation keys (jobs.sim_key hashes it) keep this form.
RECORD_FIELDS = (
    "close_speed_mps", "close_settle_s", "settle_before_s", "lift_height_m", "lift_time_s", "hold_time_s",
    "shake_ramp_time_s", "twist_ramp_time_s", "twist_oscillation_radps", "check_every_s",
    "stop_direction_when_lost", "stop_when_label_decided", "confident_stop", "confident_min_directions",
    "confident_margin_mps2", "max_cpu_s", "shake_limit_mps2", "shake_fail_below_mps2", "shake_stop_when_decided",
    "twist_fail_below_radps2", "time_step_s", "shake_directions") + SETTING_FIELDS
# Every name the stored form may hold: RECORD_FIELDS, then the protocol's optional ones (only when they differ).
STORED_FIELDS = RECORD_FIELDS + tuple(OPTIONAL_SETTING_FIELDS)
# A stored settings dict made before a field existed ran with these values (CHANGELOG.md, "Trial settings
# history"); from_record fills them in, so an old dataset or evaluation folder loads, compares and resumes.
PRE_FIELD_VALUES = {"confident_min_directions": 4, "confident_margin_mps2": 40.0, "twist_oscillation_radps": None,
                    "shake_stop_when_decided": False, "protocol": "legacy", "object_friction": None,
                    "poisson_ratio": None, "finger_hold": "force", "grip_force_friction": None}
# A dataset header that recorded only its overrides ("settings", no "trial_settings") ran the generator's
# settings of then: the legacy protocol, the 0.3 s lift and 0.1 s hold, and PRE_FIELD_VALUES.
FIRST_GENERATOR_VALUES = {**PRE_FIELD_VALUES, "lift_time_s": 0.3, "hold_time_s": 0.1}
_GROUPS = {"motion": TrialMotion, "generator": GeneratorStops, "evaluation": EvaluationStops}


@dataclass(frozen=True)
class TrialSettings:
    """Everything a trial runs with: its protocol (what the label means), how the hand moves, the generator's
    early stops and the evaluation's."""
    protocol: TrialProtocol = DEFAULT_PROTOCOL
    motion: TrialMotion = TrialMotion()
    generator: GeneratorStops = GeneratorStops()
    evaluation: EvaluationStops = EvaluationStops()

    def with_fields(self, **flat) -> TrialSettings:
        """These settings with fields changed by their stored names (RECORD_FIELDS); ValueError names an unknown
        one. The protocol's fields (protocol.SETTING_FIELDS) change the protocol."""
        unknown = sorted(set(flat) - set(STORED_FIELDS))
        if unknown:
            raise ValueError(f"unknown trial settings {unknown}; known: {', '.join(STORED_FIELDS)}")
        groups = {}
        for group, cls in _GROUPS.items():
            changed = {k: v for k, v in flat.items() if k in cls.__dataclass_fields__}
            groups[group] = replace(getattr(self, group), **changed)
        protocol = self.protocol
        if any(k in flat for k in (*SETTING_FIELDS, *OPTIONAL_SETTING_FIELDS)):
            protocol = TrialProtocol.from_setting({**self.protocol.to_setting(), **flat})
        return replace(self, protocol=protocol, **groups)

    def to_record(self) -> dict:
        """The stored form (RECORD_FIELDS, then the optional fields that differ from their old value)."""
        flat = {**asdict(self.motion), **asdict(self.generator), **asdict(self.evaluation),
                **self.protocol.to_setting()}
        return {k: flat[k] for k in STORED_FIELDS if k in flat}

    @classmethod
    def from_record(cls, recorded: dict) -> TrialSettings:
        """The settings a stored settings dict (a trial record's, a header's "trial_settings", an evaluation
        record's) describes; fields it predates get the value they had then (PRE_FIELD_VALUES)."""
        return cls().with_fields(**{**PRE_FIELD_VALUES, **recorded})

    @classmethod
    def from_generator_header(cls, generator: dict) -> TrialSettings:
        """The trial settings a dataset header's "generator" section records: its "trial_settings", or, in a
        header that recorded only its overrides ("settings"), those on FIRST_GENERATOR_VALUES."""
        if generator.get("trial_settings"):
            return cls.from_record(generator["trial_settings"])
        return cls.fast().with_fields(**{**FIRST_GENERATOR_VALUES, **generator.get("settings", {})})

    @classmethod
    def naive(cls) -> TrialSettings:
        """The probe's protocol: close 0.4 s, lift 0.8 s, every direction ramps to the end, all 16 run."""
        return cls().with_fields(close_settle_s=0.3, lift_time_s=0.6, hold_time_s=0.2,
                                 stop_direction_when_lost=False, stop_when_label_decided=False)

    @classmethod
    def exact(cls) -> TrialSettings:
        """Only the stops that cannot change the label (no surrogate); the dataclass defaults."""
        return cls()

    @classmethod
    def fast(cls) -> TrialSettings:
        """The generator's protocol: exact stops plus the confident-stop surrogate."""
        return cls().with_fields(confident_stop=True)

    @classmethod
    def legacy(cls) -> TrialSettings:
        """fem_v4's generator settings exactly (the legacy protocol, its confident stop)."""
        return cls.fast().with_fields(protocol="legacy")


def comparable_protocol(recorded: dict) -> dict:
    """A stored settings dict in the form two are compared in (resuming a dataset or an evaluation folder):
    every field, those it predates at the value they had then (TrialSettings.from_record), the surrogate's
    knobs dropped when the surrogate is off."""
    full = TrialSettings.from_record(recorded).to_record()
    if not full["confident_stop"]:
        full.pop("confident_min_directions")
        full.pop("confident_margin_mps2")
    return full


def task_protocol(recorded: dict, task: str) -> dict:
    """comparable_protocol of the settings `task` reads: the other task's own settings (shake_* for the
    twist, twist_* for the shake) drop out, so a new twist ramp does not make a folder's shake trials
    another protocol."""
    other = {"shake": "twist_", "twist": "shake_"}[task]
    return {k: v for k, v in comparable_protocol(recorded).items() if not k.startswith(other)}


def protocol_differences(records, settings: dict, task: str) -> list:
    """The settings (sorted names) in which the first of `records`' `task` trials whose task_protocol
    differs from that of `settings` differs; [] when all match. Records carry their trial_settings."""
    new = task_protocol(settings, task)
    for r in records:
        if r["task"] == task:
            old = task_protocol(r["trial_settings"], task)
            differ = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
            if differ:
                return differ
    return []
