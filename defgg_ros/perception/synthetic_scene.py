"""Analytic depth images of a table with boxes and cylinders (no rclpy).

For tests and benchmarks of the perception path without PyBullet: each
pixel's ray is intersected with the table plane and with each object: with
`walls`, a prism standing on the table (its top at the object's height, its
walls along the optical axis), so objects away from the image centre show
their walls like real ones; without, the original top-only approximation.
perception/tabletop_scenes.py renders full scenes (any camera pose, RealSense noise).
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
    # True: objects are prisms with walls along the optical axis (what a camera sees of real boxes).
    # False (the original images many tests were written for): the top is drawn where the table point
    # behind it lies in the footprint, no walls: a frustum leaning away from the image centre.
    walls: bool = False


def render(scene: SyntheticScene) -> tuple[np.ndarray, np.ndarray]:
    """(depth float32 metres, ground-truth labels uint8 with object i -> i + 1).

    With scene.walls, each object is a prism standing on the table, its walls along the camera's optical axis (for a
    camera square to the table: vertical walls, as real boxes and cans have). A pixel's ray meets the
    object's top where the ray's point at the top's height lies in the footprint, else a wall where
    the ray, between the top's height and the table, first enters the footprint (the parameter
    s in [0, 1] along that segment, found on a fine grid): away from the optical axis the camera
    sees the walls, and the top is where it really is in 3D. Without (the default, the images the
    older tests were written for), the top is drawn where the table point behind it is in the
    footprint and there are no walls.
    """
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
    depth = -offset / n_dot_ray
    labels = np.zeros((scene.height_px, scene.width_px), dtype=np.uint8)
    walls = np.linspace(0.0, 1.0, WALL_SAMPLES)
    for index, obj in enumerate(scene.objects, start=1):
        z_top = (obj.height_m - offset) / n_dot_ray          # depth where the ray is at the top's height
        z_table = -offset / n_dot_ray
        if not scene.walls:
            top = obj.footprint(ray_x * z_table, ray_y * z_table)
            hit_z = np.where(top, z_top, np.inf)
            closer = hit_z < depth
            depth[closer] = hit_z[closer]
            labels[closer] = index
            continue
        top = obj.footprint(ray_x * z_top, ray_y * z_top)
        hit_z = np.where(top, z_top, np.inf)
        # Walls: the top-plane point's (x, y) stays fixed along the optical axis, so the ray enters the
        # footprint below the top where its (x, y) at a deeper point lies inside it.
        box = _footprint_window(obj, ray_x, ray_y, z_table)
        if box is not None:
            rows, cols = box
            for s_value in walls[1:]:
                z = z_top[rows, cols] + s_value * (z_table[rows, cols] - z_top[rows, cols])
                inside = obj.footprint(ray_x[rows, cols] * z, ray_y[rows, cols] * z)
                window = hit_z[rows, cols]
                hit_z[rows, cols] = np.where(inside & ~np.isfinite(window), z, window)
        closer = hit_z < depth
        depth[closer] = hit_z[closer]
        labels[closer] = index
    return depth.astype(np.float32), labels


# Steps along a wall from the top's height to the table (0.5 mm for a 5 cm tall object).
WALL_SAMPLES = 101


def _footprint_window(obj: SceneObject, ray_x, ray_y, z_table):
    """(row slice, column slice) of the pixels whose ray can meet the object's walls: where the
    footprint's bounding circle lies between the top's and the table's height, with a margin."""
    reach = obj.radius_m if obj.radius_m > 0 else 0.5 * float(np.hypot(*obj.size_xy_m))
    cx, cy = obj.center_xy_m
    near = (np.abs(ray_x * z_table - cx) < reach * 1.5 + 0.02) & (np.abs(ray_y * z_table - cy) < reach * 1.5 + 0.02)
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    if rows.size == 0:
        return None
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)
