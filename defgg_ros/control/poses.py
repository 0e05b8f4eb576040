"""Rigid transforms as plain 4x4 numpy arrays, and the top-down grasp pose.

Poses are named `aMb` (placement of frame b in frame a), e.g. `base_M_tcp`.
The grasp convention of the cell: the TCP z axis points DOWN (approach), the
fingers close along x, so a top-down grasp is fully given by a position and
a yaw about the vertical.
"""
import math

import numpy as np

from defgg_ros import rotations

# How far the approach axis may tilt from straight down and still count as a
# top-down grasp (the 4-DoF grasp representation has no tilt).
TOP_DOWN_TILT_ATOL_RAD = math.radians(5.0)


class PoseError(ValueError):
    """A pose that cannot be used: non-finite, bad quaternion, not top-down."""


def finite_array(name: str, values, error: type[Exception] = PoseError) -> np.ndarray:
    """values as a float array, or error naming them if any is NaN or infinite."""
    array = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(array)):
        raise error(f"{name} has non-finite values: {array.tolist()}")
    return array


def quaternion_to_matrix(quat_xyzw) -> np.ndarray:
    """3x3 rotation of a quaternion (x, y, z, w); PoseError for a non-unit one."""
    return rotations.quaternion_xyzw_to_matrix(quat_xyzw, PoseError)


def matrix_to_quaternion(rotation) -> np.ndarray:
    """Quaternion (x, y, z, w) with w >= 0 of a 3x3 rotation matrix."""
    return rotations.matrix_to_quaternion_xyzw(rotation)


def pose_matrix(position_m, quat_xyzw) -> np.ndarray:
    """4x4 homogeneous transform from a position and a quaternion (x, y, z, w)."""
    p = finite_array("position", position_m)
    if p.shape != (3,):
        raise PoseError(f"position must have 3 values, got shape {p.shape}")
    m = np.eye(4)
    m[:3, :3] = quaternion_to_matrix(quat_xyzw)
    m[:3, 3] = p
    return m


def top_down_pose(position_m, yaw_rad: float) -> np.ndarray:
    """base_M_tcp of a top-down grasp: z down, fingers closing along (cos yaw, sin yaw, 0)."""
    p = finite_array("position", position_m)
    yaw = float(finite_array("yaw", yaw_rad))
    c, s = math.cos(yaw), math.sin(yaw)
    m = np.eye(4)
    # Columns are the TCP axes in the base frame: x = closing, z = down, y = z cross x.
    m[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    m[:3, 3] = p
    return m


def top_down_yaw(base_M_tcp) -> float:
    """Yaw of a top-down pose; PoseError when its z axis is not (nearly) straight down."""
    m = finite_array("pose", base_M_tcp)
    z_axis = m[:3, 2]
    tilt = math.acos(max(-1.0, min(1.0, -float(z_axis[2]))))
    if tilt > TOP_DOWN_TILT_ATOL_RAD:
        raise PoseError(
            f"grasp approach axis is tilted {math.degrees(tilt):.1f} deg from straight down "
            f"(at most {math.degrees(TOP_DOWN_TILT_ATOL_RAD):.1f} deg for a top-down grasp)"
        )
    x_axis = m[:3, 0]
    return math.atan2(float(x_axis[1]), float(x_axis[0]))


def wrap_angle(angle_rad: float) -> float:
    """Angle wrapped into [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi
