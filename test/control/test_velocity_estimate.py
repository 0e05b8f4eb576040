"""Joint velocities from positions (drivers whose joint_states carry none): an arm at rest must read as at rest.

Why: every arrival now waits for rest (every joint below still_speed_radps, 0.02 rad/s). Differencing consecutive
1 kHz messages turned 1e-5 rad of position noise into ~0.04 rad/s, so a resting arm could read as moving and a
pick time out (review, 2026-11-28).
"""
import numpy as np
import pytest

from defgg_ros.control.sequence_types import SequenceConfig
from defgg_ros.control.velocity_estimate import MIN_BASELINE_S, PositionVelocityEstimator

STILL_RADPS = SequenceConfig.still_speed_radps


def test_an_arm_at_rest_sampled_at_1khz_with_position_noise_reads_as_at_rest():
    rng = np.random.default_rng(0)
    estimate = PositionVelocityEstimator()
    q_rest = np.linspace(-1.0, 1.0, 7)
    speeds = [np.abs(estimate.update(q_rest + 1e-5 * rng.standard_normal(7), k * 1e-3)).max() for k in range(2000)]
    assert np.isnan(speeds[0])                                  # nothing to difference against yet
    assert np.nanmax(speeds[10:]) < 0.75 * STILL_RADPS           # 0.012 rad/s over 14,000 readings
    naive = np.abs(np.diff(1e-5 * rng.standard_normal((2000, 7)), axis=0) / 1e-3).max()
    assert naive > STILL_RADPS                                  # what consecutive messages would have read


@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
def test_a_moving_joint_reads_its_speed_at_any_message_rate(rate_hz):
    estimate = PositionVelocityEstimator(1)
    dt = 1.0 / rate_hz
    readings = [estimate.update([0.3 * k * dt], k * dt) for k in range(100)]
    assert all(r[0] == pytest.approx(0.3) for r in readings[int(np.ceil(MIN_BASELINE_S / dt)) + 1:])


def test_a_gap_or_a_clock_jump_gives_no_estimate_until_fresh_samples_exist():
    estimate = PositionVelocityEstimator(1)
    for k in range(20):
        estimate.update([0.0], k * 0.01)
    assert np.isnan(estimate.update([0.0], 5.0)[0])             # 4.8 s without a message
    assert np.isnan(estimate.update([0.0], 4.0)[0])             # time went backwards
    assert estimate.update([0.1], 4.01)[0] == pytest.approx(10.0)
