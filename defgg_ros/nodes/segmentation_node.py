"""segmentation_node: depth (+camera_info) -> object mask + Young's modulus image.

Thin adapter over defgg_ros.perception.stiffness_segmenter. Publishes, with
the depth frame's header (so the inference node can match by exact stamp):
- `stiffness_topic` (32FC1, Pa per pixel, 0 = background)
- `mask_topic` (mono8 labels, 0 = background)
and latches the assignments in force on `assignments_topic`. Assignments
change through the `set_stiffness` service or the `default_youngs_modulus_pa`
/ `objects_json` parameters. Bad frames are skipped with a throttled warning.
"""
import dataclasses
import json
import threading
import time

import numpy as np
from defgg_interfaces.msg import ObjectStiffness, StiffnessAssignment
from defgg_interfaces.srv import SetStiffness
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_srvs.srv import Trigger

from defgg_ros.atomic import atomic_path
from defgg_ros.nodes import qos
from defgg_ros.nodes.conversions import (
    ConversionError,
    camera_info_to_k,
    check_image_size,
    check_same_size,
    depth_msg_to_metres,
    numpy_to_image,
)
from defgg_ros.nodes.node_main import run_node
from defgg_ros.perception.geometry import transform_from_list
from defgg_ros.perception.self_filter import RobotSelfFilter
from defgg_ros.perception.stiffness_assignment import check_entries_fit_image, make_entry
from defgg_ros.perception.stiffness_segmenter import (
    SegmenterConfig,
    entries_from_json,
    entries_to_dicts,
    run_segmenter,
)
from defgg_ros.perception.table_pose import PoseFromTable
from defgg_ros.perception.tabletop import TabletopConfig, WorkspaceBox
from defgg_ros.ros.diagnostics import NodeDiagnostics
from defgg_ros.ros.parameters import at_default, declare_parameters, load_schema
from defgg_ros.ros.tf import CameraPose

WARN_THROTTLE_S = 2.0

# Names, types, defaults and bounds: defgg_ros/ros/params/segmentation_node.yaml.
PARAMETERS = load_schema("segmentation_node")


class SegmentationNode(Node):
    def __init__(self, **kwargs):
        super().__init__("segmentation_node", **kwargs)
        declare_parameters(self)  # a value outside its schema raises ParameterError here
        self._lock = threading.Lock()
        self._captured_background = None  # from capture_background; a background_depth_file wins over it
        self._last_depth_m = None
        self._joint_positions = None    # name -> rad, for the self-filter
        start = self._params()
        self._base_T_camera = transform_from_list(start["base_T_camera"])
        self._self_filter = (RobotSelfFilter(float(start["self_filter_margin_m"]))
                             if start["self_filter"] and start["segmentation"] == "tabletop" else None)
        self._config = self._config_from(start)  # invalid start-up parameters raise here
        self._camera_k = None
        self._image_size = None
        self.frames_processed = 0
        self.frames_rejected = 0
        self.last_rejection = ""  # the latest skipped frame's reason (the log line is throttled)
        p = self._params()
        self._stiffness_pub = self.create_publisher(Image, p["stiffness_topic"], qos.IMAGE_PUBLISH)
        self._mask_pub = self.create_publisher(Image, p["mask_topic"], qos.IMAGE_PUBLISH)
        self._assign_pub = self.create_publisher(StiffnessAssignment, p["assignments_topic"], qos.LATCHED)
        # Reliability follows the camera driver's, and silence is logged (qos.SensorSubscription, issue 26).
        self._info_sub = qos.SensorSubscription(self, CameraInfo, p["camera_info_topic"], self._on_camera_info,
                                                warn_after_s=0.0)
        self._depth_sub = qos.SensorSubscription(self, Image, p["depth_topic"], self._on_depth,
                                                 warn_after_s=float(p["stream_timeout_s"]))
        if self._self_filter is not None:
            self.create_subscription(JointState, p["joint_states_topic"], self._on_joint_states, qos.SENSOR_DATA)
        self.create_service(SetStiffness, p["set_stiffness_service"], self._on_set_stiffness)
        self.create_service(Trigger, p["capture_background_service"], self._on_capture_background)
        # TF, the parameter as fallback, and a table frame when the parameter is still the schema's placeholder
        # and finds no table (tabletop; a configured pose is never second-guessed).
        unset = at_default(PARAMETERS, "base_T_camera", list(p["base_T_camera"]))
        self._camera_pose = CameraPose(self, self._base_T_camera,
                                       PoseFromTable() if p["camera_pose_from_table"] and unset else None,
                                       bool(p["publish_camera_tf"]), fallback_is_placeholder=unset)
        self._max_image_size_px = tuple(int(v) for v in p["max_image_size_px"])
        self.diagnostics = NodeDiagnostics(self, self._diagnostic_status)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._publish_assignments()

    def _params(self) -> dict:
        return {name: self.get_parameter(name).value for name in PARAMETERS}

    def _config_from(self, p: dict) -> SegmenterConfig:
        background = self._captured_background
        if p["background_depth_file"]:
            background = np.load(p["background_depth_file"], allow_pickle=False).astype(np.float32)
        tabletop = None
        if p["segmentation"] == "tabletop":
            box = [float(v) for v in p["workspace_box_m"]]
            tabletop = TabletopConfig(workspace=WorkspaceBox((box[0], box[1]), (box[2], box[3]),
                                                             float(p["min_object_height_m"]),
                                                             float(p["max_object_height_m"])),
                                      table_z_m=float(p["table_z_m"]))
        return SegmenterConfig(float(p["default_youngs_modulus_pa"]), entries_from_json(p["objects_json"]),
                               float(p["min_object_height_m"]), int(p["min_object_area_px"]), background,
                               float(p["max_object_height_m"]), tabletop, self._base_T_camera)

    def base_T_camera_for(self, header) -> np.ndarray:
        """The camera optical frame in the base frame for this depth frame (4x4): TF's base_frame ->
        header.frame_id (latest), else the `base_T_camera` parameter; the first frame of each source is logged."""
        return self._camera_pose.lookup(self.get_parameter("base_frame").value, header.frame_id)

    def _on_joint_states(self, msg: JointState):
        if len(msg.name) == len(msg.position):
            with self._lock:
                self._joint_positions = {**(self._joint_positions or {}), **dict(zip(msg.name, msg.position))}

    def _robot_mask(self, depth_m, camera_k, base_T_camera):
        with self._lock:
            joints = self._joint_positions
        if self._self_filter is None or not joints:
            return None
        return self._self_filter.mask(joints, base_T_camera, camera_k, depth_m)

    def _on_set_parameters(self, params) -> SetParametersResult:
        merged = self._params()
        merged.update({param.name: param.value for param in params})
        try:
            config = self._config_from(merged)
        except (ValueError, OSError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        with self._lock:
            self._config = config
        self._publish_assignments()
        return SetParametersResult(successful=True)

    def _on_camera_info(self, msg: CameraInfo):
        try:
            self._camera_k = (camera_info_to_k(msg), msg)
        except ConversionError as exc:
            self._warn(f"ignoring camera_info: {exc}")

    def _diagnostic_status(self) -> dict:
        return {"frames perceived": self.frames_processed, "frames rejected": self.frames_rejected,
                "camera pose source": self._camera_pose.source}

    def _on_depth(self, msg: Image):
        self.diagnostics.count("frames in")
        start = time.perf_counter()
        try:
            check_image_size("depth", msg, self._max_image_size_px)
            if self._camera_k is None:
                raise ConversionError(f"no camera_info received yet on {self._params()['camera_info_topic']}")
            camera_k, info = self._camera_k
            check_same_size("depth", msg, "camera_info", info)
            depth_m = depth_msg_to_metres(msg)
            self._last_depth_m = depth_m
            with self._lock:
                config = self._config
            if config.tabletop is not None:
                base_T_camera, source = self._camera_pose.resolve(self.get_parameter("base_frame").value,
                                                                  msg.header.frame_id, depth_m, camera_k,
                                                                  config.tabletop)
                # In a table frame the robot's links cannot be placed in the image: no self-filter.
                robot = None if source == "table" else self._robot_mask(depth_m, camera_k, base_T_camera)
            else:
                base_T_camera, robot = self.base_T_camera_for(msg.header), None
            out = run_segmenter(config, depth_m, camera_k, robot, base_T_camera)
        except ValueError as exc:
            self.frames_rejected += 1
            self.last_rejection = str(exc)
            self.diagnostics.error(f"skipping depth frame: {exc}")
            self._warn(f"skipping depth frame: {exc}")
            return
        self._image_size = (msg.width, msg.height)
        self._stiffness_pub.publish(numpy_to_image(out.youngs_modulus_pa, "32FC1", msg.header))
        self._mask_pub.publish(numpy_to_image(out.labels, "mono8", msg.header))
        self.frames_processed += 1
        self.diagnostics.latency("perception", time.perf_counter() - start)

    def _on_set_stiffness(self, request, response):
        try:
            entries = tuple(make_entry(o.name, o.youngs_modulus_pa, (o.roi.x_offset, o.roi.y_offset,
                                       o.roi.width, o.roi.height), o.region_only) for o in request.objects)
            if self._image_size is not None:
                check_entries_fit_image(entries, *self._image_size)
            default = float(request.default_youngs_modulus_pa or self._config.default_youngs_modulus_pa)
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
                self._config = dataclasses.replace(self._config, background_depth_m=depth_m)
        response.success = True
        response.message = (f"captured a {depth_m.shape[1]}x{depth_m.shape[0]} empty-scene depth"
                            + (f", saved to {path}" if path else "") + "; objects are now what differs from it")
        return response

    def _publish_assignments(self):
        with self._lock:
            config = self._config
        msg = StiffnessAssignment(stamp=self.get_clock().now().to_msg(),
                                  default_youngs_modulus_pa=config.default_youngs_modulus_pa)
        for item in entries_to_dicts(config.entries):
            entry = ObjectStiffness(name=item["name"], youngs_modulus_pa=item["youngs_modulus_pa"],
                                    region_only=item["region_only"])
            entry.roi.x_offset, entry.roi.y_offset, entry.roi.width, entry.roi.height = item["roi"]
            msg.objects.append(entry)
        self._assign_pub.publish(msg)

    def _warn(self, text: str):
        self.get_logger().warning(text, throttle_duration_sec=WARN_THROTTLE_S)


def main(args=None):
    run_node("segmentation_node", SegmentationNode, startup_errors=(ValueError, OSError), args=args)


if __name__ == "__main__":
    main()
