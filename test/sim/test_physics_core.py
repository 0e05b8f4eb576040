"""One physics core: the grasp trials' objects and the simulated cell's objects are the same FEM bodies."""
import pybullet as p
import pytest

from defgg_ros.sim import cell_objects, cell_soft, objects, physics, world
from defgg_ros.sim.scene_spec import ObjectSpec as CellObjectSpec

pytestmark = pytest.mark.sim


def test_a_soft_body_of_the_cell_and_of_a_trial_get_identical_parameters(client, tmp_path):
    trial_spec = objects.ObjectSpec(objects.get_shape("box_small"), 2e5)
    world.create_world(client, trial_spec.part_moduli_pa())
    trial_body = objects.load_object(client, trial_spec).parts[0]
    cell_spec = CellObjectSpec("box_small", "box", (0.05, 0.03, 0.04), (0.3, 0.1), 0.0, 2e5,
                               mass_kg=trial_body.mass_kg, poisson_ratio=trial_spec.poisson_ratio)
    cell_objects.reset_world(client, deformable=True, time_step_s=physics.time_step_for([2e5]))
    soft = cell_soft.spawn_dormant(client, cell_spec, tmp_path)
    cell_soft.activate(client, soft)
    trial_params = physics.loaded_parameters(client, trial_body.body_id)
    cell_params = physics.loaded_parameters(client, soft.body)
    assert trial_params == cell_params
    assert trial_params["NeoHookeanDamping"] == physics.NEO_HOOKEAN_DAMPING
    assert trial_params["frictionCoeff"] == physics.DEFAULT_FRICTION


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
