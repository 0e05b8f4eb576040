"""Depth/stiffness inputs and the crop window (shared by training and inference)."""
import numpy as np
import pytest

from defgg_ros.model.preprocess import (
    InvalidDepthError,
    InvalidInputError,
    crop_origin,
    encode_depth,
    inpaint_depth,
    network_input,
)
from defgg_ros.stiffness import InvalidYoungsModulus


def _table(h=300, w=300):
    depth = np.full((h, w), 0.40, np.float32)
    depth[100:150, 120:180] = 0.35
    return depth


@pytest.mark.parametrize("bad", [0.0, np.nan, np.inf, -1.0])
def test_holes_are_filled_from_neighbours(bad):
    depth = _table()
    holed = depth.copy()
    holed[10:14, 10:14] = bad        # hole in the table
    holed[120:123, 140:143] = bad    # hole on the object top
    filled = inpaint_depth(holed)
    assert np.all(np.isfinite(filled)) and np.all(filled > 0)
    assert np.allclose(filled[10:14, 10:14], 0.40, atol=1e-3)
    assert np.allclose(filled[120:123, 140:143], 0.35, atol=1e-3)


def test_all_invalid_depth_raises():
    with pytest.raises(InvalidDepthError, match="no valid pixel"):
        inpaint_depth(np.zeros((300, 300), np.float32))


@pytest.mark.parametrize("bad", [np.zeros((3, 300, 300), np.float32), np.zeros((300, 300), np.int32)])
def test_depth_of_wrong_shape_or_type_raises(bad):
    with pytest.raises(InvalidDepthError):
        encode_depth(bad)


def test_encoded_depth_is_height_independent_and_bounded():
    a, b = encode_depth(_table()), encode_depth(_table() + 0.3)
    assert np.allclose(a, b, atol=1e-5)
    assert abs(float(a.mean())) < 1e-5
    assert encode_depth(np.where(_table() > 0.36, 50.0, 0.4).astype(np.float32)).max() <= 1.0


def test_network_input_channels_and_validation():
    depth = _table()
    moduli = np.where(depth < 0.4, 2e5, 0.0)
    assert network_input(depth, moduli, True).shape == (2, 300, 300)
    assert network_input(depth, moduli, False).shape == (1, 300, 300)
    with pytest.raises(InvalidYoungsModulus):
        network_input(depth, np.full_like(depth, np.nan), False)
    with pytest.raises(InvalidInputError, match="does not match"):
        network_input(depth, moduli[:, :200], True)


def test_crop_is_centred_on_the_mask_and_clamped():
    mask = np.zeros((480, 640), np.uint8)
    mask[200:260, 400:480] = 1
    assert crop_origin(mask.shape, mask) == (440 - 150, 230 - 150)
    assert crop_origin(mask.shape, None) == (170, 90)
    corner = np.zeros_like(mask)
    corner[470:, 630:] = 1
    assert crop_origin(mask.shape, corner) == (340, 180)
    with pytest.raises(InvalidInputError, match="smaller"):
        crop_origin((299, 640))
