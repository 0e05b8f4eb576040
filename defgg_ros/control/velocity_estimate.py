"""Joint velocities from positions, for drivers whose joint_states carry none (pure, no rclpy).

Why a baseline: the rest test (every joint below 0.02 rad/s) runs on every arrival. From consecutive 1 kHz
messages, 1e-5 rad of position noise reads as ~0.014 rad/s typically and over 0.02 at times, so an arm at rest
could keep reading as moving; differencing over at least MIN_BASELINE_S (5 ms) cuts that five-fold. Over
MAX_BASELINE_S (0.5 s) the difference says nothing about now: the estimate is NaN (never "at rest" on missing data).
"""
import numpy as np

MIN_BASELINE_S = 0.005
MAX_BASELINE_S = 0.5


class PositionVelocityEstimator:
    """qd = (q - q_ref) / (t - t_ref), the reference the newest earlier sample at least MIN_BASELINE_S old."""

    def __init__(self, n_joints: int = 7):
        self._n = n_joints
        self._samples = []          # (t_s, q), oldest first: the reference and the samples after it

    def update(self, q_rad, stamp_s: float) -> np.ndarray:
        """The velocity estimate after a sample at stamp_s (NaN until a sample MIN_BASELINE_S older exists)."""
        q = np.asarray(q_rad, dtype=float).copy()
        if self._samples and not 0.0 <= stamp_s - self._samples[-1][0] <= MAX_BASELINE_S:
            self._samples = []      # a gap or a clock jump: the old samples say nothing about now
        old = [k for k, (t, _) in enumerate(self._samples) if stamp_s - t >= MIN_BASELINE_S]
        self._samples = self._samples[old[-1]:] if old else self._samples
        self._samples.append((float(stamp_s), q))
        if not old:
            return np.full(self._n, np.nan)
        t_ref, q_ref = self._samples[0]
        return (q - q_ref) / (stamp_s - t_ref)
