"""Named QoS profiles of the cell, and the camera-stream subscription that works with any driver.

- SENSOR_DATA: best effort, keep last 5, volatile (rclpy's sensor-data
  profile), for readers that must match any image publisher (recorders).
- IMAGE_PUBLISH: what the cell's own image publishers offer (the fake
  camera, stiffness image, mask): reliable, keep last 2, volatile, like
  realsense2_camera. Best-effort readers still match it, and reliable
  readers get lost fragments of large frames repaired (see below).
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
otherwise (also before any publisher exists, since best effort matches both).
It re-checks once a second and re-creates itself when that choice changes.

The same subscription warns when no message arrived for `warn_after_s`
(repeating at doubling intervals), naming the publishers it sees, so a
silent camera or a QoS mismatch shows in the log instead of nothing.
"""
import time

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
    qos_profile_system_default,
)

SENSOR_DATA = qos_profile_sensor_data

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
# joint_state_broadcaster's joint_states, rclcpp::SystemDefaultsQoS() (reliable, volatile with Fast DDS);
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
    so it runs on the wall clock.
    """

    def __init__(self, node, msg_type, topic: str, callback, warn_after_s: float = DEFAULT_WARN_AFTER_S,
                 callback_group=None, depth: int = SENSOR_DEPTH):
        self._node, self._msg_type, self._callback, self._group = node, msg_type, callback, callback_group
        self._depth = int(depth)
        self.topic = topic
        self._resolved = node.resolve_topic_name(topic)
        self._warn_after_s = float(warn_after_s)
        self._last_message = time.monotonic()
        self._next_warning_s = self._warn_after_s
        self._warned = False
        self.subscription = None
        self.reliability = None
        self.messages_received = 0
        self.mixed_publishers = False   # reliable and best-effort publishers at once (warned)
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
        wanted = reliability_for(offered)
        if wanted == self.reliability:
            return
        self.mixed_publishers = ReliabilityPolicy.RELIABLE in offered and wanted == ReliabilityPolicy.BEST_EFFORT
        if self.mixed_publishers:
            # A best-effort reader never gets a lost fragment again: 5.5 MB camera frames then stalled for
            # seconds in the PlanGrasp bench (docs/perception.md, "Latency").
            self._node.get_logger().warning(
                f"{self._resolved}: a best-effort publisher beside reliable ones makes this reader best effort; "
                "large frames may be lost or stall for seconds. Keep every publisher of a camera topic reliable.")
        # The new reader first, then the old one goes: the new one needs a moment to match the
        # publishers, and a frame the old one still receives meanwhile is not lost.
        old = self.subscription
        self.subscription = self._node.create_subscription(self._msg_type, self.topic, self._on_message,
                                                           sensor_qos(wanted, self._depth), callback_group=self._group)
        if old is not None:
            self._node.destroy_subscription(old)
        if self.reliability is not None:
            self._node.get_logger().info(f"{self._resolved}: subscribed {wanted.name.lower()} now "
                                         "(follows the publishers' reliability)")
        self.reliability = wanted

    def _on_message(self, msg) -> None:
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
            self._node.get_logger().warning(
                f"no message on {self._resolved} for {silent_s:.0f} s "
                f"({len(offered)} publisher(s){': ' + ', '.join(offered) if offered else ''}; "
                f"subscribed {self.reliability.name.lower()})")
            self._warned = True
            self._next_warning_s = silent_s * 2.0
