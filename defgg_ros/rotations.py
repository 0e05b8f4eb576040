"""Quaternion <-> rotation matrix, pure numpy, below every core (perception, control and the ROS helpers
share it; each wraps the check in its own error type). Quaternions are (x, y, z, w) like ROS messages.
"""
from __future__ import annotations

import math

import numpy as np

# A quaternion whose norm is this far from 1 is a typo, a wrong order or a corrupted message, not
# rounding: reject it instead of silently normalising.
QUATERNION_NORM_TOLERANCE = 1e-3


def unit_quaternion_xyzw(quaternion_xyzw, error: type[Exception] = ValueError) -> np.ndarray:
    """The quaternion normalised, or `error` if it is not 4 finite numbers of norm 1 (within the tolerance)."""
    q = np.asarray(quaternion_xyzw, dtype=np.float64).reshape(-1)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise error(f"quaternion must be 4 finite numbers (x, y, z, w), got {quaternion_xyzw!r}")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise error(f"quaternion must have unit norm, got norm {norm:.6f} for {q.tolist()}")
    return q / norm


def quaternion_xyzw_to_matrix(quaternion_xyzw, error: type[Exception] = ValueError) -> np.ndarray:
    """3x3 rotation matrix of a unit quaternion (x, y, z, w); `error` for one unit_quaternion_xyzw refuses."""
    x, y, z, w = unit_quaternion_xyzw(quaternion_xyzw, error)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quaternion_xyzw(rotation) -> np.ndarray:
    """Unit quaternion (x, y, z, w) with w >= 0 of a 3x3 rotation matrix (not checked: callers that take
    matrices from outside check them first)."""
    r = np.asarray(rotation, dtype=np.float64)
    # Shepperd's method: divide by the largest of the four candidate terms, for numerical stability.
    trace = np.trace(r)
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q
