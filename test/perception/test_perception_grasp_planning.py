"""Pure helpers of the grasp inference node: top_k, quality image, finger boxes."""
import numpy as np
import pytest

from defgg_ros.constants import FINGER_DEPTH_M, GRIPPER_MAX_WIDTH_M
from defgg_ros.perception.geometry import (
    TransformError,
    matrix_to_quaternion_xyzw,
    quaternion_xyzw_to_matrix,
    top_down_grasp_in_camera,
    transform_from_list,
)
from defgg_ros.perception.grasp_planning import (
    FINGER_THICKNESS_M,
    MAX_TOP_K,
    PlanningError,
    check_top_k,
    finger_boxes_in_grasp,
    full_quality_image,
)


@pytest.mark.parametrize("top_k,expected", [(0, 1), (1, 1), (7, 7), (MAX_TOP_K, MAX_TOP_K)])
def test_top_k(top_k, expected):
    assert check_top_k(top_k) == expected


def test_top_k_too_large():
    with pytest.raises(PlanningError, match="top_k"):
        check_top_k(MAX_TOP_K + 1)


def test_quality_image_is_pasted_at_the_crop_offset():
    q = np.arange(9, dtype=np.float32).reshape(3, 3)
    full = full_quality_image(q, (4, 1), (5, 8))
    assert full.shape == (5, 8) and full.dtype == np.float32
    np.testing.assert_array_equal(full[1:4, 4:7], q)
    assert full.sum() == q.sum()


def test_finger_boxes_stand_at_the_opening_and_reach_back():
    boxes = finger_boxes_in_grasp(0.04)
    xs = sorted(pose[0, 3] for pose, _ in boxes)
    assert xs == pytest.approx([-0.02 - FINGER_THICKNESS_M / 2, 0.02 + FINGER_THICKNESS_M / 2])
    assert all(pose[2, 3] == pytest.approx(-FINGER_DEPTH_M / 2) for pose, _ in boxes)
    too_wide = finger_boxes_in_grasp(0.5)  # clipped to the hand
    assert max(p[0, 3] for p, _ in too_wide) == pytest.approx(GRIPPER_MAX_WIDTH_M / 2 + FINGER_THICKNESS_M / 2)


def test_quaternion_rejections_in_the_perception_error_type():
    # the conversion itself: test/foundation/test_rotations.py
    q = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    assert matrix_to_quaternion_xyzw(quaternion_xyzw_to_matrix(q)) == pytest.approx(q)
    with pytest.raises(TransformError, match="unit norm"):
        quaternion_xyzw_to_matrix([0, 0, 0, 2])
    with pytest.raises(TransformError, match="7 numbers"):
        transform_from_list([0, 0, 0])
    with pytest.raises(TransformError, match="proper rotation"):
        matrix_to_quaternion_xyzw(np.diag([1.0, 1.0, -1.0]))


def test_top_down_grasp_axes():
    camera_T_grasp = top_down_grasp_in_camera((0.1, 0.2, 0.4), np.pi / 2)
    np.testing.assert_allclose(camera_T_grasp[:3, 0], [0, 1, 0], atol=1e-12)  # closing along image v
    np.testing.assert_allclose(camera_T_grasp[:3, 2], [0, 0, 1], atol=1e-12)  # approach = optical axis
    with pytest.raises(TransformError):
        top_down_grasp_in_camera((0.1, np.nan, 0.4), 0.0)
