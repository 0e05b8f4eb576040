"""The energy blow-up check's speed estimate (pure numpy)."""
import numpy as np
import pytest

from defgg_ros.sim.trial import MAX_RMS_NODE_SPEED_MPS, rms_speed_mps


def test_rms_speed_of_a_translated_body():
    before = [np.zeros((4, 3)), np.zeros((1, 3))]
    after = [np.full((4, 3), [0.3, 0.4, 0.0]), np.array([[0.3, 0.4, 0.0]])]
    assert rms_speed_mps(before, after, 0.01) == pytest.approx(50.0)
    assert rms_speed_mps(before, after, 0.01) > MAX_RMS_NODE_SPEED_MPS


def test_no_speed_without_a_comparable_snapshot():
    after = [np.ones((4, 3))]
    assert rms_speed_mps(None, after, 0.01) == 0.0
    assert rms_speed_mps([np.zeros((3, 3))], after, 0.01) == 0.0   # a different body set
