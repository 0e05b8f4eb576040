"""Network inputs from raw images: ONE code path for training and inference.

Depth: invalid pixels (0, NaN, inf, negative) are inpainted from their
neighbours (OpenCV Navier-Stokes, as GG-CNN does for real depth holes), then
the crop mean is subtracted and the result clipped to [-1, 1] m. Subtracting
the mean makes the input independent of the camera height; the clip keeps a
far-away outlier from dominating. Stiffness: `defgg_ros.stiffness`.
"""
from __future__ import annotations

import cv2
import numpy as np

from defgg_ros.constants import NETWORK_INPUT_SIZE_PX
from defgg_ros.errors import InvalidInputError  # defined below the cores; model callers find it here too
from defgg_ros.stiffness import ENCODING_NAME as STIFFNESS_ENCODING_NAME
from defgg_ros.stiffness import encode_stiffness_image

DEPTH_ENCODING_NAME = "inpaint_ns_minus_mean_clip1m_v1"
DEPTH_CLIP_M = 1.0
_INPAINT_RADIUS_PX = 1

__all__ = [
    "DEPTH_ENCODING_NAME", "STIFFNESS_ENCODING_NAME", "InvalidInputError", "InvalidDepthError",
    "invalid_depth_mask", "inpaint_depth", "encode_depth", "network_input", "crop_origin", "crop",
]


class InvalidDepthError(InvalidInputError):
    """A depth image with the wrong shape/type or without any valid pixel."""


def check_depth_image(depth_m) -> np.ndarray:
    depth = np.asarray(depth_m)
    if depth.ndim != 2:
        raise InvalidDepthError(f"depth must be a 2-D HxW image in metres, got shape {depth.shape}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise InvalidDepthError(f"depth must be float metres, got dtype {depth.dtype}")
    return depth.astype(np.float32, copy=False)


def invalid_depth_mask(depth_m: np.ndarray) -> np.ndarray:
    """True where depth carries no measurement (0, negative, NaN, inf)."""
    return ~np.isfinite(depth_m) | (depth_m <= 0.0)


def inpaint_depth(depth_m) -> np.ndarray:
    """Return a float32 copy with invalid pixels filled from valid neighbours.

    Raises InvalidDepthError when no pixel is valid (nothing to fill from).
    """
    depth = check_depth_image(depth_m)
    invalid = invalid_depth_mask(depth)
    if not invalid.any():
        return depth.copy()
    if invalid.all():
        raise InvalidDepthError("depth image has no valid pixel (all 0/NaN/inf/negative)")
    filled = np.where(invalid, 0.0, depth).astype(np.float32)
    # Inpaint works best on values of order 1; scale by the max and back.
    scale = float(filled.max())
    out = cv2.inpaint(filled / scale, invalid.astype(np.uint8), _INPAINT_RADIUS_PX, cv2.INPAINT_NS)
    return (out * scale).astype(np.float32)


def encode_depth(depth_m) -> np.ndarray:
    """Depth (m, may contain holes) -> network channel (float32, [-1, 1])."""
    depth = inpaint_depth(depth_m)
    return np.clip(depth - depth.mean(dtype=np.float64), -DEPTH_CLIP_M, DEPTH_CLIP_M).astype(np.float32)


def network_input(depth_m, youngs_modulus_pa, uses_stiffness: bool) -> np.ndarray:
    """C x H x W float32: encoded depth (+ encoded stiffness when used).

    The modulus image is validated even for a depth-only network, so bad
    input fails the same way for both variants.
    """
    depth = encode_depth(depth_m)
    stiffness = encode_stiffness_image(youngs_modulus_pa)
    if stiffness.shape != depth.shape:
        raise InvalidInputError(f"stiffness image {stiffness.shape} does not match depth {depth.shape}")
    if uses_stiffness:
        return np.stack([depth, stiffness])
    return depth[None]


def crop_origin(image_shape, mask=None, size_px: int = NETWORK_INPUT_SIZE_PX) -> tuple:
    """(u0, v0) of a size x size window: centred on the mask's bounding box
    (nonzero pixels) when given and non-empty, else on the image centre;
    clamped so the window stays inside the image."""
    height, width = image_shape[:2]
    if height < size_px or width < size_px:
        raise InvalidInputError(f"image {width}x{height} is smaller than the {size_px}x{size_px} network input")
    cu, cv = width / 2.0, height / 2.0
    if mask is not None:
        rows, cols = np.flatnonzero(np.any(mask, axis=1)), np.flatnonzero(np.any(mask, axis=0))
        if cols.size:   # the bounding box from row/column projections: ~10x cheaper than np.nonzero
            cu, cv = (cols[0] + cols[-1] + 1) / 2.0, (rows[0] + rows[-1] + 1) / 2.0
    u0 = int(np.clip(round(cu - size_px / 2.0), 0, width - size_px))
    v0 = int(np.clip(round(cv - size_px / 2.0), 0, height - size_px))
    return u0, v0


def crop(image: np.ndarray, origin: tuple, size_px: int = NETWORK_INPUT_SIZE_PX) -> np.ndarray:
    u0, v0 = origin
    return image[v0:v0 + size_px, u0:u0 + size_px]
