"""`defgg-eval run` killed with SIGKILL mid-simulation, then rerun: nothing finished is lost, nothing duplicated.

A real CLI process on a rigid object (cheap real PyBullet trials) is killed
as soon as its first trial record is on disk; the rerun of the same command
must keep those records byte for byte, add only the missing trials and
end with every trial key once.
"""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from defgg_ros.evaluation.store import read_results

REPO = Path(__file__).resolve().parents[2]
ARGS = ["--sets", "common", "--only", "common_sponge", "--moduli", "2e9", "--grasps", "2", "--experiments", "main",
        "--quick", "--no-progress", "--workers", "1", "--model", f"defgg_cnn={REPO / 'models' / 'defgg_cnn.pt'}"]


def _command(out):
    return [sys.executable, "-m", "defgg_ros.evaluation.cli", "run", "--out", str(out), *ARGS]


def _complete_lines(path) -> int:
    return path.read_bytes().count(b"\n") if path.exists() else 0


def test_killed_evaluation_loses_no_finished_trial_and_duplicates_none(tmp_path):
    out = tmp_path / "eval"
    trials = out / "trials.jsonl"
    proc = subprocess.Popen(_command(out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=dict(os.environ))
    deadline = time.monotonic() + 240
    while _complete_lines(trials) < 1:
        if proc.poll() is not None:
            pytest.fail(f"evaluation ended before writing a trial: {proc.stderr.read().decode()[-2000:]}")
        assert time.monotonic() < deadline, "no trial record written in time"
        time.sleep(0.02)  # polling another process's file; there is no event to wait on
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = trials.read_bytes()
    kept = before[: before.rfind(b"\n") + 1]  # what was complete when the process died
    n_kept = kept.count(b"\n")
    done = subprocess.run(_command(out), capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert done.returncode == 0, done.stderr[-2000:]
    counts = json.loads(done.stdout.strip().splitlines()[-1])
    records = read_results(trials)
    keys = [r["key"] for r in records]
    assert len(keys) == len(set(keys)) == counts["stored"] == 4  # 1 model x 2 tasks x 2 grasps
    assert n_kept < 4, "the run finished before it could be killed"
    assert trials.read_bytes().startswith(kept)
    assert counts["simulated"] + counts["reused_or_no_grasp"] <= 4 - n_kept
