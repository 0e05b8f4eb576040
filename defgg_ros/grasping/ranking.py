"""The grasp selection policy: which grasps of the network's maps are returned, in which order.

The network (model.inference.GraspPredictor) gives the quality, angle and width maps of a crop; this
policy turns them into ranked grasps: the quality maxima, then fill ranks; with a finger opening, the
grasps whose fingers land beside the objects first (slid, grasping/finger_clearance.py); with
contact_angle, each re-angled for square pad contacts (grasping/contact_angle.py). No two returned
grasps lie within the peak distance of each other.
"""
from __future__ import annotations

import dataclasses
import math

from defgg_ros.grasping.config import PostProcessConfig
from defgg_ros.grasping.contact_angle import square_contact_angle
from defgg_ros.grasping.finger_clearance import clear_centre_shift_px, clear_grasps_first
from defgg_ros.grasping.postprocess import apart, grasps_from_maps

# Peaks considered when grasps whose fingers land beside the objects are ranked first.
CLEARANCE_POOL = 10


def rank_grasps(maps, cfg: PostProcessConfig, depth_crop, mask_crop, fx_px: float, top_k: int, opening_m: float,
                contact_angle: bool) -> tuple:
    """(top_k grasps in crop pixels, fingers-clear flags): the maxima, then fill ranks; with an
    opening, the clear ones first (slid); with contact_angle, squared. No two within the peak
    distance of each other, so a caller asking for alternatives gets distinct grasps."""
    d = cfg.peak_min_distance_px
    check_clearance = opening_m > 0 and mask_crop is not None
    allowed = None if mask_crop is None else mask_crop > 0
    grasps = grasps_from_maps(maps, cfg, allowed, max(top_k, CLEARANCE_POOL) if check_clearance else top_k)
    n_maxima = len(grasps)
    clear = [None] * n_maxima
    if check_clearance:
        grasps, clear = clear_grasps_first(grasps, depth_crop, mask_crop, opening_m, fx_px, needed=top_k,
                                           apart_px=d)
    square = check_clearance and contact_angle
    # Squaring may slide a grasp onto a better one: keep reserves to replace it (top_k > 1 only).
    wanted = top_k + CLEARANCE_POOL if square and top_k > 1 else top_k
    if len(grasps) < wanted:
        extra = _more_ranks(maps, cfg, allowed, n_maxima, grasps, wanted)
        grasps, clear = grasps + extra, clear + [None] * len(extra)
    if not square:
        return grasps[:top_k], clear[:top_k]
    out = []
    for g, c in zip(grasps, clear):     # ~1 ms each (bench/bench_finger_clearance.py)
        sg, sc = _square_contacts(g, c, depth_crop, mask_crop, opening_m, fx_px)
        if apart(sg, [o[0] for o in out], d):
            out.append((sg, sc))
        if len(out) == top_k:
            break
    for g, c in zip(grasps, clear):     # too few distinct squared ones: the rest as they are
        if len(out) < top_k and apart(g, [o[0] for o in out], d):
            out.append((g, c))
    return [o[0] for o in out], [o[1] for o in out]


def _more_ranks(maps, config: PostProcessConfig, allowed, n_maxima: int, grasps: list, wanted: int) -> list:
    """Ranks after the first n_maxima maxima (those that gave `grasps`): further maxima, then
    find_peaks' fill picks, best first, skipping any within the peak distance of a grasp (the
    clearance slide moves grasps), so no two are near-duplicates."""
    d = config.peak_min_distance_px
    out = []
    for g in grasps_from_maps(maps, config, allowed, wanted + n_maxima, fill=True)[n_maxima:]:
        if len(grasps) + len(out) >= wanted:
            break
        if apart(g, grasps + out, d):
            out.append(g)
    return out


def _square_contacts(g, clear: bool, depth_crop, mask_crop, opening_m: float, fx_px: float) -> tuple:
    """(grasp, fingers clear) after grasping/contact_angle.py, or the input when that would lose clearance."""
    angle, u, v, _score = square_contact_angle(depth_crop, mask_crop, g.center_u_px, g.center_v_px, g.angle_rad,
                                               opening_m, fx_px)
    shift = clear_centre_shift_px(depth_crop, mask_crop, u, v, angle, opening_m, fx_px)
    if shift is None:
        return (g, clear) if clear else (dataclasses.replace(g, angle_rad=angle, center_u_px=u, center_v_px=v), False)
    u, v = int(round(u + shift * math.cos(angle))), int(round(v + shift * math.sin(angle)))
    return dataclasses.replace(g, angle_rad=angle, center_u_px=u, center_v_px=v), True
