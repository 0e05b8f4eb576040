"""SessionRecorder: an rclpy node that writes the cell's topics into a session bag.

Thin adapter: raw (CDR) subscriptions -> FrameSelector -> SessionWriter. Also
records the service calls and action goals made through SessionClient
(`record_plan`, `record_pick_*`), which a topic subscription cannot see.
"""
import threading
import time

from defgg_interfaces.msg import Grasp, StiffnessAssignment
from rclpy.node import Node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from defgg_ros.ros import qos
from defgg_ros.ros.tf import tf_qos
from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.selector import FrameSelector, StampError, header_stamp_ns
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

# Pick feedback kept at most this often within one phase (s).
FEEDBACK_PERIOD_S = 0.5


def stamp_ns_of(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


class SessionRecorder(Node):
    """live=True: record the cell's topics. live=False (a replay's --update): the player writes the
    frames, grasps and assignments it sends/gets itself, with their recorded stamps and in order."""

    def __init__(self, writer, selector: FrameSelector, live: bool = True, record_color: bool = True,
                 node_name="defgg_session_recorder", **kwargs):
        super().__init__(node_name, **kwargs)
        self._writer = writer
        self._selector = selector
        self._lock = threading.Lock()
        self.closed = False
        self.errors = []
        self.latest_grasp_stamp_ns = None       # newest best grasp seen (the recorder waits on it)
        self.grasp_count = 0
        self._grasp_seen = threading.Condition()
        self._last_feedback = ("", 0)
        stamped = [(Image, topics.DEPTH_IMAGE), (CameraInfo, topics.DEPTH_CAMERA_INFO)]
        if record_color:
            stamped.append((Image, topics.COLOR_IMAGE))
        # A replay writes the frames it sends and the grasps it gets itself (write_frame, write_grasp):
        # no subscription can lose one, and the recorded stamps are kept.
        # The camera as the perception nodes read it (qos.SensorSubscription: reliable when the camera is; a
        # best-effort reader lost whole frames of a reliable 1280x720 camera, 3-11 of 30). A frame both of its
        # readers deliver while it is undecided is written once (the selector drops a (topic, stamp) it has).
        self._camera_readers = [qos.SensorSubscription(self, msg_type, topic, self._stamped_callback(topic),
                                                       warn_after_s=0.0, raw=True)
                                for msg_type, topic in (stamped if live else ())]
        if live:
            self.create_subscription(Grasp, topics.BEST_GRASP, self._on_best_grasp, qos.STATE, raw=True)
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state, qos.SENSOR_DATA, raw=True)
        latched = [(String, st.DRIVER_SCENE)]
        if live:  # a player writes the assignments it applies itself (write_raw), in order
            latched.append((StiffnessAssignment, topics.STIFFNESS_ASSIGNMENTS))
        for msg_type, topic in latched:
            self.create_subscription(msg_type, topic, self._plain_callback(topic), qos.LATCHED, raw=True)
        if live:
            # The camera's pose: the perception takes it from TF (the cell's calibration on /tf_static), and a
            # replay without it would have none. tf2's QoS: every latched publisher's message, not only the last.
            self.create_subscription(TFMessage, topics.TF_STATIC, self._plain_callback(topics.TF_STATIC),
                                     tf_qos(static=True), raw=True)

    # --- writing -------------------------------------------------------------
    def _write_all(self, items) -> None:
        with self._lock:
            if self.closed:
                return
            for topic, raw, log_time_ns in items:
                self._writer.write(topic, raw, log_time_ns)

    def _stamped_callback(self, topic):
        def callback(raw: bytes):
            try:
                with self._lock:
                    items = self._selector.offer_stamped(topic, raw, time.time_ns())
            except StampError as exc:
                self.errors.append(f"{topic}: {exc}")
                return
            self._write_all(items)
        return callback

    def _plain_callback(self, topic):
        return lambda raw: self._write_all([(topic, raw, time.time_ns())])

    def _on_best_grasp(self, raw: bytes):
        self._stamped_callback(topics.BEST_GRASP)(raw)
        with self._lock:
            # Count only grasps on frames this recorder holds: a grasp on a frame published before it
            # subscribed says the cell is busy, not that a recordable frame went through.
            recordable = self._selector.has_frame(header_stamp_ns(raw))
        if not recordable:
            return
        with self._grasp_seen:
            self.latest_grasp_stamp_ns = header_stamp_ns(raw)
            self.grasp_count += 1
            self._grasp_seen.notify_all()

    def wait_for_grasps(self, count: int, timeout_s: float) -> bool:
        """Wait until `count` more best grasps were published (fresh frames went through the cell)."""
        with self._grasp_seen:
            target = self.grasp_count + count
            return self._grasp_seen.wait_for(lambda: self.grasp_count >= target, timeout_s)

    def _on_joint_state(self, raw: bytes):
        with self._lock:
            items = self._selector.offer_joint_state(topics.JOINT_STATES, raw, time.time_ns())
        self._write_all(items)

    def keep_stamp(self, stamp_ns: int) -> None:
        """Something refers to this depth stamp: make sure its frame is in the bag."""
        with self._lock:
            found = self._selector.has_frame(stamp_ns)
            items = self._selector.keep(stamp_ns)
        if not found:
            self.errors.append(f"frame @{stamp_ns / 1e9:.3f}s was used by the cell but never reached the recorder")
            self.get_logger().warning(self.errors[-1])
        self._write_all(items)

    def write_frame(self, stamp_ns: int, camera_messages) -> None:
        """Write a frame sent by a player ([(topic, raw)]); its grasp is then recorded when it comes."""
        now = time.time_ns()
        with self._lock:
            self._selector.keep(stamp_ns)
            items = self._selector.mark_written([(topic, raw, now) for topic, raw in camera_messages])
        self._write_all(items)

    def copy_messages(self, messages) -> None:
        """Carry BagMessages of an older bag over, with their original log times."""
        self._write_all([(m.topic, m.raw, m.log_time_ns) for m in messages])

    def write_raw(self, topic: str, raw: bytes) -> None:
        self._write_all([(topic, raw, time.time_ns())])

    def write_grasp(self, grasp) -> None:
        """Write a best grasp received by a player (its stamp already the recorded one)."""
        self._write_all([(topics.BEST_GRASP, serialize_message(grasp), time.time_ns())])

    # --- client-side records ------------------------------------------------
    def record_plan(self, request, response, request_time_ns: int) -> None:
        items = [(st.PLAN_REQUEST, serialize_message(request), request_time_ns)]
        if response is not None:
            for grasp in response.grasps[:1]:
                self.keep_stamp(stamp_ns_of(grasp))
            items.append((st.PLAN_RESPONSE, serialize_message(response), time.time_ns()))
        self._write_all(items)

    def record_pick_goal(self, goal, log_time_ns: int) -> None:
        if not goal.plan_grasp:
            self.keep_stamp(stamp_ns_of(goal.grasp))
        self._write_all([(st.PICK_GOAL, serialize_message(goal), log_time_ns)])

    def record_pick_feedback(self, feedback) -> None:
        """Feedback comes at the executor's control rate (100 Hz): keep phase changes and FEEDBACK_PERIOD_S."""
        now = time.time_ns()
        if feedback.phase == self._last_feedback[0] and now - self._last_feedback[1] < FEEDBACK_PERIOD_S * 1e9:
            return
        self._last_feedback = (feedback.phase, now)
        self._write_all([(st.PICK_FEEDBACK, serialize_message(feedback), now)])

    def record_pick_result(self, result) -> None:
        if result.grasp_used.header.stamp.sec or result.grasp_used.header.stamp.nanosec:
            self.keep_stamp(stamp_ns_of(result.grasp_used))
        self._write_all([(st.PICK_RESULT, serialize_message(result), time.time_ns())])

    @property
    def counts(self) -> dict:
        """Messages written per topic so far."""
        return dict(self._writer.counts)

    def update_metadata(self, metadata: dict) -> None:
        with self._lock:
            if not self.closed:
                self._writer.update_metadata(metadata, time.time_ns())

    def finish(self):
        """Stop writing (later callbacks are dropped) and close the bag into place."""
        with self._lock:
            self.closed = True
            return self._writer.close()
