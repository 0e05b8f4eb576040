"""Is the camera's view clear of the arm? The observation pose and where a goal left the arm.

The camera looks down on the table; with the arm anywhere over it, a depth frame shows the hand,
and a grasp planned on it lands on the hand (issue 27: grasps at the hand's height after a cancel).
The executor therefore plans only on frames taken while the arm rested at the observation pose:
`ObservationWatch` follows the joint states and says since when (robot clock) the arm has been
there without a break; a frame stamped before that may show the arm. Pure: no ROS.
"""
import math

import numpy as np


def max_joint_speed_radps(qd_radps) -> float:
    """The fastest joint's speed; inf when unknown (no velocities, or a NaN one: not yet estimated), so
    an unknown speed never reads as at rest."""
    if qd_radps is None:
        return math.inf
    speed = float(np.max(np.abs(np.asarray(qd_radps, dtype=float))))
    return speed if math.isfinite(speed) else math.inf


def at_pose(q_rad, pose_q_rad, tolerance_rad: float) -> bool:
    """Every joint within tolerance_rad of pose_q_rad."""
    return float(np.max(np.abs(np.asarray(q_rad, dtype=float) - np.asarray(pose_q_rad, dtype=float)))) <= tolerance_rad


def arm_state_of(q_rad, qd_radps, observation_q_rad, tolerance_rad: float, still_speed_radps: float) -> str:
    """One of sequence_types.ARM_STATES from a single joint state (no state: unknown)."""
    if q_rad is None:
        return "unknown"
    if max_joint_speed_radps(qd_radps) >= still_speed_radps:
        return "moving"
    if observation_q_rad is not None and at_pose(q_rad, observation_q_rad, tolerance_rad):
        return "observation_pose"
    return "at_rest"


class ObservationWatch:
    """Since when (robot clock, s) has the arm been at the observation pose without a break?"""

    def __init__(self, observation_q_rad, tolerance_rad: float):
        self.observation_q_rad = np.asarray(observation_q_rad, dtype=float)
        self.tolerance_rad = float(tolerance_rad)
        self.since_s: float | None = None

    def update(self, q_rad, stamp_s: float) -> None:
        if not at_pose(q_rad, self.observation_q_rad, self.tolerance_rad):
            self.since_s = None
        elif self.since_s is None:
            self.since_s = float(stamp_s)

    def retarget(self, observation_q_rad, tolerance_rad: float) -> None:
        """A new observation pose or tolerance (a parameter change): the rest there counts afresh."""
        q = np.asarray(observation_q_rad, dtype=float)
        if not (np.array_equal(q, self.observation_q_rad) and float(tolerance_rad) == self.tolerance_rad):
            self.observation_q_rad, self.tolerance_rad, self.since_s = q, float(tolerance_rad), None

    def frames_from(self, stamp_s: float) -> None:
        """Only frames stamped stamp_s or later count as clear from now on (the perception changed then: a
        squeeze's modulus reached the segmentation node, and frames perceived before carry the old one)."""
        if self.since_s is not None:
            self.since_s = max(self.since_s, float(stamp_s))

    def at_observation(self) -> bool:
        return self.since_s is not None

    def frame_is_clear(self, frame_stamp_s: float) -> bool:
        """Was a frame stamped frame_stamp_s taken while the arm rested at the observation pose?"""
        return self.since_s is not None and frame_stamp_s >= self.since_s


class RestWatch:
    """Joint states newer than since_s (monotonic) showing every joint slower than still_radps for hold_s."""

    def __init__(self, still_radps: float, hold_s: float, since_s: float):
        self.still_radps, self.hold_s, self.since_s = still_radps, hold_s, since_s
        self.still_since_s = None
        self.last_speed_radps = None
        self.confirmed = False

    def update(self, last_state) -> None:
        if last_state is None or last_state[1] <= self.since_s or self.confirmed:
            return
        state, wall_s = last_state
        self.last_speed_radps = max_joint_speed_radps(state.qd_radps)
        if self.last_speed_radps >= self.still_radps:
            self.still_since_s = None
        elif self.still_since_s is None:
            self.still_since_s = wall_s
        elif wall_s - self.still_since_s >= self.hold_s:
            self.confirmed = True

    def describe(self) -> str:
        if self.last_speed_radps is None:
            return "no joint states arrived after the stop"
        return f"joints still at up to {self.last_speed_radps:.3f} rad/s"
