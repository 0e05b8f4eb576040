"""The labels' grip force in the cell: the rule the weights record, the mass from the height map
(planning/grip_estimate.py), on rendered D435 frames with sensor noise against the objects' true volumes."""
import math
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.constants import GRAVITY_MPS2, OBJECT_DENSITY_KG_M3
from defgg_ros.grip_force import GripRuleError, LabelGripRule, defgraspsim_finger_force_n, grasp_force_n
from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.planning.grip_estimate import grip_estimate, object_volume_m3
from defgg_ros.planning.tabletop_planner import TabletopPlanner

MODEL = GraspPredictor.from_checkpoint(Path(__file__).resolve().parents[2] / "models" / "defgg_cnn.pt",
                                       num_threads=1)
DEFGRASPSIM = LabelGripRule("defgraspsim", 0.7)

SOLIDS = {   # object, true volume (m^3)
    "block": (ts.Box((0.5, 0.0), (0.05, 0.05, 0.05), yaw_rad=0.4), 0.05 ** 3),
    "flat box": (ts.Box((0.5, 0.0), (0.07, 0.04, 0.02)), 0.07 * 0.04 * 0.02),
    "can": (ts.Cylinder((0.5, 0.0), 0.033, 0.12), math.pi * 0.033 ** 2 * 0.12),
}


def prepared(scene, seed=0, moduli_pa=2e5):
    frame = ts.render(scene, seed=seed)
    planner = TabletopPlanner(MODEL, default_youngs_modulus_pa=moduli_pa)
    depth = frame.depth_m
    return planner.prepare(depth, frame.camera_k, frame.base_T_camera,
                           youngs_modulus_pa=np.where(np.isfinite(depth), moduli_pa, 0.0)).network


@pytest.mark.parametrize("name", SOLIDS)
def test_mass_of_a_solid_under_an_overhead_camera_is_its_volume_times_the_density(name):
    obj, volume = SOLIDS[name]
    network = prepared(ts.overhead_single(obj))
    (label,) = network.view.object_ids
    grip = grip_estimate(network, label, DEFGRASPSIM)
    assert grip.mass_kg == pytest.approx(volume * OBJECT_DENSITY_KG_M3, rel=0.15)
    assert grip.softest_modulus_pa == pytest.approx(2e5)
    assert grip.finger_force_n == pytest.approx(defgraspsim_finger_force_n(2e5, grip.mass_kg, 0.7))
    # the same object, denser: the force follows the mass
    heavy = grip_estimate(network, label, DEFGRASPSIM, density_kg_m3=2000.0)
    assert heavy.mass_kg == pytest.approx(2 * grip.mass_kg) and heavy.finger_force_n > grip.finger_force_n


def test_legacy_weights_leave_the_force_to_the_executor_but_the_mass_is_still_estimated():
    network = prepared(ts.overhead_single(SOLIDS["block"][0]))
    (label,) = network.view.object_ids
    grip = grip_estimate(network, label, LabelGripRule())
    assert grip.finger_force_n == 0.0 and grip.mass_kg > 0.1
    with pytest.raises(ValueError, match="no cell"):
        grip_estimate(network, 99, LabelGripRule())


def test_touching_objects_under_a_tilted_camera_get_their_own_masses():
    """The cluttered scene's block (50 mm cube) and sponge (80 x 60 x 30 mm) touch: each object's volume
    counts its own cells only (the tilted camera misses some far-side cells; within 30 %)."""
    scene = ts.cluttered_table()
    network = prepared(scene)
    view = network.view
    frame = ts.render(scene, seed=0)
    truth = {"rubber block": 0.05 ** 3, "sponge": 0.08 * 0.06 * 0.03}
    for name, volume in truth.items():
        image_label = [o.name for o in scene.objects].index(name) + 1
        on = (frame.labels == image_label) & (view.labels > 0)
        label = int(np.bincount(view.labels[on]).argmax())
        estimated = object_volume_m3(view.grid_height_m, view.grid_labels, label)
        assert estimated == pytest.approx(volume, rel=0.3), name


def test_the_rule_a_checkpoint_records():
    assert LabelGripRule.from_meta(None) == LabelGripRule.from_meta({}) == LabelGripRule()   # weights before it
    rule = LabelGripRule.from_meta({"label_grip_rule": {"protocol": "defgraspsim", "friction": 0.7}})
    assert rule == DEFGRASPSIM and rule.needs_mass
    assert rule.finger_force_n(2e4, 0.1) == pytest.approx((1 + math.log10(2e4) / 10) * 0.1 * GRAVITY_MPS2 / 0.7 / 2)
    assert LabelGripRule().finger_force_n(2e6) == grasp_force_n(2e6)
    with pytest.raises(GripRuleError, match="mass"):
        rule.finger_force_n(2e4, None)
    with pytest.raises(GripRuleError, match="friction"):
        LabelGripRule("defgraspsim")
    with pytest.raises(GripRuleError, match="unknown"):
        LabelGripRule.from_meta({"label_grip_rule": {"protocol": "isaac"}})
    with pytest.raises(GripRuleError, match="Young"):
        rule.finger_force_n(float("nan"), 0.1)
