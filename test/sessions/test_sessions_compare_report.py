"""Comparison of replayed grasps/picks with the recording, and the diff table's verdict."""
import math

import pytest
from support.session_bag_helpers import grasp

from defgg_ros.sessions.compare import (
    GraspSummary,
    PickOutcome,
    Tolerances,
    angle_difference_rad,
    grasp_problems,
    pick_problems,
)
from defgg_ros.sessions.report import Row, diff_text, format_table, regression_message

TOL = Tolerances(position_mm=3.0, angle_deg=5.0, width_mm=3.0)


def summary(x_m=0.5, angle_rad=0.2, width_m=0.03):
    return GraspSummary.of(grasp(1, x_m, angle_rad, width_m))


@pytest.mark.parametrize("a, b, expected_deg", [
    (0.0, 0.0, 0.0), (math.pi / 2 - 0.01, -math.pi / 2 + 0.01, 1.146), (0.1, -0.1, 11.46), (1.0, 1.0 + math.pi, 0.0)])
def test_grasp_angles_are_equal_modulo_pi(a, b, expected_deg):
    assert math.degrees(angle_difference_rad(a, b)) == pytest.approx(expected_deg, abs=1e-2)


def test_within_tolerance_is_the_same_grasp():
    assert grasp_problems(summary(), summary(x_m=0.5029, angle_rad=0.2 + math.radians(4.9), width_m=0.0329), TOL) == []


@pytest.mark.parametrize("changed, words", [
    (dict(x_m=0.51), "position moved 10.0 mm"),
    (dict(angle_rad=0.2 + math.radians(20)), "angle changed 20.0 deg"),
    (dict(width_m=0.04), "width changed 10.0 mm"),
])
def test_each_difference_beyond_tolerance_is_named(changed, words):
    problems = grasp_problems(summary(), summary(**changed), TOL)
    assert len(problems) == 1 and words in problems[0]


def test_missing_and_new_grasps_are_problems():
    assert "no grasp" in grasp_problems(summary(), None, TOL)[0]
    assert "appeared" in grasp_problems(None, summary(), TOL)[0]
    assert grasp_problems(None, None, TOL) == []


def test_the_grip_a_grasp_carries_is_compared_when_both_sides_have_it():
    """Estimated mass and finger force within 10 %: the same grip; beyond: named. A recording that predates
    the fields (decoded with its own definition, no such attributes) compares the pose only."""
    def with_grip(mass_kg, force_n):
        g = grasp(1)
        g.estimated_mass_kg, g.finger_force_n = mass_kg, force_n
        return GraspSummary.of(g)

    assert grasp_problems(with_grip(0.125, 1.3), with_grip(0.13, 1.35), TOL) == []
    (problem,) = grasp_problems(with_grip(0.125, 1.3), with_grip(0.125, 2.0), TOL)
    assert "finger force changed 1.3 -> 2 N" in problem
    (problem,) = grasp_problems(with_grip(0.125, 0.0), with_grip(0.25, 0.0), TOL)
    assert "estimated mass changed 125 -> 250 g" in problem

    class Recorded:          # a grasp of an older layout: the fields it lacks are not compared
        def __init__(self, g):
            for name in ("pose_base", "angle_rad", "width_m", "quality", "center_u_px", "center_v_px"):
                setattr(self, name, getattr(g, name))

    old = GraspSummary.of(Recorded(grasp(1)))
    assert old.grip is None and grasp_problems(old, with_grip(9.0, 9.0), TOL) == []


def test_bad_tolerances_are_refused():
    with pytest.raises(ValueError, match="position_mm"):
        Tolerances(position_mm=-1.0)
    with pytest.raises(ValueError, match="angle_deg"):
        Tolerances(angle_deg=float("nan"))


def test_pick_outcome_changes_are_named():
    ok = PickOutcome(True, "done", True, "")
    dropped = PickOutcome(False, "transfer", False, "object slipped")
    problems = pick_problems(ok, dropped)
    assert "pick failed but the recording succeeded: object slipped" in problems[0]
    assert any("held after transfer False" in p for p in problems)
    assert pick_problems(ok, ok) == []
    # Where a failed pick stopped is not compared (it varies with a marginal grasp); success is.
    assert pick_problems(PickOutcome(False, "close", False, "a"), PickOutcome(False, "lift", False, "b")) == []
    assert "phase reached 'place'" in pick_problems(ok, PickOutcome(True, "place", True, ""))[0]
    assert "no pick result" in pick_problems(ok, None)[0]


def test_regression_message_names_the_frames_and_the_difference():
    rows = [Row("frame 0 @1.000s", "a", "a", diff_text(summary(), summary())),
            Row("frame 1 @2.000s", "a", "b", diff_text(summary(), summary(x_m=0.52)),
                grasp_problems(summary(), summary(x_m=0.52), TOL))]
    table = format_table("title", rows)
    assert "REGRESSION" in table.splitlines()[-1] and "d=20.0mm" in table
    message = regression_message("soft_objects", rows)
    assert "1 of 2 item(s) changed" in message
    assert "frame 1 @2.000s: position moved 20.0 mm (> 3 mm)" in message
    assert "--update soft_objects" in message
    # the replay passes the session's path: the update command then works from where it was run
    assert "--update sim_bringup/sessions/soft_objects)" in regression_message(
        "soft_objects", rows, session_path="sim_bringup/sessions/soft_objects")
    assert regression_message("s", rows[:1]) is None


def test_pure_session_modules_do_not_import_rclpy():
    import subprocess
    import sys
    modules = ["interfaces", "bag", "session", "selector", "compare", "report", "metadata", "scene_stiffness",
               "replay_graph", "replay_nodes"]
    code = ("import sys\n" + "".join(f"import defgg_ros.sessions.{m}\n" for m in modules)
            + "bad = [m for m in sys.modules if m.split('.')[0] in ('rclpy', 'torch')]\nprint(bad)\n"
            + "sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
