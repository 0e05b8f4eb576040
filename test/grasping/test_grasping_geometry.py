"""Pixel/metre geometry and the rectangle metric, against hand-computed cases."""
import math

import numpy as np
import pytest

from defgg_ros.data.format import GraspRect
from defgg_ros.grasping.geometry import (
    InvalidCameraError,
    check_camera_k,
    pixel_to_camera,
    width_m_to_px,
    width_px_to_m,
)
from defgg_ros.grasping.rectangles import angle_difference_rad, rectangle_iou, rectangle_match


def test_width_pixels_to_metres_hand_computed():
    # 77 px at 0.40 m with fx = 385 px: 77 * 0.40 / 385 = 0.08 m (the Panda's full opening).
    assert width_px_to_m(77.0, 0.40, 385.0) == pytest.approx(0.08)
    assert width_m_to_px(0.08, 0.40, 385.0) == pytest.approx(77.0)


def test_pixel_to_camera_hand_computed():
    k = np.array([[385.0, 0, 320.0], [0, 390.0, 240.0], [0, 0, 1]])
    # u = 397 is 77 px right of cx: x = 77 * 0.5 / 385 = 0.1 m; v = 162: y = -78 * 0.5 / 390 = -0.1 m
    assert pixel_to_camera(397, 162, 0.5, k) == pytest.approx([0.1, -0.1, 0.5])


@pytest.mark.parametrize("k", [np.eye(2), np.full((3, 3), np.nan), np.diag([0.0, 1.0, 1.0])])
def test_bad_intrinsics(k):
    with pytest.raises(InvalidCameraError):
        check_camera_k(k)


def test_angle_difference_is_modulo_pi():
    assert angle_difference_rad(math.radians(85), math.radians(-85)) == pytest.approx(math.radians(10))
    assert angle_difference_rad(0.0, math.pi) == pytest.approx(0.0)


def test_iou_hand_computed():
    a = GraspRect(50, 50, 0.0, 40, 20)
    assert rectangle_iou(a, a) == pytest.approx(1.0)
    # shifted by half its width: overlap 20x20 = 400 of union 800 + 800 - 400
    assert rectangle_iou(a, GraspRect(70, 50, 0.0, 40, 20)) == pytest.approx(400 / 1200)
    # a 90-degree-rotated square is the same square
    assert rectangle_iou(GraspRect(0, 0, 0.0, 30, 30), GraspRect(0, 0, math.pi / 2, 30, 30)) == pytest.approx(1.0)


def test_rectangle_metric():
    gt = [GraspRect(100, 100, math.radians(80), 50, 20)]
    assert rectangle_match(GraspRect(103, 98, math.radians(-85), 45, 20), gt)     # wraps: 15 deg apart
    assert not rectangle_match(GraspRect(100, 100, math.radians(40), 50, 20), gt)  # 40 deg apart
    assert not rectangle_match(GraspRect(160, 100, math.radians(80), 50, 20), gt)  # no overlap
