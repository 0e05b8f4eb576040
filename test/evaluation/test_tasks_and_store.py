"""Success rules and the results file (resume, torn tail, duplicates, SIGKILL)."""
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from defgg_ros.evaluation.store import ResultsError, ResultStore, read_results, repair_torn_tail
from defgg_ros.evaluation.tasks import TaskError, task_success


def test_shake_success_needs_every_direction_at_25():
    assert task_success("shake", "ok", [25.0] * 16) is True
    assert task_success("shake", "ok", [50.0] * 15 + [24.0]) is False


def test_twist_success_needs_the_limit_about_every_axis():
    assert task_success("twist", "ok", [500.0] * 6) is True
    assert task_success("twist", "ok", [500.0] * 5 + [480.0]) is False


def test_lift_failure_fails_and_sim_failures_are_not_graded():
    assert task_success("shake", "lift_failed", None) is False
    assert task_success("twist", "exploded", None) is None
    assert task_success("shake", "timeout", None) is None


def test_bad_task_and_missing_accelerations_raise():
    with pytest.raises(TaskError, match="unknown task"):
        task_success("wiggle", "ok", [1.0])
    with pytest.raises(TaskError, match="no accelerations"):
        task_success("shake", "ok", [])


def test_store_skips_existing_keys_and_survives_reopen(tmp_path):
    store = ResultStore(tmp_path)
    assert store.append({"key": "a", "x": 1})
    assert not store.append({"key": "a", "x": 2})
    store.append({"key": "b", "x": 3})
    again = ResultStore(tmp_path)
    assert len(again) == 2 and again.get("a")["x"] == 1
    with pytest.raises(ResultsError, match="key"):
        again.append({"x": 4})


def test_torn_tail_is_removed_before_appending(tmp_path):
    store = ResultStore(tmp_path)
    store.append({"key": "a"})
    with open(store.path, "a") as f:
        f.write('{"key": "b", "trunc')     # a kill in the middle of a write
    reopened = ResultStore(tmp_path)
    assert reopened.torn_bytes_removed > 0
    reopened.append({"key": "c"})
    assert [r["key"] for r in read_results(reopened.path)] == ["a", "c"]


def test_duplicate_keys_in_a_file_are_refused(tmp_path):
    path = tmp_path / "trials.jsonl"
    path.write_text(json.dumps({"key": "a"}) + "\n" + json.dumps({"key": "a"}) + "\n")
    with pytest.raises(ResultsError, match="duplicate"):
        ResultStore(tmp_path)


def test_repair_on_a_file_without_any_newline(tmp_path):
    path = tmp_path / "t.jsonl"
    path.write_text('{"key": "x"')
    assert repair_torn_tail(path) == len('{"key": "x"')
    assert path.read_text() == ""


WRITER = """
import sys
from defgg_ros.evaluation.store import ResultStore
store = ResultStore(sys.argv[1])
for i in range(100000):
    store.append({"key": f"k{i:06d}", "payload": "x" * 500})
"""


def test_sigkill_loses_no_finished_record_and_rerun_duplicates_none(tmp_path):
    """A real writer process killed with SIGKILL mid-run, twice; keys stay unique and contiguous."""
    for _ in range(2):
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path)])
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            path = tmp_path / "trials.jsonl"
            if path.exists() and path.stat().st_size > 20000:
                break
            time.sleep(0.01)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    store = ResultStore(tmp_path)
    keys = [r["key"] for r in store.records()]
    assert len(keys) == len(set(keys)) > 10
    # The writer restarts from k000000 and skips what is stored: keys are a contiguous prefix.
    assert keys == [f"k{i:06d}" for i in range(len(keys))]
