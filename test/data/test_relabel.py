"""defgg-datagen relabel (data/relabel.py): stored trials re-run under a changed setting, written under the
source's file names, resumable, refused when the folder relabels with other settings. On rigid (2e9 Pa) trials of
fem_v5 here: 0.1 CPU s each."""
import json
import shutil
from pathlib import Path

import pytest

from defgg_ros.atomic import read_jsonl
from defgg_ros.data.datagen_cli import main
from defgg_ros.data.format import DatasetError
from defgg_ros.data.relabel import RelabelSpec, over_ceiling, run
from defgg_ros.sim.trial_settings import TrialSettings

pytestmark = pytest.mark.unit

FEM_V5 = Path(__file__).resolve().parents[2] / "datasets" / "fem_v5"
SCENE = "ycb_can__E2e+09"


@pytest.fixture
def source(tmp_path) -> Path:
    """fem_v5 cut down to one rigid scene (its header, scene and trials)."""
    root = tmp_path / "source"
    (root / "scenes").mkdir(parents=True)
    (root / "trials").mkdir()
    shutil.copy(FEM_V5 / "dataset.json", root)
    shutil.copy(FEM_V5 / "scenes" / f"{SCENE}.npz", root / "scenes")
    shutil.copy(FEM_V5 / "trials" / f"{SCENE}.jsonl", root / "trials")
    return root


def test_relabel_reruns_with_the_setting_changed_and_resumes(source, tmp_path, capsys):
    out = tmp_path / "press"
    argv = ["relabel", str(source), "--out", str(out), "--settings", '{"finger_drive": "press"}',
            "--max-youngs-modulus-pa", "3e9", "--limit", "2", "--no-progress"]
    assert main(argv) == 0
    new = read_jsonl(out / "trials" / f"{SCENE}.jsonl")
    stored = {r["trial_id"]: r for r in read_jsonl(source / "trials" / f"{SCENE}.jsonl")}
    assert len(new) == 2 and all(r["trial_id"] in stored for r in new)
    for r in new:
        was = TrialSettings.from_record(stored[r["trial_id"]]["sim"]["settings"])
        assert r["sim"]["settings"] == was.with_fields(finger_drive="press").to_record()
        assert r["position_m"] == stored[r["trial_id"]]["position_m"]        # the same grasp
    report = (out / "relabel.md").read_text()
    assert "Re-run: **2 of 36**" in report and "Signal report of the source with these 2 records in" in report
    capsys.readouterr()
    assert main(argv) == 0                                                  # resumed: two more, none twice
    assert len({r["trial_id"] for r in read_jsonl(out / "trials" / f"{SCENE}.jsonl")}) == 4
    counts = next(line for line in capsys.readouterr().out.splitlines() if line.startswith('{"pending"'))
    assert json.loads(counts) == {"pending": 2, "done": 2, "errors": 0}


def test_a_folder_relabelling_with_other_settings_is_refused(source, tmp_path):
    out = tmp_path / "press"
    run(RelabelSpec(source, out, {"finger_drive": "press"}, 3e9), limit=0, progress=False)
    with pytest.raises(DatasetError, match="relabels with other settings"):
        run(RelabelSpec(source, out, {"finger_drive": "speed"}, 3e9), limit=0, progress=False)


def test_bad_settings_are_a_clear_error(source, tmp_path, capsys):
    assert main(["relabel", str(source), "--out", str(tmp_path / "x"), "--settings", '{"finger_drive": 1}']) == 2
    assert "bad --settings" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_the_trials_most_over_the_speed_drives_ceiling_come_first():
    # 2 N asked at 0.5 ms steps (ceiling 1 N) is further over it than 3 N at 0.25 ms (2 N).
    soft = {"grasp_force_n": 2.0, "youngs_modulus_pa": 2e4, "sim": {}}
    stiff = {"grasp_force_n": 3.0, "youngs_modulus_pa": 2e6, "sim": {}}
    assert over_ceiling(soft) == pytest.approx(2.0) and over_ceiling(stiff) == pytest.approx(1.5)


def test_merge_writes_the_source_with_the_relabelled_trials_in(source, tmp_path):
    relabelled, merged = tmp_path / "press", tmp_path / "merged"
    run(RelabelSpec(source, relabelled, {"finger_drive": "press"}, 3e9), limit=3, progress=False)
    assert main(["merge", str(source), str(relabelled), "--out", str(merged)]) == 0
    header = json.loads((merged / "dataset.json").read_text())
    assert header["generator"]["trial_settings"]["finger_drive"] == "press"
    assert (header["relabel"]["relabelled"], header["relabel"]["kept"]) == (3, 33)
    records = read_jsonl(merged / "trials" / f"{SCENE}.jsonl")
    pressed = [r for r in records if r["sim"]["settings"].get("finger_drive") == "press"]
    assert len(records) == 36 and len(pressed) == 3
    assert (merged / "scenes" / f"{SCENE}.npz").exists()
    assert "Relabelled (defgg-datagen relabel and merge): 3 trials" in (merged / "card.md").read_text()
    assert main(["merge", str(source), str(relabelled), "--out", str(merged)]) == 2      # never over a dataset


def test_a_seeded_sample_takes_other_trials_than_the_ordered_run_and_is_reproducible(source, tmp_path):
    def sampled(out, seed):
        run(RelabelSpec(source, out, {"finger_drive": "press"}, 3e9), limit=3, progress=False, sample_seed=seed)
        return [r["trial_id"] for r in read_jsonl(out / "trials" / f"{SCENE}.jsonl")]

    first, again, ordered = sampled(tmp_path / "a", 1), sampled(tmp_path / "b", 1), tmp_path / "c"
    run(RelabelSpec(source, ordered, {"finger_drive": "press"}, 3e9), limit=3, progress=False)
    assert sorted(first) == sorted(again)
    assert sorted(first) != sorted(r["trial_id"] for r in read_jsonl(ordered / "trials" / f"{SCENE}.jsonl"))


def test_negatives_only_reruns_only_the_trials_stored_negative(source, tmp_path):
    path = source / "trials" / f"{SCENE}.jsonl"
    records = read_jsonl(path)
    records[5] = {**records[5], "shake_accels_mps2": [0.0] * len(records[5]["shake_accels_mps2"])}   # now negative
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    out = tmp_path / "neg"
    counts = run(RelabelSpec(source, out, {"finger_drive": "press"}, 3e9), progress=False, negatives_only=True)
    assert counts["done"] == 1
    assert [r["trial_id"] for r in read_jsonl(out / "trials" / f"{SCENE}.jsonl")] == [records[5]["trial_id"]]


def test_a_second_run_into_a_folder_being_written_is_refused(source, tmp_path):
    import fcntl

    from defgg_ros.data.relabel import LOCK_FILE

    out = tmp_path / "press"
    spec = RelabelSpec(source, out, {"finger_drive": "press"}, 3e9)
    run(spec, limit=0, progress=False)                       # nothing to run: no lock needed
    with open(out / LOCK_FILE, "w") as held:                 # as a running relabel holds it
        fcntl.flock(held, fcntl.LOCK_EX)
        with pytest.raises(DatasetError, match="another defgg-datagen relabel is writing"):
            run(spec, limit=1, progress=False)
        assert run(spec, limit=0, progress=False)["pending"] == 0     # the report still writes
    assert run(spec, limit=1, progress=False)["done"] == 1
