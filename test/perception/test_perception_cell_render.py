"""Segmentation on real PyBullet renders of the simulated cell (the fake driver's camera)."""
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.perception.depth import depth_to_metres
from defgg_ros.perception.geometry import transform_from_list
from defgg_ros.perception.segmentation import segment_objects
from defgg_ros.perception.tabletop import TabletopConfig
from defgg_ros.planning.perceived_frame import perceive_frame
from defgg_ros.sim.cell.camera import DepthNoise, camera_matrix, depth_m_to_mm_u16
from defgg_ros.sim.cell.sim_cell import CellSettings, SimCell
from defgg_ros.sim.scene_spec import load_scene

SCENE = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes" / "rigid_box.yaml"
REALSENSE_LIKE = DepthNoise(noise_coeff_per_m=0.004, random_dropout_fraction=0.02, drop_edges=True)


@pytest.fixture(scope="module")
def renders():
    """(clean 16UC1 depth, noisy 16UC1 depth, ground-truth object index mask) of the rigid_box scene."""
    out = []
    for noise in (DepthNoise(), REALSENSE_LIKE):
        cell = SimCell(load_scene(SCENE), CellSettings(depth_noise=noise))
        try:
            depth_m, object_mask, _ = cell.render_depth()
        finally:
            cell.close()
        out.append(depth_m_to_mm_u16(depth_m))
    return out[0], out[1], object_mask


@pytest.mark.parametrize("which", [0, 1], ids=["clean", "realsense_noise"])
def test_the_box_is_found_on_the_table(renders, which):
    depth_mm, truth = renders[which], renders[2]
    result = segment_objects(depth_to_metres(depth_mm, "16UC1"), camera_matrix())
    assert result.object_ids == (1,)
    a, b = result.labels == 1, truth == 0
    assert (a & b).sum() / (a | b).sum() > (0.97 if which == 0 else 0.85)
    assert result.plane.offset_m == pytest.approx(0.40, abs=0.003)  # camera 0.40 m above the table


def test_stiffness_image_of_the_render(renders):
    depth_m = depth_to_metres(renders[0], "16UC1")
    base_T_camera = transform_from_list([0.5, 0.0, 0.40, 1.0, 0.0, 0.0, 0.0])     # the cell's camera mount
    parts, _, image = perceive_frame(depth_m, camera_matrix(), base_T_camera, TabletopConfig(),
                                     default_youngs_modulus_pa=2e9)
    assert set(np.unique(image)) == {0.0, np.float32(2e9)}
    assert [o.youngs_modulus_pa for o in parts.objects] == [2e9]
    assert set(np.unique(parts.grid_youngs_modulus_pa)) == {0.0, np.float32(2e9)}
