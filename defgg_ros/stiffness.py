"""The one stiffness encoding: Young's modulus (Pa) -> network input in [0, 1].

Log scale, because the paper's moduli span five decades (2e4..2e9 Pa) and
grasp behaviour changes per decade, not per pascal. Objects map into
[STIFFNESS_OBJECT_MIN, 1] and background pixels (modulus 0) to
STIFFNESS_BACKGROUND, so "no object" never looks like "very soft object".
Moduli outside [YOUNGS_MODULUS_MIN_PA, YOUNGS_MODULUS_MAX_PA] are clipped.
"""
import numpy as np

from defgg_ros.constants import (
    STIFFNESS_BACKGROUND,
    STIFFNESS_OBJECT_MIN,
    YOUNGS_MODULUS_MAX_PA,
    YOUNGS_MODULUS_MIN_PA,
)

ENCODING_NAME = "log10_clip_v1"
_LOG_MIN = np.log10(YOUNGS_MODULUS_MIN_PA)
_LOG_MAX = np.log10(YOUNGS_MODULUS_MAX_PA)


class InvalidYoungsModulus(ValueError):
    """A modulus that is not a finite positive number of pascals."""


def check_youngs_modulus(youngs_modulus_pa) -> float:
    """Return E as float, or raise InvalidYoungsModulus with the reason."""
    try:
        value = float(youngs_modulus_pa)
    except (TypeError, ValueError) as exc:
        raise InvalidYoungsModulus(f"Young's modulus must be a number, got {youngs_modulus_pa!r}") from exc
    if not np.isfinite(value) or value <= 0.0:
        raise InvalidYoungsModulus(f"Young's modulus must be finite and > 0 Pa, got {value!r}")
    return value


def encode_youngs_modulus(youngs_modulus_pa: float) -> float:
    """Encode one modulus of an object (must be finite and > 0)."""
    value = check_youngs_modulus(youngs_modulus_pa)
    t = (np.log10(value) - _LOG_MIN) / (_LOG_MAX - _LOG_MIN)
    return float(STIFFNESS_OBJECT_MIN + (1.0 - STIFFNESS_OBJECT_MIN) * np.clip(t, 0.0, 1.0))


def decode_stiffness(encoded: float) -> float:
    """Inverse of encode_youngs_modulus for object values (for display/logs)."""
    t = (float(encoded) - STIFFNESS_OBJECT_MIN) / (1.0 - STIFFNESS_OBJECT_MIN)
    return float(10.0 ** (_LOG_MIN + np.clip(t, 0.0, 1.0) * (_LOG_MAX - _LOG_MIN)))


def check_modulus_image(youngs_modulus_pa_image: np.ndarray, what: str = "stiffness image") -> None:
    """Raise InvalidYoungsModulus when a per-pixel modulus image has NaN, infinite or negative pixels.

    One min and one max (NaN propagates through both) instead of element-wise masks: a 640x480
    image is checked on every PlanGrasp call."""
    image = np.asarray(youngs_modulus_pa_image)
    if image.size == 0:
        return
    low, high = image.min(), image.max()
    if np.isnan(low) or np.isnan(high) or np.isinf(high) or low == -np.inf:
        raise InvalidYoungsModulus(f"{what} contains NaN or infinite moduli")
    if low < 0:
        raise InvalidYoungsModulus(f"{what} contains negative moduli")


def encode_stiffness_image(youngs_modulus_pa_image: np.ndarray) -> np.ndarray:
    """Encode a per-pixel modulus image (Pa; 0 = background) to float32.

    Raises InvalidYoungsModulus for negative, NaN or infinite pixels.
    """
    image = np.asarray(youngs_modulus_pa_image, dtype=np.float64)
    check_modulus_image(image)
    out = np.full(image.shape, STIFFNESS_BACKGROUND, dtype=np.float32)
    obj = image > 0.0
    if np.any(obj):
        t = (np.log10(image[obj]) - _LOG_MIN) / (_LOG_MAX - _LOG_MIN)
        out[obj] = STIFFNESS_OBJECT_MIN + (1.0 - STIFFNESS_OBJECT_MIN) * np.clip(t, 0.0, 1.0)
    return out
