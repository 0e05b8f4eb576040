"""Pure pieces of the grasp inference node (no rclpy): labels, maps, finger boxes."""
import cv2
import numpy as np

from defgg_ros.constants import FINGER_DEPTH_M, FINGER_PAD_WIDTH_M, GRIPPER_MAX_WIDTH_M
from defgg_ros.perception.segmentation import MAX_OBJECTS

# Finger thickness along the closing direction, for display only (the
# Franka finger is ~1 cm thick at the pad).
FINGER_THICKNESS_M = 0.01
# A request asking for more grasps than this is a mistake, not a use case
# (GG-CNN peaks are MIN_DISTANCE apart, a 300x300 crop holds a few dozen).
MAX_TOP_K = 50


class PlanningError(ValueError):
    """A planning request that cannot be served (reason in the message)."""


def labels_from_stiffness(youngs_modulus_pa: np.ndarray) -> np.ndarray:
    """uint8 object labels: connected components of the non-background pixels.

    The segmentation node labels components of the same foreground in the
    same raster order, so these labels match its mask.
    """
    foreground = (np.asarray(youngs_modulus_pa) > 0).astype(np.uint8)
    count, labels = cv2.connectedComponents(foreground, connectivity=8)
    if count - 1 > MAX_OBJECTS:
        labels[labels > MAX_OBJECTS] = MAX_OBJECTS  # fold the rest into the last label; they still get grasps
    return labels.astype(np.uint8)


def check_top_k(top_k: int) -> int:
    """PlanGrasp's top_k: 0 means 1; more than MAX_TOP_K is refused."""
    k = int(top_k) or 1
    if k > MAX_TOP_K:
        raise PlanningError(f"top_k = {k} is more than the {MAX_TOP_K} grasps a request may ask for")
    return k


def full_quality_image(q_crop: np.ndarray, crop_offset_px, shape) -> np.ndarray:
    """The predictor's crop quality map pasted into a zero image of the depth's size."""
    out = np.zeros(shape, dtype=np.float32)
    u0, v0 = (int(x) for x in crop_offset_px)
    h, w = q_crop.shape
    out[v0:v0 + h, u0:u0 + w] = q_crop[: shape[0] - v0, : shape[1] - u0]
    return out


def finger_boxes_in_grasp(width_m: float):
    """[(graspTfinger 4x4, size_xyz_m)] for the two fingers of an open Panda hand.

    Grasp frame: TCP at the fingertip centre, z = approach, x = closing
    direction; the fingers stand at +-width/2 in x and extend FINGER_DEPTH_M
    back towards the hand (-z).
    """
    half = float(np.clip(width_m, 0.0, GRIPPER_MAX_WIDTH_M)) / 2 + FINGER_THICKNESS_M / 2
    size = (FINGER_THICKNESS_M, FINGER_PAD_WIDTH_M, FINGER_DEPTH_M)
    boxes = []
    for side in (-1.0, 1.0):
        pose = np.eye(4)
        pose[:3, 3] = (side * half, 0.0, -FINGER_DEPTH_M / 2)
        boxes.append((pose, size))
    return boxes
