"""grasp_inference_node: depth + stiffness (+camera_info) -> Def-GG-CNN grasps.

Thin adapter over defgg_ros.model.inference.GraspPredictor:
- synchronises depth, the segmentation node's stiffness image and
  camera_info by exact stamp (defgg_ros.perception.sync, no message_filters);
- on each synchronised frame (if `publish_on_sync`) publishes the best grasp,
  the quality map (32FC1, depth-sized, 0 outside the network's crop) and a
  MarkerArray with the two finger boxes;
- serves PlanGrasp: empty request depth -> the latest synchronised frame;
  otherwise the request's depth + camera_info with either its stiffness
  image or its `objects` (then the depth is segmented here exactly like the
  segmentation node does). Every bad request gets success=false + reason.
- tabletop planner with `perceive_on_arrival`: each synchronised frame is
  perceived as it arrives (conversion, perception, moduli, network, the top_k
  1 search with `publish_on_sync` and the searches for every top_k asked for
  in the last `prepare_requested_top_k_s`; two worker threads by default,
  `perception_stages`: one converts and perceives the next frame while the
  other runs the network on the frame before, perception/frame_worker.py:
  only the newest waiting frame is kept at each stage), and an
  empty PlanGrasp only searches a perceived frame for grasps (or reads the
  search made on arrival): the newest perceived one when no
  newer frame arrived or it arrived at most `max_frame_age_s` before the
  request, else the latest frame (waiting for its perception, or perceiving
  it here when the worker has not started it). The grasps are those the
  synchronous path gives for the same frame.
"""
import dataclasses
import threading
import time
from pathlib import Path

import numpy as np
from defgg_interfaces.msg import Grasp
from defgg_interfaces.srv import PlanGrasp
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.grip_force import GripRuleError, LabelGripRule
from defgg_ros.model.inference import CheckpointError, GraspPredictor
from defgg_ros.nodes import qos
from defgg_ros.nodes.conversions import (
    camera_info_to_k,
    check_image_size,
    check_same_size,
    depth_msg_to_metres,
    grasp_to_msg,
    numpy_to_image,
    pose_from_transform,
    stamp_to_ns,
    stiffness_msg_to_pa,
    transform_from_list,
    transform_from_pose,
)
from defgg_ros.nodes.node_main import run_node
from defgg_ros.perception.frame_worker import LatestFrameWorker, RecentValues, WorkerClosed
from defgg_ros.perception.grasp_planning import (
    PlanningError,
    check_top_k,
    finger_boxes_in_grasp,
    full_quality_image,
    labels_from_stiffness,
)
from defgg_ros.perception.self_filter import RobotSelfFilter
from defgg_ros.perception.stiffness_assignment import check_entries_fit_image, make_entry
from defgg_ros.perception.stiffness_segmenter import SegmenterConfig, run_segmenter
from defgg_ros.perception.sync import StampSynchronizer
from defgg_ros.perception.table_pose import TABLE_FRAME_ID, PoseFromTable
from defgg_ros.perception.tabletop import TabletopConfig, WorkspaceBox
from defgg_ros.planning.grip_estimate import grip_estimate
from defgg_ros.planning.tabletop_grasps import base_T_grasp, image_projection
from defgg_ros.planning.tabletop_planner import TabletopPlanner
from defgg_ros.ros.diagnostics import NodeDiagnostics
from defgg_ros.ros.memory import keep_freed_memory
from defgg_ros.ros.parameters import at_default, declare_parameters, load_schema
from defgg_ros.ros.share import share_path
from defgg_ros.ros.tf import CameraPose, TfBroadcaster, transform_msg

WARN_THROTTLE_S = 2.0
# An empty PlanGrasp waits at most this long for the perception of the latest frame.
PERCEPTION_WAIT_S = 30.0
MODEL_FILES = {True: "defgg_cnn.pt", False: "ggcnn_depth_only.pt"}
# Camera 0.40 m above the table at (0.5, 0, 0) in panda_link0, looking down
# (pi about x) — the cell's scene files use the same mount.
DEFAULT_BASE_T_CAMERA = [0.5, 0.0, 0.40, 1.0, 0.0, 0.0, 0.0]

# Names, types, defaults and bounds: defgg_ros/ros/params/grasp_inference_node.yaml.
PARAMETERS = load_schema("grasp_inference_node")


def default_model_path(use_stiffness: bool) -> Path:
    """The shipped checkpoint: the source tree's models/ or the installed share/defgg_ros/models/."""
    return share_path("models", MODEL_FILES[bool(use_stiffness)])


@dataclasses.dataclass(frozen=True)
class Frame:
    """One planning input: converted arrays plus the depth header."""

    header: object                  # std_msgs/Header of the depth image
    depth_m: np.ndarray             # HxW float32, NaN = invalid
    youngs_modulus_pa: np.ndarray   # HxW float32, 0 = background
    camera_k: np.ndarray            # 3x3
    labels: np.ndarray | None       # HxW uint8 object labels, 0 = background (camera_crop planner only)
    entries: tuple = ()             # request `objects` (tabletop planner: assigned to the perceived objects)


class _Searches:
    """One frame's searches by top_k, each made once by whoever asks first (the worker's publish_on_sync
    search for top_k 1, or a request); a later asker of the same top_k waits for it and gets the same grasps."""

    def __init__(self):
        self._lock = threading.Lock()
        self._entries = {}          # top_k -> [done Event, (result, grasps), error]

    def made(self, top_k: int) -> bool:
        """Whether the search for top_k is finished (made by the worker or an earlier request)."""
        with self._lock:
            entry = self._entries.get(top_k)
        return entry is not None and entry[0].is_set()

    def get(self, top_k: int, search):
        with self._lock:
            entry = self._entries.get(top_k)
            mine = entry is None
            if mine:
                entry = self._entries[top_k] = [threading.Event(), None, None]
        if mine:
            try:
                entry[1] = search()
            except Exception as exc:  # noqa: BLE001 - every asker gets the same error
                entry[2] = exc
            finally:
                entry[0].set()
        else:
            entry[0].wait()
        if entry[2] is not None:
            raise entry[2]
        return entry[1]


@dataclasses.dataclass(frozen=True)
class PerceivedFrame:
    """A frame through the tabletop planner's request-independent part (TabletopPlanner.prepare)."""

    frame: Frame
    base_T_camera: np.ndarray
    prepared: object                # planning.tabletop_planner.PreparedFrame
    seconds: float                  # wall time of the preparation
    pose_frame_id: str              # the frame of base_T_camera and of the grasps: base_frame, or TABLE_FRAME_ID
    searches: _Searches = dataclasses.field(default_factory=_Searches, compare=False)


@dataclasses.dataclass(frozen=True)
class _Perceived:
    """A frame through perception (the first stage of perception on arrival), before the network."""

    frame: Frame
    base_T_camera: np.ndarray
    objects: object                 # planning.tabletop_planner.PerceivedObjects
    seconds: float                  # wall time so far
    pose_frame_id: str              # base_frame, or TABLE_FRAME_ID when the pose is a table frame


class GraspInferenceNode(Node):
    def __init__(self, **kwargs):
        super().__init__("grasp_inference_node", **kwargs)
        declare_parameters(self)  # a value outside its schema raises ParameterError here
        keep_freed_memory()       # frame-sized temporaries in worker threads: no page faults per frame
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self._p = p
        self._base_T_camera = transform_from_list(p["base_T_camera"])
        if not 0.0 <= float(p["finger_clearance_opening_m"]) <= GRIPPER_MAX_WIDTH_M:
            raise ValueError(f"finger_clearance_opening_m must be in [0, {GRIPPER_MAX_WIDTH_M}] m, "
                             f"got {p['finger_clearance_opening_m']}")
        model_path = Path(p["model_path"]) if p["model_path"] else default_model_path(p["use_stiffness"])
        self.predictor = GraspPredictor.from_checkpoint(model_path, num_threads=int(p["num_threads"]))
        if self.predictor.uses_stiffness != bool(p["use_stiffness"]):
            raise ValueError(f"{model_path} is a {'depth+stiffness' if self.predictor.uses_stiffness else 'depth-only'}"
                             f" network but use_stiffness is {p['use_stiffness']}")
        self._grip_rule = self._label_grip_rule(model_path, p["planner"])
        self._segmenter = SegmenterConfig(float(p["default_youngs_modulus_pa"]), (),
                                          float(p["min_object_height_m"]), int(p["min_object_area_px"]),
                                          max_height_m=float(p["max_object_height_m"]))
        self._tabletop = self._tabletop_planner(p) if p["planner"] == "tabletop" else None
        self._joint_positions = None    # name -> rad, for the self-filter
        self._predict_lock = threading.Lock()
        self._state_lock = threading.Lock()
        self._sync = StampSynchronizer(("depth", "stiffness", "info"), int(p["sync_cache_size"]))
        self._latest_frame = None
        self._latest_info = None
        self._latest_stamp_ns = None
        self.synced_frames = 0          # frames matched by stamp
        self.skipped_frames = 0         # synchronised, but not convertible (wrong sizes, encodings)
        self._worker = None
        # The top_k values empty requests asked for lately: perception on arrival makes those searches too.
        self._requested_top_k = RecentValues(float(p["prepare_requested_top_k_s"]))
        self._grasp_pub = self.create_publisher(Grasp, p["best_grasp_topic"], qos.STATE)
        self._quality_pub = self.create_publisher(Image, p["quality_topic"], qos.SENSOR_DATA)
        self._marker_pub = self.create_publisher(MarkerArray, p["markers_topic"], qos.STATE)
        self._tf_broadcaster = TfBroadcaster(self)  # the planned grasp as TF frame grasp_frame
        # TF, the parameter as fallback, and a table frame when the parameter is still the schema's placeholder
        # and finds no table (tabletop planner; a configured pose is never second-guessed).
        placeholder = at_default(PARAMETERS, "base_T_camera", list(p["base_T_camera"]))
        table_poses = PoseFromTable(self._tabletop.config) if self._tabletop is not None and \
            p["camera_pose_from_table"] and placeholder else None
        self._camera_pose = CameraPose(self, self._base_T_camera, table_poses, bool(p["publish_camera_tf"]),
                                       fallback_is_placeholder=placeholder)
        # Reliability follows the publishers', and silence is logged (qos.SensorSubscription, issue 26).
        self._stream_subs = [
            qos.SensorSubscription(self, Image, p["depth_topic"], lambda m: self._on_stream("depth", m),
                                   warn_after_s=float(p["stream_timeout_s"])),
            qos.SensorSubscription(self, Image, p["stiffness_topic"], lambda m: self._on_stream("stiffness", m),
                                   warn_after_s=float(p["stream_timeout_s"])),
            qos.SensorSubscription(self, CameraInfo, p["camera_info_topic"], lambda m: self._on_stream("info", m),
                                   warn_after_s=0.0)]
        if self._tabletop is not None and self._tabletop.self_filter is not None:
            self.create_subscription(JointState, p["joint_states_topic"], self._on_joint_states, qos.SENSOR_DATA)
        self.create_service(PlanGrasp, p["plan_grasp_service"], self._on_plan_grasp)
        # Perception on arrival (tabletop planner): a worker thread prepares each synchronised frame.
        if self._tabletop is not None and p["perceive_on_arrival"]:
            stages = (self._perceive_stage, self._network_stage)
            if int(p["perception_stages"]) == 1:
                stages = (lambda matched, checkpoint: self._network_stage(self._perceive_stage(matched, checkpoint),
                                                                          checkpoint),)
            self._worker = LatestFrameWorker(stages, float(p["max_frame_age_s"]),
                                             self._publish_perceived if p["publish_on_sync"] else None,
                                             on_error=self._on_worker_error)
        self.diagnostics = NodeDiagnostics(self, self._diagnostic_status)
        self.get_logger().info(f"loaded {model_path} (runtime {self.predictor.runtime}, "
                               f"stiffness {'on' if self.predictor.uses_stiffness else 'off'})")

    def _diagnostic_status(self) -> dict:
        counts = self.perception_counts
        return {"frames in": self.synced_frames, "frames perceived": counts.get("perceived", self.synced_frames),
                "frames dropped": counts.get("dropped", 0) + counts.get("superseded", 0),
                "frames unusable": self.skipped_frames, "camera pose source": self._camera_pose.source}

    def _tabletop_planner(self, p) -> TabletopPlanner:
        box = [float(v) for v in p["workspace_box_m"]]
        workspace = WorkspaceBox((box[0], box[1]), (box[2], box[3]), float(p["min_object_height_m"]),
                                 float(p["max_object_height_m"]))
        robot = RobotSelfFilter(float(p["self_filter_margin_m"])) if p["self_filter"] else None
        return TabletopPlanner(self.predictor, TabletopConfig(workspace=workspace, table_z_m=float(p["table_z_m"])),
                               float(p["default_youngs_modulus_pa"]), robot)

    def base_T_camera_for(self, header) -> np.ndarray:
        """The camera optical frame in the base frame for a frame with this header (4x4): TF's base_frame ->
        header.frame_id (latest), else the `base_T_camera` parameter; the first frame of each source is logged."""
        return self._camera_pose.lookup(self._p["base_frame"], header.frame_id)

    def _on_joint_states(self, msg: JointState):
        if len(msg.name) == len(msg.position):
            positions = dict(zip(msg.name, msg.position))
            with self._state_lock:
                self._joint_positions = {**(self._joint_positions or {}), **positions}

    # --- streams ------------------------------------------------------------
    def _on_stream(self, stream: str, msg):
        with self._state_lock:
            if stream == "info":
                self._latest_info = msg
            matched = self._sync.add(stream, stamp_to_ns(msg.header.stamp), msg)
        if matched is None:
            return
        stamp_ns = stamp_to_ns(matched["depth"].header.stamp)
        if self._worker is not None:
            # The worker converts the frames it takes (frames it drops are never converted): this thread only
            # matches stamps, so a PlanGrasp request does not queue behind conversions.
            with self._state_lock:
                self.synced_frames += 1
                self._latest_stamp_ns = stamp_ns
            self._worker.submit(matched)
            return
        try:
            frame = self._convert_matched(matched)
        except ValueError:
            return
        with self._state_lock:
            self._latest_frame = frame
            self._latest_stamp_ns = stamp_ns
            self.synced_frames += 1
        if self._p["publish_on_sync"]:
            self._plan_and_publish(frame)

    def _convert_matched(self, matched) -> Frame:
        """A synchronised depth + camera_info + stiffness as a Frame; a frame that cannot be converted is
        warned about, counted (skipped_frames) and raises ValueError."""
        try:
            return self._frame_from_images(matched["depth"], matched["info"], matched["stiffness"])
        except ValueError as exc:
            self._warn(f"unusable synchronised frame: {exc}")
            with self._state_lock:
                self.skipped_frames += 1
            raise

    def _plan_and_publish(self, frame: Frame):
        try:
            prediction, grasps, _ = self._plan(frame, top_k=1)
        except ValueError as exc:
            self._warn(f"no grasp for frame: {exc}")
            return
        self._publish_outputs(frame, prediction, grasps)

    def _publish_outputs(self, frame: Frame, prediction, grasps):
        # The depth-sized quality image only when someone reads it: at 1280x720 making and serialising it
        # (3.7 MB) costs ~5 ms per frame.
        if self._quality_pub.get_subscription_count() > 0:
            if self._tabletop is not None:
                quality = prediction.plan.quality_image(prediction.view)
            else:
                quality = full_quality_image(prediction.q, prediction.crop_offset_px, frame.depth_m.shape)
            self._quality_pub.publish(numpy_to_image(quality, "32FC1", frame.header))
        if grasps:
            self._grasp_pub.publish(grasps[0])
            self._marker_pub.publish(self._markers(grasps[0]))
            self._publish_grasp_frame(grasps[0])

    # --- perception on arrival (tabletop planner) ---------------------------
    def _perceive(self, frame: Frame, checkpoint) -> PerceivedFrame:
        """The preparation of a synchronised frame (TabletopPlanner.prepare); raises ValueError for a frame
        without table, objects or moduli on them (requests then answer with that reason)."""
        return self._network_stage(self._perceive_stage(frame, checkpoint), checkpoint, search=False)

    def _perceive_stage(self, frame, checkpoint) -> _Perceived:
        """Perception on arrival's first stage (and the synchronous path's first half): conversion of a
        synchronised frame (a dict of messages; a frame that cannot be converted is a perceived frame with
        that error: requests answer with it), the camera pose, perception and the objects' moduli."""
        if isinstance(frame, dict):
            frame = self._convert_matched(frame)
        start = time.perf_counter()
        base_T_camera, source = self._camera_pose.resolve(self._p["base_frame"], frame.header.frame_id,
                                                          frame.depth_m, frame.camera_k)
        with self._state_lock:
            # In a table frame the robot's links cannot be placed in the image: no self-filter.
            joints = None if source == "table" else self._joint_positions
        objects = self._tabletop.perceive(frame.depth_m, frame.camera_k, base_T_camera, frame.youngs_modulus_pa,
                                          frame.entries, joints, checkpoint)
        pose_frame_id = TABLE_FRAME_ID if source == "table" else self._p["base_frame"]
        return _Perceived(frame, base_T_camera, objects, time.perf_counter() - start, pose_frame_id)

    def _network_stage(self, perceived: _Perceived, checkpoint, search: bool = True) -> PerceivedFrame:
        """The second stage: the network on the height map and the free space (TabletopPlanner.network); on
        arrival also the frame's searches requests will want, before they see the frame: top_k 1 with
        publish_on_sync (which it publishes) and every top_k asked for lately (prepare_requested_top_k_s)."""
        start = time.perf_counter()
        prepared = self._tabletop.network(perceived.objects, checkpoint)
        out = PerceivedFrame(perceived.frame, perceived.base_T_camera, prepared,
                             perceived.seconds + time.perf_counter() - start, perceived.pose_frame_id)
        if search:      # on arrival (the worker's stages)
            self.diagnostics.latency("perception", out.seconds)
            wanted = self._requested_top_k.recent() | ({1} if self._p["publish_on_sync"] else set())
            for top_k in sorted(wanted):
                checkpoint()
                try:
                    self._search(out, top_k)
                except ValueError:  # no feasible grasp: kept for the requests, warned when publishing
                    pass
        return out

    def _publish_perceived(self, done, checkpoint):
        """publish_on_sync with perception on arrival: the best grasp of each frame the worker perceived."""
        try:
            perceived = done.value()
            result, grasps = self._search(perceived, 1)
        except ValueError as exc:
            self._warn(f"no grasp for frame: {exc}")
            return
        checkpoint()
        self._publish_outputs(perceived.frame, result, grasps)

    def _on_worker_error(self, frame, exc):
        self.get_logger().error(f"perception on arrival failed unexpectedly: {exc!r}")

    def _search(self, perceived: PerceivedFrame, top_k: int):
        """(TabletopResult, Grasp messages) of a perceived frame, searched once per top_k (_Searches)."""
        def search():
            result = self._tabletop.search(perceived.prepared, top_k)
            return result, [self._tabletop_grasp_msg(g, perceived.frame, perceived.base_T_camera,
                                                     perceived.pose_frame_id, perceived.prepared.network)
                            for g in result.grasps]
        return perceived.searches.get(top_k, search)

    def _plan_latest_perceived(self, top_k: int):
        """An empty request with perception on arrival: (grasps, seconds, summary) from a perceived frame."""
        start = time.perf_counter()
        self._requested_top_k.note(top_k)
        try:
            done = self._worker.latest(PERCEPTION_WAIT_S)
        except (TimeoutError, WorkerClosed) as exc:
            raise PlanningError(f"the latest frame could not be perceived: {exc}") from exc
        if done is None:
            raise PlanningError(NO_FRAME_YET)
        waited = time.perf_counter() - start
        perceived = done.value()
        on_arrival = perceived.searches.made(top_k)
        with self._worker.priority():
            _, grasps = self._search(perceived, top_k)
        seconds = time.perf_counter() - start
        worker = self._worker
        note = (f"; frame perceived on arrival ({perceived.seconds * 1e3:.1f} ms; waited {waited * 1e3:.1f} ms, "
                f"searched {(seconds - waited) * 1e3:.1f} ms; {worker.prepared} of {worker.submitted} "
                f"synchronised frames perceived{'; top_k searched on arrival' if on_arrival else ''})")
        return grasps, seconds, note

    # --- PlanGrasp ----------------------------------------------------------
    def _on_plan_grasp(self, request, response):
        note = ""
        try:
            top_k = check_top_k(request.top_k)
            if self._worker is not None and _unset(request.depth) and _unset(request.stiffness) \
                    and not request.objects:
                grasps, seconds, note = self._plan_latest_perceived(top_k)
            else:
                frame = self._frame_from_request(request)
                _, grasps, seconds = self._plan(frame, top_k)
        except ValueError as exc:  # ConversionError, PlanningError, predictor and segmentation errors
            response.success, response.message = False, str(exc) or type(exc).__name__
            self.diagnostics.error(f"plan_grasp: {response.message}")
            return response
        except Exception as exc:  # noqa: BLE001 - a service must answer, whatever broke
            self.get_logger().error(f"plan_grasp failed unexpectedly: {exc!r}")
            response.success, response.message = False, f"internal error: {exc!r}"
            return response
        response.success = True
        response.grasps = grasps
        response.inference_time_s = seconds
        self.diagnostics.latency("plan_grasp", seconds)
        best = grasps[0]
        self._publish_grasp_frame(best)
        response.message = (f"{len(grasps)} grasp(s); best q={best.quality:.3f} at ({best.center_u_px:.0f}, "
                            f"{best.center_v_px:.0f}) px, width {best.width_m * 1000:.1f} mm, object {best.object_id}"
                            f"{note}")
        return response

    def _publish_grasp_frame(self, grasp: Grasp) -> None:
        """The grasp's TCP pose as TF frame `grasp_frame` under the base frame (on /tf), so rviz and
        `ros2 run tf2_ros tf2_echo <base> defgg_grasp` show where the executor would be sent."""
        pose = grasp.pose_base
        try:
            base_T_grasp = transform_from_pose(pose.pose)
        except ValueError as exc:
            self._warn(f"grasp frame not published: {exc}")
            return
        self._tf_broadcaster.send(transform_msg(pose.header.frame_id or self._p["base_frame"], self._p["grasp_frame"],
                                                base_T_grasp, pose.header.stamp))

    def _frame_from_request(self, request) -> Frame:
        if _unset(request.depth):
            if not _unset(request.stiffness) or request.objects:
                raise PlanningError("stiffness or objects were given without a depth image")
            with self._state_lock:
                frame = self._latest_frame
            if frame is None:
                raise PlanningError(NO_FRAME_YET)
            return frame
        info = request.camera_info
        if info.width == 0 and info.height == 0:
            raise PlanningError("request has depth but no camera_info")
        if not _unset(request.stiffness):
            if request.objects:
                raise PlanningError("give either a stiffness image or objects, not both")
            return self._frame_from_images(request.depth, info, request.stiffness)
        return self._frame_from_objects(request.depth, info, request.objects)

    def _frame_from_images(self, depth_msg, info_msg, stiffness_msg) -> Frame:
        check_image_size("depth", depth_msg, self._p["max_image_size_px"])
        check_same_size("depth", depth_msg, "camera_info", info_msg)
        check_same_size("depth", depth_msg, "stiffness", stiffness_msg)
        camera_k = camera_info_to_k(info_msg)
        depth_m = depth_msg_to_metres(depth_msg)
        youngs_modulus_pa = stiffness_msg_to_pa(stiffness_msg)
        if self._tabletop is not None:      # objects come from the depth; the image gives their moduli
            return Frame(depth_msg.header, depth_m, youngs_modulus_pa, camera_k, None)
        return Frame(depth_msg.header, depth_m, youngs_modulus_pa, camera_k, labels_from_stiffness(youngs_modulus_pa))

    def _frame_from_objects(self, depth_msg, info_msg, objects) -> Frame:
        check_image_size("depth", depth_msg, self._p["max_image_size_px"])
        check_same_size("depth", depth_msg, "camera_info", info_msg)
        camera_k = camera_info_to_k(info_msg)
        depth_m = depth_msg_to_metres(depth_msg)
        entries = tuple(make_entry(o.name, o.youngs_modulus_pa, (o.roi.x_offset, o.roi.y_offset, o.roi.width,
                                   o.roi.height), o.region_only) for o in objects)
        check_entries_fit_image(entries, depth_msg.width, depth_msg.height)
        if self._tabletop is not None:
            return Frame(depth_msg.header, depth_m, None, camera_k, None, entries)
        config = dataclasses.replace(self._segmenter, entries=entries)
        out = run_segmenter(config, depth_m, camera_k)
        if not out.segmentation.object_ids:
            raise PlanningError("no object found above the table in the request depth")
        return Frame(depth_msg.header, depth_m, out.youngs_modulus_pa, camera_k, out.labels)

    def _plan(self, frame: Frame, top_k: int):
        if self._tabletop is not None:
            return self._plan_tabletop(frame, top_k)
        if not np.any(frame.labels):
            raise PlanningError("the stiffness image has no object pixel (all background)")
        start = time.perf_counter()
        with self._predict_lock:
            prediction = self.predictor.predict(frame.depth_m, frame.youngs_modulus_pa, frame.camera_k,
                                                object_mask=frame.labels, top_k=top_k,
                                                finger_clearance_opening_m=self._p["finger_clearance_opening_m"],
                                                contact_angle=self._p["contact_angle"])
        if not prediction.candidates:
            raise PlanningError("the network found no grasp on the objects")
        if prediction.candidates[0].fingers_clear is False:
            self._warn("no grasp among the best peaks lets both fingers land beside the objects")
        seconds = time.perf_counter() - start
        base_T_camera = self.base_T_camera_for(frame.header)
        grasps = [grasp_to_msg(c, frame.header, base_T_camera, self._p["base_frame"]) for c in prediction.candidates]
        for candidate in prediction.candidates:
            if candidate.width_m > GRIPPER_MAX_WIDTH_M:
                self._warn(f"grasp width {candidate.width_m * 1000:.0f} mm clipped to the hand's "
                           f"{GRIPPER_MAX_WIDTH_M * 1000:.0f} mm")
        return prediction, grasps, seconds

    def _plan_tabletop(self, frame: Frame, top_k: int):
        """Synchronously: perceive and search (the same steps as the worker's, in one go). The worker goes on
        meanwhile: pausing it for a whole perception would leave the latest frame unperceived."""
        start = time.perf_counter()
        perceived = self._perceive(frame, None)
        result, grasps = self._search(perceived, top_k)
        return result, grasps, time.perf_counter() - start

    def _label_grip_rule(self, model_path, planner: str) -> LabelGripRule:
        """The grip force rule of the model's labels (its weights record it; legacy when they do not)."""
        try:
            rule = LabelGripRule.from_meta(self.predictor.checkpoint_meta.get("meta"))
        except GripRuleError as exc:
            raise CheckpointError(f"{model_path}: {exc}") from exc
        if rule.needs_mass and planner != "tabletop":
            self.get_logger().warning(
                f"{model_path}'s labels squeezed with F = FOS*m*g/mu ({rule.protocol}); only the tabletop planner "
                "estimates the mass, so the executor will close these grasps with its legacy force")
        return rule

    def _grip_fields(self, msg: Grasp, grasp, network) -> None:
        """Grasp.estimated_mass_kg and finger_force_n (planning/grip_estimate.py)."""
        try:
            grip = grip_estimate(network, grasp.object_id, self._grip_rule, float(self._p["object_density_kg_m3"]))
        except ValueError as exc:     # a grasp is always on an object's cells; never lose the grasp over this
            self._warn(f"no grip estimate for object {grasp.object_id} ({exc}); Grasp.finger_force_n 0: the "
                       "executor's legacy force")
            return
        msg.estimated_mass_kg = grip.mass_kg
        msg.finger_force_n = grip.finger_force_n
        if self._grip_rule.needs_mass and grip.finger_force_n <= 0.0:
            self._warn(f"object {grasp.object_id}: no volume seen, so no mass for the labels' grip force; the "
                       "executor will close with its legacy force")

    def _tabletop_grasp_msg(self, grasp, frame: Frame, base_T_camera, pose_frame_id: str, network) -> Grasp:
        """pose_base is in pose_frame_id: the base frame, or the table frame (which the executor refuses)."""
        b_T_g = base_T_grasp(grasp)
        image = image_projection(grasp, base_T_camera, frame.camera_k)
        msg = Grasp(header=frame.header)
        camera_T_grasp = np.linalg.inv(base_T_camera) @ b_T_g
        msg.pose_camera = PoseStamped(header=frame.header, pose=pose_from_transform(camera_T_grasp))
        msg.pose_base = PoseStamped(header=Header(stamp=frame.header.stamp, frame_id=pose_frame_id),
                                    pose=pose_from_transform(b_T_g))
        msg.width_m = float(grasp.width_m)
        msg.quality = float(grasp.quality)
        msg.angle_rad = image["angle_rad"]
        msg.center_u_px, msg.center_v_px = image["u_px"], image["v_px"]
        msg.width_px = image["width_px"]
        msg.youngs_modulus_pa = float(grasp.youngs_modulus_pa)
        msg.object_id = int(grasp.object_id)
        self._grip_fields(msg, grasp, network)
        return msg

    # --- visualisation ------------------------------------------------------
    def _markers(self, grasp: Grasp) -> MarkerArray:
        base_T_grasp = transform_from_pose(grasp.pose_base.pose)
        markers = MarkerArray()
        for index, (grasp_T_finger, size) in enumerate(finger_boxes_in_grasp(grasp.width_m)):
            marker = Marker(header=grasp.pose_base.header, ns="defgg_grasp", id=index, type=Marker.CUBE,
                            action=Marker.ADD, pose=pose_from_transform(base_T_grasp @ grasp_T_finger))
            marker.scale.x, marker.scale.y, marker.scale.z = size
            marker.color.r, marker.color.g, marker.color.a = float(1.0 - grasp.quality), float(grasp.quality), 0.8
            markers.markers.append(marker)
        return markers

    def _warn(self, text: str):
        self.get_logger().warning(text, throttle_duration_sec=WARN_THROTTLE_S)

    @property
    def latest_stamp_ns(self) -> int | None:
        """Stamp of the latest synchronised frame (None before the first)."""
        with self._state_lock:
            return self._latest_stamp_ns

    @property
    def perception_counts(self) -> dict:
        """Perception on arrival: frames submitted, perceived, dropped unstarted, stopped as superseded."""
        w = self._worker
        return {} if w is None else {"submitted": w.submitted, "perceived": w.prepared, "dropped": w.dropped,
                                     "superseded": w.superseded}

    def destroy_node(self):
        if self._worker is not None:
            self._worker.close()
        return super().destroy_node()


NO_FRAME_YET = ("empty request depth and no synchronised depth + stiffness + camera_info received yet; send depth "
                "and camera_info in the request")


def _unset(image: Image) -> bool:
    """An image field the client left at its default (not a malformed image: those fail conversion)."""
    return image.width == 0 and image.height == 0 and len(image.data) == 0 and not image.encoding


def main(args=None):
    run_node("grasp_inference_node", GraspInferenceNode,
             startup_errors=(CheckpointError, ValueError, OSError), args=args)


if __name__ == "__main__":
    main()
