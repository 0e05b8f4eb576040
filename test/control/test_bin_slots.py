"""The bin's slots and the recovery's drop zone (issue 48.2, 48.3)."""
import math

import pytest

from defgg_ros.control.bin_slots import BinArea, BinFull, BinSlots, check_drop_xy, default_drop_xy, slot_centres

pytestmark = pytest.mark.unit

SHIPPED_BIN = [0.19, 0.51, -0.61, -0.29]   # executor_node.yaml's bin_inner_m (the scenes' 32 cm bin)
SMALL_BIN = [0.25, 0.45, -0.55, -0.35]     # the 20 cm bin shipped before issue 48: 4 slots
WORKSPACE = [0.22, 0.85, -0.40, 0.40]


def test_slots_keep_the_pitch_and_the_wall_margin():
    for area_m, count in ((SMALL_BIN, 4), (SHIPPED_BIN, 9)):
        area = BinArea.from_list(area_m, 0.08, 0.05)
        centres = slot_centres(area)
        assert len(centres) == count
        for x, y in centres:
            assert min(x - area.x_min_m, area.x_max_m - x, y - area.y_min_m, area.y_max_m - y) >= 0.05 - 1e-9
        gaps = [math.dist(a, b) for i, a in enumerate(centres) for b in centres[:i]]
        assert min(gaps) == pytest.approx(0.08)


def test_slots_are_used_once_until_the_bin_is_reset():
    slots = BinSlots(BinArea.from_list(SMALL_BIN, 0.08, 0.05))
    taken = []
    for _ in range(4):
        index = slots.next_free()
        assert index == slots.next_free()   # asking again does not use it: only a release does
        slots.mark_used(index)
        taken.append(index)
    assert sorted(taken) == [0, 1, 2, 3]
    with pytest.raises(BinFull, match="4 slots"):
        slots.next_free()
    assert slots.reset() == 4 and slots.next_free() == 0


@pytest.mark.parametrize("bad", [([0.25, 0.45, -0.55], 0.08, 0.05), ([0.25, 0.3, -0.55, -0.35], 0.08, 0.05),
                                 (SHIPPED_BIN, 0.0, 0.05), (SHIPPED_BIN, 0.08, -0.01)])
def test_a_bin_that_cannot_hold_a_slot_is_refused(bad):
    with pytest.raises(ValueError):
        BinArea.from_list(*bad)


def test_the_default_drop_zone_is_nearest_the_observation_pose_and_away_from_the_base():
    assert default_drop_xy((0.307, 0.0), WORKSPACE, 0.30) == pytest.approx((0.307, 0.0))
    x, y = default_drop_xy((0.15, -0.05), WORKSPACE, 0.30)   # where the block ended: pushed out
    assert WORKSPACE[0] <= x <= WORKSPACE[1] and WORKSPACE[2] <= y <= WORKSPACE[3] and math.hypot(x, y) >= 0.30
    x, y = default_drop_xy((0.9, 0.6), WORKSPACE, 0.30)       # clamped into the box
    assert (x, y) == pytest.approx((0.85, 0.40))


@pytest.mark.parametrize("drop", [(0.151, -0.05), (0.9, 0.0), (0.25, 0.0)])
def test_a_drop_point_outside_the_box_or_inside_the_keep_out_is_refused(drop):
    with pytest.raises(ValueError, match="recovery_drop_xy_m"):
        check_drop_xy(drop, WORKSPACE, 0.30)


def test_the_shipped_drop_point_is_under_the_camera_and_away_from_the_base():
    import numpy as np

    from defgg_ros.control.kinematics import PandaKinematics
    from defgg_ros.ros.parameters import defaults

    p = defaults("executor_node")
    assert p["recovery_drop_xy_m"] == [0.0, 0.0]   # the default: derived, not given
    observation_xy = PandaKinematics().fk(np.array(p["observation_q_rad"]))[:2, 3]
    x, y = default_drop_xy(observation_xy, p["workspace_box_m"], p["base_keep_out_radius_m"])
    assert (x, y) == pytest.approx((0.40, 0.0), abs=1e-3) and math.hypot(x, y) >= 0.40


def test_the_shipped_bin_holds_eight_and_every_scene_has_it():
    """Issue 48.2: eight picks in a row with an empty place_pose must fit in the shipped cell's bin, so the executor's
    bin_inner_m and every shipped scene's bin are one bin, of at least 8 slots (the 20 cm bin held 4)."""
    from pathlib import Path

    import yaml

    from defgg_ros.ros.parameters import defaults

    p = defaults("executor_node")
    area = BinArea.from_list(p["bin_inner_m"], p["bin_slot_pitch_m"], p["bin_wall_margin_m"])
    assert len(slot_centres(area)) >= 8
    assert area.contains(*p["place_position_m"][:2])
    scenes = sorted((Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes").glob("*.yaml"))
    assert scenes
    for scene in scenes:
        (cx, cy), (ix, iy, _h) = (v for v in yaml.safe_load(scene.read_text())["bin"].values())
        assert [cx - ix / 2, cx + ix / 2, cy - iy / 2, cy + iy / 2] == pytest.approx(p["bin_inner_m"]), scene.name


def test_every_shipped_slot_can_be_placed_into_from_a_pick_under_the_camera():
    """The sequence's own check before the arm moves (IK at the slot, the straight guarded lowering and the retreat)
    for a 4.5 cm block picked at each corner of the camera's table area and placed into each slot."""
    import numpy as np

    from defgg_ros.constants import PANDA_READY_Q_RAD
    from defgg_ros.control.kinematics import PandaKinematics
    from defgg_ros.control.pick_place import PickPlaceSequence
    from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget, SequenceConfig
    from defgg_ros.ros.parameters import defaults

    p, kin = defaults("executor_node"), PandaKinematics()
    area = BinArea.from_list(p["bin_inner_m"], p["bin_slot_pitch_m"], p["bin_wall_margin_m"])
    q_ready = np.array(PANDA_READY_Q_RAD)
    for grasp_xy in ((0.36, 0.19), (0.66, -0.19)):
        grasp = GraspTarget((*grasp_xy, 0.045), 0.0, 0.065, 2e9)
        for x, y in slot_centres(area):
            place = PlaceTarget((x, y, p["place_position_m"][2]), None, lower_to_contact=True)
            reason = PickPlaceSequence(kin, SequenceConfig(), grasp, place).plan_failure(q_ready)
            assert reason == "", (grasp_xy, (x, y), reason)
