"""Tabletop perception in the robot's frame, for any camera pose and resolution (no rclpy).

    view = perceive(depth_m, camera_k, base_T_camera)    # TabletopConfig() by default

The camera pose `base_T_camera` (4x4, optical frame in the robot base frame) comes from TF or a
parameter; everything below works in the base frame, so a tilted camera, a different mount height
or another resolution sees the same scene:

1. Table plane: RANSAC over the pixels inside the workspace's x/y range, hypotheses limited to
   planes whose normal is within TABLE_MAX_TILT_DEG of the base z axis and whose height is within
   table_z_tolerance_m of the expected table height; refined by least squares on the inliers.
2. Foreground: valid pixels between min and max height above that plane, inside the workspace box
   (base frame x/y, which excludes the robot's base and mounting plate and everything beside the
   table), outside the robot keep-out cylinder around the base axis, and not masked by the robot
   self-filter (perception/self_filter.py).
3. Height map: the foreground points splatted (maximum height per cell) into an orthographic
   top-down grid of the network's training pixel scale (CELL_M: the training camera's
   0.40 m / 385 px), small holes (no return, shadows) closed. The grasp network sees this grid as
   a virtual top-down depth image, so the opening in metres is cells x CELL_M whatever the camera.
4. Objects: connected regions of the height map that no height jump larger than jump_m crosses.
   Touching objects of different heights are cut at their common edge (a can against a box, a
   bottle against a block), not only separated by gaps. Image labels are read back from the cells.
   (Two flat tops at the same height that touch are one surface to any depth camera: one object.)
5. Real shapes (issue 47): occupied cells no object reached, in a group touching no object and at least
   LEFTOVER_MIN_WIDTH_M wide with what it encloses, are an object (a thin-walled cup, a mug seen from the
   side: no flat core survives the cuts); such a group around one object joins it (a cup's rim and walls
   around its inner bottom); a narrow region lower and much smaller than the one object beside it joins it
   (a drill's chuck, a mug's handle: _merge_appendages); regions at the view's border whose outline rises
   out of the table without a wall are the table itself, curving up, and are dropped (_drop_table_warps);
   unlabelled pixels one object alone encloses in the image take its label (a cup's inside: fill_enclosed).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from defgg_ros.constants import CAMERA_FX_PX, CAMERA_HEIGHT_ABOVE_TABLE_M
from defgg_ros.perception.depth_noise import DepthNoiseModel, robust_rms_m
from defgg_ros.perception.geometry import check_camera_matrix, plane_hypotheses

# The network was trained on top-down images from 0.40 m with fx = 385 px: 1.039 mm per pixel at
# the table. The height map uses that cell size, so objects have their training size in pixels.
CELL_M = CAMERA_HEIGHT_ABOVE_TABLE_M / CAMERA_FX_PX
TABLE_MAX_TILT_DEG = 15.0
PLANE_INLIER_M = 0.006
PLANE_ITERATIONS = 80
PLANE_SAMPLE_PIXELS = 6000
# The height map reaches this far beyond the outermost object point: context for the network (the
# finger pads are checked against the depth image itself, planning/tabletop_grasps.py).
GRID_MARGIN_M = 0.03
# Cells whose smoothed height slope exceeds this are the flanks of round objects and the creases
# where a round object meets a flat one: cut, so a bottle lying against a lower box stays apart.
CREASE_SLOPE = math.tan(math.radians(30.0))
# Cells cut at noise steps take a labelled neighbour's label this far away when they continue its
# surface (height within jump_m per cell of distance).
GROW_REACH_M = 0.008
# Pixels of object flanks and edges whose cell lost the object's label take it from a labelled cell
# at most this far away (horizontal scatter of side-face points, depth noise along the ray).
LABEL_REACH_M = 0.004
# Frames with a larger focal length are read at every n-th pixel (processing_stride).
FULL_RESOLUTION_MAX_FX_PX = 320.0
# A hole whose right neighbour is this much nearer than its left one is a stereo shadow (fill_holes).
SHADOW_JUMP_M = 0.005
# A region narrower than this (twice its largest inscribed radius), lower than and under a quarter of the area
# of the one region within APPENDAGE_GAP_M of it, is a part of that object (a drill's chuck, a mug's handle,
# a battery pack showing beside the body above it), not an object of its own.
APPENDAGE_MAX_WIDTH_M = 0.025
APPENDAGE_MAX_AREA_SHARE = 0.25
APPENDAGE_GAP_M = 0.005
# Occupied cells no object reached become an object of their own only as a group at least this wide (a
# mug's wall seen from the side splats into a 14 mm crescent; a battery pack's flank beside a drill's body
# into a 6 mm sliver).
LEFTOVER_MIN_WIDTH_M = 0.010
# ... and only when it stays this far under the workspace box's max_height_m (what reaches it is part of
# something taller: the robot's base seen in a table frame, a shelf).
LEFTOVER_CEILING_M = 0.01
# A region at the view's border whose outline against the table stands less than this above the minimum object
# height is the table rising there, not an object (_drop_table_warps).
WARP_OUTLINE_STEP_M = 0.004
# Unlabelled groups smaller than this share of min_object_area_m2 neither join an object nor become one (specks
# of flank between the cuts).
JOIN_MIN_SHARE = 0.25
# Gaps in a rim's outline bridged before what it encloses is found (cells of the height map, pixels).
RIM_GAP_CELLS = 7
_RIM_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (RIM_GAP_CELLS, RIM_GAP_CELLS))
# Labels travel as mono8.
MAX_LABELS = 254
_CROSS_3X3 = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


GRASP_HEIGHT_RULES = ("half_height", "below_surface")


class TabletopError(ValueError):
    """A frame the tabletop perception cannot use (no table, bad pose...)."""


@dataclass(frozen=True)
class WorkspaceBox:
    """The region objects are picked from, in the robot base frame (m). The default keeps clear of
    the Panda's base (x < 0.2 m) and mounting plate and stays on the table in front of the robot."""
    x_m: tuple = (0.22, 0.85)
    y_m: tuple = (-0.40, 0.40)
    min_height_m: float = 0.006        # above the table: thinner is noise or paper
    max_height_m: float = 0.25         # higher is not a graspable object (the arm passing through)

    def __post_init__(self):
        if not (self.x_m[0] < self.x_m[1] and self.y_m[0] < self.y_m[1] and 0 < self.min_height_m < self.max_height_m):
            raise ValueError(f"workspace box needs min < max on every axis, got {self}")


@dataclass(frozen=True)
class TabletopConfig:
    workspace: WorkspaceBox = field(default_factory=WorkspaceBox)
    table_z_m: float = 0.0             # expected table height in the base frame
    table_z_tolerance_m: float = 0.10
    robot_keepout_radius_m: float = 0.20   # around the base axis (also the arm's reach minimum)
    jump_m: float = 0.008              # a height step this large between neighbour cells cuts objects
    min_object_area_m2: float = 2.5e-4  # 16 x 16 mm: smaller blobs are speckle
    hole_close_cells: int = 5          # holes up to this many cells wide inside objects are closed
    # The camera's depth noise (perception/depth_noise.py): the free-space test allows for it on surfaces
    # above the table. depth_noise_from_table: measure it instead from the frame's own table residuals.
    depth_noise: DepthNoiseModel = field(default_factory=DepthNoiseModel)
    depth_noise_from_table: bool = False
    # How low the executor takes the fingers (its grasp_height_rule and grasp_depth_below_surface_m, which the
    # grasp search must share): half_height (half the height seen at the centre) or below_surface (this far
    # under it: a bin's top objects, whose neighbours stand higher than half their height).
    grasp_height_rule: str = "half_height"
    grasp_depth_below_surface_m: float = 0.018

    def __post_init__(self):
        if self.grasp_height_rule not in GRASP_HEIGHT_RULES or not self.grasp_depth_below_surface_m >= 0:
            raise ValueError(f"grasp_height_rule must be one of {GRASP_HEIGHT_RULES} and grasp_depth_below_surface_m "
                             f">= 0, got {self.grasp_height_rule!r}, {self.grasp_depth_below_surface_m}")


@dataclass
class TabletopView:
    base_T_camera: np.ndarray
    camera_k: np.ndarray
    table_normal: np.ndarray           # unit, base frame
    table_offset_m: float              # n . p + d = 0
    # The per-pixel images at the read stride (processing_stride); the full-resolution ones (height_m,
    # foreground, labels, pixel_cell below) are made from them when first read: a 1280x720 frame's
    # four nearest-neighbour upscales cost ~3 ms, and planning reads only the labels.
    processed_height_m: np.ndarray     # float32 height above the table, NaN unknown
    processed_foreground: np.ndarray   # bool: object pixels inside the workspace
    processed_labels: np.ndarray       # uint8 image labels, 0 = background
    processed_pixel_cell: np.ndarray   # int32 flat cell index of each foreground pixel, -1 elsewhere
    grid_origin_xy_m: tuple            # base-frame (x, y) of cell (0, 0)'s centre; row = +x? see cell_xy
    grid_height_m: np.ndarray          # R x C float32 height map (0 = table)
    grid_labels: np.ndarray            # R x C uint8 object labels
    grid_pixel: np.ndarray             # R x C int32 flat image index that gave the cell's height, -1 none
    object_ids: tuple = ()
    areas_m2: dict = field(default_factory=dict)
    depth_m: np.ndarray | None = None             # the full-resolution depth (NaN = no return)
    filled_depth_m: np.ndarray | None = None      # fill_holes of every stride-th pixel (what perceive read)
    filled_k: np.ndarray | None = None            # K of filled_depth_m
    # The table plane's depth at the processed pixels perception read as table (within min_height_m of the
    # plane), NaN elsewhere: the free-space test reads these there, without their noise.
    processed_table_depth_m: np.ndarray | None = None
    depth_noise: DepthNoiseModel = field(default_factory=DepthNoiseModel)   # what the free-space test allows for
    config: TabletopConfig | None = None

    @functools.cached_property
    def height_m(self) -> np.ndarray:
        """HxW float32 height above the table, NaN unknown."""
        return self._full_resolution(self.processed_height_m)

    @functools.cached_property
    def foreground(self) -> np.ndarray:
        """HxW bool: object pixels inside the workspace."""
        return self._full_resolution(self.processed_foreground.view(np.uint8)) > 0

    @functools.cached_property
    def labels(self) -> np.ndarray:
        """HxW uint8 image labels, 0 = background."""
        return self._full_resolution(self.processed_labels)

    @functools.cached_property
    def pixel_cell(self) -> np.ndarray:
        """HxW int32 flat cell index of each foreground pixel, -1 elsewhere."""
        return self._full_resolution(self.processed_pixel_cell)

    def _full_resolution(self, image: np.ndarray) -> np.ndarray:
        if image.shape == self.depth_m.shape:
            return image
        return cv2.resize(image, self.depth_m.shape[::-1], interpolation=cv2.INTER_NEAREST)

    def cell_xy_m(self, row, col):
        """Base-frame (x, y) of a cell centre: rows run along +x, columns along +y."""
        return (self.grid_origin_xy_m[0] + np.asarray(row) * CELL_M,
                self.grid_origin_xy_m[1] + np.asarray(col) * CELL_M)

    def xy_to_cell(self, x_m, y_m):
        return (np.rint((np.asarray(x_m) - self.grid_origin_xy_m[0]) / CELL_M).astype(int),
                np.rint((np.asarray(y_m) - self.grid_origin_xy_m[1]) / CELL_M).astype(int))

    def table_z_at(self, x_m, y_m):
        n, d = self.table_normal, self.table_offset_m
        return -(d + n[0] * x_m + n[1] * y_m) / n[2]


def _pixel_rays(camera_k, shape):
    k = check_camera_matrix(camera_k)
    h, w = shape
    xn = ((np.arange(w) - k[0, 2]) / k[0, 0]).astype(np.float32)
    yn = ((np.arange(h) - k[1, 2]) / k[1, 1]).astype(np.float32)
    return xn, yn


def _base_coordinate(depth, xn, yn, rotation_row, translation):
    """One base-frame coordinate of every pixel: z * (r0 xn + r1 yn + r2) + t (separable, no HxWx3)."""
    return depth * (rotation_row[0] * xn[None, :] + (rotation_row[1] * yn + rotation_row[2])[:, None]) + translation


def check_base_T_camera(base_T_camera) -> np.ndarray:
    t = np.asarray(base_T_camera, dtype=np.float64)
    if t.shape != (4, 4) or not np.all(np.isfinite(t)):
        raise TabletopError(f"base_T_camera must be a finite 4x4 transform, got shape {t.shape}")
    r = t[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or np.linalg.det(r) < 0:
        raise TabletopError("base_T_camera's rotation is not a proper rotation")
    return t


def fit_table(depth, xn, yn, base_T_camera, config: TabletopConfig, rng_seed: int = 0):
    """(unit normal, offset) of the table in the base frame: constrained RANSAC + least squares."""
    h, w = depth.shape
    stride = max(1, int(math.sqrt(h * w / PLANE_SAMPLE_PIXELS)))
    d = depth[::stride, ::stride]
    r, t = base_T_camera[:3, :3], base_T_camera[:3, 3]
    pts = np.stack([_base_coordinate(d, xn[::stride], yn[::stride], r[i], t[i]) for i in range(3)], axis=-1)
    ws = config.workspace
    margin = 0.05
    ok = np.isfinite(d) & (d > 0)
    ok &= (pts[..., 0] > ws.x_m[0] - margin) & (pts[..., 0] < ws.x_m[1] + margin)
    ok &= (pts[..., 1] > ws.y_m[0] - margin) & (pts[..., 1] < ws.y_m[1] + margin)
    ok &= np.abs(pts[..., 2] - config.table_z_m) < config.table_z_tolerance_m
    points = pts[ok].astype(np.float64)
    if len(points) < 50:
        raise TabletopError(f"no table in the workspace: only {len(points)} depth points lie within "
                            f"{config.table_z_tolerance_m} m of the expected table height z = {config.table_z_m} m "
                            "(check base_T_camera and the workspace box)")
    rng = np.random.default_rng(rng_seed)
    triples = points[rng.integers(0, len(points), size=(PLANE_ITERATIONS, 3))]
    normals, offsets = plane_hypotheses(triples, min_cross_norm=1e-9)
    up = np.sign(normals[:, 2] + 1e-12)      # normals point up (an exact sign flip of normal and offset)
    normals *= up[:, None]
    offsets *= up
    upright = normals[:, 2] > math.cos(math.radians(TABLE_MAX_TILT_DEG))
    if not upright.any():
        raise TabletopError("no table plane within 15 degrees of the base's horizontal")
    normals, offsets = normals[upright], offsets[upright]
    counts = np.count_nonzero(np.abs(plane_distances(points, normals, offsets)) < PLANE_INLIER_M, axis=0)
    best = int(np.argmax(counts))
    inliers = points[np.abs(plane_distances(points, normals[best:best + 1], offsets[best:best + 1])[:, 0])
                     < PLANE_INLIER_M]
    centroid = inliers.mean(axis=0)
    centred = inliers - centroid
    _, vectors = np.linalg.eigh(np.einsum("ni,nj->ij", centred, centred))
    normal = vectors[:, 0] * np.sign(vectors[2, 0] + 1e-12)
    if normal[2] < math.cos(math.radians(TABLE_MAX_TILT_DEG)):
        normal, centroid = normals[best], inliers.mean(axis=0)
    return normal, -float(normal @ centroid)


def plane_distances(points, normals, offsets) -> np.ndarray:
    """N x M signed distances of N points to M planes, written out per coordinate: a matmul with an
    inner dimension of 3 goes to multi-threaded BLAS, whose threads cost 5-8 ms a call when the
    cores are busy (measured with the cell's other jobs running), the broadcast ~1 ms."""
    out = points[:, 0, None] * normals[:, 0]
    out += points[:, 1, None] * normals[:, 1]
    out += points[:, 2, None] * normals[:, 2]
    out += offsets
    return out


def processing_stride(camera_k) -> int:
    """Pixels skipped per processed pixel: a 1280x720 D435 frame (fx ~645) is read at every 2nd
    pixel, whose ~1.6 mm footprint at 0.5 m is still finer than the objects' features and about the
    height map's 1.04 mm cells (holes closed); 640x480 and 848x480 frames are read whole."""
    return max(1, int(check_camera_matrix(camera_k)[0, 0] // FULL_RESOLUTION_MAX_FX_PX))


def perceive(depth_m, camera_k, base_T_camera, config: TabletopConfig | None = None,
             robot_mask=None, checkpoint=None) -> TabletopView:
    """The table, the objects in the workspace and their height map (module docstring).
    checkpoint: called between stages (perception on arrival pauses there while a request runs)."""
    config = config or TabletopConfig()
    checkpoint = checkpoint or _no_checkpoint
    full = np.asarray(depth_m, dtype=np.float32)
    if full.ndim != 2 or full.size == 0:
        raise TabletopError(f"depth must be a non-empty HxW image in metres, got shape {full.shape}")
    k_full = check_camera_matrix(camera_k)
    pose = check_base_T_camera(base_T_camera)
    stride = processing_stride(k_full)
    # Holes inside a surface (a dark object's missing returns, speckle) take the surface's depth;
    # stereo shadows take the background's (fill_holes).
    depth = fill_holes(full[::stride, ::stride])
    k = k_full.copy()
    k[:2] /= stride
    xn, yn = _pixel_rays(k, depth.shape)
    normal, offset = fit_table(depth, xn, yn, pose, config)
    checkpoint()
    # Height above the table of every pixel: n . (R p_cam + t) + d, separable in u and v.
    n_cam = (pose[:3, :3].T @ normal).astype(np.float32)
    term = n_cam[0] * xn[None, :] + (n_cam[1] * yn + n_cam[2])[:, None]
    ws = config.workspace
    with np.errstate(invalid="ignore"):
        height = depth * term + np.float32(normal @ pose[:3, 3] + offset)
        candidate = (height > ws.min_height_m) & (height < ws.max_height_m)
    if robot_mask is not None:
        candidate &= ~np.asarray(robot_mask, bool)[::stride, ::stride]
    # Flat pixel indices from here on (a fifth of the frame; 2-D fancy indexing costs twice as much).
    index = np.flatnonzero(candidate)
    index = index[~_flying_at(depth, index, config.jump_m)]
    z = depth.reshape(-1)[index]
    vs, us = np.divmod(index, depth.shape[1])
    r, t = pose[:3, :3].astype(np.float32), pose[:3, 3].astype(np.float32)
    xr, yr = xn[us], yn[vs]
    x = z * (r[0, 0] * xr + r[0, 1] * yr + r[0, 2]) + t[0]
    y = z * (r[1, 0] * xr + r[1, 1] * yr + r[1, 2]) + t[1]
    inside = (x > ws.x_m[0]) & (x < ws.x_m[1]) & (y > ws.y_m[0]) & (y < ws.y_m[1]) \
        & (x * x + y * y > config.robot_keepout_radius_m ** 2)
    index, vs, us, x, y = index[inside], vs[inside], us[inside], x[inside], y[inside]
    hgt = height.reshape(-1)[index]
    empty = x.size == 0
    if empty:     # an empty table: a view without objects (callers that need one say so)
        x, y = np.array([0.5 * sum(ws.x_m)], np.float32), np.array([0.5 * sum(ws.y_m)], np.float32)
        index, vs, us, hgt = (np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64),
                              np.zeros(1, np.float32))
    # The grid covers the objects' extent plus a margin (fingers land beside them), not the whole box.
    margin = GRID_MARGIN_M
    origin = (float(max(ws.x_m[0], x.min() - margin)), float(max(ws.y_m[0], y.min() - margin)))
    rows_n = int(math.ceil((min(ws.x_m[1], x.max() + margin) - origin[0]) / CELL_M)) + 1
    cols_n = int(math.ceil((min(ws.y_m[1], y.max() + margin) - origin[1]) / CELL_M)) + 1
    rows = np.clip(np.rint((x - origin[0]) / CELL_M).astype(np.int32), 0, rows_n - 1)
    cols = np.clip(np.rint((y - origin[1]) / CELL_M).astype(np.int32), 0, cols_n - 1)
    cell = rows * cols_n + cols
    checkpoint()
    full_pixel = (vs * stride) * full.shape[1] + us * stride
    grid, owner = _splat_max(cell, hgt, full_pixel, rows_n * cols_n)
    grid, owner = grid.reshape(rows_n, cols_n), owner.reshape(rows_n, cols_n)
    grid = _close_holes(grid, config.hole_close_cells)
    grid = _fill_seams(grid, config.jump_m)
    checkpoint()
    grid_labels, areas = _segment_grid(grid, config)
    checkpoint()
    # Cells cut at jumps and creases and the side-face points around an object take the nearest
    # object's label within LABEL_REACH_M.
    grid_labels, near_labels = _nearest_labels(grid_labels, grid > 0, grid, config.jump_m, GROW_REACH_M / CELL_M,
                                               LABEL_REACH_M / CELL_M)
    # The cells at the view's border: those of the image's border pixels and the grid's own edges (the box's).
    h_p, w_p = depth.shape
    border_cells = np.zeros(grid.shape, bool)
    border_cells[[0, -1], :] = True
    border_cells[:, [0, -1]] = True
    border_cells.reshape(-1)[cell[(vs == 0) | (vs == h_p - 1) | (us == 0) | (us == w_p - 1)]] = True
    grid_labels, near_labels = _label_leftovers(grid_labels, near_labels, grid, areas, config, border_cells)
    grid_labels, near_labels, areas = _merge_appendages(grid_labels, near_labels, grid, areas)
    at_border = {int(v) for v in np.unique(grid_labels[border_cells])} - {0}
    grid_labels, near_labels, areas = _drop_table_warps(grid_labels, near_labels, grid, areas, at_border, config)
    processed_labels = np.zeros(depth.shape, np.uint8)
    processed_labels.reshape(-1)[index] = near_labels.reshape(-1)[cell]
    processed_fg = np.zeros(depth.shape, bool)
    processed_fg.reshape(-1)[index] = not empty
    pixel_cell = np.full(depth.shape, -1, np.int32)
    pixel_cell.reshape(-1)[index] = -1 if empty else cell
    processed_labels = _with_enclosed_pixels(processed_labels, processed_fg, pixel_cell, depth, xn, yn, r, t, origin,
                                             (rows_n, cols_n))
    table_depth = _table_depth(height, term, np.float32(normal @ pose[:3, 3] + offset), ws.min_height_m)
    noise = _depth_noise(config, height, depth, k_full[0, 0])
    return TabletopView(pose, k_full, normal, offset, height, processed_fg, processed_labels, pixel_cell, origin, grid,
                        grid_labels, owner, tuple(sorted(areas)), areas, full, depth, k, table_depth, noise, config)


def _table_depth(height, term, height_at_zero_depth, min_height_m) -> np.ndarray:
    """The plane's depth (height 0: depth * term + c = 0) at the pixels within min_height_m of it, NaN elsewhere."""
    with np.errstate(invalid="ignore", divide="ignore"):
        table = np.abs(height) < min_height_m
        return np.where(table, -height_at_zero_depth / term, np.float32(np.nan)).astype(np.float32)


# Table pixels sampled for the measured noise (every n-th of each axis).
NOISE_SAMPLE_STRIDE = 4


def _depth_noise(config: TabletopConfig, height, depth, fx_px: float) -> DepthNoiseModel:
    """config.depth_noise, or with depth_noise_from_table the same baseline with the subpixel RMS the table's
    residuals show (robust RMS of the heights within PLANE_INLIER_M of the plane, at their median depth)."""
    if not config.depth_noise_from_table:
        return config.depth_noise
    h = height[::NOISE_SAMPLE_STRIDE, ::NOISE_SAMPLE_STRIDE]
    with np.errstate(invalid="ignore"):
        on_table = np.abs(h) < PLANE_INLIER_M
    if np.count_nonzero(on_table) < 50:
        return config.depth_noise
    z = float(np.median(depth[::NOISE_SAMPLE_STRIDE, ::NOISE_SAMPLE_STRIDE][on_table]))
    return config.depth_noise.measured(robust_rms_m(h[on_table]), z, fx_px)


def partly_seen_objects(view: TabletopView) -> set:
    """The labels of objects the camera sees only in part: with a pixel on the image's border, or next to
    the start of a row's returns (the stereo camera's left invalid band: fill_holes leaves it empty).
    Their extent beyond the cut is unknown (a plate under the robot, a hand hanging into view, an object
    half out of the frame), so planning ranks their grasps after those on objects seen whole."""
    labels = view.processed_labels
    if not view.object_ids:
        return set()
    edge = np.zeros(labels.shape, bool)
    edge[[0, -1], :] = True
    edge[:, [0, -1]] = True
    if view.filled_depth_m is not None:
        valid = np.isfinite(view.filled_depth_m)
        first = np.where(valid.any(axis=1), np.argmax(valid, axis=1), 0)
        cols = np.arange(labels.shape[1])[None, :]
        edge |= (cols >= first[:, None]) & (cols <= first[:, None] + 1)
    return {int(v) for v in np.unique(labels[edge]) if v}


def _no_checkpoint() -> None:
    pass


def _nearest_labels(labels: np.ndarray, occupied: np.ndarray, grid: np.ndarray, jump_m: float,
                    grow_cells: float, reach_cells: float) -> tuple:
    """(grid labels, labels for pixels), from one distance transform to the nearest labelled cell.
    Grid: occupied cells without a label take the nearest one's within grow_cells when their height
    differs from that cell's by at most jump_m per cell of distance (they continue its surface: cells
    cut at noise steps, not a neighbour's wall). Pixels: any occupied cell within reach_cells takes it
    (an object's side faces scatter a few millimetres around its outline)."""
    background = labels == 0
    flat_labels = labels.reshape(-1)
    # Flat indices of the occupied cells without a label (a few per cent of the grid).
    cells = np.flatnonzero(occupied.reshape(-1) & background.reshape(-1))
    if cells.size == 0 or background.all():
        return labels, labels
    distance, index = cv2.distanceTransformWithLabels(background.view(np.uint8), cv2.DIST_L2, 3,
                                                      labelType=cv2.DIST_LABEL_PIXEL)
    # DIST_LABEL_PIXEL numbers the zero-valued pixels of the source (our labelled cells) in raster order.
    sources = np.concatenate([[0], np.flatnonzero(flat_labels)])
    d = distance.reshape(-1)[cells]
    near = d <= max(grow_cells, reach_cells)
    cells, d = cells[near], d[near]
    source = sources[index.reshape(-1)[cells]]
    flat_grid = grid.reshape(-1)
    continues = (d <= grow_cells) & (np.abs(flat_grid[cells] - flat_grid[source]) <= jump_m * np.maximum(d, 1.0))
    grown = labels.copy()
    grown.reshape(-1)[cells[continues]] = flat_labels[source[continues]]
    for_pixels = grown.copy()
    reach = (d <= reach_cells) & ~continues
    for_pixels.reshape(-1)[cells[reach]] = flat_labels[source[reach]]
    return grown, for_pixels


def _label_leftovers(labels: np.ndarray, for_pixels: np.ndarray, grid: np.ndarray, areas: dict,
                     config: TabletopConfig, border_cells: np.ndarray) -> tuple:
    """Occupied cells that no object reached, in groups that touch no object, of at least min_object_area_m2:
    objects too, each group one (areas gets theirs). They are objects without a flat core that the jump and
    crease cuts leave: a thin-walled cup or bowl (rim, walls and inner bottom all cut), a mug's outer wall seen
    from the side. A group touching one object joins it when it encloses it or is larger (_joins); other groups
    touching objects stay unlabelled (their flanks, as before). Each group is looked at in its own box."""
    rest = (grid > 0) & (labels == 0)
    if not rest.any() or len(areas) >= MAX_LABELS:
        return labels, for_pixels
    count, groups = cv2.connectedComponents(rest.view(np.uint8), connectivity=8)
    sizes = np.bincount(groups.reshape(-1), minlength=count)
    min_cells = config.min_object_area_m2 / (CELL_M * CELL_M)
    # Per group the highest and lowest label next to it (one label: they agree; none: 0 and 255).
    near_hi = cv2.dilate(labels, np.ones((3, 3), np.uint8))
    near_lo = cv2.erode(np.where(labels > 0, labels, 255).astype(np.uint8), np.ones((3, 3), np.uint8))
    flat = groups.reshape(-1)
    edge = np.flatnonzero((flat > 0) & (near_hi.reshape(-1) > 0))
    hi = np.zeros(count, np.int32)
    lo = np.full(count, 255, np.int32)
    np.maximum.at(hi, flat[edge], near_hi.reshape(-1)[edge])
    np.minimum.at(lo, flat[edge], near_lo.reshape(-1)[edge])
    cut = np.zeros(count, bool)
    cut[np.unique(groups[border_cells])] = True
    lut = np.zeros(count, np.uint8)
    new = []
    pad = RIM_GAP_CELLS + 1
    for g in range(1, count):
        if sizes[g] < JOIN_MIN_SHARE * min_cells:
            continue                                # specks of flank: as before
        window = _box(groups == g, pad)
        mine = groups[window] == g
        if hi[g] > 0:
            if hi[g] == lo[g] and _joins(mine, labels[window] == hi[g], int(sizes[g]), labels == hi[g]):
                lut[g] = hi[g]
        # Not cut by the view's border, not rising to the box's ceiling (the robot's base, a shelf: structures
        # seen in part), not a sliver (a rim counts with what it holds).
        elif not cut[g] and sizes[g] >= min_cells \
                and float(grid[window][mine].max()) < config.workspace.max_height_m - LEFTOVER_CEILING_M \
                and _width_m(_filled(mine)) >= LEFTOVER_MIN_WIDTH_M:
            new.append(g)
    if not new and not lut.any():
        return labels, for_pixels
    for g in sorted(new, key=lambda g: -sizes[g])[:MAX_LABELS - len(areas)]:
        lut[g] = len(areas) + 1
        areas[len(areas) + 1] = float(sizes[g]) * CELL_M * CELL_M
    extra = lut[groups]
    return np.where(extra > 0, extra, labels), np.where(extra > 0, extra, for_pixels)


def _box(mask: np.ndarray, pad: int) -> tuple:
    """(row slice, column slice) of a mask's bounding box grown by pad cells (clipped to the image)."""
    x, y, w, h = cv2.boundingRect(mask.view(np.uint8))
    return slice(max(0, y - pad), y + h + pad), slice(max(0, x - pad), x + w + pad)


def _joins(group: np.ndarray, object_in_window: np.ndarray, group_cells: int, object_cells: np.ndarray) -> bool:
    """Does a group of unlabelled cells belong to the one object it touches (a cup's rim and walls around its
    inner bottom)? When it is larger than the object (a bowl's walls around a speck of its bottom that survived
    the cuts) or encloses at least 90 % of it (the object lies within the group's window then)."""
    total = int(np.count_nonzero(object_cells))
    if group_cells > total:
        return True
    inside = int(np.count_nonzero(object_in_window))
    return inside >= 0.9 * total and np.count_nonzero(_filled(group) & object_in_window) >= 0.9 * total


def _filled(mask: np.ndarray) -> np.ndarray:
    """The mask with its holes filled (a cup's rim with its inside), gaps up to RIM_GAP_CELLS in its outline
    bridged (a rim broken by a stereo shadow or dropouts)."""
    closed = cv2.morphologyEx(mask.view(np.uint8), cv2.MORPH_CLOSE, _RIM_KERNEL)
    contours, _ = cv2.findContours(closed, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    out = np.zeros(mask.shape, np.uint8)
    cv2.drawContours(out, contours, -1, 1, thickness=cv2.FILLED)
    return out > 0


def _with_enclosed_pixels(labels, foreground, pixel_cell, depth, xn, yn, r, t, origin, grid_shape) -> np.ndarray:
    """fill_enclosed(labels), the pixels it adds made foreground with their height-map cell (in place), so every
    labelled pixel has a cell, as every other one does; added pixels without a depth stay unlabelled."""
    filled = fill_enclosed(labels)
    added = np.flatnonzero((filled != labels).reshape(-1))
    if added.size == 0:
        return labels
    z = depth.reshape(-1)[added]
    seen = np.isfinite(z)
    filled.reshape(-1)[added[~seen]] = 0
    added, z = added[seen], z[seen]
    vs, us = np.divmod(added, depth.shape[1])
    x = z * (r[0, 0] * xn[us] + r[0, 1] * yn[vs] + r[0, 2]) + t[0]
    y = z * (r[1, 0] * xn[us] + r[1, 1] * yn[vs] + r[1, 2]) + t[1]
    rows = np.clip(np.rint((x - origin[0]) / CELL_M).astype(np.int32), 0, grid_shape[0] - 1)
    cols = np.clip(np.rint((y - origin[1]) / CELL_M).astype(np.int32), 0, grid_shape[1] - 1)
    pixel_cell.reshape(-1)[added] = rows * grid_shape[1] + cols
    foreground.reshape(-1)[added] = True
    return filled


def fill_enclosed(labels: np.ndarray) -> np.ndarray:
    """_fill_enclosed, then again with the outlines closed over gaps of a few pixels (a rim broken by a shadow
    still encloses its inside); worked in the labelled pixels' bounding box (nothing outside it is enclosed)."""
    if not labels.any():
        return labels
    box = _box(labels > 0, 1)
    out = labels.copy()
    out[box] = _fill_enclosed(_fill_enclosed(labels[box], False), True)
    return out


def _fill_enclosed(labels: np.ndarray, close_gaps: bool) -> np.ndarray:
    """Image labels with every unlabelled region that one object alone encloses given that object's label: the
    inside of a hollow object seen from above (the inner bottom of a cup or bowl, lower than the minimum object
    height), missing returns inside an object. A region bordered by several objects (a gap between them, one
    inside a bin's floor next to an object) stays as it is."""
    labelled = (labels > 0).view(np.uint8)
    if close_gaps:
        labelled = cv2.morphologyEx(labelled, cv2.MORPH_CLOSE, _RIM_KERNEL)
    free = (labelled == 0).view(np.uint8)
    count, regions = cv2.connectedComponents(free, connectivity=4)
    if count <= 2:
        return labels
    border = np.unique(np.concatenate([regions[0], regions[-1], regions[:, 0], regions[:, -1]]))
    enclosed = np.ones(count, bool)
    enclosed[border] = False
    enclosed[0] = False                         # labelled pixels
    if not enclosed.any():
        return labels
    # Each enclosed region's neighbouring labels: a region takes a label when every labelled pixel next to it
    # carries that one.
    grown_max = cv2.dilate(labels, _CROSS_3X3)
    grown_min = cv2.erode(np.where(labels > 0, labels, 255).astype(np.uint8), _CROSS_3X3)
    index = regions.reshape(-1)
    pick = enclosed[index] & (grown_max.reshape(-1) > 0)       # the regions' pixels next to a label
    hi = np.zeros(count, np.int32)
    lo = np.full(count, 255, np.int32)
    np.maximum.at(hi, index[pick], grown_max.reshape(-1)[pick])
    np.minimum.at(lo, index[pick], grown_min.reshape(-1)[pick])
    lut = np.where(enclosed & (hi == lo) & (hi > 0) & (hi < 255), hi, 0).astype(np.uint8)
    extra = lut[regions]
    return np.where((extra > 0) & (labels == 0), extra, labels)


def _width_m(mask: np.ndarray) -> float:
    """Twice the largest inscribed radius of a cell mask (m): the width of a strip, the diameter of a disc."""
    return 2.0 * float(cv2.distanceTransform(np.pad(mask, 1).view(np.uint8), cv2.DIST_L2, 3).max()) * CELL_M


def _merge_appendages(labels: np.ndarray, for_pixels: np.ndarray, grid: np.ndarray, areas: dict) -> tuple:
    """(grid labels, pixel labels, areas) with each appendage (APPENDAGE_MAX_WIDTH_M) merged into the object it
    hangs on, labels renumbered 1..N in their order. Touching distinct objects are wider, or not lower and
    smaller than their neighbour (a can against a cereal box, a block against a sponge), and stay apart."""
    if len(areas) < 2:
        return labels, for_pixels, areas
    gap = max(1, int(round(APPENDAGE_GAP_M / CELL_M)))
    near = np.ones((2 * gap + 1, 2 * gap + 1), np.uint8)
    counts = np.bincount(labels.reshape(-1), minlength=256)
    size = {label: int(counts[label]) for label in areas}
    height = {}
    target = {}
    for label in sorted(areas, key=lambda lab: size[lab]):
        if not size[label]:
            continue
        whole = labels == label
        box = _box(whole, gap + 1)
        mask, around_labels = whole[box], labels[box]
        height[label] = float(np.median(grid[box][mask]))
        if _width_m(mask) >= APPENDAGE_MAX_WIDTH_M:
            continue
        around = np.unique(around_labels[(cv2.dilate(mask.view(np.uint8), near) > 0) & ~mask])
        around = [int(a) for a in around if a and a != label]
        if len(around) == 1:
            host = around[0]
            if host not in height:
                height[host] = float(np.median(grid[labels == host]))
            if size[label] < APPENDAGE_MAX_AREA_SHARE * size[host] and height[label] < height[host]:
                target[label] = host
    return _relabel(labels, for_pixels, areas, target)


def _relabel(labels: np.ndarray, for_pixels: np.ndarray, areas: dict, target: dict) -> tuple:
    """(grid labels, pixel labels, areas) with each label in target merged into target[label] (0: dropped),
    the others renumbered 1..N in their order."""
    if not target:
        return labels, for_pixels, areas

    def root(label):
        while target.get(label):
            label = target[label]
        return label
    kept = [label for label in sorted(areas) if label not in target]
    lut = np.zeros(256, np.uint8)
    for new, label in enumerate(kept, start=1):
        lut[label] = new
    for label in target:
        lut[label] = lut[root(label)] if target[label] else 0
    merged = {}
    for label, area in areas.items():
        if lut[label]:
            merged[int(lut[label])] = merged.get(int(lut[label]), 0.0) + area
    return lut[labels], lut[for_pixels], merged


def _drop_table_warps(labels: np.ndarray, for_pixels: np.ndarray, grid: np.ndarray, areas: dict, at_border: set,
                      config: TabletopConfig) -> tuple:
    """_relabel without the objects that are the table itself rising above the fitted plane at the view's edge
    (a slightly curved or tilted table, 1-2 cm high along its far edge): regions cut by the image's or the
    workspace's border whose outline against the table stands less than WARP_OUTLINE_STEP_M above the
    minimum object height, i.e. a surface that rises out of the table without a wall. Every object has a wall
    at its outline (a 1.5 cm block's outline cells: 14 mm; a warped table's: 6-7 mm)."""
    if not at_border:
        return labels, for_pixels, areas
    empty_near = cv2.dilate((grid <= 0).view(np.uint8), _CROSS_3X3) > 0
    step = config.workspace.min_height_m + WARP_OUTLINE_STEP_M
    target = {}
    for label in at_border & set(areas):
        outline = (labels == label) & empty_near
        if outline.any() and float(np.median(grid[outline])) < step:
            target[label] = 0
    return _relabel(labels, for_pixels, areas, target)


def fill_holes(depth_m: np.ndarray) -> np.ndarray:
    """Depth with its holes filled along the rows. A stereo camera whose left imager is the depth
    reference leaves a shadow (no return) just left of a foreground edge, over background: a hole
    whose nearest valid pixel on the right is nearer than the one on the left by more than
    SHADOW_JUMP_M takes the left (background) depth. Any other hole (speckle, a dark object's missing
    returns) takes the nearer of its two neighbours, so it is never emptier than what surrounds it.
    Rows without any return stay NaN, and so do holes at a row's left end: that is the D4xx's left invalid
    band (what the right imager cannot see, fB/z pixels wide), unseen space, not a surface to extend.

    Worked per run of invalid pixels (a run has one left and one right neighbour), not per pixel:
    a frame has ~1e4 runs and ~5e4 invalid pixels among its 3e5."""
    depth = np.asarray(depth_m, np.float32)
    with np.errstate(invalid="ignore"):
        valid = (depth > 0) & (depth < np.inf)       # NaN compares False: finite and positive
    if valid.all():
        return depth
    h, w = depth.shape
    # Each row framed by one valid column on either side, so no run crosses a row.
    holes = np.zeros((h, w + 2), bool)
    np.logical_not(valid, out=holes[:, 1:-1])
    flat = holes.reshape(-1)
    edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    starts, ends = edges[0::2], edges[1::2]            # [start, end) in the framed raster
    row = starts // (w + 2)
    left_col = starts - row * (w + 2) - 2               # the pixel left of the run, -1: none
    right_col = ends - row * (w + 2) - 1                # the pixel right of the run, w: none
    nan = np.float32(np.nan)
    left_depth = np.where(left_col >= 0, depth[row, np.maximum(left_col, 0)], nan)
    right_depth = np.where(right_col < w, depth[row, np.minimum(right_col, w - 1)], nan)
    with np.errstate(invalid="ignore"):
        shadow = right_depth < left_depth - SHADOW_JUMP_M
    fill = np.where(shadow, left_depth, np.fmin(left_depth, right_depth))
    fill[left_col < 0] = nan                            # the left invalid band (docstring)
    out = depth.copy()
    out[~valid] = np.repeat(fill, ends - starts)
    return out


def flying_pixels(depth: np.ndarray, jump_m: float) -> np.ndarray:
    """Pixels whose depth lies between their 3x3 neighbours' extremes, far from both: the mixed
    foreground/background returns a stereo camera gives at depth edges (they float in mid-air)."""
    depth = np.asarray(depth, np.float32)
    return _flying_at(depth, np.arange(depth.size), jump_m).reshape(depth.shape)


def _flying_at(depth: np.ndarray, index: np.ndarray, jump_m: float) -> np.ndarray:
    """flying_pixels(depth, jump_m) at the flat pixel indices `index` only."""
    valid_all = depth.min() > 0      # NaN propagates through min: no NaN and no pixel <= 0
    flat = depth.reshape(-1)
    z = flat[index]
    with np.errstate(invalid="ignore"):
        valid = (z > 0) & (z < np.inf)
    kernel = np.ones((3, 3), np.uint8)
    if valid_all:
        high, low = cv2.dilate(depth, kernel), cv2.erode(depth, kernel)
    else:
        valid_map = np.isfinite(depth) & (depth > 0)
        high = cv2.dilate(np.where(valid_map, depth, 0).astype(np.float32), kernel)
        low = cv2.erode(np.where(valid_map, depth, np.inf).astype(np.float32), kernel)
    with np.errstate(invalid="ignore"):
        return valid & (z - low.reshape(-1)[index] > jump_m) & (high.reshape(-1)[index] - z > jump_m)


def _splat_max(cell, value, pixel, n_cells):
    """Per cell the maximum value and a pixel that gave it (np.maximum.at: ~1 ms for 1e5 points)."""
    grid = np.zeros(n_cells, np.float32)
    np.maximum.at(grid, cell, value.astype(np.float32))
    owner = np.full(n_cells, -1, np.int32)
    top = value >= grid[cell]
    owner[cell[top]] = pixel[top]
    return grid, owner


def _close_holes(grid: np.ndarray, size_cells: int) -> np.ndarray:
    """Fill empty cells (0) enclosed by object cells with the highest neighbour: the cells between the
    splatted points of a coarse or tilted camera, dropouts on dark parts, flying-pixel gaps."""
    if size_cells < 2:
        return grid
    occupied = (grid > 0).astype(np.uint8)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size_cells, size_cells))
    closed = cv2.morphologyEx(occupied, cv2.MORPH_CLOSE, kernel) > 0
    out = grid.copy()
    fill = closed & (grid <= 0)
    if fill.any():
        # Grey closing: the holes get the level of the surface around them.
        grey = cv2.morphologyEx(grid, cv2.MORPH_CLOSE, kernel)
        out[fill] = grey[fill]
    return out


_SEAM_KERNELS = (np.ones((1, 3), np.uint8), np.ones((3, 1), np.uint8))


def _fill_seams(grid: np.ndarray, jump_m: float) -> np.ndarray:
    """Occupied cells more than jump_m lower than both their neighbours on either side along a row or a column
    (a one-cell valley that would cut a surface) raised to the lower of the two: the seams a tilted camera
    leaves in a surface it sees at a grazing angle, where a cell got only the points of a lower surface seen
    past an overhang (a drill's body over its battery cut in three by them). Empty cells (the table) stay
    empty: a gap between objects is not filled."""
    out = grid
    for kernel in _SEAM_KERNELS:
        closed = cv2.morphologyEx(grid, cv2.MORPH_CLOSE, kernel)
        out = np.maximum(out, np.where((grid > 0) & (closed - grid > jump_m), closed, np.float32(0.0)))
    return out


def _segment_grid(grid: np.ndarray, config: TabletopConfig):
    """Labels of the height map: connected cells without a height jump > jump_m between them. The
    lower cell of every jump is cut first, then given back to its neighbours of similar height."""
    # A cell is the lower side of a jump when its highest 4-neighbour stands more than jump_m above it
    # (max(n) - c > jump exactly when some n - c > jump: rounding is monotonic).
    highest = cv2.dilate(grid, _CROSS_3X3, borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
    cut = highest - grid > config.jump_m
    smooth = cv2.GaussianBlur(grid, (0, 0), 1.5)
    gv, gu = np.gradient(smooth, CELL_M)
    cut |= gv * gv + gu * gu > CREASE_SLOPE ** 2
    core = (grid > 0) & ~cut
    count, raw = cv2.connectedComponents(core.view(np.uint8), connectivity=4)
    sizes = np.bincount(raw.reshape(-1), minlength=count)
    min_cells = config.min_object_area_m2 / (CELL_M * CELL_M)
    keep = [i for i in range(1, count) if sizes[i] >= min_cells * 0.5]
    keep = sorted(keep, key=lambda i: -sizes[i])[:MAX_LABELS]
    # Labels 1.. in the components' order, for those of at least min_object_area_m2.
    lut = np.zeros(count, np.uint8)
    areas = {}
    for old in sorted(keep):
        area = int(sizes[old]) * CELL_M * CELL_M
        if area >= config.min_object_area_m2:
            lut[old] = len(areas) + 1
            areas[len(areas) + 1] = area
    return lut[raw], areas
