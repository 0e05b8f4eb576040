"""Which messages a recording keeps: decimated depth, referenced frames pulled from the buffer, no duplicates."""
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from defgg_ros.ros.conversions import ns_to_stamp
from defgg_ros.sessions.selector import BUFFER_STAMPS, FrameSelector, StampError, header_stamp_ns

DEPTH, INFO = "/depth", "/info"
S = 1_000_000_000


def raw(kind, stamp_ns):
    return serialize_message(kind(header=Header(stamp=ns_to_stamp(stamp_ns))))


def test_header_stamp_is_read_from_cdr():
    assert header_stamp_ns(raw(Image, 12 * S + 345)) == 12 * S + 345
    with pytest.raises(StampError):
        header_stamp_ns(b"\x00\x01\x00")


def test_depth_is_decimated_and_its_info_follows():
    sel = FrameSelector(DEPTH, depth_period_s=1.0)
    written = []
    for i in range(10):  # 10 Hz camera for 1 s (+ info after depth)
        written += sel.offer_stamped(DEPTH, raw(Image, i), i * S // 10)
        written += sel.offer_stamped(INFO, raw(CameraInfo, i), i * S // 10 + 1)
    assert [(t, header_stamp_ns(r)) for t, r, _ in written] == [(DEPTH, 0), (INFO, 0)]


def test_a_referenced_frame_is_pulled_from_the_buffer_once():
    sel = FrameSelector(DEPTH, depth_period_s=100.0)
    sel.offer_stamped(DEPTH, raw(Image, 0), 0)
    assert sel.offer_stamped(INFO, raw(CameraInfo, 5), 1) == []
    assert sel.offer_stamped(DEPTH, raw(Image, 5), 2) == []
    pulled = sel.keep(5)
    assert sorted(t for t, _, _ in pulled) == [DEPTH, INFO]
    assert sel.offer_stamped(DEPTH, raw(Image, 5), 3) == []          # a re-sent copy is not written twice
    assert len(sel.offer_stamped("/grasp", raw(Image, 5), 4)) == 1   # but the grasp for it is


def test_buffer_is_bounded():
    sel = FrameSelector(DEPTH, depth_period_s=1e6)
    sel.offer_stamped(DEPTH, raw(Image, 0), 0)
    for i in range(1, BUFFER_STAMPS + 10):
        sel.offer_stamped(DEPTH, raw(Image, i), i)
    assert sel.keep(1) == []            # too old: dropped
    assert len(sel.keep(BUFFER_STAMPS + 5)) == 1


def test_joint_states_are_decimated():
    sel = FrameSelector(DEPTH, joint_state_period_s=0.1)
    kept = [t for t in range(0, S, S // 100) if sel.offer_joint_state("/js", b"x", t)]
    assert len(kept) == 10
