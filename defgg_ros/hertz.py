"""Hertz contact approaches of a curved body pressed on a flat rigid pad: point and line contacts (no rclpy).

The squeeze (defgg_ros/squeeze.py, docs/squeeze.md) reads how far the opening closes as the force grows; each pad's
contact approaches by d(F), and the body's modulus is the E* whose summed approaches fit the readings.

- **Point contact** (the surface curved both ways; a sphere of radius R standing for it):
      d(F) = (9 F^2 / (16 E*^2 R))^(1/3)
- **Line contact** (the surface straight one way over the pad, curved the other with radius R: a cylinder's side,
  a lying bone's shaft) along a length l: with the load per length P = F / l and the contact's half-width
  b = sqrt(4 P R / (pi E*)), each contact of a cylinder between two plates approaches by
      d(F) = P / (pi E*) * (2 ln(4 R / b) - 1)
  (two equal contacts sum to the classical diametral compression of a cylinder between plates,
  2 P / (pi E*) (2 ln(4 R / b) - 1); Johnson, Contact Mechanics, 1985, section 5.6). The approach is nearly
  linear in F (the log grows slowly), where the point law goes as F^(2/3): a line contact read with the point
  law comes out several times too stiff (docs/archive/squeeze_notes.md: 4-13x on the standing cylinder and
  the toy bone).

E* = E / (1 - nu^2). The line law has E* inside the log, so E* is found by a one-dimensional least squares over
log E* (a grid, then a golden-section refinement), not in closed form.
"""
from __future__ import annotations

import math

# The search range of E* (Pa): below any foam, above any hand's resolution (squeeze.RIGID_ABOVE_PA is 5e6).
E_STAR_RANGE_PA = (1e1, 1e12)
GRID_PER_DECADE = 40
GOLDEN_STEPS = 60


def point_approach_m(force_n: float, e_star_pa: float, radius_m: float) -> float:
    """A sphere of radius R on a rigid plane: d = (9 F^2 / (16 E*^2 R))^(1/3)."""
    return (9.0 * force_n ** 2 / (16.0 * e_star_pa ** 2 * radius_m)) ** (1.0 / 3.0)


def line_approach_m(force_n: float, e_star_pa: float, radius_m: float, length_m: float) -> float:
    """A cylinder of radius R touching a rigid plane along length l (one of the two contacts between plates):
    P / (pi E*) (2 ln(4 R / b) - 1), b the contact's half-width; 0 where the log term would go negative (a contact
    as wide as the body: beyond the law)."""
    load_npm = force_n / length_m
    half_width_m = math.sqrt(4.0 * load_npm * radius_m / (math.pi * e_star_pa))
    return load_npm / (math.pi * e_star_pa) * max(2.0 * math.log(4.0 * radius_m / half_width_m) - 1.0, 0.0)


def contacts_approach_m(force_n: float, e_star_pa: float, radii_m, line_lengths_m) -> float:
    """The two contacts' approaches summed: a line contact where its length is > 0, a point contact where 0."""
    return sum(line_approach_m(force_n, e_star_pa, r, length) if length > 0 else
               point_approach_m(force_n, e_star_pa, r) for r, length in zip(radii_m, line_lengths_m))


def _residual(points, log_e_star: float, radii_m, line_lengths_m) -> float:
    """Squared misfit of the compressions since the first force (its own compression is unknown)."""
    e_star = math.exp(log_e_star)
    f0 = points[0][0]
    d0 = contacts_approach_m(f0, e_star, radii_m, line_lengths_m)
    return sum((x - (contacts_approach_m(f, e_star, radii_m, line_lengths_m) - d0)) ** 2 for f, x in points)


def fitted_e_star_pa(points, radii_m, line_lengths_m) -> float:
    """E* (Pa) whose summed contact approaches best fit (force, compression since the first force) points: a grid
    over log E* (GRID_PER_DECADE per decade over E_STAR_RANGE_PA), then golden-section steps around its best."""
    return log_grid_minimum(lambda log_e_star: _residual(points, log_e_star, radii_m, line_lengths_m),
                            E_STAR_RANGE_PA, GRID_PER_DECADE, GOLDEN_STEPS)


def log_grid_minimum(misfit, range_pa: tuple, per_decade: int, golden_steps: int) -> float:
    """The value (Pa) in range_pa whose log minimises misfit(log value): a grid of per_decade points per decade,
    then golden-section steps between the best point's neighbours (one new misfit per step). inf when the misfit
    is infinite everywhere on the grid (nothing fits)."""
    lo, hi = (math.log(v) for v in range_pa)
    n = int(round((hi - lo) / math.log(10.0) * per_decade))
    grid = [lo + (hi - lo) * i / n for i in range(n + 1)]
    misfits = [misfit(g) for g in grid]
    best = min(range(n + 1), key=misfits.__getitem__)
    if not math.isfinite(misfits[best]):
        return math.inf
    a, b = grid[max(best - 1, 0)], grid[min(best + 1, n)]
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = misfit(c), misfit(d)
    for _ in range(golden_steps):    # each step keeps one of the two inner points: one new misfit per step
        if fc <= fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = misfit(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = misfit(d)
    return math.exp((a + b) / 2.0)
