"""A small TF listener and broadcaster over tf2_msgs/TFMessage, for a venv without tf2_ros.

tf2_ros (the C++ buffer and its Python wrapper) is not on PyPI; tf2_msgs is (built from
vendor_interfaces/ into the venv; on a ROS install the real package). The cell needs little of tf2:
the camera is fixed in the cell, so the latest transform of each frame is enough (no time
interpolation), and frames form a tree (each child has one parent), as in tf2.

- `TransformTree`: the pure part (no rclpy): add TransformStamped messages, look up
  `target_T_source` (4x4) along the tree, like tf2's lookupTransform(target, source).
- `TfListener(node)`: subscribes /tf and /tf_static with tf2_ros's QoS and fills a TransformTree;
  `lookup(target, source)` raises LookupError naming the missing link.
- `base_T_camera(listener, base_frame, camera_frame, fallback)`: what perception uses: the camera
  optical frame's pose in the robot base, from TF when known, else the fallback (the parameter).
- `transform_msg(parent, child, parent_T_child, stamp)`: a TransformStamped from a 4x4 matrix.

Not supported (say so rather than guess): a camera moving relative to the base (eye-in-hand)
needs transforms at the image's stamp; this tree keeps only the latest transform of each frame.
"""
import threading
import time

import numpy as np

from defgg_ros.perception.geometry import transform_to_xyz_quaternion
from defgg_ros.perception.table_pose import TABLE_FRAME_ID
from defgg_ros.rotations import matrix_to_quaternion_xyzw, quaternion_xyzw_to_matrix

FALLBACK_PUBLISH_DELAY_S = 2.0
TF_TOPIC = "/tf"            # absolute, as tf2_ros uses them; remap for a namespaced robot
TF_STATIC_TOPIC = "/tf_static"


class TransformTree:
    """Latest parent_T_child per child frame; lookups compose along the tree."""

    def __init__(self):
        self._lock = threading.Lock()
        self._edges = {}  # child -> (parent, parent_T_child 4x4, stamp_ns, static)

    def add(self, transform, static: bool = False) -> None:
        """Insert a geometry_msgs/TransformStamped. Raises ValueError on a malformed one (nothing changes)."""
        parent, child = transform.header.frame_id.lstrip("/"), transform.child_frame_id.lstrip("/")
        if not parent or not child or parent == child:
            raise ValueError(f"transform needs two different frame ids, got '{parent}' -> '{child}'")
        matrix = matrix_from_transform(transform.transform)
        stamp_ns = transform.header.stamp.sec * 1_000_000_000 + transform.header.stamp.nanosec
        with self._lock:
            if self._would_loop(parent, child):
                raise ValueError(f"transform {parent} -> {child} would close a loop in the TF tree")
            self._edges[child] = (parent, matrix, stamp_ns, bool(static))

    def add_message(self, tf_message, static: bool = False) -> list[str]:
        """Insert every transform of a tf2_msgs/TFMessage; returns the problems of the ones skipped."""
        problems = []
        for transform in tf_message.transforms:
            try:
                self.add(transform, static)
            except ValueError as error:
                problems.append(str(error))
        return problems

    def frames(self) -> set[str]:
        with self._lock:
            return set(self._edges) | {parent for parent, *_ in self._edges.values()}

    def lookup(self, target_frame: str, source_frame: str) -> np.ndarray:
        """target_T_source (4x4): maps points in source_frame to target_frame. LookupError if not connected."""
        target_frame, source_frame = target_frame.lstrip("/"), source_frame.lstrip("/")
        with self._lock:
            root_t, root_T_target = self._to_root(target_frame)
            root_s, root_T_source = self._to_root(source_frame)
        if root_t != root_s:
            known = ", ".join(sorted(self.frames())) or "none"
            raise LookupError(f"no TF path from '{source_frame}' to '{target_frame}' "
                              f"(their trees end at '{root_s}' and '{root_t}'; frames known: {known})")
        return np.linalg.inv(root_T_target) @ root_T_source

    def root_of(self, frame: str):
        """(root frame of frame's tree, root_T_frame 4x4); (frame, identity) for a frame TF does not know."""
        with self._lock:
            return self._to_root(frame.lstrip("/"))

    def _to_root(self, frame: str):
        """(root frame, root_T_frame) following parents (lock held)."""
        matrix, seen = np.eye(4), {frame}
        while frame in self._edges:
            parent, parent_T_child, _, _ = self._edges[frame]
            matrix = parent_T_child @ matrix
            frame = parent
            if frame in seen:  # cannot happen through add(); guards a corrupted tree
                raise LookupError(f"TF loop at '{frame}'")
            seen.add(frame)
        return frame, matrix

    def _would_loop(self, parent: str, child: str) -> bool:
        frame = parent
        while frame in self._edges:
            if frame == child:
                return True
            frame = self._edges[frame][0]
        return frame == child


def matrix_from_transform(transform) -> np.ndarray:
    """4x4 from a geometry_msgs/Transform. ValueError on non-finite values or a zero quaternion."""
    t, r = transform.translation, transform.rotation
    xyz = np.array([t.x, t.y, t.z], dtype=float)
    quat = np.array([r.x, r.y, r.z, r.w], dtype=float)
    norm = float(np.linalg.norm(quat))
    if not (np.all(np.isfinite(xyz)) and np.all(np.isfinite(quat))) or norm < 1e-6:
        raise ValueError(f"transform has non-finite values or a zero quaternion: {xyz.tolist()}, {quat.tolist()}")
    matrix = np.eye(4)
    # tf2 accepts any non-zero quaternion and normalises it; so does this
    matrix[:3, :3] = quaternion_xyzw_to_matrix(quat / norm)
    matrix[:3, 3] = xyz
    return matrix


def quaternion_from_matrix(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a 3x3 rotation matrix, w >= 0."""
    return tuple(float(v) for v in matrix_to_quaternion_xyzw(rotation))


def transform_msg(parent_frame: str, child_frame: str, parent_T_child: np.ndarray, stamp=None):
    """geometry_msgs/TransformStamped of a 4x4 matrix (stamp: builtin_interfaces/Time, default zero)."""
    from geometry_msgs.msg import TransformStamped

    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent_frame, child_frame
    if stamp is not None:
        msg.header.stamp = stamp
    matrix = np.asarray(parent_T_child, dtype=float)
    t = msg.transform.translation
    t.x, t.y, t.z = (float(v) for v in matrix[:3, 3])
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = quaternion_from_matrix(matrix[:3, :3])
    return msg


def tf_qos(static: bool):
    """tf2_ros's QoS: /tf reliable, volatile, keep last 100; /tf_static reliable, transient local, keep last 100
    (a static broadcaster's latched depth-1 writer matches it)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if static else DurabilityPolicy.VOLATILE)


class TfListener:
    """Fills a TransformTree from /tf and /tf_static (latest transform per frame)."""

    def __init__(self, node, tree: TransformTree | None = None, callback_group=None):
        from tf2_msgs.msg import TFMessage

        self.tree = tree or TransformTree()
        self._node = node
        node.create_subscription(TFMessage, TF_TOPIC, lambda m: self._on_message(m, False), tf_qos(False),
                                 callback_group=callback_group)
        node.create_subscription(TFMessage, TF_STATIC_TOPIC, lambda m: self._on_message(m, True), tf_qos(True),
                                 callback_group=callback_group)

    def _on_message(self, msg, static: bool) -> None:
        for problem in self.tree.add_message(msg, static):
            self._node.get_logger().warning(f"ignoring a transform: {problem}", throttle_duration_sec=5.0)

    def lookup(self, target_frame: str, source_frame: str) -> np.ndarray:
        """target_T_source (4x4); LookupError when TF does not connect the two frames (yet)."""
        return self.tree.lookup(target_frame, source_frame)


def base_T_camera(source, base_frame: str, camera_frame: str, fallback: np.ndarray | None = None):
    """(base_T_camera 4x4, where it came from: 'tf' or 'parameter').

    `source` is a TfListener or TransformTree. Without a TF path from camera_frame to base_frame the
    fallback is returned, or LookupError raised when there is none.
    """
    try:
        return source.lookup(base_frame, camera_frame), "tf"
    except LookupError:
        if fallback is None:
            raise
        return np.asarray(fallback, dtype=float), "parameter"


class TfBroadcaster:
    """Publishes transforms on /tf (moving frames, e.g. the planned grasp) or /tf_static (latched)."""

    def __init__(self, node, static: bool = False):
        from tf2_msgs.msg import TFMessage

        self._msg_type = TFMessage
        self._pub = node.create_publisher(TFMessage, TF_STATIC_TOPIC if static else TF_TOPIC,
                                          tf_qos(static) if static else tf_qos(False))

    def send(self, *transforms) -> None:
        self._pub.publish(self._msg_type(transforms=list(transforms)))


# A configured base_T_camera and TF's pose of the same frames may differ by this much (a calibration's own
# noise); more means one of them is stale or wrong (issue 46: a stale node's pose on /tf_static won silently).
POSE_AGREEMENT_M = 0.005
POSE_AGREEMENT_DEG = 0.5


class CameraPoseConflict(ValueError):
    """TF and the base_T_camera parameter give the same camera frame poses that disagree (message: both)."""


class CameraPoseUnknown(ValueError):
    """Neither TF nor a set base_T_camera gives the camera's pose, and no table frame can stand in."""


def pose_difference(a_T_b: np.ndarray, a_T_c: np.ndarray) -> tuple[float, float]:
    """(translation distance in m, rotation angle in degrees) between two 4x4 poses."""
    a, b = np.asarray(a_T_b, float), np.asarray(a_T_c, float)
    cos = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3])), float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def _pose_text(pose: np.ndarray) -> str:
    xyz, quaternion = transform_to_xyz_quaternion(pose)
    return "[" + ", ".join(f"{v:.4f}" for v in (*xyz, *quaternion)) + "]"


def check_poses_agree(tf_pose: np.ndarray, parameter_pose: np.ndarray, base_frame: str, camera_frame: str) -> None:
    """Raise CameraPoseConflict when TF's base_frame -> camera_frame and the parameter's differ by more than
    POSE_AGREEMENT_M or POSE_AGREEMENT_DEG; the message names both sources and both poses."""
    distance_m, angle_deg = pose_difference(tf_pose, parameter_pose)
    if distance_m > POSE_AGREEMENT_M or angle_deg > POSE_AGREEMENT_DEG:
        raise CameraPoseConflict(
            f"camera pose {base_frame} -> {camera_frame}: TF (/tf, /tf_static) gives {_pose_text(tf_pose)} but the "
            f"base_T_camera parameter gives {_pose_text(parameter_pose)} ([x, y, z, qx, qy, qz, qw]); they differ by "
            f"{distance_m * 1e3:.1f} mm and {angle_deg:.2f} deg (allowed {POSE_AGREEMENT_M * 1e3:.0f} mm, "
            f"{POSE_AGREEMENT_DEG} deg). Planning stops until they agree: correct the calibration on TF (or stop "
            "the node that publishes a stale one) or the parameter, or leave base_T_camera unset to use TF")


class CameraPose:
    """A node's camera pose per frame: TF's base_frame -> the frame's camera frame (latest transform), else
    the fallback (the base_T_camera parameter; None: not set). Without either, never the robot's frame: with
    `table_poses` a table frame estimated from the depth (perception/table_pose.py), else CameraPoseUnknown.
    Each change of source is logged once (the table frame as a warning: its grasps are not in the robot's
    frame). A fallback that disagrees with TF by more than POSE_AGREEMENT_M or POSE_AGREEMENT_DEG raises
    CameraPoseConflict for every frame until they agree (logged as an error).

    publish (parameter publish_camera_tf, off unless asked for: a camera driver or calibration publishes the
    camera on TF in a real cell): the pose in use goes on /tf_static, so RViz and other nodes see what the cell
    uses. A parameter pose as base_frame -> the root of the camera's TF tree (base -> camera_link when
    realsense2_camera publishes camera_link -> ... -> the optical frame; a frame has one parent, so never base
    -> optical frame then); a table frame as the camera frame's child `TABLE_FRAME_ID` (the grasps' frame
    then). Once published, the node's own lookups find the pose on TF (logged as such)."""

    def __init__(self, node, fallback: np.ndarray | None, table_poses=None, publish: bool = False):
        self._listener = TfListener(node)
        self._fallback = None if fallback is None else np.asarray(fallback, dtype=float)
        self._table_poses = table_poses
        self._logger = node.get_logger()
        self._source = None
        self._conflict = None           # the last CameraPoseConflict's text (logged once per change)
        self._static = TfBroadcaster(node, static=True) if publish else None
        # A latched calibration (or the fake driver's pose) may reach the node a moment after the first frame:
        # the parameter is published only once TF had that long to say otherwise.
        self._publish_fallback_after = time.monotonic() + FALLBACK_PUBLISH_DELAY_S
        self._sent = {}                 # (parent, child) -> the parent_T_child last published
        self._sent_lock = threading.Lock()

    @property
    def source(self) -> str:
        """Where the last frame's pose came from: 'tf', 'parameter', 'table', 'conflict' or '' (no frame yet)."""
        return "conflict" if self._conflict else (self._source or "")

    def lookup(self, base_frame: str, camera_frame: str) -> np.ndarray:
        """TF, else the parameter (no look at the frame); CameraPoseUnknown without either."""
        return self.resolve(base_frame, camera_frame)[0]

    def resolve(self, base_frame: str, camera_frame: str, depth_m=None, camera_k=None, table_config=None) -> tuple:
        """(base_T_camera, source: 'tf', 'parameter' or 'table'). Without TF and a configured parameter, the table
        frame from the frame's depth (m) and K (table_config: the tabletop perception's current TabletopConfig).
        Raises TabletopError when a table frame is needed and the depth shows no table, CameraPoseUnknown when
        one is needed and there is no depth or no table_poses."""
        try:
            pose, source = base_T_camera(self._listener, base_frame, camera_frame, self._fallback)
        except LookupError:
            pose, source = self._without_calibration(base_frame, camera_frame, depth_m, camera_k, table_config)
        if source == "tf" and self._fallback is not None:
            self._check(pose, base_frame, camera_frame)
        if source != self._source:
            self._source = source
            names = f"{base_frame} -> {camera_frame or '(no frame id)'}"
            if source == "table":
                self._logger.warning(
                    f"camera pose {names}: TF has none (yet) and base_T_camera is not set, "
                    "so a table frame estimated from the depth is used (the table at "
                    "table_z_m, the view's centre at the workspace box's centre): grasps are NOT in the robot's "
                    f"frame and the self-filter is off. Publish {names} on TF or set base_T_camera.")
            else:
                self._logger.info(f"camera pose {names} from "
                                  f"{'TF' if source == 'tf' else 'the base_T_camera parameter'}")
        if self._static is not None and camera_frame:
            self._publish(base_frame, camera_frame.lstrip("/"), pose, source)
        return pose, source

    def _without_calibration(self, base_frame, camera_frame, depth_m, camera_k, table_config) -> tuple:
        """Neither TF nor the parameter gives the pose: never the robot's frame (until 2026-12-02 the schema's
        placeholder pose stood in; a camera mounted near it passed the table check and its grasps would have sent
        the arm to the wrong place). The table frame, or the frame is refused."""
        if self._table_poses is None or depth_m is None:
            raise CameraPoseUnknown(
                f"no camera pose {base_frame} -> {camera_frame or '(no frame id)'}: TF has none (yet) and "
                "base_T_camera is not set. Publish the hand-eye calibration on TF (/tf_static) or set base_T_camera")
        return self._table_poses.pose_for(depth_m, camera_k, None, table_config)[0], "table"

    def _check(self, tf_pose: np.ndarray, base_frame: str, camera_frame: str) -> None:
        try:
            check_poses_agree(tf_pose, self._fallback, base_frame, camera_frame or "(no frame id)")
        except CameraPoseConflict as exc:
            if str(exc) != self._conflict:
                self._conflict = str(exc)
                self._logger.error(str(exc))
            raise
        if self._conflict:
            self._conflict = None
            self._logger.info(f"camera pose {base_frame} -> {camera_frame}: TF and base_T_camera agree again")

    def _publish(self, base_frame: str, camera_frame: str, pose: np.ndarray, source: str) -> None:
        if source == "parameter" and time.monotonic() >= self._publish_fallback_after:
            root, root_T_camera = self._listener.tree.root_of(camera_frame)
            parent, child, matrix = base_frame, root, pose @ np.linalg.inv(root_T_camera)
        elif source == "table":
            parent, child, matrix = camera_frame, TABLE_FRAME_ID, np.linalg.inv(pose)
        else:
            return
        with self._sent_lock:
            last = self._sent.get((parent, child))
            if last is not None and np.allclose(last, matrix, atol=1e-9):
                return
            self._sent[(parent, child)] = matrix
            transforms = [transform_msg(p, c, m) for (p, c), m in self._sent.items()]
        # /tf_static is latched per publisher: every transform this node publishes goes in each message.
        self._static.send(*transforms)
