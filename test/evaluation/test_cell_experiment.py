"""The cell experiment (issue 49 item 3): its plan (paired poses, cases, evaluation objects only), its records'
resume rule, its statistics (paired margin, bootstrap over objects, sign test) and its report; one real pick
through the node graph (e2e) with a restart that must not pick again."""
import json
import math

import pytest

from defgg_ros.evaluation import cell_experiment as ce
from defgg_ros.evaluation import cell_report as cr

pytestmark = pytest.mark.unit


def pick(obj, case, index, success, **extra):
    return {"key": ce.pick_key(obj, case, index), "object": obj, "case": case, "pick": index, "success": success,
            "wall_s": 30.0, **extra}


def test_every_object_is_an_evaluation_object_with_seven_soft_and_seven_stiff():
    from defgg_ros.sim import objects as sim_objects

    sets = {sim_objects.get_shape(o.name).set_name for o in ce.OBJECTS}
    assert sets <= {"common", "adversarial"}
    assert len({o.name for o in ce.OBJECTS}) == 14
    soft = [o.youngs_modulus_pa for o in ce.OBJECTS if o.soft]
    stiff = [o.youngs_modulus_pa for o in ce.OBJECTS if not o.soft]
    assert len(soft) == 7 and all(2e4 <= e <= 2e5 for e in soft)
    assert len(stiff) == 7 and all(2e6 <= e <= 2e9 for e in stiff)


def test_a_training_object_is_refused():
    with pytest.raises(ValueError, match="evaluation objects only"):
        ce.scene_object(ce.CellObject("cube", "train", 2e9), ce.pick_pose(0, "cube", 0), "unused")


def test_the_cases_tell_the_segmentation_node_the_true_a_rigid_or_a_soft_modulus():
    obj = ce.CellObject("common_ball", "common", 2e5)
    assert [ce.input_modulus_pa(c, obj) for c in ce.CASES] == [2e5, 2e9, 2e4]
    assert ce.input_modulus_pa(ce.MEASURED, obj) == 0.0     # nothing told: the squeeze tells the node
    with pytest.raises(ValueError, match="unknown case"):
        ce.input_modulus_pa("medium", obj)


def test_a_grasp_only_case_plans_with_the_wrong_input_and_grips_as_the_true_modulus():
    ball, block = ce.CellObject("common_ball", "common", 2e5), ce.CellObject("egad_test_00_c1", "adversarial", 2e9)
    assert [ce.input_modulus_pa(c, ball) for c in ce.GRASP_ONLY_CASES] == [2e9, 2e4]
    assert [ce.grip_modulus_pa(c, ball) for c in ce.GRASP_ONLY_CASES] == [2e5, 2e5]
    assert [ce.grip_modulus_pa(c, ball) for c in (*ce.CASES, ce.MEASURED)] == [None] * 4    # as planned
    # rigid_grasp on a 2e9 Pa object is its rigid case (same plan, same grip): not run again
    plan = ce.planned_picks([ball, block], ce.GRASP_ONLY_CASES, 2)
    assert [(o.name, c) for o, c, i in plan if i == 0] == [
        ("common_ball", "rigid_grasp"), ("common_ball", "soft_grasp"), ("egad_test_00_c1", "soft_grasp")]
    assert len(ce.planned_picks(ce.OBJECTS, ce.GRASP_ONLY_CASES, 5)) == 95     # 9 not rigid + 10 not 2e4, x5


def test_grip_as_gives_the_planned_grasp_the_true_modulus_and_the_labels_force_for_it():
    from defgg_interfaces.msg import Grasp

    from defgg_ros.evaluation.cell_picks import grip_as
    from defgg_ros.grip_force import defgraspsim_finger_force_n
    from defgg_ros.model.checkpoint import load_checkpoint
    from defgg_ros.ros.share import share_path

    model = share_path("models", "defgg_cnn.pt")
    friction = load_checkpoint(model)["meta"]["label_grip_rule"]["friction"]
    grasp = Grasp(youngs_modulus_pa=2e9, estimated_mass_kg=0.05, finger_force_n=0.68)   # planned as rigid
    record = {}
    grip_as(grasp, 2e4, model, record)
    assert grasp.youngs_modulus_pa == 2e4        # the executor's closing speed follows it
    assert grasp.finger_force_n == pytest.approx(defgraspsim_finger_force_n(2e4, 0.05, friction))
    assert grasp.finger_force_n < 0.68 * 1.43 / 1.93 * 1.01      # FOS 1.43 at 2e4 Pa vs 1.93 at 2e9 Pa
    assert record["grip"] == {"youngs_modulus_pa": 2e4, "finger_force_n": grasp.finger_force_n}
    unknown_mass = Grasp(youngs_modulus_pa=2e9, estimated_mass_kg=0.0, finger_force_n=0.68)
    grip_as(unknown_mass, 2e4, model, {})
    assert unknown_mass.finger_force_n == 0.0     # no mass: the executor's own rule of the (true) modulus


def test_poses_are_seeded_per_object_and_pick_and_stay_on_the_camera_centre():
    a = ce.pick_pose(0, "common_ball", 3)
    assert a == ce.pick_pose(0, "common_ball", 3)          # the same pose for every case: paired
    assert a != ce.pick_pose(0, "common_ball", 4) and a != ce.pick_pose(1, "common_ball", 3)
    for i in range(20):
        p = ce.pick_pose(0, "common_pear", i)
        assert abs(p["x_m"] - ce.CENTRE_XY_M[0]) <= ce.MAX_OFFSET_M and abs(p["y_m"]) <= ce.MAX_OFFSET_M
        assert 0 <= p["yaw_rad"] < math.pi


def test_the_order_is_pick_major_so_a_stopped_run_holds_complete_pairs():
    objects = ce.OBJECTS[:2]
    plan = ce.planned_picks(objects, ce.CASES, 2)
    assert len(plan) == 12
    first = plan[:6]
    assert {i for _, _, i in first} == {0} and {(o.name, c) for o, c, _ in first} == {
        (o.name, c) for o in objects for c in ce.CASES}
    order = ce.run_order(ce.OBJECTS)
    assert sorted(o.name for o in order) == sorted(o.name for o in ce.OBJECTS)
    assert [o.soft for o in order] == [True, False] * 7      # a round stopped early holds both kinds


def test_resume_skips_outcomes_and_retries_a_failed_cell_at_most_twice():
    records = [pick("a", "correct", 0, True),
               {"key": ce.pick_key("a", "rigid", 0), "cell_error": "CellCallError: timed out"},
               {"key": ce.pick_key("a", "soft", 0), "cell_error": "BringupError: died"},
               {"key": ce.pick_key("a", "soft", 0), "cell_error": "BringupError: died"}]
    done = ce.finished_keys(records)
    assert ce.pick_key("a", "correct", 0) in done
    assert ce.pick_key("a", "rigid", 0) not in done       # one failure: tried again
    assert ce.pick_key("a", "soft", 0) in done            # two: given up
    assert ce.pick_key("a", "soft", 0) not in ce.finished_keys(records, max_attempts=3)   # --max-attempts 3: once more
    assert set(cr.outcomes(records)) == {ce.pick_key("a", "correct", 0)}
    assert ce.is_cell_failure("driver silent: no joint states for 2.0 s (watchdog 2.0 s)")
    assert not ce.is_cell_failure("the object slipped out of the fingers in transfer")


def test_a_squeeze_ended_by_the_simulator_makes_the_measured_pick_a_cell_failure():
    silent = "driver silent: no joint states for 1187.8 s (watchdog 60.0 s)"
    measured = {"failure_reason": "PlanGrasp: no object found", "squeeze": {"failure_reason": silent}}
    assert ce.cell_failure_of(measured) == silent
    assert ce.cell_failure_of({"failure_reason": silent}) == silent
    assert ce.cell_failure_of({"failure_reason": "object dropped during lift", "squeeze": {"failure_reason": ""}}) == ""


def test_sign_test_and_paired_margin_over_picks():
    # 3 objects x 4 picks: correct wins 5 discordant pairs, rigid 1.
    records = []
    wins = {"x": (2, 0), "y": (2, 1), "z": (1, 0)}
    for obj, (a_only, b_only) in wins.items():
        for i in range(4):
            a = i < a_only or i == 3
            b = (a_only <= i < a_only + b_only) or i == 3
            records += [pick(obj, "correct", i, a), pick(obj, "rigid", i, b)]
    c = cr.compare(records, "correct", "rigid")
    assert (c.counts.a_only, c.counts.b_only, c.counts.both, c.counts.pairs) == (5, 1, 3, 12)
    assert c.counts.margin_pts == pytest.approx(100 * 4 / 12)
    assert c.p_value == pytest.approx(2 * (1 + 6) / 2**6)     # exact two-sided: 0.21875
    # objects' nets +2, +1, +1: |sum| 4 only when all three signs agree, 2 of the 8 patterns
    assert c.nets == (2, 1, 1) and c.object_p_value == pytest.approx(0.25)
    assert c.interval_pts is None          # 3 objects where the inputs differed: too few for a bootstrap


def test_the_bootstrap_needs_enough_objects_where_the_inputs_differed():
    """One object's 1 vs 1 gave [+0.0, +0.0]: the bootstrap can only replay the few objects' margins."""
    one = {"only": [(True, False), (False, True)], "same": [(True, True)] * 4}
    assert cr.bootstrap_margin_ci(one) is None
    five = {n: [(True, False), (True, True)] for n in "abcde"}
    lo, hi = cr.bootstrap_margin_ci(five)
    assert lo == pytest.approx(50.0) == hi      # every object the same margin: nothing to resample


def test_the_bootstrap_resamples_objects_not_picks():
    # One object decides everything: resampling objects must give an interval that reaches 0 (the draws without
    # it), which resampling the 20 pairs independently would not.
    by_object = {"big": [(True, False)] * 10, **{n: [(False, True), (True, True)] for n in "abcd"}}
    lo, hi = cr.bootstrap_margin_ci(by_object)
    # pooled margin (10 - 4) / 18 = +33 points; without "big" every draw is -50, with it mostly far above
    assert lo == pytest.approx(-50.0) and hi >= 60.0
    assert cr.bootstrap_margin_ci({}) is None


def test_the_average_counts_only_sets_that_every_case_reached():
    records = [pick("a", "correct", 0, True), pick("a", "soft", 0, False),
               pick("b", "correct", 0, True)]          # b: no soft pick yet
    assert cr.complete_totals(records, ["correct", "soft"]) == ({"correct": [1, 1], "soft": [0, 1]}, 1)


def test_unpaired_picks_are_left_out_of_the_comparison():
    records = [pick("a", "correct", 0, True), pick("a", "correct", 1, True), pick("a", "soft", 0, False)]
    c = cr.compare(records, "correct", "soft")
    assert c.counts.pairs == 1 and c.counts.a_only == 1


def test_report_tables_figure_and_text_outside_the_markers_is_kept(tmp_path):
    from defgg_ros.atomic import append_jsonl

    for obj in ("common_sponge", "egad_test_00_c1"):
        for case, ok in (("correct", True), ("rigid", False), ("soft", obj == "egad_test_00_c1")):
            append_jsonl(tmp_path / ce.RECORDS_NAME, pick(obj, case, 0, ok))
    append_jsonl(tmp_path / ce.RECORDS_NAME, {"key": ce.pick_key("common_ball", "correct", 0), "cell_error": "x"})
    (tmp_path / cr.REPORT_NAME).write_text("# Cell experiment\n\nprotocol text\n", encoding="utf-8")
    body = cr.write_report(tmp_path, ce.OBJECTS, planned_picks=5)
    text = (tmp_path / cr.REPORT_NAME).read_text(encoding="utf-8")
    assert text.startswith("# Cell experiment\n\nprotocol text\n") and body in text
    assert "**6 of 210** planned" in body and "cell failures recorded (retried): 1" in body
    assert "| 1 | common_sponge | 2e+04 | 100 % (1/1) | 0 % (0/1) | 0 % (0/1) |" in body
    assert "| correct vs rigid | all | 2 | 2 | 2 / 0 | +100.0 |" in body
    assert "| | **2 complete sets** (object and pose in every case) | | 100 % (2/2) | 0 % (0/2) | 50 % (1/2) |" in body
    assert (tmp_path / cr.FIGURE_NAME).stat().st_size > 1000
    assert not (tmp_path / cr.GRASP_FIGURE_NAME).exists()      # no grasp-only run: no second figure
    cr.write_report(tmp_path, ce.OBJECTS, planned_picks=5)     # rewriting replaces the results, not appends them
    assert (tmp_path / cr.REPORT_NAME).read_text(encoding="utf-8").count("| correct vs rigid | all |") == 1


def test_the_measured_case_is_compared_with_every_input_and_its_estimates_are_tabled(tmp_path):
    from defgg_ros.atomic import append_jsonl

    assert cr.comparisons(["correct", "rigid", "soft", "measured"]) == [
        ("correct", "rigid"), ("correct", "soft"), ("correct", "measured"), ("measured", "rigid"),
        ("measured", "soft")]
    assert cr.comparisons(["correct", "rigid"]) == [("correct", "rigid")]
    for i, estimate in enumerate((1e5, 3e5, 9e5)):       # true 2e5: the third is beyond a factor 3
        append_jsonl(tmp_path / ce.RECORDS_NAME, pick("common_ball", "rigid", i, False))
        squeeze = {"success": True, "measured_youngs_modulus_pa": estimate, "rigid": False}
        append_jsonl(tmp_path / "records_measured.jsonl", pick("common_ball", "measured", i, True, squeeze=squeeze))
    body = cr.write_report(tmp_path, ce.OBJECTS, planned_picks=3)
    assert "| measured vs rigid | all | 1 | 3 | 3 / 0 | +100.0 |" in body
    assert "| common_ball | 2e+05 | 3e+05 | 1.5 | 9.00 | 2/3 | 0/3 |" in body


def test_the_squeeze_table_splits_the_estimates_by_law_and_pools_soft_and_rigid_objects(tmp_path):
    """Each squeeze is counted under the law its estimate used, per object and pooled (soft against their own
    modulus, rigid by call): the law on record (contact_law), else read off the squeeze's grasp (curved without line
    lengths on record: the point law of an earlier build; a line length: the line law; no contact radii: the flat
    law; no grasp on record: not recorded); only the laws some squeeze used get a column."""
    from defgg_ros.atomic import append_jsonl

    line_grasp = {"contact_radii_m": [0.02, 0.02], "contact_line_lengths_m": [0.0, 0.018]}
    flat_grasp = {"contact_radii_m": [], "contact_line_lengths_m": []}
    squeezes = [("common_ball", 0, 1e5, False, {}), ("common_ball", 1, 9e5, False, {"grasp": line_grasp}),
                ("common_ball", 2, 2.2e5, False, {"grasp": line_grasp, "contact_law": "section"}),
                ("common_sponge", 0, 2.5e4, False, {"grasp": line_grasp}),
                ("common_sponge", 1, 5e3, False, {"grasp": flat_grasp}),
                ("egad_test_00_c1", 0, 1.5e6, True, {"grasp": {"contact_radii_m": [0.02, 0.02]}}),
                ("egad_test_00_c1", 1, 4e5, False, {"grasp": line_grasp})]
    for obj, i, estimate, rigid, extra in squeezes:
        squeeze = {"success": True, "measured_youngs_modulus_pa": estimate, "rigid": rigid, **extra}
        append_jsonl(tmp_path / "records_measured.jsonl", pick(obj, "measured", i, True, squeeze=squeeze))
    body = cr.write_report(tmp_path, ce.OBJECTS, planned_picks=3)
    assert ("| object | true E (Pa) | median estimate (Pa) | ratio | spread | within ×3 | called rigid | flat law "
            "| point law | line law | section law | point or flat law, not recorded |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|") in body
    assert ("| common_ball | 2e+05 | 2.2e+05 | 1.1 | 9.00 | 2/3 | 0/3 | - | - | 0 / 0 / 1 | 1 / 0 / 1 "
            "| 1 / 0 / 1 |") in body
    assert "| common_sponge | 2e+04 | 2.5e+04 | 1.2 | 5.00 | 1/2 | 0/2 | 0 / 0 / 1 | - | 1 / 0 / 1 | - | - |" in body
    assert ("| egad_test_00_c1 | 2e+09 | 1.5e+06 | 0.00075 | - | 0/2 | 1/2 | - | 0 / 1 / 1 | 0 / 0 / 1 | - "
            "| - |") in body
    assert ("| **soft and 2e6 Pa objects** | | | | 0 of 2 ≤ 1.2 | | | 0 / 0 / 1 | - | 1 / 0 / 2 | 1 / 0 / 1 "
            "| 1 / 0 / 1 |") in body
    assert "| **rigid (2e9 Pa) objects** | | | | - | | | - | 0 / 1 / 1 | 0 / 0 / 1 | - | - |" in body
    recorded_only = [r for r in cr.read_records(tmp_path) if r["squeeze"].get("contact_law")]
    assert cr.squeeze_laws_present(recorded_only) == [("section", "section law")]


def test_a_rigid_verdict_is_not_counted_within_a_factor_3_even_when_its_lower_bound_is(tmp_path):
    """A squeeze called rigid carries only a lower bound; the object's "within x3" must not count it even when that
    bound lies within a factor 3 of the true modulus (the same rule as the per-law columns, _estimate_counts)."""
    from defgg_ros.atomic import append_jsonl

    for i, (estimate, rigid) in enumerate(((3e5, True), (2.5e5, False))):      # true 2e5
        squeeze = {"success": True, "measured_youngs_modulus_pa": estimate, "rigid": rigid}
        append_jsonl(tmp_path / "records_measured.jsonl", pick("common_ball", "measured", i, True, squeeze=squeeze))
    body = cr.write_report(tmp_path, ce.OBJECTS, planned_picks=2)
    assert "| common_ball | 2e+05 | 3e+05 | 1.5 | - | 1/2 | 1/2 |" in body


def test_grasp_only_picks_are_compared_with_correct_and_with_their_plain_case_and_stand_ins_fill_the_rest(
        tmp_path):
    from defgg_ros.atomic import append_jsonl

    def rec(obj, e, case, i, ok, input_pa):
        return pick(obj, case, i, ok, youngs_modulus_pa=e, input_youngs_modulus_pa=input_pa)

    plain = [rec("common_sponge", 2e4, "correct", 0, False, 2e4), rec("common_sponge", 2e4, "rigid", 0, True, 2e9),
             rec("common_sponge", 2e4, "soft", 0, False, 2e4),
             rec("egad_test_00_c1", 2e9, "correct", 0, True, 2e9), rec("egad_test_00_c1", 2e9, "rigid", 0, True, 2e9),
             rec("egad_test_00_c1", 2e9, "soft", 0, False, 2e4)]
    assert cr.with_plain_substitutes(plain) == plain        # no grasp-only run: nothing stands in
    grasp_only = [rec("common_sponge", 2e4, "rigid_grasp", 0, False, 2e9),
                  rec("egad_test_00_c1", 2e9, "soft_grasp", 0, False, 2e4)]
    filled = cr.with_plain_substitutes(plain + grasp_only)
    stand_ins = {r["key"]: r["stands_in_for"] for r in filled if "stands_in_for" in r}
    assert stand_ins == {"common_sponge|soft_grasp|0": "common_sponge|soft|0",
                         "egad_test_00_c1|rigid_grasp|0": "egad_test_00_c1|rigid|0"}
    assert cr.comparisons(["correct", "rigid", "soft", "rigid_grasp", "soft_grasp"]) == [
        ("correct", "rigid"), ("correct", "soft"), ("correct", "rigid_grasp"), ("correct", "soft_grasp"),
        ("rigid", "rigid_grasp"), ("soft", "soft_grasp")]
    for r in plain:
        append_jsonl(tmp_path / ce.RECORDS_NAME, r)
    for r in grasp_only:
        append_jsonl(tmp_path / "records_grasp_only.jsonl", r)
    body = cr.write_report(tmp_path, ce.OBJECTS, planned_picks=1)
    assert "| correct vs rigid_grasp | all | 2 | 2 | 0 / 0 | +0.0 |" in body       # the force was the difference
    # egad_test_00_c1's rigid_grasp is its rigid pick's stand-in: one pick, not a pair (it could never differ)
    assert "| rigid vs rigid_grasp | all | 1 | 1 | 1 / 0 | +100.0 |" in body
    assert [(a["key"], b["key"]) for a, b in cr.case_pairs(filled, "rigid", "rigid_grasp")] == [
        ("common_sponge|rigid|0", "common_sponge|rigid_grasp|0")]
    ran = rec("egad_test_00_c1", 2e9, "rigid_grasp", 0, False, 2e9)      # a pick that ran is not replaced by a copy
    assert [r for r in cr.with_plain_substitutes(plain + grasp_only + [ran])
            if r["key"] == "egad_test_00_c1|rigid_grasp|0"] == [ran]
    assert "**10 of 70** planned (14 objects × 5 cases" in body
    assert (tmp_path / cr.FIGURE_NAME).exists() and (tmp_path / cr.GRASP_FIGURE_NAME).stat().st_size > 1000


def test_discordant_pairs_are_split_by_whether_the_plans_chose_the_same_grasp():
    def g(x, angle):
        return {"x_m": x, "y_m": 0.0, "angle_rad": angle}

    assert cr.same_grasp({"grasp": g(0.5, 1.55)}, {"grasp": g(0.503, -1.55)})    # 3 mm, 2.4 deg across +-pi/2
    assert not cr.same_grasp({"grasp": g(0.5, 0.0)}, {"grasp": g(0.51, 0.0)})
    assert not cr.same_grasp({"grasp": g(0.5, 0.0)}, {"grasp": g(0.5, 0.5)})
    assert not cr.same_grasp({"grasp": None}, {"grasp": g(0.5, 0.0)})
    records = [pick("a", "correct", 0, True, grasp=g(0.5, 0.0)), pick("a", "soft", 0, False, grasp=g(0.5, 0.0)),
               pick("a", "correct", 1, True, grasp=g(0.5, 0.0)), pick("a", "soft", 1, False, grasp=g(0.52, 0.0)),
               pick("a", "correct", 2, False, grasp=g(0.5, 0.0)), pick("a", "soft", 2, True, grasp=g(0.52, 0.0))]
    assert cr.channel_rows(records, ["correct", "soft"]) == ["| correct vs soft | 1 | 1 / 0 | 2 | 1 / 1 |"]


def test_run_to_run_noise_counts_only_identical_inputs_run_twice():
    def rec(obj, e, case, i, ok, input_pa, **extra):
        return pick(obj, case, i, ok, youngs_modulus_pa=e, input_youngs_modulus_pa=input_pa,
                    grasp={"x_m": 0.5, "y_m": 0.0, "angle_rad": 0.0}, **extra)

    records = [rec("ring", 2e9, "correct", 0, True, 2e9), rec("ring", 2e9, "rigid", 0, False, 2e9),
               rec("ring", 2e9, "soft", 0, False, 2e4),                              # another input
               rec("sponge", 2e4, "correct", 0, True, 2e4), rec("sponge", 2e4, "soft", 0, True, 2e4),
               rec("sponge", 2e4, "rigid", 0, True, 2e9)]
    filled = cr.with_plain_substitutes(records + [rec("ring", 2e9, "soft_grasp", 0, True, 2e4)])
    assert len(cr.repeat_pairs(filled)) == 2            # the rigid_grasp stand-in is a copy, not a repeat
    assert "1 of 2 pairs ended the same way (1 discordant); the two plans chose the same grasp in 2 of 2" in \
        cr.repeat_line(records)


def test_cli_refuses_unknown_objects_and_cases(capsys):
    assert ce.main(["run", "--out", "unused", "--objects", "cube"]) == 2
    assert "not objects of the experiment" in capsys.readouterr().err
    assert ce.main(["run", "--out", "unused", "--cases", "correct,medium"]) == 2
    assert "unknown case" in capsys.readouterr().err
    assert ce.main(["run", "--out", "unused", "--cases", "correct_grasp"]) == 2     # only the wrong inputs have one
    assert "unknown case" in capsys.readouterr().err
    assert ce.main(["run", "--out", "unused", "--records", "../elsewhere.jsonl"]) == 2
    assert "--records must be a file name" in capsys.readouterr().err
    assert ce.main(["run", "--out", "unused", "--max-attempts", "0"]) == 2
    assert "--max-attempts must be >= 1" in capsys.readouterr().err


@pytest.mark.e2e
def test_one_real_pick_is_recorded_and_a_restart_does_not_pick_again(tmp_path):
    """A rigid evaluation object, the correct input, one pick through the whole node graph; then the same run
    again, which must find the pick done; then the report."""
    from defgg_ros.ros.share import share_path

    out, work = tmp_path / "out", tmp_path / "work"
    objects = [o for o in ce.OBJECTS if o.name == "egad_test_00_c1"]
    model = share_path("models", "defgg_cnn.pt")
    assert ce.run(out, work, model, 1, 0, objects, ["correct"], progress=False) == 1
    (record,) = [json.loads(line) for line in (out / ce.RECORDS_NAME).read_text().splitlines()]
    assert not record.get("cell_error"), record
    assert record["key"] == "egad_test_00_c1|correct|0" and record["input_youngs_modulus_pa"] == 2e9
    assert record["perceived_moduli_pa"] == [2e9]      # the segmentation node used the SetStiffness default
    assert isinstance(record["success"], bool) and record["success"] == (
        record["held_after_transfer"] and record["in_bin"])
    assert ce.run(out, work, model, 1, 0, objects, ["correct"], progress=False) == 0
    assert "**1 of" in cr.write_report(out, objects, planned_picks=1)


@pytest.mark.e2e
def test_the_measured_case_squeezes_first_and_the_plan_carries_the_estimate(tmp_path):
    """The fourth case on a rigid evaluation object: the executor's squeeze (measure_only) sends its estimate to
    the segmentation node, whose next frame gives the object the measurement, and the plan carries it; then the
    pick. (How close the estimate is, is the squeeze's own test: on this 2e9 Pa EGAD shape it read 4e5 Pa.)"""
    from defgg_ros.ros.share import share_path

    out, work = tmp_path / "out", tmp_path / "work"
    objects = [o for o in ce.OBJECTS if o.name == "egad_test_00_c1"]
    assert ce.run(out, work, share_path("models", "defgg_cnn.pt"), 1, 0, objects, [ce.MEASURED], progress=False,
                  records_name="records_measured.jsonl") == 1
    (record,) = [json.loads(line) for line in (out / "records_measured.jsonl").read_text().splitlines()]
    assert not record.get("cell_error"), record
    squeeze = record["squeeze"]
    assert squeeze["success"], squeeze
    moved_m = [a - b for a, b in zip(squeeze["position_after_m"], record["start_position_m"])]
    assert len(moved_m) == 3 and max(abs(c) for c in moved_m) < 0.05, moved_m   # where the pick then met it
    assert squeeze["update"].startswith("sent") and squeeze["sent_pa"] > 0, squeeze
    assert record["perceived_moduli_pa"] == [pytest.approx(squeeze["sent_pa"])]
    assert record["grasp"]["youngs_modulus_pa"] == pytest.approx(squeeze["sent_pa"])
    assert squeeze["contact_law"] in ("flat", "hertz", "hertz-line", "section"), squeeze  # the law on record
    squeezed_on = squeeze["grasp"]          # the executor's own grasp for the squeeze
    assert squeezed_on["width_m"] > 0 and len(squeezed_on["contact_radii_m"]) in (0, 2), squeezed_on
    lengths = squeezed_on["contact_line_lengths_m"]                  # point contacts, or a line at a pad
    assert len(lengths) in (0, 2) and (not lengths or len(squeezed_on["contact_radii_m"]) == 2), squeezed_on
    assert "| egad_test_00_c1 | 2e+09 |" in cr.write_report(out, objects, planned_picks=1)


def test_the_report_sets_the_grip_force_s_mass_estimate_against_the_true_mass(tmp_path):
    """The labels' grip force is FOS(E) m g / mu / 2 with the inference node's mass: the report shows that estimate
    against the cell's mass of each object (its surface's volume at the trials' density), so a slip can be told
    from a too-low mass."""
    from defgg_ros.atomic import append_jsonl

    sponge = next(o for o in ce.OBJECTS if o.name == "common_sponge")
    assert sponge.mass_kg == pytest.approx(0.162, abs=0.001)        # 9 x 6 x 3 cm of water
    for index, estimate_kg in enumerate((0.150, 0.162, 0.200)):
        append_jsonl(tmp_path / ce.RECORDS_NAME, pick("common_sponge", "correct", index, True,
                                                      grasp={"estimated_mass_kg": estimate_kg}))
    body = cr.write_report(tmp_path, ce.OBJECTS, planned_picks=3)
    assert "| common_sponge | 162.0 | 162.0 | 1.00 | 0.93 .. 1.23 | 3 |" in body


def test_a_rerun_is_compared_pick_by_pick_with_the_earlier_run(tmp_path):
    """`compare`: the picks with an outcome in both runs, how many ended the same way and chose the same grasp,
    and each that ended otherwise; a failed cell (no outcome) is left out."""
    from defgg_ros.atomic import append_jsonl

    grasp = {"x_m": 0.5, "y_m": 0.0, "angle_rad": 0.1}
    moved = {"x_m": 0.52, "y_m": 0.0, "angle_rad": 0.1}
    for folder, rows in (("earlier", [(0, True, grasp), (1, True, grasp), (2, False, grasp)]),
                         ("rerun", [(0, True, grasp), (1, False, moved), (2, False, grasp)])):
        for index, ok, g in rows:
            append_jsonl(tmp_path / folder / ce.RECORDS_NAME, pick("common_sponge", "correct", index, ok, grasp=g,
                                                                   failure_reason="" if ok else "dropped"))
    append_jsonl(tmp_path / "rerun" / ce.RECORDS_NAME, {"key": ce.pick_key("common_ball", "correct", 0),
                                                        "cell_error": "x"})
    lines = cr.rerun_lines(cr.read_records(tmp_path / "earlier"), cr.read_records(tmp_path / "rerun"))
    assert lines[0] == "the same outcome in 2 of 3 picks run in both; the same grasp in 2 of 3"
    assert lines[1:] == ["  common_sponge|correct|1: held -> missed (another grasp): dropped"]
    assert ce.main(["compare", "--out", str(tmp_path / "rerun"), "--earlier", str(tmp_path / "nothing")]) == 2


def test_the_report_joins_another_run_s_cases_at_the_same_poses_and_refuses_a_pick_in_both(tmp_path, capsys):
    """A measured-case run and the three inputs' run are separate folders: --with pairs them pick by pick."""
    from defgg_ros.atomic import append_jsonl

    measured, inputs = tmp_path / "measured", tmp_path / "inputs"
    for i, ok in enumerate((True, True, False)):
        append_jsonl(measured / "records_measured.jsonl", pick("common_ball", "measured", i, ok))
        append_jsonl(inputs / ce.RECORDS_NAME, pick("common_ball", "correct", i, False))
    alone = cr.write_report(measured, ce.OBJECTS, planned_picks=3)
    assert "| correct vs measured | all | 0 | 0 |" in alone
    joined = cr.write_report(measured, ce.OBJECTS, planned_picks=3, with_dirs=[inputs])
    assert joined.startswith(f"Joined with the records of {inputs}")
    assert "| correct vs measured | all | 1 | 3 | 0 / 2 |" in joined
    append_jsonl(inputs / "records_b.jsonl", pick("common_ball", "measured", 0, True))
    assert ce.main(["report", "--out", str(measured), "--with", str(inputs)]) == 2
    assert "common_ball|measured|0" in capsys.readouterr().err
    assert ce.main(["report", "--out", str(measured), "--with", str(tmp_path / "none")]) == 2
    assert "holds no records" in capsys.readouterr().err


def test_a_run_without_squeezes_has_no_squeeze_table(tmp_path):
    from defgg_ros.atomic import append_jsonl

    append_jsonl(tmp_path / ce.RECORDS_NAME, pick("common_ball", "correct", 0, True))
    records = cr.read_records(tmp_path)
    assert cr.squeeze_rows(records, ce.OBJECTS, cr.squeeze_laws_present(records)) == []
    assert "The squeeze's estimates" not in cr.write_report(tmp_path, ce.OBJECTS, planned_picks=1)


def test_a_pick_records_the_code_weights_and_body_it_ran_on(tmp_path):
    """Pairs across runs compared different bodies (each machine meshed the objects itself) and nothing on record
    said so: each pick now carries the commit and the weights' and body's hashes."""
    from defgg_ros.provenance import file_sha256

    model, mesh = tmp_path / "m.pt", tmp_path / "body.npz"
    model.write_bytes(b"weights")
    mesh.write_bytes(b"tets")
    ids = ce.identities({"shape": "mesh", "mesh": str(mesh)}, model)
    assert ids["model_sha256"] == file_sha256(model) and ids["mesh_sha256"] == file_sha256(mesh)
    assert ids["commit"]
    assert ce.identities({"shape": "box", "size_m": [0.05] * 3}, model)["mesh_sha256"] is None


def test_picks_on_other_bodies_or_weights_are_not_paired():
    same = [dict(pick("a", "correct", 0, True), mesh_sha256="M", model_sha256="W"),
            dict(pick("a", "rigid", 0, False), mesh_sha256="M", model_sha256="W")]
    other_body = [same[0], dict(same[1], mesh_sha256="N")]
    other_weights = [same[0], dict(same[1], model_sha256="V")]
    unrecorded = [pick("a", "correct", 0, True), pick("a", "rigid", 0, False)]
    assert cr.compare(same, "correct", "rigid").counts.pairs == 1
    assert cr.compare(other_body, "correct", "rigid").counts.pairs == 0
    assert cr.compare(other_weights, "correct", "rigid").counts.pairs == 0
    assert cr.compare(unrecorded, "correct", "rigid").counts.pairs == 1
