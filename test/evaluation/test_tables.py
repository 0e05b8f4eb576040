"""Aggregation into the paper's tables: counts, sim failures apart, old weights ignored, targets."""
import csv
import json

from defgg_ros.atomic import write_json_atomic
from defgg_ros.evaluation import report
from defgg_ros.evaluation.figures import common_n_label
from defgg_ros.evaluation.store import ResultStore


def _rec(i, model, sha, e, success, task="shake", experiment="main", err=0.0, obj="a"):
    return {"key": f"k{i}", "experiment": experiment, "model": model, "model_sha": sha, "object": obj,
            "object_set": "common", "youngs_modulus_pa": e, "input_error_pct": err, "task": task,
            "success": success, "reused_from": None, "sim_key": f"s{i}", "cpu_s": 10.0, "input": "true"}


def _manifest(out):
    write_json_atomic(out / "run.json", {
        "command": "defgg-eval run", "commit": "x", "seed": 0, "grasps_per_object": 2, "tasks": ["shake"],
        "experiments": ["main", "sensitivity"],
        "models": {"stiff": {"sha": "S", "uses_stiffness": True, "path": "p"},
                   "base": {"sha": "B", "uses_stiffness": False, "path": "q"}},
        "objects": {"common": [{"name": "a", "moduli_pa": [2e4, 2e9]}, {"name": "b", "moduli_pa": [2e4, 2e9]}]}})


def test_tables_count_trials_and_judge_targets(tmp_path):
    _manifest(tmp_path)
    store = ResultStore(tmp_path)
    recs = [_rec(0, "stiff", "S", 2e4, True), _rec(1, "stiff", "S", 2e4, True), _rec(2, "stiff", "S", 2e9, None),
            _rec(3, "base", "B", 2e4, False), _rec(4, "base", "B", 2e9, True),
            _rec(5, "base", "OLD", 2e9, True),                       # trial of older weights: ignored
            _rec(6, "stiff", "S", 2e4, False, experiment="sensitivity", err=-60.0)]
    for r in recs:
        store.append(r)
    summary = report.write_outputs(tmp_path)
    shake = summary["tasks"]["shake"]
    assert shake["common|stiff"] == {"success_pct": 100.0, "successes": 2, "graded": 2, "sim_failed": 1,
                                     "no_grasp": 0, "expected": 8}
    assert shake["common|base"]["graded"] == 2 and shake["common|base"]["success_pct"] == 50.0
    md = (tmp_path / "tables" / "shake.md").read_text()
    assert "100.0 (2/2; 3 of 8 run; 1 sim-failed)" in md
    sens = summary["sensitivity"]["stiff"]
    assert sens["0"]["graded"] == 2 and sens["-60"]["successes"] == 0 and sens["-60"]["graded"] == 1
    assert (tmp_path / "tables" / "sensitivity.png").stat().st_size > 1000
    (target,) = summary["targets"]
    assert target["margin_pts"] == 50.0 and target["margin_met"] and not target["complete"]
    assert json.loads((tmp_path / "summary.json").read_text())["records"] == 6


def test_report_lists_each_trial_running_command_once_whatever_its_worker_count():
    from defgg_ros.evaluation.docs import distinct_commands

    commands = ["defgg-eval run --out r --workers 1 --sets common", "defgg-eval run --out r --workers=2 --sets common",
                "defgg-eval run --out r --sets adversarial --workers 2", "defgg-eval run --out r --plan-only"]
    assert distinct_commands(commands) == ["defgg-eval run --out r --sets common",
                                           "defgg-eval run --out r --sets adversarial"]


def test_success_by_rank_and_any_rank_per_view(tmp_path):
    _manifest(tmp_path)
    store = ResultStore(tmp_path)
    ranked = [  # (model, object, E, rank, success)
        ("stiff", "a", 2e4, 0, False), ("stiff", "a", 2e4, 1, True),     # view a/2e4: rank 2 saves it
        ("stiff", "b", 2e4, 0, True), ("stiff", "b", 2e4, 1, True),
        ("stiff", "a", 2e9, 0, False), ("stiff", "a", 2e9, 1, None),     # sim failure is not a success
        ("base", "a", 2e4, 0, True)]
    for i, (m, obj, e, rank, ok) in enumerate(ranked):
        store.append({**_rec(i, m, {"stiff": "S", "base": "B"}[m], e, ok, obj=obj), "rank": rank})
    store.append({**_rec(9, "stiff", "S", 2e4, False, experiment="sensitivity", err=-60.0), "rank": 0})
    report.write_outputs(tmp_path)
    rows = {(r["model"], r["rank"]): r for r in csv.DictReader(open(tmp_path / "tables" / "shake_by_rank.csv"))}
    assert (rows[("stiff", "1")]["successes"], rows[("stiff", "1")]["graded"]) == ("1", "3")
    assert (rows[("stiff", "2")]["successes"], rows[("stiff", "2")]["graded"], rows[("stiff", "2")]["sim_failed"]) \
        == ("2", "2", "1")
    anyr = rows[("stiff", "any")]
    assert (anyr["successes"], anyr["graded"], anyr["expected_trials"]) == ("2", "3", "4")
    assert rows[("base", "any")]["successes"] == "1" and rows[("base", "2")]["graded"] == "0"
    md = (tmp_path / "tables" / "shake_by_rank.md").read_text()
    assert "| common | with stiffness (stiff) | 33.3 (1/3; 3 of 4 run) |" in md


def test_sensitivity_adds_like_for_like_columns_while_ranks_are_partial(tmp_path):
    from defgg_ros.evaluation.jobs import SENSITIVITY_ERRORS_PCT

    _manifest(tmp_path)
    manifest = json.loads((tmp_path / "run.json").read_text())
    write_json_atomic(tmp_path / "run.json", {**manifest, "grasps_per_object": 3})
    store = ResultStore(tmp_path)
    i = 0
    for obj in ("a", "b"):
        for e in (2e4, 2e9):
            for rank in range(3):
                for err in SENSITIVITY_ERRORS_PCT:
                    if err != 0 and rank == 2:
                        continue                       # rank 3 so far only in the main experiment (0 %)
                    exp = "main" if err == 0 else "sensitivity"
                    ok = rank == 0 or (rank == 1 and obj == "a")
                    store.append({**_rec(i, "stiff", "S", e, ok, experiment=exp, err=float(err), obj=obj),
                                  "rank": rank})
                    i += 1
    summary = report.write_outputs(tmp_path)
    sens = summary["sensitivity"]
    assert sens["stiff"]["0"]["graded"] == 12 and sens["stiff"]["-60"]["graded"] == 8
    assert sens["stiff|ranks"]["-60"] == sens["stiff|ranks"]["0"] == {
        "success_pct": 75.0, "successes": 6, "graded": 8, "sim_failed": 0, "no_grasp": 0, "expected": 8}
    assert sens["stiff|best"]["0"]["successes"] == 4 and sens["stiff|best"]["0"]["expected"] == 4
    md = (tmp_path / "tables" / "sensitivity.md").read_text()
    assert "| +0 | 50.0 (6/12) | 75.0 (6/8) | 100.0 (4/4) |" in md
    assert "| -60 | 75.0 (6/8; 8 of 12 run) | 75.0 (6/8) | 100.0 (4/4) |" in md
    assert "success, ranks 1–2, run at every error (%)" in md and "like-for-like" in md
    rows = list(csv.DictReader(open(tmp_path / "tables" / "sensitivity.csv")))
    assert len(rows) == 3 * len(SENSITIVITY_ERRORS_PCT)
    store.append({**_rec(i, "stiff", "S", 2e4, True, experiment="sensitivity", err=-60.0, obj="a"), "rank": 2})
    assert "stiff|ranks" in report.write_outputs(tmp_path)["sensitivity"]   # one rank-3 trial: still partial
    for obj, e in (("a", 2e9), ("b", 2e4), ("b", 2e9), ("a", 2e4)):
        for err in SENSITIVITY_ERRORS_PCT:
            if err != 0 and not (obj == "a" and e == 2e4 and err == -60.0):
                i += 1
                store.append({**_rec(i, "stiff", "S", e, False, experiment="sensitivity", err=float(err), obj=obj),
                              "rank": 2})
    assert "stiff|ranks" not in report.write_outputs(tmp_path)["sensitivity"]   # all ranks run


def test_sensitivity_curve_states_one_n_in_the_legend_only_when_every_point_shares_it():
    assert common_n_label([135, 135, 135]) == ", n = 135 per point"
    assert common_n_label([135, 124, 135]) == ""


def test_a_resumed_evaluation_keeps_every_code_commit_it_ran_with(tmp_path):
    """run.json's `commits`: a folder filled by runs from several commits must not name only the last one."""
    from defgg_ros.evaluation.cli import merge_manifest
    from defgg_ros.evaluation.docs import _commits_md

    base = {"command": "defgg-eval run --out x", "models": {"m": {"sha": "s"}}, "grasps_per_object": 5, "seed": 0,
            "objects": {"common": []}, "tasks": ["shake"], "experiments": ["main"], "multimaterial_moduli_pa": []}
    path = tmp_path / report.MANIFEST_FILE
    for commit in ("aaa", "bbb", "aaa", "ccc"):
        write_json_atomic(path, merge_manifest(tmp_path, {**base, "commit": commit}))
    manifest = json.loads(path.read_text())
    assert manifest["commits"] == ["aaa", "bbb", "ccc"] and manifest["commit"] == "ccc"
    assert _commits_md(manifest) == ("Evaluation code commits: 3, one per run start that found a new one (the "
                                     "evaluation was resumed), first `aaa`, latest run `ccc` (all in `run.json`)")
    again = merge_manifest(tmp_path, {**base, "commit": "bbb"})    # back on an earlier commit: named as the latest
    assert again["commits"] == ["aaa", "bbb", "ccc"] and "latest run `bbb`" in _commits_md(again)
    assert _commits_md({"commit": "aaa"}) == "Evaluation code commit: `aaa`"     # a folder from before the list
    # Other models: a different evaluation, the list starts anew.
    other = merge_manifest(tmp_path, {**base, "commit": "ddd", "models": {"m": {"sha": "t"}}})
    assert other["commits"] == ["ddd"]
