"""Label rules (data/labels.py): positives that slip in a measured direction."""
import numpy as np
import pytest

from defgg_ros.data.format import GraspRect, TrialRecord
from defgg_ros.data.labels import height_offset_m, is_positive, slips_in_a_direction


def _trial(accels, measured=None):
    return TrialRecord(trial_id="t", scene_id="s", object_name="box", youngs_modulus_pa=2e4, candidate_index=0,
                       rect=GraspRect(150.0, 150.0, 0.0, 40.0, 20.0), position_m=[0, 0, 0], yaw_rad=0.0,
                       width_m=0.04, status="ok", shake_accels_mps2=accels,
                       sim={} if measured is None else {"shake_measured": measured})


def test_a_positive_mean_can_hide_a_direction_that_slips():
    slipping = _trial([50.0] * 8 + [10.0] + [30.0] * 7)
    assert slipping.label is True and slips_in_a_direction(slipping)
    assert not slips_in_a_direction(_trial([30.0] * 16))


def test_skipped_directions_are_not_counted():
    # Label decided after 8 directions at 50: the rest are stored as 0 and flagged unmeasured.
    decided = _trial([50.0] * 8 + [0.0] * 8, [True] * 8 + [False] * 8)
    assert decided.label is True and not slips_in_a_direction(decided)
    assert not slips_in_a_direction(_trial(None))


def test_the_strict_rule_drops_only_the_positives_seen_to_slip():
    slipping, clean = _trial([50.0] * 8 + [10.0] + [30.0] * 7), _trial([30.0] * 16)
    assert is_positive(slipping) and not is_positive(slipping, "every_direction")
    assert is_positive(clean, "every_direction")
    assert not is_positive(_trial([10.0] * 16), "every_direction")
    with pytest.raises(ValueError, match="label rule"):
        is_positive(clean, "median")


def test_height_offset_is_measured_from_the_executors_height_on_the_trials_pixel():
    """A 60 mm tall object under pixel (150, 150), the table elsewhere: the executor grasps at half
    the height seen at the pixel (30 mm), so a trial at 42 mm is 12 mm too high; a trial whose pixel
    sees the table is measured from the lowest grasp (fingertips 3 mm above the table)."""
    depth = np.full((300, 300), 0.40)
    depth[140:160, 140:160] = 0.40 - 0.06
    trial = _trial([30.0] * 16)
    trial.position_m = [0.0, 0.0, 0.042]
    assert height_offset_m(trial, depth) == pytest.approx(0.012)
    trial.rect = GraspRect(20.0, 20.0, 0.0, 40.0, 20.0)
    assert height_offset_m(trial, depth) == pytest.approx(0.042 - 0.010)
