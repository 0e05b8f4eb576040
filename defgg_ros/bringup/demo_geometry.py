"""Pure geometry of the demo: objects of the scene in the camera image, grasps on objects, the bin.

No rclpy. Poses come from the fake driver's ground truth, the camera from
the scene file (`base_T_camera`), intrinsics from camera_info.
"""
import numpy as np

from defgg_ros.constants import PANDA_FINGER_LENGTH_M, PANDA_FINGERTIP_BELOW_TCP_M
from defgg_ros.perception.geometry import transform_from_xyz_quaternion

# Margin around an object's projected footprint for its stiffness ROI (px).
ROI_MARGIN_PX = 6
# Objects placed in the bin may rest on each other: count anything this far
# above the walls' top, inside them, as in the bin.
BIN_STACK_MARGIN_M = 0.1
# A grasp belongs to an object when its centre is within the object's half
# diagonal plus this margin of the object's centre (m).
GRASP_ON_OBJECT_MARGIN_M = 0.01
# An object's projected centre lies inside its own segment (its centroid projects within its top
# face); a segment farther than this belongs to another object (px, ~1 mm each at 0.4 m).
OBJECT_SEEN_RADIUS_PX = 10.0


def base_T_camera(scene_dict: dict) -> np.ndarray:
    return transform_from_xyz_quaternion(scene_dict["base_xyz_camera_m"], scene_dict["base_quat_camera_xyzw"])


def project_base_points(points_base_m, base_t_camera: np.ndarray, camera_k: np.ndarray) -> np.ndarray:
    """(N, 3) base-frame points -> (N, 2) pixel (u, v)."""
    pts = np.atleast_2d(np.asarray(points_base_m, dtype=float))
    camera_t_base = np.linalg.inv(base_t_camera)
    pts_cam = pts @ camera_t_base[:3, :3].T + camera_t_base[:3, 3]
    if np.any(pts_cam[:, 2] <= 0):
        raise ValueError("a point lies behind the camera")
    uv = pts_cam[:, :2] / pts_cam[:, 2:3]
    return uv * [camera_k[0, 0], camera_k[1, 1]] + [camera_k[0, 2], camera_k[1, 2]]


def half_extent_m(obj: dict) -> float:
    """Largest horizontal half-extent of a scene object (box: half diagonal; cylinder: radius)."""
    size = obj["size_m"]
    if obj["shape"] == "cylinder":
        return size[0] / 2
    return float(np.hypot(size[0], size[1]) / 2)


def object_roi(obj: dict, position_base_m, base_t_camera, camera_k, image_wh) -> tuple:
    """(x, y, w, h) pixel box around the object's bounding box (top and bottom), clipped to the image."""
    r = half_extent_m(obj)
    half_h = obj["size_m"][-1] / 2
    corners = [[position_base_m[0] + dx, position_base_m[1] + dy, position_base_m[2] + dz]
               for dx in (-r, r) for dy in (-r, r) for dz in (-half_h, half_h)]
    uv = project_base_points(corners, base_t_camera, camera_k)
    lo = np.floor(uv.min(axis=0)) - ROI_MARGIN_PX
    hi = np.ceil(uv.max(axis=0)) + ROI_MARGIN_PX
    lo = np.clip(lo, 0, np.array(image_wh) - 1).astype(int)
    hi = np.clip(hi, 0, np.array(image_wh)).astype(int)
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])


def label_of_object(labels: np.ndarray, uv, max_distance_px: float = OBJECT_SEEN_RADIUS_PX) -> int:
    """Segmentation label of the object seen at pixel uv: the nearest labelled pixel within
    max_distance_px, else 0 (nothing there: the object was knocked away, or is hidden)."""
    ys, xs = np.nonzero(labels)
    if xs.size == 0:
        return 0
    d2 = (xs - uv[0]) ** 2 + (ys - uv[1]) ** 2
    i = int(np.argmin(d2))
    return int(labels[ys[i], xs[i]]) if d2[i] <= max_distance_px ** 2 else 0


def grasp_is_on_object(grasp_xy_m, obj: dict, position_base_m) -> bool:
    distance = np.hypot(grasp_xy_m[0] - position_base_m[0], grasp_xy_m[1] - position_base_m[1])
    return bool(distance <= half_extent_m(obj) + GRASP_ON_OBJECT_MARGIN_M)


def in_bin(position_base_m, bin_dict: dict | None) -> bool:
    """Is a point inside the bin's walls (horizontally), not higher than a stack of objects in it?"""
    if not bin_dict:
        return False
    (cx, cy), (ix, iy, h) = bin_dict["center_xy_m"], bin_dict["inner_size_m"]
    x, y, z = position_base_m
    return bool(abs(x - cx) <= ix / 2 and abs(y - cy) <= iy / 2 and z <= h + BIN_STACK_MARGIN_M)


# The order in which the demo fills the bin's quadrants: diagonal first, so the next object lands
# as far as possible from the one before (all at the bin's centre, they piled up and one came to
# rest on the rim: 3/4 in the bin on a fresh clone).
BIN_QUADRANT_ORDER = ((1, 1), (-1, -1), (1, -1), (-1, 1))


def bin_place_xy(bin_dict: dict, slot: int) -> tuple:
    """(x, y) base-frame centre of the bin quadrant for the slot-th placed object (cycles after 4)."""
    if slot < 0:
        raise ValueError(f"slot must be >= 0, got {slot}")
    (cx, cy), (ix, iy, _h) = bin_dict["center_xy_m"], bin_dict["inner_size_m"]
    sx, sy = BIN_QUADRANT_ORDER[slot % len(BIN_QUADRANT_ORDER)]
    return cx + sx * ix / 4, cy + sy * iy / 4


def part_roi(obj: dict, position_base_m, base_t_camera, camera_k, image_wh) -> tuple | None:
    """(x, y, w, h) around the object's second-material part (local x >= part.x_from_m), or None.

    Uses the scene's yaw: objects have not turned before they are picked.
    """
    part = obj.get("part")
    if not part or obj["shape"] != "box":
        return None
    sx, sy, sz = obj["size_m"]
    c, s = np.cos(obj.get("yaw_rad", 0.0)), np.sin(obj.get("yaw_rad", 0.0))
    corners = []
    for lx in (part["x_from_m"], sx / 2):
        for ly in (-sy / 2, sy / 2):
            for lz in (-sz / 2, sz / 2):
                corners.append([position_base_m[0] + c * lx - s * ly, position_base_m[1] + s * lx + c * ly,
                                position_base_m[2] + lz])
    uv = project_base_points(corners, base_t_camera, camera_k)
    lo = np.clip(np.floor(uv.min(axis=0)), 0, np.array(image_wh) - 1).astype(int)
    hi = np.clip(np.ceil(uv.max(axis=0)), 0, np.array(image_wh)).astype(int)
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])


# Release: the object's lowest point at least this far above the bin floor (the table). From the fixed 0.12 m
# release a 5 cm soft block fell ~7 cm, bounced and came to rest on a wall's top (bench/README.md).
RELEASE_DROP_M = 0.03
# The palm's underside stays this far above the walls' top: it is wider (0.204 m along the closing
# direction) than a quadrant, so it passes over a wall while the fingers are inside.
PALM_WALL_CLEARANCE_M = 0.01


def release_tcp_z(grasp_point_z_m: float, bin_dict: dict, max_z_m: float) -> float:
    """TCP height at the release. The grasp point lies on the object's top surface and the executor's TCP
    went down to it or lower, so the object hangs at most grasp_point_z below the TCP (it stood on the
    table, the bin's floor): a TCP at grasp_point_z + RELEASE_DROP_M lets it drop at most that far plus
    the grasp's depth. Never lower than the palm's clearance over the walls, never higher than the
    executor's configured release height."""
    palm_above_tcp_m = PANDA_FINGER_LENGTH_M - PANDA_FINGERTIP_BELOW_TCP_M
    lowest = bin_dict["inner_size_m"][2] + PALM_WALL_CLEARANCE_M - palm_above_tcp_m
    return float(min(max_z_m, max(grasp_point_z_m + RELEASE_DROP_M, lowest)))
