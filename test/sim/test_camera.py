"""Top-down rendering: soft bodies appear in depth, stiffness and mask; projection is consistent."""
import numpy as np
import pytest

from defgg_ros.constants import CAMERA_FX_PX, CAMERA_HEIGHT_ABOVE_TABLE_M, NETWORK_INPUT_SIZE_PX
from defgg_ros.sim import camera, objects, world


@pytest.mark.parametrize("youngs_modulus_pa", [2e4, 2e9])
def test_object_appears_in_depth_stiffness_and_mask(client, youngs_modulus_pa):
    spec = objects.ObjectSpec(objects.get_shape("box_small"), youngs_modulus_pa)   # 5 x 3 x 4 cm
    world.create_world(client, [youngs_modulus_pa])
    loaded = objects.load_object(client, spec, position_xy_m=(0.05, 0.02))
    images = camera.render_object_images(client, loaded)
    depth, mask, modulus = images["depth_m"], images["object_mask"], images["youngs_modulus_pa"]
    assert depth.shape == (NETWORK_INPUT_SIZE_PX, NETWORK_INPUT_SIZE_PX)
    on = mask == 1
    # top face 4 cm above the table, table at the camera height
    assert np.median(depth[on]) == pytest.approx(CAMERA_HEIGHT_ABOVE_TABLE_M - 0.04, abs=0.002)
    assert np.median(depth[~on]) == pytest.approx(CAMERA_HEIGHT_ABOVE_TABLE_M, abs=0.001)
    assert np.all(modulus[on] == np.float32(youngs_modulus_pa)) and np.all(modulus[~on] == 0)
    # x right = +u, y forward = -v: the object at (+5, +2) cm sits right of and above the centre
    vs, us = np.nonzero(on)
    expected = camera.TopDownCamera().world_to_pixel([[0.05, 0.02, 0.04]])[0]
    assert us.mean() == pytest.approx(expected[0], abs=1.5) and vs.mean() == pytest.approx(expected[1], abs=1.5)
    area_px = 0.05 * 0.03 * (CAMERA_FX_PX / (CAMERA_HEIGHT_ABOVE_TABLE_M - 0.04)) ** 2
    assert on.sum() == pytest.approx(area_px, rel=0.1)


def test_multi_material_parts_get_their_own_modulus(client):
    spec = objects.ObjectSpec(objects.get_shape("mallet_mm"), 2e9, part_youngs_modulus_pa=2e4)
    world.create_world(client, spec.part_moduli_pa())
    loaded = objects.load_object(client, spec)
    images = camera.render_object_images(client, loaded)
    assert set(np.unique(images["object_mask"])) == {0, 1, 2}
    assert set(np.unique(images["youngs_modulus_pa"][images["object_mask"] == 1])) == {np.float32(2e9)}
    assert set(np.unique(images["youngs_modulus_pa"][images["object_mask"] == 2])) == {np.float32(2e4)}


def test_pixel_round_trip():
    cam = camera.TopDownCamera()
    pts = np.array([[0.1, -0.05, 0.0], [-0.12, 0.1, 0.03]])
    uv = cam.world_to_pixel(pts)
    depth = cam.base_T_camera[2, 3] - pts[:, 2]
    np.testing.assert_allclose(cam.pixel_to_world(uv, depth), pts, atol=1e-12)
    np.testing.assert_allclose(cam.k[:2, 2], [NETWORK_INPUT_SIZE_PX / 2] * 2)
