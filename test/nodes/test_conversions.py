"""Round trips and bad inputs of the shared ROS conversion helpers."""
import math

import numpy as np
import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.perception.geometry import quaternion_xyzw_to_matrix, transform_from_list
from defgg_ros.ros import conversions as cv

RNG = np.random.default_rng(7)


@pytest.mark.parametrize("encoding,dtype,shape", [
    ("16UC1", np.uint16, (4, 5)), ("32FC1", np.float32, (3, 7)),
    ("mono8", np.uint8, (2, 2)), ("rgb8", np.uint8, (3, 4, 3)),
])
def test_image_round_trip(encoding, dtype, shape):
    array = (RNG.random(shape) * 200).astype(dtype)
    msg = cv.numpy_to_image(array, encoding, Header(frame_id="cam"))
    assert msg.step == shape[1] * (shape[2] if len(shape) == 3 else 1) * np.dtype(dtype).itemsize
    back = cv.image_to_numpy(msg)
    assert back.dtype == dtype and np.array_equal(back, array)


def test_big_endian_and_padded_rows_are_read_correctly():
    values = np.array([[1000, 2000], [3000, 65535]], dtype=np.uint16)
    padded = np.zeros((2, 3), dtype=">u2")  # one padding element per row
    padded[:, :2] = values
    msg = Image(height=2, width=2, encoding="16UC1", is_bigendian=1, step=6, data=padded.tobytes())
    assert np.array_equal(cv.image_to_numpy(msg), values)


@pytest.mark.parametrize("mutate,reason", [
    (lambda m: setattr(m, "encoding", "bayer_rggb8"), "unsupported"),
    (lambda m: setattr(m, "height", 0), "empty"),
    (lambda m: setattr(m, "step", 2), "shorter than a row"),
    (lambda m: setattr(m, "data", bytes(3)), "expected step"),
])
def test_bad_images_raise(mutate, reason):
    msg = cv.numpy_to_image(np.ones((4, 4), np.uint16), "16UC1")
    mutate(msg)
    with pytest.raises(cv.ConversionError, match=reason):
        cv.image_to_numpy(msg)


def test_numpy_to_image_rejects_wrong_dtype():
    with pytest.raises(cv.ConversionError, match="dtype"):
        cv.numpy_to_image(np.ones((2, 2), np.float64), "32FC1")


def test_depth_mm_and_m_agree_and_invalid_is_nan():
    depth_m = np.full((6, 8), 0.4, np.float32)
    depth_m[1, 2] = np.nan
    mm_msg = cv.depth_metres_to_msg(depth_m, "16UC1")
    m_msg = cv.depth_metres_to_msg(depth_m, "32FC1")
    from_mm, from_m = cv.depth_msg_to_metres(mm_msg), cv.depth_msg_to_metres(m_msg)
    assert cv.image_to_numpy(mm_msg)[1, 2] == 0 and cv.image_to_numpy(mm_msg)[0, 0] == 400
    assert np.isnan(from_mm[1, 2]) and np.isnan(from_m[1, 2])
    np.testing.assert_allclose(from_mm[0, 0], 0.4, atol=1e-6)
    np.testing.assert_allclose(np.nan_to_num(from_mm), np.nan_to_num(from_m), atol=5e-4)


def test_depth_unit_mistakes_are_detected():
    metres_as_u16 = cv.numpy_to_image(np.full((4, 4), 1, np.uint16), "16UC1")
    with pytest.raises(cv.ConversionError, match="look like metres"):
        cv.depth_msg_to_metres(metres_as_u16)
    mm_as_float = cv.numpy_to_image(np.full((4, 4), 400.0, np.float32), "32FC1")
    with pytest.raises(cv.ConversionError, match="look like millimetres"):
        cv.depth_msg_to_metres(mm_as_float)
    with pytest.raises(cv.ConversionError, match="no valid pixel"):
        cv.depth_msg_to_metres(cv.numpy_to_image(np.full((4, 4), np.nan, np.float32), "32FC1"))
    with pytest.raises(cv.ConversionError, match="16UC1 .* or 32FC1"):
        cv.depth_msg_to_metres(cv.numpy_to_image(np.ones((4, 4), np.uint8), "mono8"))


def test_stiffness_checks():
    good = np.array([[0.0, 2e5], [2e9, 0.0]], np.float32)
    assert np.array_equal(cv.stiffness_msg_to_pa(cv.numpy_to_image(good, "32FC1")), good)
    for bad in (np.nan, -1.0, np.inf):
        image = good.copy()
        image[0, 0] = bad
        with pytest.raises(cv.ConversionError):
            cv.stiffness_msg_to_pa(cv.numpy_to_image(image, "32FC1"))
    with pytest.raises(cv.ConversionError, match="32FC1"):
        cv.stiffness_msg_to_pa(cv.numpy_to_image(np.ones((2, 2), np.uint16), "16UC1"))


def test_camera_info_round_trip_and_errors():
    k = np.array([[385.0, 0, 320], [0, 385.0, 240], [0, 0, 1]])
    info = cv.make_camera_info(k, 640, 480)
    np.testing.assert_array_equal(cv.camera_info_to_k(info), k)
    info.k = [0.0] * 9
    with pytest.raises(cv.ConversionError, match="focal"):
        cv.camera_info_to_k(info)
    info = cv.make_camera_info(k, 640, 480)
    info.width = 0
    with pytest.raises(cv.ConversionError, match="empty"):
        cv.camera_info_to_k(info)


def test_check_same_size():
    a = cv.numpy_to_image(np.ones((4, 5), np.uint16), "16UC1")
    b = cv.numpy_to_image(np.ones((4, 6), np.float32), "32FC1")
    cv.check_same_size("depth", a, "depth", a)
    with pytest.raises(cv.ConversionError, match="5x4 .* 6x4"):
        cv.check_same_size("depth", a, "stiffness", b)


def test_pose_round_trip():
    T = transform_from_list([0.1, -0.2, 0.3, 0.2, -0.3, 0.1, math.sqrt(1 - 0.14)])
    np.testing.assert_allclose(cv.transform_from_pose(cv.pose_from_transform(T)), T, atol=1e-12)


class _Candidate:
    center_u_px, center_v_px, angle_rad, width_px = 320.0, 240.0, math.pi / 6, 90.0
    width_m, quality, position_camera_m = 0.095, 0.8, (0.01, 0.02, 0.38)
    youngs_modulus_pa, object_id = 2e5, 1


def test_grasp_msg_pose_convention_and_width_clip():
    # Camera 0.5 m above the base origin looking straight down: optical z = -base z.
    base_T_camera = transform_from_list([0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0])
    header = Header(frame_id="camera_depth_optical_frame")
    msg = cv.grasp_to_msg(_Candidate(), header, base_T_camera, "panda_link0")
    assert msg.width_m == GRIPPER_MAX_WIDTH_M  # 95 mm clipped to the hand's 80 mm
    assert msg.pose_base.header.frame_id == "panda_link0"
    p = msg.pose_base.pose.position
    np.testing.assert_allclose([p.x, p.y, p.z], [0.51, -0.02, 0.12], atol=1e-9)
    o = msg.pose_base.pose.orientation
    R = quaternion_xyzw_to_matrix([o.x, o.y, o.z, o.w])
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-9)  # approach points down
    # Fingers close along the image direction at 30 deg from u towards v.
    np.testing.assert_allclose(R[:, 0], base_T_camera[:3, :3] @ [math.cos(math.pi / 6), 0.5, 0], atol=1e-9)


def test_grasp_msg_rejects_nan():
    cand = _Candidate()
    cand.width_m = float("nan")
    with pytest.raises(cv.ConversionError):
        cv.grasp_to_msg(cand, Header(), np.eye(4), "base")


def test_stamp_ns_round_trip():
    assert cv.stamp_to_ns(cv.ns_to_stamp(12_345_678_901)) == 12_345_678_901


def test_seconds_to_stamp_carries_a_rounded_up_fraction_into_the_seconds():
    # The simulated driver split seconds before rounding: 12.9999999997 s was stamped 12.000000000 s, 1 s in
    # the past, which read as a clock jumping back.
    from defgg_ros.ros.conversions import seconds_to_stamp

    stamp = seconds_to_stamp(12.9999999997)
    assert (stamp.sec, stamp.nanosec) == (13, 0)
    stamp = seconds_to_stamp(3.25)
    assert (stamp.sec, stamp.nanosec) == (3, 250_000_000)
