"""Post-processing constants in one place (grasp maps -> ranked grasps).

GG-CNN's filters (sigma 2 px on Q and angle, 1 px on width) with our own peak rules: peaks at least 10 px
apart on a 300 px map (GG-CNN: 20), no Q threshold (GG-CNN: 0.2, no grasp below it) and no border exclusion, so
the network's best pixel is always returned with its quality. The values used in training-time validation and at
inference, so both score the same grasps (a little more leniently than GG-CNN's own detection would).
"""
from __future__ import annotations

from dataclasses import dataclass

from defgg_ros.constants import WIDTH_SCALE_PX


@dataclass(frozen=True)
class PostProcessConfig:
    q_sigma_px: float = 2.0
    # Applied to the cos 2phi / sin 2phi maps before atan2 (filtering an angle
    # map directly would average +89 deg and -89 deg into 0 deg).
    angle_sigma_px: float = 2.0
    width_sigma_px: float = 1.0
    peak_min_distance_px: int = 10
    # Local maxima must have Q strictly above this. When no pixel passes, the
    # best allowed pixel is still returned with its (low) quality, so callers
    # always see the network's best guess and can judge it by `quality`.
    q_threshold: float = 0.0
    width_scale_px: float = WIDTH_SCALE_PX

    def __post_init__(self):
        for name in ("q_sigma_px", "angle_sigma_px", "width_sigma_px"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0")
        if self.peak_min_distance_px < 1:
            raise ValueError("peak_min_distance_px must be >= 1")


DEFAULT_POSTPROCESS = PostProcessConfig()
