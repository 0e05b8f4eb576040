"""The Franka Hand's move and grasp commands as a small state machine.

Shaped like franka_gripper: `move` drives the fingers to a width and fails
when they are blocked before it; `grasp` closes with a force limit until the
fingers stop and succeeds when they stopped inside [width - epsilon_inner,
width + epsilon_outer]. The machine reads the measured opening each sim step
and says what the finger motors should do; it has no PyBullet in it.
"""
from dataclasses import dataclass, replace

from defgg_ros.constants import GRIPPER_MAX_FORCE_N, GRIPPER_MAX_WIDTH_M
from defgg_ros.sim.finger_press import ContactWindow

# The fingers count as stopped when the opening changes slower than this...
STALL_SPEED_MPS = 0.002
# ...for this long (sim time); shorter windows ended grasps on soft objects
# while they were still being squeezed.
STALL_TIME_S = 0.15
# So "stopped" means the opening stayed within this band for STALL_TIME_S. Measured as a
# displacement over the window, not a per-step speed: at the 0.5 ms step of a 2e4 Pa sponge a
# 1 um contact jitter is already 2 mm/s, and a grasp held still at 48.8 mm timed out (demo, 2026-11-25).
STALL_BAND_M = STALL_SPEED_MPS * STALL_TIME_S
# A move has arrived when the opening is this close to its target.
MOVE_TOLERANCE_M = 0.002
# Franka's gripper rejects speeds above 0.1 m/s (opening rate).
GRIPPER_MAX_SPEED_MPS = 0.1
# Force pressing the fingers along for a `move` (franka_gripper uses its own).
MOVE_FORCE_N = GRIPPER_MAX_FORCE_N
# A grasp presses (MotorCommand.press) once its fingers are on the object (sim.finger_press.on_object, the trial
# hand's rule too). Until then the drive is speed-limited.
# A command that has not finished after this much sim time fails.
GRIPPER_TIMEOUT_S = 5.0


class GripperCommandError(ValueError):
    """A move/grasp goal with an impossible width, speed or force."""


@dataclass(frozen=True)
class GripperOutcome:
    success: bool
    width_m: float
    error: str = ""
    # A grasp that stopped outside its epsilon band: libfranka's grasp() returns false, no exception, so
    # franka_gripper's result carries no error text (the driver sends none; `error` is for the cell's own log).
    outside_band: bool = False


@dataclass(frozen=True)
class MotorCommand:
    finger_target_m: float     # per finger (opening / 2)
    finger_speed_mps: float    # per finger
    finger_force_n: float
    # On the object: each finger pushes with finger_force_n (force control; the cell falls back to the speed
    # drive while a finger closes faster than the hand can: the object is gone). franka_gripper's grasp holds its
    # force, not a speed; a speed-driven finger pressed an FEM body with only ~ its momentum per step
    # (docs/real_cell.md, "Grasp force on FEM objects").
    press: bool = False


def _check(width_m, speed_mps, force_n=None):
    if not 0.0 <= width_m <= GRIPPER_MAX_WIDTH_M + 1e-9:
        raise GripperCommandError(f"width {width_m} m outside [0, {GRIPPER_MAX_WIDTH_M}] m")
    if not 0.0 < speed_mps <= GRIPPER_MAX_SPEED_MPS + 1e-9:
        raise GripperCommandError(f"speed {speed_mps} m/s outside (0, {GRIPPER_MAX_SPEED_MPS}] m/s")
    if force_n is not None and not 0.0 < force_n <= GRIPPER_MAX_FORCE_N + 1e-9:
        raise GripperCommandError(f"force {force_n} N outside (0, {GRIPPER_MAX_FORCE_N}] N")


class GripperController:
    """One active command at a time; a new command pre-empts the old one."""

    def __init__(self, initial_width_m: float):
        self._motor = MotorCommand(initial_width_m / 2, GRIPPER_MAX_SPEED_MPS / 2, MOVE_FORCE_N)
        self._kind = None
        self._goal = None
        self._started_s = 0.0
        self._last_moving_s = 0.0
        self._last_width_m = initial_width_m
        self._anchor_width_m = initial_width_m   # opening when the fingers last moved
        self._contact: ContactWindow | None = None   # the running grasp's: on the object yet? (start_grasp)

    @property
    def motor(self) -> MotorCommand:
        return self._motor

    @property
    def busy(self) -> bool:
        return self._kind is not None

    def start_move(self, width_m: float, speed_mps: float, now_s: float) -> None:
        _check(width_m, speed_mps)
        self._begin("move", (width_m,), now_s)
        self._motor = MotorCommand(width_m / 2, speed_mps / 2, MOVE_FORCE_N)

    def start_grasp(self, width_m: float, eps_inner_m: float, eps_outer_m: float, speed_mps: float,
                    force_n: float, now_s: float) -> None:
        _check(width_m, speed_mps, force_n)
        if eps_inner_m < 0 or eps_outer_m < 0:
            raise GripperCommandError(f"epsilons must be >= 0, got {eps_inner_m}, {eps_outer_m}")
        self._begin("grasp", (width_m, eps_inner_m, eps_outer_m), now_s)
        # Drive towards closed; the force limit is what holds the object.
        self._motor = MotorCommand(0.0, speed_mps / 2, force_n)
        self._contact = ContactWindow(speed_mps / 2)
        self._contact.start(now_s, self._last_width_m)

    def stop(self) -> None:
        """franka_gripper's cancel (Gripper::stop): the running command ends and the fingers hold no force (a
        grasp lets go of its object); they stay where they are unless something pushes them."""
        self._kind = None
        self._contact = None
        self._motor = MotorCommand(self._last_width_m / 2, GRIPPER_MAX_SPEED_MPS / 2, 0.0)

    def _begin(self, kind, goal, now_s):
        self._kind, self._goal = kind, goal
        self._started_s = self._last_moving_s = now_s
        self._anchor_width_m = self._last_width_m

    def _check_contact(self, now_s: float, width_m: float) -> None:
        """A grasp's fingers on the object (finger_press.ContactWindow) press with the grasp's force from then on
        (MotorCommand.press)."""
        if self._kind == "grasp" and not self._motor.press and self._contact.update(now_s, width_m):
            self._motor = replace(self._motor, press=True)

    def update(self, now_s: float, width_m: float) -> GripperOutcome | None:
        """Feed the measured opening; returns the outcome when the command ends."""
        if abs(width_m - self._anchor_width_m) > STALL_BAND_M:
            self._anchor_width_m, self._last_moving_s = width_m, now_s
        self._last_width_m = width_m
        if self._kind is None:
            return None
        self._check_contact(now_s, width_m)
        stalled = now_s - self._last_moving_s >= STALL_TIME_S
        timed_out = now_s - self._started_s >= GRIPPER_TIMEOUT_S
        outcome = self._move_outcome(width_m, stalled) if self._kind == "move" else \
            self._grasp_outcome(width_m, stalled)
        if outcome is None and timed_out:
            outcome = GripperOutcome(False, width_m, f"{self._kind} timed out after {GRIPPER_TIMEOUT_S} s")
        if outcome is not None:
            self._kind = None
        return outcome

    def _move_outcome(self, width_m, stalled):
        (target,) = self._goal
        if abs(width_m - target) <= MOVE_TOLERANCE_M:
            return GripperOutcome(True, width_m)
        if stalled:
            return GripperOutcome(False, width_m, f"fingers blocked at {width_m * 1000:.1f} mm "
                                                  f"before reaching {target * 1000:.1f} mm")
        return None

    def _grasp_outcome(self, width_m, stalled):
        if not stalled:
            return None
        target, eps_in, eps_out = self._goal
        if target - eps_in <= width_m <= target + eps_out:
            return GripperOutcome(True, width_m)
        return GripperOutcome(False, width_m, f"fingers stopped at {width_m * 1000:.1f} mm, outside "
                                              f"[{(target - eps_in) * 1000:.1f}, {(target + eps_out) * 1000:.1f}] mm",
                              outside_band=True)
