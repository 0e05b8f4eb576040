"""Young's modulus from a squeeze: close on the object at a few gentle forces and read the widths.

Pure arithmetic (no ROS, no simulator), below the cores like grip_force.py: the executor and the cell's
benches call it. docs/real_cell.md ("Stiffness by squeezing") says how it maps on a Franka Hand.

Model. A two-finger squeeze compresses the object between two flat pads. Its force-compression slope
k (N/m) is a series of the object and of everything else that yields (finger, contact):

    1 / k = 1 / k_machine + L / (E * A)

with L the object's width along the closing axis (the width at the first squeeze) and A the loaded
cross-section. A pad smaller than the object's face does not load the whole face: the load spreads into
the body, the "2:1" rule of foundation engineering widening the loaded patch by z at depth z. The two pads
press from both sides, so the patch at the mid-plane (depth L/2) is

    A = min(pad_w + L/2, face_w) * min(pad_h + L/2, face_h)

(face_w: the object's extent across the closing axis, face_h: its height). E follows as L / (A (1/k - 1/k_machine)).

Resolution. Widths are read to `width_resolution_m` (the Franka Hand reports its opening to ~0.1 mm; the
simulated cell to ~1 um); a compression that resolution cannot separate from the machine's own compliance
gives a lower bound ("at least this stiff"), never a number: `rigid` is then True when even that lower
bound is above `RIGID_ABOVE_PA`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from defgg_ros.constants import FINGER_DEPTH_M, FINGER_PAD_WIDTH_M

# A lower bound above this counts as "rigid" for the grasp: the paper's soft classes end at 2e6 Pa, the next
# is 2e9 Pa, and no hand resolves more: 70 N over 2e-3 m^2 of a 5 cm object at a 10 um width resolution
# bounds E at ~2e8 Pa, at 0.1 mm at ~2e7 Pa.
RIGID_ABOVE_PA = 5e6
# The uncertainty of the model itself (the loaded area's spread rule, the pad's contact): a factor, one
# standard deviation in log space. Measured in the simulated cell (bench/bench_squeeze_stiffness.py).
MODEL_FACTOR = 1.6


# The squeeze's force schedule: gentle first (a 2e4 Pa foam compresses ~1 mm at 2 N), firmer only while the
# compression is not resolved (needs_firmer): a stiff object does not mind 20 N, a soft one is not crushed.
GENTLE_FORCES_N = (0.5, 1.0, 1.5, 2.0)
FIRM_FORCES_N = (10.0, 20.0)
# Resolved = the compression spans this many width resolutions (a <= 10 % reading error).
RESOLVED_SPANS = 10.0


class SqueezeError(ValueError):
    """Readings the estimate cannot use (fewer than two forces, non-finite, widths growing with force)."""


@dataclass(frozen=True)
class SqueezeReading:
    force_n: float      # squeeze force (each finger presses the object with it)
    width_m: float      # opening once the fingers stopped at that force


@dataclass(frozen=True)
class ModulusEstimate:
    youngs_modulus_pa: float    # the estimate; with `lower_bound` set, only "at least this"
    low_pa: float               # one-sigma band (model factor and width resolution)
    high_pa: float              # math.inf when the compression was not resolved
    stiffness_npm: float        # measured force-compression slope (machine included)
    lower_bound: bool           # the compression was within the width resolution
    rigid: bool                 # stiffer than RIGID_ABOVE_PA for the grasp's purposes

    def describe(self) -> str:
        if self.rigid:
            return f"rigid (E >= {self.low_pa:.1e} Pa; k {self.stiffness_npm:.0f} N/m)"
        if self.lower_bound:
            return f"E >= {self.youngs_modulus_pa:.1e} Pa (compression not resolved; k {self.stiffness_npm:.0f} N/m)"
        return (f"E ~ {self.youngs_modulus_pa:.1e} Pa ({self.low_pa:.1e} .. {self.high_pa:.1e}; "
                f"k {self.stiffness_npm:.0f} N/m)")


def loaded_area_m2(width_m: float, face_width_m: float, face_height_m: float,
                   pad_width_m: float = FINGER_PAD_WIDTH_M, pad_height_m: float = FINGER_DEPTH_M) -> float:
    """Cross-section loaded at the mid-plane (the 2:1 spread of the module doc), clipped to the face."""
    spread = width_m / 2.0
    return min(pad_width_m + spread, face_width_m) * min(pad_height_m + spread, face_height_m)


def squeeze_slope_npm(readings) -> tuple[float, float]:
    """Least-squares slope of force against compression (N/m) and the compression spanned (m)."""
    readings = sorted(readings, key=lambda r: r.force_n)
    if len(readings) < 2:
        raise SqueezeError(f"a squeeze needs readings at two forces at least, got {len(readings)}")
    for r in readings:
        if not (math.isfinite(r.force_n) and math.isfinite(r.width_m)) or r.force_n <= 0 or r.width_m <= 0:
            raise SqueezeError(f"reading {r} is not a positive, finite force and width")
    if readings[-1].force_n - readings[0].force_n <= 0:
        raise SqueezeError("the readings' forces must differ")
    x = [readings[0].width_m - r.width_m for r in readings]     # compression, m
    f = [r.force_n for r in readings]
    mx, mf = sum(x) / len(x), sum(f) / len(f)
    sxx = sum((xi - mx) ** 2 for xi in x)
    span = max(x) - min(x)
    if x[-1] < -1e-9:   # the strongest squeeze left the fingers wider than the first
        raise SqueezeError(f"the opening grew with the force ({[round(r.width_m * 1e3, 3) for r in readings]} mm): "
                           "the object moved or the fingers slipped; squeeze again")
    if sxx <= 0:
        return math.inf, 0.0
    return sum((xi - mx) * (fi - mf) for xi, fi in zip(x, f)) / sxx, span


def needs_firmer(readings, width_resolution_m: float) -> bool:
    """True while the readings' compression is not resolved (RESOLVED_SPANS resolutions): squeeze harder."""
    widths = [r.width_m for r in sorted(readings, key=lambda r: r.force_n)]
    return widths[0] - widths[-1] < RESOLVED_SPANS * width_resolution_m


def estimate_modulus(readings, face_width_m: float, face_height_m: float, machine_stiffness_npm: float = math.inf,
                     width_resolution_m: float = 1e-4, model_factor: float = MODEL_FACTOR) -> ModulusEstimate:
    """The object's Young's modulus from squeeze readings (see the module doc) with its one-sigma band."""
    # A face extent may be math.inf (not known: the pad's spread alone is loaded); the resolution must be finite.
    for name, value in (("face_width_m", face_width_m), ("face_height_m", face_height_m),
                        ("width_resolution_m", width_resolution_m)):
        if not (value > 0 and (math.isfinite(value) or name != "width_resolution_m")):
            raise SqueezeError(f"{name} must be > 0, got {value}")
    readings = sorted(readings, key=lambda r: r.force_n)
    k, span = squeeze_slope_npm(readings)
    width_m = readings[0].width_m
    area = loaded_area_m2(width_m, face_width_m, face_height_m)
    force_span = readings[-1].force_n - readings[0].force_n

    def modulus(compliance_mpn: float) -> float:
        return width_m / (area * compliance_mpn) if compliance_mpn > 0 else math.inf

    machine = 1.0 / machine_stiffness_npm if machine_stiffness_npm > 0 else 0.0
    resolved = span > 2.0 * width_resolution_m
    if not resolved:
        # The most compliant object this reading allows: all the unresolved compression its own.
        bound = modulus(max(2.0 * width_resolution_m / force_span - machine, 1e-12))
        return ModulusEstimate(bound, bound, math.inf, k, True, bound >= RIGID_ABOVE_PA)
    e = modulus(1.0 / k - machine)
    if not math.isfinite(e):
        bound = modulus(max(2.0 * width_resolution_m / force_span, 1e-12))
        return ModulusEstimate(bound, bound, math.inf, k, True, bound >= RIGID_ABOVE_PA)
    rel = width_resolution_m / span     # the compression's relative reading error
    sigma = math.exp(math.hypot(math.log(model_factor), rel))
    return ModulusEstimate(e, e / sigma, e * sigma, k, False, False)
