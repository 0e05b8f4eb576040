"""Depth images in either ROS unit convention -> float32 metres (no rclpy).

ROS cameras publish depth as 16UC1 millimetres (realsense, 0 = invalid) or
32FC1 metres (REP 118; NaN/+-Inf = invalid). Everything downstream works in
float32 metres with NaN for invalid pixels, so the two conventions cannot
be mixed up later. The plausibility rule (perception/plausibility.py) catches metres written
into 16UC1 (values 0..2), millimetres in 32FC1 and byte-swapped 16UC1 (is_bigendian mismatch).
"""
import numpy as np

from defgg_ros.perception.plausibility import MILLIMETRES_PER_METRE, ImplausibleDepth, check_depth_plausible

DEPTH_ENCODINGS_MM = ("16UC1", "mono16")
DEPTH_ENCODINGS_M = ("32FC1",)


class DepthError(ValueError):
    """A depth image that cannot be used (empty, no valid pixel, wrong unit...)."""


def depth_to_metres(raw: np.ndarray, encoding: str) -> np.ndarray:
    """Convert a raw HxW depth array in `encoding` to float32 metres, NaN = invalid.

    Raises DepthError for an empty/non-2D image, no valid pixel, an unknown
    encoding, or values whose magnitude shows the wrong unit.
    """
    array = np.asarray(raw)
    if array.ndim != 2 or array.size == 0:
        raise DepthError(f"depth must be a non-empty HxW image, got shape {array.shape}")
    if encoding in DEPTH_ENCODINGS_MM:
        depth_m = _from_millimetres(array)
    elif encoding in DEPTH_ENCODINGS_M:
        depth_m = _from_metres(array)
    else:
        raise DepthError(f"depth encoding must be one of {DEPTH_ENCODINGS_MM + DEPTH_ENCODINGS_M}, got {encoding!r}")
    return depth_m


def _from_millimetres(array: np.ndarray) -> np.ndarray:
    if not np.issubdtype(array.dtype, np.integer):
        raise DepthError(f"16UC1 depth must hold integers (mm), got dtype {array.dtype}")
    valid = array > 0
    if not np.any(valid):
        raise DepthError("depth image has no valid pixel (all zero)")
    _check_plausible(array, "16UC1", _valid_median(array, valid) / MILLIMETRES_PER_METRE)
    depth_m = array.astype(np.float32) / np.float32(MILLIMETRES_PER_METRE)
    depth_m[~valid] = np.nan
    return depth_m


def _from_metres(array: np.ndarray) -> np.ndarray:
    if not np.issubdtype(array.dtype, np.floating):
        raise DepthError(f"32FC1 depth must hold floats (m), got dtype {array.dtype}")
    depth_m = array.astype(np.float32, copy=True)
    valid = np.isfinite(depth_m) & (depth_m > 0)
    if not np.any(valid):
        raise DepthError("depth image has no valid pixel (all NaN, Inf or <= 0)")
    _check_plausible(array, "32FC1", _valid_median(depth_m, valid))
    depth_m[~valid] = np.nan
    return depth_m


# The plausibility median is read from every n-th pixel of a larger frame: it looks for gross errors (units,
# byte order), and the full median of a 1280x720 frame costs ~2 ms per frame (the node's profile at 30 Hz).
MEDIAN_SAMPLE_STRIDE = 4
MEDIAN_FULL_BELOW_PX = 200_000


def _valid_median(values: np.ndarray, valid: np.ndarray) -> float:
    if values.size >= MEDIAN_FULL_BELOW_PX and values.ndim == 2:
        sample, sample_valid = values[::MEDIAN_SAMPLE_STRIDE, ::MEDIAN_SAMPLE_STRIDE], \
            valid[::MEDIAN_SAMPLE_STRIDE, ::MEDIAN_SAMPLE_STRIDE]
        if np.count_nonzero(sample_valid) >= 1000:
            return float(np.median(sample[sample_valid]))
    return float(np.median(values[valid]))


def _check_plausible(array: np.ndarray, encoding: str, median_m: float) -> None:
    try:
        check_depth_plausible(array, encoding, median_m)
    except ImplausibleDepth as exc:
        raise DepthError(str(exc)) from exc


def metres_to_millimetres_u16(depth_m: np.ndarray) -> np.ndarray:
    """float metres (NaN/<=0 invalid) -> uint16 millimetres (0 invalid), rounded."""
    depth = np.asarray(depth_m, dtype=np.float64)
    valid = np.isfinite(depth) & (depth > 0)
    out = np.zeros(depth.shape, dtype=np.uint16)
    mm = np.rint(depth[valid] * MILLIMETRES_PER_METRE)
    if mm.size and mm.max() > np.iinfo(np.uint16).max:
        raise DepthError(f"depth {mm.max() / MILLIMETRES_PER_METRE:.1f} m does not fit 16-bit millimetres")
    out[valid] = mm.astype(np.uint16)
    return out
