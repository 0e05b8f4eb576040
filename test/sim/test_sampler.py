"""Antipodal sampler: kept grasps do not collide (checked independently), rectangles follow format.py."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.sim import hand, objects, sampler
from defgg_ros.sim.camera import TopDownCamera
from defgg_ros.sim.trial import OPENING_CLEARANCE_M, WorldGrasp

DATASETS = Path(__file__).resolve().parents[2] / "datasets"


def _inside(mesh, points):
    """Point-in-mesh by ray parity along +x (independent of PyBullet's collision check).

    Only points inside the mesh's bounding box can be inside; the others are skipped."""
    lo, hi = mesh.bounds
    near = np.all((points >= lo) & (points <= hi), axis=1)
    tris = mesh.triangles
    return np.array([len(sampler._ray_hits(pt, np.array([1.0, 0.0, 0.0]), tris)[0]) % 2 == 1
                     for pt in points[near]], dtype=bool)


def _hand_points(grasp, spacing=0.005):
    opening = grasp.finger_opening_m()
    pose = hand.world_T_hand(grasp.position_m, grasp.yaw_rad)
    pts = []
    for centre, half in hand.hand_boxes(opening):
        axes = [np.linspace(c - h, c + h, max(2, int(2 * h / spacing) + 1)) for c, h in zip(centre, half)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        pts.append(grid @ pose[:3, :3].T + pose[:3, 3])
    return np.vstack(pts)


def _collides(mesh, grasp):
    pts = _hand_points(grasp)
    return pts[:, 2].min() < 0.0 or _inside(mesh, pts).any()


@pytest.mark.parametrize("name", ["box_small", "ycb_mug"])
def test_kept_grasps_do_not_collide_and_are_antipodal(name):
    surface = objects.get_shape(name).surface()
    kept = sampler.sample_grasps(surface, seed=1, n_candidates=40, keep=10)
    assert len(kept) >= 5
    for cand in kept:
        assert not _collides(surface, cand.grasp), cand
        p1, p2 = map(np.asarray, cand.contacts_m)
        assert np.linalg.norm(p2 - p1) == pytest.approx(cand.grasp.width_m, abs=1e-6)
        axis = np.array([math.cos(cand.grasp.yaw_rad), math.sin(cand.grasp.yaw_rad), 0.0])
        assert np.allclose((p2 - p1) / np.linalg.norm(p2 - p1), axis, atol=1e-6)


@pytest.mark.parametrize("name", ["box_small", "sphere"])
def test_executor_height_candidates_sit_where_the_executor_will_grasp(name):
    """With height_rule="executor" each TCP is at tcp_height_m of the surface seen above its centre
    (the height the cell and the evaluation derive from the depth image), the contacts are on that
    horizontal line, antipodal and collision-free; the contacts rule spreads over the object's side."""
    from defgg_ros.grasping.geometry import tcp_height_m

    surface = objects.get_shape(name).surface()
    kept = sampler.sample_grasps(surface, seed=1, n_candidates=40, keep=10, height_rule="executor")
    assert len(kept) >= 5
    for cand in kept:
        centre = np.asarray(cand.grasp.position_m)
        assert centre[2] == pytest.approx(tcp_height_m(sampler._surface_height_m(centre, surface.triangles)), abs=1e-3)
        p1, p2 = map(np.asarray, cand.contacts_m)
        assert p1[2] == pytest.approx(centre[2]) and p2[2] == pytest.approx(centre[2])
        assert np.linalg.norm(p2 - p1) == pytest.approx(cand.grasp.width_m, abs=1e-6)
        assert not _collides(surface, cand.grasp), cand
    heights = [c.grasp.position_m[2] for c in sampler.sample_grasps(surface, seed=1, n_candidates=40, keep=10)]
    assert np.ptp(heights) > 0.005
    with pytest.raises(ValueError, match="height rule"):
        sampler.sample_grasps(surface, seed=1, height_rule="middle")


def test_the_filter_removes_colliding_candidates():
    surface = objects.get_shape("ycb_mug").surface()
    raw = sampler.antipodal_pairs(surface, 100, np.random.default_rng(3))
    checker = sampler.CollisionChecker(surface)
    try:
        rejected = [c for c in raw if checker.hand_collides(c.grasp)]
    finally:
        checker.close()
    assert rejected, "the mug's walls and handle must reject some grasps"
    # most rejected grasps really put the hand into the mug or the table
    really = sum(_collides(surface, c.grasp) for c in rejected[:10])
    assert really >= 0.5 * min(10, len(rejected))


def test_sampling_is_deterministic_per_seed():
    surface = objects.get_shape("cube").surface()
    a = sampler.sample_grasps(surface, seed=7, n_candidates=30, keep=10)
    b = sampler.sample_grasps(surface, seed=7, n_candidates=30, keep=10)
    assert a and [c.grasp for c in a] == [c.grasp for c in b]


@pytest.mark.parametrize("yaw, angle", [(0.0, 0.0), (math.pi / 4, -math.pi / 4), (math.pi / 2, -math.pi / 2),
                                        (3 * math.pi / 4, math.pi / 4), (math.pi, 0.0)])
def test_rectangle_angle_convention(yaw, angle):
    rect = sampler.grasp_rect(WorldGrasp((0.0, 0.0, 0.02), yaw, 0.04))
    assert math.cos(2 * rect.angle_rad) == pytest.approx(math.cos(2 * angle), abs=1e-9)
    assert math.sin(2 * rect.angle_rad) == pytest.approx(math.sin(2 * angle), abs=1e-9)
    assert -math.pi / 2 <= rect.angle_rad <= math.pi / 2


def test_rectangle_centre_and_size_in_pixels():
    cam = TopDownCamera()
    grasp = WorldGrasp((0.03, -0.02, 0.02), 0.3, 0.05)
    rect = sampler.grasp_rect(grasp, cam)
    assert (rect.center_u_px, rect.center_v_px) == pytest.approx(tuple(cam.world_to_pixel([grasp.position_m])[0]))
    assert rect.width_px == pytest.approx(0.05 * cam.fx_px / 0.38)
    # the rectangle's width axis in the image runs along the world closing direction
    ends = cam.world_to_pixel([[0.03 + 0.025 * math.cos(0.3), -0.02 + 0.025 * math.sin(0.3), 0.02]])[0]
    along = np.array([math.cos(rect.angle_rad), math.sin(rect.angle_rad)])
    assert abs(along @ (ends - [rect.center_u_px, rect.center_v_px])) == pytest.approx(rect.width_px / 2, rel=1e-6)


# Issue 49: five training objects had no candidate at the executed height (docs/dataset.md, "Candidates").
@pytest.mark.parametrize("name", ["cone", "egad_train_08_c5", "prism_tri"])
def test_the_second_stage_gives_candidates_where_the_first_gave_none(name):
    """cone and egad_08 widen below the TCP (the fingers at width + 10 mm met them), prism_tri has no pair
    along a face normal: the second stage gives each collision-free antipodal candidates at the executor's
    height, each opened to clear the object (checked independently of PyBullet)."""
    from defgg_ros.grasping.geometry import tcp_height_m

    surface = objects.get_shape(name).surface()
    assert not sampler.sample_grasps(surface, seed=3, n_candidates=40, keep=6, height_rule="executor")
    kept = sampler.sample_grasps(surface, seed=3, n_candidates=40, keep=6, height_rule="executor", fill_short=True)
    assert len(kept) == 6
    for cand in kept:
        grasp = cand.grasp
        assert grasp.width_m < grasp.finger_opening_m() <= GRIPPER_MAX_WIDTH_M
        assert not _collides(surface, grasp), cand
        p1, p2 = map(np.asarray, cand.contacts_m)
        assert np.linalg.norm(p2 - p1) == pytest.approx(grasp.width_m, abs=1e-6)
        centre = np.asarray(grasp.position_m)
        assert centre[2] == pytest.approx(tcp_height_m(sampler._surface_height_m(centre, surface.triangles)), abs=1e-3)


@pytest.mark.parametrize("name, stored", [("egad_train_05_c3", 6), ("cube", 36)])
def test_the_first_stage_still_gives_fem_v5s_candidates(name, stored):
    """The candidates fem_v5 was labelled on come out first and in their order (an object short of them
    gets more appended), so its trials stay the trials of the sampler's candidates."""
    from defgg_ros.data.datagen import grasp_fields, object_seed

    recorded = json.loads((DATASETS / "fem_v5" / "candidates" / f"{name}.json").read_text())["candidates"]
    assert len(recorded) == stored
    kept = sampler.sample_grasps(objects.get_shape(name).surface(), object_seed(0, name), 200, keep=36,
                                 height_rule="executor", fill_short=True)
    assert len(kept) == 36
    assert [grasp_fields(c.grasp) for c in kept[:stored]] == [r["grasp"] for r in recorded]
    assert all(c.grasp.opening_m is None for c in kept[:stored])


def test_a_tall_bottle_gets_candidates_with_the_palm_above_its_top():
    """ycb_bottle (11 cm): at half the height seen the palm (4.7 cm above the TCP) met its top; the TCP rule
    now keeps the palm clear, and the first stage finds candidates."""
    surface = objects.get_shape("ycb_bottle").surface()
    kept = sampler.sample_grasps(surface, seed=3, n_candidates=40, keep=6, height_rule="executor")
    assert len(kept) == 6
    for cand in kept:
        assert not _collides(surface, cand.grasp), cand
        assert cand.grasp.position_m[2] > 0.11 - 0.047


@pytest.mark.unit
def test_a_grasp_opening_is_between_its_width_and_the_gripper():
    assert WorldGrasp((0, 0, 0.02), 0.0, 0.03).finger_opening_m() == pytest.approx(0.03 + OPENING_CLEARANCE_M)
    assert WorldGrasp((0, 0, 0.02), 0.0, 0.075).finger_opening_m() == GRIPPER_MAX_WIDTH_M
    assert WorldGrasp((0, 0, 0.02), 0.0, 0.03, opening_m=0.05).finger_opening_m() == 0.05
    for bad in (0.02, 0.081):
        with pytest.raises(ValueError, match="opening"):
            WorldGrasp((0, 0, 0.02), 0.0, 0.03, opening_m=bad)


@pytest.mark.unit
def test_the_tcp_rises_only_where_the_palm_would_meet_the_surface():
    """Half the height seen, unless the palm (4.7 cm above the TCP) would come within 1.5 mm of that surface:
    ycb_bottle (11 cm) rises from 5.5 to 6.45 cm; every evaluation object (at most common_can, 9 cm) keeps its
    height."""
    from defgg_ros.grasping.geometry import palm_above_tcp_m, tcp_height_m

    assert palm_above_tcp_m() == pytest.approx(0.047)
    assert tcp_height_m(0.11) == pytest.approx(0.11 - 0.047 + 0.0015)
    assert tcp_height_m(0.09) == pytest.approx(0.045)
    assert tcp_height_m(0.05) == pytest.approx(0.025)
    assert tcp_height_m(0.61, 0.5) == pytest.approx(0.5 + 0.11 - 0.047 + 0.0015)   # on a raised table
