"""segmentation_node: the cell's only perceiver. depth (+camera_info, joint states, TF) -> PerceivedObjects.

Thin adapter over defgg_ros.planning.perceived_frame.perceive_frame (tabletop perception, the robot
self-filter, the stiffness entries; docs/perception.md "One perceiver"). For every frame it perceives it
publishes, with the depth frame's header (the inference node matches depth by exact stamp):
- `perceived_topic`: defgg_interfaces/PerceivedObjects (camera pose and its source, table plane, label
  image, each object's stiffness, height, area and cut, the height map planning runs on);
- `stiffness_topic` (32FC1 Pa, 0 = background) and `mask_topic` (mono8 labels), only while subscribed.
Newest frame wins: a worker thread perceives the newest frame; frames that arrive meanwhile replace the one
waiting (counted as dropped), so the output is never older than one perception. `perceive_service`
(defgg_interfaces/Perceive) perceives a client's own depth the same way. Assignments change through
`set_stiffness` or the `default_youngs_modulus_pa` / `objects_json` parameters and are latched on
`assignments_topic`. `capture_background` takes the latest depth as the empty scene: pixels not above it by
min_object_height_m are never objects (fixtures that are not table). Bad frames are skipped with a throttled
warning, counted, and on /diagnostics.
"""
import json
import threading
import time

import numpy as np
from defgg_interfaces.msg import ObjectStiffness, PerceivedObjects, StiffnessAssignment
from defgg_interfaces.srv import Perceive, SetStiffness
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_srvs.srv import Trigger

from defgg_ros.atomic import atomic_path
from defgg_ros.nodes.node_main import run_node
from defgg_ros.nodes.perceived_msg import perceived_to_msg
from defgg_ros.perception.depth_noise import DepthNoiseModel
from defgg_ros.perception.frame_worker import LatestFrameWorker, WorkerClosed, keep_executor_responsive
from defgg_ros.perception.geometry import transform_from_list
from defgg_ros.perception.self_filter import RobotSelfFilter
from defgg_ros.perception.stiffness_assignment import check_entries_fit_image, make_entry
from defgg_ros.perception.stiffness_segmenter import (
    check_plausible_default,
    entries_from_json,
    entries_to_dicts,
)
from defgg_ros.perception.table_pose import TABLE_FRAME_ID, PoseFromTable
from defgg_ros.perception.tabletop import TabletopConfig, WorkspaceBox
from defgg_ros.planning.perceived_frame import perceive_frame
from defgg_ros.ros import qos
from defgg_ros.ros.conversions import (
    ConversionError,
    camera_info_to_k,
    check_image_size,
    check_same_size,
    depth_msg_to_metres,
    numpy_to_image,
)
from defgg_ros.ros.diagnostics import NodeDiagnostics
from defgg_ros.ros.parameters import declare_parameters, load_schema
from defgg_ros.ros.service import answer
from defgg_ros.ros.tf import CameraPose

WARN_THROTTLE_S = 2.0
# A Perceive request's own depth is perceived in the request; it waits at most this long for the stream's.
PERCEIVE_LOCK_WAIT_S = 30.0

# Names, types, defaults and bounds: defgg_ros/ros/params/segmentation_node.yaml.
PARAMETERS = load_schema("segmentation_node")


class SegmentationNode(Node):
    def __init__(self, **kwargs):
        super().__init__("segmentation_node", **kwargs)
        declare_parameters(self)  # a value outside its schema raises ParameterError here
        keep_executor_responsive()  # the perception thread must not hold up the executor's depth callbacks
        self._lock = threading.Lock()
        self._captured_background = None  # from capture_background; a background_depth_file wins over it
        self._last_depth_m = None
        self._joint_positions = None    # name -> rad, for the self-filter
        p = self._params()
        self._base_T_camera = None if not any(p["base_T_camera"]) else transform_from_list(p["base_T_camera"])
        self._self_filter = RobotSelfFilter(float(p["self_filter_margin_m"])) if p["self_filter"] else None
        self._settings = self._settings_from(p)  # invalid start-up parameters raise here
        self._max_image_size_px = tuple(int(v) for v in p["max_image_size_px"])
        self._camera_k = None
        self._image_size = None
        self.frames_in = 0
        self.frames_processed = 0
        self.frames_rejected = 0
        self.last_rejection = ""  # the latest skipped frame's reason (the log line is throttled)
        self._perceived_pub = self.create_publisher(PerceivedObjects, p["perceived_topic"], qos.IMAGE_PUBLISH)
        self._stiffness_pub = self.create_publisher(Image, p["stiffness_topic"], qos.IMAGE_PUBLISH)
        self._mask_pub = self.create_publisher(Image, p["mask_topic"], qos.IMAGE_PUBLISH)
        self._assign_pub = self.create_publisher(StiffnessAssignment, p["assignments_topic"], qos.LATCHED)
        # TF, the parameter as fallback, and without either a table frame the executor refuses (a configured pose
        # is never second-guessed; one that disagrees with TF stops us).
        self._camera_pose = CameraPose(self, self._base_T_camera,
                                       PoseFromTable() if p["camera_pose_from_table"] else None,
                                       bool(p["publish_camera_tf"]))
        self.diagnostics = NodeDiagnostics(self, self._diagnostic_status)
        # Newest frame wins: the subscription only hands frames to one worker thread.
        self._worker = LatestFrameWorker(self._perceive_stream_frame, 0.0, self._publish_perceived,
                                         name="segmentation_perception", on_error=self._on_worker_error,
                                         max_busy_fraction=float(p["perception_max_core_fraction"]))
        # Reliability follows the camera driver's, and silence is logged (qos.SensorSubscription, issue 26).
        self._info_sub = qos.SensorSubscription(self, CameraInfo, p["camera_info_topic"], self._on_camera_info,
                                                warn_after_s=0.0)
        self._depth_sub = qos.SensorSubscription(self, Image, p["depth_topic"], self._on_depth,
                                                 warn_after_s=float(p["stream_timeout_s"]))
        if self._self_filter is not None:
            self.create_subscription(JointState, p["joint_states_topic"], self._on_joint_states, qos.SENSOR_DATA)
        self.create_service(SetStiffness, p["set_stiffness_service"], self._on_set_stiffness)
        self.create_service(Trigger, p["capture_background_service"], self._on_capture_background)
        # Its own group: a Perceive request is not queued behind the stream's callbacks.
        self.create_service(Perceive, p["perceive_service"], self._on_perceive,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._publish_assignments()

    def _params(self) -> dict:
        return {name: self.get_parameter(name).value for name in PARAMETERS}

    def _settings_from(self, p: dict) -> dict:
        """What perception reads per frame, from the parameters (ValueError/OSError on bad values)."""
        background = self._captured_background
        if p["background_depth_file"]:
            background = np.load(p["background_depth_file"], allow_pickle=False).astype(np.float32)
        box = [float(v) for v in p["workspace_box_m"]]
        noise = {}
        if "camera_model" in p:         # the camera's depth noise (perception/depth_noise.py)
            noise = {"depth_noise": DepthNoiseModel.for_camera(p["camera_model"]),
                     "depth_noise_from_table": bool(p["depth_noise_from_table"])}
        tabletop = TabletopConfig(workspace=WorkspaceBox((box[0], box[1]), (box[2], box[3]),
                                                         float(p["min_object_height_m"]),
                                                         float(p["max_object_height_m"])),
                                  table_z_m=float(p["table_z_m"]), **noise)
        return {"tabletop": tabletop, "entries": entries_from_json(p["objects_json"]),
                "default_pa": check_plausible_default(float(p["default_youngs_modulus_pa"])),
                "background_m": background, "min_height_m": float(p["min_object_height_m"]),
                "base_frame": p["base_frame"]}

    def base_T_camera_for(self, header) -> np.ndarray:
        """The camera optical frame in the base frame for this depth frame (4x4): TF's base_frame ->
        header.frame_id (latest), else the `base_T_camera` parameter; the first frame of each source is logged."""
        return self._camera_pose.lookup(self.get_parameter("base_frame").value, header.frame_id)

    def _on_joint_states(self, msg: JointState):
        if len(msg.name) == len(msg.position):
            with self._lock:
                self._joint_positions = {**(self._joint_positions or {}), **dict(zip(msg.name, msg.position))}

    def _excluded(self, depth_m, camera_k, base_T_camera, source, settings):
        """HxW bool pixels that are never objects: the robot (self-filter) and what the empty-scene capture
        already had (not above it by min_object_height_m); None when neither applies."""
        mask = None
        with self._lock:
            joints = self._joint_positions
        # In a table frame the robot's links cannot be placed in the image: no self-filter.
        if self._self_filter is not None and joints and source != "table":
            mask = self._self_filter.mask(joints, base_T_camera, camera_k, depth_m)
        background = settings["background_m"]
        if background is not None:
            if background.shape != depth_m.shape:
                raise ValueError(f"the empty-scene capture is {background.shape[1]}x{background.shape[0]} but the "
                                 f"depth is {depth_m.shape[1]}x{depth_m.shape[0]}")
            with np.errstate(invalid="ignore"):
                fixture = ~(background - depth_m > settings["min_height_m"])
            mask = fixture if mask is None else mask | fixture
        return mask

    def _on_set_parameters(self, params) -> SetParametersResult:
        merged = self._params()
        merged.update({param.name: param.value for param in params})
        try:
            settings = self._settings_from(merged)
        except (ValueError, OSError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        with self._lock:
            self._settings = settings
        self._publish_assignments()
        return SetParametersResult(successful=True)

    def _on_camera_info(self, msg: CameraInfo):
        try:
            self._camera_k = (camera_info_to_k(msg), msg)
        except ConversionError as exc:
            self._warn(f"ignoring camera_info: {exc}")

    # --- the stream -----------------------------------------------------------------------------------------
    def _on_depth(self, msg: Image):
        self.frames_in += 1
        try:
            self._worker.submit((msg, self._camera_k, time.perf_counter()))
        except WorkerClosed:
            pass

    def _perceive_stream_frame(self, item, checkpoint):
        msg, camera, received_s = item
        if camera is None:
            raise ConversionError(f"no camera_info received yet on {self._params()['camera_info_topic']}")
        out = self._perceive(msg, camera[1], None, checkpoint)
        self._last_depth_m = out[3]
        return (*out, received_s)

    def _perceive(self, depth_msg, info_msg, entries, checkpoint=None):
        """(PerceivedObjects, stiffness image, labels, depth m) of one frame; ValueError with the reason."""
        check_image_size("depth", depth_msg, self._max_image_size_px)
        check_same_size("depth", depth_msg, "camera_info", info_msg)
        camera_k = camera_info_to_k(info_msg)
        depth_m = depth_msg_to_metres(depth_msg)
        with self._lock:
            settings = self._settings
        base_frame = settings["base_frame"]
        base_T_camera, source = self._camera_pose.resolve(base_frame, depth_msg.header.frame_id, depth_m, camera_k,
                                                          settings["tabletop"])
        excluded = self._excluded(depth_m, camera_k, base_T_camera, source, settings)
        parts, _, image = perceive_frame(depth_m, camera_k, base_T_camera, settings["tabletop"],
                                         settings["entries"] if entries is None else entries,
                                         settings["default_pa"], excluded, checkpoint)
        pose_frame = TABLE_FRAME_ID if source == "table" else base_frame
        return perceived_to_msg(parts, depth_msg.header, pose_frame, source), image, parts.labels, depth_m

    def _publish_perceived(self, done, checkpoint):
        """The worker's output: publish each frame's perception, or count its rejection."""
        try:
            msg, image, labels, depth_m, received_s = done.value()
        except ValueError as exc:
            self.frames_rejected += 1
            self.last_rejection = str(exc)
            self.diagnostics.error(f"skipping depth frame: {exc}")
            self._warn(f"skipping depth frame: {exc}")
            # The frame's stamp with the reason: the inference node answers PlanGrasp with it instead of an
            # older frame's grasps (a camera pose conflict stops planning).
            self._perceived_pub.publish(PerceivedObjects(header=done.frame[0].header, error=str(exc)))
            return
        self._image_size = (msg.labels.width, msg.labels.height)
        self._perceived_pub.publish(msg)
        if self._stiffness_pub.get_subscription_count() > 0:
            self._stiffness_pub.publish(numpy_to_image(image, "32FC1", msg.header))
        if self._mask_pub.get_subscription_count() > 0:
            self._mask_pub.publish(numpy_to_image(labels, "mono8", msg.header))
        self.frames_processed += 1
        self.diagnostics.latency("perception", time.perf_counter() - received_s)

    def _on_worker_error(self, frame, exc):
        if not self.context.ok():
            return   # the context was shut down under a publish of the worker: the node is stopping, not failing
        self.get_logger().error(f"perception failed unexpectedly: {exc!r}")

    def _diagnostic_status(self) -> dict:
        w = self._worker
        return {"frames in": self.frames_in, "frames perceived": self.frames_processed,
                "frames rejected": self.frames_rejected, "frames dropped": w.dropped + w.superseded,
                "camera pose source": self._camera_pose.source}

    @property
    def frames_dropped(self) -> int:
        """Frames replaced by a newer one before perception started them (newest frame wins)."""
        return self._worker.dropped + self._worker.superseded

    # --- services -------------------------------------------------------------------------------------------
    def _on_perceive(self, request, response):
        def perceive() -> str:
            start = time.perf_counter()
            entries = None
            if request.objects:
                entries = tuple(make_entry(o.name, o.youngs_modulus_pa, (o.roi.x_offset, o.roi.y_offset,
                                           o.roi.width, o.roi.height), o.region_only) for o in request.objects)
                check_image_size("depth", request.depth, self._max_image_size_px)
                check_entries_fit_image(entries, request.depth.width, request.depth.height)
            if request.camera_info.width == 0 and request.camera_info.height == 0:
                raise ConversionError("request has depth but no camera_info")
            response.perceived = self._perceive(request.depth, request.camera_info, entries)[0]
            seconds = time.perf_counter() - start
            self.diagnostics.latency("perceive service", seconds)
            return (f"{len(response.perceived.objects)} object(s), camera pose from "
                    f"{response.perceived.camera_pose_source}, {seconds * 1e3:.0f} ms")
        return answer(response, perceive, "perceive", self.get_logger(), self.diagnostics.error)

    def _on_set_stiffness(self, request, response):
        try:
            entries = tuple(make_entry(o.name, o.youngs_modulus_pa, (o.roi.x_offset, o.roi.y_offset,
                                       o.roi.width, o.roi.height), o.region_only) for o in request.objects)
            if self._image_size is not None:
                check_entries_fit_image(entries, *self._image_size)
            default = float(request.default_youngs_modulus_pa or self._settings["default_pa"])
        except ValueError as exc:
            response.success, response.message = False, str(exc)
            return response
        # Go through the parameters so `objects_json` always shows what is in force.
        result = self.set_parameters_atomically([
            Parameter("objects_json", value=json.dumps(entries_to_dicts(entries))),
            Parameter("default_youngs_modulus_pa", value=default)])
        response.success, response.message = result.successful, result.reason
        if result.successful:
            response.message = f"{len(entries)} stiffness entries, default {default:g} Pa"
            self.get_logger().info(response.message)
        return response

    def _on_capture_background(self, request, response):
        depth_m = self._last_depth_m
        if depth_m is None:
            response.success, response.message = False, "no valid depth frame received yet"
            return response
        path = self._params()["background_save_file"]
        try:
            if path:
                with atomic_path(path) as tmp, open(tmp, "wb") as f:
                    np.save(f, depth_m, allow_pickle=False)
        except OSError as exc:
            response.success, response.message = False, f"could not save the capture to {path}: {exc}"
            return response
        with self._lock:
            self._captured_background = depth_m
            if not self._params()["background_depth_file"]:
                self._settings = {**self._settings, "background_m": depth_m}
        response.success = True
        response.message = (f"captured a {depth_m.shape[1]}x{depth_m.shape[0]} empty-scene depth"
                            + (f", saved to {path}" if path else "") + "; objects are now what rises above it")
        return response

    def _publish_assignments(self):
        with self._lock:
            settings = self._settings
        msg = StiffnessAssignment(stamp=self.get_clock().now().to_msg(),
                                  default_youngs_modulus_pa=settings["default_pa"])
        for item in entries_to_dicts(settings["entries"]):
            entry = ObjectStiffness(name=item["name"], youngs_modulus_pa=item["youngs_modulus_pa"],
                                    region_only=item["region_only"])
            entry.roi.x_offset, entry.roi.y_offset, entry.roi.width, entry.roi.height = item["roi"]
            msg.objects.append(entry)
        self._assign_pub.publish(msg)

    def _warn(self, text: str):
        self.get_logger().warning(text, throttle_duration_sec=WARN_THROTTLE_S)

    def destroy_node(self):
        self._worker.close()
        return super().destroy_node()


def main(args=None):
    run_node("segmentation_node", SegmentationNode, startup_errors=(ValueError, OSError), args=args)


if __name__ == "__main__":
    main()
