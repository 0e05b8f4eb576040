"""Random crops (shifts), zooms and rotations, identical for all images and labels.

One 2x3 affine matrix per sample maps source pixels to augmented pixels. The
images are warped with it and the grasp rectangles are transformed with it
(centre mapped, angle + rotation, width and finger height x zoom) before the
label maps are drawn, so labels stay exact: no interpolated angles.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from defgg_ros.data.format import GraspRect
from defgg_ros.data.groundtruth import wrap_angle


@dataclass(frozen=True)
class AugmentConfig:
    max_rotation_rad: float = math.pi
    # Zoom stays mild: the depth values are not rescaled, so a strong zoom
    # would teach a wrong pixel-to-metre relation at a given depth.
    zoom_range: tuple = (0.9, 1.1)
    max_shift_px: float = 40.0


def affine_matrix(rotation_rad: float, zoom: float, shift_px, centre_px) -> np.ndarray:
    """2x3 matrix: rotate by rotation_rad (from u towards v) and zoom about
    centre_px, then shift. Source (u, v) -> destination (u', v')."""
    c, s = math.cos(rotation_rad) * zoom, math.sin(rotation_rad) * zoom
    a = np.array([[c, -s], [s, c]])
    centre = np.asarray(centre_px, float)
    t = centre - a @ centre + np.asarray(shift_px, float)
    return np.hstack([a, t[:, None]])


def random_affine(rng: np.random.Generator, config: AugmentConfig, centre_px) -> tuple:
    """(matrix, rotation_rad, zoom)."""
    rotation = rng.uniform(-config.max_rotation_rad, config.max_rotation_rad)
    zoom = rng.uniform(*config.zoom_range)
    shift = rng.uniform(-config.max_shift_px, config.max_shift_px, size=2)
    return affine_matrix(rotation, zoom, shift, centre_px), rotation, zoom


def transform_rect(rect: GraspRect, matrix: np.ndarray, rotation_rad: float, zoom: float) -> GraspRect:
    u, v = matrix @ np.array([rect.center_u_px, rect.center_v_px, 1.0])
    return GraspRect(center_u_px=float(u), center_v_px=float(v),
                     angle_rad=float(wrap_angle(rect.angle_rad + rotation_rad)),
                     width_px=rect.width_px * zoom, finger_height_px=rect.finger_height_px * zoom)


def warp_images(depth_m, youngs_modulus_pa, object_mask, matrix: np.ndarray):
    """Warp (filled) depth linearly, replicating the border (the table
    continues); modulus and mask with nearest neighbour and 0 outside."""
    h, w = depth_m.shape
    depth = cv2.warpAffine(depth_m, matrix, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    nearest = {"flags": cv2.INTER_NEAREST, "borderMode": cv2.BORDER_CONSTANT, "borderValue": 0}
    moduli = cv2.warpAffine(youngs_modulus_pa.astype(np.float32), matrix, (w, h), **nearest)
    mask = cv2.warpAffine(object_mask.astype(np.uint8), matrix, (w, h), **nearest)
    return depth, moduli, mask


def augment_sample(depth_m, youngs_modulus_pa, object_mask, rects, rng, config: AugmentConfig):
    """Apply one random transform to images and rectangles (depth must have no holes)."""
    h, w = depth_m.shape
    matrix, rotation, zoom = random_affine(rng, config, ((w - 1) / 2.0, (h - 1) / 2.0))
    depth, moduli, mask = warp_images(depth_m, youngs_modulus_pa, object_mask, matrix)
    return depth, moduli, mask, [transform_rect(r, matrix, rotation, zoom) for r in rects]
