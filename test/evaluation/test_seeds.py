"""The seed study's report (evaluation/seeds.py, defgg-eval seeds): margins per seed, the mean with a bootstrap
interval over objects, the pooled sign test."""
import json

import pytest

from defgg_ros.evaluation.cli import main
from defgg_ros.evaluation.seeds import seeds_markdown, summarise

pytestmark = pytest.mark.unit


def trial(model, obj, e_pa, rank, success, object_set="common"):
    return {"model": model, "object": obj, "object_set": object_set, "youngs_modulus_pa": e_pa, "rank": rank,
            "task": "shake", "experiment": "main", "input_error_pct": 0.0, "status": "ok", "success": success}


def seed_records(a_wins: dict):
    """Each object: 4 views; the stiffness-aware model holds a_wins[obj] of them that the baseline drops."""
    out = []
    for obj, wins in a_wins.items():
        for view in range(4):
            out.append(trial("defgg_cnn", obj, 2e4, view, view < wins or view == 3))
            out.append(trial("ggcnn_depth_only", obj, 2e4, view, view == 3))
    return out


def test_margins_per_seed_their_mean_and_the_pooled_test():
    runs = {"0": seed_records({"a": 2, "b": 0}), "1": seed_records({"a": 1, "b": 1})}
    s = summarise(runs, "common", resamples=500)
    assert [r.counts.margin_pts for r in s.rows] == [25.0, 25.0]        # 2 of 8 pairs each
    assert s.mean_margin_pts == pytest.approx(25.0) and s.objects == 2
    assert (s.pooled.a_only, s.pooled.b_only, s.pooled.pairs) == (4, 0, 16)
    assert s.pooled_p == pytest.approx(0.125)
    # Over objects: a's net +3 over the seeds, b's +1: of the 4 sign patterns, |sum| >= 4 only for ++ and --
    assert s.object_nets == (3, 1) and s.pooled_object_p == pytest.approx(0.5)
    assert "objects 0.5; pairs 0.125 (pooled)" in seeds_markdown([s])
    # Resampling objects: {a, a} gives 25 + 50 / 2 ... the interval spans what the objects allow, not more.
    assert 0.0 <= s.interval_pts[0] <= 25.0 <= s.interval_pts[1] <= 50.0


def test_no_difference_between_the_models_gives_a_zero_margin_and_p_1():
    runs = {"0": seed_records({"a": 0, "b": 0})}
    s = summarise(runs, "common", resamples=100)
    assert s.mean_margin_pts == 0.0 and s.pooled_p == 1.0 and s.interval_pts == (0.0, 0.0)


def test_the_cli_reads_each_seed_s_folder_and_writes_the_table(tmp_path, capsys):
    folders = []
    for seed, wins in (("0", {"a": 2}), ("1", {"a": 1})):
        folder = tmp_path / f"s{seed}"
        folder.mkdir()
        with open(folder / "trials.jsonl", "w") as f:
            for i, rec in enumerate(seed_records(wins)):
                f.write(json.dumps({**rec, "key": f"{seed}|{i}"}) + "\n")
        folders.append(f"{seed}={folder}")
    out = tmp_path / "seeds.md"
    assert main(["seeds", "--run", *folders, "--sets", "common", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "| common | 0 | 4 | 75.0 % / 25.0 % | 2 | 0 | +50.0 |" in table             # held 3 / 1 of 4 views
    assert "| common | **mean of 2 seeds** | 8 | 62.5 % / 25.0 % | 3 | 0 |" in table   # pooled: 5 / 2 of 8
    assert out.read_text() == table
    assert main(["seeds", "--run", "nonsense"]) == 2


def test_a_partial_seed_is_compared_on_the_views_every_seed_has():
    """Seed 1 has only rank 0 of each object: seed 0 is then counted on rank 0 too (matched), not on its four
    ranks, where its rank-3 pairs (both held) would dilute its margin against seed 1's."""
    full = seed_records({"a": 1, "b": 1})
    partial = [r for r in seed_records({"a": 1, "b": 0}) if r["rank"] == 0]
    s = summarise({"0": full, "1": partial}, "common", resamples=50)
    assert [r.counts.pairs for r in s.rows] == [2, 2] and s.matched_views == 2
    assert [r.counts.margin_pts for r in s.rows] == [100.0, 50.0]
    unmatched = summarise({"0": full, "1": partial}, "common", resamples=50, matched=False)
    assert [r.counts.pairs for r in unmatched.rows] == [8, 2] and unmatched.matched_views is None


def test_a_seed_without_trials_does_not_empty_the_comparison():
    s = summarise({"0": seed_records({"a": 2}), "1": []}, "common", resamples=50)
    assert [r.counts.pairs for r in s.rows] == [4, 0] and s.matched_views == 4
    assert "| common | **mean of 1 seeds** | 4 |" in seeds_markdown([s])     # the mean is over seed 0 alone


def test_only_the_trials_of_the_weights_a_folder_s_run_json_names_are_read(tmp_path, capsys):
    """A retrained model's older trials stay in trials.jsonl; the seed study reads the current weights' only (as
    the report's tables do), else an old trial of a view would stand in for the new one."""
    shas = {"defgg_cnn": "new", "ggcnn_depth_only": "base"}
    records = [{**r, "model_sha": shas[r["model"]]} for r in seed_records({"a": 2})]
    stale = [{**r, "model_sha": "old", "success": False} for r in records if r["model"] == "defgg_cnn"]
    (tmp_path / "trials.jsonl").write_text("".join(json.dumps({**r, "key": f"{i}"}) + "\n"
                                                   for i, r in enumerate(records + stale)))
    (tmp_path / "run.json").write_text(json.dumps({"models": {
        name: {"sha": sha, "uses_stiffness": name == "defgg_cnn"} for name, sha in shas.items()}}))
    assert main(["seeds", "--run", f"0={tmp_path}", "--sets", "common"]) == 0
    assert "| common | 0 | 4 | 75.0 % / 25.0 % | 2 | 0 | +50.0 |" in capsys.readouterr().out
