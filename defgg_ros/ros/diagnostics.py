"""One small diagnostics publisher for every cell node: diagnostic_msgs/DiagnosticArray on /diagnostics at 1 Hz.

    self._diagnostics = NodeDiagnostics(self, status=lambda: {"frames in": 12, ...})
    self._diagnostics.count("frames in")          # counters kept here (thread-safe)
    self._diagnostics.latency("perceive", 0.012)  # seconds; median / p99 of the last LATENCY_WINDOW values
    self._diagnostics.error("no table in frame")  # the last error (level WARN until OK is set again)

What a ROS user looks at first when a cell misbehaves (`ros2 topic echo /diagnostics`, rqt_runtime_monitor):
one DiagnosticStatus per node named `<node's fully qualified name>`, hardware_id the node's name, level OK
unless an error was noted in the last ERROR_HOLD_S (WARN) and a message of the last error. Values: every
counter, each latency's count, median and p99 in ms, whatever `status()` adds (e.g. the camera pose's
source), and `last error`. The topic is absolute, as diagnostic_aggregator reads it. Pure helpers
(`LatencyWindow`, `percentile_ms`) need no rclpy.
"""
from __future__ import annotations

import collections
import threading
import time

import numpy as np

DIAGNOSTICS_TOPIC = "/diagnostics"
PERIOD_S = 1.0
LATENCY_WINDOW = 500          # values per latency series: 16 s of a 30 Hz camera
ERROR_HOLD_S = 10.0           # an error noted this recently makes the status WARN


def percentile_ms(seconds, q: float) -> float:
    """The q-th percentile of a list of seconds, in ms (NaN for an empty list)."""
    return float(np.percentile(np.asarray(seconds, float), q) * 1e3) if len(seconds) else float("nan")


class LatencyWindow:
    """The last `size` durations of one kind (s), thread-safe."""

    def __init__(self, size: int = LATENCY_WINDOW):
        self._values = collections.deque(maxlen=size)
        self._lock = threading.Lock()
        self.total = 0

    def add(self, seconds: float) -> None:
        with self._lock:
            self._values.append(float(seconds))
            self.total += 1

    def summary(self) -> dict:
        """{'count', 'median_ms', 'p99_ms'} of the window (count: every value ever added)."""
        with self._lock:
            values = list(self._values)
            total = self.total
        return {"count": total, "median_ms": percentile_ms(values, 50), "p99_ms": percentile_ms(values, 99)}


class NodeDiagnostics:
    """Publishes the node's status every PERIOD_S on DIAGNOSTICS_TOPIC (module docstring)."""

    def __init__(self, node, status=None, period_s: float = PERIOD_S, clock=time.monotonic):
        from diagnostic_msgs.msg import DiagnosticArray

        self._node = node
        self._status = status
        self._clock = clock
        self._lock = threading.Lock()
        self._counters = collections.Counter()
        self._latencies = {}
        self._last_error, self._last_error_s = "", None
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)
        self._timer = node.create_timer(period_s, self.publish)

    def count(self, name: str, n: int = 1) -> None:
        with self._lock:
            self._counters[name] += n

    def latency(self, name: str, seconds: float) -> None:
        with self._lock:
            window = self._latencies.setdefault(name, LatencyWindow())
        window.add(seconds)

    def error(self, text: str) -> None:
        with self._lock:
            self._last_error, self._last_error_s = str(text), self._clock()

    def values(self) -> dict:
        """Every value the next message carries, as name -> value (str, int or float)."""
        with self._lock:
            out = dict(self._counters)
            latencies = dict(self._latencies)
            last_error = self._last_error
        for name, window in latencies.items():
            summary = window.summary()
            out[f"{name} count"] = summary["count"]
            out[f"{name} median ms"] = round(summary["median_ms"], 2)
            out[f"{name} p99 ms"] = round(summary["p99_ms"], 2)
        if self._status is not None:
            out.update(self._status())
        out["last error"] = last_error
        return out

    def message(self):
        """The DiagnosticArray to publish now."""
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

        values = self.values()
        with self._lock:
            recent = self._last_error_s is not None and self._clock() - self._last_error_s <= ERROR_HOLD_S
            last_error = self._last_error
        status = DiagnosticStatus(level=DiagnosticStatus.WARN if recent else DiagnosticStatus.OK,
                                  name=self._node.get_fully_qualified_name(), hardware_id=self._node.get_name(),
                                  message=last_error if recent else "ok",
                                  values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()])
        return DiagnosticArray(header=self._header(), status=[status])

    def _header(self):
        from std_msgs.msg import Header

        return Header(stamp=self._node.get_clock().now().to_msg())

    def publish(self) -> None:
        try:
            self._pub.publish(self.message())
        except Exception as exc:  # noqa: BLE001 - diagnostics must never take the node down
            self._node.get_logger().warning(f"diagnostics not published: {exc!r}", throttle_duration_sec=30.0)
