"""When an input topic last delivered, and, when it is silent, what the graph says about why.

A reader gets nothing from a publisher whose QoS it does not match (a reliable reader and a best-effort
publisher: franka_robot_state_broadcaster's convenience topics since franka_ros2 3.3.0), from a topic
nobody publishes (a controller not active, a wrong name or namespace), or from a publisher that stopped.
ROS tells only the first, once, in a log line that is easy to miss; `TopicWatch.diagnosis()` says which
of the three it is: the topic, how many publishers the graph shows and the QoS each offers, and this
reader's QoS.
"""
import time

from rclpy.qos import HistoryPolicy, ReliabilityPolicy


def describe_qos(profile) -> str:
    """'best effort, keep last 1, volatile'. The graph does not carry a publisher's history (DDS does not
    announce it): then only reliability and durability, 'reliable, transient local'."""
    words = [profile.reliability.name.lower().replace("_", " ")]
    if profile.history == HistoryPolicy.KEEP_LAST:
        words.append(f"keep last {profile.depth}")
    elif profile.history == HistoryPolicy.KEEP_ALL:
        words.append("keep all")
    words.append(profile.durability.name.lower().replace("_", " "))
    return ", ".join(words)


class TopicWatch:
    """Counts the messages a callback reports (`heard`) on one topic; monotonic clock, so a stopped sim clock
    cannot hide a silent topic."""

    def __init__(self, node, topic: str, reader_qos):
        self._node, self.topic, self.reader_qos = node, topic, reader_qos
        self.resolved = node.resolve_topic_name(topic)
        self.created_s = time.monotonic()
        self.last_s = None
        self.messages = 0

    def heard(self, at_s: float | None = None) -> None:
        """A message arrived at at_s (monotonic; now by default)."""
        self.last_s = time.monotonic() if at_s is None else at_s
        self.messages += 1

    def silent_s(self) -> float:
        """Seconds since the last message (since this watch started when none came yet)."""
        return time.monotonic() - (self.last_s if self.last_s is not None else self.created_s)

    def publishers(self) -> list:
        """[(node name, QoS profile)] of the topic's publishers on the graph now ([] when the graph is gone)."""
        try:
            infos = self._node.get_publishers_info_by_topic(self.resolved)
        except Exception:  # noqa: BLE001 - graph queries fail while the context shuts down
            return []
        return [(f"{info.node_namespace.rstrip('/')}/{info.node_name}", info.qos_profile) for info in infos]

    def diagnosis(self) -> str:
        """Why nothing arrives, from the graph: e.g. 'no message on /x for 4 s (none since start); 1 publisher
        (/fake_panda_driver: best effort, keep last 1, volatile); this reader: reliable, keep last 10,
        volatile: a reliable reader gets nothing from a best-effort publisher'."""
        heard = "none since start" if self.last_s is None else f"{self.messages} before"
        text = f"no message on {self.resolved} for {self.silent_s():.1f} s ({heard})"
        publishers = self.publishers()
        if not publishers:
            return (f"{text}; no publisher on the graph (is its driver or controller running, in this namespace "
                    f"and ROS domain?); this reader: {describe_qos(self.reader_qos)}")
        offered = "; ".join(f"{name}: {describe_qos(profile)}" for name, profile in publishers)
        text = f"{text}; {len(publishers)} publisher(s) ({offered}); this reader: {describe_qos(self.reader_qos)}"
        if self.reader_qos.reliability == ReliabilityPolicy.RELIABLE and any(
                profile.reliability == ReliabilityPolicy.BEST_EFFORT for _, profile in publishers):
            return f"{text}: a reliable reader gets nothing from a best-effort publisher"
        return f"{text}: the publishers send nothing (stopped, or their process is stalled)"
