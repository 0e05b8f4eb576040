"""Data types of the pick-and-place sequence: configuration, targets, commands, outcome."""
import math
from dataclasses import dataclass, field

import numpy as np

from defgg_ros.constants import FINGER_DEPTH_M, PREGRASP_HEIGHT_M
from defgg_ros.control.gripper_rule import GraspCommand
from defgg_ros.control.trajectories import LIMITS_SAFETY_SCALE, SAMPLE_DT_S, SampledTrajectory
from defgg_ros.squeeze import HandCalibration

# Where the cell's TCP goes down to for a grasp whose point lies on the seen surface:
# "below_surface" = grasp_depth_below_surface_m under that point (one finger pad: the pads overlap the
# top of the object); "half_height" = grasping.geometry.tcp_height_m, the height the simulated
# evaluation grasps at and datasets made with `defgg-datagen --grasp-height executor` are labelled at.
CELL_GRASP_HEIGHT_RULES = ("below_surface", "half_height")

# "squeeze": the stiffness measurement between the descent and the close (a goal with measure_stiffness).
PHASES = ("pre_grasp", "descend", "squeeze", "close", "lift", "transfer", "place", "retreat", "done")
# Feedback phase while the executor brings the arm back after a failure or cancel (not in phase_reached).
RECOVER_PHASE = "recover"

# Where a run left the arm (Outcome.arm_state, PickAndPlace result `arm_state`):
#   observation_pose  at rest at the observation pose (out of the camera's view), holding nothing
#   at_rest           at rest elsewhere (after a success: above the place pose; else where it stopped)
#   moving            did not come to rest within stop_timeout_s of the stop (a failure of its own)
#   unknown           no joint states (driver silent): nobody can tell
#   robot_error       the robot stopped itself and its controller was deactivated (a reflex or another FCI
#                     error): no goal moves it until the recovery (docs/real_cell.md, "After a robot error")
ARM_STATES = ("observation_pose", "at_rest", "moving", "unknown", "robot_error")

@dataclass(frozen=True)
class SequenceConfig:
    table_z_m: float = 0.0
    limits_scale: float = LIMITS_SAFETY_SCALE
    pregrasp_height_m: float = PREGRASP_HEIGHT_M
    # The network's grasp point lies on the visible surface; where the TCP goes below it is the
    # grasp_height_rule (one of CELL_GRASP_HEIGHT_RULES). half_height is the rule the simulated
    # evaluation measured the shipped models with. below_surface: the fingertips go
    # grasp_depth_below_surface_m below the point so the pads overlap the object (never below the
    # table: see GRASP_MIN_HEIGHT_ABOVE_TABLE_M); the cell's rule until 2026-11-26.
    grasp_height_rule: str = "half_height"
    grasp_depth_below_surface_m: float = FINGER_DEPTH_M
    descent_speed_mps: float = 0.03
    line_speed_mps: float = 0.1            # lift, place, retreat
    lift_height_m: float = 0.15
    place_approach_height_m: float = 0.10
    contact_force_threshold_n: float = 10.0
    watchdog_timeout_s: float = 2.0        # wall clock
    arrival_joint_atol_rad: float = 0.02
    settle_timeout_s: float = 3.0          # robot clock, after a trajectory's end
    gripper_timeout_s: float = 10.0        # robot clock
    # Held object: width may not fall below this fraction of the closed width.
    slip_width_fraction: float = 0.5
    sample_dt_s: float = SAMPLE_DT_S
    # The transfer passes this TCP position (base frame) without stopping, so
    # the held object sees a predefined path with real accelerations (the
    # paper's real-robot test); None: straight joint motion to the place.
    transfer_via_position_m: tuple | None = None
    # The transfer and a recovery's carry (both holding the object) are slowed down in time until the TCP
    # accelerates at most this (m/s^2); None: as fast as the joint limits allow.
    transfer_max_tcp_accel_mps2: float | None = 3.0
    # The arm counts as at rest when every joint is slower than still_speed_radps for rest_hold_s
    # (robot clock); a stop waits at most stop_timeout_s after its trajectory ended for that.
    still_speed_radps: float = 0.02
    rest_hold_s: float = 0.1
    stop_timeout_s: float = 3.0
    # After a failure or cancel the arm goes here (joint positions, out of the camera's view): hand
    # opened first if it holds nothing (else the held object is placed first), TCP lifted straight up
    # by observation_lift_m, then a joint motion. None: the arm stays where it stopped.
    observation_q_rad: tuple | None = None
    observation_lift_m: float = 0.12
    # The arm is "at the observation pose" within this joint distance (rad, every joint).
    observation_tolerance_rad: float = 0.05
    # A place target with lower_to_contact (the bin) is lowered into at this TCP speed, guarded by
    # contact_force_threshold_n, down to where the held object's bottom is place_release_clearance_m above the
    # table (the bin's floor); the hand opens where the lowering stopped.
    place_lowering_speed_mps: float = 0.05
    place_release_clearance_m: float = 0.01
    # The release (at the place, or a recovery's put-down) opens the hand this much wider than it closed.
    place_release_opening_m: float = 0.01
    # A recovery holding the object puts it down here (TCP x, y over the table, base frame) the same guarded way,
    # where the arm can pick it again; None: at the goal's place target.
    recovery_drop_xy_m: tuple | None = None

    def validate(self) -> None:
        positive = ("pregrasp_height_m", "descent_speed_mps", "line_speed_mps", "lift_height_m",
                    "place_approach_height_m", "contact_force_threshold_n", "watchdog_timeout_s",
                    "arrival_joint_atol_rad", "settle_timeout_s", "gripper_timeout_s", "sample_dt_s",
                    "still_speed_radps", "rest_hold_s", "stop_timeout_s", "observation_tolerance_rad",
                    "place_lowering_speed_mps", "place_release_opening_m")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if not 0.0 < self.limits_scale <= 1.0:
            raise ValueError(f"limits_scale must be in (0, 1], got {self.limits_scale}")
        cap = self.transfer_max_tcp_accel_mps2
        if cap is not None and not (math.isfinite(cap) and cap > 0):
            raise ValueError(f"transfer_max_tcp_accel_mps2 must be > 0 (or None), got {cap}")
        via = self.transfer_via_position_m
        if via is not None and (len(via) != 3 or not all(math.isfinite(v) for v in via)):
            raise ValueError(f"transfer_via_position_m must be 3 finite numbers, got {via}")
        if not (math.isfinite(self.grasp_depth_below_surface_m) and self.grasp_depth_below_surface_m >= 0):
            raise ValueError(f"grasp_depth_below_surface_m must be >= 0, got {self.grasp_depth_below_surface_m}")
        if self.grasp_height_rule not in CELL_GRASP_HEIGHT_RULES:
            raise ValueError(f"grasp_height_rule must be one of {CELL_GRASP_HEIGHT_RULES}, "
                             f"got {self.grasp_height_rule!r}")
        q_obs = self.observation_q_rad
        if q_obs is not None and (len(q_obs) != 7 or not all(math.isfinite(v) for v in q_obs)):
            raise ValueError(f"observation_q_rad must be 7 finite joint positions, got {q_obs}")
        if not (math.isfinite(self.observation_lift_m) and self.observation_lift_m >= 0):
            raise ValueError(f"observation_lift_m must be >= 0, got {self.observation_lift_m}")
        if not (math.isfinite(self.place_release_clearance_m) and self.place_release_clearance_m >= 0):
            raise ValueError(f"place_release_clearance_m must be >= 0, got {self.place_release_clearance_m}")
        drop = self.recovery_drop_xy_m
        if drop is not None and (len(drop) != 2 or not all(math.isfinite(v) for v in drop)):
            raise ValueError(f"recovery_drop_xy_m must be 2 finite numbers, got {drop}")
        if not 0.0 <= self.slip_width_fraction < 1.0:
            raise ValueError(f"slip_width_fraction must be in [0, 1), got {self.slip_width_fraction}")


@dataclass(frozen=True)
class GraspTarget:
    position_m: tuple          # TCP at the grasp, base frame
    yaw_rad: float             # finger closing direction about the vertical
    width_m: float
    youngs_modulus_pa: float
    finger_force_n: float = 0.0   # the force the grasp carries (its model's label rule); 0: the modulus rule's
    # Per pad (-closing side first) the object's contact radius, m (Grasp.contact_radii_m); (): flat or not known:
    # the squeeze's flat law.
    contact_radii_m: tuple = ()
    # Per pad, in contact_radii_m's order: 0 a point contact, > 0 the length (m) of the line the pad touches where the
    # surface is straight one way (Grasp.contact_line_lengths_m); (): all point contacts.
    contact_line_lengths_m: tuple = ()
    # The section the pads squeeze (Grasp.section_*): its cell (m) and the object's height on it (rows of m, the
    # grasp line the middle row, 0: not the object); (): not perceived (the contact laws).
    section_cell_m: float = 0.0
    section_heights_m: tuple = ()


@dataclass(frozen=True)
class PlaceTarget:
    position_m: tuple          # TCP where the object is released, base frame
    # Closing direction about the vertical at the release. None: the grasp's, so the wrist does not turn
    # on the way; a turn spins an object held with a low grip force between the pads (it pried a 3 N grasp
    # of a 5 cm block open, CHANGELOG 2026-11-27).
    yaw_rad: float | None = 0.0
    # The bin: position_m's z is only the height above which the transfer arrives (plus place_approach_height_m);
    # the lowering goes on down, guarded by the contact force, until the object stands on what is below it
    # (SequenceConfig.place_lowering_speed_mps). False: lowered to position_m and released there (a goal's pose).
    lower_to_contact: bool = False


@dataclass(frozen=True)
class SqueezeRequest:
    """Measure the object's stiffness after the descent (docs/squeeze.md; defgg_ros.control.squeeze_phase)."""

    only: bool = False                 # measure, open, lift back (to the observation pose): no pick
    # The width reading's resolution (m): a compression within it gives a lower bound (squeeze.estimate_modulus).
    width_resolution_m: float = 1e-4
    # The opening is read this long after each squeeze's gripper result (robot clock): the fingers and a soft
    # object settle (the bench reads 0.2 s after the fingers stopped).
    settle_s: float = 0.3
    speed_mps: float = 0.02            # closing speed of each squeeze (franka_gripper's Grasp speed)
    # The hand's own compliance, taken out in series (squeeze.HandCalibration); None: not calibrated.
    hand: HandCalibration | None = None

    def validate(self) -> None:
        for name in ("width_resolution_m", "settle_s", "speed_mps"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"squeeze {name} must be a positive number, got {value}")


@dataclass(frozen=True)
class ArmState:
    q_rad: np.ndarray
    qd_radps: np.ndarray
    gripper_width_m: float
    stamp_s: float = math.nan     # robot time it was measured (the joint state's stamp); NaN: not known


# --- commands for the owner to carry out ------------------------------------
@dataclass(frozen=True)
class SendTrajectory:
    trajectory: SampledTrajectory
    start_s: float | None = None   # robot time its time 0 applies (the goal's header.stamp); None: on receipt


@dataclass(frozen=True)
class MoveGripper:
    width_m: float
    speed_mps: float


@dataclass(frozen=True)
class GraspGripper:
    command: GraspCommand


@dataclass(frozen=True)
class CancelGripper:
    pass


@dataclass(frozen=True)
class Feedback:
    phase: str
    phase_progress: float
    gripper_width_m: float
    external_force_n: float


@dataclass
class Outcome:
    """The PickAndPlace result fields (minus grasp_used, which the owner knows)."""

    success: bool = False
    canceled: bool = False
    failure_reason: str = ""
    phase_reached: str = ""
    contact_detected: bool = False
    contact_height_m: float = float("nan")
    gripper_width_closed_m: float = float("nan")
    gripper_force_n: float = float("nan")
    held_after_lift: bool = False
    held_after_transfer: bool = False
    duration_s: float = 0.0
    # Where the run left the arm (one of ARM_STATES) and, after a failure or cancel, what the
    # recovery did ("" when nothing was needed), for a person to read.
    arm_state: str = "unknown"
    recovery: str = ""


@dataclass
class _Motion:
    trajectory: SampledTrajectory
    start_s: float
    guarded_stop: bool = False   # ends when the arm is still, wherever that is
    stamped_start_s: float | None = None   # the start sent with it (controller's clock); None: on receipt


@dataclass
class _Plan:
    """Everything computed before the arm moves, so unreachable goals fail early."""

    pregrasp_q: np.ndarray
    grasp_M: np.ndarray
    place_approach_q: np.ndarray
    place_M: np.ndarray          # the release pose (lower_to_contact: the lowest the lowering may go)
    gripper: GraspCommand
    place_approach_M: np.ndarray | None = None   # above the place pose, where the transfer ends


class SequenceFailure(Exception):
    """Internal: ends the sequence with a reason."""


@dataclass
class _Pending:
    gripper: bool = False
    gripper_sent_s: float = 0.0
    gripper_result: tuple | None = None


@dataclass
class _Observed:
    state: ArmState | None = None
    state_wall_s: float = -math.inf
    own_stall_s: float = 0.0            # wall time the owner did not tick since that state (not the driver's)
    last_tick_wall_s: float | None = None
    force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    force_bias_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    force_wall_s: float | None = None   # when the last wrench arrived (None: not told, no age kept)
    own_stall_force_s: float = 0.0      # the owner's own stall since that wrench
