"""Sealed (compressed) trial files read exactly like the plain ones and are never appended to."""
import json

import pytest

from defgg_ros.data import format as fmt
from defgg_ros.evaluation.store import ResultsError, ResultStore, results_path

pytestmark = pytest.mark.unit


def test_sealing_a_dataset_keeps_records_and_fingerprint_and_refuses_appends(tmp_path):
    from defgg_ros.data import synthetic

    root = tmp_path / "ds"
    synthetic.write_synthetic_dataset(root, n_objects=2)
    before = fmt.dataset_fingerprint(root)
    records = {sid: fmt.read_trials(root, sid) for sid in fmt.list_scene_ids(root)}
    assert fmt.seal_trials(root) > 0
    assert not list((root / "trials").glob("*.jsonl"))
    assert fmt.dataset_fingerprint(root) == before
    assert {sid: fmt.read_trials(root, sid) for sid in fmt.list_scene_ids(root)} == records
    sid, trials = next((s, t) for s, t in records.items() if t)
    with pytest.raises(fmt.DatasetError, match="sealed"):
        fmt.DatasetWriter(root).append_trial(trials[0])


def test_sealed_evaluation_results_are_read_and_refuse_new_trials(tmp_path):
    store = ResultStore(tmp_path)
    store.append({"key": "a", "task": "shake"})
    from defgg_ros.atomic import compress_jsonl

    compress_jsonl(results_path(tmp_path))
    assert results_path(tmp_path).name == "trials.jsonl.gz"
    sealed = ResultStore(tmp_path)
    assert [r["key"] for r in sealed.records()] == ["a"]
    with pytest.raises(ResultsError, match="sealed"):
        sealed.append({"key": "b"})
    assert json.loads(json.dumps(sealed.get("a")))["task"] == "shake"
