"""Pixel grasp -> world grasp conventions (against the training labels' sampler), trial keys and order."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from defgg_ros.evaluation import jobs
from defgg_ros.evaluation.planning import plan_world_grasp, yaw_from_image_angle
from defgg_ros.grasping.geometry import tcp_height_m
from defgg_ros.sim.camera import TopDownCamera
from defgg_ros.sim.sampler import grasp_rect
from defgg_ros.sim.trial import WorldGrasp


def _candidate_from_rect(rect, camera, surface_z_m):
    depth = camera.base_T_camera[2, 3] - surface_z_m
    point = camera.pixel_to_world([[rect.center_u_px, rect.center_v_px]], depth)[0]
    point_camera = camera.base_T_camera[:3, :3].T @ (point - camera.base_T_camera[:3, 3])
    return SimpleNamespace(center_u_px=rect.center_u_px, center_v_px=rect.center_v_px, angle_rad=rect.angle_rad,
                           width_px=rect.width_px, width_m=rect.width_px * depth / camera.fx_px, quality=0.9,
                           position_camera_m=tuple(point_camera), object_id=1, youngs_modulus_pa=2e5, depth_m=depth)


@pytest.mark.parametrize("yaw", [0.0, 0.4, -1.2, 1.5])
def test_label_rectangle_plans_back_to_the_labelled_world_grasp(yaw):
    """A training label's rectangle, read back the way model outputs are, gives the labelled grasp."""
    camera = TopDownCamera()
    surface_z = 0.04
    grasp = WorldGrasp((0.012, -0.021, tcp_height_m(surface_z)), yaw, 0.045)
    cand = _candidate_from_rect(grasp_rect(grasp, camera), camera, surface_z)
    planned = plan_world_grasp(cand, 0, camera.base_T_camera, camera.k)
    np.testing.assert_allclose(planned.position_m, grasp.position_m, atol=1e-6)
    assert planned.width_m == pytest.approx(0.045, rel=1e-6)
    # a parallel gripper is symmetric: yaw and yaw + pi are the same grasp
    assert math.cos(2 * (planned.yaw_rad - yaw)) == pytest.approx(1.0, abs=1e-9)


def test_tcp_stays_above_the_table_for_flat_objects():
    assert tcp_height_m(0.004) > 0.007
    assert tcp_height_m(0.06) == pytest.approx(0.03)


def test_bad_camera_and_points_raise():
    camera = TopDownCamera()
    cand = SimpleNamespace(position_camera_m=(0.0, 0.0, -1.0), width_px=10.0, width_m=0.01, angle_rad=0.0)
    with pytest.raises(ValueError, match="in front"):
        plan_world_grasp(cand, 0, camera.base_T_camera, camera.k)
    with pytest.raises(ValueError, match="4x4"):
        plan_world_grasp(cand, 0, np.eye(3), camera.k)
    with pytest.raises(ValueError, match="look down"):
        side = np.eye(4)
        side[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
        yaw_from_image_angle(0.0, side)


def _objs():
    return [SimpleNamespace(name="a", set_name="common", moduli_pa=(2e4, 2e9), multi_material=False),
            SimpleNamespace(name="mm", set_name="common", moduli_pa=(2e4, 2e9), multi_material=True)]


def test_jobs_are_unique_and_rank_major():
    views = jobs.main_views(["m1", "m2"], _objs()) + jobs.sensitivity_views(["m1"], _objs()) \
        + jobs.multimaterial_views(["m1", "m2"], _objs())
    trial_jobs = jobs.trial_jobs(views, {"m1": "aaa", "m2": "bbb"}, 3, ("shake", "twist"), seed=0)
    keys = [j.key for j in trial_jobs]
    assert len(keys) == len(set(keys))
    main = [j for j in trial_jobs if j.view.experiment == "main"]
    assert [j.rank for j in main] == sorted(j.rank for j in main)
    assert len(main) == 2 * 2 * 2 * 3 * 2          # models x objects x moduli x grasps x tasks
    sens = {j.view.input_error_pct for j in trial_jobs if j.view.experiment == "sensitivity"}
    assert 0 not in sens and len(sens) == len(jobs.SENSITIVITY_ERRORS_PCT) - 1
    mm = [j for j in trial_jobs if j.view.experiment == "multimaterial"]
    assert {j.view.object_name for j in mm} == {"mm"}
    assert {j.view.input_label for j in mm} == {"true", "assume2e+09"}
    with pytest.raises(ValueError, match="unknown task"):
        jobs.trial_jobs(views, {"m1": "a", "m2": "b"}, 1, ("spin",), 0)


def test_sim_key_changes_with_anything_that_changes_the_simulation():
    g = WorldGrasp((0.0, 0.0, 0.02), 0.3, 0.04)
    base = jobs.sim_key("common", "a", [2e5], 0.1, g, "shake", {"x": 1})
    assert base == jobs.sim_key("common", "a", [2e5], 0.1, g, "shake", {"x": 1})
    assert base != jobs.sim_key("common", "a", [2e6], 0.1, g, "shake", {"x": 1})
    assert base != jobs.sim_key("common", "a", [2e5], 0.1, WorldGrasp((0.0, 0.001, 0.02), 0.3, 0.04), "shake",
                                {"x": 1})
    assert base != jobs.sim_key("common", "a", [2e5], 0.1, g, "twist", {"x": 1})
    assert base != jobs.sim_key("common", "a", [2e5], 0.1, g, "shake", {"x": 2})
