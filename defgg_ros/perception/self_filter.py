"""The robot sees itself: which depth pixels are the arm, from joint states and the camera pose (no rclpy).

    robot = RobotSelfFilter(margin_m=0.02)
    mask = robot.mask(joint_positions_by_name, base_T_camera, camera_k, depth_m)   # HxW bool

Each link's collision mesh (the Panda URDF the cell simulates, pybullet_data's franka_panda) is
placed by Pinocchio's forward kinematics at the measured joint positions, projected with the
camera pose and intrinsics, and its convex outline drawn, widened by the margin (calibration error,
joint-state latency). Only pixels at or behind the link (depth >= the link's nearest point minus the
margin) are the robot: an object held in front of the arm stays visible. Tabletop perception
(perception/tabletop.py) leaves these pixels out of segmentation and planning.

Joint names are matched by their ending (`joint1`..`joint7`, `finger_joint1/2`), so `panda_joint1`
and `fr3_joint1` both work; missing joints keep their neutral position.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np
import pinocchio as pin

from defgg_ros.control.kinematics import panda_urdf_path

DEFAULT_MARGIN_M = 0.02
# Links nearer the camera than this are not drawn (the projection degenerates).
MIN_LINK_DEPTH_M = 0.05
MAX_VERTICES_PER_LINK = 120


def _rpy_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    return pin.rpy.rpyToMatrix(r, p, y)


def _obj_vertices(path: Path) -> np.ndarray:
    vertices = [tuple(float(v) for v in line.split()[1:4]) for line in path.read_text().splitlines()
                if line.startswith("v ")]
    return np.asarray(vertices, float)


def _link_meshes(urdf_path: Path) -> dict:
    """link name -> vertices (N x 3) in the link frame, from each <collision> mesh and origin."""
    root = ET.parse(urdf_path).getroot()
    out = {}
    rng = np.random.default_rng(0)
    for link in root.findall("link"):
        points = []
        for collision in link.findall("collision"):
            mesh = collision.find("geometry/mesh")
            if mesh is None:
                continue
            filename = mesh.get("filename").replace("package://", "")
            vertices = _obj_vertices(urdf_path.parent / filename)
            origin = collision.find("origin")
            placement = np.eye(4)
            if origin is not None:
                placement[:3, :3] = _rpy_matrix([float(v) for v in origin.get("rpy", "0 0 0").split()])
                placement[:3, 3] = [float(v) for v in origin.get("xyz", "0 0 0").split()]
            points.append(vertices @ placement[:3, :3].T + placement[:3, 3])
        if points:
            vertices = np.concatenate(points)
            if len(vertices) > MAX_VERTICES_PER_LINK:   # the outline only needs the extreme points
                hull = _hull_3d_extremes(vertices)
                rest = vertices[rng.choice(len(vertices), MAX_VERTICES_PER_LINK, replace=False)]
                vertices = np.concatenate([hull, rest])
            out[link.get("name")] = vertices
    return out


def _hull_3d_extremes(vertices: np.ndarray) -> np.ndarray:
    """The vertices extreme along 26 directions: a cheap superset of the silhouette's corners."""
    dirs = np.array([(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1) if (a, b, c) != (0, 0, 0)],
                    float)
    return vertices[np.unique(np.argmax(vertices @ dirs.T, axis=0))]


class RobotSelfFilter:
    def __init__(self, margin_m: float = DEFAULT_MARGIN_M, urdf_path: Path | None = None):
        if not (math.isfinite(margin_m) and margin_m >= 0):
            raise ValueError(f"self-filter margin must be >= 0 m, got {margin_m}")
        path = Path(urdf_path) if urdf_path else panda_urdf_path()
        self.margin_m = float(margin_m)
        self.model = pin.buildModelFromUrdf(str(path))
        meshes = _link_meshes(path)
        self.links = [(self.model.getFrameId(name), vertices) for name, vertices in meshes.items()
                      if self.model.existFrame(name)]
        # joint name ending -> index in q (revolute and prismatic joints have one coordinate each).
        self._q_index = {}
        for joint_id in range(1, self.model.njoints):
            name = self.model.names[joint_id]
            key = "finger_" + name.split("finger_")[-1] if "finger_" in name else name.split("_")[-1]
            self._q_index[key] = self.model.joints[joint_id].idx_q

    def q_from_names(self, positions_by_name: dict) -> np.ndarray:
        q = pin.neutral(self.model)
        for name, value in positions_by_name.items():
            key = "finger_" + name.split("finger_")[-1] if "finger_" in name else name.split("_")[-1]
            if key in self._q_index and math.isfinite(float(value)):
                q[self._q_index[key]] = float(value)
        return q

    def link_points_base(self, positions_by_name: dict) -> list:
        """[(vertices N x 3 in the base frame)] per link at these joint positions. Thread-safe: a node's stream
        and its Perceive service mask frames at once, and pinocchio's Data is scratch space (a shared one gave
        one call the other's link poses: 5 in 600)."""
        q = self.q_from_names(positions_by_name)
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, q)
        out = []
        for frame_id, vertices in self.links:
            placement = data.oMf[frame_id]
            out.append(vertices @ placement.rotation.T + placement.translation)
        return out

    def mask(self, positions_by_name: dict, base_T_camera, camera_k, depth_m: np.ndarray) -> np.ndarray:
        """HxW bool: the robot's pixels (module docstring)."""
        depth = np.asarray(depth_m, np.float32)
        h, w = depth.shape
        k = np.asarray(camera_k, float)
        camera_T_base = np.linalg.inv(np.asarray(base_T_camera, float))
        out = np.zeros((h, w), bool)
        for vertices in self.link_points_base(positions_by_name):
            p = vertices @ camera_T_base[:3, :3].T + camera_T_base[:3, 3]
            p = p[p[:, 2] > MIN_LINK_DEPTH_M]
            if len(p) < 3:
                continue
            uv = np.stack([k[0, 0] * p[:, 0] / p[:, 2] + k[0, 2], k[1, 1] * p[:, 1] / p[:, 2] + k[1, 2]], axis=1)
            if uv[:, 0].max() < 0 or uv[:, 0].min() >= w or uv[:, 1].max() < 0 or uv[:, 1].min() >= h:
                continue
            nearest = float(p[:, 2].min())
            margin_px = int(math.ceil(self.margin_m * k[0, 0] / nearest))
            hull = cv2.convexHull(np.clip(uv, -4 * w, 4 * w).astype(np.int32))
            link = np.zeros((h, w), np.uint8)
            cv2.fillConvexPoly(link, hull, 1)
            if margin_px > 0:
                cv2.polylines(link, [hull], True, 1, thickness=2 * margin_px + 1)
            with np.errstate(invalid="ignore"):
                behind = ~(depth < nearest - self.margin_m)      # NaN (no return) counts as robot
            out |= (link > 0) & behind
        return out
