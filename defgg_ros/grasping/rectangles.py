"""Grasp rectangles and the GG-CNN rectangle metric.

A predicted grasp is correct when its rectangle overlaps a positive
ground-truth rectangle with IoU > 0.25 and their angles differ by less than
30 degrees (modulo 180 degrees, since a parallel grasp is symmetric).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

IOU_THRESHOLD = 0.25
ANGLE_THRESHOLD_RAD = math.radians(30.0)


@dataclass
class GraspRect:
    """A grasp in image space: centre (px), angle from the u axis towards v (rad), opening width and
    finger height (px)."""
    center_u_px: float
    center_v_px: float
    angle_rad: float
    width_px: float
    finger_height_px: float

    def corners(self) -> np.ndarray:
        """4x2 (u, v) corners; the width runs along the angle direction."""
        c, s = math.cos(self.angle_rad), math.sin(self.angle_rad)
        along = np.array([c, s]) * self.width_px / 2.0
        across = np.array([-s, c]) * self.finger_height_px / 2.0
        centre = np.array([self.center_u_px, self.center_v_px])
        return np.stack([centre - along - across, centre + along - across,
                         centre + along + across, centre - along + across])


def angle_difference_rad(a_rad: float, b_rad: float) -> float:
    """Smallest difference of two grasp angles, modulo pi, in [0, pi/2]."""
    d = (a_rad - b_rad) % math.pi
    return min(d, math.pi - d)


def rectangle_iou(a: GraspRect, b: GraspRect) -> float:
    pa = a.corners().astype(np.float32)
    pb = b.corners().astype(np.float32)
    area_a = abs(cv2.contourArea(pa))
    area_b = abs(cv2.contourArea(pb))
    if area_a <= 0 or area_b <= 0:
        return 0.0
    inter, _ = cv2.intersectConvexConvex(pa, pb)
    inter = max(float(inter), 0.0)
    return inter / (area_a + area_b - inter)


def rectangle_match(predicted: GraspRect, positives) -> bool:
    """True when `predicted` matches any positive rectangle (GG-CNN metric)."""
    for gt in positives:
        if angle_difference_rad(predicted.angle_rad, gt.angle_rad) < ANGLE_THRESHOLD_RAD \
                and rectangle_iou(predicted, gt) > IOU_THRESHOLD:
            return True
    return False
