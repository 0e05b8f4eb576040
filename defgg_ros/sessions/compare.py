"""Compare a replay with its recording: grasps per frame and pick outcomes, with tolerances.

Works on anything with the Grasp / PickAndPlace_Result field names (rosbags
dataclasses from the bag, rclpy messages from the live graph). No rclpy.
"""
import math
from dataclasses import dataclass

# Defaults: about 3 px of the 640x480 camera at 0.4 m (1 px ~ 1 mm), a few
# degrees, and 3 mm of opening — far below what a changed model or a wrong
# calibration moves, above CPU-to-CPU float differences.
DEFAULT_POSITION_TOL_MM = 3.0
DEFAULT_ANGLE_TOL_DEG = 5.0
DEFAULT_WIDTH_TOL_MM = 3.0
# The grip a grasp carries (estimated mass, the labels' finger force): a grasp within the tolerances above
# sees nearly the same cells, so its object's volume moves by a few per cent at most.
GRIP_TOL_REL = 0.1


@dataclass(frozen=True)
class Tolerances:
    position_mm: float = DEFAULT_POSITION_TOL_MM
    angle_deg: float = DEFAULT_ANGLE_TOL_DEG
    width_mm: float = DEFAULT_WIDTH_TOL_MM

    def __post_init__(self):
        for name in ("position_mm", "angle_deg", "width_mm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"tolerance {name} must be a finite number >= 0, got {value!r}")


@dataclass(frozen=True)
class GraspSummary:
    position_base_m: tuple
    angle_rad: float
    width_m: float
    quality: float
    center_px: tuple
    # (estimated_mass_kg, finger_force_n); None for a grasp recorded before the Grasp had them
    grip: tuple | None = None

    @classmethod
    def of(cls, grasp) -> "GraspSummary":
        p = grasp.pose_base.pose.position
        grip = (float(grasp.estimated_mass_kg), float(grasp.finger_force_n)) \
            if hasattr(grasp, "estimated_mass_kg") else None
        return cls((p.x, p.y, p.z), float(grasp.angle_rad), float(grasp.width_m), float(grasp.quality),
                   (float(grasp.center_u_px), float(grasp.center_v_px)), grip)

    def brief(self) -> str:
        x, y, z = (1000 * v for v in self.position_base_m)
        return (f"({x:.0f},{y:.0f},{z:.0f})mm {math.degrees(self.angle_rad):+.0f}deg "
                f"w{1000 * self.width_m:.0f}mm q{self.quality:.2f}")


@dataclass(frozen=True)
class GraspDiff:
    position_mm: float
    angle_deg: float
    width_mm: float


def angle_difference_rad(a: float, b: float) -> float:
    """|a - b| for grasp angles, which are the same grasp modulo pi (the fingers are symmetric)."""
    d = (a - b) % math.pi
    return min(d, math.pi - d)


def grasp_diff(expected: GraspSummary, actual: GraspSummary) -> GraspDiff:
    return GraspDiff(1000 * math.dist(expected.position_base_m, actual.position_base_m),
                     math.degrees(angle_difference_rad(expected.angle_rad, actual.angle_rad)),
                     1000 * abs(expected.width_m - actual.width_m))


def grasp_problems(expected: GraspSummary | None, actual: GraspSummary | None, tol: Tolerances) -> list[str]:
    """What changed between two grasps, beyond the tolerances (empty: the same grasp)."""
    if expected is None and actual is None:
        return []
    if expected is None:
        return [f"a grasp appeared ({actual.brief()}) where the recording had none"]
    if actual is None:
        return [f"no grasp (recorded {expected.brief()})"]
    d = grasp_diff(expected, actual)
    problems = []
    if d.position_mm > tol.position_mm:
        problems.append(f"position moved {d.position_mm:.1f} mm (> {tol.position_mm:g} mm)")
    if d.angle_deg > tol.angle_deg:
        problems.append(f"angle changed {d.angle_deg:.1f} deg (> {tol.angle_deg:g} deg)")
    if d.width_mm > tol.width_mm:
        problems.append(f"width changed {d.width_mm:.1f} mm (> {tol.width_mm:g} mm)")
    return problems + grip_problems(expected.grip, actual.grip)


def grip_problems(expected: tuple | None, actual: tuple | None) -> list[str]:
    """Estimated mass and finger force beyond GRIP_TOL_REL of the recording (nothing to compare when the
    recording predates them)."""
    if expected is None or actual is None:
        return []
    problems = []
    for name, unit, scale, e, a in zip(("estimated mass", "finger force"), ("g", "N"), (1000.0, 1.0),
                                       expected, actual):
        if abs(a - e) > GRIP_TOL_REL * max(abs(e), abs(a)):
            problems.append(f"{name} changed {scale * e:.3g} -> {scale * a:.3g} {unit} (> {100 * GRIP_TOL_REL:g} %)")
    return problems


@dataclass(frozen=True)
class PickOutcome:
    success: bool
    phase_reached: str
    held_after_transfer: bool
    failure_reason: str

    @classmethod
    def of(cls, result) -> "PickOutcome":
        return cls(bool(result.success), str(result.phase_reached), bool(result.held_after_transfer),
                   str(result.failure_reason))

    def brief(self) -> str:
        text = f"{'success' if self.success else 'FAILED'} at {self.phase_reached or '-'}"
        return text + f", held {'yes' if self.held_after_transfer else 'no'}"


def pick_problems(expected: PickOutcome | None, actual: PickOutcome | None) -> list[str]:
    """The pick outcome must match: success and held after transfer (and the phase of a successful pick).

    Where a *failed* pick stopped is shown but not compared: with a marginal grasp it varies from run
    to run (the same replay, 3 runs: fingers stopped outside the width window at `close`, or closed and
    slipped out at `lift`), while failed-vs-succeeded does not.
    """
    if expected is None:
        return [] if actual is None else ["a pick result appeared where the recording had none"]
    if actual is None:
        return [f"no pick result (recorded {expected.brief()})"]
    problems = []
    if expected.success != actual.success:
        problems.append(f"pick {'succeeded' if actual.success else 'failed'} but the recording "
                        f"{'succeeded' if expected.success else 'failed'}"
                        + (f": {actual.failure_reason}" if actual.failure_reason else ""))
    if expected.success and actual.success and expected.phase_reached != actual.phase_reached:
        problems.append(f"phase reached {actual.phase_reached!r}, recorded {expected.phase_reached!r}")
    if expected.held_after_transfer != actual.held_after_transfer:
        problems.append(f"held after transfer {actual.held_after_transfer}, recorded {expected.held_after_transfer}")
    return problems
