"""Finger landing check on synthetic depth: a table 0.40 m below the camera and boxes on it."""
import math

import numpy as np
import pytest

from defgg_ros.grasping.finger_clearance import (
    TIP_BELOW_SURFACE_M,
    clear_centre_shift_px,
    clear_grasps_first,
    finger_footprints_px,
    fingers_clear,
)
from defgg_ros.grasping.postprocess import Grasp2D

FX = 350.0                       # 1 px = 1 mm at 0.35 m: the top of the 50 mm boxes below
TABLE_M = 0.40
OPENING_M = 0.08


def scene(*boxes):
    """(depth, mask): boxes as (u0, v0, u1, v1, height_m) pixel rectangles."""
    depth = np.full((240, 320), TABLE_M, np.float32)
    mask = np.zeros(depth.shape, np.uint8)
    for label, (u0, v0, u1, v1, h) in enumerate(boxes, start=1):
        depth[v0:v1, u0:u1] = TABLE_M - h
        mask[v0:v1, u0:u1] = label
    return depth, mask


def clear(depth, mask, u, v, angle_rad):
    return fingers_clear(depth, mask, u, v, angle_rad, float(depth[int(v), int(u)]), OPENING_M, FX)


def test_pads_stand_half_the_opening_plus_half_a_pad_from_the_centre():
    left, right = finger_footprints_px(160, 120, 0.0, OPENING_M, 0.35, FX)
    # 1 px per mm: pads centred at +-(40 + 7) px along u, 14 px thick, 20 px wide.
    assert np.allclose(right.mean(axis=0), [160 + 47, 120]) and np.allclose(left.mean(axis=0), [160 - 47, 120])
    assert np.ptp(right[:, 0]) == pytest.approx(14) and np.ptp(right[:, 1]) == pytest.approx(20)
    up_left, up_right = finger_footprints_px(160, 120, math.pi / 2, OPENING_M, 0.35, FX)
    assert np.allclose(up_right.mean(axis=0), [160, 120 + 47])


def test_a_centred_grasp_on_a_50mm_box_is_clear_and_an_off_centre_one_lands_on_it():
    depth, mask = scene((135, 95, 185, 145, 0.05))         # 50 x 50 mm box centred at (160, 120)
    assert clear(depth, mask, 160, 120, 0.0)
    assert clear(depth, mask, 160, 120, math.pi / 2)
    # Open 80 mm around a 50 mm box: up to 15 mm off along the closing line the pads pass beside it.
    assert clear(depth, mask, 147, 120, 0.0)
    assert not clear(depth, mask, 140, 120, 0.0)            # 20 mm off: the -u pad lands on its top
    assert not clear(depth, mask, 180, 120, 0.0)            # and the +u pad, 20 mm off the other way
    assert clear(depth, mask, 160, 100, 0.0)                # 20 mm off across the closing line: beside it


def test_a_neighbour_under_a_pad_blocks_only_if_it_stands_above_the_fingertip():
    tall = scene((135, 95, 185, 145, 0.05), (200, 110, 230, 130, 0.05))   # neighbour where the +u pad lands
    assert not clear(*tall, 160, 120, 0.0)
    assert clear(*tall, 160, 120, math.pi / 2)              # turned 90 deg, the pads miss it
    low_height = 0.05 - TIP_BELOW_SURFACE_M - 0.01          # its top is under the fingertip's lowest point
    low = scene((135, 95, 185, 145, 0.05), (200, 110, 230, 130, low_height))
    assert clear(*low, 160, 120, 0.0)


def test_the_table_and_pixels_off_the_image_are_never_obstacles():
    depth, mask = scene((2, 100, 30, 140, 0.02))             # a low box at the left border
    assert clear(depth, mask, 16, 120, 0.0)                  # the -u pad is off the image


def test_an_off_centre_grasp_slides_along_its_closing_line_to_the_middle_of_the_object():
    depth, mask = scene((135, 95, 185, 145, 0.05))           # box pixels u 135..184: middle 159.5
    assert clear_centre_shift_px(depth, mask, 160, 120, 0.0, OPENING_M, FX) == -0.5
    assert clear_centre_shift_px(depth, mask, 140, 120, 0.0, OPENING_M, FX) == 19.5
    assert clear_centre_shift_px(depth, mask, 180, 120, 0.0, OPENING_M, FX) == -20.5
    # A neighbour under a pad at the middle: the smallest slide that clears it instead.
    blocked = scene((135, 95, 185, 145, 0.05), (200, 110, 215, 130, 0.05))
    shift = clear_centre_shift_px(*blocked, 150, 120, 0.0, OPENING_M, FX)
    assert shift is not None and 150 + shift < 159 and clear(*blocked, 150 + shift, 120, 0.0)
    # Turned 90 deg the same grasp is already centred on its chord (the slide runs along v, not u).
    assert clear_centre_shift_px(depth, mask, 140, 120, math.pi / 2, OPENING_M, FX) == -0.5
    # A centre off every object, or a 100 mm box the 80 mm opening cannot straddle, has no clear slide.
    assert clear_centre_shift_px(depth, mask, 100, 120, 0.0, OPENING_M, FX) is None
    wide = scene((110, 95, 210, 145, 0.05))
    assert clear_centre_shift_px(*wide, 160, 120, 0.0, OPENING_M, FX) is None


def test_clear_grasps_first_slides_the_clear_able_ones_and_keeps_each_groups_order():
    depth, mask = scene((135, 95, 185, 145, 0.05), (190, 160, 290, 210, 0.05))    # a 50 mm and a 100 mm box
    grasps = [Grasp2D(240, 185, 0.0, 40.0, 0.9),     # across the wide box: no slide clears it
              Grasp2D(142, 120, 0.0, 30.0, 0.8),     # 18 mm off on the small box: slides
              Grasp2D(160, 120, 0.3, 30.0, 0.7)]     # clear where it is
    ranked, flags = clear_grasps_first(grasps, depth, mask, OPENING_M, FX)
    assert [g.quality for g in ranked] == [0.8, 0.7, 0.9] and flags == [True, True, False]
    assert (ranked[0].center_u_px, ranked[0].center_v_px) == (160, 120)     # 142 + 17.5, rounded
    assert ranked[1] == grasps[2] and ranked[2] == grasps[0]
    # Asked for one clear grasp, the search stops at the first: same head, the rest unchecked.
    ranked_1, flags_1 = clear_grasps_first(grasps, depth, mask, OPENING_M, FX, needed=1)
    assert ranked_1[0] == ranked[0] and flags_1 == [True, False, None]
    assert ranked_1[1:] == [grasps[0], grasps[2]]
    assert clear_grasps_first(grasps, depth, mask, OPENING_M, FX, needed=2) == (ranked, flags)
    # The first grasp slides onto (160, 120), where the third already is: with apart_px it is dropped.
    apart, apart_flags = clear_grasps_first(grasps, depth, mask, OPENING_M, FX, apart_px=10)
    assert [g.quality for g in apart] == [0.8, 0.9] and apart_flags == [True, False]


def test_bad_geometry_is_refused():
    with pytest.raises(ValueError, match="> 0"):
        finger_footprints_px(10, 10, 0.0, OPENING_M, 0.0, FX)


def test_the_slide_search_checks_every_shift_like_fingers_clear():
    """clear_after_shifts (one pass over all shifts) agrees with fingers_clear shift by shift."""
    from defgg_ros.grasping.finger_clearance import clear_after_shifts
    depth, mask = scene((135, 95, 185, 145, 0.05), (192, 100, 230, 140, 0.07), (90, 110, 128, 135, 0.03))
    rng = np.random.default_rng(0)
    for _ in range(40):
        u, v = int(rng.integers(136, 184)), int(rng.integers(96, 144))
        angle = float(rng.uniform(-math.pi / 2, math.pi / 2))
        shifts = list(range(-60, 61, 3))
        fast = clear_after_shifts(depth, mask, u, v, angle, shifts, OPENING_M, FX)
        assert len(fast) == len(shifts)
        for k, got in zip(shifts, fast):
            cu, cv = int(round(u + k * math.cos(angle))), int(round(v + k * math.sin(angle)))
            on_box = 0 <= cu < 320 and 0 <= cv < 240 and mask[cv, cu] == mask[v, u]
            assert got == (on_box and clear(depth, mask, cu, cv, angle)), (u, v, angle, k)
