"""One perceiver: planning on a view rebuilt from the segmentation node's perceived parts (planning/
perceived_frame.py) gives exactly the grasps of planning on the perception's own view, on the generated scenes."""
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.stiffness_assignment import make_entry
from defgg_ros.perception.tabletop import TabletopConfig
from defgg_ros.planning.perceived_frame import (
    check_parts_fit,
    moduli_image,
    perceive_frame,
    view_from_parts,
)
from defgg_ros.planning.tabletop_grasps import prepare_tabletop, search_tabletop

pytestmark = pytest.mark.unit
MODEL = GraspPredictor.from_checkpoint(Path(__file__).resolve().parents[2] / "models" / "defgg_cnn.pt", num_threads=1)
CONFIG = TabletopConfig()


def _scenes():
    yield "cluttered 640x480", ts.render(ts.cluttered_table(640, 480), seed=7)
    yield "cluttered 1280x720", ts.render(ts.cluttered_table(1280, 720), seed=3)
    yield "cluttered 848x480", ts.render(ts.cluttered_table(848, 480), seed=5)
    yield "drill overhead", ts.render(ts.overhead_single(ts.drill_like(), 640, 480), seed=1)


SCENES = dict(_scenes())
ENTRIES = (make_entry("soft", 2e4, (0, 0, 320, 480)), make_entry("stiff part", 5e8, (300, 200, 80, 80), True))


def _grasp_tuple(g):
    return (g.object_id, g.cell_rc, g.position_base_m, g.closing_direction_base, g.width_m, g.quality,
            g.rank_quality, g.youngs_modulus_pa)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_the_rebuilt_view_plans_the_same_grasps(name):
    frame = SCENES[name]
    parts, view, image = perceive_frame(frame.depth_m, frame.camera_k, frame.base_T_camera, CONFIG, ENTRIES)
    assert parts.objects, "the scene has objects"
    before = search_tabletop(prepare_tabletop(view, MODEL, image, 2e6), 5)
    rebuilt = view_from_parts(parts, frame.depth_m, frame.camera_k)
    np.testing.assert_array_equal(rebuilt.processed_labels, view.processed_labels)
    np.testing.assert_array_equal(rebuilt.filled_depth_m, view.filled_depth_m)
    for name in ("processed_table_depth_m", "depth_noise"):     # the free-space test's inputs, where they exist
        if hasattr(view, name):
            np.testing.assert_array_equal(np.asarray(getattr(rebuilt, name)), np.asarray(getattr(view, name)))
    if getattr(view, "config", None) is not None:
        assert rebuilt.config.workspace == view.config.workspace
    after = search_tabletop(prepare_tabletop(rebuilt, MODEL, moduli_image(parts, frame.depth_m.shape), 2e6), 5)
    assert before.grasps, "grasps to compare"
    assert [_grasp_tuple(g) for g in after.grasps] == [_grasp_tuple(g) for g in before.grasps]
    np.testing.assert_array_equal(after.quality_grid, before.quality_grid)
    # The quality image seen from the camera: the same on every labelled pixel.
    on = rebuilt.processed_labels > 0
    np.testing.assert_array_equal(rebuilt.processed_pixel_cell[on], view.processed_pixel_cell[on])


def test_the_objects_carry_their_stiffness_height_area_and_cut():
    frame = SCENES["cluttered 640x480"]
    parts, view, _ = perceive_frame(frame.depth_m, frame.camera_k, frame.base_T_camera, CONFIG, ENTRIES, 3e6)
    assert parts.object_ids == view.object_ids
    names = {o.name for o in parts.objects}
    assert {"soft", "default"} <= names
    for o in parts.objects:
        assert o.youngs_modulus_pa == (2e4 if o.name == "soft" else 3e6)
        assert 0.005 < o.height_m < 0.25 and o.area_m2 > 0 and o.area_px == int(np.sum(parts.labels == o.label))
        x, y, w, h = o.roi_px
        assert np.all(parts.labels[y:y + h, x:x + w][parts.labels[y:y + h, x:x + w] == o.label])


def test_parts_that_do_not_fit_the_depth_are_refused():
    frame = SCENES["cluttered 640x480"]
    parts, _, _ = perceive_frame(frame.depth_m, frame.camera_k, frame.base_T_camera, CONFIG)
    with pytest.raises(ValueError, match="label image is 640x480 but the depth is 848x480"):
        check_parts_fit(parts, (480, 848))
    import dataclasses

    stray = dataclasses.replace(parts, grid_labels=np.full_like(parts.grid_labels, 200))
    with pytest.raises(ValueError, match="labels \\[200\\]"):
        check_parts_fit(stray, frame.depth_m.shape)


def test_the_rebuilt_view_plans_with_the_executors_grasp_height_rule():
    """PerceivedObjects does not carry the executor's grasp height rule: the inference node passes its own
    (grasp_height_rule, grasp_depth_below_surface_m) and the grasps are those of perception's own view under
    that rule. The cluttered table's grasps differ between the rules (fingertips 5 mm under the top reach
    objects half_height finds too wide or blocked)."""
    frame = SCENES["cluttered 640x480"]
    below = TabletopConfig(grasp_height_rule="below_surface", grasp_depth_below_surface_m=0.005)
    parts, view, image = perceive_frame(frame.depth_m, frame.camera_k, frame.base_T_camera, below)
    expected = search_tabletop(prepare_tabletop(view, MODEL, image, 2e6), 5)
    moduli = moduli_image(parts, frame.depth_m.shape)
    rebuilt = view_from_parts(parts, frame.depth_m, frame.camera_k, "below_surface", 0.005)
    assert rebuilt.config.grasp_height_rule == "below_surface"
    assert rebuilt.config.grasp_depth_below_surface_m == 0.005
    after = search_tabletop(prepare_tabletop(rebuilt, MODEL, moduli, 2e6), 5)
    assert [_grasp_tuple(g) for g in after.grasps] == [_grasp_tuple(g) for g in expected.grasps]
    half = view_from_parts(parts, frame.depth_m, frame.camera_k)
    other = search_tabletop(prepare_tabletop(half, MODEL, moduli, 2e6), 5)
    assert [_grasp_tuple(g) for g in other.grasps] != [_grasp_tuple(g) for g in expected.grasps]
    with pytest.raises(ValueError, match="grasp_height_rule"):
        view_from_parts(parts, frame.depth_m, frame.camera_k, "middle")
