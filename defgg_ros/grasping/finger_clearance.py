"""Would a finger land on an object? A top-down grasp checked against the depth image.

A hand opened to `opening_m` before it descends (the full 80 mm when the width is the network's,
often narrower than the object) lowers the TCP FINGER_DEPTH_M under the surface seen at the grasp
centre. (The executor opens per grasp since 2026-11-29: control/gripper_rule.pre_grasp_opening_m.) A finger whose pad
footprint holds an object surface higher than the fingertip's lowest point lands on that object:
the descent stops on contact and the hand closes on the wrong thing ("a finger is on the object").
GG-CNN takes the best pixel without this check. The predictor (model/inference.py), when asked,
slides each grasp along its closing line until both pads land beside the objects and ranks the
grasps that can be made clear first.

Pure numpy; pixels are full-image (u, v), angles from u towards v as everywhere in grasping/.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from defgg_ros.constants import (
    FINGER_DEPTH_M,
    FINGER_PAD_WIDTH_M,
    PANDA_FINGER_THICKNESS_M,
    PANDA_FINGERTIP_BELOW_TCP_M,
)
from defgg_ros.grasping.postprocess import apart

# The fingertip's lowest point under the surface at the grasp centre (TCP depth + tip offset).
TIP_BELOW_SURFACE_M = FINGER_DEPTH_M + PANDA_FINGERTIP_BELOW_TCP_M
# Surfaces within this of the tip's height do not count (depth noise, rounded edges).
CLEARANCE_MARGIN_M = 0.005
# Sample points per pad side (a grid of SAMPLES x SAMPLES over each footprint).
SAMPLES = 7
# How far a grasp centre may slide along its closing line to let both fingers land beside the
# objects (beyond it the grasp is left as predicted and ranked after the clear ones).
MAX_CENTRE_SHIFT_M = 0.03


def finger_footprints_px(u_px: float, v_px: float, angle_rad: float, opening_m: float,
                         surface_depth_m: float, fx_px: float) -> list:
    """The two finger pads' footprints as (SAMPLES^2, 2) arrays of (u, v) sample points.

    Sizes are projected at the surface depth (the pads are at least that close to the camera
    while they descend onto anything, so this is the larger, conservative footprint).
    """
    if not (surface_depth_m > 0 and fx_px > 0 and opening_m > 0):
        raise ValueError(f"need depth, focal length and opening > 0, got {surface_depth_m}, {fx_px}, {opening_m}")
    px_per_m = fx_px / surface_depth_m
    along = np.array([math.cos(angle_rad), math.sin(angle_rad)])
    across = np.array([-along[1], along[0]])
    s = np.linspace(-0.5, 0.5, SAMPLES)
    grid_along, grid_across = np.meshgrid(s * PANDA_FINGER_THICKNESS_M, s * FINGER_PAD_WIDTH_M)
    local = grid_along.reshape(-1, 1) * along + grid_across.reshape(-1, 1) * across
    centre = np.array([u_px, v_px], dtype=float)
    offset = (opening_m + PANDA_FINGER_THICKNESS_M) / 2 * along
    return [centre + (side * offset + local) * px_per_m for side in (-1.0, 1.0)]


def fingers_clear(depth_m: np.ndarray, object_mask: np.ndarray, u_px: float, v_px: float, angle_rad: float,
                  surface_depth_m: float, opening_m: float, fx_px: float) -> bool:
    """True when neither finger pad's footprint holds an object surface above the fingertip.

    surface_depth_m: depth at the grasp centre (the executor's reference for the descent).
    object_mask: HxW, non-zero on object pixels (the table is never an obstacle: the executor
    stops the descent above it). Footprint samples off the image or on invalid depth are ignored.
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    mask = np.asarray(object_mask)
    height, width = depth.shape
    tip_depth = surface_depth_m + TIP_BELOW_SURFACE_M
    for pad in finger_footprints_px(u_px, v_px, angle_rad, opening_m, surface_depth_m, fx_px):
        cols, rows = np.rint(pad[:, 0]).astype(int), np.rint(pad[:, 1]).astype(int)
        inside = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
        cols, rows = cols[inside], rows[inside]
        under = depth[rows, cols]
        if np.any((mask[rows, cols] != 0) & np.isfinite(under) & (under < tip_depth - CLEARANCE_MARGIN_M)):
            return False
    return True


def touchable(depth_m: np.ndarray, object_mask: np.ndarray, u_px: int, v_px: int) -> np.ndarray:
    """HxW bool: the pixels of the object at (u, v) that stand above the fingertip's lowest point
    (what the fingers will touch)."""
    depth = np.asarray(depth_m, dtype=np.float32)
    tip_depth = float(depth[v_px, u_px]) + TIP_BELOW_SURFACE_M
    return (np.asarray(object_mask) == object_mask[v_px, u_px]) & (depth < tip_depth - CLEARANCE_MARGIN_M)


def chord_ends_px(depth_m: np.ndarray, object_mask: np.ndarray, u_px: int, v_px: int, angle_rad: float) -> tuple:
    """(start, end): signed steps (px, along the closing direction) from (u, v) to the ends of the
    object's chord on the closing line: the run of touchable pixels through the centre."""
    obj = touchable(depth_m, object_mask, u_px, v_px)
    height, width = obj.shape
    along = (math.cos(angle_rad), math.sin(angle_rad))
    ends = []
    for sign in (-1, 1):
        step = 0
        while True:
            u = int(round(u_px + sign * (step + 1) * along[0]))
            v = int(round(v_px + sign * (step + 1) * along[1]))
            if not (0 <= u < width and 0 <= v < height) or not obj[v, u]:
                break
            step += 1
        ends.append(sign * step)
    return ends[0], ends[1]


def clear_centre_shift_px(depth_m: np.ndarray, object_mask: np.ndarray, u_px: int, v_px: int, angle_rad: float,
                          opening_m: float, fx_px: float, max_shift_m: float = MAX_CENTRE_SHIFT_M):
    """Shift (px, signed, along the closing direction) of the grasp centre after which both fingers
    land beside the objects, keeping the centre on the same object; None if none within max_shift_m.

    First choice: the middle of the object's chord on the closing line, so both fingers touch at
    once (the Franka Hand's fingers are coupled: one that touches first pushes the object, and in
    the simulated cell it stalled the grasp on the object's edge). If that is blocked (e.g. by a
    neighbour), the smallest slide that clears. Sliding along the closing line keeps the grasp's
    line of contact; it moves the centre between the contacts, which the network places poorly on
    objects wider than its predicted width.
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    mask = np.asarray(object_mask)
    if mask[v_px, u_px] == 0 or not math.isfinite(float(depth[v_px, u_px])):
        return None
    max_shift_px = max_shift_m * fx_px / float(depth[v_px, u_px])
    start, end = chord_ends_px(depth, mask, u_px, v_px, angle_rad)
    half_opening_px = opening_m * fx_px / float(depth[v_px, u_px]) / 2
    if end - start + 1 >= 2 * half_opening_px:
        return None     # the object is wider than the opening along this line: no slide can clear it
    middle = (start + end) / 2.0
    if abs(middle) <= max_shift_px and clear_after_shifts(depth, mask, u_px, v_px, angle_rad, [middle], opening_m,
                                                         fx_px)[0]:
        return middle
    # Only slides that keep both fingers outside the chord can clear it.
    low = max(math.ceil(end - half_opening_px), -math.floor(max_shift_px))
    high = min(math.floor(start + half_opening_px), math.floor(max_shift_px))
    shifts = sorted(range(low, high + 1), key=lambda k: (abs(k), k))
    clear = clear_after_shifts(depth, mask, u_px, v_px, angle_rad, shifts, opening_m, fx_px)
    return next((k for k, ok in zip(shifts, clear) if ok), None)


def clear_after_shifts(depth_m: np.ndarray, object_mask: np.ndarray, u_px: int, v_px: int, angle_rad: float,
                       shifts_px, opening_m: float, fx_px: float) -> np.ndarray:
    """Per shift (px along the closing direction): does the grasp, moved there, stay on the object at
    (u, v) and let both fingers land beside the objects? fingers_clear for every shift in one pass
    (a slide search tries up to ~100 shifts per grasp; one by one they cost 4-5 ms per PlanGrasp)."""
    depth, mask = np.asarray(depth_m, dtype=np.float32), np.asarray(object_mask)
    height, width = depth.shape
    label = mask[v_px, u_px]
    shifts = np.asarray(shifts_px, dtype=float).reshape(-1)
    along = np.array([math.cos(angle_rad), math.sin(angle_rad)])
    centres = np.rint(np.array([u_px, v_px], dtype=float) + shifts[:, None] * along).astype(int)   # K x 2
    clear = np.zeros(len(shifts), bool)
    inside = (centres[:, 0] >= 0) & (centres[:, 0] < width) & (centres[:, 1] >= 0) & (centres[:, 1] < height)
    candidates = np.flatnonzero(inside)
    surface = depth[centres[candidates, 1], centres[candidates, 0]]
    keep = (mask[centres[candidates, 1], centres[candidates, 0]] == label) & np.isfinite(surface) & (surface > 0)
    candidates, surface = candidates[keep], surface[keep].astype(np.float64)   # as fingers_clear's floats
    if len(candidates) == 0:
        return clear
    blocked = np.zeros(len(candidates), bool)
    tip_depth = (surface + TIP_BELOW_SURFACE_M - CLEARANCE_MARGIN_M).astype(np.float32)[:, None]
    for pad in finger_footprints_px(0.0, 0.0, angle_rad, opening_m, 1.0, 1.0):   # metres around the centre
        points = centres[candidates, None, :] + pad[None] * (fx_px / surface)[:, None, None]    # K x P x 2
        cols, rows = np.rint(points[..., 0]).astype(int), np.rint(points[..., 1]).astype(int)
        on_image = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
        cols, rows = np.where(on_image, cols, 0), np.where(on_image, rows, 0)
        under = depth[rows, cols]
        blocked |= np.any(on_image & (mask[rows, cols] != 0) & np.isfinite(under) & (under < tip_depth), axis=1)
    clear[candidates] = ~blocked
    return clear


def clear_grasps_first(grasps: list, depth_m: np.ndarray, object_mask: np.ndarray, opening_m: float,
                       fx_px: float, needed: int | None = None, apart_px: int | None = None) -> tuple:
    """(grasps, clear flags): the grasps that a slide along the closing line makes clear
    (clear_centre_shift_px), slid, then the others as predicted; each group keeps its order.
    apart_px: drop a slid grasp that lands within apart_px (Chebyshev) of an earlier clear one (two
    peaks on one chord slide to its middle; a caller asking for alternatives wants distinct ones).

    grasps: grasping.postprocess.Grasp2D in the same pixel frame as depth_m and object_mask.
    needed: stop checking once this many grasps are clear (the caller keeps that many: the first
    `needed` entries are then the same as with every grasp checked); the unchecked ones follow the
    blocked ones with flag None. A PlanGrasp wants one grasp of a pool of 10: ~0.5 ms per check saved.
    """
    clear, blocked = [], []
    for i, g in enumerate(grasps):
        if needed is not None and len(clear) >= needed:
            unchecked = grasps[i:]
            return clear + blocked + unchecked, [True] * len(clear) + [False] * len(blocked) + [None] * len(unchecked)
        shift = clear_centre_shift_px(depth_m, object_mask, g.center_u_px, g.center_v_px, g.angle_rad, opening_m,
                                      fx_px)
        if shift is None:
            blocked.append(g)
            continue
        u = int(round(g.center_u_px + shift * math.cos(g.angle_rad)))
        v = int(round(g.center_v_px + shift * math.sin(g.angle_rad)))
        slid = dataclasses.replace(g, center_u_px=u, center_v_px=v)
        if apart_px is None or apart(slid, clear, apart_px):
            clear.append(slid)
    return clear + blocked, [True] * len(clear) + [False] * len(blocked)
