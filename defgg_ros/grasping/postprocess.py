"""Raw network maps -> filtered grasp maps -> ranked image-space grasps.

Pure numpy/OpenCV; used by the predictor at inference time and by the
validation metric during training, so both rank grasps identically.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from defgg_ros.constants import ANGLE_MAX_RAD, ANGLE_MIN_RAD
from defgg_ros.grasping.config import DEFAULT_POSTPROCESS, PostProcessConfig

# OpenCV's Gaussian kernel for float images reaches 4 sigma from the centre.
_KERNEL_REACH_PX = 4


class GraspMaps:
    """Per-pixel grasp maps of one image (all H x W float32): q in [0, 1], angle_rad in
    [-pi/2, pi/2] from image u towards v, width_px in [0, width_scale_px].

    q_unclipped is the filtered quality before the clip to [0, 1]: the peak search ranks on it.
    The network's quality output is linear, and where it overshoots 1 over a whole object the
    clipped map is one plateau of ties that the search resolved in raster order, i.e. at the
    plateau's top-left edge (the fem_v5 pair: 58-66 % of the evaluation's grasps, 2026-11-28,
    docs/model.md). Clipping is monotone, so ranking on q_unclipped never reverses an order of q.
    q is filtered at once (the peak search reads all of it); the angle and width maps only when
    read, because ranking needs them at a few peaks (at_pixel): ~0.7 ms of a PlanGrasp call.
    """

    def __init__(self, raw: np.ndarray, config: PostProcessConfig):
        self._raw, self._config = raw, config
        self.q_unclipped = _blur(raw[0], config.q_sigma_px).astype(np.float32, copy=False)
        self.q = np.clip(self.q_unclipped, 0.0, 1.0)

    @functools.cached_property
    def angle_rad(self) -> np.ndarray:
        sigma = self._config.angle_sigma_px
        return angle_from_cos_sin(_blur(self._raw[1], sigma), _blur(self._raw[2], sigma))

    @functools.cached_property
    def width_px(self) -> np.ndarray:
        return _width_px(_blur(self._raw[3], self._config.width_sigma_px), self._config)

    def at_pixel(self, v: int, u: int) -> tuple:
        """(angle_rad, width_px) at one pixel, as the full maps have them there."""
        if "angle_rad" in self.__dict__ and "width_px" in self.__dict__:
            return float(self.angle_rad[v, u]), float(self.width_px[v, u])
        c = self._config
        cos2, sin2 = (_blur_at(self._raw[i], v, u, c.angle_sigma_px) for i in (1, 2))
        angle = min(max(0.5 * math.atan2(sin2, cos2), ANGLE_MIN_RAD), ANGLE_MAX_RAD)
        width = min(max(_blur_at(self._raw[3], v, u, c.width_sigma_px), 0.0), 1.0) * c.width_scale_px
        return float(np.float32(angle)), float(np.float32(width))   # the maps' float32 values


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


def _blur_at(image: np.ndarray, v: int, u: int, sigma_px: float) -> float:
    """_blur(image)[v, u] from the window that reaches it, cut with clamped indices (what
    BORDER_REPLICATE does at the edges) and weighted by OpenCV's own kernel: ~10 us, not a map's ~0.2 ms."""
    if sigma_px <= 0:
        return float(image[v, u])
    kernel = _gaussian_kernel(float(sigma_px))
    reach = len(kernel) // 2
    height, width = image.shape
    if reach <= v < height - reach and reach <= u < width - reach:
        window = image[v - reach:v + reach + 1, u - reach:u + reach + 1]
    else:
        rows = np.clip(np.arange(v - reach, v + reach + 1), 0, height - 1)
        cols = np.clip(np.arange(u - reach, u + reach + 1), 0, width - 1)
        window = image[np.ix_(rows, cols)]
    return float(kernel @ window @ kernel)


@functools.lru_cache(maxsize=8)
def _gaussian_kernel(sigma_px: float) -> np.ndarray:
    """The 1-D kernel cv2.GaussianBlur uses for float images with ksize (0, 0): 4 sigma each side."""
    size = int(round(sigma_px * _KERNEL_REACH_PX * 2 + 1)) | 1
    return cv2.getGaussianKernel(size, sigma_px, cv2.CV_32F)[:, 0]


def _width_px(blurred: np.ndarray, config: PostProcessConfig) -> np.ndarray:
    return (np.clip(blurred, 0.0, 1.0) * config.width_scale_px).astype(np.float32)


def angle_from_cos_sin(cos2, sin2) -> np.ndarray:
    """phi = 1/2 atan2(sin 2phi, cos 2phi), in [-pi/2, pi/2]."""
    return np.clip(0.5 * np.arctan2(sin2, cos2), ANGLE_MIN_RAD, ANGLE_MAX_RAD).astype(np.float32)


def maps_from_network(raw: np.ndarray, config: PostProcessConfig = DEFAULT_POSTPROCESS) -> GraspMaps:
    """raw: 4 x H x W network output (q, cos 2phi, sin 2phi, width/scale)."""
    raw = np.asarray(raw, dtype=np.float32)
    if raw.ndim != 3 or raw.shape[0] != 4:
        raise ValueError(f"expected 4 x H x W network output, got {raw.shape}")
    return GraspMaps(raw, config)


def find_peaks(q: np.ndarray, min_distance_px: int, threshold: float, allowed=None, top_k: int = 1,
               fill: bool = False) -> list:
    """Up to top_k (v, u) local maxima of q, best first, at least
    min_distance_px apart (Chebyshev), with q > threshold, on allowed pixels.

    fill: when q has fewer such maxima than top_k (a small object's quality map is often one
    blob), continue with the best remaining pixels that keep min_distance_px from every pick
    (greedy non-maximum suppression), after all the maxima: so the local maxima keep their ranks.
    When no pixel passes the threshold, the best allowed pixel is returned
    alone. Returns [] only when no pixel is allowed.
    """
    if top_k < 1:
        raise ValueError(f"top_k must be >= 1, got {top_k}")
    q = np.asarray(q, dtype=np.float32)
    allowed = np.ones(q.shape, bool) if allowed is None else np.asarray(allowed, bool)
    if allowed.shape != q.shape:
        raise ValueError(f"mask shape {allowed.shape} does not match map shape {q.shape}")
    rows, cols = np.flatnonzero(allowed.any(axis=1)), np.flatnonzero(allowed.any(axis=0))
    if not rows.size:
        return []
    # Only the allowed pixels' bounding box can hold a peak, and everything outside it is -inf (see
    # below): searching the box alone gives the same peaks in the same order, for less work.
    v0, u0 = int(rows[0]), int(cols[0])
    box = np.s_[v0:int(rows[-1]) + 1, u0:int(cols[-1]) + 1]
    peaks = _peaks_in(q[box], allowed[box], min_distance_px, threshold, top_k, fill)
    return [(v + v0, u + u0) for v, u in peaks]


def _peaks_in(q: np.ndarray, allowed: np.ndarray, min_distance_px: int, threshold: float, top_k: int,
              fill: bool) -> list:
    # Masked-out pixels get -inf so they neither win nor suppress neighbours.
    qm = np.where(allowed, q, -np.inf).astype(np.float32)
    size = 2 * int(min_distance_px) + 1
    dilated = cv2.dilate(qm, np.ones((size, size), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
    passes = (qm > threshold) & allowed
    vs, us = np.nonzero((qm == dilated) & passes)
    if vs.size == 0:
        v, u = np.unravel_index(int(np.argmax(qm)), q.shape)
        return [(int(v), int(u))]
    suppressed = np.zeros(q.shape, bool)
    kept = _pick_apart(qm, vs, us, int(min_distance_px), top_k, suppressed)
    if fill and len(kept) < top_k:
        vs, us = np.nonzero(passes & ~suppressed)
        kept += _pick_apart(qm, vs, us, int(min_distance_px), top_k - len(kept), suppressed)
    return kept


def _pick_apart(qm: np.ndarray, vs: np.ndarray, us: np.ndarray, d: int, n: int, suppressed: np.ndarray) -> list:
    """Up to n of the candidate pixels (vs, us), best qm first, each more than d from every earlier
    pick (marked in `suppressed`, updated in place)."""
    order = np.argsort(-qm[vs, us], kind="stable")
    vs, us = vs[order], us[order]
    # Plateaus give several equal maxima (a saturated quality map: thousands): keep them min_distance
    # apart by blanking the square around each kept peak, so each pick is one vectorised look-up.
    kept = []
    while len(kept) < n:
        free = ~suppressed[vs, us]
        if not free.any():
            break
        i = int(np.argmax(free))
        v, u = int(vs[i]), int(us[i])
        kept.append((v, u))
        suppressed[max(0, v - d):v + d + 1, max(0, u - d):u + d + 1] = True
        vs, us = vs[i + 1:], us[i + 1:]
    return kept


def apart(g, others, min_distance_px: int) -> bool:
    """True when grasp g's centre is more than min_distance_px (Chebyshev, as find_peaks) from every other's."""
    return all(max(abs(g.center_u_px - h.center_u_px), abs(g.center_v_px - h.center_v_px)) > min_distance_px
               for h in others)


def grasps_from_maps(maps: GraspMaps, config: PostProcessConfig = DEFAULT_POSTPROCESS,
                     allowed=None, top_k: int = 1, fill: bool = False) -> list:
    """Ranked Grasp2D list from filtered maps (fill: see find_peaks)."""
    peaks = find_peaks(maps.q_unclipped, config.peak_min_distance_px, config.q_threshold, allowed, top_k, fill)
    return [Grasp2D(u, v, *maps.at_pixel(v, u), quality=float(maps.q[v, u])) for v, u in peaks]
