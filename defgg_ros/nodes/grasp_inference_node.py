"""grasp_inference_node: depth + PerceivedObjects (+camera_info) -> Def-GG-CNN grasps. It does not perceive.

The segmentation node is the cell's only perceiver (docs/perception.md, "One perceiver"); this node holds the
parameters and the ROS I/O and runs only the network on the height map it sent and the grasp search:
- synchronises depth, PerceivedObjects and camera_info by exact stamp (perception/sync.py); the view is rebuilt
  from them (nodes/perceived_msg.frame_from_messages), with the executor's grasp height rule;
- `prepare_on_arrival` (default): worker threads prepare each synchronised frame as it arrives (the network,
  the free space, the searches requests will want: top_k 1 with `publish_on_sync`, which publishes the best
  grasp, quality map and finger markers, and every top_k asked for in the last `prepare_requested_top_k_s`);
  newest frame wins at each stage (perception/frame_worker.py, perception/prepared_frames.py);
- serves PlanGrasp: empty depth and perceived -> the latest frame: a lookup of the newest prepared frame's
  search (`max_frame_age_s`, `max_wait_s`); depth + camera_info + perceived -> that frame; depth + camera_info
  alone -> perceived first by the segmentation node's Perceive service (with the request's `objects`). A bad
  request or a frame the segmentation node could not perceive answers success=false with the reason.
"""
import threading
import time
from pathlib import Path

from defgg_interfaces.msg import Grasp, PerceivedObjects
from defgg_interfaces.srv import Perceive, PlanGrasp
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from visualization_msgs.msg import MarkerArray

from defgg_ros.model.inference import CheckpointError, GraspPredictor
from defgg_ros.nodes.grasp_msg import finger_markers, grasp_msg, label_grip_rule
from defgg_ros.nodes.node_main import run_node
from defgg_ros.nodes.perceived_msg import frame_from_messages, is_empty
from defgg_ros.perception.frame_worker import (
    LatestFrameWorker,
    RecentValues,
    WorkerClosed,
    keep_executor_responsive,
)
from defgg_ros.perception.grasp_planning import PlanningError, check_top_k
from defgg_ros.perception.prepared_frames import Frame, PreparedFrame
from defgg_ros.perception.sync import StampSynchronizer
from defgg_ros.planning.perceived_frame import REBUILT_DEFAULT_PA
from defgg_ros.planning.tabletop_planner import TabletopPlanner
from defgg_ros.ros import qos
from defgg_ros.ros.conversions import check_image_size, numpy_to_image, stamp_to_ns, transform_from_pose
from defgg_ros.ros.diagnostics import NodeDiagnostics
from defgg_ros.ros.memory import keep_freed_memory
from defgg_ros.ros.parameters import declare_parameters, load_schema
from defgg_ros.ros.service import ServiceTimeout, answer, call_idempotent
from defgg_ros.ros.share import share_path
from defgg_ros.ros.tf import TfBroadcaster, transform_msg

WARN_THROTTLE_S = 2.0
# An empty PlanGrasp waits at most this long for the preparation of the latest frame.
PERCEPTION_WAIT_S = 30.0
MODEL_FILES = {True: "defgg_cnn.pt", False: "ggcnn_depth_only.pt"}

# Names, types, defaults and bounds: defgg_ros/ros/params/grasp_inference_node.yaml.
PARAMETERS = load_schema("grasp_inference_node")


def default_model_path(use_stiffness: bool) -> Path:
    """The shipped checkpoint: the source tree's models/ or the installed share/defgg_ros/models/."""
    return share_path("models", MODEL_FILES[bool(use_stiffness)])


class GraspInferenceNode(Node):
    def __init__(self, **kwargs):
        super().__init__("grasp_inference_node", **kwargs)
        declare_parameters(self)  # a value outside its schema raises ParameterError here
        keep_freed_memory()       # frame-sized temporaries in worker threads: no page faults per frame
        keep_executor_responsive()  # a PlanGrasp lookup is not held up by the preparation threads
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self._p = p
        model_path = Path(p["model_path"]) if p["model_path"] else default_model_path(p["use_stiffness"])
        self.predictor = GraspPredictor.from_checkpoint(model_path, num_threads=int(p["num_threads"]))
        if self.predictor.uses_stiffness != bool(p["use_stiffness"]):
            raise ValueError(f"{model_path} is a {'depth+stiffness' if self.predictor.uses_stiffness else 'depth-only'}"
                             f" network but use_stiffness is {p['use_stiffness']}")
        self._grip_rule = label_grip_rule(self.predictor, model_path)
        self._grasp_rule = {"grasp_height_rule": p["grasp_height_rule"],
                            "grasp_depth_below_surface_m": float(p["grasp_depth_below_surface_m"])}
        self._planner = TabletopPlanner(self.predictor, default_youngs_modulus_pa=REBUILT_DEFAULT_PA)
        self._max_image_size_px = tuple(int(v) for v in p["max_image_size_px"])
        self._state_lock = threading.Lock()
        self._sync = StampSynchronizer(("depth", "perceived", "info"), int(p["sync_cache_size"]))
        self._latest_matched = None     # without prepare_on_arrival: the latest synchronised messages
        self._latest_stamp_ns = None
        self.synced_frames = 0          # frames matched by stamp
        self.skipped_frames = 0         # synchronised, but not usable (wrong sizes, not perceived)
        self._worker = None
        # The top_k values empty requests asked for lately: preparation on arrival makes those searches too.
        self._requested_top_k = RecentValues(float(p["prepare_requested_top_k_s"]))
        self._grasp_pub = self.create_publisher(Grasp, p["best_grasp_topic"], qos.STATE)
        self._quality_pub = self.create_publisher(Image, p["quality_topic"], qos.SENSOR_DATA)
        self._marker_pub = self.create_publisher(MarkerArray, p["markers_topic"], qos.STATE)
        self._tf_broadcaster = TfBroadcaster(self)  # the planned grasp as TF frame grasp_frame
        # Reliability follows the publishers', and silence is logged (qos.SensorSubscription, issue 26).
        self._stream_subs = [
            qos.SensorSubscription(self, Image, p["depth_topic"], lambda m: self._on_stream("depth", m),
                                   warn_after_s=float(p["stream_timeout_s"])),
            qos.SensorSubscription(self, PerceivedObjects, p["perceived_topic"],
                                   lambda m: self._on_stream("perceived", m),
                                   warn_after_s=float(p["stream_timeout_s"])),
            qos.SensorSubscription(self, CameraInfo, p["camera_info_topic"], lambda m: self._on_stream("info", m),
                                   warn_after_s=0.0)]
        # A request with its own depth asks the segmentation node to perceive it: the client's answers are
        # handled in their own group while the PlanGrasp callback waits (run with two threads).
        self._perceive_client = self.create_client(Perceive, p["perceive_service"],
                                                   callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(PlanGrasp, p["plan_grasp_service"], self._on_plan_grasp,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.diagnostics = NodeDiagnostics(self, self._diagnostic_status)
        if p["prepare_on_arrival"]:
            stages = (self._convert_stage, self._network_stage)
            if int(p["prepare_stages"]) == 1:
                stages = (lambda matched, checkpoint: self._network_stage(self._convert_stage(matched, checkpoint),
                                                                          checkpoint),)
            self._worker = LatestFrameWorker(stages, float(p["max_frame_age_s"]),
                                             self._publish_prepared if p["publish_on_sync"] else None,
                                             on_error=self._on_worker_error)
        self.get_logger().info(f"loaded {model_path} (runtime {self.predictor.runtime}, "
                               f"stiffness {'on' if self.predictor.uses_stiffness else 'off'})")

    def _diagnostic_status(self) -> dict:
        counts = self.perception_counts
        return {"frames in": self.synced_frames, "frames prepared": counts.get("prepared", 0),
                "frames dropped": counts.get("dropped", 0) + counts.get("superseded", 0),
                "frames unusable": self.skipped_frames}

    # --- streams ------------------------------------------------------------
    def _on_stream(self, stream: str, msg):
        with self._state_lock:
            matched = self._sync.add(stream, stamp_to_ns(msg.header.stamp), msg)
        if matched is None:
            return
        stamp_ns = stamp_to_ns(matched["depth"].header.stamp)
        with self._state_lock:
            self.synced_frames += 1
            self._latest_stamp_ns = stamp_ns
            self._latest_matched = matched
        if self._worker is not None:
            # The worker converts the frames it takes (frames it drops are never converted): this thread only
            # matches stamps, so a PlanGrasp request does not queue behind conversions.
            self._worker.submit(matched)
        elif self._p["publish_on_sync"]:
            try:
                prepared = self._prepare(self._convert(matched))
                result, grasps = self._search(prepared, 1)
            except ValueError as exc:
                self._warn(f"no grasp for frame: {exc}")
                return
            self._publish_outputs(prepared.frame, result, grasps)

    def _convert(self, matched) -> Frame:
        """Synchronised (or requested) depth + PerceivedObjects + camera_info as a Frame; ValueError with the
        reason (perceived_msg.frame_from_messages)."""
        return frame_from_messages(matched["depth"], matched["perceived"], matched["info"], self._max_image_size_px,
                                   self._grasp_rule)

    def _convert_stage(self, matched, checkpoint) -> Frame:
        try:
            return self._convert(matched)
        except ValueError as exc:
            self._warn(f"unusable synchronised frame: {exc}")
            with self._state_lock:
                self.skipped_frames += 1
            raise

    def _network_stage(self, frame: Frame, checkpoint, search: bool = True) -> PreparedFrame:
        """The network on the height map and the free space (TabletopPlanner.network); on arrival also the
        frame's searches requests will want, before they see the frame: top_k 1 with publish_on_sync (which it
        publishes) and every top_k asked for lately (prepare_requested_top_k_s)."""
        start = time.perf_counter()
        out = PreparedFrame(frame, self._planner.network(frame.objects, checkpoint), time.perf_counter() - start)
        if search:      # on arrival (the worker's stages)
            self.diagnostics.latency("network", out.seconds)
            wanted = self._requested_top_k.recent() | ({1} if self._p["publish_on_sync"] else set())
            for top_k in sorted(wanted):
                checkpoint()
                try:
                    self._search(out, top_k)
                except ValueError:  # no feasible grasp: kept for the requests, warned when publishing
                    pass
        return out

    def _prepare(self, frame: Frame) -> PreparedFrame:
        return self._network_stage(frame, None, search=False)

    def _publish_prepared(self, done, checkpoint):
        """publish_on_sync with preparation on arrival: the best grasp of each frame the worker prepared."""
        try:
            prepared = done.value()
            result, grasps = self._search(prepared, 1)
        except ValueError as exc:
            self._warn(f"no grasp for frame: {exc}")
            return
        checkpoint()
        self._publish_outputs(prepared.frame, result, grasps)

    def _on_worker_error(self, frame, exc):
        if not self.context.ok():
            return   # the context was shut down under a publish of the worker: the node is stopping, not failing
        self.get_logger().error(f"preparation on arrival failed unexpectedly: {exc!r}")

    def _search(self, prepared: PreparedFrame, top_k: int):
        """(TabletopResult, Grasp messages) of a prepared frame, searched once per top_k (_Searches)."""
        def search():
            result = self._planner.search(prepared.prepared, top_k)
            return result, [grasp_msg(g, prepared.frame, prepared.prepared.network, self._grip_rule,
                                      self._p["object_density_kg_m3"], self._warn) for g in result.grasps]
        return prepared.searches.get(top_k, search)

    def _publish_outputs(self, frame: Frame, result, grasps):
        # The depth-sized quality image only when someone reads it: at 1280x720 making and serialising it
        # (3.7 MB) costs ~5 ms per frame.
        if self._quality_pub.get_subscription_count() > 0:
            self._quality_pub.publish(numpy_to_image(result.plan.quality_image(result.view), "32FC1", frame.header))
        if grasps:
            self._grasp_pub.publish(grasps[0])
            self._marker_pub.publish(finger_markers(grasps[0]))
            self._publish_grasp_frame(grasps[0])

    # --- PlanGrasp ----------------------------------------------------------
    def _plan_latest(self, top_k: int):
        """An empty request: (grasps, seconds, summary) from the latest synchronised frame."""
        start = time.perf_counter()
        if self._worker is None:
            with self._state_lock:
                matched = self._latest_matched
            if matched is None:
                raise PlanningError(NO_FRAME_YET)
            _, grasps = self._search(self._prepare(self._convert(matched)), top_k)
            return grasps, time.perf_counter() - start, ""
        self._requested_top_k.note(top_k)
        try:
            done = self._worker.latest(PERCEPTION_WAIT_S, float(self._p["max_wait_s"]))
        except (TimeoutError, WorkerClosed) as exc:
            raise PlanningError(f"the latest frame could not be prepared: {exc}") from exc
        if done is None:
            raise PlanningError(NO_FRAME_YET)
        waited = time.perf_counter() - start
        prepared = done.value()
        on_arrival = prepared.searches.made(top_k)
        with self._worker.priority():
            _, grasps = self._search(prepared, top_k)
        seconds = time.perf_counter() - start
        worker = self._worker
        note = (f"; frame prepared on arrival ({prepared.seconds * 1e3:.1f} ms; waited {waited * 1e3:.1f} ms, "
                f"searched {(seconds - waited) * 1e3:.1f} ms; {worker.prepared} of {worker.submitted} "
                f"synchronised frames prepared{'; top_k searched on arrival' if on_arrival else ''})")
        return grasps, seconds, note

    def _plan_request(self, request, top_k: int):
        """A request carrying its frame: (grasps, seconds, summary)."""
        start = time.perf_counter()
        info = request.camera_info
        if _unset(request.depth):
            raise PlanningError("perceived objects or stiffness entries were given without the depth image")
        if info.width == 0 and info.height == 0:
            raise PlanningError("request has depth but no camera_info")
        check_image_size("depth", request.depth, self._max_image_size_px)
        perceived = request.perceived
        if is_empty(perceived):
            perceived = self._perceive(request)
        elif request.objects:
            raise PlanningError("give either perceived objects or stiffness entries, not both (entries go to "
                                "the Perceive service that made the perceived objects)")
        frame = self._convert({"depth": request.depth, "perceived": perceived, "info": info})
        _, grasps = self._search(self._prepare(frame), top_k)
        return grasps, time.perf_counter() - start, ""

    def _perceive(self, request) -> PerceivedObjects:
        """The segmentation node's perception of the request's depth (its Perceive service)."""
        if not self._perceive_client.wait_for_service(timeout_sec=float(self._p["perceive_timeout_s"])):
            raise PlanningError(f"the request has no perceived objects and the segmentation node's "
                                f"{self._p['perceive_service']} service is not available")
        try:
            response = call_idempotent(self._perceive_client, Perceive.Request(
                depth=request.depth, camera_info=request.camera_info, objects=request.objects),
                float(self._p["perceive_timeout_s"]), "perceive")
        except (ServiceTimeout, RuntimeError) as exc:
            raise PlanningError(f"the segmentation node did not perceive the request's depth: {exc}") from exc
        if not response.success:
            raise PlanningError(f"the segmentation node could not perceive the request's depth: {response.message}")
        return response.perceived

    def _on_plan_grasp(self, request, response):
        def plan() -> str:
            top_k = check_top_k(request.top_k)
            if _unset(request.depth) and is_empty(request.perceived) and not request.objects:
                grasps, seconds, note = self._plan_latest(top_k)
            else:
                grasps, seconds, note = self._plan_request(request, top_k)
            response.grasps, response.inference_time_s = grasps, seconds
            self.diagnostics.latency("plan_grasp", seconds)
            best = grasps[0]
            self._publish_grasp_frame(best)
            return (f"{len(grasps)} grasp(s); best q={best.quality:.3f} at ({best.center_u_px:.0f}, "
                    f"{best.center_v_px:.0f}) px, width {best.width_m * 1000:.1f} mm, object {best.object_id}{note}")
        return answer(response, plan, "plan_grasp", self.get_logger(), self.diagnostics.error)

    def _publish_grasp_frame(self, grasp: Grasp) -> None:
        """The grasp's TCP pose as TF frame `grasp_frame` under the grasp's base frame (on /tf), so rviz and
        `ros2 run tf2_ros tf2_echo <base> defgg_grasp` show where the executor would be sent."""
        pose = grasp.pose_base
        try:
            base_T_grasp_m = transform_from_pose(pose.pose)
        except ValueError as exc:
            self._warn(f"grasp frame not published: {exc}")
            return
        self._tf_broadcaster.send(transform_msg(pose.header.frame_id, self._p["grasp_frame"], base_T_grasp_m,
                                                pose.header.stamp))

    def _warn(self, text: str):
        self.get_logger().warning(text, throttle_duration_sec=WARN_THROTTLE_S)

    @property
    def latest_stamp_ns(self) -> int | None:
        """Stamp of the latest synchronised frame (None before the first)."""
        with self._state_lock:
            return self._latest_stamp_ns

    @property
    def perception_counts(self) -> dict:
        """Preparation on arrival: frames submitted, prepared, dropped unstarted, stopped as superseded."""
        w = self._worker
        return {} if w is None else {"submitted": w.submitted, "prepared": w.prepared, "dropped": w.dropped,
                                     "superseded": w.superseded}

    def destroy_node(self):
        if self._worker is not None:
            self._worker.close()
        return super().destroy_node()


NO_FRAME_YET = ("empty request and no synchronised depth + perceived objects + camera_info received yet (is the "
                "segmentation node running?); or send depth and camera_info in the request")


def _unset(image: Image) -> bool:
    """An image field the client left at its default (not a malformed image: those fail conversion)."""
    return image.width == 0 and image.height == 0 and len(image.data) == 0 and not image.encoding


def main(args=None):
    run_node("grasp_inference_node", GraspInferenceNode,
             startup_errors=(CheckpointError, ValueError, OSError), threads=2, args=args)


if __name__ == "__main__":
    main()
