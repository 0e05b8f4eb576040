"""Named QoS profiles of the cell, and the camera-stream subscription that works with any driver.

- SENSOR_DATA: best effort, keep last 5, volatile (rclpy's sensor-data
  profile), for readers that must match any image publisher (recorders).
- REALSENSE_IMAGE, REALSENSE_CAMERA_INFO: realsense2_camera's (and the
  simulated camera's) image and camera_info publishers (below).
- IMAGE_PUBLISH: what the cell's own image publishers offer (stiffness
  image, mask, perceived objects): reliable, keep last 2, volatile.
  Best-effort readers still match it, and reliable readers get lost
  fragments of large frames repaired (see below).
- LATCHED: state that a late joiner must still get (stiffness assignments,
  the scene description): reliable + transient local, keep last 1 — the
  "latched topic" of ROS 1.
- STATE: robot state and results (joint states, wrench, best grasp,
  markers): reliable, keep last 10.
- COMMAND: commands: reliable, keep last 1 so a stale command is never
  replayed after a newer one.

Camera streams are subscribed with `SensorSubscription`, not with a fixed
profile. Why (issue 26, bench/bench_transport.py): a 1280x720 16UC1 frame is
1.8 MB, which Fast DDS splits into ~28 fragments of 64 kB. With the
publisher's default transports (512 kB shared-memory segments, ~208 kB UDP
socket buffers) many fragments are dropped on the way; a best-effort reader
never gets them again, so the whole frame is lost (3-11 of 30 frames arrived
from a default-configured rclpy publisher at 30 Hz), while a reliable reader
asks for the missing fragments and gets every frame (30 of 30). The
publisher's transports are not ours to configure, so the reader must be
reliable whenever the publisher is (realsense2_camera's default, the fake
driver's); but a reliable reader does not match a best-effort publisher at
all. Hence the subscription follows the publishers it sees, as rosbag2's
recorder does: reliable when every publisher offers reliable, best effort
otherwise. Before any publisher exists it reads with both a best-effort and a
reliable reader, so the first frames of a camera started after the node reach
it whichever QoS the camera offers (issue 46: starting best effort and
switching after the publisher showed lost the frames of the switch); a frame
both readers deliver is passed on once (same header stamp and frame id). It
re-checks once a second; on a change the new reader is created first and the
old one is kept until the new one has matched every publisher.
A reader that cannot match a publisher meanwhile is expected, so its
incompatible-QoS event goes to the debug log instead of rclpy's "No messages
will be received" warning (a silent camera still gets the warning below).

The same subscription warns when no message arrived for `warn_after_s`
(repeating at doubling intervals), naming the publishers it sees, so a
silent camera or a QoS mismatch shows in the log instead of nothing.
"""
import collections
import time

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
    qos_profile_system_default,
)

SENSOR_DATA = qos_profile_sensor_data

# realsense2_camera 4.56 publishes its images with SYSTEM_DEFAULT (`<stream>_qos`, include/constants.h IMAGE_QOS):
# whatever the middleware's writer defaults are (Fast DDS: reliable, transient local, keep last 1), and their
# camera_info with DEFAULT (`<stream>_info_qos`): reliable, volatile, keep last 10. The simulated camera offers the
# same, so a reader that works with it works with the real camera on the same middleware.
REALSENSE_IMAGE = qos_profile_system_default
REALSENSE_CAMERA_INFO = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                   durability=DurabilityPolicy.VOLATILE)

IMAGE_PUBLISH = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=2,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

STATE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

COMMAND = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# franka_ros2 3.x's publishers (docs/franka_contract.md has the file each is read from):
# franka_robot_state_broadcaster's convenience topics, rclcpp::QoS(1).best_effort() since 3.3.0;
FRANKA_CONVENIENCE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                                durability=DurabilityPolicy.VOLATILE)
# joint_state_broadcaster's joint_states, rclcpp::SystemDefaultsQoS(): the writer defaults (Fast DDS: reliable,
# transient local);
FRANKA_SYSTEM_DEFAULT = qos_profile_system_default
# joint_state_publisher's merged joint_states, create_publisher(..., 10): reliable, keep last 10;
JOINT_STATE_PUBLISHER = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                   durability=DurabilityPolicy.VOLATILE)
# franka_gripper's ~/joint_states, create_publisher(..., 1): reliable, keep last 1.
GRIPPER_STATE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)
# How the cell reads every franka topic: a best-effort reader matches best-effort AND reliable publishers
# (a reliable reader gets nothing from a best-effort one: "offering incompatible QoS"); depth 1 because
# only the newest state matters, and over shared memory / localhost nothing is lost that a newer
# message does not replace.
ROBOT_STATE_READ = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                              durability=DurabilityPolicy.VOLATILE)

SENSOR_DEPTH = 5                 # frames kept per reader: a late frame is worthless
RECHECK_PERIOD_S = 1.0           # how often the publishers' reliability is looked at again
DEFAULT_WARN_AFTER_S = 5.0       # silence on a camera stream that is worth a warning


def sensor_qos(reliability: ReliabilityPolicy, depth: int = SENSOR_DEPTH) -> QoSProfile:
    """Keep last `depth` (default SENSOR_DEPTH), volatile, with the given reliability."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability,
                      durability=DurabilityPolicy.VOLATILE)


def reliability_for(publisher_reliabilities) -> ReliabilityPolicy:
    """RELIABLE when there is at least one publisher and all offer RELIABLE, else BEST_EFFORT.

    A best-effort reader matches every publisher, so it is the choice whenever one publisher is best
    effort or none is known yet; a reliable reader repairs lost fragments of large frames.
    """
    offered = list(publisher_reliabilities)
    if offered and all(r == ReliabilityPolicy.RELIABLE for r in offered):
        return ReliabilityPolicy.RELIABLE
    return ReliabilityPolicy.BEST_EFFORT


class SensorSubscription:
    """A camera-stream subscription whose reliability follows its publishers (see the module doc).

    `warn_after_s` <= 0 turns the silence warning off; `depth` is the reader's keep-last history.
    The node's clock is not used for the warning: a stopped sim clock must not hide a silent camera,
    so it runs on the wall clock. `reliability` is the reader's the publishers decided; while no publisher
    is on the graph (`undecided`) a best-effort and a reliable reader both run. `raw`: the callback gets the
    serialized bytes (a recorder); a frame both readers deliver is then passed on twice, for the caller to drop.
    """

    def __init__(self, node, msg_type, topic: str, callback, warn_after_s: float = DEFAULT_WARN_AFTER_S,
                 callback_group=None, depth: int = SENSOR_DEPTH, raw: bool = False):
        self._node, self._msg_type, self._callback, self._group = node, msg_type, callback, callback_group
        self._depth, self._raw = int(depth), raw
        self.topic = topic
        self._resolved = node.resolve_topic_name(topic)
        self._warn_after_s = float(warn_after_s)
        self._last_message = time.monotonic()
        self._next_warning_s = self._warn_after_s
        self._warned = False
        self._readers = {}               # ReliabilityPolicy -> Subscription
        self._delivered = collections.deque(maxlen=4 * self._depth)   # (stamp, frame id) passed on lately
        self.reliability = None
        self.undecided = True            # no publisher seen yet: both readers run
        self.messages_received = 0
        self.duplicates_dropped = 0      # frames both readers delivered, passed on once
        self.incompatible_events = 0     # a reader not matching a publisher (logged at debug: expected)
        self.mixed_publishers = False    # reliable and best-effort publishers at once (warned)
        self._update()
        self._timer = node.create_timer(RECHECK_PERIOD_S, self._on_timer, callback_group=callback_group)

    def _publisher_reliabilities(self):
        try:
            infos = self._node.get_publishers_info_by_topic(self._resolved)
        except Exception:  # noqa: BLE001 - graph queries fail while the context shuts down
            return []
        return [info.qos_profile.reliability for info in infos]

    def _update(self) -> None:
        offered = self._publisher_reliabilities()
        if offered:
            wanted = reliability_for(offered)
            readers_wanted = {wanted}
        else:   # nobody yet, or the camera went away: ready for whichever QoS it comes (back) with
            wanted = self.reliability or ReliabilityPolicy.BEST_EFFORT
            readers_wanted = {ReliabilityPolicy.BEST_EFFORT, ReliabilityPolicy.RELIABLE}
        for reliability in readers_wanted - set(self._readers):
            self._readers[reliability] = self._node.create_subscription(
                self._msg_type, self.topic, self._on_message, sensor_qos(reliability, self._depth),
                callback_group=self._group, raw=self._raw,
                event_callbacks=SubscriptionEventCallbacks(incompatible_qos=self._on_incompatible_qos))
        self._retire_readers(readers_wanted, len(offered))
        if wanted != self.reliability:
            self._report_change(offered, wanted)
        self.reliability, self.undecided = wanted, not offered

    def _on_incompatible_qos(self, info) -> None:
        """Replaces rclpy's default "offering incompatible QoS ... No messages will be received" warning.

        While both readers run, one of them cannot match a camera by design, and a decided reader that a
        new publisher does not match is replaced at the next re-check: the message would send users
        looking for a fault that is not there. A camera that really delivers nothing still gets the
        silence warning, naming its publishers.
        """
        self.incompatible_events += 1
        self._node.get_logger().debug(
            f"{self._resolved}: a reader of {len(self._readers)} does not match a publisher "
            f"(policy {info.last_policy_kind}); expected while the reliability follows the publishers")

    def _retire_readers(self, readers_wanted: set, publishers: int) -> None:
        """Destroy the readers no longer wanted once every wanted one has matched all `publishers`: a frame
        the old reader still receives meanwhile is not lost (the duplicate is dropped in _on_message)."""
        surplus = set(self._readers) - readers_wanted
        if not surplus:
            return
        if any(self._readers[r].get_publisher_count() < publishers for r in readers_wanted):
            return   # the next check (RECHECK_PERIOD_S) tries again
        for reliability in surplus:
            self._node.destroy_subscription(self._readers.pop(reliability))

    def _report_change(self, offered, wanted) -> None:
        self.mixed_publishers = ReliabilityPolicy.RELIABLE in offered and wanted == ReliabilityPolicy.BEST_EFFORT
        if self.mixed_publishers:
            # A best-effort reader never gets a lost fragment again: 5.5 MB camera frames then stalled for
            # seconds in the PlanGrasp bench (docs/perception.md, "Latency").
            self._node.get_logger().warning(
                f"{self._resolved}: a best-effort publisher beside reliable ones makes this reader best effort; "
                "large frames may be lost or stall for seconds. Keep every publisher of a camera topic reliable.")
        if self.reliability is not None:
            self._node.get_logger().info(f"{self._resolved}: subscribed {wanted.name.lower()} now "
                                         "(follows the publishers' reliability)")

    def _is_duplicate(self, msg) -> bool:
        """While two readers run, the same frame can come through both: pass it on once."""
        header = getattr(msg, "header", None)
        if header is None or len(self._readers) < 2:
            return False
        key = (header.stamp.sec, header.stamp.nanosec, header.frame_id)
        if key in self._delivered:
            return True
        self._delivered.append(key)
        return False

    def _on_message(self, msg) -> None:
        if self._is_duplicate(msg):
            self.duplicates_dropped += 1
            return
        self._last_message = time.monotonic()
        self.messages_received += 1
        if self._warned:
            self._warned = False
            self._next_warning_s = self._warn_after_s
            self._node.get_logger().info(f"{self._resolved}: messages arrive again")
        self._callback(msg)

    def _on_timer(self) -> None:
        self._update()
        silent_s = time.monotonic() - self._last_message
        if self._warn_after_s > 0 and silent_s >= self._next_warning_s:
            offered = [r.name.lower() for r in self._publisher_reliabilities()]
            reading = "best effort and reliable" if self.undecided else self.reliability.name.lower()
            self._node.get_logger().warning(
                f"no message on {self._resolved} for {silent_s:.0f} s "
                f"({len(offered)} publisher(s){': ' + ', '.join(offered) if offered else ''}; "
                f"subscribed {reading})")
            self._warned = True
            self._next_warning_s = silent_s * 2.0
