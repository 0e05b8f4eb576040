"""Ground-truth maps from grasp rectangles."""
import math

import numpy as np
import pytest

from defgg_ros.data.format import GraspRect
from defgg_ros.data.groundtruth import ground_truth_maps, rectangle_pixels, training_targets, wrap_angle


def test_axis_aligned_rectangle_hand_computed():
    # Opening 60 px along u, finger 20 px along v, centre third drawn: u in [90, 110], v in [40, 60].
    rect = GraspRect(100, 50, 0.0, 60, 20)
    q, angle, width = ground_truth_maps([rect], (120, 200))
    vs, us = np.nonzero(q)
    assert (us.min(), us.max(), vs.min(), vs.max()) == (90, 110, 40, 60)
    assert np.all(width[q > 0] == 60) and np.all(angle[q > 0] == 0)
    assert q.sum() == 21 * 21
    full, _, _ = ground_truth_maps([rect], (120, 200), length_fraction=1.0)
    assert np.nonzero(full)[1].min() == 70 and np.nonzero(full)[1].max() == 130


def test_rotated_rectangle_runs_along_its_angle():
    rect = GraspRect(100, 100, math.pi / 2, 90, 10)  # opening along v
    mask = rectangle_pixels(rect, (200, 200))
    vs, us = np.nonzero(mask)
    assert vs.max() - vs.min() == 30 and us.max() - us.min() == 10


def test_outside_is_zero_and_targets_encode_the_angle():
    rects = [GraspRect(60, 60, 0.4, 45, 15), GraspRect(140, 140, -1.3, 75, 15)]
    q, angle, width = ground_truth_maps(rects, (200, 200))
    y = training_targets(q, angle, width)
    assert y.shape == (4, 200, 200)
    outside = q == 0
    assert np.all(y[:, outside] == 0)
    assert y[1, 60, 60] == pytest.approx(math.cos(0.8)) and y[2, 60, 60] == pytest.approx(math.sin(0.8))
    assert y[2, 140, 140] == pytest.approx(math.sin(-2.6), abs=1e-6)
    assert y[3, 140, 140] == pytest.approx(75 / 150)
    assert np.all((y[3] >= 0) & (y[3] <= 1))


def test_wrap_angle():
    assert wrap_angle(math.pi / 2 + 0.1) == pytest.approx(-math.pi / 2 + 0.1)
    assert wrap_angle(-math.pi) == pytest.approx(0.0)
    assert wrap_angle(0.3) == pytest.approx(0.3)
