"""Raw network maps -> filtered grasp maps -> ranked image-space grasps.

Pure numpy/OpenCV; used by the predictor at inference time and by the
validation metric during training, so both rank grasps identically.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from defgg_ros.constants import ANGLE_MAX_RAD, ANGLE_MIN_RAD
from defgg_ros.grasping.config import DEFAULT_POSTPROCESS, PostProcessConfig


@dataclass(frozen=True)
class GraspMaps:
    """Per-pixel grasp maps of one image (all H x W float32)."""

    q: np.ndarray          # quality in [0, 1]
    angle_rad: np.ndarray  # in [-pi/2, pi/2], from image u towards v
    width_px: np.ndarray   # finger opening in pixels, in [0, width_scale_px]


@dataclass(frozen=True)
class Grasp2D:
    """A grasp in map (network crop) pixel coordinates."""

    center_u_px: int
    center_v_px: int
    angle_rad: float
    width_px: float
    quality: float


def _blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    if sigma_px <= 0:
        return image
    return cv2.GaussianBlur(image, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REPLICATE)


def angle_from_cos_sin(cos2, sin2) -> np.ndarray:
    """phi = 1/2 atan2(sin 2phi, cos 2phi), in [-pi/2, pi/2]."""
    return np.clip(0.5 * np.arctan2(sin2, cos2), ANGLE_MIN_RAD, ANGLE_MAX_RAD).astype(np.float32)


def maps_from_network(raw: np.ndarray, config: PostProcessConfig = DEFAULT_POSTPROCESS) -> GraspMaps:
    """raw: 4 x H x W network output (q, cos 2phi, sin 2phi, width/scale)."""
    raw = np.asarray(raw, dtype=np.float32)
    if raw.ndim != 3 or raw.shape[0] != 4:
        raise ValueError(f"expected 4 x H x W network output, got {raw.shape}")
    q = np.clip(_blur(raw[0], config.q_sigma_px), 0.0, 1.0)
    angle = angle_from_cos_sin(_blur(raw[1], config.angle_sigma_px), _blur(raw[2], config.angle_sigma_px))
    width = np.clip(_blur(raw[3], config.width_sigma_px), 0.0, 1.0) * config.width_scale_px
    return GraspMaps(q=q, angle_rad=angle, width_px=width.astype(np.float32))


def find_peaks(q: np.ndarray, min_distance_px: int, threshold: float, allowed=None, top_k: int = 1) -> list:
    """Up to top_k (v, u) local maxima of q, best first, at least
    min_distance_px apart (Chebyshev), with q > threshold, on allowed pixels.

    When no pixel passes the threshold, the best allowed pixel is returned
    alone. Returns [] only when no pixel is allowed.
    """
    if top_k < 1:
        raise ValueError(f"top_k must be >= 1, got {top_k}")
    q = np.asarray(q, dtype=np.float32)
    allowed = np.ones(q.shape, bool) if allowed is None else np.asarray(allowed, bool)
    if allowed.shape != q.shape:
        raise ValueError(f"mask shape {allowed.shape} does not match map shape {q.shape}")
    if not allowed.any():
        return []
    # Masked-out pixels get -inf so they neither win nor suppress neighbours.
    qm = np.where(allowed, q, -np.inf).astype(np.float32)
    size = 2 * int(min_distance_px) + 1
    dilated = cv2.dilate(qm, np.ones((size, size), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
    vs, us = np.nonzero((qm == dilated) & (qm > threshold) & allowed)
    if vs.size == 0:
        v, u = np.unravel_index(int(np.argmax(qm)), q.shape)
        return [(int(v), int(u))]
    order = np.argsort(-qm[vs, us], kind="stable")
    vs, us = vs[order], us[order]
    # Plateaus give several equal maxima (a saturated quality map: thousands): keep them min_distance
    # apart by blanking the square around each kept peak, so each pick is one vectorised look-up.
    d = int(min_distance_px)
    suppressed = np.zeros(q.shape, bool)
    kept = []
    while len(kept) < top_k:
        free = ~suppressed[vs, us]
        if not free.any():
            break
        i = int(np.argmax(free))
        v, u = int(vs[i]), int(us[i])
        kept.append((v, u))
        suppressed[max(0, v - d):v + d + 1, max(0, u - d):u + d + 1] = True
        vs, us = vs[i + 1:], us[i + 1:]
    return kept


def grasps_from_maps(maps: GraspMaps, config: PostProcessConfig = DEFAULT_POSTPROCESS,
                     allowed=None, top_k: int = 1) -> list:
    """Ranked Grasp2D list from filtered maps."""
    peaks = find_peaks(maps.q, config.peak_min_distance_px, config.q_threshold, allowed, top_k)
    return [Grasp2D(center_u_px=u, center_v_px=v, angle_rad=float(maps.angle_rad[v, u]),
                    width_px=float(maps.width_px[v, u]), quality=float(maps.q[v, u])) for v, u in peaks]
