"""Analytic depth images of a table with boxes and cylinders (no rclpy).

For tests and benchmarks of the perception path without PyBullet: each
pixel's ray is intersected with the table plane, the object footprints are
looked up at that table point, and the depth is the ray parameter at which
the surface is raised by the object's height along the plane normal. Side
walls are not modelled (a top-down view barely sees them).
"""
from dataclasses import dataclass, field

import numpy as np

from defgg_ros.constants import (
    CAMERA_FX_PX,
    CAMERA_FY_PX,
    CAMERA_HEIGHT_ABOVE_TABLE_M,
    CAMERA_HEIGHT_PX,
    CAMERA_WIDTH_PX,
)


def default_camera_k(width_px: int = CAMERA_WIDTH_PX, height_px: int = CAMERA_HEIGHT_PX) -> np.ndarray:
    """The cell camera's K: fx = fy = CAMERA_F*_PX, principal point at the image centre."""
    return np.array([[CAMERA_FX_PX, 0.0, (width_px - 1) / 2.0],
                     [0.0, CAMERA_FY_PX, (height_px - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class SceneObject:
    """A box (radius_m = 0) or a cylinder on the table; centre in table-plane metres."""

    center_xy_m: tuple[float, float]
    height_m: float
    size_xy_m: tuple[float, float] = (0.04, 0.04)
    yaw_rad: float = 0.0
    radius_m: float = 0.0

    def footprint(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        dx, dy = x_m - self.center_xy_m[0], y_m - self.center_xy_m[1]
        if self.radius_m > 0:
            return dx * dx + dy * dy <= self.radius_m ** 2
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        along, across = c * dx + s * dy, -s * dx + c * dy
        return (np.abs(along) <= self.size_xy_m[0] / 2) & (np.abs(across) <= self.size_xy_m[1] / 2)


@dataclass(frozen=True)
class SyntheticScene:
    objects: tuple[SceneObject, ...]
    # Table plane tilt about the camera x and y axes (a camera not mounted
    # perpendicular to the table); 0 = straight down.
    tilt_xy_rad: tuple[float, float] = (0.0, 0.0)
    table_distance_m: float = CAMERA_HEIGHT_ABOVE_TABLE_M
    width_px: int = CAMERA_WIDTH_PX
    height_px: int = CAMERA_HEIGHT_PX
    camera_k: np.ndarray = field(default_factory=default_camera_k)


def render(scene: SyntheticScene) -> tuple[np.ndarray, np.ndarray]:
    """(depth float32 metres, ground-truth labels uint8 with object i -> i + 1)."""
    k = scene.camera_k
    u = np.arange(scene.width_px, dtype=np.float64)[None, :]
    v = np.arange(scene.height_px, dtype=np.float64)[:, None]
    ray_x = np.broadcast_to((u - k[0, 2]) / k[0, 0], (scene.height_px, scene.width_px))
    ray_y = np.broadcast_to((v - k[1, 2]) / k[1, 1], (scene.height_px, scene.width_px))
    ax, ay = scene.tilt_xy_rad
    # Unit normal of the table towards the camera: -z tilted about x then y.
    normal = np.array([np.sin(ay), -np.sin(ax) * np.cos(ay), -np.cos(ax) * np.cos(ay)])
    # n . p + d = 0 at the table point on the optical axis.
    offset = -normal @ np.array([0.0, 0.0, scene.table_distance_m])
    n_dot_ray = normal[0] * ray_x + normal[1] * ray_y + normal[2]
    table_z = -offset / n_dot_ray
    table_x, table_y = ray_x * table_z, ray_y * table_z
    height = np.zeros((scene.height_px, scene.width_px))
    labels = np.zeros((scene.height_px, scene.width_px), dtype=np.uint8)
    for index, obj in enumerate(scene.objects, start=1):
        inside = obj.footprint(table_x, table_y) & (obj.height_m > height)
        height[inside] = obj.height_m
        labels[inside] = index
    depth = (height - offset) / n_dot_ray
    return depth.astype(np.float32), labels
