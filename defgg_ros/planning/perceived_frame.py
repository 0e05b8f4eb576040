"""A perceived frame as plain arrays and back (no rclpy): what the segmentation node sends the inference node.

The segmentation node is the only node that perceives (docs/perception.md, "One perceiver"). It runs
`perceive_frame` (the robot self-filter, tabletop perception, the stiffness entries) and sends the result as a
`defgg_interfaces/PerceivedObjects` (nodes/perceived_msg.py converts `PerceivedParts` to and from it). The
inference node rebuilds the planner's TabletopView from those parts and the frame's depth
(`view_from_parts`) without perceiving again: the table plane, the full-resolution label image and the height
map (heights, labels, the pixel behind each cell, the modulus per cell) are taken as sent; the hole-filled
depth the free-space test reads is recomputed from the depth with the same function, so the grasps are the
ones planning on the segmentation node's own view gives (test/perception/test_perceived_frame.py).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from defgg_ros.perception.depth_noise import DepthNoiseModel
from defgg_ros.perception.geometry import check_camera_matrix
from defgg_ros.perception.stiffness_assignment import assign_stiffness
from defgg_ros.perception.tabletop import (
    CELL_M,
    TabletopConfig,
    TabletopView,
    WorkspaceBox,
    fill_holes,
    partly_seen_objects,
    perceive,
    processing_stride,
)
from defgg_ros.planning.tabletop_grasps import grid_moduli

# Cells without an own modulus (no pixel behind them) take their object's median in grid_moduli; a view
# rebuilt from parts has one on every object cell, so this default is never used for them.
REBUILT_DEFAULT_PA = 2e6


@dataclass(frozen=True)
class ObjectSummary:
    """One perceived object as PerceivedObject carries it."""
    label: int
    name: str                    # the stiffness entry's name ("default": none addressed it)
    youngs_modulus_pa: float     # its whole-object modulus
    roi_px: tuple                # (x, y, width, height) bounding box in the depth image
    height_m: float
    area_m2: float
    area_px: int
    partly_seen: bool


@dataclass(frozen=True)
class PerceivedParts:
    """One perceived frame: everything planning needs besides the depth and K (module docstring)."""
    base_T_camera: np.ndarray        # 4x4, camera optical frame in the pose frame
    table_plane: tuple               # (n_x, n_y, n_z, d) in the pose frame
    labels: np.ndarray               # HxW uint8, the depth's size
    objects: tuple                   # ObjectSummary, by label
    grid_origin_xy_m: tuple
    grid_height_m: np.ndarray        # R x C float32
    grid_labels: np.ndarray          # R x C uint8
    grid_pixel: np.ndarray           # R x C int32 flat full-resolution pixel index, -1 none
    grid_youngs_modulus_pa: np.ndarray   # R x C float32
    workspace_box_m: tuple = (0.22, 0.85, -0.40, 0.40)   # x_min, x_max, y_min, y_max in the pose frame
    object_height_range_m: tuple = (0.006, 0.25)         # min, max above the table
    depth_noise: tuple = (0.050, 0.08)                    # stereo baseline (m), subpixel RMS (px)
    cell_m: float = CELL_M

    @property
    def object_ids(self) -> tuple:
        return tuple(o.label for o in self.objects)


def perceive_frame(depth_m, camera_k, base_T_camera, config: TabletopConfig, entries=(),
                   default_youngs_modulus_pa: float = 2e6, robot_mask=None, checkpoint=None):
    """(PerceivedParts, TabletopView, youngs_modulus_pa image): tabletop perception and the stiffness entries
    (assigned by each object's centroid, region entries painted on their pixels). Raises TabletopError (no
    table...). A frame without objects is a valid perception (objects empty)."""
    view = perceive(depth_m, camera_k, base_T_camera, config, robot_mask, checkpoint)
    labels = view.labels
    boxes, centroids, pixels = _label_geometry(labels, view.object_ids)
    image, per_object = assign_stiffness(labels, centroids, entries, default_youngs_modulus_pa)
    moduli = grid_moduli(view, image, default_youngs_modulus_pa)
    partly = partly_seen_objects(view)
    objects = []
    for label in view.object_ids:
        name, modulus = per_object.get(label, ("default", default_youngs_modulus_pa))
        on = view.grid_labels == label
        objects.append(ObjectSummary(int(label), str(name), float(modulus), boxes.get(label, (0, 0, 0, 0)),
                                     float(view.grid_height_m[on].max()) if on.any() else 0.0,
                                     float(view.areas_m2.get(label, 0.0)), int(pixels.get(label, 0)),
                                     label in partly))
    ws = config.workspace
    noise = getattr(view, "depth_noise", None) or getattr(config, "depth_noise", None) or DepthNoiseModel()
    parts = PerceivedParts(np.asarray(view.base_T_camera, float), (*map(float, view.table_normal),
                                                                   float(view.table_offset_m)),
                           labels, tuple(objects), tuple(float(v) for v in view.grid_origin_xy_m),
                           view.grid_height_m, view.grid_labels, view.grid_pixel, moduli,
                           (*map(float, ws.x_m), *map(float, ws.y_m)), (float(ws.min_height_m), float(ws.max_height_m)),
                           (float(noise.baseline_m), float(noise.subpixel_rms_px)))
    return parts, view, image


def _label_geometry(labels: np.ndarray, object_ids):
    """label -> (x, y, w, h) box, label -> (u, v) centroid, label -> pixel count.
    One pass over the image (the labelled pixels grouped by a stable sort, so each label's pixels stay in raster
    order and the centroids are bit for bit those of np.nonzero(labels == label)): a 1280x720 frame's eight
    per-label scans took ~17 ms of perception's ~46."""
    boxes, centroids, pixels = {}, {}, {}
    index = np.flatnonzero(labels)
    values = labels.reshape(-1)[index]
    order = np.argsort(values, kind="stable")
    index, values = index[order], values[order]
    wanted = np.asarray(object_ids, values.dtype)
    starts, ends = np.searchsorted(values, wanted, "left"), np.searchsorted(values, wanted, "right")
    for label, start, end in zip(object_ids, starts, ends):
        vs, us = np.divmod(index[start:end], labels.shape[1])
        if vs.size:
            boxes[int(label)] = (int(us.min()), int(vs.min()), int(us.max() - us.min() + 1),
                                 int(vs.max() - vs.min() + 1))
            centroids[int(label)] = (float(us.mean()), float(vs.mean()))
            pixels[int(label)] = int(vs.size)
    return boxes, centroids, pixels


def check_parts_fit(parts: PerceivedParts, depth_shape) -> None:
    """ValueError unless the parts belong to a depth image of this shape (sizes, indices, labels)."""
    if parts.labels.shape != tuple(depth_shape):
        raise ValueError(f"the perceived label image is {parts.labels.shape[1]}x{parts.labels.shape[0]} but the "
                         f"depth is {depth_shape[1]}x{depth_shape[0]}")
    grids = (parts.grid_height_m, parts.grid_labels, parts.grid_pixel, parts.grid_youngs_modulus_pa)
    if len({g.shape for g in grids}) != 1 or parts.grid_height_m.ndim != 2:
        raise ValueError(f"the perceived height map's images differ in size: {[g.shape for g in grids]}")
    if parts.grid_pixel.size and int(parts.grid_pixel.max()) >= depth_shape[0] * depth_shape[1]:
        raise ValueError("the perceived height map points at pixels outside the depth image")
    known = set(parts.object_ids)
    stray = set(np.unique(parts.grid_labels).tolist()) - known - {0}
    if stray:
        raise ValueError(f"the perceived height map has labels {sorted(stray)} that no object carries")
    if abs(parts.cell_m - CELL_M) > 1e-12:
        raise ValueError(f"the perceived height map's cells are {parts.cell_m} m; this planner's are {CELL_M} m")


def view_from_parts(parts: PerceivedParts, depth_m, camera_k, grasp_height_rule: str = "half_height",
                    grasp_depth_below_surface_m: float = 0.018) -> TabletopView:
    """The TabletopView planning reads, rebuilt from a perceived frame and its depth (no perception).
    grasp_height_rule, grasp_depth_below_surface_m: the executor's (the grasp search puts the fingertips where
    the executor will; PerceivedObjects does not carry them: the inference node's parameters)."""
    full = np.asarray(depth_m, np.float32)
    check_parts_fit(parts, full.shape)
    k_full = check_camera_matrix(camera_k)
    stride = processing_stride(k_full)
    depth = fill_holes(full[::stride, ::stride])
    k = k_full.copy()
    k[:2] /= stride
    processed_labels = np.ascontiguousarray(parts.labels[::stride, ::stride])
    normal = np.asarray(parts.table_plane[:3], float)
    pose = np.asarray(parts.base_T_camera, float)
    height = _heights(depth, k, pose, normal, float(parts.table_plane[3]))
    pixel_cell = _pixel_cells(depth, k, pose, processed_labels, parts)
    view = TabletopView(pose, k_full, normal, float(parts.table_plane[3]), height, pixel_cell >= 0,
                        processed_labels, pixel_cell, parts.grid_origin_xy_m, parts.grid_height_m,
                        parts.grid_labels, parts.grid_pixel, parts.object_ids,
                        {o.label: o.area_m2 for o in parts.objects}, full, depth, k)
    config = config_of(parts, grasp_height_rule, grasp_depth_below_surface_m)
    return _with_planning_inputs(view, parts, height, config)


def config_of(parts: PerceivedParts, grasp_height_rule: str = "half_height",
              grasp_depth_below_surface_m: float = 0.018) -> TabletopConfig:
    """The TabletopConfig fields planning reads: the workspace box and the depth noise as perception had them,
    the executor's grasp height rule (ValueError for an unknown rule)."""
    x0, x1, y0, y1 = parts.workspace_box_m
    workspace = WorkspaceBox((x0, x1), (y0, y1), *parts.object_height_range_m)
    return TabletopConfig(workspace=workspace, depth_noise=DepthNoiseModel(*parts.depth_noise),
                          grasp_height_rule=grasp_height_rule,
                          grasp_depth_below_surface_m=float(grasp_depth_below_surface_m))


def _with_planning_inputs(view: TabletopView, parts: PerceivedParts, height, config: TabletopConfig) -> TabletopView:
    """The view's fields for the free-space test and the workspace check, where this TabletopView has them:
    the table plane's depth at the pixels read as table, the depth noise, the configuration."""
    names = {f.name for f in dataclasses.fields(TabletopView)}
    extra = {}
    if "processed_table_depth_m" in names:
        extra["processed_table_depth_m"] = _table_depth(view, height, parts.object_height_range_m[0])
    if "depth_noise" in names:
        extra["depth_noise"] = DepthNoiseModel(*parts.depth_noise)
    if "config" in names:
        extra["config"] = config
    return dataclasses.replace(view, **extra) if extra else view


def _table_depth(view: TabletopView, height, min_height_m: float) -> np.ndarray:
    """The plane's depth (height 0) at the read pixels within min_height_m of it, NaN elsewhere: perception's."""
    xn, yn = _rays(view.filled_k, height.shape)
    pose, normal = view.base_T_camera, view.table_normal
    n_cam = (pose[:3, :3].T @ normal).astype(np.float32)
    term = n_cam[0] * xn[None, :] + (n_cam[1] * yn + n_cam[2])[:, None]
    at_zero_depth = np.float32(normal @ pose[:3, 3] + view.table_offset_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        table = np.abs(height) < min_height_m
        return np.where(table, -at_zero_depth / term, np.float32(np.nan)).astype(np.float32)


def moduli_image(parts: PerceivedParts, shape) -> np.ndarray:
    """A depth-sized modulus image with each cell's modulus at the pixel behind it: planning's grid_moduli
    reads back exactly the perceived moduli per cell."""
    image = np.zeros(shape, np.float32)
    behind = parts.grid_pixel >= 0
    image.reshape(-1)[parts.grid_pixel[behind]] = parts.grid_youngs_modulus_pa[behind]
    return image


def _rays(k, shape):
    h, w = shape
    return (((np.arange(w) - k[0, 2]) / k[0, 0]).astype(np.float32),
            ((np.arange(h) - k[1, 2]) / k[1, 1]).astype(np.float32))


def _heights(depth, k, pose, normal, offset) -> np.ndarray:
    """Height above the table of every read pixel (float32, NaN unknown), as perception computes it."""
    xn, yn = _rays(k, depth.shape)
    n_cam = (pose[:3, :3].T @ normal).astype(np.float32)
    term = n_cam[0] * xn[None, :] + (n_cam[1] * yn + n_cam[2])[:, None]
    with np.errstate(invalid="ignore"):
        return depth * term + np.float32(normal @ pose[:3, 3] + offset)


def _pixel_cells(depth, k, pose, processed_labels, parts: PerceivedParts) -> np.ndarray:
    """The height-map cell under each labelled read pixel (-1 elsewhere): for the quality image only."""
    out = np.full(depth.shape, -1, np.int32)
    index = np.flatnonzero(processed_labels)
    if index.size == 0:
        return out
    xn, yn = _rays(k, depth.shape)
    vs, us = np.divmod(index, depth.shape[1])
    z = depth.reshape(-1)[index]
    r, t = pose[:3, :3].astype(np.float32), pose[:3, 3].astype(np.float32)
    x = z * (r[0, 0] * xn[us] + r[0, 1] * yn[vs] + r[0, 2]) + t[0]
    y = z * (r[1, 0] * xn[us] + r[1, 1] * yn[vs] + r[1, 2]) + t[1]
    rows_n, cols_n = parts.grid_height_m.shape
    with np.errstate(invalid="ignore"):
        rows = np.rint((x - parts.grid_origin_xy_m[0]) / CELL_M)
        cols = np.rint((y - parts.grid_origin_xy_m[1]) / CELL_M)
    inside = np.isfinite(rows) & np.isfinite(cols) & (rows >= 0) & (rows < rows_n) & (cols >= 0) & (cols < cols_n)
    out.reshape(-1)[index[inside]] = (rows[inside] * cols_n + cols[inside]).astype(np.int32)
    return out
