"""Realistic tabletop depth frames made by code (no downloads), with ground truth (no rclpy).

What a RealSense D4xx on a real cell sends: a tilted camera looking at a cluttered table, objects
touching each other, the robot's base (and mounting plate) in view, and the sensor's artefacts.
Analytic primitives (table, boxes, upright and lying cylinders, spheres; the robot's base as a
cylinder on a plate) are ray-cast in the robot base frame with numpy, each only inside the pixel
rectangle its bounding box projects to. The arm itself, when asked for, is drawn by PyBullet's
TinyRenderer from the Panda's meshes (render_arm_depth), so the self-filter that removes it
(perception/self_filter.py, Pinocchio frames + collision vertices) is tested against different code.

The noise model (parameters and sources: docs/perception.md):
- stereo occlusion shadow: pixels the right imager cannot see (left of foreground edges; the
  left imager is the depth reference) are invalid (0), and so is the left invalid band (fB/z pixels
  at the image's left edge, outside the right imager's view);
- depth RMS error sigma_z = z^2 * subpixel / (fx * baseline) (Intel's D400 formula), i.i.d. plus
  a spatially correlated part;
- flying pixels: next to depth jumps, pixels with a mix of the foreground and background depth;
- holes: random speckle dropouts, and missing returns on dark objects (blotches) and on shiny
  ones (where the surface faces the camera: specular);
- out of range (< min_z or > max_z) invalid; 16UC1 millimetre quantisation.

Frames come at the D4xx's standard depth modes with their intrinsics (realsense_k).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from defgg_ros.perception.depth_noise import REALSENSE_BASELINES_M, TYPICAL_SUBPIXEL_RMS_PX, DepthNoiseModel
from defgg_ros.perception.geometry import rotation_about_z

# D435 depth intrinsics per mode (fx = fy, principal point at the centre): the 1280x720 and 848x480
# modes span the D435's 90 degree horizontal field of view (fx = (width / 2) / tan 45 deg); the
# 640x480 mode is narrower, fx ~385 px in typical calibrations (the cell's CAMERA_FX_PX).
REALSENSE_FX_PX = {(1280, 720): 640.0, (848, 480): 424.0, (640, 360): 320.0, (640, 480): 385.0}
STEREO_BASELINE_M = REALSENSE_BASELINES_M["d435"]   # the scenes' default camera (TabletopScene.depth_noise)
SUBPIXEL_RMS_PX = TYPICAL_SUBPIXEL_RMS_PX          # Intel's typical subpixel RMS for a well-textured surface
MIN_Z_M = 0.17                      # D435 MinZ at 640x480 (0.28 m at 1280x720; objects here are farther)
MAX_Z_M = 3.0                       # beyond this the table scene has nothing; invalid
FLYING_JUMP_M = 0.010               # a neighbour depth jump this large makes edge pixels mixed
FLYING_PROBABILITY = 0.5
SPECKLE_SEED_FRACTION = 0.002       # seeds of 3x3 dropouts: ~1.5 % of the pixels
DARK_DROPOUT_FRACTION = 0.30        # share of a dark object's pixels without a return (blotches)
SHINY_SPECULAR_COS = math.cos(math.radians(18.0))
ROBOT_LABEL = 255                   # ground-truth label of robot pixels (base, plate, arm)

MATERIALS = ("matte", "dark", "shiny")


def realsense_k(width_px: int, height_px: int, fx_px: float | None = None) -> np.ndarray:
    """K of a D4xx depth mode (REALSENSE_FX_PX) or of `fx_px`; principal point at the centre."""
    f = fx_px if fx_px is not None else REALSENSE_FX_PX[(int(width_px), int(height_px))]
    return np.array([[f, 0.0, (width_px - 1) / 2.0], [0.0, f, (height_px - 1) / 2.0], [0.0, 0.0, 1.0]])


def look_at(eye_m, target_m, up_hint=(0.0, 0.0, 1.0)) -> np.ndarray:
    """base_T_camera of an optical frame (z forward, x right, y down) at eye looking at target."""
    eye, target = np.asarray(eye_m, float), np.asarray(target_m, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up_hint, float))
    if np.linalg.norm(x) < 1e-6:             # looking straight down: image up = base +x
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    out = np.eye(4)
    out[:3, :3] = np.stack([x, y, z], axis=1)
    out[:3, 3] = eye
    return out


@dataclass(frozen=True)
class Box:
    center_xy_m: tuple
    size_m: tuple                      # (along yaw, across, height)
    yaw_rad: float = 0.0
    z_bottom_m: float = 0.0
    material: str = "matte"
    name: str = "box"

    def bounds_corners(self) -> np.ndarray:
        half = np.array(self.size_m[:2]) / 2
        r = rotation_about_z(self.yaw_rad)[:2, :2]
        corners = []
        for sx in (-1, 1):
            for sy in (-1, 1):
                xy = np.asarray(self.center_xy_m) + r @ (half * (sx, sy))
                for z in (self.z_bottom_m, self.z_bottom_m + self.size_m[2]):
                    corners.append((xy[0], xy[1], z))
        return np.array(corners)

    def contains(self, points) -> np.ndarray:
        """Which base-frame points (N x 3) lie inside (ground truth for tests)."""
        r = rotation_about_z(self.yaw_rad)
        local = (np.asarray(points, float) - np.array([*self.center_xy_m, self.z_bottom_m + self.size_m[2] / 2])) @ r
        return np.all(np.abs(local) <= np.asarray(self.size_m) / 2, axis=1)

    def intersect(self, origin, rays):
        """(t, normal) of rays (N x 3, camera-depth scaled) with the box; t = inf on a miss."""
        r = rotation_about_z(self.yaw_rad)
        centre = np.array([*self.center_xy_m, self.z_bottom_m + self.size_m[2] / 2])
        o = (origin - centre) @ r          # into the box frame (r orthonormal: r^T x = x @ r)
        d = rays @ r
        half = np.asarray(self.size_m, float) / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (-half - o) / d, (half - o) / d
        t_near_axis = np.minimum(t1, t2)
        t_near = np.nanmax(t_near_axis, axis=1)
        t_far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (t_near <= t_far) & (t_far > 0) & (t_near > 0)
        axis = np.argmax(t_near_axis, axis=1)
        normal_local = np.zeros_like(rays)
        normal_local[np.arange(len(rays)), axis] = -np.sign(d[np.arange(len(rays)), axis])
        return np.where(hit, t_near, np.inf), normal_local @ r.T


@dataclass(frozen=True)
class Cylinder:
    """Upright cylinder standing on z_bottom_m."""
    center_xy_m: tuple
    radius_m: float
    height_m: float
    z_bottom_m: float = 0.0
    material: str = "matte"
    name: str = "cylinder"

    def bounds_corners(self) -> np.ndarray:
        c, r = self.center_xy_m, self.radius_m
        return np.array([(c[0] + sx * r, c[1] + sy * r, z) for sx in (-1, 1) for sy in (-1, 1)
                         for z in (self.z_bottom_m, self.z_bottom_m + self.height_m)])

    def contains(self, points) -> np.ndarray:
        p = np.asarray(points, float)
        d = p[:, :2] - np.asarray(self.center_xy_m)
        return (np.einsum("ij,ij->i", d, d) <= self.radius_m ** 2) & (p[:, 2] >= self.z_bottom_m) \
            & (p[:, 2] <= self.z_bottom_m + self.height_m)

    def intersect(self, origin, rays):
        o = origin - np.array([*self.center_xy_m, 0.0])
        top = self.z_bottom_m + self.height_m
        a = rays[:, 0] ** 2 + rays[:, 1] ** 2
        b = 2 * (o[0] * rays[:, 0] + o[1] * rays[:, 1])
        c = o[0] ** 2 + o[1] ** 2 - self.radius_m ** 2
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            t_side = (-b - np.sqrt(disc)) / (2 * a)
            z_side = o[2] + t_side * rays[:, 2]
            side = (disc >= 0) & (t_side > 0) & (z_side >= self.z_bottom_m) & (z_side <= top)
            t_cap = (top - o[2]) / rays[:, 2]
        px, py = o[0] + t_cap * rays[:, 0], o[1] + t_cap * rays[:, 1]
        cap = (t_cap > 0) & (px * px + py * py <= self.radius_m ** 2)
        t = np.where(side, t_side, np.inf)
        use_cap = cap & (t_cap < t)
        t = np.where(use_cap, t_cap, t)
        normal = np.zeros_like(rays)
        hit_xy = o[:2] + t_side[:, None] * rays[:, :2]
        normal[:, :2] = hit_xy / self.radius_m
        normal[use_cap] = (0.0, 0.0, 1.0)
        return t, normal


@dataclass(frozen=True)
class LyingCylinder:
    """A cylinder lying on the table (bottle, banana-like), axis along yaw."""
    center_xy_m: tuple
    radius_m: float
    length_m: float
    yaw_rad: float = 0.0
    material: str = "matte"
    name: str = "lying cylinder"
    z_bottom_m: float = 0.0            # its lowest line's height (above the table: held by another part)

    def bounds_corners(self) -> np.ndarray:
        return Box(self.center_xy_m, (self.length_m, 2 * self.radius_m, 2 * self.radius_m),
                   self.yaw_rad, self.z_bottom_m).bounds_corners()

    def contains(self, points) -> np.ndarray:
        r = rotation_about_z(self.yaw_rad)
        local = (np.asarray(points, float) - np.array([*self.center_xy_m, self.z_bottom_m + self.radius_m])) @ r
        return (local[:, 1] ** 2 + local[:, 2] ** 2 <= self.radius_m ** 2) & (np.abs(local[:, 0]) <= self.length_m / 2)

    def intersect(self, origin, rays):
        r = rotation_about_z(self.yaw_rad)
        centre = np.array([*self.center_xy_m, self.z_bottom_m + self.radius_m])
        o, d = (origin - centre) @ r, rays @ r      # axis = local x
        a = d[:, 1] ** 2 + d[:, 2] ** 2
        b = 2 * (o[1] * d[:, 1] + o[2] * d[:, 2])
        c = o[1] ** 2 + o[2] ** 2 - self.radius_m ** 2
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (-b - np.sqrt(disc)) / (2 * a)
        x = o[0] + t * d[:, 0]
        hit = (disc >= 0) & (t > 0) & (np.abs(x) <= self.length_m / 2)
        normal_local = o + t[:, None] * d
        normal_local[:, 0] = 0.0
        normal_local /= self.radius_m
        return np.where(hit, t, np.inf), normal_local @ r.T


@dataclass(frozen=True)
class Sphere:
    center_m: tuple
    radius_m: float
    material: str = "matte"
    name: str = "sphere"

    def bounds_corners(self) -> np.ndarray:
        c, r = np.asarray(self.center_m), self.radius_m
        return np.array([c + (sx * r, sy * r, sz * r) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])

    def contains(self, points) -> np.ndarray:
        d = np.asarray(points, float) - np.asarray(self.center_m)
        return np.einsum("ij,ij->i", d, d) <= self.radius_m ** 2

    def intersect(self, origin, rays):
        o = origin - np.asarray(self.center_m)
        a = np.einsum("ij,ij->i", rays, rays)
        b = 2 * rays @ o
        c = o @ o - self.radius_m ** 2
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore"):
            t = (-b - np.sqrt(disc)) / (2 * a)
        hit = (disc >= 0) & (t > 0)
        normal = (o + t[:, None] * rays) / self.radius_m
        return np.where(hit, t, np.inf), normal


@dataclass(frozen=True)
class HollowCylinder:
    """An open cup or bowl standing on the table: a wall of wall_m around an inside whose bottom lies
    bottom_m above the table. From above: the rim, the inside of the far wall and the inner bottom."""
    center_xy_m: tuple
    radius_m: float
    height_m: float
    wall_m: float = 0.004
    bottom_m: float = 0.012
    material: str = "matte"
    name: str = "cup"

    def _outer(self) -> Cylinder:
        return Cylinder(self.center_xy_m, self.radius_m, self.height_m)

    def bounds_corners(self) -> np.ndarray:
        return self._outer().bounds_corners()

    def contains(self, points) -> np.ndarray:
        p = np.asarray(points, float)
        d = p[:, :2] - np.asarray(self.center_xy_m)
        inside = (np.einsum("ij,ij->i", d, d) < (self.radius_m - self.wall_m) ** 2) & (p[:, 2] > self.bottom_m)
        return self._outer().contains(p) & ~inside

    def intersect(self, origin, rays):
        t, normal = self._outer().intersect(origin, rays)
        o = origin - np.array([*self.center_xy_m, 0.0])
        inner = self.radius_m - self.wall_m
        hit_xy = o[:2] + np.where(np.isfinite(t), t, 0.0)[:, None] * rays[:, :2]
        into = np.isfinite(t) & (normal[:, 2] > 0.5) & (np.einsum("ij,ij->i", hit_xy, hit_xy) < inner ** 2)
        if not into.any():
            return t, normal
        d = rays[into]
        # Through the opening: the inside of the wall (the inner cylinder's far crossing) or the inner bottom.
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = 2 * (o[0] * d[:, 0] + o[1] * d[:, 1])
        c = o[0] ** 2 + o[1] ** 2 - inner ** 2
        with np.errstate(invalid="ignore", divide="ignore"):
            t_wall = (-b + np.sqrt(np.maximum(b * b - 4 * a * c, 0.0))) / (2 * a)
            t_bottom = (self.bottom_m - o[2]) / d[:, 2]
        z_wall = o[2] + t_wall * d[:, 2]
        on_wall = z_wall > self.bottom_m
        t_in = np.where(on_wall, t_wall, t_bottom)
        n_in = np.zeros_like(d)
        wall_xy = o[:2] + t_wall[:, None] * d[:, :2]
        n_in[:, :2] = -wall_xy / inner
        n_in[~on_wall] = (0.0, 0.0, 1.0)
        t, normal = t.copy(), normal.copy()
        t[into], normal[into] = t_in, n_in
        return t, normal


@dataclass(frozen=True)
class Compound:
    """One object made of several primitives (a drill, a mug with its handle): one label."""
    parts: tuple
    name: str = "compound"
    material: str = "matte"

    def bounds_corners(self) -> np.ndarray:
        return np.concatenate([part.bounds_corners() for part in self.parts])

    def contains(self, points) -> np.ndarray:
        return np.any([part.contains(points) for part in self.parts], axis=0)

    def intersect(self, origin, rays):
        best_t, best_normal = np.full(len(rays), np.inf), np.zeros_like(rays)
        for part in self.parts:
            t, normal = part.intersect(origin, rays)
            closer = t < best_t
            best_t[closer], best_normal[closer] = t[closer], normal[closer]
        return best_t, best_normal


def robot_base_parts() -> tuple:
    """The Panda's base (link0 ~ a 0.11 m cylinder up to the shoulder) on a 15 mm mounting plate."""
    return (Box((-0.03, 0.0), (0.32, 0.28, 0.015), name="mounting plate"),
            Cylinder((0.0, 0.0), 0.11, 0.33, z_bottom_m=0.015, name="robot base"))


@dataclass(frozen=True)
class TabletopScene:
    objects: tuple                          # graspable objects, labels 1..N in this order
    base_T_camera: np.ndarray
    width_px: int = 640
    height_px: int = 480
    fx_px: float | None = None              # None: the D435 value of the mode
    table_z_m: float = 0.0
    table_x_range_m: tuple = (-0.4, 1.2)
    table_y_range_m: tuple = (-0.8, 0.8)
    floor_z_m: float = -0.75
    robot_parts: tuple = field(default_factory=robot_base_parts)
    depth_noise: DepthNoiseModel = field(default_factory=DepthNoiseModel)   # the camera's baseline and subpixel RMS
    table_warp: object = None               # callable (x, y) -> the table's height above table_z_m there, or None

    @property
    def camera_k(self) -> np.ndarray:
        return realsense_k(self.width_px, self.height_px, self.fx_px)


@dataclass(frozen=True)
class RenderedFrame:
    depth_m: np.ndarray          # HxW float32, NaN = no return (what the driver sends as 0 in 16UC1)
    clean_depth_m: np.ndarray    # HxW float32 without noise
    labels: np.ndarray           # HxW uint8: 0 table/floor, 1..N objects, ROBOT_LABEL robot
    camera_k: np.ndarray
    base_T_camera: np.ndarray


def _rays_in_base(scene: TabletopScene) -> np.ndarray:
    k = scene.camera_k
    u = (np.arange(scene.width_px) - k[0, 2]) / k[0, 0]
    v = (np.arange(scene.height_px) - k[1, 2]) / k[1, 1]
    rays_cam = np.stack(np.broadcast_arrays(u[None, :], v[:, None], 1.0), axis=-1)   # z = 1: t is depth
    return rays_cam @ scene.base_T_camera[:3, :3].T


def _pixel_window(scene: TabletopScene, corners_base: np.ndarray):
    """(v0, v1, u0, u1) the primitive can cover, or the whole image when it reaches behind the camera."""
    camera_T_base = np.linalg.inv(scene.base_T_camera)
    p = corners_base @ camera_T_base[:3, :3].T + camera_T_base[:3, 3]
    if np.any(p[:, 2] <= 1e-3):
        return 0, scene.height_px, 0, scene.width_px
    k = scene.camera_k
    u, v = k[0, 0] * p[:, 0] / p[:, 2] + k[0, 2], k[1, 1] * p[:, 1] / p[:, 2] + k[1, 2]
    u0, u1 = int(max(0, math.floor(u.min()) - 1)), int(min(scene.width_px, math.ceil(u.max()) + 2))
    v0, v1 = int(max(0, math.floor(v.min()) - 1)), int(min(scene.height_px, math.ceil(v.max()) + 2))
    return v0, max(v0, v1), u0, max(u0, u1)


def ray_cast(scene: TabletopScene):
    """(clean depth m, labels uint8, normals HxWx3 base frame, materials HxW int) of the scene."""
    h, w = scene.height_px, scene.width_px
    rays = _rays_in_base(scene)
    origin = scene.base_T_camera[:3, 3]
    depth = np.full((h, w), np.inf)
    labels = np.zeros((h, w), np.uint8)
    normals = np.zeros((h, w, 3))
    normals[..., 2] = 1.0
    material = np.zeros((h, w), np.int8)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_table = (scene.table_z_m - origin[2]) / rays[..., 2]
        t_floor = (scene.floor_z_m - origin[2]) / rays[..., 2]
    x, y = origin[0] + t_table * rays[..., 0], origin[1] + t_table * rays[..., 1]
    for _ in range(4 if scene.table_warp is not None else 0):     # a warped table: a fixed-point ray cast
        with np.errstate(divide="ignore", invalid="ignore"):
            t_table = (scene.table_z_m + scene.table_warp(x, y) - origin[2]) / rays[..., 2]
        x, y = origin[0] + t_table * rays[..., 0], origin[1] + t_table * rays[..., 1]
    on_table = (t_table > 0) & (x >= scene.table_x_range_m[0]) & (x <= scene.table_x_range_m[1]) \
        & (y >= scene.table_y_range_m[0]) & (y <= scene.table_y_range_m[1])
    depth = np.where(on_table, t_table, np.where(t_floor > 0, t_floor, np.inf))
    parts = [(obj, i) for i, obj in enumerate(scene.objects, start=1)] + [(p, ROBOT_LABEL) for p in scene.robot_parts]
    for obj, label in parts:
        v0, v1, u0, u1 = _pixel_window(scene, obj.bounds_corners())
        if v1 <= v0 or u1 <= u0:
            continue
        window_rays = rays[v0:v1, u0:u1].reshape(-1, 3)
        t, n = obj.intersect(origin, window_rays)
        t = t.reshape(v1 - v0, u1 - u0)
        closer = t < depth[v0:v1, u0:u1]
        depth[v0:v1, u0:u1][closer] = t[closer]
        labels[v0:v1, u0:u1][closer] = label
        normals[v0:v1, u0:u1][closer] = n.reshape(v1 - v0, u1 - u0, 3)[closer]
        material[v0:v1, u0:u1][closer] = MATERIALS.index(getattr(obj, "material", "matte"))
    return depth, labels, normals, material


def add_realsense_noise(depth_m: np.ndarray, labels: np.ndarray, normals_base: np.ndarray, material: np.ndarray,
                        scene: TabletopScene, rng: np.random.Generator) -> np.ndarray:
    """The D4xx artefacts (module docstring) on a clean depth image; returns float32 m, NaN = no return."""
    import cv2

    fx = scene.camera_k[0, 0]
    z = np.where(np.isfinite(depth_m), depth_m, 0.0)
    h, w = z.shape
    out = z.copy()
    # Depth RMS error, i.i.d. plus a correlated part (the stereo matcher's window correlates neighbours).
    sigma = scene.depth_noise.sigma_m(z, fx)
    baseline_m = scene.depth_noise.baseline_m
    low = cv2.resize(rng.standard_normal((max(h // 8, 1), max(w // 8, 1))).astype(np.float32), (w, h),
                     interpolation=cv2.INTER_LINEAR)
    out += sigma * (0.8 * rng.standard_normal((h, w)) + 0.6 * low)
    # Flying pixels: across horizontal and vertical jumps, mixes of the two depths.
    for axis in (0, 1):
        a = np.swapaxes(z, 0, axis)
        jump = np.abs(np.diff(a, axis=0)) > FLYING_JUMP_M
        rows, cols = np.nonzero(jump & (rng.random(jump.shape) < FLYING_PROBABILITY))
        alpha = rng.uniform(0.15, 0.85, rows.size)
        mixed = alpha * a[rows, cols] + (1 - alpha) * a[rows + 1, cols]
        pick = rng.random(rows.size) < 0.5          # which side of the jump gets the mixed value
        target_rows = np.where(pick, rows, rows + 1)
        np.swapaxes(out, 0, axis)[target_rows, cols] = mixed
    invalid = ~(z > 0)
    # Stereo occlusion: the right imager sees pixel u at u - fB/z; hidden when a pixel to its right
    # maps at or left of it (a closer surface covers it).
    with np.errstate(divide="ignore"):
        x_right = np.arange(w)[None, :] - np.where(z > 0, fx * baseline_m / np.where(z > 0, z, 1), 0)
    suffix_min = np.minimum.accumulate(x_right[:, ::-1], axis=1)[:, ::-1]
    hidden = np.zeros_like(invalid)
    hidden[:, :-1] = x_right[:, :-1] > suffix_min[:, 1:] + 0.5
    invalid |= hidden
    # The left invalid band: what lies left of the right imager's field of view (fB/z pixels wide, ~40-65 px
    # at 0.5 m) has no match at all.
    invalid |= x_right < 0
    # Speckle dropouts.
    seeds = (rng.random((h, w)) < SPECKLE_SEED_FRACTION).astype(np.uint8)
    invalid |= cv2.dilate(seeds, np.ones((3, 3), np.uint8)) > 0
    # Dark parts: blotches without return; shiny parts: specular spots facing the camera.
    dark = material == MATERIALS.index("dark")
    if dark.any():
        field_ = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 4.0)
        threshold = np.quantile(field_[dark], 1 - DARK_DROPOUT_FRACTION)
        invalid |= dark & (field_ > threshold)
    shiny = material == MATERIALS.index("shiny")
    if shiny.any():
        view = _rays_in_base(scene)
        view /= np.linalg.norm(view, axis=-1, keepdims=True)
        facing = -np.einsum("hwc,hwc->hw", view, normals_base)
        invalid |= shiny & ((facing > SHINY_SPECULAR_COS) | (rng.random((h, w)) < 0.15))
    out = np.round(out * 1000.0) / 1000.0           # 16UC1 millimetres
    invalid |= (out < MIN_Z_M) | (out > MAX_Z_M)
    out[invalid] = np.nan
    return out.astype(np.float32)


def render(scene: TabletopScene, seed: int = 0, noise: bool = True, arm_q_rad=None) -> RenderedFrame:
    """Ray-cast `scene` (plus the arm at arm_q_rad, drawn by PyBullet) and add the sensor noise."""
    depth, labels, normals, material = ray_cast(scene)
    if arm_q_rad is not None:
        arm = render_arm_depth(arm_q_rad, scene.base_T_camera, scene.camera_k, scene.width_px, scene.height_px)
        closer = arm < depth
        depth[closer] = arm[closer]
        labels[closer] = ROBOT_LABEL
        material[closer] = 0
        normals[closer] = (0.0, 0.0, 1.0)
    clean = np.where(np.isfinite(depth) & (depth <= MAX_Z_M), depth, np.nan).astype(np.float32)
    noisy = add_realsense_noise(depth, labels, normals, material, scene, np.random.default_rng(seed)) if noise \
        else clean.copy()
    return RenderedFrame(noisy, clean, labels, scene.camera_k, scene.base_T_camera.copy())


def render_arm_depth(q_rad, base_T_camera, camera_k, width_px: int, height_px: int) -> np.ndarray:
    """Depth (m, inf = no arm) of the Panda at arm joints q_rad, drawn by PyBullet's TinyRenderer from
    its own meshes (the same URDF the cell simulates), with the camera's exact pinhole model."""
    import pybullet as p
    import pybullet_data

    near, far = 0.05, 5.0
    client = p.connect(p.DIRECT)
    try:
        robot = p.loadURDF(str(__import__("pathlib").Path(pybullet_data.getDataPath()) / "franka_panda" /
                               "panda.urdf"), useFixedBase=True, physicsClientId=client)
        for joint, value in enumerate(np.asarray(q_rad, float)):
            p.resetJointState(robot, joint, float(value), physicsClientId=client)
        for finger in (9, 10):
            p.resetJointState(robot, finger, 0.04, physicsClientId=client)
        view = np.linalg.inv(base_T_camera)                 # camera_T_base, optical frame
        gl_from_optical = np.diag([1.0, -1.0, -1.0, 1.0])   # OpenGL camera: y up, looking along -z
        view_gl = gl_from_optical @ view
        k = camera_k
        projection = np.zeros((4, 4))
        projection[0, 0] = 2 * k[0, 0] / width_px
        projection[1, 1] = 2 * k[1, 1] / height_px
        projection[0, 2] = -(2 * k[0, 2] / width_px - 1) + 1.0 / width_px
        projection[1, 2] = (2 * k[1, 2] / height_px - 1) - 1.0 / height_px
        projection[2, 2] = -(far + near) / (far - near)
        projection[2, 3] = -2 * far * near / (far - near)
        projection[3, 2] = -1.0
        _, _, _, buffer, _ = p.getCameraImage(width_px, height_px, viewMatrix=view_gl.T.reshape(-1).tolist(),
                                              projectionMatrix=projection.T.reshape(-1).tolist(),
                                              renderer=p.ER_TINY_RENDERER, physicsClientId=client)
    finally:
        p.disconnect(client)
    buffer = np.asarray(buffer, dtype=np.float64).reshape(height_px, width_px)
    depth = far * near / (far - (far - near) * buffer)
    return np.where(buffer < 1.0 - 1e-7, depth, np.inf)


# --- ready-made scenes -------------------------------------------------------------------------
# A tilted camera at the far side of the table looking back at the robot: the table 0.45-0.6 m
# away, the robot's base and mounting plate at the top of the image.
TILTED_EYE_M = (0.86, 0.02, 0.40)
TILTED_TARGET_M = (0.42, 0.0, 0.0)
MODES = ((640, 480), (848, 480), (1280, 720))


def cluttered_objects() -> tuple:
    """Eight objects, some touching (at different heights, so depth can tell them apart), one dark
    and one shiny: a cereal box lying flat (its top face far wider than the gripper), a can touching
    it, a bottle and a banana lying down, a cup, a block touching a sponge, a ball."""
    return (
        Box((0.50, 0.12), (0.20, 0.14, 0.06), yaw_rad=0.1, name="cereal box"),
        Cylinder((0.50, 0.2325), 0.033, 0.12, name="can", material="shiny"),
        LyingCylinder((0.36, -0.06), 0.035, 0.22, yaw_rad=1.2, name="bottle"),
        LyingCylinder((0.62, -0.10), 0.018, 0.16, yaw_rad=-0.4, name="banana"),
        Cylinder((0.355, 0.13), 0.04, 0.09, name="cup", material="dark"),
        Box((0.52, -0.24), (0.05, 0.05, 0.05), yaw_rad=0.3, name="rubber block"),
        Box((0.585, -0.24), (0.08, 0.06, 0.03), yaw_rad=0.3, name="sponge"),
        Sphere((0.66, 0.03, 0.03), 0.03, name="ball"),
    )


def cluttered_table(width_px: int = 640, height_px: int = 480, fx_px: float | None = None,
                    objects: tuple | None = None) -> TabletopScene:
    return TabletopScene(cluttered_objects() if objects is None else objects,
                         look_at(TILTED_EYE_M, TILTED_TARGET_M), width_px, height_px, fx_px)


def overhead_single(obj, width_px: int = 640, height_px: int = 480, height_m: float = 0.55) -> TabletopScene:
    """One object under a camera looking straight down from height_m above (0.5, 0)."""
    return TabletopScene((obj,), look_at((0.5, 0.0, height_m), (0.5, 0.0, 0.0)), width_px, height_px)


def hand_fingers_in_view(base_T_camera, camera_k, height_px: int, distance_m: float = 0.17,
                         gap_m: float = 0.05) -> tuple:
    """The Franka hand's two fingers as a wrist camera sees them: boxes (18 x 20 x 55 mm, like the Panda's
    finger) hanging at the image's bottom edge, their nearest face distance_m along the bottom rows' central
    ray, gap_m apart across the image; drawn as robot parts (the camera is on the hand above them)."""
    k = np.asarray(camera_k, float)
    ray = np.array([0.0, (height_px - 1 - k[1, 2]) / k[1, 1], 1.0])          # bottom row, centre column
    point = base_T_camera[:3, :3] @ (ray * distance_m) + base_T_camera[:3, 3]
    across = base_T_camera[:3, 0]                                             # image x in the base frame
    fingers = []
    for side in (-1.0, 1.0):
        centre = point + side * (gap_m / 2 + 0.009) * across
        fingers.append(Box((float(centre[0]), float(centre[1])), (0.018, 0.02, 0.055),
                           z_bottom_m=float(point[2] - 0.055), name=f"finger {'left' if side < 0 else 'right'}"))
    return tuple(fingers)


def overhead_with_fingers(obj, width_px: int = 640, height_px: int = 480, height_m: float = 0.40,
                          finger_distance_m: float = 0.17) -> TabletopScene:
    """overhead_single from a wrist camera: the hand's fingers hang into view at the image's bottom edge."""
    scene = overhead_single(obj, width_px, height_px, height_m)
    fingers = hand_fingers_in_view(scene.base_T_camera, scene.camera_k, height_px, finger_distance_m)
    return TabletopScene(scene.objects, scene.base_T_camera, width_px, height_px,
                         robot_parts=scene.robot_parts + fingers)


# --- real shapes (issue 47): one object of several parts, hollow objects, a warped table, bin clutter --------

def drill_like(center_xy_m=(0.50, 0.0), yaw_rad: float = 0.0, name: str = "drill") -> Compound:
    """A cordless drill standing on its battery: a battery pack on the table, a handle rising from its rear to
    the body, a body lying across the top (a cylinder, its chuck overhanging the table in front). Its parts
    meet only above the table: from above, the body crosses the battery, which shows around it."""
    r = rotation_about_z(yaw_rad)[:2, :2]

    def at(dx, dy):
        x, y = np.asarray(center_xy_m, float) + r @ (dx, dy)
        return float(x), float(y)
    return Compound((
        Box(at(0.0, 0.0), (0.11, 0.08, 0.065), yaw_rad, name="battery"),
        Box(at(-0.03, 0.0), (0.04, 0.032, 0.12), yaw_rad, 0.06, name="handle"),
        LyingCylinder(at(0.035, 0.0), 0.028, 0.17, yaw_rad, z_bottom_m=0.165, name="body"),
        LyingCylinder(at(0.14, 0.0), 0.012, 0.045, yaw_rad, z_bottom_m=0.181, name="chuck"),
    ), name=name)


def mug_like(center_xy_m=(0.50, 0.0), yaw_rad: float = 0.0, radius_m: float = 0.04, height_m: float = 0.095,
             name: str = "mug") -> Compound:
    """An open mug with a handle on its side: the handle (a 12 mm wide loop, seen from above as a strip) is
    joined to the wall between 2.5 cm above the table and just under the rim; the table shows beneath it."""
    x, y = center_xy_m
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    reach = 0.028
    handle_xy = (x + c * (radius_m + reach / 2 - 0.002), y + s * (radius_m + reach / 2 - 0.002))
    return Compound((
        HollowCylinder(center_xy_m, radius_m, height_m, name="mug body"),
        Box(handle_xy, (reach, 0.012, height_m - 0.035), yaw_rad, 0.025, name="handle"),
    ), name=name)


def curved_table_warp(rise_m: float = 0.018, start_x_m: float = 0.62, end_x_m: float = 0.85):
    """A table that curves up towards its far edge (+x): flat up to start_x_m, rise_m higher at end_x_m."""
    def warp(x, y):
        u = np.clip((np.asarray(x) - start_x_m) / (end_x_m - start_x_m), 0.0, None)
        return rise_m * u * u
    return warp


def bin_walls(center_xy_m=(0.50, 0.0), size_m=(0.30, 0.22), height_m: float = 0.09, wall_m: float = 0.006,
              floor_m: float = 0.008) -> tuple:
    """A tote bin's floor and four walls, as robot parts (ground truth 'not an object to pick')."""
    x, y = center_xy_m
    lx, ly = size_m
    return (Box((x, y), (lx, ly, floor_m), name="bin floor"),
            Box((x + (lx - wall_m) / 2, y), (wall_m, ly, height_m), name="bin wall"),
            Box((x - (lx - wall_m) / 2, y), (wall_m, ly, height_m), name="bin wall"),
            Box((x, y + (ly - wall_m) / 2), (lx, wall_m, height_m), name="bin wall"),
            Box((x, y - (ly - wall_m) / 2), (lx, wall_m, height_m), name="bin wall"))


def bin_clutter_objects(count: int = 24, center_xy_m=(0.50, 0.0), size_m=(0.30, 0.22), floor_m: float = 0.008,
                        seed: int = 0, tall_m=(0.05, 0.08)) -> tuple:
    """count small objects dense in a bin, a few millimetres to two centimetres apart: low ones (1-2 cm: lids,
    flat boxes, small balls) and, every third, tall ones (5-8 cm: standing cans and blocks): the top objects
    a gripper can take, its fingers going down beside them onto the low ones."""
    rng = np.random.default_rng(seed)
    cols = int(math.ceil(math.sqrt(count * size_m[0] / size_m[1])))
    rows = int(math.ceil(count / cols))
    pitch = ((size_m[0] - 0.02) / cols, (size_m[1] - 0.02) / rows)
    objects = []
    for n in range(count):
        i, j = n % cols, n // cols
        x = center_xy_m[0] - (size_m[0] - 0.02) / 2 + (i + 0.5) * pitch[0] + rng.uniform(-0.003, 0.003)
        y = center_xy_m[1] - (size_m[1] - 0.02) / 2 + (j + 0.5) * pitch[1] + rng.uniform(-0.003, 0.003)
        tall = (n + seed) % 3 == 0
        h = float(rng.uniform(*tall_m) if tall else rng.uniform(0.01, 0.02))
        kind = int(rng.integers(0, 2 if tall else 3))
        if kind == 0:
            size = (min(pitch) * rng.uniform(0.55, 0.85), min(pitch) * rng.uniform(0.5, 0.8), h)
            objects.append(Box((x, y), size, float(rng.uniform(-0.5, 0.5)), floor_m, name=f"box {n}"))
        elif kind == 1:
            objects.append(Cylinder((x, y), min(pitch) * rng.uniform(0.28, 0.42), h, floor_m, name=f"can {n}"))
        else:
            rad = h / 2 + 0.004
            objects.append(Sphere((x, y, floor_m + rad), rad, name=f"ball {n}"))
    return tuple(objects)


def overhead_072(objects, width_px: int = 640, height_px: int = 480, fx_px: float = 525.0, centre_xy_m=(0.5, 0.0),
                 **scene) -> TabletopScene:
    """The issue's real overhead frames: 640x480, fx 525, the camera 0.72 m above the table, looking down."""
    eye = (centre_xy_m[0], centre_xy_m[1], 0.72)
    return TabletopScene(tuple(objects), look_at(eye, (centre_xy_m[0], centre_xy_m[1], 0.0)), width_px, height_px,
                         fx_px, **scene)
