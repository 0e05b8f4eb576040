"""A stereo depth camera's noise as a property of the camera (no rclpy).

    noise = DepthNoiseModel.for_camera("d415")          # or DepthNoiseModel(baseline_m, subpixel_rms_px)
    sigma_m = noise.sigma_m(z_m, fx_px)                  # depth RMS error at distance z

Intel's D400 formula: depth RMS error = z^2 * subpixel / (fx * baseline) (docs/perception.md, "Depth noise as a
camera property", for the sources and each model's figures). The grasp search's free-space test allows three of
it on object surfaces (planning/tabletop_grasps.FreeSpace). `measured_from_table_rms_m` turns a frame's own table
residuals into a model (an unknown camera, or one whose noise differs from its datasheet's).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Intel's typical subpixel RMS of the D4 vision processor on a well-textured surface (every D400 model).
TYPICAL_SUBPIXEL_RMS_PX = 0.08
# Stereo baselines of the RealSense models (Intel's D400 series datasheet).
REALSENSE_BASELINES_M = {"d405": 0.018, "d415": 0.055, "d435": 0.050, "d435i": 0.050, "d455": 0.095}
# A measured noise is never taken below this share of the quantisation's RMS (1 mm steps: 0.29 mm).
QUANTISATION_STEP_M = 0.001


@dataclass(frozen=True)
class DepthNoiseModel:
    """sigma_z = z^2 * subpixel_rms_px / (fx * baseline_m)."""
    baseline_m: float = REALSENSE_BASELINES_M["d435"]
    subpixel_rms_px: float = TYPICAL_SUBPIXEL_RMS_PX

    def __post_init__(self):
        if not (math.isfinite(self.baseline_m) and self.baseline_m > 0
                and math.isfinite(self.subpixel_rms_px) and self.subpixel_rms_px >= 0):
            raise ValueError(f"depth noise needs baseline_m > 0 and subpixel_rms_px >= 0, got {self}")

    @classmethod
    def for_camera(cls, model: str, subpixel_rms_px: float = TYPICAL_SUBPIXEL_RMS_PX) -> DepthNoiseModel:
        key = str(model).strip().lower().replace("-", "").replace("_", "")
        if key not in REALSENSE_BASELINES_M:
            raise ValueError(f"unknown camera model {model!r}: one of {sorted(REALSENSE_BASELINES_M)}")
        return cls(REALSENSE_BASELINES_M[key], subpixel_rms_px)

    def sigma_m(self, z_m, fx_px: float):
        """Depth RMS error (m) at distance z_m (scalar or array) for a camera of focal length fx_px."""
        z = np.asarray(z_m, dtype=np.float64) if np.ndim(z_m) else float(z_m)
        return z * z * self.subpixel_rms_px / (float(fx_px) * self.baseline_m)

    def measured(self, residual_rms_m: float, at_z_m: float, fx_px: float) -> DepthNoiseModel:
        """The same baseline with the subpixel RMS that gives residual_rms_m at at_z_m (a frame's table)."""
        rms = max(float(residual_rms_m), QUANTISATION_STEP_M / math.sqrt(12.0))
        return DepthNoiseModel(self.baseline_m, rms * float(fx_px) * self.baseline_m / (float(at_z_m) ** 2))


def robust_rms_m(residuals_m) -> float:
    """The RMS of the bulk of a sample of residuals (1.4826 x the median absolute deviation): objects and
    warps at the table's edges do not count."""
    r = np.asarray(residuals_m, dtype=np.float64).reshape(-1)
    r = r[np.isfinite(r)]
    if r.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(r - np.median(r))))
