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


COLOR = "/color"


def test_a_colour_frame_stamped_by_its_own_sensor_is_kept_with_its_depth_frame():
    """realsense2_camera stamps colour with its own capture time (enable_sync off), never the depth frame's: the
    colour of a kept frame, 1 ms after its depth (the fake driver) or before it, is written with it, and one of a
    frame not kept is not. Filed under its own stamp it waited for a reference that never came: no colour frame
    was ever recorded (a review's 100 frames: depth 100, colour 0)."""
    selector = FrameSelector(DEPTH, depth_period_s=1.0, frame_topics=(INFO,), paired_topics=(COLOR,))
    written = []
    for i in range(10):   # 10 Hz: every 10th frame kept
        depth_ns = 1_000_000_000 + i * 100_000_000
        color = (COLOR, _raw(depth_ns + 1_000_000), 0)
        if i % 2:   # the colour frame before its depth frame
            written += selector.offer_stamped(*color)
        written += selector.offer_stamped(DEPTH, _raw(depth_ns), depth_ns)
        written += selector.offer_stamped(INFO, _raw(depth_ns), depth_ns)
        if not i % 2:
            written += selector.offer_stamped(*color)
    kept = [topic for topic, _, _ in written]
    assert kept.count(DEPTH) == 1 and kept.count(INFO) == 1 and kept.count(COLOR) == 1, kept
    written = []
    written += selector.offer_stamped(COLOR, _raw(2_000_000_000 - 2_000_000), 0)   # before, 2 ms
    written += selector.offer_stamped(DEPTH, _raw(2_000_000_000), 2_000_000_000)
    assert sorted(topic for topic, _, _ in written) == sorted([DEPTH, COLOR])
