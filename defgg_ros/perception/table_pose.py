"""A camera pose from the table itself, for frames without a calibrated one (no rclpy).

    pose = table_frame_pose(depth_m, camera_k, config)         # raises TabletopError: no plane
    poses = PoseFromTable(config)                              # the nodes' rule
    base_T_camera, estimated = poses.pose_for(depth_m, camera_k, None)   # the nodes: no pose to check

A cell before its hand-eye calibration, or a recorded frame replayed without one, has no camera pose (the
nodes: nothing on TF and `base_T_camera` not set), and a given pose may put the table where the tabletop
perception does not look for it (perception/tabletop.py: within table_z_tolerance_m of table_z_m, tilted at
most 15 degrees). Rather than refuse every frame, the nodes may use a *table frame* instead: the frame's
dominant plane facing the camera becomes the table at table_z_m, the point the optical axis meets on it lies
at the workspace box's centre, and +x points towards the image's top (the camera's -y axis along the table).
Objects are then segmented and grasped as usual, but the grasps are in that table frame, not in the robot's,
and the robot self-filter cannot be placed: the nodes log it as a warning and say how to give the real pose
(TF or base_T_camera).
"""
from __future__ import annotations

import math
import threading
import time

import numpy as np

from defgg_ros.constants import CAMERA_FAR_M, CAMERA_NEAR_M
from defgg_ros.perception.geometry import plane_hypotheses
from defgg_ros.perception.segmentation import back_project, refine_plane
from defgg_ros.perception.tabletop import (
    TABLE_MAX_TILT_DEG,
    TabletopConfig,
    TabletopError,
    check_base_T_camera,
    plane_distances,
)

# The frame a table frame's grasps are given in (instead of the robot's base frame): an executor that
# checks the grasp's frame refuses them, so a guessed pose never moves the robot.
TABLE_FRAME_ID = "defgg_table_estimate"
SAMPLE_PIXELS = 3000
HYPOTHESES = 120
# Inlier distance of the rough plane (the tabletop perception refits the table in the new frame with its
# own 6 mm): a RealSense at 0.6 m is noisy to a few millimetres, and a slight warp of a real table adds to it.
INLIER_M = 0.010
# A plane seen more edge-on than this (angle between its normal and the ray to its points) is a wall or a
# box side, not a table the camera looks onto.
MAX_VIEW_ANGLE_DEG = 75.0
MIN_INLIER_SHARE = 0.15


def camera_points(depth_m, camera_k) -> np.ndarray:
    """Up to ~SAMPLE_PIXELS valid pixels as camera-frame points (N x 3)."""
    depth = np.asarray(depth_m, np.float32)
    h, w = depth.shape
    points = back_project(depth, camera_k, max(1, int(math.sqrt(h * w / SAMPLE_PIXELS)))).reshape(-1, 3)
    with np.errstate(invalid="ignore"):
        return points[(points[:, 2] > CAMERA_NEAR_M) & (points[:, 2] < CAMERA_FAR_M)]


def dominant_plane(points: np.ndarray, rng_seed: int = 0):
    """(unit normal towards the camera, offset d with n.p + d = 0, inlier share) of the plane with the most
    inliers among those the camera looks onto (RANSAC, refined by least squares); TabletopError if none."""
    if len(points) < 50:
        raise TabletopError(f"too few depth returns to find a table ({len(points)} sampled)")
    rng = np.random.default_rng(rng_seed)
    triples = points[rng.integers(0, len(points), size=(HYPOTHESES, 3))]
    normals, offsets = plane_hypotheses(triples, min_cross_norm=1e-12)
    flip = offsets < 0                       # the camera (the origin) on the normal's side: d > 0
    normals[flip], offsets[flip] = -normals[flip], -offsets[flip]
    # Planes in the order of their inlier counts; the first whose fit the camera looks onto (the ray to its
    # inliers' centroid within MAX_VIEW_ANGLE_DEG of its normal) wins.
    distances = np.abs(plane_distances(points, normals, offsets))   # N x H
    counts = np.count_nonzero(distances < INLIER_M, axis=0)
    for best in np.argsort(-counts):
        inliers = points[distances[:, best] < INLIER_M]
        if len(inliers) < MIN_INLIER_SHARE * len(points):
            break
        plane = refine_plane(inliers)
        normal, offset = plane.normal, plane.offset_m
        centroid = inliers.mean(axis=0)
        cos_view = float(-normal @ centroid / np.linalg.norm(centroid))
        if cos_view >= math.cos(math.radians(MAX_VIEW_ANGLE_DEG)):
            return normal, offset, len(inliers) / len(points)
    raise TabletopError("no plane the camera looks onto covers at least "
                        f"{MIN_INLIER_SHARE:.0%} of the depth returns: no table in view")


def table_frame_pose(depth_m, camera_k, config: TabletopConfig | None = None) -> np.ndarray:
    """base_T_camera (4x4) of the table frame (module docstring) for this frame."""
    config = config or TabletopConfig()
    normal, offset, _ = dominant_plane(camera_points(depth_m, camera_k))
    return _table_frame(normal, offset, config)


def _table_frame(normal, offset, config: TabletopConfig) -> np.ndarray:
    # Where the optical axis meets the table; a camera looking parallel to it sees its foot point instead.
    axis = np.array([0.0, 0.0, 1.0])
    along = float(normal @ axis)
    anchor = -offset / along * axis if along < -1e-3 else -offset * normal
    z_axis = normal                                    # the table's up, towards the camera
    up_in_image = np.array([0.0, -1.0, 0.0])
    x_axis = up_in_image - (up_in_image @ z_axis) * z_axis
    if np.linalg.norm(x_axis) < 1e-6:                  # looking along the image's y axis: take its x
        x_axis = np.array([1.0, 0.0, 0.0]) - z_axis[0] * z_axis
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    camera_R_base = np.stack([x_axis, y_axis, z_axis], axis=1)        # base axes in camera coordinates
    ws = config.workspace
    centre_base = np.array([0.5 * sum(ws.x_m), 0.5 * sum(ws.y_m), config.table_z_m])
    base_T_camera = np.eye(4)
    base_T_camera[:3, :3] = camera_R_base.T
    base_T_camera[:3, 3] = centre_base - camera_R_base.T @ anchor
    return check_base_T_camera(base_T_camera)


def pose_fits_plane(base_T_camera, normal, offset, config: TabletopConfig) -> bool:
    """Whether a pose puts the plane (camera frame: n.p + d = 0) where the tabletop perception looks for the
    table: within TABLE_MAX_TILT_DEG of level and table_z_tolerance_m of table_z_m below the camera."""
    pose = check_base_T_camera(base_T_camera)
    normal_base = pose[:3, :3] @ np.asarray(normal, float)
    foot_base = pose[:3, :3] @ (-offset * np.asarray(normal, float)) + pose[:3, 3]
    level = abs(normal_base[2]) >= math.cos(math.radians(TABLE_MAX_TILT_DEG))
    return bool(level and abs(foot_base[2] - config.table_z_m) <= config.table_z_tolerance_m)


class PoseFromTable:
    """The configured pose when it puts the frame's dominant plane where the table is expected, else a table
    frame estimated from that plane, kept for the next frames while it still fits (a fixed camera: one
    estimate, not a slightly different one per frame). A wrong pose can still find a 'table' among the
    points near table_z_m (a box top, a tilted slice of the real table), so the check is on the dominant
    plane, not on the tabletop perception's own fit. The decision is reused for recheck_s (~3 ms a check)
    while the configured pose stays the same. Thread-safe."""

    def __init__(self, config: TabletopConfig | None = None, recheck_s: float = 1.0, clock=time.monotonic):
        self.config = config or TabletopConfig()
        self.recheck_s = float(recheck_s)
        self._clock = clock
        self._lock = threading.Lock()
        self.estimate = None
        self._decision = None            # (configured pose bytes, checked at, (pose, estimated))

    def pose_for(self, depth_m, camera_k, configured, config: TabletopConfig | None = None) -> tuple:
        """(base_T_camera, estimated: bool). configured None: no pose to check, always the table frame. config:
        replaces the one given at construction (a node whose workspace parameters changed). Raises TabletopError
        when the frame shows no plane to use."""
        configured = None if configured is None else np.asarray(configured, float)
        key, now = (b"" if configured is None else configured.tobytes()), self._clock()
        with self._lock:
            if config is not None and config != self.config:
                self.config, self.estimate, self._decision = config, None, None
            if self._decision is not None and self._decision[0] == key and now - self._decision[1] < self.recheck_s:
                return self._decision[2]
        normal, offset, _ = dominant_plane(camera_points(depth_m, camera_k))
        with self._lock:
            if configured is not None and pose_fits_plane(configured, normal, offset, self.config):
                decision = (configured, False)
            else:
                if self.estimate is None or not pose_fits_plane(self.estimate, normal, offset, self.config):
                    self.estimate = _table_frame(normal, offset, self.config)
                decision = (self.estimate, True)
            self._decision = (key, now, decision)
        return decision
