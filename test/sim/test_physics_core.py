"""One physics core: the grasp trials' objects and the simulated cell's objects are the same FEM bodies, made of
the material of the protocol that labelled the shipped weights."""
import json
from pathlib import Path

import pybullet as p
import pytest

from defgg_ros.sim import objects, physics, world
from defgg_ros.sim.cell import objects as cell_objects
from defgg_ros.sim.cell import soft as cell_soft
from defgg_ros.sim.cell.sim_cell import SimCell
from defgg_ros.sim.scene_spec import SceneObject, load_scene
from defgg_ros.sim.trial import TrialSettings

pytestmark = pytest.mark.sim

ROOT = Path(__file__).resolve().parents[2]
SHIPPED_TRAINING_RECORD = ROOT / "models" / "defgg_cnn.train.json"


def shipped_weights_material() -> dict:
    """The material of the trials that labelled the shipped weights: their training record names the dataset,
    whose header records the trial settings."""
    dataset = json.loads(SHIPPED_TRAINING_RECORD.read_text())["data_source"]
    header = json.loads((ROOT / dataset / "dataset.json").read_text())
    return TrialSettings.from_record(header["generator"]["trial_settings"]).protocol.material.facts()


def test_the_cells_material_is_the_one_that_labelled_the_shipped_weights():
    material = shipped_weights_material()
    assert cell_objects.MATERIAL.facts() == material
    assert material == {"finger_friction": 1.0, "object_friction": 0.7, "effective_friction": 0.7,
                        "poisson_ratio": 0.3}


def test_a_soft_body_of_the_cell_and_of_a_trial_of_the_shipped_protocol_get_identical_parameters(client, tmp_path):
    material = shipped_weights_material()
    trial_spec = objects.ObjectSpec(objects.get_shape("box_small"), 2e5, poisson_ratio=material["poisson_ratio"])
    world.create_world(client, trial_spec.part_moduli_pa())
    trial_body = objects.load_object(client, trial_spec, friction=material["object_friction"]).parts[0]
    cell_spec = SceneObject("box_small", "box", (0.05, 0.03, 0.04), (0.3, 0.1), 0.0, 2e5,
                               mass_kg=trial_body.mass_kg)
    cell_objects.reset_world(client, deformable=True, time_step_s=physics.time_step_for([2e5]))
    soft = cell_soft.spawn_dormant(client, cell_spec, tmp_path)
    assert p.getDynamicsInfo(soft.body, -1, physicsClientId=client)[1] == pytest.approx(0.7)   # the static proxy
    cell_soft.activate(client, soft)
    trial_params = physics.loaded_parameters(client, trial_body.body_id)
    cell_params = physics.loaded_parameters(client, soft.body)
    assert trial_params == cell_params
    assert trial_params["NeoHookeanDamping"] == physics.NEO_HOOKEAN_DAMPING
    assert trial_params["frictionCoeff"] == 0.7
    assert (trial_params["NeoHookeanMu"], trial_params["NeoHookeanLambda"]) == physics.neo_hookean_lame(2e5, 0.3)


def test_rigid_objects_of_the_cell_and_of_a_trial_have_the_shipped_protocols_friction(client):
    """The cell's resting objects add rolling and spinning friction (physics.CELL_*), the trials' have none."""
    cell = SimCell(load_scene(ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"))
    try:
        info = p.getDynamicsInfo(cell.object_ids[0], -1, physicsClientId=cell.client)
        assert (info[1], info[6], info[7]) == pytest.approx(
            (0.7, physics.CELL_ROLLING_FRICTION, physics.CELL_SPINNING_FRICTION))   # lateral, rolling, spinning
        for finger in cell.finger_joints:
            assert p.getDynamicsInfo(cell.robot, finger, physicsClientId=cell.client)[1] == 1.0
    finally:
        cell.close()
    world.create_world(client, [2e9])
    spec = objects.ObjectSpec(objects.get_shape("box_small"), 2e9)
    body = objects.load_object(client, spec, friction=shipped_weights_material()["object_friction"]).body_ids[0]
    info = p.getDynamicsInfo(body, -1, physicsClientId=client)
    assert (info[1], info[6], info[7]) == pytest.approx((0.7, 0.0, 0.0))


def test_both_worlds_share_gravity_step_and_soft_step_rules(client):
    world.create_world(client, [2e6])
    trial_engine = p.getPhysicsEngineParameters(physicsClientId=client)
    cell_objects.reset_world(client, deformable=True, time_step_s=cell_objects.soft_time_step_s(2e6))
    cell_engine = p.getPhysicsEngineParameters(physicsClientId=client)
    assert trial_engine == cell_engine
    assert trial_engine["gravityAccelerationZ"] == -physics.GRAVITY_MPS2
    assert trial_engine["fixedTimeStep"] == 2.5e-4


def test_material_table_friction_is_the_product_of_both_bodies():
    assert physics.MATERIALS["legacy"].effective_friction == pytest.approx(0.64)
    assert physics.MATERIALS["defgraspsim"].effective_friction == pytest.approx(0.7)
    assert physics.MATERIALS["defgraspsim"].poisson_ratio == 0.3


def test_the_signal_reports_legacy_friction_is_the_material_tables():
    from defgg_ros.data.signal import LEGACY_EFFECTIVE_FRICTION

    assert LEGACY_EFFECTIVE_FRICTION == pytest.approx(physics.MATERIALS["legacy"].effective_friction)
