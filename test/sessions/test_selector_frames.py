"""A frame counts as recorded only when depth and camera_info both arrived."""
import struct

from defgg_ros.sessions.selector import FrameSelector

DEPTH, INFO = "/depth", "/info"


def _raw(stamp_ns: int) -> bytes:
    # CDR little-endian encapsulation header, then builtin_interfaces/Time (sec, nanosec).
    return bytes([0, 1, 0, 0]) + struct.pack("<iI", stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)


def test_depth_without_camera_info_is_not_a_whole_frame():
    selector = FrameSelector(DEPTH, depth_period_s=1000.0, frame_topics=(INFO,))
    selector.offer_stamped(DEPTH, _raw(5_000_000_000), 1)
    assert not selector.has_frame(5_000_000_000)
    selector.offer_stamped(INFO, _raw(5_000_000_000), 2)
    assert selector.has_frame(5_000_000_000)


def test_without_frame_topics_depth_alone_is_a_frame():
    selector = FrameSelector(DEPTH, depth_period_s=1000.0)
    selector.offer_stamped(DEPTH, _raw(7_000_000_000), 1)
    assert selector.has_frame(7_000_000_000)
