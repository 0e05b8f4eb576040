"""Square pad contacts on synthetic depth: a table 0.40 m below the camera, a block and a can on it."""
import math

import cv2
import numpy as np
import pytest

from defgg_ros.grasping.contact_angle import contact_scores, square_contact_angle
from defgg_ros.grasping.finger_clearance import touchable
from defgg_ros.grasping.geometry import check_camera_k
from defgg_ros.model.inference import GraspPredictor

FX = 350.0            # 1 px = 1 mm at 0.35 m, the top of the 50 mm objects below
TABLE_M = 0.40
OPENING_M = 0.08


def scene(kind: str, yaw_deg: float = 20.0, centre=(160, 120)):
    """(depth, mask) with one object: a 45 mm square block turned by yaw_deg, or a 66 mm can."""
    depth = np.full((240, 320), TABLE_M, np.float32)
    mask = np.zeros(depth.shape, np.uint8)
    if kind == "block":
        corners = cv2.boxPoints((centre, (45, 45), yaw_deg))
        cv2.fillPoly(mask, [np.rint(corners).astype(np.int32)], 1)
    else:
        cv2.circle(mask, centre, 33, 1, -1)
    depth[mask > 0] = TABLE_M - 0.05
    return depth, mask


def angle_between_deg(a_rad, b_rad):
    return abs(math.degrees((a_rad - b_rad + math.pi / 2) % math.pi - math.pi / 2))


@pytest.mark.parametrize("network_deg", [45.0, 65.0, -35.0, 10.0])
def test_a_square_block_is_grasped_across_faces_not_corners(network_deg):
    depth, mask = scene("block", yaw_deg=20.0)
    angle, u, v, score = square_contact_angle(depth, mask, 160, 120, math.radians(network_deg), OPENING_M, FX)
    # the faces are at 20 and 110 degrees; of the two, the one nearer the network's angle
    faces = [math.radians(20.0), math.radians(110.0)]
    nearest = min(faces, key=lambda f: angle_between_deg(f, math.radians(network_deg)))
    assert angle_between_deg(angle, nearest) <= 5.0 + 1e-6 and score == 1.0
    assert abs(u - 160) <= 1 and abs(v - 120) <= 1


def test_a_diagonal_scores_far_below_a_face():
    depth, mask = scene("block", yaw_deg=0.0)
    obj = touchable(depth, mask, 160, 120)
    scores, _, chord = contact_scores(obj, 160, 120, np.radians([0.0, 45.0]), FX / 0.35, 90)
    assert scores[0] == 1.0 and scores[1] < 0.5
    assert chord[1] > chord[0] * 1.3        # the diagonal: 64 mm against 45


def test_an_off_centre_grasp_on_a_can_turns_through_its_axis_and_moves_to_it():
    depth, mask = scene("can")
    # 18 mm off the axis, closing across the radius (the demo's slipped grasp)
    angle, u, v, score = square_contact_angle(depth, mask, 160 - 13, 120 + 13, math.radians(-45.0 + 90.0),
                                              OPENING_M, FX)
    radial = math.atan2(13, -13)
    assert angle_between_deg(angle, radial) <= 15.0
    assert math.hypot(u - 160, v - 120) <= 4.0 and score >= 0.7


def test_the_networks_angle_is_kept_when_it_is_already_square():
    depth, mask = scene("block", yaw_deg=0.0)
    for network in (0.02, math.pi / 2 - 0.03):
        angle, *_ = square_contact_angle(depth, mask, 160, 120, network, OPENING_M, FX)
        assert angle == pytest.approx(network)


def test_chords_wider_than_the_opening_are_never_chosen():
    depth = np.full((240, 320), TABLE_M, np.float32)
    mask = np.zeros(depth.shape, np.uint8)
    mask[105:135, 100:220] = 1        # 120 x 30 mm bar: only the 30 mm direction fits in 80 mm
    depth[mask > 0] = TABLE_M - 0.05
    angle, *_ = square_contact_angle(depth, mask, 160, 120, 0.0, OPENING_M, FX)
    assert angle_between_deg(angle, math.pi / 2) <= 5.0


def test_a_centre_off_the_objects_is_returned_unchanged():
    depth, mask = scene("can")
    assert square_contact_angle(depth, mask, 10, 10, 0.3, OPENING_M, FX)[:3] == (0.3, 10, 10)


def test_the_predictor_applies_it_when_asked(tmp_path):
    from defgg_ros.model.checkpoint import make_random_checkpoint
    predictor = GraspPredictor.from_checkpoint(make_random_checkpoint(tmp_path / "random.pt"))
    depth, mask = np.full((480, 640), TABLE_M, np.float32), np.zeros((480, 640), np.uint8)
    d, m = scene("block", yaw_deg=20.0)
    depth[120:360, 160:480], mask[120:360, 160:480] = d, m
    moduli = np.where(mask > 0, 2e6, 0.0).astype(np.float32)
    k = check_camera_k([[FX, 0, 320], [0, FX, 240], [0, 0, 1]])
    faces = [math.radians(20.0), math.radians(110.0)]
    square = predictor.predict(depth, moduli, k, mask, finger_clearance_opening_m=OPENING_M, top_k=3,
                               contact_angle=True).candidates
    plain = predictor.predict(depth, moduli, k, mask, finger_clearance_opening_m=OPENING_M, top_k=3).candidates
    assert len(square) == len(plain) == 3
    squared = 0
    for grasp, before in zip(square, plain):
        assert mask[int(grasp.center_v_px), int(grasp.center_u_px)] == 1
        if min(angle_between_deg(grasp.angle_rad, f) for f in faces) <= 5.0:
            squared += 1
        else:   # left as it was only when squaring would have slid it onto a better grasp
            assert (grasp.center_u_px, grasp.center_v_px, grasp.angle_rad) == \
                (before.center_u_px, before.center_v_px, before.angle_rad)
    assert squared >= 2 and min(angle_between_deg(square[0].angle_rad, f) for f in faces) <= 5.0
    for grasps in (plain, square):      # distinct alternatives: no two slid onto the same spot
        for i, a in enumerate(grasps):
            for b in grasps[i + 1:]:
                assert max(abs(a.center_u_px - b.center_u_px), abs(a.center_v_px - b.center_v_px)) > 10
    assert [g.quality for g in plain] == pytest.approx([g.quality for g in square])   # same peaks, same order
    # off without an opening: the step needs to know how wide the fingers open
    unchanged = predictor.predict(depth, moduli, k, mask, top_k=3, contact_angle=True).candidates
    assert [g.angle_rad for g in unchanged] == [g.angle_rad for g in predictor.predict(
        depth, moduli, k, mask, top_k=3).candidates]
