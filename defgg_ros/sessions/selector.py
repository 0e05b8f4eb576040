"""Which incoming messages a recording keeps, so sessions stay small. No rclpy.

A camera streams depth at 30 Hz; a session needs only the frames that
matter. Stamped topics (depth, camera_info, colour, best grasp) are grouped
by their header stamp: a stamp is *kept* when a depth frame arrives at least
`depth_period_s` after the last kept one, or when something refers to it
(a planned grasp's header stamp). Messages of kept stamps are written; the
others wait in a short buffer so that a later reference can still pull its
frame in. Unstamped-rate topics (joint states) are decimated by period.

A stream stamped by its own sensor (realsense2_camera's colour: with enable_sync off each stream carries its own
capture time, never the depth frame's) is filed under the nearest depth stamp within PAIR_WINDOW_S
(`paired_topics`); filed under its own stamp it waited for a reference that never came and was dropped.
"""
import struct
from collections import OrderedDict

DEFAULT_DEPTH_PERIOD_S = 2.0
DEFAULT_JOINT_STATE_PERIOD_S = 0.1
# Frames waiting for a possible reference: ~1 s of a 30 Hz camera.
BUFFER_STAMPS = 40
# A paired stream's frame belongs to the depth frame within this of its stamp: under half a 30 Hz frame period.
PAIR_WINDOW_S = 0.015


def nearest_stamp(stamps, stamp: int, window_s: float) -> int | None:
    """Of `stamps` (ns), the one nearest `stamp` within window_s, else None."""
    near = [s for s in stamps if abs(s - stamp) <= window_s * 1e9]
    return min(near, key=lambda s: abs(s - stamp)) if near else None


class StampError(ValueError):
    """A message whose CDR bytes are too short to hold a header stamp."""


def header_stamp_ns(raw: bytes) -> int:
    """Stamp of a message whose first field is std_msgs/Header, read straight from CDR.

    CDR: 4 bytes of encapsulation (byte 1: 1 = little endian), then
    int32 sec, uint32 nanosec. Avoids deserialising a 600 kB image to get it.
    """
    if len(raw) < 12:
        raise StampError(f"message of {len(raw)} B is too short to hold a header stamp")
    order = "<" if raw[1] & 1 else ">"
    sec, nanosec = struct.unpack_from(order + "iI", raw, 4)
    return sec * 1_000_000_000 + nanosec


def restamp(raw: bytes, stamp_ns: int) -> bytes:
    """The same message with another header stamp (CDR bytes patched in place of a copy)."""
    header_stamp_ns(raw)  # validates length
    order = "<" if raw[1] & 1 else ">"
    out = bytearray(raw)
    struct.pack_into(order + "iI", out, 4, stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)
    return bytes(out)


class FrameSelector:
    """Decide what to write; every method returns [(topic, raw, log_time_ns)] to write now."""

    def __init__(self, depth_topic: str, depth_period_s: float = DEFAULT_DEPTH_PERIOD_S,
                 joint_state_period_s: float = DEFAULT_JOINT_STATE_PERIOD_S, frame_topics=(), paired_topics=()):
        if depth_period_s < 0 or joint_state_period_s < 0:
            raise ValueError("periods must be >= 0 s")
        self.depth_topic = depth_topic
        # A frame counts as recorded only when every one of these arrived with its stamp (a depth
        # image without its camera_info cannot be replayed; best-effort streams can drop either).
        self.frame_topics = (depth_topic, *frame_topics)
        self.depth_period_ns = int(depth_period_s * 1e9)
        self.joint_state_period_ns = int(joint_state_period_s * 1e9)
        self._last_kept_depth_ns = None
        self._last_joint_state_ns = None
        self._kept = OrderedDict()       # stamp -> None (recent kept stamps)
        self._pending = OrderedDict()    # stamp -> [(topic, raw, log_time_ns)]
        self._written = OrderedDict()    # (topic, stamp) -> None: a re-sent frame is written once
        self.paired_topics = tuple(paired_topics)
        self._depth_stamps = OrderedDict()   # recent depth stamps, for the paired topics

    def offer_stamped(self, topic: str, raw: bytes, log_time_ns: int) -> list:
        stamp = header_stamp_ns(raw)
        item = (topic, raw, log_time_ns)
        if (topic, stamp) in self._written:
            return []
        if topic in self.paired_topics:
            stamp = self._nearest_depth_stamp(stamp)
        if stamp in self._kept:
            return self._mark([item])
        if topic == self.depth_topic:
            self._depth_stamps[stamp] = None
            _trim(self._depth_stamps)
            self._adopt_paired(stamp)
            if self._last_kept_depth_ns is None or log_time_ns - self._last_kept_depth_ns >= self.depth_period_ns:
                self._last_kept_depth_ns = log_time_ns
                return self.keep(stamp) + self._mark([item])
        self._pending.setdefault(stamp, {})[topic] = item  # a re-sent message replaces the waiting one
        _trim(self._pending)
        return []

    def _nearest_depth_stamp(self, stamp: int) -> int:
        """The depth stamp within PAIR_WINDOW_S nearest `stamp`, else `stamp` (its depth frame not here yet)."""
        nearest = nearest_stamp(self._depth_stamps, stamp, PAIR_WINDOW_S)
        return stamp if nearest is None else nearest

    def _adopt_paired(self, depth_stamp: int) -> None:
        """Paired messages that came before their depth frame wait under their own stamp: file them under it."""
        window_ns = PAIR_WINDOW_S * 1e9
        for stamp in [s for s in self._pending if s != depth_stamp and abs(s - depth_stamp) <= window_ns]:
            waiting = self._pending[stamp]
            if waiting and all(topic in self.paired_topics for topic in waiting):
                self._pending.setdefault(depth_stamp, {}).update(self._pending.pop(stamp))

    def has_frame(self, stamp: int) -> bool:
        """Is the whole frame (depth + frame_topics) of this stamp written or still in the buffer?"""
        pending = self._pending.get(stamp, {})
        return all((topic, stamp) in self._written or topic in pending for topic in self.frame_topics)

    def keep(self, stamp: int) -> list:
        """Keep a stamp (e.g. a grasp was planned on it): flush what waits for it."""
        self._kept[stamp] = None
        _trim(self._kept)
        return self._mark(list(self._pending.pop(stamp, {}).values()))

    def mark_written(self, items: list) -> list:
        """Items written directly (not offered): later copies of them are dropped."""
        return self._mark([i for i in items if (i[0], header_stamp_ns(i[1])) not in self._written])

    def _mark(self, items: list) -> list:
        for topic, raw, _ in items:
            self._written[(topic, header_stamp_ns(raw))] = None
        _trim(self._written, 4 * BUFFER_STAMPS)
        return items

    def offer_joint_state(self, topic: str, raw: bytes, log_time_ns: int) -> list:
        last = self._last_joint_state_ns
        if last is not None and log_time_ns - last < self.joint_state_period_ns:
            return []
        self._last_joint_state_ns = log_time_ns
        return [(topic, raw, log_time_ns)]


def _trim(ordered: OrderedDict, size: int = BUFFER_STAMPS) -> None:
    while len(ordered) > size:
        ordered.popitem(last=False)
