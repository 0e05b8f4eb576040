"""Paired comparison of the two models: pairing, the exact sign test, the margin a split would need."""
import json
import math

import pytest

from defgg_ros.atomic import write_json_atomic
from defgg_ros.evaluation import paired, report
from defgg_ros.evaluation.docs import results_markdown
from defgg_ros.evaluation.store import ResultStore


def _two_model_run(out):
    write_json_atomic(out / "run.json", {
        "command": "defgg-eval run", "commit": "c", "seed": 0, "grasps_per_object": 1, "tasks": ["shake"],
        "experiments": ["main"], "models": {"stiff": {"sha": "S", "uses_stiffness": True, "path": "p"},
                                            "base": {"sha": "B", "uses_stiffness": False, "path": "q"}},
        "objects": {"common": [{"name": n, "moduli_pa": [2e4, 2e9]} for n in ("a", "b")]}})


def _trial(i, model, sha, obj, e, rank, success, **extra):
    rec = {"key": f"k{i}", "experiment": "main", "model": model, "model_sha": sha, "object": obj,
           "object_set": "common", "youngs_modulus_pa": e, "input_error_pct": 0.0, "task": "shake", "rank": rank,
           "success": success, "reused_from": None, "sim_key": f"s{i}", "cpu_s": 1.0, "input": "true"}
    rec.update(extra)
    return rec


def test_sign_test_matches_the_binomial_tail():
    assert paired.sign_test_p(0, 0) == 1.0
    assert paired.sign_test_p(4, 0) == pytest.approx(2 / 16)
    # 13 vs 3 of 16: 2 * P(X <= 3), X ~ Bin(16, 1/2)
    tail = sum(math.comb(16, k) for k in range(4)) / 2**16
    assert paired.sign_test_p(13, 3) == pytest.approx(2 * tail)
    assert paired.sign_test_p(3, 13) == paired.sign_test_p(13, 3)
    assert paired.sign_test_p(8, 8) == 1.0


def test_margin_needed_is_the_least_uneven_significant_split():
    p = paired.Paired(both=50, a_only=9, b_only=7, neither=30)       # 16 discordant of 96
    assert p.pairs == 96 and p.margin_pts == pytest.approx(100 * 2 / 96)
    assert paired.sign_test_p(13, 3) < 0.05 <= paired.sign_test_p(12, 4)
    assert p.margin_needed_pts == pytest.approx(100 * (13 - 3) / 96)
    assert paired.Paired(both=10, a_only=4, b_only=0, neither=10).margin_needed_pts is None   # 4 cannot reach 0.05
    low, high = p.margin_ci_pts()
    assert low < p.margin_pts < high


def test_trials_pair_by_view_and_rank_and_unpaired_or_ungraded_ones_are_left_out():
    recs = [
        _trial(0, "stiff", "S", "a", 2e4, 0, True), _trial(1, "base", "B", "a", 2e4, 0, False),    # A only
        _trial(2, "stiff", "S", "a", 2e4, 1, True), _trial(3, "base", "B", "a", 2e4, 1, True),     # both
        _trial(4, "stiff", "S", "b", 2e9, 0, False), _trial(5, "base", "B", "b", 2e9, 0, True),    # B only
        _trial(6, "stiff", "S", "b", 2e4, 0, True),                                               # no partner
        _trial(7, "stiff", "S", "a", 2e9, 0, None), _trial(8, "base", "B", "a", 2e9, 0, False),    # sim failed
        _trial(9, "stiff", "S", "b", 2e4, 1, None, status="no_grasp"), _trial(10, "base", "B", "b", 2e4, 1, True),
        _trial(11, "stiff", "S", "a", 2e4, 0, False, experiment="sensitivity", input_error_pct=-60.0),
        _trial(12, "stiff", "S", "a", 2e4, 2, False, task="twist"), _trial(13, "base", "B", "a", 2e4, 2, False),
    ]
    every = paired.paired_counts(recs, "shake", "common", "stiff", "base", best_only=False)
    assert (every.both, every.a_only, every.b_only, every.neither) == (1, 1, 1, 0)
    best = paired.paired_counts(recs, "shake", "common", "stiff", "base", best_only=True)
    assert (best.both, best.a_only, best.b_only, best.neither) == (0, 1, 1, 0)


def test_report_writes_the_paired_table_and_the_results_doc_shows_it(tmp_path):
    _two_model_run(tmp_path)
    store = ResultStore(tmp_path)
    for i, (obj, e) in enumerate([("a", 2e4), ("a", 2e9), ("b", 2e4), ("b", 2e9)]):
        store.append(_trial(2 * i, "stiff", "S", obj, e, 0, True))
        store.append(_trial(2 * i + 1, "base", "B", obj, e, 0, i == 0))
    summary = report.write_outputs(tmp_path)
    best = next(r for r in summary["paired"] if r["grasps"] == paired.BEST_GRASP)
    assert (best["pairs"], best["a_only"], best["b_only"]) == (4, 3, 0)
    assert best["p_sign_test"] == pytest.approx(0.25)
    csv_text = (tmp_path / "tables" / "paired.csv").read_text()
    # 4 pairs on 2 objects: a's net +1 (2e4 and 2e9: 1 vs 0 and a draw), b's +2; the objects' test 2 of 4 sign flips
    assert csv_text.splitlines()[1].startswith("shake,common,best grasp,stiff,base,4,2,1,3,0,0,75.00,50.00,100.00,"
                                               "0.5000,0.2500")
    doc = results_markdown(tmp_path, tmp_path / "results.md")
    assert "## Are the two models separable on these trials?" in doc and "| shake | common | best grasp | 4 |" in doc
    notes = tmp_path / "notes.md"
    notes.write_text("The analysis.\n")
    with_notes = results_markdown(tmp_path, tmp_path / "results.md", notes)
    step2 = next(line for line in with_notes.splitlines() if line.startswith("2. Tables, plots"))
    assert f"--notes {notes}" in step2 and "The analysis." in with_notes   # following step 2 keeps the notes


def test_wrong_stiffness_input_pairs_with_the_correct_input_of_the_same_view_and_rank(tmp_path):
    _two_model_run(tmp_path)
    manifest = json.loads((tmp_path / "run.json").read_text())
    write_json_atomic(tmp_path / "run.json", {**manifest, "experiments": ["main", "sensitivity"]})
    sens = {"experiment": "sensitivity"}
    recs = [
        _trial(0, "stiff", "S", "a", 2e4, 0, True), _trial(1, "stiff", "S", "a", 2e4, 0, False,
                                                           input_error_pct=-60.0, **sens),       # only correct
        _trial(2, "stiff", "S", "b", 2e4, 0, False), _trial(3, "stiff", "S", "b", 2e4, 0, True,
                                                            input_error_pct=-60.0, **sens),      # only wrong
        _trial(4, "stiff", "S", "a", 2e9, 1, True), _trial(5, "stiff", "S", "a", 2e9, 1, True,
                                                           input_error_pct=-60.0, **sens),       # both
        _trial(6, "stiff", "S", "a", 2e9, 0, True, input_error_pct=-60.0, **sens),               # no partner
        _trial(7, "stiff", "S", "a", 2e4, 0, None, input_error_pct=30.0, **sens),                # sim failed
        _trial(8, "stiff", "S", "a", 2e4, 0, False, input_error_pct=30.0, **sens),
        _trial(9, "base", "B", "a", 2e4, 0, False),                                              # other model
    ]
    rows = dict(paired.sensitivity_pairs(recs, "stiff", "common"))
    assert set(rows) == {-60.0, 30.0}
    assert (rows[-60.0].both, rows[-60.0].a_only, rows[-60.0].b_only, rows[-60.0].neither) == (1, 1, 1, 0)
    assert (rows[30.0].pairs, rows[30.0].a_only) == (1, 1)
    store = ResultStore(tmp_path)
    for r in recs:
        store.append(r)
    summary = report.write_outputs(tmp_path)
    assert summary["sensitivity"]["stiff|paired"]["-60"]["pairs"] == 3
    doc = results_markdown(tmp_path, tmp_path / "results.md")
    assert "**Does a wrong stiffness input cost grasps?**" in doc and "| -60 | 3 | 1 | 1 | 1 | 0 | +0.0 |" in doc


def test_results_doc_names_the_trial_protocol_and_whether_the_labels_could_carry_the_margin(tmp_path):
    from defgg_ros.data.synthetic import write_synthetic_dataset
    from defgg_ros.evaluation.diagnose import diagnostics_markdown, label_stats
    from defgg_ros.sim.trial import TrialSettings

    _two_model_run(tmp_path)
    report.write_outputs(tmp_path)
    doc = results_markdown(tmp_path, tmp_path / "results.md")
    assert "Trial protocol: not recorded" in doc and "run `defgg-eval report --data DATASET`" in doc
    manifest = json.loads((tmp_path / "run.json").read_text())
    settings = TrialSettings.fast().to_record() | {"protocol": "defgraspsim"}
    write_json_atomic(tmp_path / "run.json", {**manifest, "trial_settings": settings})
    data = tmp_path / "data"
    write_synthetic_dataset(data, n_objects=3, trials_per_scene=5)
    labels = label_stats(data)
    write_json_atomic(tmp_path / "diagnostics.json", {"labels": labels})
    (tmp_path / "diagnostics.md").write_text(diagnostics_markdown(labels, None))   # as `report --data` writes
    doc = results_markdown(tmp_path, tmp_path / "results.md")
    assert "Trial protocol: **defgraspsim**" in doc and "the label's own criterion" in doc
    assert f"`defgg-datagen signal {data}`" in doc and doc.count("A perfect stiffness-aware choice") == 1
    assert f"`defgg-eval report --out {tmp_path} --docs {tmp_path / 'results.md'} --data {data}`" in doc


def test_pending_budget_costs_each_task_and_modulus_from_the_folders_own_simulations():
    from defgg_ros.evaluation.budget import budget_lines, pending_budget

    finished = [{"task": "shake", "youngs_modulus_pa": 2e4, "cpu_s": 30.0, "reused_from": None},
                {"task": "shake", "youngs_modulus_pa": 2e4, "cpu_s": 90.0, "reused_from": None},
                {"task": "shake", "youngs_modulus_pa": 2e4, "cpu_s": 0.0, "reused_from": "k0"}]   # reused: free
    to_run = {f"s{i}": [({"task": "shake", "youngs_modulus_pa": 2e4}, None)] for i in range(6)}
    to_run["t"] = [({"task": "twist", "youngs_modulus_pa": 2e4}, None)] * 2     # two trials, one simulation
    budget = pending_budget([{"status": "no_grasp"}], to_run, finished)
    assert budget["simulations"] == 7 and budget["settled_without_simulation"] == 1 and budget["trials"] == 9
    shake = next(c for c in budget["cells"] if c["task"] == "shake")
    assert shake["simulations"] == 6 and shake["cpu_h"] == pytest.approx(6 * 60.0 / 3600)
    assert budget["cpu_h_estimated"] == pytest.approx(0.1) and budget["cells_without_cost"] == 1
    assert budget_lines(budget)[-1] == "estimated: ~0.1 CPU-h plus 1 cell(s) without a cost"


def _adversarial_run(out, objects):
    write_json_atomic(out / "run.json", {
        "command": "defgg-eval run", "commit": "c", "seed": 0, "grasps_per_object": 3, "tasks": ["shake"],
        "experiments": ["main"], "models": {"stiff": {"sha": "S", "uses_stiffness": True, "path": "p"},
                                            "base": {"sha": "B", "uses_stiffness": False, "path": "q"}},
        "objects": {"adversarial": [{"name": n, "moduli_pa": [2e4]} for n in objects]}})
    store, i = ResultStore(out), 0
    for obj in objects:
        for rank in range(3):          # the stiffness-aware grasp holds, the baseline's does not
            store.append(_trial(i, "stiff", "S", obj, 2e4, rank, True, object_set="adversarial"))
            store.append(_trial(i + 1, "base", "B", obj, 2e4, rank, False, object_set="adversarial"))
            i += 2
    (target,) = report.write_outputs(out)["targets"]
    return target


def test_the_adversarial_target_needs_the_objects_sign_flip_test_over_the_five_best_grasps(tmp_path):
    """Six pairs all one way look significant as independent pairs (p 2/2^6), but they are the three ranks of two
    objects: only 2 of 4 sign patterns of the objects are that extreme (p 0.5), and the target is not met. Six
    objects all one way reach p 2/2^6 over objects."""
    two = _adversarial_run(tmp_path / "two", ("a", "b"))
    assert two["set"] == "adversarial" and two["p_sign_test"] == pytest.approx(2 / 2**6)
    assert two["p_objects"] == pytest.approx(0.5)
    assert two["margin_met"] and not two["sign_test_met"]
    doc = results_markdown(tmp_path / "two", tmp_path / "two" / "results.md")
    assert "objects the independent units (objects p = 0.5; as independent pairs 0.0312) | NOT met" in doc
    six = _adversarial_run(tmp_path / "six", tuple("abcdef"))
    assert six["p_objects"] == pytest.approx(2 / 2**6) and six["sign_test_met"]


def test_the_objects_sign_flip_test_is_exact_and_the_interval_resamples_objects():
    assert paired.sign_flip_p([]) == 1.0 and paired.sign_flip_p([0, 0]) == 1.0
    assert paired.sign_flip_p([3, 1, 2]) == pytest.approx(1 / 4)     # |sum| 6: only all + or all -
    # nets 2, 1, -1: sums over the 8 sign patterns +-2+-1+-1 -> 4, 2, 2, 0, 0, -2, -2, -4; |s| >= 2 in 6 of 8
    assert paired.sign_flip_p([2, 1, -1]) == pytest.approx(6 / 8)
    p = paired.Paired(both=0, a_only=4, b_only=0, neither=4,
                      objects=(("a", 4, 0, 4), ("b", 0, 0, 4)))
    low, high = p.object_interval_pts()
    assert (low, high) == (0.0, 100.0)     # drawing a twice or b twice: the only spread is which object
    assert paired.Paired(1, 0, 0, 0, objects=(("a", 0, 0, 1),)).object_interval_pts() is None


def test_every_direction_column_only_where_graded_trials_carry_it(tmp_path):
    _two_model_run(tmp_path)
    manifest = json.loads((tmp_path / "run.json").read_text())
    write_json_atomic(tmp_path / "run.json", {**manifest, "tasks": ["shake", "twist"]})
    store = ResultStore(tmp_path)
    for i, model, sha in ((0, "stiff", "S"), (1, "base", "B")):
        store.append(_trial(i, model, sha, "a", 2e4, 0, True, status="ok", success_every_direction=i == 0))
        # a twist outcome copied from another view carries the field as None (runner._reused before 2026-11-28)
        store.append(_trial(2 + i, model, sha, "a", 2e4, 0, False, status="ok", task="twist",
                            success_every_direction=None))
    (tmp_path / "tables").mkdir(exist_ok=True)
    (tmp_path / "tables" / "twist_every_direction.md").write_text("stale\n")
    summary = report.write_outputs(tmp_path)
    assert (tmp_path / "tables" / "shake_every_direction.md").exists()
    assert summary["tasks"]["shake_every_direction"]["common|stiff"]["successes"] == 1
    assert not (tmp_path / "tables" / "twist_every_direction.md").exists()
    assert "twist_every_direction" not in summary["tasks"]


def test_a_reused_outcome_copies_only_the_fields_the_original_has():
    from defgg_ros.evaluation.runner import _reused

    original = {"key": "main|x|twist", "status": "ok", "accels": [500.0], "success": True}
    rec = _reused({"key": "multimaterial|x|twist", "task": "twist"}, original)
    assert rec["success"] is True and rec["reused_from"] == "main|x|twist"
    assert "success_every_direction" not in rec


def test_a_p_value_near_the_bar_is_not_rounded_onto_it():
    rows = [("shake", "adversarial", paired.ALL_RANKS, paired.Paired(both=322, a_only=69, b_only=47, neither=41))]
    table = paired.paired_markdown(rows, "A", "B")
    assert "| 0.051 |" in table and "| 0.05 |" not in table     # sim_v5's adversarial five best: p = 0.0507
