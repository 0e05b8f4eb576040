"""Model grasps (image pixels) -> world-frame grasps for the simulator.

The predictor returns each grasp as a pixel, an image angle (from u towards
v), a width in pixels and the camera-frame point at the centre depth. The
world grasp follows the conventions of the training labels
(``defgg_ros.sim.sampler``): the TCP is the midpoint of the two contacts,
which for the sampled side contacts lies on average at half the object's
height, so the TCP goes to half the height seen at the grasp centre (never
lower than the sampler's fingertip clearance); the label's width in pixels
was measured at the TCP's depth, so the opening is converted back at that
depth and the TCP is put on the pixel's viewing ray at that height; yaw =
direction of the image angle in the world.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.grasping.geometry import tcp_height_m
from defgg_ros.sim.sampler import MIN_WIDTH_M
from defgg_ros.sim.trial import WorldGrasp


@dataclass(frozen=True)
class PlannedGrasp:
    """One of a model's ranked grasps, in the image and in the world."""
    rank: int
    center_u_px: float
    center_v_px: float
    angle_rad: float
    width_px: float
    quality: float
    predicted_width_m: float
    position_m: tuple
    yaw_rad: float
    width_m: float
    mask_label: int = -1                 # part under the grasp centre: 1 = part 0, 2 = part 1, -1 background
    input_modulus_pa: float = 0.0        # stiffness input at the grasp centre

    def world_grasp(self) -> WorldGrasp:
        return WorldGrasp(tuple(self.position_m), self.yaw_rad, self.width_m)

    def to_json(self) -> dict:
        return asdict(self)


def yaw_from_image_angle(angle_rad: float, base_T_camera: np.ndarray) -> float:
    """World yaw of the closing direction for an image angle (from u towards v)."""
    d_camera = np.array([math.cos(angle_rad), math.sin(angle_rad), 0.0])
    d_world = np.asarray(base_T_camera, dtype=float)[:3, :3] @ d_camera
    if math.hypot(d_world[0], d_world[1]) < 1e-6:
        raise ValueError("camera does not look down: image angle has no horizontal direction")
    return float(math.atan2(d_world[1], d_world[0]))


def plan_world_grasp(candidate, rank: int, base_T_camera: np.ndarray, camera_k: np.ndarray,
                     table_top_z_m: float = 0.0) -> PlannedGrasp:
    """A GraspCandidate (defgg_ros.model.inference) -> PlannedGrasp in the world frame."""
    base_T_camera = np.asarray(base_T_camera, dtype=float)
    if base_T_camera.shape != (4, 4) or not np.all(np.isfinite(base_T_camera)):
        raise ValueError(f"base_T_camera must be a finite 4x4 matrix, got shape {base_T_camera.shape}")
    point_camera = np.asarray(candidate.position_camera_m, dtype=float)
    if not np.all(np.isfinite(point_camera)) or point_camera[2] <= 0:
        raise ValueError(f"grasp point {point_camera} is not in front of the camera")
    point_world = base_T_camera[:3, :3] @ point_camera + base_T_camera[:3, 3]
    z_tcp = tcp_height_m(point_world[2], table_top_z_m)
    # The label's pixel is the image of the TCP itself (sampler.grasp_rect), so the TCP lies on the
    # pixel's viewing ray at the TCP height, not below the surface point seen there.
    origin = base_T_camera[:3, 3]
    ray = point_world - origin
    if abs(ray[2]) < 1e-9:
        raise ValueError("viewing ray is horizontal: cannot place a top-down grasp")
    tcp = origin + ray * (z_tcp - origin[2]) / ray[2]
    position = (float(tcp[0]), float(tcp[1]), float(z_tcp))
    # Depth of the TCP along the optical axis: where the label's width in pixels was measured.
    tcp_depth_m = float((np.asarray(position) - base_T_camera[:3, 3]) @ base_T_camera[:3, 2])
    width_m = float(np.clip(candidate.width_px * tcp_depth_m / float(np.asarray(camera_k)[0, 0]),
                            MIN_WIDTH_M, GRIPPER_MAX_WIDTH_M))
    return PlannedGrasp(rank=rank, center_u_px=candidate.center_u_px, center_v_px=candidate.center_v_px,
                        angle_rad=candidate.angle_rad, width_px=candidate.width_px, quality=candidate.quality,
                        predicted_width_m=float(candidate.width_m), position_m=position,
                        yaw_rad=yaw_from_image_angle(candidate.angle_rad, base_T_camera), width_m=width_m,
                        mask_label=int(candidate.object_id), input_modulus_pa=float(candidate.youngs_modulus_pa))
