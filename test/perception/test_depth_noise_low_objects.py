"""Depth noise as a camera property (perception/depth_noise.py) and grasps on low objects (issue 47, item 2): an
overhead camera 0.72 m above the table (640x480, fx 525, a D435's noise) sees objects 1.5 and 2 cm tall; the
free-space test must not take the table's own noise for an obstacle under the pads. When no grasp is feasible,
the plan says per object which test rejected it."""
import numpy as np
import pytest

from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.depth_noise import REALSENSE_BASELINES_M, DepthNoiseModel
from defgg_ros.perception.tabletop import TabletopConfig, WorkspaceBox, perceive
from defgg_ros.planning import tabletop_grasps as tg
from defgg_ros.planning.tabletop_planner import NoFeasibleGrasp, TabletopPlanner

MODEL = GraspPredictor.from_checkpoint(__import__("pathlib").Path(__file__).resolve().parents[2] / "models" /
                                       "defgg_cnn.pt", num_threads=1)


def test_each_realsense_model_has_its_baseline_and_the_intel_formula():
    assert REALSENSE_BASELINES_M == {"d405": 0.018, "d415": 0.055, "d435": 0.050, "d435i": 0.050, "d455": 0.095}
    d435 = DepthNoiseModel.for_camera("D435i")
    assert d435 == DepthNoiseModel() and d435.subpixel_rms_px == 0.08
    # The figure of the issue: 3 sigma + 2 mm = 6.7 mm at 0.72 m with fx 525.
    assert 3 * d435.sigma_m(0.72, 525.0) + tg.CARVING_TOLERANCE_M == pytest.approx(0.0067, abs=1e-4)
    assert DepthNoiseModel.for_camera("d455").sigma_m(0.72, 525.0) == pytest.approx(
        d435.sigma_m(0.72, 525.0) * 0.050 / 0.095)
    with pytest.raises(ValueError, match="unknown camera model"):
        DepthNoiseModel.for_camera("kinect")
    with pytest.raises(ValueError, match="baseline_m > 0"):
        DepthNoiseModel(0.0, 0.08)


def _overhead_072(obj, noise=None):
    return ts.TabletopScene((obj,), ts.look_at((0.5, 0.0, 0.72), (0.5, 0.0, 0.0)), 640, 480, fx_px=525.0,
                            depth_noise=noise or DepthNoiseModel())


LOW_OBJECTS = [ts.Box((0.50, 0.01), (0.06, 0.04, h), yaw_rad=0.4, name=f"block {h * 100:.1f} cm")
               for h in (0.015, 0.02)] \
    + [ts.Cylinder((0.49, -0.02), 0.025, h, name=f"puck {h * 100:.1f} cm") for h in (0.015, 0.02)]


@pytest.mark.parametrize("obj", LOW_OBJECTS, ids=[o.name for o in LOW_OBJECTS])
def test_objects_1_5_and_2_cm_tall_from_0_72_m_get_a_grasp_on_the_object(obj):
    for seed in (0, 1):
        frame = ts.render(_overhead_072(obj), seed=seed)
        view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
        assert len(view.object_ids) == 1, f"{obj.name}: {len(view.object_ids)} objects"
        grasps = tg.plan_tabletop_grasps(view, MODEL, None, top_k=1)
        assert grasps, f"{obj.name}, seed {seed}: no grasp"
        uv = tg.image_projection(grasps[0], frame.base_T_camera, frame.camera_k)
        assert frame.labels[int(round(uv["v_px"])), int(round(uv["u_px"]))] == 1, f"{obj.name}: not on it"
        assert grasps[0].width_m <= 0.08


def test_the_noise_measured_from_the_tables_residuals_is_the_cameras():
    """depth_noise_from_table: a frame rendered with twice Intel's typical subpixel RMS gives about that."""
    noisy = DepthNoiseModel(0.050, 0.16)
    frame = ts.render(_overhead_072(LOW_OBJECTS[1], noisy), seed=3)
    config = TabletopConfig(depth_noise_from_table=True)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera, config)
    assert view.depth_noise.baseline_m == 0.050
    assert view.depth_noise.subpixel_rms_px == pytest.approx(0.16, rel=0.3)
    assert perceive(frame.depth_m, frame.camera_k, frame.base_T_camera).depth_noise == DepthNoiseModel()


def _plan(objects, config=None, eye=(0.5, 0.0, 0.55), target=(0.5, 0.0, 0.0), noise=True):
    frame = ts.render(ts.TabletopScene(tuple(objects), ts.look_at(eye, target)), seed=1, noise=noise)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera, config)
    return view, tg.plan_tabletop(view, MODEL, None, 5)


def test_without_a_feasible_grasp_the_plan_says_per_object_which_test_rejected_it():
    _, plan = _plan([ts.Box((0.5, 0.0), (0.15, 0.13, 0.05), name="cereal box")])
    assert not plan.grasps and plan.rejected == {1: tg.WIDTH}
    far = TabletopConfig(workspace=WorkspaceBox(x_m=(0.22, 1.1)))
    _, plan = _plan([ts.Box((0.92, 0.0), (0.05, 0.04, 0.04))], far, eye=(0.9, 0.0, 0.55), target=(0.9, 0.0, 0.0))
    assert not plan.grasps and plan.rejected == {1: tg.REACH}
    # A 3 mm plate (seen without noise, perceived from 2 mm): the fingertips cannot go low enough.
    flat = TabletopConfig(workspace=WorkspaceBox(min_height_m=0.002), depth_noise=DepthNoiseModel(0.05, 0.0))
    _, plan = _plan([ts.Box((0.5, 0.0), (0.05, 0.04, 0.003))], flat, noise=False)
    assert not plan.grasps and plan.rejected == {1: tg.TOO_LOW}
    # A block fenced in by a taller frame: the pads have nowhere to land.
    fence = [ts.Box((0.5, 0.0), (0.03, 0.03, 0.03), name="block")] + [
        ts.Box((0.5 + dx, dy), size, name="fence") for dx, dy, size in (
            (0.03, 0.0, (0.02, 0.08, 0.08)), (-0.03, 0.0, (0.02, 0.08, 0.08)),
            (0.0, 0.03, (0.04, 0.02, 0.08)), (0.0, -0.03, (0.04, 0.02, 0.08)))]
    frame = ts.render(ts.TabletopScene(tuple(fence), ts.look_at((0.5, 0.0, 0.55), (0.5, 0.0, 0.0))), seed=1)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    block = int(np.bincount(view.labels[frame.labels == 1]).argmax())
    plan = tg.plan_tabletop(view, MODEL, None, 5, targets={block})
    assert block and not plan.grasps and plan.rejected == {block: tg.COLLISION}
    # The planner's error names them.
    frame = ts.render(ts.TabletopScene((ts.Box((0.5, 0.0), (0.15, 0.13, 0.05)),), ts.look_at((0.5, 0, 0.55),
                                                                                              (0.5, 0, 0))), seed=1)
    with pytest.raises(NoFeasibleGrasp, match=r"object 1: width") as error:
        TabletopPlanner(MODEL).plan(frame.depth_m, frame.camera_k, frame.base_T_camera)
    assert error.value.rejected == {1: tg.WIDTH}
