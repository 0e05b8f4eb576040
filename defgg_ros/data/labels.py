"""Which trials are positive training examples: the paper's rule and a stricter one.

"mean" (the paper's, the default): the mean held acceleration over the 16 shake directions is
>= SHAKE_POSITIVE_THRESHOLD_MPS2 (TrialRecord.label). "every_direction": that, and no measured
direction held less, which is the evaluation's shake-task criterion under the legacy protocol (every
direction must hold the threshold; under defgraspsim the evaluation's second table). Directions the
generator skipped once the label was decided are not known, so the strict rule only removes positives
that were seen to slip; it is an experiment (docs/archive/notes_v2.md), not the paper's protocol.
"""
from __future__ import annotations

import numpy as np

from defgg_ros.constants import CAMERA_HEIGHT_ABOVE_TABLE_M, SHAKE_POSITIVE_THRESHOLD_MPS2
from defgg_ros.grasping.geometry import tcp_height_m

LABEL_RULES = ("mean", "every_direction")


def slips_in_a_direction(trial) -> bool:
    """A measured shake direction held less than the threshold (skipped directions do not count)."""
    accels = trial.shake_accels_mps2
    if accels is None:
        return False
    measured = (trial.sim or {}).get("shake_measured") or [True] * len(accels)
    return any(m and a < SHAKE_POSITIVE_THRESHOLD_MPS2 for a, m in zip(accels, measured))


def measured_mean_mps2(accels, measured=None) -> float:
    """Mean held shake acceleration over the directions really measured (the generator imputes the
    others once the label is decided, which piles recorded means up at the threshold); 0 without any
    (a failed lift)."""
    if not accels:
        return 0.0
    values = [a for a, m in zip(accels, measured or [True] * len(accels)) if m]
    return float(sum(values) / len(values)) if values else 0.0


def check_label_rule(rule: str) -> str:
    if rule not in LABEL_RULES:
        raise ValueError(f"label rule must be one of {LABEL_RULES}, got {rule!r}")
    return rule


def is_positive(trial, rule: str = "mean") -> bool:
    check_label_rule(rule)
    return trial.label is True and (rule == "mean" or not slips_in_a_direction(trial))


def height_offset_m(trial, scene_depth_m: np.ndarray) -> float:
    """The trial's TCP height minus the height the executor would grasp at on the same pixel.

    The sampler puts each candidate at its own contacts' height, but an image-space grasp has no
    height: the evaluation's executor derives it from the depth at the centre pixel (tcp_height_m). The scene's
    camera looks straight down from CAMERA_HEIGHT_ABOVE_TABLE_M above the table (z = 0).
    """
    h, w = scene_depth_m.shape
    u = int(np.clip(round(trial.rect.center_u_px), 0, w - 1))
    v = int(np.clip(round(trial.rect.center_v_px), 0, h - 1))
    surface_z_m = CAMERA_HEIGHT_ABOVE_TABLE_M - float(scene_depth_m[v, u])
    return float(trial.position_m[2]) - tcp_height_m(surface_z_m)
