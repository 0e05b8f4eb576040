"""The object's radius of curvature where each finger pad touches it (issue 49 item 4; no rclpy).

The squeeze's Hertz law (defgg_ros/squeeze.py, docs/squeeze.md) needs, per pad, the radius of the sphere that
stands for the object's surface at the contact: the geometric mean sqrt(R_h R_v) of the surface's two principal
radii (R_h across the closing direction, R_v vertical), each at most half the body's width (a straight direction
spreads the contact as far as the body lets it). A pad whose footprint the surface stays within FLAT_RECESSION_M
of is on a flat face; both flat: no radii, the flat law. A pad whose surface is straight one way (its sag that way
within FLAT_RECESSION_M) and curved the other touches it along a line (a cylinder's side, a lying bone's shaft):
its radius is then the curved direction's, and its line length how far the surface runs under the pad the straight
way (`PadContacts.line_lengths_m`; the squeeze's line law, defgg_ros/hertz.py). Same threshold, no new one.

Two sources of the surface, one convention:
- `surface_pad_contact`: reach samples of the true surface over the pad's footprint (the squeeze bench ray-casts
  the object's mesh along the closing axis): d(y, z) = (y - y*)^2 / (2 R_h) + (z - z*)^2 / (2 R_v) fitted by
  least squares about the most advanced sample (y*, z*); flat when every sample is within FLAT_RECESSION_M.
- `perceived_pad_contacts`: what the cell perceives, the height map of planning (perception/tabletop.py;
  CELL_M ~1 mm cells). At a height z the object's cells standing at least z high are its outline there, seen
  from above; the pad's reach along the closing line is where that outline ends (the occupancy interpolated
  bilinearly between cell centres, its 0.5 crossing: to a fraction of a cell on a slanted or curved edge, to the
  cell's boundary on a straight one aligned with the grid). Per pad:
  R_h from the outline at the pad's lowest height against the offset y across the closing line (a quadratic
  least squares: its linear term is a face turned against the pad, not curvature);
  R_v from the reach against height: a camera above sees no surface under the widest point, so the outline
  stays as wide as that point below it; the recession d(z) = max(0, z - z0)^2 / (2 R_v) is fitted with the
  widest point's height z0 free (a straight side, a box's face or a standing cylinder's: no recession, R_v
  infinite, capped at half the width);
  flat when the fitted recession over the pad's footprint is within FLAT_RECESSION_M (the fit, not the samples:
  a face turned half a cell against the grid steps by a cell; the sag across less SAG_SIGMAS standard errors of
  its fit: the cell steps alone fit up to ~0.5 mm).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from defgg_ros.constants import FINGER_DEPTH_M, FINGER_PAD_WIDTH_M, GRIPPER_MAX_WIDTH_M
from defgg_ros.perception.tabletop import CELL_M

# A pad lies on a flat face when the surface under its whole footprint is within this of its most advanced point.
FLAT_RECESSION_M = 5e-4
# The perceived outline: offsets across the closing line over the pad's width, heights over the pad's length
# (from the fingertips up), and the step of the search along the closing line (a quarter cell).
ACROSS_SAMPLES = 11
HEIGHT_SAMPLES = 10
ALONG_STEP_M = CELL_M / 4
# The search along the closing line for the outline's end: from this far inside the grasp's extent's end to
# MARGIN_OUT_M outside it (the extent is the widest run over the pad's band; a reach further in than SEARCH_IN_M is
# a 5 mm radius at most: the cap takes over there anyway).
SEARCH_IN_M = 0.012
MARGIN_OUT_M = 0.004
# The occupancy's smoothing before its 0.5 contour is read (Gaussian sigma, cells), and the margin of the window
# it is smoothed over (cells).
OUTLINE_BLUR_CELLS = 1.0
WINDOW_PAD_CELLS = 4
# The outline's sag across the pad counts towards "curved" only beyond this many standard errors of its fit.
SAG_SIGMAS = 2.0


def contact_radius_m(r_h_m: float, r_v_m: float, half_width_m: float) -> float:
    """The sphere standing for a contact of principal radii r_h, r_v (inf or <= 0: straight): sqrt(R_h R_v), each
    at most half the body's width."""
    def capped(r):
        return min(r, half_width_m) if (r > 0 and math.isfinite(r)) else half_width_m
    return float(math.sqrt(capped(r_h_m) * capped(r_v_m)))


@dataclass(frozen=True)
class PadContacts:
    """Per pad, the pad on the -closing side first: the contact radius (m; () flat faces: the flat law) and the
    line length (m; 0 a point contact; () when no pad is a line contact)."""
    radii_m: tuple = ()
    line_lengths_m: tuple = ()


def pad_contact(r_h_m: float, r_v_m: float, sag_h_m: float, sag_v_m: float, half_width_m: float,
                run_h_m: float, run_v_m: float) -> tuple[float, float]:
    """(radius, line length) of one pad that is not flat: a point contact (the sphere of contact_radius_m, length
    0) unless the surface is straight one way (its sag within FLAT_RECESSION_M) and curved the other: then the
    curved way's radius (at most half the width) and the run of the surface under the pad the straight way."""
    straight_h, straight_v = sag_h_m <= FLAT_RECESSION_M, sag_v_m <= FLAT_RECESSION_M
    if straight_h == straight_v:
        return contact_radius_m(r_h_m, r_v_m, half_width_m), 0.0
    curved_r = r_v_m if straight_h else r_h_m
    return contact_radius_m(curved_r, curved_r, half_width_m), (run_h_m if straight_h else run_v_m)


def _run_m(coordinates_m: np.ndarray, present: np.ndarray, pad_extent_m: float) -> float:
    """How far the surface runs under the pad along one way: the span of the samples that found it plus one
    sample spacing (each sample stands for its spacing), at most the pad's extent."""
    found = np.asarray(coordinates_m, float)[np.asarray(present, bool)]
    if found.size == 0:
        return 0.0
    spacing = pad_extent_m / max(np.asarray(coordinates_m).size - 1, 1)
    return float(min(found.max() - found.min() + spacing, pad_extent_m))


def _radius_of_curvature(coefficient: float) -> float:
    """R of a recession d = coefficient * s^2 (coefficient = 1 / (2 R)); inf when it does not recede."""
    return 1.0 / (2.0 * coefficient) if coefficient > 0 else math.inf


def surface_pad_contact(dy_m, dz_m, reach_m, half_width_m: float) -> tuple[float, float, bool]:
    """(contact radius, line length, flat) of one pad from reach samples of the true surface over its footprint.

    dy_m, dz_m: the samples' offsets across the closing line and in height; reach_m: how far the surface reaches
    towards the pad at each (nan: the line missed the body). The fit of the module doc; flat when every sample
    hit and all lie within FLAT_RECESSION_M of the most advanced one; a line contact (pad_contact) when the
    fitted sag over the hit samples is within it one way only."""
    dy_m, dz_m, reach_m = (np.asarray(a, float).ravel() for a in (dy_m, dz_m, reach_m))
    hit = np.isfinite(reach_m)
    best = int(np.argmax(np.where(hit, reach_m, -np.inf)))
    d = reach_m[best] - reach_m[hit]
    dy, dz = dy_m[hit] - dy_m[best], dz_m[hit] - dz_m[best]
    (a, b), *_ = np.linalg.lstsq(np.column_stack([dy ** 2, dz ** 2]), d, rcond=None)
    flat = bool(hit.all() and d.max() <= FLAT_RECESSION_M)
    runs = [_run_m(np.unique(v), np.isin(np.unique(v), v[hit]), float(np.ptp(v))) for v in (dy_m, dz_m)]
    radius, line_m = pad_contact(_radius_of_curvature(a), _radius_of_curvature(b), max(a, 0.0) * float(np.max(dy ** 2)),
                                 max(b, 0.0) * float(np.max(dz ** 2)), half_width_m, *runs)
    return radius, line_m, flat


def _bilinear(values: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """values (R x C x Z) read bilinearly at fractional (rows, cols) (N each): N x Z; 0 outside the grid."""
    padded = np.zeros((values.shape[0] + 2, values.shape[1] + 2, values.shape[2]), values.dtype)
    padded[1:-1, 1:-1] = values
    r = np.clip(rows + 1.0, 0.0, padded.shape[0] - 1.001)
    c = np.clip(cols + 1.0, 0.0, padded.shape[1] - 1.001)
    r0, c0 = r.astype(np.int64), c.astype(np.int64)
    fr, fc = (r - r0)[:, None], (c - c0)[:, None]
    return ((1 - fr) * ((1 - fc) * padded[r0, c0] + fc * padded[r0, c0 + 1])
            + fr * ((1 - fc) * padded[r0 + 1, c0] + fc * padded[r0 + 1, c0 + 1]))


def _reach_m(occupancy: np.ndarray, along_m: np.ndarray) -> np.ndarray:
    """Per line (... x S occupancy samples at along_m, increasing away from the grasp centre): where the
    occupancy falls through 0.5 the first time (linear between samples); nan when the first sample is already
    below (the line starts off the object), the last sample's distance when it never falls."""
    inside = occupancy >= 0.5
    out = ~inside
    first_out = np.argmax(out, axis=-1)
    never = ~out.any(axis=-1)
    k = np.clip(first_out, 1, along_m.size - 1)
    before = np.take_along_axis(occupancy, (k - 1)[..., None], -1)[..., 0]
    after = np.take_along_axis(occupancy, k[..., None], -1)[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.clip((before - 0.5) / (before - after), 0.0, 1.0)
    reach = along_m[k - 1] + share * (along_m[k] - along_m[k - 1])
    reach = np.where(never, along_m[-1], reach)
    return np.where((first_out == 0) & ~never, np.nan, reach)


def _quadratic_radius(s_m: np.ndarray, reach_m: np.ndarray, footprint_m: float) -> tuple[float, float]:
    """(R, the fitted sag over the footprint's half width) of reach = c0 + c1 s + c2 s^2 (c2 < 0: receding; c1: a
    face turned against the pad, not curvature). The sag is taken SAG_SIGMAS standard errors towards zero: the
    outline's cell steps alone fit a sag of up to ~0.5 mm on a box's face (a face at 0.4 rad to the grid)."""
    ok = np.isfinite(reach_m)
    if ok.sum() < 6:     # polyfit's covariance needs more points than the order + 2
        return math.nan, math.nan
    (c2, _, _), cov = np.polyfit(s_m[ok], reach_m[ok], 2, cov=True)
    if c2 >= 0:
        return math.inf, 0.0
    half_sq = (footprint_m / 2) ** 2
    return _radius_of_curvature(-c2), float(max(-c2 - SAG_SIGMAS * math.sqrt(max(cov[0, 0], 0.0)), 0.0) * half_sq)


def _vertical_radius(z_m: np.ndarray, reach_m: np.ndarray) -> tuple[float, float]:
    """(R_v, the fitted recession at the pad's top) of d(z) = max(0, z - z0)^2 / (2 R_v), d the reach's drop below
    the lowest sample's, z0 free over the sample heights (least squares); the recession taken SAG_SIGMAS standard
    errors of the fit towards zero, as across."""
    ok = np.isfinite(reach_m)
    if ok.sum() < 3:
        return math.inf, 0.0
    z, d = z_m[ok], reach_m[ok][0] - reach_m[ok]
    u = np.maximum(z[None, :] - z[:-1, None], 0.0) ** 2          # one row per z0 (every sample height but the top)
    uu = np.einsum("ij,ij->i", u, u)
    a = u @ d / uu
    residual = np.sum((d[None, :] - a[:, None] * u) ** 2, axis=1)
    residual = np.where(a > 0, residual, np.inf)
    best = int(np.argmin(residual))
    if not residual[best] < float(np.sum(d ** 2)):     # no recession fits better than none at all
        return math.inf, 0.0
    sd = math.sqrt(residual[best] / max(z.size - 2, 1) / uu[best])
    return _radius_of_curvature(float(a[best])), float(max(a[best] - SAG_SIGMAS * sd, 0.0) * (z_m[-1] - z[best]) ** 2)


def perceived_pad_contacts(grid_height_m: np.ndarray, grid_labels: np.ndarray, label: int, centre_rc,
                           direction_rc, tip_height_m: float, extent_m: float | None = None,
                           pad_width_m: float = FINGER_PAD_WIDTH_M, pad_length_m: float = FINGER_DEPTH_M,
                           details: dict | None = None) -> PadContacts:
    """Per pad, the pad on the -direction side first, the perceived contact radius and line length (PadContacts;
    empty when both pads are on flat faces (the flat law) or the height map shows no outline there: module doc).

    grid_height_m, grid_labels: the view's height map (height above the table, object labels; CELL_M cells);
    label: the grasped object's; centre_rc: the grasp centre in cells (row, col; may be fractional); direction_rc:
    the closing direction in cells (unit, rows then columns); tip_height_m: the fingertips' height above the table
    (the pads reach pad_length_m up from there); extent_m: the object's extent along the closing line (None: the
    outline is searched from the centre out). details: gets per pad (R_h, R_v, flat) and half_width_m when given."""
    centre = np.asarray(centre_rc, float)
    along_dir = np.asarray(direction_rc, float)
    along_dir = along_dir / np.linalg.norm(along_dir)
    across_dir = np.array([-along_dir[1], along_dir[0]])
    ys = np.linspace(-pad_width_m / 2, pad_width_m / 2, ACROSS_SAMPLES)
    zs = tip_height_m + np.linspace(0.0, pad_length_m, HEIGHT_SAMPLES)
    if extent_m is None:
        along = np.arange(0.0, GRIPPER_MAX_WIDTH_M / 2 + MARGIN_OUT_M, ALONG_STEP_M)
    else:
        along = np.arange(max(extent_m / 2 - SEARCH_IN_M, 0.0), extent_m / 2 + MARGIN_OUT_M, ALONG_STEP_M)
    mine = (grid_labels == label) | (grid_labels == 0)   # unlabelled occupied cells: flanks cut at a crease
    reaches = _pads_reach_m(mine, grid_height_m, centre, along_dir, across_dir, along, ys, zs)
    widest = [reach[:, 0] for reach in reaches]
    if not all(np.isfinite(w).any() for w in widest):
        return PadContacts()
    half_width_m = float(sum(np.nanmax(w) for w in widest)) / 2
    if details is not None:
        details["half_width_m"] = half_width_m
    radii, lines, flat = [], [], []
    for reach in reaches:
        r_h, recession_h = _quadratic_radius(ys, reach[:, 0], pad_width_m)
        if math.isnan(r_h):
            return PadContacts()
        middle = slice(ACROSS_SAMPLES // 4, ACROSS_SAMPLES - ACROSS_SAMPLES // 4)   # the pad's middle half
        middle_reach = _mean_over_finite(reach[middle])
        r_v, recession_v = _vertical_radius(zs, middle_reach)
        pad_flat = recession_h + recession_v <= FLAT_RECESSION_M
        radius, line_m = pad_contact(r_h, r_v, recession_h, recession_v, half_width_m,
                                     _run_m(ys, np.isfinite(reach[:, 0]), pad_width_m),
                                     _run_m(zs, np.isfinite(middle_reach), pad_length_m))
        radii.append(radius)
        lines.append(line_m)
        flat.append(pad_flat)
        if details is not None:
            details.setdefault("pads", []).append((r_h, r_v, pad_flat))
    if all(flat):
        return PadContacts()
    return PadContacts(tuple(radii), tuple(lines) if any(v > 0 for v in lines) else ())


def _pads_reach_m(mine, grid_height_m, centre, along_dir, across_dir, along_m, ys_m, zs_m) -> np.ndarray:
    """The outline's reach from the centre (cells) along -along_dir and +along_dir at each offset across (ys) and
    height (zs): 2 x Y x Z, m (nan: no outline there). The occupancy is smoothed (OUTLINE_BLUR_CELLS) before it is
    read: its 0.5 contour is then the cells' outline with the cell steps rounded off, the edge to a fraction of a
    cell. All heights in one pass (one channel each)."""
    sides = np.array([-1.0, 1.0])[:, None, None, None]
    points = centre + (sides * along_m[None, None, :, None] * along_dir
                       + ys_m[None, :, None, None] * across_dir) / CELL_M                  # 2 x Y x S x 2 (cells)
    flat_points = points.reshape(-1, 2)
    lo = np.maximum(np.floor(flat_points.min(axis=0)).astype(int) - WINDOW_PAD_CELLS, 0)
    hi = np.ceil(flat_points.max(axis=0)).astype(int) + WINDOW_PAD_CELLS + 1
    window = (slice(lo[0], hi[0]), slice(lo[1], hi[1]))
    occupied = (mine[window][..., None] & (grid_height_m[window][..., None] >= zs_m[None, None, :]))
    smooth = _blurred(occupied.astype(np.float32))
    values = _bilinear(smooth, flat_points[:, 0] - lo[0], flat_points[:, 1] - lo[1])     # N x Z
    values = values.reshape(*points.shape[:3], zs_m.size)                                # 2 x Y x S x Z
    return _reach_m(np.moveaxis(values, 2, 3), along_m)


def _blurred(occupied: np.ndarray) -> np.ndarray:
    """H x W x Z occupancies, each smoothed by a Gaussian of OUTLINE_BLUR_CELLS (0 beyond the window)."""
    out = np.empty_like(occupied)
    for start in range(0, occupied.shape[2], 4):      # cv2 filters up to 4 channels at a time
        part = np.ascontiguousarray(occupied[..., start:start + 4])
        blurred = cv2.GaussianBlur(part, (0, 0), OUTLINE_BLUR_CELLS, borderType=cv2.BORDER_CONSTANT)
        out[..., start:start + 4] = blurred.reshape(part.shape)
    return out


def _mean_over_finite(values: np.ndarray) -> np.ndarray:
    """Column means over the finite entries (nan where a column has none)."""
    finite = np.isfinite(values)
    count = finite.sum(axis=0)
    total = np.where(finite, values, 0.0).sum(axis=0)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)
