"""The cell's RealSense-like depth camera rendered with PyBullet's TinyRenderer.

640x480, fx = fy = CAMERA_FX_PX, principal point at the image centre, pose
`base_T_camera` of the optical frame (z forward, x right, y down). The colour
image is a D435's colour stream: its own camera, 15 mm beside the depth origin
with its own focal length (COLOR_FX_PX), as realsense2_camera publishes it
(not pixel-aligned with the depth image). Depth is
the z distance along the optical axis, recovered from the OpenGL depth buffer
with z = far*near / (far - (far - near) * d). Optional realistic degradations
(depth-dependent noise, dropped pixels at depth edges and at random) are off
unless asked for.
"""
from dataclasses import dataclass

import numpy as np
import pybullet as p

from defgg_ros.constants import (
    CAMERA_FAR_M,
    CAMERA_FX_PX,
    CAMERA_FY_PX,
    CAMERA_HEIGHT_PX,
    CAMERA_NEAR_M,
    CAMERA_WIDTH_PX,
    COLOR_FX_PX,
    COLOR_FY_PX,
    LINK_COLOR_OFFSET_M,
)
from defgg_ros.sim import physics

# Noise sigma = coefficient * z^2: stereo depth error grows with the square of
# the distance; 0.004/m gives ~0.6 mm at 0.4 m, in the range of a D435 there.
DEFAULT_NOISE_COEFF_PER_M = 0.004
# Stereo cameras lose pixels where the depth jumps (occlusion shadows).
EDGE_JUMP_M = 0.01
# The 16UC1 image encodes mm; 0 means "no measurement" (RealSense convention).
MAX_DEPTH_MM = np.iinfo(np.uint16).max


@dataclass(frozen=True)
class DepthNoise:
    noise_coeff_per_m: float = 0.0
    random_dropout_fraction: float = 0.0
    drop_edges: bool = False

    @property
    def enabled(self) -> bool:
        return self.noise_coeff_per_m > 0 or self.random_dropout_fraction > 0 or self.drop_edges


def camera_matrix() -> np.ndarray:
    """K of the depth camera; the optical axis hits the image centre."""
    return np.array([[CAMERA_FX_PX, 0.0, (CAMERA_WIDTH_PX - 1) / 2.0],
                     [0.0, CAMERA_FY_PX, (CAMERA_HEIGHT_PX - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


def color_camera_matrix() -> np.ndarray:
    """K of the colour stream (the same 640x480, its own focal length)."""
    return np.array([[COLOR_FX_PX, 0.0, (CAMERA_WIDTH_PX - 1) / 2.0],
                     [0.0, COLOR_FY_PX, (CAMERA_HEIGHT_PX - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


def color_offset_in_depth_optical_m() -> np.ndarray:
    """Where the colour optical frame's origin sits in the depth optical frame (the two share their axes): camera_link's
    +y is the optical frames' -x."""
    x_link, y_link, z_link = LINK_COLOR_OFFSET_M
    return np.array([-y_link, -z_link, x_link])


def _view_and_projection(eye, rot, fy_px: float):
    # OpenGL looks along -z with y up; the optical frame looks along +z with y down.
    view = p.computeViewMatrix(eye.tolist(), (eye + rot[:, 2]).tolist(), (-rot[:, 1]).tolist())
    fov_y_deg = np.degrees(2.0 * np.arctan(CAMERA_HEIGHT_PX / 2.0 / fy_px))
    projection = p.computeProjectionMatrixFOV(fov_y_deg, CAMERA_WIDTH_PX / CAMERA_HEIGHT_PX, CAMERA_NEAR_M,
                                              CAMERA_FAR_M)
    return view, projection


def buffer_to_depth_m(depth_buffer, near_m=CAMERA_NEAR_M, far_m=CAMERA_FAR_M) -> np.ndarray:
    """OpenGL depth buffer values in [0, 1] -> metric z along the optical axis."""
    return physics.depth_from_buffer_m(depth_buffer, near_m, far_m)


def depth_m_to_mm_u16(depth_m) -> np.ndarray:
    """Metres -> 16UC1 millimetres; invalid (non-finite, <= 0, beyond range) -> 0."""
    mm = np.round(np.asarray(depth_m, dtype=np.float64) * 1000.0)
    valid = np.isfinite(mm) & (mm > 0) & (mm <= MAX_DEPTH_MM)
    return np.where(valid, mm, 0).astype(np.uint16)


class DepthCamera:
    """Renders depth (m) and the body-id mask from a fixed camera pose."""

    def __init__(self, client: int, base_xyz_camera_m, base_quat_camera_xyzw, noise: DepthNoise = DepthNoise(),
                 seed: int = 0):
        self._client = client
        self.noise = noise
        self._rng = np.random.default_rng(seed)
        rot = np.array(p.getMatrixFromQuaternion(base_quat_camera_xyzw)).reshape(3, 3)
        eye = np.asarray(base_xyz_camera_m, dtype=float)
        self._view, self._proj = _view_and_projection(eye, rot, CAMERA_FY_PX)
        self._color_view, self._color_proj = _view_and_projection(eye + rot @ color_offset_in_depth_optical_m(), rot,
                                                                  COLOR_FY_PX)

    def render(self, with_color: bool = False):
        """(depth_m float32 HxW with NaN = invalid, body-id mask int32 HxW, rgb uint8 HxWx3 or None)."""
        _, _, _, depth_buffer, seg = p.getCameraImage(
            CAMERA_WIDTH_PX, CAMERA_HEIGHT_PX, self._view, self._proj, renderer=p.ER_TINY_RENDERER,
            physicsClientId=self._client)
        depth_m = buffer_to_depth_m(np.reshape(depth_buffer, (CAMERA_HEIGHT_PX, CAMERA_WIDTH_PX)))
        # Nothing hit before the far plane: a real camera has no reading there.
        depth_m = np.where(depth_m >= CAMERA_FAR_M * 0.999, np.nan, depth_m)
        mask = np.reshape(np.asarray(seg, dtype=np.int64), (CAMERA_HEIGHT_PX, CAMERA_WIDTH_PX))
        mask = np.where(mask >= 0, mask & ((1 << 24) - 1), -1).astype(np.int32)
        rgb = None
        if with_color:   # a second render: the colour camera's own viewpoint and focal length
            _, _, rgba, _, _ = p.getCameraImage(CAMERA_WIDTH_PX, CAMERA_HEIGHT_PX, self._color_view, self._color_proj,
                                                renderer=p.ER_TINY_RENDERER, physicsClientId=self._client)
            rgb = np.reshape(np.asarray(rgba, dtype=np.uint8), (CAMERA_HEIGHT_PX, CAMERA_WIDTH_PX, 4))[..., :3].copy()
        if self.noise.enabled:
            depth_m = self._degrade(depth_m)
        return depth_m.astype(np.float32), mask, rgb

    def _degrade(self, depth_m: np.ndarray) -> np.ndarray:
        out = depth_m.copy()
        if self.noise.noise_coeff_per_m > 0:
            out += self._rng.normal(size=out.shape) * self.noise.noise_coeff_per_m * np.nan_to_num(out) ** 2
        drop = np.zeros(out.shape, dtype=bool)
        if self.noise.random_dropout_fraction > 0:
            drop |= self._rng.random(out.shape) < self.noise.random_dropout_fraction
        if self.noise.drop_edges:
            filled = np.nan_to_num(depth_m, nan=CAMERA_FAR_M)
            jump_u = np.abs(np.diff(filled, axis=1)) > EDGE_JUMP_M
            jump_v = np.abs(np.diff(filled, axis=0)) > EDGE_JUMP_M
            drop[:, 1:] |= jump_u
            drop[1:, :] |= jump_v
        out[drop] = np.nan
        return out
