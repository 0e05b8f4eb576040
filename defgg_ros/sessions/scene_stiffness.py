"""Stiffness assignments for a simulated scene: what an operator would enter for each object.

The segmentation node learns moduli only through SetStiffness (image
regions, see ObjectStiffness.msg). For a recorded sim session the recorder
enters them from the scene file: one whole-object entry per object (a box
around its projected footprint) and, for a multi-material object, a
region-only entry over its part. No rclpy.
"""
import numpy as np

from defgg_ros.bringup.demo_geometry import ROI_MARGIN_PX, project_base_points
from defgg_ros.perception.geometry import transform_from_xyz_quaternion
from defgg_ros.sim.scene_spec import SceneObject, SceneSpec


def _footprint_corners(obj: SceneObject, x_range_m=None) -> np.ndarray:
    """Top-face corners (4, 3) in the base frame; x_range_m limits the object's local x (a part's slab)."""
    if obj.shape == "cylinder":
        half_x = half_y = obj.size_m[0] / 2
    else:
        half_x, half_y = obj.size_m[0] / 2, obj.size_m[1] / 2
    x0, x1 = x_range_m if x_range_m is not None else (-half_x, half_x)
    local = np.array([[x, y] for x in (x0, x1) for y in (-half_y, half_y)])
    c, s = np.cos(obj.yaw_rad), np.sin(obj.yaw_rad)
    xy = local @ np.array([[c, s], [-s, c]]) + np.asarray(obj.position_xy_m)
    return np.column_stack([xy, np.full(4, obj.height_m)])


def _roi(corners_base_m, base_t_camera, camera_k, image_wh, margin_px: int) -> list:
    uv = project_base_points(corners_base_m, base_t_camera, camera_k)
    lo = np.clip(np.floor(uv.min(axis=0)) - margin_px, 0, np.array(image_wh) - 1).astype(int)
    hi = np.clip(np.ceil(uv.max(axis=0)) + margin_px, 0, np.array(image_wh)).astype(int)
    return [int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])]


def scene_stiffness_entries(scene: SceneSpec, camera_k, image_wh) -> list[dict]:
    """[{name, youngs_modulus_pa, roi [x, y, w, h], region_only}] for SetStiffness."""
    base_t_camera = transform_from_xyz_quaternion(scene.base_xyz_camera_m, scene.base_quat_camera_xyzw)
    camera_k = np.asarray(camera_k, dtype=float)
    entries = []
    for obj in scene.objects:
        entries.append({"name": obj.name, "youngs_modulus_pa": obj.youngs_modulus_pa, "region_only": False,
                        "roi": _roi(_footprint_corners(obj), base_t_camera, camera_k, image_wh, ROI_MARGIN_PX)})
        if obj.part is not None:
            slab = (obj.part.x_from_m, obj.size_m[0] / 2)
            entries.append({"name": f"{obj.name}/part", "youngs_modulus_pa": obj.part.youngs_modulus_pa,
                            "region_only": True,
                            "roi": _roi(_footprint_corners(obj, slab), base_t_camera, camera_k, image_wh, 0)})
    return entries
