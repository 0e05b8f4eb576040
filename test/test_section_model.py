"""The squeeze's section law: the plane-stress FEM of the loaded section and the section from a height map."""
import math

import numpy as np
import pytest

from defgg_ros.perception.tabletop import CELL_M
from defgg_ros.planning.section_outline import perceived_section
from defgg_ros.section_model import SectionError, section_curve
from defgg_ros.squeeze import FLAT_FILL_MIN, HandCalibration, SqueezeReading, estimate_modulus

pytestmark = pytest.mark.unit

CELL = 0.002


def bar(length_m: float, width_m: float, height_m: float, rows: int = 21, cols: int = 31):
    """A bar along the closing axis centred on the middle row: (mask, heights)."""
    mask = np.zeros((rows, cols), bool)
    half_rows = int(round(width_m / CELL / 2))
    n_cols = int(round(length_m / CELL))
    mask[rows // 2 - half_rows:rows // 2 + half_rows + 1, 2:2 + n_cols] = True
    return mask, np.where(mask, height_m, 0.0)


def diamond(length_m: float, width_m: float, height_m: float, rows: int = 41, cols: int = 31):
    """A rhombus: pointed at both pads (a star prism's arms, end to end)."""
    r = (np.arange(rows) + 0.5) * CELL - rows * CELL / 2
    c = (np.arange(cols) + 0.5) * CELL - cols * CELL / 2
    mask = np.abs(c)[None, :] / (length_m / 2) + np.abs(r)[:, None] / (width_m / 2) <= 1.0
    return mask, np.where(mask, height_m, 0.0)


def test_a_bar_under_full_pads_is_a_column_of_its_cross_section():
    # 20 mm across (the pads' width), 10 mm high (under the pads' 18 mm length), 40 mm long: F = E A u / L,
    # a little stiffer with the pads holding its ends (no Poisson bulge there).
    mask, height = bar(0.04, 0.02, 0.01)
    width_m = mask.any(axis=1).sum() * CELL
    curve = section_curve(mask, height, CELL, pad_width_m=width_m + 1e-6, approaches_m=(1e-4,))
    u, f = curve.approaches_m[0], curve.force_per_pa[0]
    column = width_m * 0.01 * u / (mask.any(axis=0).sum() * CELL)
    assert 1.0 <= f / column <= 1.15


def test_pointed_ends_yield_more_than_a_bar_and_stiffen_as_the_contact_grows():
    approaches_m = (1e-4, 1e-3, 2e-2)
    bar_curve = section_curve(*bar(0.04, 0.04, 0.02, rows=21, cols=21), CELL, approaches_m=approaches_m)
    point_curve = section_curve(*diamond(0.04, 0.04, 0.02, rows=21, cols=21), CELL, approaches_m=approaches_m)
    assert all(p < b / 3 for p, b in zip(point_curve.force_per_pa[:2], bar_curve.force_per_pa[:2]))
    # a point's contact widens once the pads pass the next cells (2 mm): the secant stiffness grows (a bar's stays)
    point_secant = [f / u for f, u in zip(point_curve.force_per_pa, approaches_m)]
    bar_secant = [f / u for f, u in zip(bar_curve.force_per_pa, approaches_m)]
    assert point_secant[2] > 1.5 * point_secant[0]
    assert bar_secant[2] == pytest.approx(bar_secant[0], rel=0.01)


def test_the_fit_returns_the_modulus_the_readings_were_made_with_the_hand_taken_out():
    curve = section_curve(*diamond(0.03, 0.02, 0.03, rows=11, cols=15), CELL,
                          approaches_m=tuple(np.geomspace(5e-5, 0.03, 12)))
    hand = HandCalibration(13509.0, 9.7e-6, "test")
    true_pa, forces = 7e4, (0.5, 1.0, 1.5, 2.0)
    approach = np.interp(np.array(forces) / true_pa, curve.force_per_pa, curve.approaches_m)
    readings = [SqueezeReading(f, 0.05 - a - f / hand.stiffness_npm) for f, a in zip(forces, approach)]
    estimate = estimate_modulus(readings, 0.03, 0.03, hand=hand, width_resolution_m=1e-5, section=curve,
                                contact_radii_m=(0.004, 0.004), contact_line_lengths_m=(0.018, 0.018))
    assert estimate.contact_law == "section"
    assert estimate.youngs_modulus_pa == pytest.approx(true_pa, rel=0.02)
    assert estimate.low_pa < true_pa < estimate.high_pa
    # flat pads (no contact radii) on a body that does not fill the flat law's prism (the rhombus) read the section;
    # on one that does (a block as wide as the pads' spread), the flat law: the executor's and the bench's one rule
    assert curve.flat_fill < FLAT_FILL_MIN
    flat = estimate_modulus(readings, 0.03, 0.03, hand=hand, width_resolution_m=1e-5, section=curve)
    assert flat.contact_law == "section" and flat.youngs_modulus_pa == pytest.approx(estimate.youngs_modulus_pa)
    block = section_curve(*bar(0.03, 0.06, 0.03, rows=41), CELL, approaches_m=curve.approaches_m)
    assert block.flat_fill == pytest.approx(1.0)
    box = estimate_modulus(readings, 0.03, 0.03, hand=hand, width_resolution_m=1e-5, section=block)
    assert box.contact_law == "flat"
    forced = estimate_modulus(readings, 0.03, 0.03, hand=hand, width_resolution_m=1e-5, section=block,
                              contact_law="section")     # the bench's --section-on-flat-pads
    assert forced.contact_law == "section"
    # two point contacts keep the point law (squeeze.section_may_apply)
    points = estimate_modulus(readings, 0.03, 0.03, hand=hand, width_resolution_m=1e-5, section=curve,
                              contact_radii_m=(0.004, 0.004), contact_line_lengths_m=(0.0, 0.0))
    assert points.contact_law == "hertz"
    one_line = estimate_modulus(readings, 0.03, 0.03, hand=hand, width_resolution_m=1e-5, section=curve,
                                contact_radii_m=(0.004, 0.004), contact_line_lengths_m=(0.0, 0.018))
    assert one_line.contact_law == "section"


@pytest.mark.parametrize("mask, height, reason", [
    (np.zeros((11, 11), bool), np.zeros((11, 11)), "empty"),
    (np.arange(11)[:, None].repeat(11, axis=1) < 2, np.ones((11, 11)), "under the pads"),
    (np.ones((11, 11), bool), -np.ones((11, 11)), "positive height"),
    (np.ones((11, 11), bool), np.ones((5, 5)), "2-D mask"),
])
def test_a_section_the_model_cannot_squeeze_is_refused_with_the_reason(mask, height, reason):
    with pytest.raises(SectionError, match=reason):
        section_curve(mask, height, CELL, pad_width_m=0.004)


def height_map_with_box(length_m, width_m, height_m, yaw_rad, size=200):
    """A height map (CELL_M cells) with a box of label 1 at its centre, turned by yaw, and a box of label 2 beside
    it; rows are x, columns y (as the planner's)."""
    rc = (np.mgrid[0:size, 0:size].transpose(1, 2, 0) + 0.5 - size / 2) * CELL_M
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    along, across = rc[..., 0] * c + rc[..., 1] * s, -rc[..., 0] * s + rc[..., 1] * c
    box = (np.abs(along) <= length_m / 2) & (np.abs(across) <= width_m / 2)
    other = (np.abs(rc[..., 0]) <= 0.01) & (np.abs(rc[..., 1] - 0.07) <= 0.01)
    labels = np.where(box, 1, np.where(other, 2, 0)).astype(np.int32)
    return np.where(labels > 0, height_m, 0.0), labels, (size / 2 - 0.5, size / 2 - 0.5), (c, s)


@pytest.mark.parametrize("yaw_rad", [0.0, 0.7])
def test_the_perceived_section_is_the_object_at_the_pads_height_in_the_grasps_frame(yaw_rad):
    heights, labels, centre, direction = height_map_with_box(0.05, 0.03, 0.04, yaw_rad)
    mask, height = perceived_section(heights, labels, 1, centre, direction, tip_height_m=0.013)
    cell = 0.003
    assert mask.sum() * cell ** 2 == pytest.approx(0.05 * 0.03, rel=0.15)
    assert np.ptp(np.nonzero(mask.any(axis=0))[0]) * cell == pytest.approx(0.05, abs=2 * cell)   # along: columns
    assert np.ptp(np.nonzero(mask.any(axis=1))[0]) * cell == pytest.approx(0.03, abs=2 * cell)
    assert np.allclose(height[mask], 0.04)
    assert mask[mask.shape[0] // 2].any()          # the grasp line is the middle row
    # nothing of it stands as high as the fingertips: no section
    assert not perceived_section(heights, labels, 1, centre, direction, tip_height_m=0.05)[0].any()
