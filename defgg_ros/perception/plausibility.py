"""Plausibility of the cell's input values: ONE rule set for every entry (no rclpy).

Every depth image (subscribed topics, PlanGrasp requests, both encodings) goes through
`check_depth_plausible` (called by perception/depth.py's converter), and every Young's modulus
(SetStiffness entries and defaults, stiffness images on topics and in PlanGrasp requests, arrays
given to the predictor) through `check_moduli_plausible`. So a value refused at one entry is
refused at all of them, with the same message.

Depth. A median beyond the camera's range (CAMERA_FAR_M) is not a scene this cell can grasp in;
the message names the likely cause, found by trying the usual mistakes:
- 16UC1 with its two bytes swapped (little-endian data flagged `is_bigendian=1`, or big-endian
  data flagged 0): a 0.45 m table (450 = 0x01C2) reads 0xC201 = 49.7 m; swapping back gives a
  median inside the range;
- a unit mistake: millimetres in 32FC1 (0.4 m reads 400), or 16UC1 in 0.1 mm / micrometre units.
A median below CAMERA_NEAR_M in 16UC1 is metres written as integers (0..2).

Moduli. Outside [1 Pa, 1.2e12 Pa] a value is a unit mistake, not a material: softer than any gel or
stiffer than diamond (~1.2e12 Pa). Background pixels of a stiffness image are 0.
"""
import numpy as np

from defgg_ros.constants import CAMERA_FAR_M, CAMERA_NEAR_M
from defgg_ros.stiffness import InvalidYoungsModulus

PLAUSIBLE_YOUNGS_MODULUS_MIN_PA = 1.0
PLAUSIBLE_YOUNGS_MODULUS_MAX_PA = 1.2e12
MILLIMETRES_PER_METRE = 1000.0


class ImplausibleDepth(ValueError):
    """Depth whose values cannot be this scene's distances (byte order, unit)."""


def plausible_range_text() -> str:
    return f"[{PLAUSIBLE_YOUNGS_MODULUS_MIN_PA:g}, {PLAUSIBLE_YOUNGS_MODULUS_MAX_PA:g}] Pa"


def check_depth_plausible(raw: np.ndarray, encoding: str, median_m: float) -> None:
    """Raise ImplausibleDepth when the valid pixels' median (in metres, as read) is outside the
    camera's range; the message names the likely cause. raw: the array as decoded (uint16 mm or
    float32 m), used to test the byte-swap hypothesis."""
    if encoding == "32FC1":
        if median_m > CAMERA_FAR_M:
            cause = ("the values look like millimetres; send metres in 32FC1 or millimetres in 16UC1"
                     if CAMERA_NEAR_M <= median_m / MILLIMETRES_PER_METRE <= CAMERA_FAR_M
                     else "no unit makes it a table scene")
            raise ImplausibleDepth(f"32FC1 depth median is {median_m:.1f} m, far beyond the camera's "
                                   f"{CAMERA_FAR_M} m range: {cause}")
        return
    median_mm = median_m * MILLIMETRES_PER_METRE
    if median_mm < CAMERA_NEAR_M * MILLIMETRES_PER_METRE:
        raise ImplausibleDepth(
            f"16UC1 depth median is {median_mm:.0f}, below the camera's near limit of "
            f"{CAMERA_NEAR_M * MILLIMETRES_PER_METRE:.0f} mm: the values look like metres; "
            "send millimetres in 16UC1 or metres in 32FC1")
    if median_m <= CAMERA_FAR_M:
        return
    array = np.asarray(raw)
    swapped = array.byteswap()
    swapped_valid = swapped[swapped > 0]
    swapped_median_m = float(np.median(swapped_valid)) / MILLIMETRES_PER_METRE if swapped_valid.size else np.inf
    if CAMERA_NEAR_M <= swapped_median_m <= CAMERA_FAR_M:
        cause = (f"the byte order is wrong: swapped, the median would be {swapped_median_m:.3f} m; check the "
                 "image's is_bigendian flag against the data (ROS depth is little-endian, is_bigendian=0)")
    elif CAMERA_NEAR_M <= median_m / 10.0 <= CAMERA_FAR_M:
        cause = "the unit looks like 0.1 mm (RealSense depth_units 0.0001); send millimetres in 16UC1"
    else:
        cause = "wrong byte order (is_bigendian) or unit; 16UC1 depth is little-endian millimetres"
    raise ImplausibleDepth(f"16UC1 depth median is {median_m:.1f} m, far beyond the camera's {CAMERA_FAR_M} m "
                           f"range: {cause}")


def check_moduli_plausible(youngs_modulus_pa, what: str = "stiffness image", background_allowed: bool = True):
    """Raise InvalidYoungsModulus unless every value is finite and either 0 (background, when
    allowed) or inside the plausible range. Scalars and images alike; two reductions per image."""
    values = np.asarray(youngs_modulus_pa)
    if values.size == 0:
        return
    if not np.issubdtype(values.dtype, np.number) or values.dtype == bool:
        raise InvalidYoungsModulus(f"{what} must be numeric, got dtype {values.dtype}")
    low, high = values.min(), values.max()
    if np.isnan(low) or np.isnan(high) or np.isinf(high) or low == -np.inf:
        raise InvalidYoungsModulus(f"{what} contains NaN or infinite moduli (must be finite Pa)")
    if low < 0:
        raise InvalidYoungsModulus(f"{what} contains negative moduli (min {float(low):g} Pa)")
    if low == 0 and not background_allowed:
        raise InvalidYoungsModulus(f"{what} must be > 0 Pa, got 0")
    if high > PLAUSIBLE_YOUNGS_MODULUS_MAX_PA:
        raise InvalidYoungsModulus(f"{what} holds {float(high):g} Pa, outside the plausible range "
                                   f"{plausible_range_text()} (wrong unit?)")
    if low < PLAUSIBLE_YOUNGS_MODULUS_MIN_PA:
        positive_min = float(values[values > 0].min()) if high > 0 else float(low)
        if positive_min < PLAUSIBLE_YOUNGS_MODULUS_MIN_PA and (positive_min > 0 or not background_allowed):
            raise InvalidYoungsModulus(f"{what} holds {positive_min:g} Pa, outside the plausible range "
                                       f"{plausible_range_text()} (wrong unit?)")
