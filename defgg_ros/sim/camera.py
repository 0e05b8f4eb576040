"""Top-down virtual depth camera: PyBullet's TinyRenderer with known intrinsics.

The camera looks straight down from CAMERA_HEIGHT_ABOVE_TABLE_M, optical
frame x = world x, y = -world y, z = -world z, so a scene rendered at
300x300 equals a centred 300x300 crop of the cell's 640x480 camera (same
fx, same height). Soft bodies appear in both the depth buffer and the
segmentation mask (checked in test/sim/test_camera.py). TinyRenderer costs
~70 ms per 640x480 frame: render on demand, not at 30 fps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p

from defgg_ros.constants import (
    CAMERA_FAR_M,
    CAMERA_FX_PX,
    CAMERA_FY_PX,
    CAMERA_HEIGHT_ABOVE_TABLE_M,
    CAMERA_NEAR_M,
    NETWORK_INPUT_SIZE_PX,
)
from defgg_ros.sim import physics


@dataclass(frozen=True)
class TopDownCamera:
    width_px: int = NETWORK_INPUT_SIZE_PX
    height_px: int = NETWORK_INPUT_SIZE_PX
    fx_px: float = CAMERA_FX_PX
    fy_px: float = CAMERA_FY_PX
    centre_xy_m: tuple = (0.0, 0.0)
    height_above_table_m: float = CAMERA_HEIGHT_ABOVE_TABLE_M
    table_top_z_m: float = 0.0

    @property
    def k(self) -> np.ndarray:
        """3x3 intrinsics; principal point at the image centre."""
        return np.array([[self.fx_px, 0, self.width_px / 2], [0, self.fy_px, self.height_px / 2], [0, 0, 1.0]])

    @property
    def base_T_camera(self) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, :3] = np.diag([1.0, -1.0, -1.0])
        pose[:3, 3] = [*self.centre_xy_m, self.table_top_z_m + self.height_above_table_m]
        return pose

    def world_to_pixel(self, xyz_m) -> np.ndarray:
        """(N,3) world points -> (N,2) pixel (u, v) and their depth along the optical axis."""
        pts = np.atleast_2d(np.asarray(xyz_m, dtype=float))
        cam = (pts - self.base_T_camera[:3, 3]) @ self.base_T_camera[:3, :3]
        uv = cam[:, :2] / cam[:, 2:3] * [self.fx_px, self.fy_px] + [self.width_px / 2, self.height_px / 2]
        return uv

    def pixel_to_world(self, uv_px, depth_m) -> np.ndarray:
        uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
        z = np.broadcast_to(np.asarray(depth_m, dtype=float), (len(uv),))
        cam = np.c_[(uv[:, 0] - self.width_px / 2) / self.fx_px * z, (uv[:, 1] - self.height_px / 2) / self.fy_px * z,
                    z]
        return cam @ self.base_T_camera[:3, :3].T + self.base_T_camera[:3, 3]

    def metres_to_pixels(self, length_m: float, depth_m: float) -> float:
        return length_m * self.fx_px / depth_m

    def render(self, client: int):
        """Return (depth_m float32 HxW, segmentation int32 HxW as PyBullet's body+link code)."""
        eye = self.base_T_camera[:3, 3]
        target = [eye[0], eye[1], self.table_top_z_m]
        view = p.computeViewMatrix(eye.tolist(), target, [0, 1, 0], physicsClientId=client)
        fov_deg = math.degrees(2 * math.atan(self.height_px / 2 / self.fy_px))
        proj = p.computeProjectionMatrixFOV(fov_deg, self.width_px / self.height_px * self.fy_px / self.fx_px,
                                            CAMERA_NEAR_M, CAMERA_FAR_M, physicsClientId=client)
        _, _, _, depth_buf, seg = p.getCameraImage(
            self.width_px, self.height_px, view, proj, renderer=p.ER_TINY_RENDERER,
            flags=p.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX, physicsClientId=client)
        d = np.asarray(depth_buf, dtype=np.float64).reshape(self.height_px, self.width_px)
        depth = physics.depth_from_buffer_m(d, CAMERA_NEAR_M, CAMERA_FAR_M)
        return depth.astype(np.float32), np.asarray(seg, dtype=np.int64).reshape(self.height_px, self.width_px)


def split_segmentation(seg) -> tuple:
    """PyBullet's combined code -> (body id, link index) arrays; background body is -1."""
    seg = np.asarray(seg, dtype=np.int64)
    body = np.where(seg >= 0, seg & ((1 << 24) - 1), -1)
    link = np.where(seg >= 0, (seg >> 24) - 1, -1)
    return body, link


def render_object_images(client: int, loaded, camera: TopDownCamera | None = None) -> dict:
    """Depth (m), per-pixel Young's modulus (Pa, 0 = background) and part mask (0 bg, 1.. parts)."""
    camera = camera or TopDownCamera()
    depth, seg = camera.render(client)
    body, link = split_segmentation(seg)
    modulus = np.zeros(depth.shape, dtype=np.float32)
    mask = np.zeros(depth.shape, dtype=np.uint8)
    for i, part in enumerate(loaded.parts):
        hit = body == part.body_id
        if not part.soft:
            hit &= link == part.link_index
        modulus[hit] = part.youngs_modulus_pa
        mask[hit] = i + 1
    return {"depth_m": depth, "youngs_modulus_pa": modulus, "object_mask": mask,
            "camera_k": camera.k, "base_T_camera": camera.base_T_camera}
