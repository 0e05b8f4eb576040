"""Pinhole geometry between image pixels and the camera optical frame.

Optical frame: x along image u (right), y along image v (down), z forward.
"""
from __future__ import annotations

import numpy as np

from defgg_ros.constants import (
    GRASP_HEIGHT_FRACTION,
    PALM_CLEARANCE_M,
    PANDA_FINGER_LENGTH_M,
    PANDA_FINGERTIP_BELOW_TCP_M,
    TABLE_CLEARANCE_M,
)
from defgg_ros.errors import InvalidInputError


class InvalidCameraError(InvalidInputError):
    """Camera intrinsics that are not a finite 3x3 pinhole matrix."""


def check_camera_k(camera_k) -> np.ndarray:
    k = np.asarray(camera_k, dtype=np.float64)
    if k.shape == (9,):
        k = k.reshape(3, 3)
    if k.shape != (3, 3):
        raise InvalidCameraError(f"camera_k must be 3x3, got shape {k.shape}")
    if not np.all(np.isfinite(k)):
        raise InvalidCameraError("camera_k contains NaN or infinite values")
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        raise InvalidCameraError(f"focal lengths must be > 0, got fx={k[0, 0]}, fy={k[1, 1]}")
    return k


def width_px_to_m(width_px, depth_m, fx_px):
    """Length of an image segment of `width_px` pixels at `depth_m` (fronto-parallel)."""
    return np.asarray(width_px) * np.asarray(depth_m) / fx_px


def width_m_to_px(width_m, depth_m, fx_px):
    return np.asarray(width_m) * fx_px / np.asarray(depth_m)


def pixel_to_camera(u_px, v_px, depth_m, camera_k) -> np.ndarray:
    """3D point (m) in the optical frame of pixel (u, v) at depth z."""
    k = check_camera_k(camera_k)
    x = (u_px - k[0, 2]) * depth_m / k[0, 0]
    y = (v_px - k[1, 2]) * depth_m / k[1, 1]
    return np.array([x, y, depth_m], dtype=np.float64)


def tcp_height_m(surface_z_m: float, table_top_z_m: float = 0.0) -> float:
    """TCP height for a top-down grasp whose centre pixel sees the surface at surface_z_m: the rule the
    evaluation executes grasps with (evaluation.planning.plan_world_grasp) and "executor"-height
    candidates are sampled at: GRASP_HEIGHT_FRACTION of the height seen there, fingertips above the
    table, and high enough that the palm clears that surface (on an object taller than the fingers' reach
    below the palm, twice: the half-height rule put the palm into ycb_bottle's top). (The cell's executor node
    goes its grasp_depth_below_surface_m parameter below the surface.)"""
    lowest = table_top_z_m + PANDA_FINGERTIP_BELOW_TCP_M + TABLE_CLEARANCE_M
    palm_clear = surface_z_m - palm_above_tcp_m() + PALM_CLEARANCE_M
    return float(max(table_top_z_m + GRASP_HEIGHT_FRACTION * (surface_z_m - table_top_z_m), lowest, palm_clear))


def palm_above_tcp_m() -> float:
    """Height of the palm's underside above the TCP (the fingers' length minus the fingertip's offset below it)."""
    return PANDA_FINGER_LENGTH_M - PANDA_FINGERTIP_BELOW_TCP_M
