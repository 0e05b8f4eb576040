"""Young's modulus from a squeeze: close on the object at a few gentle forces and read the widths.

Pure arithmetic (no ROS, no simulator), below the cores like grip_force.py: the executor and the cell's
benches call it. docs/real_cell.md ("Stiffness by squeezing") says how it maps on a Franka Hand.

Model (docs/squeeze.md writes the equations out). Everything that yields is in series: the hand (fingers, pads,
their contact), measured once by squeezing a rigid calibration block (`calibrate_hand`, HandCalibration), and the
object. The object's own compression x(F) (the opening's decrease from the first force, less the hand's) follows
one of two contact laws, chosen by the object's shape where the pads touch it (`contact_radii_m`: None for flat
faces). The curve's exponent (x = C (F^m - F0^m), F ~ x^n, n = 1/m: `fit_contact_exponent`) is fitted and
reported, but does not choose: in the simulated cell flat boxes fitted n = 1.3-2.5 (docs/squeeze.md).

  flat   (m near 1, F proportional to the compression): two flat pads on flat faces,
         x = F L / (E A), A = min(pad_w + L/2, face_w) * min(pad_h + L/2, face_h)
         (L the object's width along the closing axis; A the cross-section loaded at the mid-plane, the pad widened
         by the "2:1" load-spread rule: the patch grows by z at depth z, two pads so z = L/2; clipped to the face);
  hertz  (m = 2/3, F proportional to the compression^1.5): a curved surface against each flat pad (Hertz: a
         sphere of radius R_i on a plane, R_i the surface's radius at contact i, at most L/2), each contact
         approaching by d_i = (9 F^2 / (16 E*^2 R_i))^(1/3), E* = E / (1 - nu^2), so x = d(F) - d(F0) summed
         over the two contacts;
  hertz-line (nearly F proportional to the compression): a surface straight one way over a pad (a cylinder's
         side) touches it along a line (`contact_line_lengths_m` > 0 at that pad): defgg_ros/hertz.py's line law,
         E* fitted over log E* (it sits inside a log);
  section (given a `section` curve): the whole cross-section the pads load, a plane-stress FEM of the perceived
         outline (defgg_ros/section_model.py): what yields behind the contact too (a star prism's arm); E fitted.

Settling. An elastic body's compression grows smoothly with the force: over the gentle forces no curve the fit
allows (F ~ x^0.77 .. x^2.5) makes one interval's compliance (opening lost per newton) more than ~1.7x another's.
A step SETTLE_STEP_RATIO times the other gentle intervals' (or the width resolution's) is the object turning or
settling between the pads, not compression (docs/archive/squeeze_notes.md: rigid star prisms read 7e4-1.5e6
Pa from such a step): `without_settling_step` keeps the longer run of readings on one side of it, and the
estimate says so.

Rigid. An object compliance (1/k less the hand's) within two standard deviations of the calibration's (and of the
width reading's) noise of zero is "rigid": only a lower bound, the softest object that noise could hide, is
given. Without a calibration, a compression the width resolution cannot separate gives the lower bound, `rigid`
when it is above `RIGID_ABOVE_PA`.
"""
from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

from defgg_ros import hertz, section_model
from defgg_ros.constants import FINGER_DEPTH_M, FINGER_PAD_WIDTH_M

# A lower bound above this counts as "rigid" for the grasp: the paper's soft classes end at 2e6 Pa, the next
# is 2e9 Pa, and no hand resolves more: 70 N over 2e-3 m^2 of a 5 cm object at a 10 um width resolution
# bounds E at ~2e8 Pa, at 0.1 mm at ~2e7 Pa.
RIGID_ABOVE_PA = 5e6
# The uncertainty of the model itself (the loaded area's spread rule, the contact radii, the pad's contact): a
# factor, one standard deviation in log space: the rms of ln(estimate / true) over the tuning set's soft squeezes
# read as a number, 0.69 (bench/bench_squeeze_stiffness.py --objects tuning, 2026-11-29; it was 1.6, from the flat
# law's boxes, before Hertz and the perceived radii).
MODEL_FACTOR = 2.0
# Flat pads read the section law when the perceived section fills less than this of the flat law's loaded region
# (section_model.flat_fill): the training boxes fill 0.98-1.00 (the flat law reads them, the section law 2-8x
# high), the training star prism egad_train_08_c5 met on faces 0.74 (flat law 0.16-0.18x); docs/squeeze.md.
FLAT_FILL_MIN = 0.9


# The squeeze's force schedule: gentle first (a 2e4 Pa foam compresses ~1 mm at 2 N), firmer only while the
# compression is not resolved (needs_firmer): a stiff object does not mind 20 N, a soft one is not crushed.
GENTLE_FORCES_N = (0.5, 1.0, 1.5, 2.0)
FIRM_FORCES_N = (10.0, 20.0)
# Resolved = the compression spans this many width resolutions (a <= 10 % reading error).
RESOLVED_SPANS = 10.0
# A gentle interval whose compliance is this many times the other gentle intervals' is a settling step (module
# doc): elastic curves stay within ~1.7x; the stored squeezes' soft readings within 6.8x, the settling steps of
# rigid bodies 25-196x (docs/squeeze.md, "Settling steps").
SETTLE_STEP_RATIO = 10.0


class SqueezeError(ValueError):
    """Readings the estimate cannot use (fewer than two forces, non-finite, widths growing with force)."""


@dataclass(frozen=True)
class SqueezeReading:
    force_n: float      # squeeze force (each finger presses the object with it)
    width_m: float      # opening once the fingers stopped at that force


@dataclass(frozen=True)
class HandCalibration:
    """The hand's own stiffness (fingers, pads, contact), from squeezes of a rigid block: subtracted in series."""
    stiffness_npm: float          # 1 / the mean compliance of the calibration squeezes
    compliance_sd_mpn: float      # their standard deviation (m/N): the calibration's noise
    source: str = ""              # where it came from (block, date, command)

    def __post_init__(self):
        if not (self.stiffness_npm > 0 and self.compliance_sd_mpn >= 0 and math.isfinite(self.compliance_sd_mpn)):
            raise SqueezeError(f"a hand calibration needs a stiffness > 0 and a noise >= 0, got {self.stiffness_npm} "
                               f"N/m, {self.compliance_sd_mpn} m/N")

    @property
    def compliance_mpn(self) -> float:
        return 1.0 / self.stiffness_npm

    def describe(self) -> str:
        return (f"k_hand {self.stiffness_npm:.0f} N/m (compliance {self.compliance_mpn * 1e6:.1f} +- "
                f"{self.compliance_sd_mpn * 1e6:.1f} um/N; {self.source or 'source not given'})")


@dataclass(frozen=True)
class ModulusEstimate:
    youngs_modulus_pa: float    # the estimate; with `lower_bound` set, only "at least this"
    low_pa: float               # one-sigma band (model factor, width resolution, the hand calibration's noise)
    high_pa: float              # math.inf when the compression was not resolved
    stiffness_npm: float        # measured force-compression slope (hand included)
    lower_bound: bool           # the compression was within the width resolution / the calibration's noise
    rigid: bool                 # no compliance of its own that the hand can resolve (see the module doc)
    contact_law: str = "flat"   # "flat", "hertz" (point contacts), "hertz-line" (a line among them) or "section"
    exponent: float = math.nan  # fitted n of F ~ compression^n (1 flat, 1.5 Hertz); nan: not fitted
    settling_step_m: float = 0.0  # a settling step taken out of the readings (module doc); 0.0: none

    def describe(self) -> str:
        settled = f"; a {self.settling_step_m * 1e3:.2f} mm settling step left out" if self.settling_step_m else ""
        if self.rigid:
            return f"rigid (E >= {self.low_pa:.1e} Pa; k {self.stiffness_npm:.0f} N/m{settled})"
        if self.lower_bound:
            return (f"E >= {self.youngs_modulus_pa:.1e} Pa (compression not resolved; k {self.stiffness_npm:.0f} "
                    f"N/m{settled})")
        return (f"E ~ {self.youngs_modulus_pa:.1e} Pa ({self.low_pa:.1e} .. {self.high_pa:.1e}; "
                f"k {self.stiffness_npm:.0f} N/m; {self.contact_law} contact, F ~ x^{self.exponent:.2f}{settled})")


def loaded_area_m2(width_m: float, face_width_m: float, face_height_m: float,
                   pad_width_m: float = FINGER_PAD_WIDTH_M, pad_height_m: float = FINGER_DEPTH_M) -> float:
    """Cross-section loaded at the mid-plane (the 2:1 spread of the module doc), clipped to the face."""
    spread = width_m / 2.0
    return min(pad_width_m + spread, face_width_m) * min(pad_height_m + spread, face_height_m)


def _checked(readings) -> list:
    readings = sorted(readings, key=lambda r: r.force_n)
    if len(readings) < 2:
        raise SqueezeError(f"a squeeze needs readings at two forces at least, got {len(readings)}")
    for r in readings:
        if not (math.isfinite(r.force_n) and math.isfinite(r.width_m)) or r.force_n <= 0 or r.width_m <= 0:
            raise SqueezeError(f"reading {r} is not a positive, finite force and width")
    if any(b.force_n <= a.force_n for a, b in zip(readings, readings[1:])):
        raise SqueezeError(f"the readings' forces must differ, got {[r.force_n for r in readings]} N")
    if readings[0].width_m - readings[-1].width_m < -1e-9:   # the strongest squeeze left the fingers wider
        raise SqueezeError(f"the opening grew with the force ({[round(r.width_m * 1e3, 3) for r in readings]} mm): "
                           "the object moved or the fingers slipped; squeeze again")
    return readings


def squeeze_slope_npm(readings) -> tuple[float, float]:
    """Least-squares slope of force against compression (N/m) and the compression spanned (m)."""
    readings = _checked(readings)
    x = [readings[0].width_m - r.width_m for r in readings]     # compression, m
    f = [r.force_n for r in readings]
    mx, mf = sum(x) / len(x), sum(f) / len(f)
    sxx = sum((xi - mx) ** 2 for xi in x)
    span = max(x) - min(x)
    if sxx <= 0:
        return math.inf, 0.0
    return sum((xi - mx) * (fi - mf) for xi, fi in zip(x, f)) / sxx, span


def calibrate_hand(squeezes, source: str) -> HandCalibration:
    """The hand's stiffness from squeezes (lists of readings) of a rigid block: mean compliance and its spread."""
    compliances = []
    if not squeezes:
        raise SqueezeError("a calibration needs one squeeze of the rigid block at least")
    for readings in squeezes:
        k, _ = squeeze_slope_npm(readings)
        if not (math.isfinite(k) and k > 0):
            raise SqueezeError(f"a calibration squeeze resolved no compliance (k = {k} N/m): a finer width reading "
                               "or firmer forces are needed")
        compliances.append(1.0 / k)
    mean = sum(compliances) / len(compliances)
    sd = math.sqrt(sum((c - mean) ** 2 for c in compliances) / (len(compliances) - 1)) if len(compliances) > 1 else 0.0
    return HandCalibration(1.0 / mean, sd, source)


def object_compression_m(readings, hand: HandCalibration | None) -> list:
    """(force, the object's own compression since the first force) with the hand's share taken out."""
    readings = _checked(readings)
    f0, w0 = readings[0].force_n, readings[0].width_m
    hand_c = hand.compliance_mpn if hand is not None else 0.0
    return [(r.force_n, (w0 - r.width_m) - (r.force_n - f0) * hand_c) for r in readings]


def _power_fit(points, m: float) -> tuple[float, float]:
    """Least squares of x = C (F^m - F0^m) through the first point: (C, residual sum of squares)."""
    f0 = points[0][0]
    u = [f ** m - f0 ** m for f, _ in points]
    suu = sum(ui * ui for ui in u)
    c = sum(ui * x for ui, (_, x) in zip(u, points)) / suu
    return c, sum((x - c * ui) ** 2 for ui, (_, x) in zip(u, points))


def fit_contact_exponent(points) -> float:
    """n of F ~ compression^n (1: flat contact, 1.5: Hertz) fitted to (force, compression) points: x ~ F^(1/n).

    A grid over the exponent m = 1/n of x = C (F^m - F0^m) (the first point's own compression is unknown, so the
    law is fitted to the differences); nan with fewer than three points (two points fit any exponent)."""
    if len(points) < 3:
        return math.nan
    best = min(EXPONENT_GRID_M, key=lambda m: _power_fit(points, m)[1])
    return 1.0 / best


# The fitted x ~ F^m's exponent is searched over 0.4 .. 1.3 (n = 2.5 .. 0.77).
EXPONENT_GRID_M = tuple(0.4 + 0.005 * i for i in range(181))
# Poisson's ratio assumed for E* = E / (1 - nu^2): the cell's material (sim/cell/objects.py MATERIAL); 0.5 (a
# rubber) instead would change E by 18 %, within the model's factor.
ASSUMED_POISSON_RATIO = 0.3


def hertz_modulus_pa(points, first_width_m: float, radii_m: tuple | None = None,
                     poisson_ratio: float = ASSUMED_POISSON_RATIO, line_lengths_m: tuple | None = None) -> float:
    """E from (force, compression) points of a body touching each flat pad on a curved surface (Hertz; module doc).

    radii_m: the surface's radius of curvature at each of the two contacts (a sphere's radius; for unequal principal
    radii their geometric mean; for a line contact the curved direction's), each at most half the body's unloaded
    width; None: half that width at both. line_lengths_m: per contact, > 0 for a line contact that long (the
    surface straight one way over the pad), 0 for a point contact; None: both point contacts (closed form)."""
    c, _ = _power_fit(points, 2.0 / 3.0)   # x = C (F^(2/3) - F0^(2/3)), C = (9/(16 E*^2))^(1/3) sum(R_i^(-1/3))
    if c <= 0:
        return math.inf
    half_width_m = (first_width_m + c * points[0][0] ** (2.0 / 3.0)) / 2.0   # the first force's approach added
    radii_m = tuple(min(r, half_width_m) for r in (radii_m or (half_width_m, half_width_m)))
    if line_lengths_m and any(length > 0 for length in line_lengths_m):
        return hertz.fitted_e_star_pa(points, radii_m, line_lengths_m) * (1.0 - poisson_ratio ** 2)
    shape = sum(r ** (-1.0 / 3.0) for r in radii_m)
    e_star = 0.75 * (shape / c) ** 1.5
    return e_star * (1.0 - poisson_ratio ** 2)


def gentle_step_ratios(readings, width_resolution_m: float) -> list:
    """Per gentle interval (readings sorted by force): its compliance over the other gentle intervals' median (in
    magnitude) or the width resolution's over the shortest interval, whichever is larger; [] with fewer than three
    gentle intervals (a step needs two others to stand out from)."""
    gentle = [r for r in sorted(readings, key=lambda r: r.force_n) if r.force_n <= GENTLE_FORCES_N[-1]]
    if len(gentle) < 4:
        return []
    compliance = [(a.width_m - b.width_m) / (b.force_n - a.force_n) for a, b in zip(gentle, gentle[1:])]
    floor = width_resolution_m / min(b.force_n - a.force_n for a, b in zip(gentle, gentle[1:]))
    others = [[abs(v) for v in compliance[:i] + compliance[i + 1:]] for i in range(len(compliance))]
    return [c / max(statistics.median(o), floor) for c, o in zip(compliance, others)]


def without_settling_step(readings, width_resolution_m: float) -> tuple[list, float]:
    """The readings (sorted by force) with a settling step among the gentle forces taken out (a gentle interval
    whose `gentle_step_ratios` is above SETTLE_STEP_RATIO), and the step (m; 0.0: none, the readings as given). The
    longer run of readings on one side of the step is kept (the later on a tie: the object has settled)."""
    readings = sorted(readings, key=lambda r: r.force_n)
    for i, ratio in enumerate(gentle_step_ratios(readings, width_resolution_m)):
        if ratio > SETTLE_STEP_RATIO:
            before, after = readings[:i + 1], readings[i + 1:]
            return (before if len(before) > len(after) else after), readings[i].width_m - readings[i + 1].width_m
    return readings, 0.0


def needs_firmer(readings, width_resolution_m: float) -> bool:
    """True while the readings' compression (a settling step left out) is not resolved (RESOLVED_SPANS
    resolutions): squeeze harder."""
    readings, _ = without_settling_step(readings, width_resolution_m)
    return readings[0].width_m - readings[-1].width_m < RESOLVED_SPANS * width_resolution_m


def _bound(e_pa: float, k: float, law: str = "flat", exponent: float = math.nan,
           settling_m: float = 0.0) -> ModulusEstimate:
    """A lower bound only; rigid when the bound is above RIGID_ABOVE_PA."""
    return ModulusEstimate(e_pa, e_pa, math.inf, k, True, e_pa >= RIGID_ABOVE_PA, law, exponent, settling_m)


def estimate_modulus(readings, face_width_m: float, face_height_m: float, hand: HandCalibration | None = None,
                     width_resolution_m: float = 1e-4, model_factor: float = MODEL_FACTOR,
                     contact_law: str = "auto", contact_radii_m: tuple | None = None,
                     contact_line_lengths_m: tuple | None = None,
                     section: section_model.SectionCurve | None = None) -> ModulusEstimate:
    """The object's Young's modulus from squeeze readings (see the module doc) with its one-sigma band.

    contact_radii_m: the object's radius of curvature where each pad touches it (from its perceived shape; None:
    flat faces under the pads). contact_law: "auto" (hertz when the contacts are curved, else flat), "flat",
    "hertz" (without radii: half the object's width) or "section" (the section's model whatever the contacts: the
    bench's --section-on-flat-pads). contact_line_lengths_m: per pad, > 0 where the surface is
    straight one way and touches the pad along a line that long (m), 0 for a point contact; None or (): both point
    contacts (the estimate's law is then "hertz-line" when any is a line). The curve's exponent is fitted and
    reported either way; it does not choose the law (docs/squeeze.md: in the simulated cell flat boxes fit
    n = 1.3-2.5). section: the loaded cross-section's curve (section_model.section_curve, from the perceived
    outline: planning/section_outline.py); the law ("section") where a pad touches along a line and on flat pads
    whose section does not fill the flat law's prism (section_may_apply); point contacts keep the point law, flat
    pads on a box the flat law (docs/squeeze.md "The section law")."""
    # A face extent may be math.inf (not known: the pad's spread alone is loaded); the resolution must be finite.
    for name, value in (("face_width_m", face_width_m), ("face_height_m", face_height_m),
                        ("width_resolution_m", width_resolution_m)):
        if not (value > 0 and (math.isfinite(value) or name != "width_resolution_m")):
            raise SqueezeError(f"{name} must be > 0, got {value}")
    if contact_law not in ("auto", "flat", "hertz", "section"):
        raise SqueezeError(f"contact_law must be auto, flat, hertz or section, got {contact_law!r}")
    if contact_law == "section" and section is None:
        raise SqueezeError("contact_law section needs the section")
    if contact_radii_m and (len(contact_radii_m) != 2
                            or not all(r > 0 and math.isfinite(r) for r in contact_radii_m)):
        raise SqueezeError(f"contact_radii_m must be the two pads' radii > 0 m, got {contact_radii_m}")
    line_lengths_m = _checked_line_lengths(contact_line_lengths_m, contact_radii_m)
    readings, settling_m = without_settling_step(_checked(readings), width_resolution_m)
    k, span = squeeze_slope_npm(readings)
    if not k > 0 and span > 2.0 * width_resolution_m:   # resolved, but the opening did not close with the force
        raise SqueezeError(f"the opening did not close with the force ({[round(r.width_m * 1e3, 3) for r in readings]}"
                           " mm): the object moved or the fingers slipped; squeeze again")
    width_m = readings[0].width_m
    area = loaded_area_m2(width_m, face_width_m, face_height_m)
    force_span = readings[-1].force_n - readings[0].force_n

    def flat_modulus(compliance_mpn: float) -> float:
        return width_m / (area * compliance_mpn) if compliance_mpn > 0 else math.inf

    hand_c = hand.compliance_mpn if hand is not None else 0.0
    # The object's compliance is within this of zero when it cannot be told from the hand's noise and the reading's
    # (two standard deviations of each, added in quadrature).
    noise_mpn = 2.0 * math.hypot(hand.compliance_sd_mpn if hand is not None else 0.0, width_resolution_m / force_span)
    object_c = (1.0 / k if k > 0 else math.inf) - hand_c
    if span <= 2.0 * width_resolution_m or object_c <= noise_mpn:
        bound = flat_modulus(noise_mpn)   # the most compliant object the noise could hide
        if hand is not None:   # calibrated: within the hand's noise of zero is rigid ("at least bound")
            return ModulusEstimate(bound, bound, math.inf, k, True, True, settling_step_m=settling_m)
        return _bound(bound, k, settling_m=settling_m)
    points = object_compression_m(readings, hand)
    exponent = fit_contact_exponent(points)
    law = contact_law if contact_law != "auto" else ("hertz" if contact_radii_m else "flat")
    if law == "hertz" and line_lengths_m:
        law = "hertz-line"
    if section is not None and (law == "hertz-line" or (law == "flat" and contact_law == "auto"
                                                          and section.flat_fill < FLAT_FILL_MIN)):
        law = "section"     # a pad along a line, or flat pads on a body the flat law's prism does not describe
    if law == "section":
        e = section_model.fit_modulus_pa(points, section)
    else:
        e = (hertz_modulus_pa(points, width_m, contact_radii_m, line_lengths_m=line_lengths_m) if law != "flat"
             else flat_modulus(object_c))
    if not math.isfinite(e):
        return _bound(flat_modulus(noise_mpn), k, law, exponent, settling_m)
    rel = width_resolution_m / span     # the compression's relative reading error
    sigma = math.exp(math.hypot(math.log(model_factor), rel, calibration_sd_log(hand, object_c, law)))
    return ModulusEstimate(e, e / sigma, e * sigma, k, False, False, law, exponent, settling_m)


def section_may_apply(contact_radii_m, contact_line_lengths_m) -> bool:
    """Whether a squeeze with a section may read it with the section law: where a pad touches along a line (an
    edge, a prism's side: what yields behind it, a star prism's arm, matters), and on flat pads when the section
    does not fill the flat law's prism (SectionCurve.flat_fill < FLAT_FILL_MIN). Two point contacts keep Hertz's
    point law: on the training shapes the section law read round bodies lower as E grew (a sphere 0.98x at 2e4 Pa,
    0.45x at 2e5), the point law did not (1.42x, 1.38x); docs/squeeze.md "The section law"."""
    return not contact_radii_m or any(v > 0 for v in (contact_line_lengths_m or ()))


def _checked_line_lengths(line_lengths_m, radii_m) -> tuple:
    """() (all point contacts) or the two per-pad line lengths, with a line among them; SqueezeError otherwise."""
    lengths = tuple(float(v) for v in (line_lengths_m or ()))
    if not lengths:
        return ()
    if len(lengths) != 2 or not all(math.isfinite(v) and v >= 0 for v in lengths):
        raise SqueezeError(f"contact_line_lengths_m must be two lengths >= 0 m (0: a point contact), got {lengths}")
    if not radii_m or len(radii_m) != 2:
        raise SqueezeError("contact_line_lengths_m needs the two pads' contact_radii_m")
    return lengths if any(v > 0 for v in lengths) else ()


def calibration_sd_log(hand: HandCalibration | None, object_compliance_mpn: float, law: str) -> float:
    """The estimate's spread (log space, one sd) from the hand's calibration noise: the object's compliance is
    what is left after the hand's is taken out, so its relative error is s_hand / c_object, and E goes as
    c_object^-1 (flat; a line contact nearly so, its log aside) or C^-3/2 (point Hertz, C the fit's compliance
    scale). Near the rigid limit (c_object = 2 s_hand) this dominates the band: an object barely softer than the
    hand reads with a wide one."""
    if hand is None or hand.compliance_sd_mpn == 0.0:
        return 0.0
    return (1.5 if law == "hertz" else 1.0) * hand.compliance_sd_mpn / object_compliance_mpn
