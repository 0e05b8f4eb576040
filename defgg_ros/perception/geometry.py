"""Rigid transforms and the top-down grasp pose, in plain numpy (no rclpy).

Naming: `aTb` is the 4x4 homogeneous placement of frame b expressed in frame
a, so `aTc = aTb @ bTc`. Quaternions are (x, y, z, w) like ROS messages.
"""
import math

import numpy as np

from defgg_ros import rotations


class TransformError(ValueError):
    """A transform, quaternion or camera matrix that is not usable."""


def check_quaternion_xyzw(quaternion_xyzw) -> np.ndarray:
    """Return a unit quaternion (x, y, z, w) or raise TransformError."""
    return rotations.unit_quaternion_xyzw(quaternion_xyzw, TransformError)


def quaternion_xyzw_to_matrix(quaternion_xyzw) -> np.ndarray:
    """3x3 rotation matrix of a unit quaternion (x, y, z, w); TransformError for any other."""
    return rotations.quaternion_xyzw_to_matrix(quaternion_xyzw, TransformError)


def matrix_to_quaternion_xyzw(rotation) -> np.ndarray:
    """Unit quaternion (x, y, z, w, with w >= 0) of a 3x3 rotation matrix; TransformError for a matrix
    that is not a proper rotation."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise TransformError(f"rotation must be a finite 3x3 matrix, got shape {r.shape}")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise TransformError("matrix is not a proper rotation (orthonormal, det +1)")
    return rotations.matrix_to_quaternion_xyzw(r)


def transform_from_xyz_quaternion(xyz_m, quaternion_xyzw) -> np.ndarray:
    """4x4 transform from a translation (m) and a unit quaternion (x, y, z, w)."""
    t = _finite_xyz_m("translation", xyz_m)
    out = np.eye(4)
    out[:3, :3] = quaternion_xyzw_to_matrix(quaternion_xyzw)
    out[:3, 3] = t
    return out


def _finite_xyz_m(what: str, values) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise TransformError(f"{what} must be 3 finite numbers (m), got {values!r}")
    return v


def transform_from_list(values) -> np.ndarray:
    """4x4 transform from the 7-number parameter form [x, y, z, qx, qy, qz, qw]."""
    v = list(values)
    if len(v) != 7:
        raise TransformError(f"a transform parameter needs 7 numbers [x, y, z, qx, qy, qz, qw], got {len(v)}")
    return transform_from_xyz_quaternion(v[:3], v[3:])


def transform_to_xyz_quaternion(transform) -> tuple[np.ndarray, np.ndarray]:
    """(translation m, quaternion xyzw) of a 4x4 transform."""
    t = np.asarray(transform, dtype=np.float64)
    if t.shape != (4, 4):
        raise TransformError(f"transform must be 4x4, got shape {t.shape}")
    return t[:3, 3].copy(), matrix_to_quaternion_xyzw(t[:3, :3])


def rotation_about_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def top_down_grasp_in_camera(position_camera_m, angle_rad: float) -> np.ndarray:
    """cameraTgrasp for a top-down grasp seen by the camera.

    The grasp z axis is the camera's optical axis (pointing away from the
    camera, i.e. the approach direction); x is the finger-closing direction,
    which is the image direction at `angle_rad` from u towards v. Because the
    optical frame has x = u and y = v, this is a pure rotation about z.
    """
    p = _finite_xyz_m("grasp position", position_camera_m)
    if not math.isfinite(angle_rad):
        raise TransformError(f"grasp angle must be finite, got {angle_rad!r}")
    out = np.eye(4)
    out[:3, :3] = rotation_about_z(angle_rad)
    out[:3, 3] = p
    return out


def check_camera_matrix(camera_k) -> np.ndarray:
    """Return K as a 3x3 float64 array or raise TransformError."""
    k = np.asarray(camera_k, dtype=np.float64)
    if k.size == 9:
        k = k.reshape(3, 3)
    if k.shape != (3, 3) or not np.all(np.isfinite(k)):
        raise TransformError(f"camera matrix K must be 9 finite numbers, got shape {k.shape}")
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        raise TransformError(f"camera focal lengths must be > 0, got fx={k[0, 0]}, fy={k[1, 1]}")
    return k


def plane_hypotheses(triples: np.ndarray, min_cross_norm: float) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC's plane hypotheses, one per point triple (K x 3 x 3): unit normals (M x 3) and offsets d (M) with
    n.p + d = 0, for the M triples whose cross product is longer than min_cross_norm (not collinear)."""
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    usable = norms > min_cross_norm
    normals = normals[usable] / norms[usable, None]
    return normals, -np.einsum("ij,ij->i", normals, triples[usable, 0])
