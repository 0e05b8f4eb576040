"""Table removal and object masks from one depth image (no rclpy).

Background model. Two options, chosen per call:
1. Table plane fit (default): the valid pixels are back-projected with K,
   a RANSAC plane is fitted (the table is the dominant plane even with a
   few objects on it) and refined by least squares on its inliers. It needs
   no calibration capture and works for a camera that is not exactly
   perpendicular to the table (a tilted mount or a sloped table).
2. Empty-scene capture (`background_depth_m`): height = captured depth minus
   current depth, per pixel. Use it when the background is not a plane
   (bins, clutter fixed to the cell); it needs a capture with no objects
   and a camera that has not moved since.

Objects are the connected components of pixels between OBJECT_MIN_HEIGHT_M
and OBJECT_MAX_HEIGHT_M above the background with at least
OBJECT_MIN_AREA_PX pixels. Labels are 1..N in raster order of the components (0 = background).
"""
from dataclasses import dataclass

import cv2
import numpy as np

from defgg_ros.perception.geometry import check_camera_matrix, plane_hypotheses

# Points farther than this from the plane are not table (depth noise of a
# D435 at 0.4 m is ~1-2 mm, so 4 mm keeps the table and rejects objects).
PLANE_INLIER_DISTANCE_M = 0.004
PLANE_RANSAC_ITERATIONS = 60
PLANE_RANSAC_SAMPLE_POINTS = 4000
# The table must cover at least this fraction of the valid pixels; otherwise
# the fit found something else (a big object, a wall) and we refuse.
PLANE_MIN_INLIER_FRACTION = 0.2
# Something thinner than this above the table is noise or a sheet of paper.
OBJECT_MIN_HEIGHT_M = 0.005
# Anything higher above the table than this is not a graspable object but the
# robot's own hand/arm passing through the view (the camera is 0.40 m above
# the table; the paper's objects are well under 0.2 m tall).
OBJECT_MAX_HEIGHT_M = 0.25
# Smaller blobs are speckle, not a graspable object (a 2 cm object at 0.4 m
# covers ~400 px with fx = 385).
OBJECT_MIN_AREA_PX = 60
# Labels travel as mono8, so at most this many objects per image.
MAX_OBJECTS = 255
MIN_VALID_PIXELS = 100
RANSAC_SEED = 0
# The plane is fitted on every 4th pixel in u and v: 16x fewer points, the
# same plane to well under a millimetre on a 640x480 image.
PLANE_FIT_STRIDE_PX = 4


class SegmentationError(ValueError):
    """A depth image or background that cannot be segmented."""


@dataclass(frozen=True)
class Plane:
    """n . p + d = 0 in the camera frame, n unit, oriented towards the camera (d > 0)."""

    normal: np.ndarray
    offset_m: float


@dataclass(frozen=True)
class SegmentationResult:
    labels: np.ndarray           # HxW uint8, 0 = background, 1..N objects
    height_m: np.ndarray         # HxW float32 height above the background, NaN where unknown
    object_ids: tuple[int, ...]  # the labels present, ascending
    centroids_px: dict           # label -> (u, v) mask centroid in pixels
    areas_px: dict               # label -> pixel count
    plane: Plane | None          # None when an empty-scene capture was used


def back_project(depth_m: np.ndarray, camera_k, stride_px: int = 1) -> np.ndarray:
    """Points in the camera optical frame (m) of every stride-th pixel; NaN where depth is invalid."""
    k = check_camera_matrix(camera_k)
    depth_m = depth_m[::stride_px, ::stride_px]
    height, width = depth_m.shape
    u = np.arange(width, dtype=np.float64)[None, :] * stride_px
    v = np.arange(height, dtype=np.float64)[:, None] * stride_px
    z = depth_m.astype(np.float64)
    x = (u - k[0, 2]) / k[0, 0] * z
    y = (v - k[1, 2]) / k[1, 1] * z
    return np.stack([x, y, z], axis=-1)


def _check_depth(depth_m: np.ndarray) -> np.ndarray:
    depth = np.asarray(depth_m)
    if depth.ndim != 2 or depth.size == 0:
        raise SegmentationError(f"depth must be a non-empty HxW image in metres, got shape {depth.shape}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise SegmentationError(f"depth must be float metres (convert 16UC1 mm first), got dtype {depth.dtype}")
    valid = np.isfinite(depth) & (depth > 0)
    if int(valid.sum()) < MIN_VALID_PIXELS:
        raise SegmentationError(f"depth has only {int(valid.sum())} valid pixels (need {MIN_VALID_PIXELS})")
    return valid


def fit_table_plane(points_m: np.ndarray, rng_seed: int = RANSAC_SEED) -> Plane:
    """RANSAC + least-squares plane through Nx3 points (camera frame)."""
    rng = np.random.default_rng(rng_seed)
    sample = points_m
    if len(points_m) > PLANE_RANSAC_SAMPLE_POINTS:
        sample = points_m[rng.integers(0, len(points_m), PLANE_RANSAC_SAMPLE_POINTS)]
    # All hypotheses at once: one plane per random point triple.
    triples = sample[rng.integers(0, len(sample), size=(PLANE_RANSAC_ITERATIONS, 3))]
    normals, offsets = plane_hypotheses(triples, min_cross_norm=1e-12)
    if not len(normals):
        raise SegmentationError("table plane fit failed: the valid depth points are degenerate (collinear)")
    counts = np.count_nonzero(np.abs(sample @ normals.T + offsets) < PLANE_INLIER_DISTANCE_M, axis=0)
    best = int(np.argmax(counts))
    best = (normals[best], offsets[best])
    inliers = points_m[np.abs(points_m @ best[0] + best[1]) < PLANE_INLIER_DISTANCE_M]
    if len(inliers) < PLANE_MIN_INLIER_FRACTION * len(points_m):
        raise SegmentationError(
            f"no dominant table plane: only {len(inliers)} of {len(points_m)} valid points lie on the best plane")
    return refine_plane(inliers)


def refine_plane(inliers: np.ndarray) -> Plane:
    """The least-squares plane through Nx3 inlier points (camera frame), oriented so the camera (the origin)
    lies on its positive side."""
    centroid = inliers.mean(axis=0)
    # The normal is the direction of least variance of the inliers.
    centred = inliers - centroid
    _, eigenvectors = np.linalg.eigh(centred.T @ centred)
    normal = eigenvectors[:, 0]
    offset = -float(normal @ centroid)
    if offset < 0:  # orient so the camera (origin) has positive height
        normal, offset = -normal, -offset
    return Plane(normal=normal, offset_m=offset)


def height_above_plane(depth_m: np.ndarray, camera_k, plane: Plane) -> np.ndarray:
    """Per-pixel height (m) above the plane; NaN where depth is invalid.

    n . p + d with p = z * ((u - cx) / fx, (v - cy) / fy, 1), evaluated as
    separable row/column terms so no HxWx3 point cloud is built.
    """
    k = check_camera_matrix(camera_k)
    height, width = depth_m.shape
    n = plane.normal
    column_term = (n[0] * (np.arange(width) - k[0, 2]) / k[0, 0]).astype(np.float32)[None, :]
    row_term = (n[1] * (np.arange(height) - k[1, 2]) / k[1, 1] + n[2]).astype(np.float32)[:, None]
    with np.errstate(invalid="ignore"):
        out = depth_m.astype(np.float32) * (column_term + row_term) + np.float32(plane.offset_m)
        out[~(depth_m > 0)] = np.nan
    return out


def segment_objects(depth_m: np.ndarray, camera_k, background_depth_m: np.ndarray | None = None,
                    min_height_m: float = OBJECT_MIN_HEIGHT_M,
                    min_area_px: int = OBJECT_MIN_AREA_PX,
                    max_height_m: float = OBJECT_MAX_HEIGHT_M) -> SegmentationResult:
    """Object labels above the table for a float32 depth image in metres (NaN/0 = invalid)."""
    valid = _check_depth(depth_m)
    if not (np.isfinite(min_height_m) and 0 < min_height_m < max_height_m and min_area_px >= 1):
        raise SegmentationError(f"thresholds must satisfy 0 < min_height_m < max_height_m and min_area_px >= 1, got "
                                f"{min_height_m}, {max_height_m}, {min_area_px}")
    plane = None
    if background_depth_m is None:
        stride = PLANE_FIT_STRIDE_PX
        points = back_project(depth_m, camera_k, stride)
        plane = fit_table_plane(points[valid[::stride, ::stride]])
        height = height_above_plane(depth_m, camera_k, plane)
    else:
        height = _height_from_background(depth_m, background_depth_m, valid)
    with np.errstate(invalid="ignore"):  # NaN (unknown height) compares False: background
        foreground = (height > min_height_m) & (height < max_height_m)
    labels, centroids, areas = _components(foreground, min_area_px)
    ids = tuple(sorted(centroids))
    return SegmentationResult(labels, height, ids, centroids, areas, plane)


def _height_from_background(depth_m, background_depth_m, valid) -> np.ndarray:
    background = np.asarray(background_depth_m)
    if background.shape != depth_m.shape:
        raise SegmentationError(f"background depth is {background.shape}, depth is {depth_m.shape}")
    bg_valid = np.isfinite(background) & (background > 0)
    both = valid & bg_valid
    if int(both.sum()) < MIN_VALID_PIXELS:
        raise SegmentationError("depth and background capture share too few valid pixels")
    height = np.full(depth_m.shape, np.nan, dtype=np.float32)
    height[both] = background[both] - depth_m[both]
    return height


def _components(foreground: np.ndarray, min_area_px: int):
    count, raw, stats, centroids = cv2.connectedComponentsWithStats(foreground.astype(np.uint8), connectivity=8)
    keep = [i for i in range(1, count) if stats[i, cv2.CC_STAT_AREA] >= min_area_px]
    if len(keep) > MAX_OBJECTS:  # keep the largest ones; labels must fit mono8
        keep = sorted(sorted(keep, key=lambda i: -stats[i, cv2.CC_STAT_AREA])[:MAX_OBJECTS])
    lut = np.zeros(count, dtype=np.uint8)
    for new_label, old in enumerate(keep, start=1):
        lut[old] = new_label
    labels = lut[raw]
    centroid_px = {int(lut[i]): (float(centroids[i][0]), float(centroids[i][1])) for i in keep}
    area_px = {int(lut[i]): int(stats[i, cv2.CC_STAT_AREA]) for i in keep}
    return labels, centroid_px, area_px
