"""Pure pieces of the grasp inference node (no rclpy): top_k, maps, finger boxes."""
import numpy as np

from defgg_ros.constants import FINGER_DEPTH_M, FINGER_PAD_WIDTH_M, GRIPPER_MAX_WIDTH_M

# Finger thickness along the closing direction, for display only (the
# Franka finger is ~1 cm thick at the pad).
FINGER_THICKNESS_M = 0.01
# A request asking for more grasps than this is a mistake, not a use case
# (GG-CNN peaks are MIN_DISTANCE apart, a 300x300 crop holds a few dozen).
MAX_TOP_K = 50


class PlanningError(ValueError):
    """A planning request that cannot be served (reason in the message)."""


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
