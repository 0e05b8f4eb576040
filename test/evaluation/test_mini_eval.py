"""The miniature evaluation, end to end through `defgg-eval`: one object, two moduli, one grasp each,
both tasks, both shipped models, real PyBullet trials in two worker processes (short --quick ramps)."""
import csv
import json
from pathlib import Path

import pytest

from defgg_ros.evaluation import cli
from defgg_ros.evaluation.store import read_results

REPO = Path(__file__).resolve().parents[2]
MODELS = [f"defgg_cnn={REPO / 'models/defgg_cnn.pt'}", f"ggcnn_depth_only={REPO / 'models/ggcnn_depth_only.pt'}"]
ARGS = ["--sets", "common", "--only", "common_sponge", "--moduli", "2e5", "2e9", "--grasps", "1",
        "--experiments", "main", "--quick", "--no-progress", "--workers", "2"]


@pytest.fixture(scope="module")
def mini_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("eval")
    argv = ["run", "--out", str(out), *ARGS]
    for m in MODELS:
        argv += ["--model", m]
    assert cli.main(argv) == 0
    return out, argv


def test_every_trial_ran_in_the_simulator(mini_run):
    out, _ = mini_run
    records = read_results(out / "trials.jsonl")
    assert len(records) == 2 * 2 * 1 * 2           # models x moduli x grasps x tasks
    assert len({r["key"] for r in records}) == len(records)
    for r in records:
        assert r["status"] in ("ok", "lift_failed", "exploded", "timeout", "no_grasp")
        if r["status"] == "no_grasp":
            continue
        original = r if r["reused_from"] is None else next(x for x in records if x["key"] == r["reused_from"])
        assert original["sim_steps"] > 0 and original["cpu_s"] > 0
        soft = r["youngs_modulus_pa"] == 2e5
        assert r["soft"] == [soft]                                   # FEM soft body vs rigid body
        assert r["time_step_s"] == (5e-4 if soft else 1e-3)
        assert r["trial_settings"]["protocol"] == "defgraspsim"          # a new folder's default
        if r["status"] == "ok" and r["task"] == "shake":
            # the label's own criterion: directions ramped to 50 m/s^2, success = the mean held >= 25 m/s^2,
            # the every-direction column beside it; directions are skipped only once both are certain (a
            # measured one failed) or capped at a held value >= 25 m/s^2 that decides both
            assert len(r["accels"]) == 16 and max(r["accels"]) <= 50.0
            assert r["success"] == (sum(r["accels"]) / 16 >= 25.0)
            assert r["success_every_direction"] == (min(r["accels"]) >= 25.0)
            measured = [a for a, m in zip(r["accels"], r["measured"]) if m]
            unmeasured = [a for a, m in zip(r["accels"], r["measured"]) if not m]
            assert not unmeasured or min(measured) < 25.0 or min(unmeasured) >= 25.0
        elif r["status"] == "ok":
            assert len(r["accels"]) == 6
            assert r["success"] == (min(r["accels"]) >= 500.0)
            measured = [a for a, m in zip(r["accels"], r["measured"]) if m]
            # fail-fast: every measured axis but the last held the limit; the rest was skipped
            assert all(a >= 500.0 for a in measured[:-1])
            assert r["success"] == (len(measured) == 6 and measured[-1] >= 500.0)
        elif r["status"] == "lift_failed":
            assert r["success"] is False
        g = r["grasp"]
        assert 0 < g["width_m"] <= 0.08 and g["position_m"][2] > 0


def test_outputs_have_the_papers_table_structure(mini_run, tmp_path):
    out, _ = mini_run
    for task in ("shake", "twist"):
        md = (out / "tables" / f"{task}.md").read_text()
        assert "| 2e5 |" in md and "| 2e9 |" in md and "all stiffnesses" in md
        assert "common: with stiffness (defgg_cnn)" in md and "common: no stiffness (ggcnn_depth_only)" in md
        rows = list(csv.DictReader((out / "tables" / f"{task}.csv").open()))
        assert len(rows) == 2 * 3                                    # models x (2 moduli + all)
        assert sum(int(r["graded"]) + int(r["sim_failed"]) for r in rows if r["youngs_modulus_pa"] != "all "
                   "stiffnesses") == 4
    summary = json.loads((out / "summary.json").read_text())
    assert summary["records"] == 8
    # the candidate ceiling, run into the same folder, becomes a section of the report
    assert cli.main(["ceiling", "--out", str(out), "--only", "common_sponge", "--moduli", "2e9",
                     "--candidates", "1"]) == 0
    doc = tmp_path / "results.md"
    assert cli.main(["report", "--out", str(out), "--docs", str(doc)]) == 0
    text = doc.read_text()
    assert "--quick" in text and "## Shake task" in text and "## Twist task" in text
    assert "Trial protocol: **defgraspsim**" in text and "the label's own criterion" in text
    every = (out / "tables" / "shake_every_direction.md").read_text()     # the second column's table
    assert "| 2e5 |" in every and every.strip() in text
    assert "## What any grasp choice could reach" in text and "| shake | 2e+09 | 1 | 1 |" in text
    # the seed study's table and the cell experiment's report join the same document (issue 49 item 5)
    cell = tmp_path / "cell"
    cell.mkdir()
    (cell / "report.md").write_text("# Cell experiment\n\n| object | correct |\n\n![per object](per_object.png)\n")
    assert cli.main(["report", "--out", str(out), "--docs", str(doc), "--seeds", f"0={out}", f"1={out}",
                     "--cell", str(cell)]) == 0
    text = doc.read_text()
    assert "## Seeds: how much of the margin is the training seed?" in text and "mean of 2 seeds" in text
    assert "## The paper's real-robot experiment in the simulated cell" in text and "| object | correct |" in text
    assert "![per object](cell/per_object.png)" in text and f"--seeds 0={out} 1={out} --cell {cell}" in text
    # a second study (another dataset's pair): one table each, each under the title of its trial hand
    assert cli.main(["report", "--out", str(out), "--docs", str(doc), "--seeds", f"0={out}", f"1={out}",
                     "--seeds", f"0={out}"]) == 0
    text = doc.read_text()
    assert text.count("### speed-driven trial hand; training data fingerprint") == 2
    assert "mean of 2 seeds" in text and f"--seeds 0={out} 1={out} --seeds 0={out}" in text
    assert (out / "seeds.png").stat().st_size > 0 and "![seed studies](" in text   # the studies at a glance
    assert cli.main(["seeds", "--run", f"0={out}", "--png", str(tmp_path / "seeds.png")]) == 0
    assert (tmp_path / "seeds.png").read_bytes()[:4] == b"\x89PNG"


def test_rerun_skips_finished_trials(mini_run, capsys):
    out, argv = mini_run
    before = (out / "trials.jsonl").read_bytes()
    capsys.readouterr()
    assert cli.main(argv) == 0
    counts = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert counts["simulated"] == 0 and counts["stored"] == 8
    assert (out / "trials.jsonl").read_bytes() == before


def test_a_folder_of_another_protocol_is_refused(mini_run, capsys):
    out, argv = mini_run
    before = (out / "trials.jsonl").read_bytes()
    no_quick = [a for a in argv if a != "--quick"]         # the full protocol into the --quick folder
    assert cli.main(no_quick) == 2
    assert "another protocol" in capsys.readouterr().err
    assert (out / "trials.jsonl").read_bytes() == before
