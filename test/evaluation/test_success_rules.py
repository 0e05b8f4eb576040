"""Success rules of the evaluation: the legacy every-direction shake, the defgraspsim label criterion."""
import pytest

from defgg_ros.evaluation.runner import eval_trial_settings
from defgg_ros.evaluation.tasks import TaskError, shake_success_rule, task_success

pytestmark = pytest.mark.unit


def test_mean_rule_is_the_label_criterion_and_every_is_the_strict_column():
    accels = [50.0] * 8 + [10.0] * 8          # mean 30: a positive label, yet 8 directions failed
    assert task_success("shake", "ok", accels, "mean") is True
    assert task_success("shake", "ok", accels, "every") is False
    assert task_success("shake", "lift_failed", None, "mean") is False
    assert task_success("shake", "exploded", None, "mean") is None
    with pytest.raises(TaskError, match="does not apply"):
        task_success("twist", "ok", [500.0] * 6, "mean")


def test_defgraspsim_evaluation_ramps_every_direction_to_the_label_limit_until_both_outcomes_are_certain():
    s = eval_trial_settings("defgraspsim")
    assert s.protocol.name == "defgraspsim" and shake_success_rule(s.protocol.name) == "mean"
    assert s.evaluation.shake_limit_mps2 == 50.0 and s.evaluation.shake_fail_below_mps2 is None
    assert s.generator.stop_direction_when_lost and not s.generator.stop_when_label_decided
    assert not s.generator.confident_stop
    assert s.evaluation.shake_stop_when_decided   # only once the mean AND the every-direction outcome are certain
    legacy = eval_trial_settings("legacy")
    assert legacy.evaluation.shake_limit_mps2 == 25.0 and shake_success_rule(legacy.protocol.name) == "every"


def test_outcome_fields_follow_the_protocol():
    from defgg_ros.evaluation.tasks import outcome_fields

    accels = [50.0] * 8 + [10.0] * 8
    assert outcome_fields("shake", "ok", accels, "defgraspsim") == {"success": True, "success_every_direction": False}
    assert outcome_fields("shake", "ok", accels, "legacy") == {"success": False}
    assert outcome_fields("twist", "ok", [500.0] * 6, "defgraspsim") == {"success": True}


def test_a_missing_grasp_is_a_failure_with_the_fields_of_its_task():
    # the runner's record for a grasp the model did not propose: failed, and the every-direction verdict only
    # where the task's graded trials carry one (the defgraspsim shake), not for the twist
    from defgg_ros.evaluation.tasks import STATUS_NO_GRASP, outcome_fields

    assert outcome_fields("shake", STATUS_NO_GRASP, None, "defgraspsim") == {
        "success": False, "success_every_direction": False}
    assert outcome_fields("twist", STATUS_NO_GRASP, None, "defgraspsim") == {"success": False}
    assert outcome_fields("shake", STATUS_NO_GRASP, None, "legacy") == {"success": False}
