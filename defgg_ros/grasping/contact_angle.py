"""Closing angles whose finger pads meet the object squarely (an optional step after the network).

GG-CNN regresses the grasp angle as (cos 2phi, sin 2phi). Where one pixel admits two closing
directions (the top of a square block: 0 and 90 degrees), the training labels pull these outputs
to opposite values, they average out near zero, and the angle read from them is noise: the demo's
45 mm rubber block was grasped across its diagonal, with a corner on each pad, and slipped out
(docs/model.md). The quality and width maps do not have this problem.

This step keeps the network's grasp centre and re-chooses the angle there: for each angle of a
5-degree grid, the centre is moved to the middle of the object's chord on the closing line (as the
finger-clearance step does) and each pad's contact is scored by the fraction of its width that
touches the object within CONTACT_TOLERANCE_M of the pad's first contact. A face takes the whole
pad; a corner, or a round side touched far from its extreme point, only a sliver. The angle with
the best smaller-of-two-pads score (within one pad sample) wins, the network's own angle when it
is as good, else the closest to it. Pure numpy; pixels are (u, v), angles from u towards v as everywhere in grasping/.
"""
from __future__ import annotations

import math

import numpy as np

from defgg_ros.constants import FINGER_PAD_WIDTH_M
from defgg_ros.grasping.finger_clearance import touchable

ANGLE_STEP_RAD = math.radians(5.0)
# A pad sample counts as touching when the object reaches within this of the pad's first contact
# (depth-image resolution and soft edges; a 33 mm-radius can falls 1.5 mm over a 20 mm pad).
CONTACT_TOLERANCE_M = 0.0015
PAD_SAMPLES = 7
# Scores within one pad sample of the best count as equally square (rasterised edges move a
# sample in or out of the tolerance); among them the angle nearest the network's wins.
SCORE_SLACK = 1.0 / PAD_SAMPLES


def _run_lengths(inside: np.ndarray) -> np.ndarray:
    """Per ray (last axis = steps from the start): how many leading steps are inside."""
    return np.argmin(np.concatenate([inside, np.zeros(inside.shape[:-1] + (1,), bool)], axis=-1), axis=-1)


def _sample(obj: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    h, w = obj.shape
    ui, vi = np.rint(u).astype(int), np.rint(v).astype(int)
    ok = (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
    out = np.zeros(u.shape, bool)
    out[ok] = obj[vi[ok], ui[ok]]
    return out


def contact_scores(obj: np.ndarray, u_px: float, v_px: float, angles_rad: np.ndarray, px_per_m: float,
                   max_reach_px: int) -> tuple:
    """(scores, centre shifts px along each angle, chord lengths px) for grasps at (u, v)."""
    steps = np.arange(max_reach_px + 1, dtype=float)
    along = np.stack([np.cos(angles_rad), np.sin(angles_rad)], axis=-1)               # A x 2
    across = np.stack([-along[:, 1], along[:, 0]], axis=-1)
    # 1. the chord through (u, v) on each closing line, and its middle
    sides = np.array([-1.0, 1.0])
    ray = u_px + sides[None, :, None] * steps * along[:, None, None, 0], \
        v_px + sides[None, :, None] * steps * along[:, None, None, 1]                   # A x 2 x T
    ends = _run_lengths(_sample(obj, *ray)) - 1                                      # A x 2, -1: centre outside
    shift = (ends[:, 1] - ends[:, 0]) / 2.0
    centre = np.array([u_px, v_px]) + shift[:, None] * along                          # A x 2
    # 2. each pad's reach over its width: how far the object extends along the closing line
    offsets = np.linspace(-0.5, 0.5, PAD_SAMPLES) * FINGER_PAD_WIDTH_M * px_per_m      # S
    start = centre[:, None, :] + offsets[None, :, None] * across[:, None, :]          # A x S x 2
    pu = start[:, None, :, None, 0] + sides[None, :, None, None] * steps * along[:, None, None, None, 0]
    pv = start[:, None, :, None, 1] + sides[None, :, None, None] * steps * along[:, None, None, None, 1]
    reach = _run_lengths(_sample(obj, pu, pv)).astype(float)                          # A x 2 x S
    first_contact = reach.max(axis=2, keepdims=True)
    touching = (reach >= first_contact - CONTACT_TOLERANCE_M * px_per_m) & (first_contact > 0)
    scores = touching.mean(axis=2).min(axis=1)
    chord = first_contact[:, :, 0].sum(axis=1)
    return scores, shift, chord


def square_contact_angle(depth_m: np.ndarray, object_mask: np.ndarray, u_px: int, v_px: int, angle_rad: float,
                         opening_m: float, fx_px: float) -> tuple:
    """(angle_rad, u_px, v_px, score) of the grasp at (u, v) with the squarest pad contacts.

    Angles whose chord does not fit in opening_m are not taken. Returns the input grasp with score
    nan when the centre is not on an object or has no valid depth.
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    if object_mask[v_px, u_px] == 0 or not math.isfinite(float(depth[v_px, u_px])) or depth[v_px, u_px] <= 0:
        return angle_rad, u_px, v_px, float("nan")
    px_per_m = fx_px / float(depth[v_px, u_px])
    obj = touchable(depth, np.asarray(object_mask), u_px, v_px)
    grid = angle_rad + np.arange(0.0, math.pi, ANGLE_STEP_RAD)     # the network's angle first
    scores, shift, chord = contact_scores(obj, u_px, v_px, grid, px_per_m, int(math.ceil(opening_m * px_per_m)))
    scores = np.where(chord <= opening_m * px_per_m, scores, -1.0)
    distance = np.abs((grid - angle_rad + math.pi / 2) % math.pi - math.pi / 2)
    ties = np.flatnonzero(scores >= scores.max() - SCORE_SLACK - 1e-9)
    best = int(ties[np.argmin(distance[ties])])     # of the best, the nearest to the network's angle
    # the shift is along grid[best]; wrapping the angle by pi below does not move the centre
    u = int(round(u_px + shift[best] * math.cos(grid[best])))
    v = int(round(v_px + shift[best] * math.sin(grid[best])))
    return float((grid[best] + math.pi / 2) % math.pi - math.pi / 2), u, v, float(scores[best])
