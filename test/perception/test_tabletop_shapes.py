"""Segmentation of real shapes (issue 47, item 3) on generated frames (perception/tabletop_scenes.py): an object
whose parts meet above the table (a drill standing on its battery, a mug with its handle) is one object; a hollow
cup or bowl seen from above (rim, inside, inner bottom) is one object; a table curving up 1-2 cm along its far
edge makes no phantom object; dense bin clutter gets its top five grasps on at least four distinct objects.
Touching distinct objects stay apart: test_tabletop_scenes.py."""
import numpy as np
import pytest

from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.tabletop import TabletopConfig, perceive
from defgg_ros.planning.tabletop_grasps import image_projection, plan_tabletop_grasps

MODEL = GraspPredictor.from_checkpoint(__import__("pathlib").Path(__file__).resolve().parents[2] / "models" /
                                       "defgg_cnn.pt", num_threads=1)


def _segments(scene, seed=0):
    """(frame, view, per object of the scene: (the label holding most of its pixels, its share of them, the
    share of that label's pixels that are the object's))."""
    frame = ts.render(scene, seed=seed)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    found = []
    for index in range(1, len(scene.objects) + 1):
        truth = frame.labels == index
        labels = view.labels[truth]
        label = int(np.bincount(labels[labels > 0], minlength=1).argmax()) if np.any(labels > 0) else 0
        share = float(np.mean(labels == label)) if label else 0.0
        purity = float(np.mean(frame.labels[view.labels == label] == index)) if label else 0.0
        found.append((label, share, purity))
    return frame, view, found


SHAPES = {
    "drill from 0.72 m": ts.overhead_072([ts.drill_like()]),
    "drill turned from 0.72 m": ts.overhead_072([ts.drill_like(yaw_rad=0.7)]),
    "drill from 0.55 m": ts.overhead_single(ts.drill_like()),
    "drill from the tilted camera": ts.cluttered_table(objects=(ts.drill_like((0.5, 0.0)),)),
    "mug from 0.72 m": ts.overhead_072([ts.mug_like(yaw_rad=0.4)]),
    "mug from the tilted camera": ts.cluttered_table(objects=(ts.mug_like((0.5, 0.0), yaw_rad=1.2),)),
    "cup, thin bottom, from 0.72 m": ts.overhead_072([ts.HollowCylinder((0.5, 0.0), 0.035, 0.09, bottom_m=0.004)]),
    "cup, thin bottom, from 0.55 m": ts.overhead_single(ts.HollowCylinder((0.5, 0.0), 0.04, 0.09, bottom_m=0.004)),
    "cup, 12 mm bottom, from 0.72 m": ts.overhead_072([ts.HollowCylinder((0.5, 0.0), 0.03, 0.09)]),
    "bowl from 0.72 m": ts.overhead_072([ts.HollowCylinder((0.5, 0.0), 0.07, 0.05, bottom_m=0.005, name="bowl")]),
}


@pytest.mark.parametrize("name", list(SHAPES))
def test_an_object_of_several_parts_or_hollow_is_one_object(name):
    _, view, [(label, share, purity)] = _segments(SHAPES[name])
    assert len(view.object_ids) == 1, f"{name}: {len(view.object_ids)} objects"
    assert label and share > 0.7 and purity > 0.9, f"{name}: label {label} covers {share:.0%}, purity {purity:.0%}"


@pytest.mark.parametrize("rise_m", [0.012, 0.018, 0.025])
def test_a_table_curving_up_along_its_far_edge_makes_no_phantom_object(rise_m):
    objects = (ts.Box((0.5, 0.0), (0.05, 0.04, 0.04), name="block"),
               ts.Box((0.42, -0.12), (0.06, 0.04, 0.015), yaw_rad=0.4, name="low block"))
    scene = ts.overhead_072(objects, table_warp=ts.curved_table_warp(rise_m, 0.60 if rise_m > 0.02 else 0.62))
    frame, view, found = _segments(scene, seed=int(rise_m * 1000))
    assert np.any(frame.labels[:40] == 0) and np.nanmax(ts.ray_cast(scene)[0][:5]) < 0.72    # the far edge is in view
    assert len(view.object_ids) == 2, f"{len(view.object_ids)} objects"
    assert all(label and share > 0.7 for label, share, _ in found), found
    grasps = plan_tabletop_grasps(view, MODEL, None, top_k=2)
    on = {int(frame.labels[int(round(p["v_px"])), int(round(p["u_px"]))])
          for p in (image_projection(g, frame.base_T_camera, frame.camera_k) for g in grasps)}
    assert on == {1, 2}, on


def _bin_top_five(seed: int, tall_m=(0.05, 0.08), config=None) -> list:
    """The ground-truth objects the top five grasps of a bin frame land on (0: table, bin: len(small) + 1)."""
    small = ts.bin_clutter_objects(24, seed=seed, tall_m=tall_m)
    scene = ts.overhead_072(small + (ts.Compound(ts.bin_walls(), name="bin"),))
    frame = ts.render(scene, seed=seed)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera, config)
    assert len(view.object_ids) >= 12
    on = []
    for grasp in plan_tabletop_grasps(view, MODEL, None, top_k=5):
        uv = image_projection(grasp, frame.base_T_camera, frame.camera_k)
        on.append(int(frame.labels[int(round(uv["v_px"])), int(round(uv["u_px"]))]))
    return on


def _on_four_distinct_objects(on: list, distinct: int = 4) -> bool:
    return len(on) == 5 and all(1 <= label <= 24 for label in on) and len(set(on)) >= distinct    # not on the bin


# Seed 1 has three graspable objects: its fourth one (a can beside the bin wall) has a 42.6 mm grasp whose
# finger, opened to the executor's 52.6 mm, reaches 40.3 mm from the grasp's centre; the wall stands at
# 41.7 mm in the render's truth, inside the free-space test's depth-noise tolerance. Seeds 0-9: 9 of 10 bins
# have their top five on >= 4 objects (opened fully to 80 mm: 9 of 10, five distinct in 2 bins instead of 8;
# bench/bench_pre_grasp_opening.py, test_pads_sweep.py).
@pytest.mark.parametrize("seed, distinct", [(0, 4), (1, 3), (2, 4), (3, 4)])
def test_dense_bin_clutter_gets_its_top_five_grasps_on_four_distinct_objects(seed, distinct):
    """24 objects in a bin, a third of them 5-8 cm tall among 1-2 cm ones (the executor's half_height rule)."""
    on = _bin_top_five(seed)
    assert _on_four_distinct_objects(on, distinct), on


def test_bin_objects_as_tall_as_their_neighbours_with_the_below_surface_rule():
    """4-6 cm objects among 1-2 cm ones: half their height puts the fingers onto the neighbours; with the
    executor's below_surface rule (fingertips 25 mm under the top) the grasp search finds them (7 of 8 frames
    measured)."""
    config = TabletopConfig(grasp_height_rule="below_surface")
    good = [_on_four_distinct_objects(_bin_top_five(seed, (0.04, 0.06), config)) for seed in range(8)]
    assert sum(good) >= 6, good


OPENING_SINGLES = (
    ts.Box((0.52, 0.03), (0.05, 0.04, 0.05), yaw_rad=0.3, name="block"),
    ts.Box((0.48, -0.05), (0.09, 0.035, 0.03), yaw_rad=-0.7, name="bar"),
    ts.Cylinder((0.50, 0.00), 0.025, 0.07, name="wooden can"),
    ts.LyingCylinder((0.52, -0.02), 0.02, 0.18, yaw_rad=0.9, name="marker"),
    ts.Box((0.50, 0.01), (0.06, 0.04, 0.015), yaw_rad=0.4, name="low block"),
    ts.mug_like((0.50, 0.0), yaw_rad=0.4, radius_m=0.03),
)


@pytest.mark.parametrize("obj", OPENING_SINGLES, ids=[o.name for o in OPENING_SINGLES])
def test_the_opening_is_the_same_at_1280x720_848x480_and_640x360(obj):
    """The issue's three modes (640x360 included: fx 320, read whole): the best grasp's opening within 3 mm."""
    widths = []
    for w, h in ((1280, 720), (848, 480), (640, 360)):
        frame = ts.render(ts.overhead_single(obj, w, h), seed=w)
        grasps = plan_tabletop_grasps(perceive(frame.depth_m, frame.camera_k, frame.base_T_camera), MODEL, None, 1)
        assert grasps, f"{obj.name} at {w}x{h}: no grasp"
        widths.append(grasps[0].width_m)
    assert np.ptp(widths) <= 0.003, f"{obj.name}: openings {np.round(widths, 4)} m"
