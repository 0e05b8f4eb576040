"""The dataset format and atomic writes: round trip, torn lines, tampering."""
import json
import os

import numpy as np
import pytest

from defgg_ros.atomic import append_jsonl, atomic_path, read_jsonl, write_json_atomic
from defgg_ros.data import format as fmt


def _scene(scene_id="box__E2e+04"):
    depth = np.full((8, 8), 0.4, np.float32)
    depth[2:5, 2:5] = 0.36
    e = np.zeros_like(depth)
    e[2:5, 2:5] = 2e4
    mask = (e > 0).astype(np.uint8)
    return fmt.Scene(scene_id, depth, e, mask, np.eye(3), np.eye(4), {"object_name": "box", "seed": 3})


def _trial(i, accels):
    rect = fmt.GraspRect(3.0, 3.0, 0.5, 4.0, 2.0)
    return fmt.TrialRecord(f"box__E2e+04/g{i:03d}", "box__E2e+04", "box", 2e4, i, rect,
                           [0.0, 0.0, 0.02], 0.5, 0.04, fmt.STATUS_OK, shake_accels_mps2=accels)


def test_scene_and_trials_round_trip(tmp_path):
    writer = fmt.DatasetWriter(tmp_path, {"seed": 1})
    writer.write_scene(_scene())
    writer.append_trial(_trial(0, [30.0] * 16))
    writer.append_trial(_trial(1, [10.0] * 16))
    assert fmt.list_scene_ids(tmp_path) == ["box__E2e+04"]
    scene = fmt.read_scene(tmp_path / "scenes" / "box__E2e+04.npz")
    assert scene.object_name == "box" and scene.depth_m.dtype == np.float32
    assert fmt.read_scene_meta(tmp_path / "scenes" / "box__E2e+04.npz") == scene.meta     # the card's read
    np.testing.assert_array_equal(scene.youngs_modulus_pa, _scene().youngs_modulus_pa)
    trials = fmt.read_trials(tmp_path, "box__E2e+04")
    assert [t.label for t in trials] == [True, False]
    assert trials[0].rect.corners().shape == (4, 2)
    assert writer.finished_trial_ids("box__E2e+04") == {"box__E2e+04/g000", "box__E2e+04/g001"}
    fp = fmt.dataset_fingerprint(tmp_path)
    writer.append_trial(_trial(2, [26.0] * 16))
    assert fmt.dataset_fingerprint(tmp_path) != fp


def test_sim_failures_are_not_labels():
    trial = _trial(0, None)
    trial.status = fmt.STATUS_EXPLODED
    assert trial.label is None
    trial.status = fmt.STATUS_LIFT_FAILED
    assert trial.label is False


def test_truncated_scene_gives_dataset_error(tmp_path):
    fmt.DatasetWriter(tmp_path).write_scene(_scene())
    path = tmp_path / "scenes" / "box__E2e+04.npz"
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(fmt.DatasetError, match="cannot read scene"):
        fmt.read_scene(path)
    with pytest.raises(fmt.DatasetError, match="cannot read scene"):
        fmt.read_scene_meta(path)


def test_foreign_header_is_rejected(tmp_path):
    write_json_atomic(tmp_path / "dataset.json", {"format": "other", "version": 9})
    with pytest.raises(fmt.DatasetError, match="expected"):
        fmt.list_scene_ids(tmp_path)


def test_torn_last_jsonl_line_is_skipped_but_corruption_inside_raises(tmp_path):
    path = tmp_path / "t.jsonl"
    append_jsonl(path, {"a": 1})
    append_jsonl(path, {"a": 2})
    with open(path, "a") as f:
        f.write('{"a": 3, "b"')  # crash mid-write
    assert read_jsonl(path) == [{"a": 1}, {"a": 2}]
    path.write_text('{"a": 1}\n{broken\n{"a": 3}\n')
    with pytest.raises(ValueError, match="line 2"):
        read_jsonl(path)
    path.write_text('{"a": 1}\n{broken}\n')   # complete (its newline written): corruption, not a crash mid-write
    with pytest.raises(ValueError, match="line 2"):
        read_jsonl(path)


def test_an_append_after_a_torn_line_drops_it_first_and_the_file_stays_readable(tmp_path):
    """A generator or relabel run resumed after a crash mid-append: the next record was glued onto the torn line
    (lost) and a second made it a corrupt line inside the file ("corrupt record on line 3": the scene unreadable
    for training, cards and fingerprints)."""
    path = tmp_path / "t.jsonl"
    append_jsonl(path, {"a": 1})
    with open(path, "a") as f:
        f.write('{"a": 2, "b"')  # crash mid-write
    append_jsonl(path, {"a": 3})
    append_jsonl(path, {"a": 4})
    assert read_jsonl(path) == [{"a": 1}, {"a": 3}, {"a": 4}]


def test_atomic_path_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.json"
    write_json_atomic(target, {"v": 1})
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash")
    assert json.loads(target.read_text()) == {"v": 1}
    assert os.listdir(tmp_path) == ["out.json"]
