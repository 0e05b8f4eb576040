"""ROS message <-> numpy helpers shared by every node of the cell.

No cv_bridge on these machines (and none needed): sensor_msgs/Image is a
byte buffer with an encoding, a row step and an endianness flag. Every
helper raises ConversionError (a ValueError) with the reason instead of
returning a wrongly shaped or wrongly scaled array.

Conventions:
- depth: 16UC1 millimetres (0 = invalid) or 32FC1 metres (NaN = invalid) in,
  float32 metres with NaN = invalid out (`depth_msg_to_metres`).
- stiffness image: 32FC1 Young's modulus in Pa per pixel, 0 = background.
- object mask: mono8 labels, 0 = background.
- transforms: 4x4 numpy `aTb` (see defgg_ros.perception.geometry); the
  parameter form is [x, y, z, qx, qy, qz, qw].
- Grasp.pose_*: TCP at the grasp point, z = approach (optical axis, down for
  a top-down camera), x = finger closing direction.
"""
import numpy as np
from builtin_interfaces.msg import Time
from defgg_interfaces.msg import Grasp
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.perception.depth import DepthError, depth_to_metres, metres_to_millimetres_u16
from defgg_ros.perception.geometry import (
    TransformError,
    check_camera_matrix,
    top_down_grasp_in_camera,
    transform_from_list,
    transform_from_xyz_quaternion,
    transform_to_xyz_quaternion,
)
from defgg_ros.perception.plausibility import check_moduli_plausible
from defgg_ros.stiffness import InvalidYoungsModulus

__all__ = [
    "ConversionError", "ENCODINGS", "image_to_numpy", "numpy_to_image", "depth_msg_to_metres",
    "depth_metres_to_msg", "stiffness_msg_to_pa", "mask_msg_to_labels", "camera_info_to_k",
    "make_camera_info", "check_image_size", "MAX_IMAGE_SIZE_PX", "check_same_size", "pose_from_transform",
    "transform_from_pose",
    "transform_from_list", "grasp_to_msg", "stamp_to_ns", "ns_to_stamp",
]

# encoding -> (numpy dtype, channels)
ENCODINGS = {
    "16UC1": (np.uint16, 1),
    "mono16": (np.uint16, 1),
    "32FC1": (np.float32, 1),
    "32SC1": (np.int32, 1),
    "mono8": (np.uint8, 1),
    "8UC1": (np.uint8, 1),
    "rgb8": (np.uint8, 3),
    "bgr8": (np.uint8, 3),
}


class ConversionError(ValueError):
    """A message that cannot be converted (unknown encoding, wrong size, bad values)."""


def image_to_numpy(msg: Image) -> np.ndarray:
    """Image -> HxW (1 channel) or HxWxC array in native byte order (a copy)."""
    if msg.encoding not in ENCODINGS:
        raise ConversionError(f"unsupported image encoding {msg.encoding!r}; supported: {sorted(ENCODINGS)}")
    dtype, channels = ENCODINGS[msg.encoding]
    height, width = int(msg.height), int(msg.width)
    if height == 0 or width == 0:
        raise ConversionError(f"image is empty ({width}x{height})")
    itemsize = np.dtype(dtype).itemsize
    row_bytes = width * channels * itemsize
    if msg.step < row_bytes:
        raise ConversionError(f"image step {msg.step} B is shorter than a row ({row_bytes} B for {msg.encoding})")
    if len(msg.data) != msg.step * height:
        raise ConversionError(f"image data has {len(msg.data)} B, expected step*height = {msg.step * height} B")
    raw = np.frombuffer(msg.data, dtype=np.uint8).reshape(height, msg.step)[:, :row_bytes]
    wire = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    array = np.ascontiguousarray(raw).view(wire).astype(dtype, copy=True)
    return array.reshape(height, width) if channels == 1 else array.reshape(height, width, channels)


def numpy_to_image(array: np.ndarray, encoding: str, header: Header | None = None) -> Image:
    """HxW or HxWxC array -> Image (little endian, packed rows)."""
    if encoding not in ENCODINGS:
        raise ConversionError(f"unsupported image encoding {encoding!r}; supported: {sorted(ENCODINGS)}")
    dtype, channels = ENCODINGS[encoding]
    a = np.asarray(array)
    expected_ndim = 2 if channels == 1 else 3
    if a.ndim != expected_ndim or (channels > 1 and a.shape[2] != channels) or a.size == 0:
        raise ConversionError(f"{encoding} needs a non-empty array with {channels} channel(s), got shape {a.shape}")
    if a.dtype != dtype:
        raise ConversionError(f"{encoding} needs dtype {np.dtype(dtype).name}, got {a.dtype}")
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(a.shape[0]), int(a.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = msg.width * channels * a.dtype.itemsize
    msg.data = np.ascontiguousarray(a, dtype=np.dtype(dtype).newbyteorder("<")).tobytes()
    return msg


def depth_msg_to_metres(msg: Image) -> np.ndarray:
    """Depth Image (16UC1 mm or 32FC1 m) -> float32 metres, NaN = invalid."""
    if msg.encoding not in ("16UC1", "mono16", "32FC1"):
        raise ConversionError(f"depth must be 16UC1 (mm) or 32FC1 (m), got {msg.encoding!r}")
    try:
        return depth_to_metres(image_to_numpy(msg), msg.encoding)
    except DepthError as exc:
        raise ConversionError(str(exc)) from exc


def depth_metres_to_msg(depth_m: np.ndarray, encoding: str = "16UC1", header: Header | None = None) -> Image:
    """float metres -> depth Image in 16UC1 mm (0 invalid) or 32FC1 m (NaN invalid)."""
    if encoding == "16UC1":
        try:
            return numpy_to_image(metres_to_millimetres_u16(depth_m), "16UC1", header)
        except DepthError as exc:
            raise ConversionError(str(exc)) from exc
    if encoding == "32FC1":
        depth = np.asarray(depth_m, dtype=np.float32).copy()
        depth[~(np.isfinite(depth) & (depth > 0))] = np.nan
        return numpy_to_image(depth, "32FC1", header)
    raise ConversionError(f"depth encoding must be 16UC1 or 32FC1, got {encoding!r}")


def stiffness_msg_to_pa(msg: Image) -> np.ndarray:
    """Stiffness Image (32FC1, Pa, 0 = background) -> float32 HxW; rejects NaN/Inf/negative."""
    if msg.encoding != "32FC1":
        raise ConversionError(f"stiffness image must be 32FC1 (Young's modulus in Pa), got {msg.encoding!r}")
    youngs_modulus_pa = image_to_numpy(msg)
    try:
        check_moduli_plausible(youngs_modulus_pa)   # the same rule as SetStiffness
    except InvalidYoungsModulus as exc:
        raise ConversionError(f"{exc} (0 = background)") from exc
    return youngs_modulus_pa


def mask_msg_to_labels(msg: Image) -> np.ndarray:
    """Object mask Image (mono8/8UC1 labels, 0 = background) -> uint8 HxW."""
    if msg.encoding not in ("mono8", "8UC1"):
        raise ConversionError(f"object mask must be mono8 labels, got {msg.encoding!r}")
    return image_to_numpy(msg)


def camera_info_to_k(msg: CameraInfo) -> np.ndarray:
    """CameraInfo -> 3x3 intrinsic matrix K (float64)."""
    if msg.width == 0 or msg.height == 0:
        raise ConversionError("camera_info is empty (width or height 0)")
    try:
        return check_camera_matrix(np.asarray(msg.k, dtype=np.float64))
    except TransformError as exc:
        raise ConversionError(f"camera_info: {exc}") from exc


def make_camera_info(camera_k, width_px: int, height_px: int, header: Header | None = None) -> CameraInfo:
    """An undistorted pinhole CameraInfo (plumb_bob, zero distortion) for K."""
    k = check_camera_matrix(camera_k)
    msg = CameraInfo()
    if header is not None:
        msg.header = header
    msg.width, msg.height = int(width_px), int(height_px)
    msg.distortion_model = "plumb_bob"
    msg.d = [0.0] * 5
    msg.k = k.reshape(-1).tolist()
    msg.r = np.eye(3).reshape(-1).tolist()
    p = np.zeros((3, 4))
    p[:, :3] = k
    msg.p = p.reshape(-1).tolist()
    return msg


# The largest depth image a node accepts by default: every RealSense depth mode fits (D400 series up to
# 1280x720, D405 1280x720, L515 1024x768; docs/perception.md, "Input bounds").
MAX_IMAGE_SIZE_PX = (1280, 800)


def check_image_size(name: str, msg, max_size_px=MAX_IMAGE_SIZE_PX) -> None:
    """Raise ConversionError when an Image/CameraInfo is larger than max_size_px (width, height) in either
    direction: checked before any conversion, so a request's memory is bounded by the limit, not by the
    sender (docs/perception.md, "Input bounds")."""
    max_w, max_h = (int(v) for v in max_size_px)
    if int(msg.width) > max_w or int(msg.height) > max_h:
        raise ConversionError(f"{name} is {msg.width}x{msg.height} px, larger than the node's limit {max_w}x{max_h} px "
                              "(parameter max_image_size_px; every RealSense depth mode fits the default)")


def check_same_size(name_a: str, msg_a, name_b: str, msg_b) -> None:
    """Raise ConversionError unless two Image/CameraInfo messages have the same width x height."""
    if (msg_a.width, msg_a.height) != (msg_b.width, msg_b.height):
        raise ConversionError(
            f"{name_a} is {msg_a.width}x{msg_a.height} but {name_b} is {msg_b.width}x{msg_b.height}")


def pose_from_transform(transform) -> Pose:
    """4x4 transform -> geometry_msgs/Pose."""
    try:
        xyz, q = transform_to_xyz_quaternion(transform)
    except TransformError as exc:
        raise ConversionError(str(exc)) from exc
    return Pose(position=Point(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def transform_from_pose(pose: Pose) -> np.ndarray:
    """geometry_msgs/Pose -> 4x4 transform."""
    p, q = pose.position, pose.orientation
    try:
        return transform_from_xyz_quaternion([p.x, p.y, p.z], [q.x, q.y, q.z, q.w])
    except TransformError as exc:
        raise ConversionError(str(exc)) from exc


def grasp_to_msg(candidate, header: Header, base_T_camera, base_frame: str) -> Grasp:
    """A predictor candidate -> defgg_interfaces/Grasp.

    `candidate` has the GraspPredictor fields (center_u_px, center_v_px,
    angle_rad, width_px, width_m, quality, position_camera_m,
    youngs_modulus_pa, object_id). `header` is the depth frame's header (its
    frame is the camera optical frame). width_m is clipped to the Panda
    hand's 0..GRIPPER_MAX_WIDTH_M; compare with the candidate to detect it.
    """
    width_m = float(candidate.width_m)
    if not np.isfinite(width_m):
        raise ConversionError(f"grasp width is not finite: {width_m!r}")
    try:
        camera_T_grasp = top_down_grasp_in_camera(candidate.position_camera_m, float(candidate.angle_rad))
        base_T_grasp = np.asarray(base_T_camera, dtype=np.float64) @ camera_T_grasp
        pose_camera = pose_from_transform(camera_T_grasp)
        pose_base = pose_from_transform(base_T_grasp)
    except TransformError as exc:
        raise ConversionError(str(exc)) from exc
    msg = Grasp()
    msg.header = header
    msg.pose_camera = PoseStamped(header=header, pose=pose_camera)
    msg.pose_base = PoseStamped(header=Header(stamp=header.stamp, frame_id=base_frame), pose=pose_base)
    msg.width_m = float(np.clip(width_m, 0.0, GRIPPER_MAX_WIDTH_M))
    msg.quality = float(candidate.quality)
    msg.angle_rad = float(candidate.angle_rad)
    msg.center_u_px = float(candidate.center_u_px)
    msg.center_v_px = float(candidate.center_v_px)
    msg.width_px = float(candidate.width_px)
    msg.youngs_modulus_pa = float(candidate.youngs_modulus_pa)
    msg.object_id = int(candidate.object_id)
    return msg


def stamp_to_ns(stamp: Time) -> int:
    """builtin_interfaces/Time -> integer nanoseconds (exact, for stamp matching)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(stamp_ns: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces/Time."""
    return Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))


def seconds_to_stamp(time_s: float) -> Time:
    """Seconds -> builtin_interfaces/Time, rounded to whole nanoseconds before the split, so x.9999999997 s
    becomes (x + 1) s, not x s (splitting first stamped such messages 1 s in the past)."""
    return ns_to_stamp(int(round(time_s * 1e9)))
