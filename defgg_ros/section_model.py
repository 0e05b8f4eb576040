"""The object's cross-section squeezed between the two pads: a plane-stress FEM, per unit Young's modulus.

Pure numpy (no ROS, no simulator), beside squeeze.py which fits E with it (the "section" law, docs/squeeze.md
"The section law"). Hertz's laws see only the surface where each pad touches; a slender part behind the contact
(a star prism's arm, a cluster's lobe) yields too, bending and tapering, and the squeeze reads such objects 2-10x
too soft (docs/archive/squeeze_notes.md, "Shipped meshes"). Here the whole section the pads load is elastic:

- the section: the object's outline at the pads' height, seen from above, on square cells of `cell_m`, rows across
  the closing axis and columns along it (planning/section_outline.py makes it from the height map);
- each cell a bilinear plane-stress element (Poisson's ratio 0.3, the cell's material) whose thickness is the
  object's height there, capped by the load's spread from the pads (the flat law's 2:1 rule: the pad's length
  plus the distance from the nearer pad);
- the pads: rigid and flat, across the closing axis, as wide as a Franka Hand's (20 mm), centred on the section's
  middle row; a pad touching a node holds it (the pads' friction, 1.0, sticks); contact found by an active set
  (a node the pad reaches is added, one the pad would pull is let go).

Linear elasticity: force = E * g(u) for the pads' total approach u, so g is computed once per section (E = 1 Pa)
and the squeeze's readings are fitted by E alone (`fit_modulus_pa`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from defgg_ros import hertz
from defgg_ros.constants import FINGER_DEPTH_M, FINGER_PAD_WIDTH_M

POISSON_RATIO = 0.3
# The pads' total approach at which the curve is computed (m): 0.05 mm to 30 mm, geometric.
APPROACHES_M = tuple(float(v) for v in np.geomspace(5e-5, 0.03, 24))
# The fit's grid over log E (Pa): 40 per decade over 1e1 .. 1e10, then golden-section steps.
FIT_RANGE_PA = (1e1, 1e10)
FIT_GRID_PER_DECADE = 40
FIT_GOLDEN_STEPS = 40
MAX_ACTIVE_SET_ROUNDS = 40


class SectionError(ValueError):
    """A section the model cannot squeeze (empty, nothing under a pad, bad sizes)."""


@dataclass(frozen=True)
class SectionCurve:
    """Force per unit modulus (N/Pa) at each total approach of the pads (m): force = E * force_per_pa; and how much
    of the flat law's loaded region the section fills (`flat_fill`, 0..1: a box 1, a star prism met on a face
    less)."""
    approaches_m: tuple
    force_per_pa: tuple
    flat_fill: float = 1.0


def _element_stiffness(cell_m: float) -> np.ndarray:
    """8x8 stiffness of a square bilinear plane-stress element, E = 1 Pa, unit thickness (2x2 Gauss points)."""
    nu = POISSON_RATIO
    d = np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, (1.0 - nu) / 2.0]]) / (1.0 - nu ** 2)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    k = np.zeros((8, 8))
    g = 1.0 / math.sqrt(3.0)
    for xi in (-g, g):
        for eta in (-g, g):
            dn = np.c_[corners[:, 0] * (1 + eta * corners[:, 1]), corners[:, 1] * (1 + xi * corners[:, 0])] / 4
            dn *= 2.0 / cell_m
            b = np.zeros((3, 8))
            b[0, 0::2], b[1, 1::2] = dn[:, 0], dn[:, 1]
            b[2, 0::2], b[2, 1::2] = dn[:, 1], dn[:, 0]
            k += b.T @ d @ b * (cell_m / 2.0) ** 2
    return k


def _assembled(mask: np.ndarray, thickness_m: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Global stiffness (E = 1 Pa) and node positions (m; x along the closing axis, y across)."""
    rows, cols = np.nonzero(mask)
    corners = np.stack([np.c_[rows + dr, cols + dc] for dr, dc in ((0, 0), (0, 1), (1, 1), (1, 0))], axis=1)
    keys, node_of = np.unique(corners.reshape(-1, 2), axis=0, return_inverse=True)
    node_of = node_of.reshape(-1, 4)
    dofs = np.stack([2 * node_of, 2 * node_of + 1], axis=2).reshape(-1, 8)
    k = np.zeros((2 * len(keys), 2 * len(keys)))
    ke = _element_stiffness(cell_m)
    for element, t in zip(dofs, thickness_m[rows, cols]):
        k[np.ix_(element, element)] += ke * t
    return k, np.c_[keys[:, 1], keys[:, 0]] * cell_m


def section_curve(mask: np.ndarray, height_m: np.ndarray, cell_m: float, pad_width_m: float = FINGER_PAD_WIDTH_M,
                  pad_length_m: float = FINGER_DEPTH_M, approaches_m=APPROACHES_M) -> SectionCurve:
    """The section's force per unit modulus at each approach (module doc). mask: the section's cells (rows across
    the closing axis, columns along it; the pads centred on the middle row); height_m: the object's height at
    each cell (m)."""
    mask = np.asarray(mask, bool)
    height_m = np.asarray(height_m, float)
    if mask.ndim != 2 or height_m.shape != mask.shape or not cell_m > 0:
        raise SectionError(f"a section needs a 2-D mask, heights of its shape and a cell > 0 m (got {mask.shape}, "
                           f"{height_m.shape}, {cell_m})")
    if not mask.any() or not np.all(np.isfinite(height_m[mask])) or (height_m[mask] <= 0).any():
        raise SectionError("the section is empty or has cells without a positive height")
    centre_y = mask.shape[0] * cell_m / 2.0
    band_rows = np.abs((np.arange(mask.shape[0]) + 0.5) * cell_m - centre_y) <= pad_width_m / 2.0
    loaded_cols = np.nonzero(mask[band_rows].any(axis=0))[0]
    if loaded_cols.size < 2:
        raise SectionError("no section under the pads (the middle rows are empty)")
    x_lo, x_hi = loaded_cols.min() * cell_m, (loaded_cols.max() + 1) * cell_m
    x_cells = (np.arange(mask.shape[1]) + 0.5) * cell_m
    depth_m = np.maximum(np.minimum(x_cells - x_lo, x_hi - x_cells), 0.0)    # distance from the nearer pad
    spread_m = pad_length_m + depth_m
    thickness_m = np.minimum(height_m, spread_m[None, :])
    k, xy = _assembled(mask, thickness_m, cell_m)
    under = np.abs(xy[:, 1] - centre_y) <= pad_width_m / 2.0 + 1e-9
    # Only nodes a pad can reach may touch it: under it and within the largest approach (plus a cell) of its side.
    reach_m = max(approaches_m) / 2.0 + cell_m
    candidates = under & ((xy[:, 0] <= x_lo + reach_m) | (xy[:, 0] >= x_hi - reach_m))
    s, xy_c = _condensed(k, candidates), xy[candidates]
    tol = 1e-9
    left, right = xy_c[:, 0] <= x_lo + tol, xy_c[:, 0] >= x_hi - tol
    approaches_m = tuple(sorted(float(u) for u in approaches_m))
    forces = []
    for u in approaches_m:    # the contact grows with the approach: each starts from the last one's
        force, left, right = _pads_force(s, xy_c, x_lo, x_hi, u, left, right)
        forces.append(force)
    y_cells = (np.arange(mask.shape[0]) + 0.5) * cell_m
    return SectionCurve(approaches_m, tuple(forces), flat_fill(mask, y_cells - centre_y, x_cells, x_lo, x_hi,
                                                               pad_width_m + depth_m))


def flat_fill(mask: np.ndarray, y_m: np.ndarray, x_m: np.ndarray, x_lo: float, x_hi: float, width_m: np.ndarray
              ) -> float:
    """The share of the flat law's loaded region that the section fills: between the pads, within the pad's width
    spread by the 2:1 rule (`width_m` at each column) about the grasp line (squeeze.py's flat law assumes a body
    there). y_m: the rows' offsets from the grasp line; x_m: the columns' positions."""
    region = (np.abs(y_m)[:, None] <= width_m[None, :] / 2.0) & ((x_m >= x_lo) & (x_m <= x_hi))[None, :]
    return float((mask & region).sum() / region.sum())


def _condensed(k: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """The stiffness seen at the candidate nodes with every other node free and unloaded (a Schur complement):
    one solve for the whole curve instead of one per approach and contact set."""
    on = np.repeat(candidates, 2)
    c, i = np.nonzero(on)[0], np.nonzero(~on)[0]
    if i.size == 0:
        return k
    return k[np.ix_(c, c)] - k[np.ix_(c, i)] @ np.linalg.solve(k[np.ix_(i, i)], k[np.ix_(i, c)])


def _pads_force(s: np.ndarray, xy: np.ndarray, x_lo: float, x_hi: float, u: float, left: np.ndarray,
                right: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The pads' force (E = 1 Pa) at total approach u, each pad moved u/2 in, the nodes it touches held (starting
    from the touching sets left, right; s, xy: the condensed stiffness and its nodes); and the sets found."""
    tol = 1e-9
    for _ in range(MAX_ACTIVE_SET_ROUNDS):
        disp, reaction = _solved(s, xy, left, right, x_lo + u / 2.0, x_hi - u / 2.0)
        x_now = xy[:, 0] + disp[0::2]
        grow_left = left | (x_now < x_lo + u / 2.0 - tol)
        grow_right = right | (x_now > x_hi - u / 2.0 + tol)
        new_left = grow_left & ~(left & (reaction[0::2] < 0.0))       # a pad pulling on a node lets it go
        new_right = grow_right & ~(right & (reaction[0::2] > 0.0))
        if not new_left.any() or not new_right.any():
            break
        if (new_left == left).all() and (new_right == right).all():
            break
        left, right = new_left, new_right
    return float(reaction[0::2][left].sum()), left, right


def _solved(k, xy, left, right, left_x_m, right_x_m) -> tuple[np.ndarray, np.ndarray]:
    """Displacements with the touching nodes held at the pads (x) and stuck (y), and the reactions."""
    n = len(xy)
    held = np.zeros(2 * n, bool)
    value = np.zeros(2 * n)
    for nodes, pad_x in ((np.nonzero(left)[0], left_x_m), (np.nonzero(right)[0], right_x_m)):
        held[2 * nodes] = held[2 * nodes + 1] = True
        value[2 * nodes] = pad_x - xy[nodes, 0]
    free = ~held
    disp = value.copy()
    if free.any():
        disp[free] = np.linalg.solve(k[np.ix_(free, free)], -k[np.ix_(free, held)] @ value[held])
    return disp, k @ disp


def _approach_m(curve: SectionCurve, force_per_pa: np.ndarray) -> np.ndarray:
    """The approach at which the section carries these forces per unit modulus (nan beyond the curve)."""
    carried = np.maximum.accumulate(np.asarray(curve.force_per_pa, float))    # interp needs it non-decreasing
    return np.interp(force_per_pa, carried, curve.approaches_m, left=0.0, right=np.nan)


def _misfit(points, curve: SectionCurve, log_e: float) -> float:
    forces = np.array([f for f, _ in points]) / math.exp(log_e)
    u = _approach_m(curve, forces)
    if np.isnan(u).any():
        return math.inf
    return float(sum((x - (ui - u[0])) ** 2 for (_, x), ui in zip(points, u)))


def fit_modulus_pa(points, curve: SectionCurve) -> float:
    """E (Pa) whose approaches u(F / E) - u(F0 / E) best fit (force, compression since the first force) points;
    inf when even the stiffest E of FIT_RANGE_PA leaves the curve's range."""
    return hertz.log_grid_minimum(lambda log_e: _misfit(points, curve, log_e), FIT_RANGE_PA, FIT_GRID_PER_DECADE,
                                  FIT_GOLDEN_STEPS)
