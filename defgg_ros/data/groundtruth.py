"""Ground-truth grasp maps from labelled grasp rectangles (the paper, Sec. Dataset).

Only positive rectangles are drawn. Inside a rectangle: Q = 1, the angle and
the opening width of that grasp; outside: Q = 0 and cos 2phi = sin 2phi =
width = 0 (no grasp; the zero cos/sin vector carries no angle). Overlapping
rectangles: the later one wins, as in GG-CNN.

Which part of a rectangle becomes "grasp centre" pixels: the paper says the
rectangle; the GG-CNN code it builds on draws only the centre third along the
opening, because a grasp centred near a finger is not the labelled grasp.
We follow the code (GT_CENTRE_FRACTION); set it to 1.0 for the literal reading.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from defgg_ros.constants import WIDTH_SCALE_PX
from defgg_ros.data.format import GraspRect

GT_CENTRE_FRACTION = 1.0 / 3.0
_SUBPIXEL_BITS = 4  # cv2.fillPoly fixed-point precision: 1/16 px


def rectangle_pixels(rect: GraspRect, shape, length_fraction: float = GT_CENTRE_FRACTION) -> np.ndarray:
    """Boolean HxW mask of the rectangle, shortened along the opening."""
    inner = GraspRect(rect.center_u_px, rect.center_v_px, rect.angle_rad,
                      rect.width_px * length_fraction, rect.finger_height_px)
    canvas = np.zeros(shape[:2], np.uint8)
    # Corners are pixel-centre coordinates; fillPoly fills pixel centres inside.
    corners = np.round(inner.corners() * (1 << _SUBPIXEL_BITS)).astype(np.int32)
    cv2.fillPoly(canvas, [corners], 1, lineType=cv2.LINE_8, shift=_SUBPIXEL_BITS)
    return canvas.astype(bool)


def wrap_angle(angle_rad):
    """Wrap a grasp angle (period pi) into [-pi/2, pi/2)."""
    return (np.asarray(angle_rad) + math.pi / 2) % math.pi - math.pi / 2


def ground_truth_maps(positive_rects, shape, length_fraction: float = GT_CENTRE_FRACTION):
    """(q, angle_rad, width_px) HxW float32 maps from positive rectangles."""
    q = np.zeros(shape[:2], np.float32)
    angle = np.zeros(shape[:2], np.float32)
    width = np.zeros(shape[:2], np.float32)
    for rect in positive_rects:
        pixels = rectangle_pixels(rect, shape, length_fraction)
        q[pixels] = 1.0
        angle[pixels] = float(wrap_angle(rect.angle_rad))
        width[pixels] = rect.width_px
    return q, angle, width


def training_targets(q, angle_rad, width_px, width_scale_px: float = WIDTH_SCALE_PX) -> np.ndarray:
    """4 x H x W regression targets in the network's output order
    (q, cos 2phi, sin 2phi, width / scale); zero outside grasps."""
    valid = q > 0
    cos2 = np.where(valid, np.cos(2 * angle_rad), 0.0)
    sin2 = np.where(valid, np.sin(2 * angle_rad), 0.0)
    w = np.clip(width_px / width_scale_px, 0.0, 1.0)
    return np.stack([q, cos2, sin2, w]).astype(np.float32)
