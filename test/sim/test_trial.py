"""Grasp trials in real PyBullet FEM: stability, physics ordering, restore, twist, failures.

Kept short with fewer directions, quicker phases and a short ramp; the
settings are the same for both moduli where results are compared.
"""
import math

import numpy as np
import pytest

from defgg_ros.data.format import STATUS_LIFT_FAILED, STATUS_OK
from defgg_ros.sim import objects, trial, world
from defgg_ros.sim.trial import TrialSettings, WorldGrasp, run_grasp_trial

QUICK = TrialSettings.fast().with_fields(close_settle_s=0.05, lift_time_s=0.15, hold_time_s=0.05,
                            shake_ramp_time_s=0.3, twist_ramp_time_s=0.3, stop_when_label_decided=False,
                            confident_stop=False)
# Across the 3 cm side of the 5 x 3 x 4 cm box, 1.5 cm off-centre along its length
# (off-centre grasps separate soft from stiff most clearly, FEM notes).
OFF_CENTRE = WorldGrasp((0.015, 0.0, 0.02), math.pi / 2, 0.03)


def box(e):
    return objects.ObjectSpec(objects.get_shape("box_small"), e)


def test_rigid_box_all_16_directions_and_twist():
    out = run_grasp_trial(box(2e9), OFF_CENTRE, ("shake", "twist"), QUICK)
    assert out.status == STATUS_OK, out.note
    assert len(out.shake_accels_mps2) == 16 and all(out.shake_measured)
    assert all(0.0 <= a <= 50.0 for a in out.shake_accels_mps2)
    assert len(out.twist_accels_radps2) == 6 and all(0.0 <= a <= 500.0 for a in out.twist_accels_radps2)
    assert out.sim["soft"] == [False]


def test_soft_box_is_held_less_than_a_stiff_one():
    """The physics the network must learn: same grasp, same settings, softer = lower held acceleration."""
    settings = QUICK.with_fields(shake_directions=4)
    soft = run_grasp_trial(box(2e4), OFF_CENTRE, ("shake",), settings)
    stiff = run_grasp_trial(box(2e6), OFF_CENTRE, ("shake",), settings)
    for out in (soft, stiff):
        assert out.status == STATUS_OK, out.note       # grasped, lifted, shaken, no explosion
        assert out.sim["soft"] == [True]
    assert soft.shake_mean_mps2 < stiff.shake_mean_mps2 - 2.0, (soft.shake_accels_mps2, stiff.shake_accels_mps2)


def test_restore_between_directions_restores_the_soft_body(client):
    run = trial._Trial(client, box(2e4), OFF_CENTRE, QUICK, (0.0, 0.0), 0.0)
    run.grasp_and_lift()
    saved_nodes = run.saved[0][run.obj.soft_body_ids[0]][1]
    d = trial.shake_directions(1)[0]
    g = np.array([0, 0, -world.GRAVITY_MPS2])

    def shake_a_bit():
        run.restore()
        assert np.array_equal(run.obj.node_positions(run.obj.soft_body_ids[0]), saved_nodes)
        path = []
        for k in range(20):
            run.world.set_gravity(g - 2.0 * k * d)
            run.step(10)
            path.append(run.obj.node_positions(run.obj.soft_body_ids[0]))
        return np.array(path)

    first, second = shake_a_bit(), shake_a_bit()
    moved = np.abs(first[-1] - saved_nodes).max()
    error = np.abs(second - first).max(axis=(1, 2))     # per block of 10 steps
    # Positions are restored exactly (asserted above) and velocities zeroed; the replay then tracks
    # the first run closely at the start and drifts as the slipping contact amplifies what Bullet's
    # warm-started contact solver keeps (resetMeshData cannot reset it). Measured 2026-11-24 (AMD
    # EPYC VM): <= 21 um over the first 40 steps, ~0.3 mm after 200 (of 25.6 mm moved); on the
    # previous sessions' VM ~20 um after 200. Without the velocity reset: 1.9 mm after 10 steps,
    # 6-10 mm later.
    assert moved > 1e-4                                          # the shake did move the nodes
    assert error[:4].max() < 1e-4, error
    assert error.max() < 0.05 * moved, (error, moved)


def test_grasp_beside_the_object_is_a_failed_lift_not_a_crash():
    out = run_grasp_trial(box(2e9), WorldGrasp((0.15, 0.0, 0.02), 0.0, 0.03), ("shake",), QUICK)
    assert out.status == STATUS_LIFT_FAILED and out.shake_accels_mps2 is None


def test_explosions_are_detected(client):
    world.create_world(client, [2e4])
    loaded = objects.load_object(client, box(2e4))
    assert loaded.is_finite()
    nodes = loaded.node_positions(loaded.soft_body_ids[0])
    nodes[0] = [5.0, 0.0, 0.0]                                  # one runaway node
    import pybullet as p

    p.resetMeshData(loaded.soft_body_ids[0], vertices=nodes.tolist(), physicsClientId=client)
    assert not loaded.is_finite()


def test_label_early_stop_keeps_the_label():
    """Deciding the label early must give the label of the full run (rigid: cheap, deterministic)."""
    full = run_grasp_trial(box(2e9), OFF_CENTRE, ("shake",), QUICK)
    early = run_grasp_trial(box(2e9), OFF_CENTRE, ("shake",), QUICK.with_fields(stop_when_label_decided=True))
    assert (full.shake_mean_mps2 >= 25.0) == (early.shake_mean_mps2 >= 25.0)
    assert not all(early.shake_measured) and early.sim_steps < full.sim_steps
    n = sum(early.shake_measured)
    assert early.shake_accels_mps2[:n] == pytest.approx(full.shake_accels_mps2[:n], abs=1.0)


def test_confident_stop_waits_for_enough_directions_and_a_wide_margin():
    from defgg_ros.sim.trial import _confidently_decided
    from defgg_ros.sim.trial_settings import comparable_protocol

    assert not _confidently_decided([50.0, 50.0], 3, 20.0)          # too few directions
    assert _confidently_decided([50.0, 40.0, 35.0], 3, 20.0)        # mean 41.7 >= 25 + 11.5
    assert not _confidently_decided([50.0, 30.0, 25.0], 3, 20.0)    # mean 35.0: could still fall
    assert _confidently_decided([10.0, 12.0, 14.0, 18.0], 3, 20.0)  # mean 13.5 <= 25 - 10
    assert not _confidently_decided([10.0, 12.0, 14.0, 18.0], 4, 40.0)  # the rule of before the knobs existed
    # the surrogate's knobs only matter when it is on; absent knobs are the old rule's
    off = QUICK.to_record()
    assert comparable_protocol(off) == comparable_protocol({**off, "confident_margin_mps2": 99.0})
    on = QUICK.with_fields(confident_stop=True).to_record()
    old = {k: v for k, v in on.items() if not k.startswith("confident_m")}
    assert comparable_protocol(old) != comparable_protocol(on)
    assert comparable_protocol(old) == comparable_protocol({**on, "confident_min_directions": 4,
                                                            "confident_margin_mps2": 40.0})


def test_bad_grasps_and_tests_are_refused():
    with pytest.raises(ValueError, match="width"):
        WorldGrasp((0, 0, 0.02), 0.0, 0.2)
    with pytest.raises(ValueError, match="unknown tests"):
        run_grasp_trial(box(2e9), OFF_CENTRE, ("wiggle",))


def test_multi_material_object_rests_stably_and_a_grasp_on_its_soft_head_works():
    """Rigid handle + soft head (2e4 Pa) anchored together: no fling at rest, and it can be grasped."""
    spec = objects.ObjectSpec(objects.get_shape("mallet_mm"), 2e9, part_youngs_modulus_pa=2e4)
    head = spec.shape.tet_parts[1].nodes_m
    centre = (head.max(axis=0) + head.min(axis=0)) / 2
    grasp = WorldGrasp((float(centre[0]), 0.0, 0.02), math.pi / 2, float(np.ptp(head[:, 1])))
    out = run_grasp_trial(spec, grasp, ("shake",), QUICK.with_fields(shake_directions=2))
    assert out.status in (STATUS_OK, STATUS_LIFT_FAILED), out.note
    assert out.sim["soft"] == [False, True]


def test_multi_material_parts_do_not_fling_each_other(client):
    spec = objects.ObjectSpec(objects.get_shape("mallet_mm"), 2e9, part_youngs_modulus_pa=2e4)
    w = world.create_world(client, spec.part_moduli_pa())
    loaded = objects.load_object(client, spec)
    start = loaded.centroid_m()
    w.step(400)
    assert loaded.is_finite()
    assert np.linalg.norm(loaded.centroid_m() - start) < 0.005
