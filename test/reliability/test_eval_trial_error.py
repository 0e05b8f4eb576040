"""A trial that raises does not end `defgg-eval run`: it is logged to errors.jsonl and retried by the rerun.

The fault is real: the in-process worker's PyBullet server is disconnected
before the first trial, so PyBullet itself raises on it. The guard logs the
error, starts a fresh server, and the other trials of the run complete.
"""
import json
from pathlib import Path

import pybullet as p

from defgg_ros.evaluation import cli, runner
from defgg_ros.evaluation.store import read_results

REPO = Path(__file__).resolve().parents[2]
ARGS = ["--sets", "common", "--only", "common_sponge", "--moduli", "2e9", "--grasps", "2", "--experiments", "main",
        "--quick", "--no-progress", "--workers", "1", "--model", f"defgg_cnn={REPO / 'models' / 'defgg_cnn.pt'}"]


def _counts(capsys) -> tuple[dict, str]:
    """The run's counts (its last stdout line) and its stderr."""
    captured = capsys.readouterr()
    return json.loads(captured.out.strip().splitlines()[-1]), captured.err


def test_a_trial_that_raises_is_logged_and_retried_and_the_run_goes_on(tmp_path, capsys, monkeypatch):
    out = tmp_path / "eval"
    dead = p.connect(p.DIRECT)
    p.disconnect(dead)
    monkeypatch.setattr(runner, "_WORKER_CLIENT", dead)

    assert cli.main(["run", "--out", str(out), *ARGS]) == 0
    first, err = _counts(capsys)
    assert "retried when this command runs again" in err
    errors = [json.loads(line) for line in (out / runner.ERRORS_FILE).read_text().splitlines()]
    assert first["errors"] == len(errors) == 1
    assert "Not connected to physics server" in errors[0]["error"], errors[0]   # PyBullet's own error
    stored = {r["key"] for r in read_results(out / "trials.jsonl")}
    assert errors[0]["key"] not in stored and len(stored) == first["stored"] == 3   # the other trials ran

    assert cli.main(["run", "--out", str(out), *ARGS]) == 0
    second, _ = _counts(capsys)
    assert second["errors"] == 0 and second["stored"] == 4
    assert errors[0]["key"] in {r["key"] for r in read_results(out / "trials.jsonl")}
