"""The pads' contact radii from the perceived height map (planning/contact_radii.py, issue 49 item 4): generated
shapes of known curvature rendered with the D435's noise, perceived as the nodes do, then the radii of a grasp
across them; and the planner's grasps carry them (TabletopGrasp.contact_radii_m)."""
import math
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.constants import PANDA_FINGERTIP_BELOW_TCP_M
from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.tabletop import perceive
from defgg_ros.planning.contact_radii import (
    FLAT_RECESSION_M,
    PadContacts,
    contact_radius_m,
    perceived_pad_contacts,
    surface_pad_contact,
)
from defgg_ros.planning.tabletop_grasps import plan_tabletop_grasps

pytestmark = pytest.mark.unit

CENTRE_XY_M = (0.5, 0.0)
# A perceived radius within this factor of the shape's: E from Hertz scales as R^(-1/2), so a factor 2 in R is
# 1.41 in E (the estimate's own model factor is 1.6). Perceived spheres read 0.6-0.85 of their radius: the
# height map's outline of a ball is ~0.5 mm out of round (the camera's pixels against the grid's cells), which
# over the pad's +-10 mm is a third of the recession.
RADIUS_FACTOR = 2.0


def perceived(obj, height_m, direction_rc=(1.0, 0.0), seed=0, details=None):
    """Render `obj` under the cell's overhead camera (0.40 m) with the D435's noise, perceive it, and take the
    radii of a grasp at its centre closing along direction_rc at half its height (the executor's rule)."""
    return perceived_contacts(obj, height_m, direction_rc, seed, details).radii_m


def perceived_contacts(obj, height_m, direction_rc=(1.0, 0.0), seed=0, details=None) -> PadContacts:
    """perceived's PadContacts (radii and line lengths)."""
    frame = ts.render(ts.overhead_single(obj, height_m=0.40), seed=seed)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    row, col = view.xy_to_cell(*CENTRE_XY_M)
    label = int(view.grid_labels[row, col])
    assert label > 0, f"{obj.name}: no object under the grasp centre"
    return perceived_pad_contacts(view.grid_height_m, view.grid_labels, label, (row, col), direction_rc,
                                  height_m / 2 - PANDA_FINGERTIP_BELOW_TCP_M, details=details)


@pytest.mark.parametrize("radius_m", [0.025, 0.03])
def test_a_sphere_reads_its_radius_at_both_pads(radius_m):
    radii = perceived(ts.Sphere((*CENTRE_XY_M, radius_m), radius_m), 2 * radius_m)
    assert len(radii) == 2
    for r in radii:
        assert radius_m / RADIUS_FACTOR <= r <= radius_m * RADIUS_FACTOR, radii


def test_a_standing_cylinders_side_is_straight_up_and_curved_across():
    """R_h the cylinder's radius, R_v straight (infinite): capped at half the width, so the contact is the radius."""
    details = {}
    radii = perceived(ts.Cylinder(CENTRE_XY_M, 0.02, 0.08), 0.08, details=details)
    assert len(radii) == 2
    for (r_h, r_v, flat), r in zip(details["pads"], radii):
        assert not flat and 0.02 / RADIUS_FACTOR <= r_h <= 0.02 * RADIUS_FACTOR and r_v > 0.1
        assert 0.02 / RADIUS_FACTOR <= r <= 0.02 * RADIUS_FACTOR


def test_a_lying_cylinder_is_straight_across_and_curved_up():
    details = {}
    radii = perceived(ts.LyingCylinder(CENTRE_XY_M, 0.02, 0.12, yaw_rad=math.pi / 2), 0.04, details=details)
    assert len(radii) == 2
    for r_h, r_v, flat in details["pads"]:
        assert not flat and r_h > 0.1 and 0.02 / 2 <= r_v <= 0.02 * RADIUS_FACTOR


@pytest.mark.parametrize("yaw_rad", [0.0, 0.3])
def test_a_box_face_is_flat(yaw_rad):
    """A box closed across its faces (turned against the height map's grid too): flat, no radii (the flat law)."""
    box = ts.Box(CENTRE_XY_M, (0.05, 0.05, 0.05), yaw_rad=yaw_rad)
    assert perceived(box, 0.05, (math.cos(yaw_rad), math.sin(yaw_rad))) == ()


def test_the_planners_grasps_carry_the_radii_curved_and_flat():
    """plan_tabletop_grasps puts them on TabletopGrasp.contact_radii_m: a ball's two, a box's none."""
    model = GraspPredictor.from_checkpoint(Path(__file__).resolve().parents[2] / "models" / "defgg_cnn.pt",
                                           num_threads=1)
    for obj, expected_m in ((ts.Sphere((*CENTRE_XY_M, 0.025), 0.025), 0.025),
                            (ts.Box(CENTRE_XY_M, (0.05, 0.04, 0.05), yaw_rad=0.2), None)):
        frame = ts.render(ts.overhead_single(obj, height_m=0.40))
        grasps = plan_tabletop_grasps(perceive(frame.depth_m, frame.camera_k, frame.base_T_camera), model, None, 1)
        assert grasps, obj.name
        radii = grasps[0].contact_radii_m
        if expected_m is None:
            assert radii == (), radii
        else:
            assert len(radii) == 2 and all(expected_m / RADIUS_FACTOR <= r <= expected_m * RADIUS_FACTOR
                                           for r in radii), radii


def test_the_surface_fit_of_the_bench():
    """surface_pad_contact (the squeeze bench's ray-cast surface): a sphere's cap reads its radius, a plane flat."""
    ys, zs = np.meshgrid(np.linspace(-0.01, 0.01, 9), np.linspace(-0.009, 0.009, 9))
    sphere_reach = np.sqrt(0.03 ** 2 - ys ** 2 - zs ** 2)
    radius, _, flat = surface_pad_contact(ys, zs, sphere_reach, 0.03)
    assert not flat and radius == pytest.approx(0.03, rel=0.05)
    radius, _, flat = surface_pad_contact(ys, zs, np.full(ys.shape, 0.02) + FLAT_RECESSION_M / 4 * (ys > 0),
                                          0.025)
    assert flat and radius == pytest.approx(0.025)


def test_a_contact_radius_is_capped_at_half_the_width():
    assert contact_radius_m(0.02, math.inf, 0.03) == pytest.approx(math.sqrt(0.02 * 0.03))
    assert contact_radius_m(0.5, 0.5, 0.03) == pytest.approx(0.03)
    assert contact_radius_m(0.01, 0.04, 0.05) == pytest.approx(0.02)


def test_a_standing_cylinder_touches_each_pad_along_a_vertical_line():
    """Straight up, curved across: a line contact at both pads, as long as the pad (18 mm: the cylinder is taller
    than the pad reaches), its radius the cylinder's (the squeeze's line law: defgg_ros/hertz.py)."""
    contacts = perceived_contacts(ts.Cylinder(CENTRE_XY_M, 0.02, 0.08), 0.08)
    assert len(contacts.line_lengths_m) == 2, contacts
    for r, length in zip(contacts.radii_m, contacts.line_lengths_m):
        assert 0.015 <= length <= 0.018 + 1e-9 and 0.02 / RADIUS_FACTOR <= r <= 0.02 * RADIUS_FACTOR, contacts


def test_a_lying_cylinder_touches_each_pad_along_a_horizontal_line():
    """Straight across (the pad's 20 mm lie along the cylinder's axis), curved up: a line contact as wide as the pad,
    its radius the cylinder's."""
    contacts = perceived_contacts(ts.LyingCylinder(CENTRE_XY_M, 0.02, 0.12, yaw_rad=math.pi / 2), 0.04)
    assert len(contacts.line_lengths_m) == 2, contacts
    for r, length in zip(contacts.radii_m, contacts.line_lengths_m):
        assert 0.018 <= length <= 0.020 + 1e-9 and 0.02 / 2 <= r <= 0.02 * RADIUS_FACTOR, contacts


def test_a_sphere_and_a_box_have_no_line_contact():
    sphere = perceived_contacts(ts.Sphere((*CENTRE_XY_M, 0.025), 0.025), 0.05)
    assert len(sphere.radii_m) == 2 and sphere.line_lengths_m == (), sphere
    assert perceived_contacts(ts.Box(CENTRE_XY_M, (0.05, 0.05, 0.05)), 0.05) == PadContacts()


def test_the_surface_fit_finds_a_cylinders_line():
    """surface_pad_contact on a vertical cylinder's side (reach independent of height): a line over the pad's
    whole height, the radius the cylinder's; a sphere's cap: a point contact (length 0)."""
    ys, zs = np.meshgrid(np.linspace(-0.01, 0.01, 9), np.linspace(-0.009, 0.009, 9))
    radius, length, flat = surface_pad_contact(ys, zs, np.sqrt(0.02 ** 2 - ys ** 2), 0.02)
    assert not flat and length == pytest.approx(0.018) and radius == pytest.approx(0.02, rel=0.1)  # a parabola's fit
    radius, length, flat = surface_pad_contact(ys, zs, np.sqrt(0.03 ** 2 - ys ** 2 - zs ** 2), 0.03)
    assert not flat and length == 0.0 and radius == pytest.approx(0.03, rel=0.05)
