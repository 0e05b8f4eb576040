"""Stiffness entries entered for a simulated scene: every object addressed, the multi-material part inside it."""
from pathlib import Path

import numpy as np

from defgg_ros.bringup.demo_geometry import project_base_points
from defgg_ros.perception.geometry import transform_from_xyz_quaternion
from defgg_ros.perception.synthetic_scene import default_camera_k
from defgg_ros.sessions.scene_stiffness import scene_stiffness_entries
from defgg_ros.sim.scene_spec import load_scene

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "sessions" / "scenes"


def test_mixed_scene_entries_cover_objects_and_the_soft_part():
    scene = load_scene(SCENES / "mixed_objects.yaml")
    k = default_camera_k()
    entries = {e["name"]: e for e in scene_stiffness_entries(scene, k, (640, 480))}
    assert set(entries) == {"foam_cube", "wooden_can", "padded_block", "padded_block/part"}
    base_t_camera = transform_from_xyz_quaternion(scene.base_xyz_camera_m, scene.base_quat_camera_xyzw)
    for obj in scene.objects:  # each whole-object roi holds the object's projected centre (its mask centroid)
        x, y, w, h = entries[obj.name]["roi"]
        (u, v), = project_base_points([[*obj.position_xy_m, obj.height_m]], base_t_camera, k)
        assert x < u < x + w and y < v < y + h and not entries[obj.name]["region_only"]
    part, whole = entries["padded_block/part"], entries["padded_block"]
    assert part["region_only"] and part["youngs_modulus_pa"] == 2e4 and whole["youngs_modulus_pa"] == 2e9
    px, py, pw, ph = part["roi"]
    wx, wy, ww, wh = whole["roi"]
    assert wx <= px and px + pw <= wx + ww and wy <= py and py + ph <= wy + wh
    # The pad is the +x end (x >= 15 mm of a 90 mm block): about a third of the block, on the image's right.
    assert px > wx + ww / 2 and 0.25 < pw / ww < 0.45
    assert np.all(np.array(part["roi"]) >= 0)
