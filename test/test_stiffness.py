import math

import numpy as np
import pytest

from defgg_ros.constants import STIFFNESS_BACKGROUND, STIFFNESS_OBJECT_MIN, TRAINING_YOUNGS_MODULI_PA
from defgg_ros.stiffness import (
    InvalidYoungsModulus,
    decode_stiffness,
    encode_stiffness_image,
    encode_youngs_modulus,
)


def test_training_moduli_are_ordered_inside_the_object_range():
    codes = [encode_youngs_modulus(e) for e in TRAINING_YOUNGS_MODULI_PA]
    assert codes == sorted(codes)
    assert all(STIFFNESS_OBJECT_MIN < c < 1.0 for c in codes)


def test_encoding_is_continuous_and_log_scaled():
    # One decade is the same step everywhere.
    step1 = encode_youngs_modulus(2e5) - encode_youngs_modulus(2e4)
    step2 = encode_youngs_modulus(2e7) - encode_youngs_modulus(2e6)
    assert step1 == pytest.approx(step2)
    # +-60 % errors move the code by a small, finite amount.
    assert 0 < encode_youngs_modulus(2e5 * 1.6) - encode_youngs_modulus(2e5) < step1


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, "soft", None])
def test_invalid_modulus_raises(bad):
    with pytest.raises(InvalidYoungsModulus):
        encode_youngs_modulus(bad)


def test_image_background_and_round_trip():
    image = np.zeros((4, 4), np.float32)
    image[1:3, 1:3] = 2e5
    enc = encode_stiffness_image(image)
    assert enc.dtype == np.float32
    assert enc[0, 0] == STIFFNESS_BACKGROUND
    assert enc[1, 1] == pytest.approx(encode_youngs_modulus(2e5))
    assert decode_stiffness(enc[1, 1]) == pytest.approx(2e5, rel=1e-5)


@pytest.mark.parametrize("bad", [np.nan, -5.0, np.inf])
def test_image_with_invalid_pixels_raises(bad):
    image = np.full((3, 3), 2e5)
    image[1, 1] = bad
    with pytest.raises(InvalidYoungsModulus):
        encode_stiffness_image(image)
