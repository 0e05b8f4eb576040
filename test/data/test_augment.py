"""Augmentation moves images and labels together and rotates angles correctly."""
import math

import numpy as np
import pytest

from defgg_ros.data.augment import AugmentConfig, affine_matrix, augment_sample, transform_rect, warp_images
from defgg_ros.data.format import GraspRect
from defgg_ros.data.groundtruth import ground_truth_maps


def _scene(n=101):
    depth = np.full((n, n), 0.40, np.float32)
    moduli = np.zeros((n, n), np.float32)
    mask = np.zeros((n, n), np.uint8)
    depth[20:40, 55:90] = 0.35
    moduli[20:40, 55:90] = 2e5
    mask[20:40, 55:90] = 1
    return depth, moduli, mask


def test_quarter_turn_rotates_images_and_label_maps_exactly():
    n = 101
    depth, moduli, mask = _scene(n)
    rect = GraspRect(72, 30, math.radians(80), 30, 10)
    m = affine_matrix(math.pi / 2, 1.0, (0, 0), ((n - 1) / 2, (n - 1) / 2))
    d2, e2, m2 = warp_images(depth, moduli, mask, m)
    # +90 deg from u towards v is a clockwise quarter turn of the displayed image.
    assert np.allclose(d2, np.rot90(depth, k=-1), atol=1e-5)
    assert np.array_equal(e2, np.rot90(moduli, k=-1)) and np.array_equal(m2, np.rot90(mask, k=-1))
    r2 = transform_rect(rect, m, math.pi / 2, 1.0)
    assert (r2.center_u_px, r2.center_v_px) == pytest.approx((n - 1 - 30, 72))
    assert r2.angle_rad == pytest.approx(math.radians(-10))   # 80 + 90 = 170 deg = -10 deg
    q, angle, width = ground_truth_maps([rect], (n, n))
    q2, angle2, width2 = ground_truth_maps([r2], (n, n))
    assert np.array_equal(q2, np.rot90(q, k=-1))
    assert np.allclose(angle2[q2 > 0], math.radians(-10), atol=1e-6)
    assert np.array_equal(width2, np.rot90(width, k=-1))


def test_random_augmentation_keeps_labels_on_the_warped_maps():
    depth, moduli, mask = _scene()
    rect = GraspRect(72, 30, 0.2, 40, 12)
    rng = np.random.default_rng(4)
    for _ in range(5):
        state = rng.bit_generator.state
        d2, e2, m2, (r2,) = augment_sample(depth, moduli, mask, [rect], rng, AugmentConfig(max_shift_px=10))
        rng2 = np.random.default_rng()
        rng2.bit_generator.state = state
        matrix = affine_matrix(*_draw(rng2, AugmentConfig(max_shift_px=10), depth.shape))
        q_warped = warp_images(ground_truth_maps([rect], depth.shape)[0], moduli, mask, matrix)[0] > 0.5
        q_new = ground_truth_maps([r2], depth.shape)[0] > 0
        iou = (q_warped & q_new).sum() / (q_warped | q_new).sum()
        assert iou > 0.8
        # the grasp centre stays on the object in every image
        assert m2[int(round(r2.center_v_px)), int(round(r2.center_u_px))] == 1
        assert e2[int(round(r2.center_v_px)), int(round(r2.center_u_px))] == 2e5


def _draw(rng, config, shape):
    rotation = rng.uniform(-config.max_rotation_rad, config.max_rotation_rad)
    zoom = rng.uniform(*config.zoom_range)
    shift = rng.uniform(-config.max_shift_px, config.max_shift_px, size=2)
    return rotation, zoom, shift, ((shape[1] - 1) / 2, (shape[0] - 1) / 2)


def test_zoom_scales_rectangle_size():
    m = affine_matrix(0.0, 1.1, (5, -3), (50, 50))
    r = transform_rect(GraspRect(60, 50, 0.3, 40, 10), m, 0.0, 1.1)
    assert (r.center_u_px, r.center_v_px) == pytest.approx((50 + 11 + 5, 50 - 3))
    assert (r.width_px, r.finger_height_px, r.angle_rad) == pytest.approx((44, 11, 0.3))
