"""Shipping a (tiny, real) training run: weights copied and verified, provenance, snapshot, generated card."""
import json

import pytest

from defgg_ros.data.synthetic import write_synthetic_dataset
from defgg_ros.evaluation import cli
from defgg_ros.evaluation.cards import CardError, render_card
from defgg_ros.evaluation.snapshot import verify_snapshot
from defgg_ros.train.cli import main as train_main


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("ship")
    data, run = root / "data", root / "run"
    write_synthetic_dataset(data, n_objects=7, trials_per_scene=6)
    # freeze the (growing) dataset, then train on the frozen copy
    assert cli.main(["freeze", "--data", str(data), "--archive", str(root / "frozen.tar.gz"), "--extract-to",
                     str(root / "frozen")]) == 0
    argv = ["--data", str(root / "frozen" / "train_data"), "--out", str(run), "--epochs", "1", "--max-steps", "2",
            "--samples-per-scene", "1", "--no-progress"]
    assert train_main(argv) == 0
    return root, data, run, "defgg-train " + " ".join(argv)


def test_ship_snapshot_and_card(trained):
    root, data, run, command = trained
    models = root / "models"
    assert cli.main(["ship", "--run", str(run), "--name", "m", "--command", command, "--wall-s", "12",
                     "--commit", "abc123", "--models-dir", str(models), "--data-archive",
                     str(root / "frozen.tar.gz")]) == 0
    prov = json.loads((models / "m.train.json").read_text())
    assert prov["commit"] == "abc123" and prov["n_trials"] == sum(prov["manifest"].values()) > 0
    counts = prov["trial_counts"]
    assert sum(c["trials"] for per in counts.values() for c in per.values()) == prov["n_trials"]
    # the generator keeps appending trials after training: the snapshot holds exactly what the run used
    for path in (data / "trials").glob("*.jsonl"):
        rec = json.loads(path.read_text().splitlines()[0])
        rec["trial_id"] += "_later"
        with path.open("a") as f:
            f.write(json.dumps(rec) + "\n")
    assert verify_snapshot(root / "frozen.tar.gz", prov["manifest"]) == prov["data_fingerprint"]
    archive = root / "data.tar.gz"
    assert cli.main(["snapshot", "--name", "m", "--out", str(archive), "--models-dir", str(models)]) == 0
    assert verify_snapshot(archive, prov["manifest"]) == prov["data_fingerprint"]
    assert cli.main(["card", "--name", "m", "--models-dir", str(models)]) == 0
    card = (models / "m.md").read_text()
    for needle in (prov["data_fingerprint"], "abc123", command, "Validation", "Not evaluated yet", "frozen.tar.gz"):
        assert needle in card
    # a synthetic dataset names no protocol: legacy labels, and the weights say so
    assert "closes these grasps with**: legacy, 2 N + 0.5 N per decade of E a finger (recorded in the weights)" in card


def test_card_states_the_grip_rule_its_weights_record():
    from defgg_ros.evaluation.cards import _grip_rule_text

    assert _grip_rule_text({"label_grip_rule": {"protocol": "defgraspsim", "friction": 0.7}}).startswith(
        "defgraspsim, FOS·m·g/μ with μ 0.70")
    assert "record no rule" in _grip_rule_text({}) and _grip_rule_text({}).startswith("legacy")


def test_card_refuses_weights_that_changed_after_shipping(trained, tmp_path):
    root, data, run, command = trained
    assert cli.main(["ship", "--run", str(run), "--name", "m", "--command", command, "--wall-s", "1",
                     "--models-dir", str(tmp_path)]) == 0
    prov_path = tmp_path / "m.train.json"
    prov = json.loads(prov_path.read_text())
    prov["weights_sha256"] = "0" * 64
    prov_path.write_text(json.dumps(prov))
    with pytest.raises(CardError, match="does not match"):
        render_card("m", tmp_path)


def test_card_reads_the_generator_header_from_the_archive_and_states_the_height_rule(tmp_path):
    """Without the frozen folder (a fresh clone) the header comes from the shipped archive; labels of
    contacts-height candidates carry their known limitation, executor-height ones do not."""
    import io
    import tarfile

    from defgg_ros.evaluation.cards import _data_section

    def archive(generator):
        path = tmp_path / f"{generator.get('grasp_height', 'contacts')}.tar.gz"
        blob = json.dumps({"format": "defgg-dataset", "version": 1, "generator": generator}).encode()
        with tarfile.open(path, "w:gz") as tar:
            info = tarfile.TarInfo("train_data/dataset.json")
            info.size = len(blob)
            tar.addfile(info, io.BytesIO(blob))
        return path

    prov = {"data_root": str(tmp_path / "gone"), "object_split": {"train": ["box"]}, "train_config": {"seed": 0},
            "trial_counts": {"box": {"2e+04": {"positive": 1, "labelled": 2}}}}
    contacts = "\n".join(_data_section({**prov, "data_archive": str(archive({"n_candidates": 200}))}))
    assert '"n_candidates": 200' in contacts and "Known limitation" in contacts
    executor = "\n".join(_data_section({**prov, "data_archive": str(
        archive({"n_candidates": 200, "grasp_height": "executor"}))}))
    assert '"grasp_height": "executor"' in executor and "Known limitation" not in executor
    assert "Grip force of these labels" not in executor          # legacy labels: the executor's own force rule
    weight_rule = "\n".join(_data_section({**prov, "data_archive": str(archive({
        "n_candidates": 200, "grasp_height": "executor", "trial_settings": {"protocol": "defgraspsim"}}))}))
    assert "Grip force of these labels: FOS·m·g/μ" in weight_rule
    assert "record the rule (`label_grip_rule`)" in weight_rule


def test_card_lists_the_other_training_seeds_and_which_was_shipped(trained, tmp_path):
    """`card --seeds DIR`: each other seed's best validation epoch and accuracy (from the seed study's stored
    metrics) beside the shipped seed's, so a reader sees how lucky the shipped seed was (issue 49 item 1)."""
    root, data, run, command = trained
    models = tmp_path / "models"
    assert cli.main(["ship", "--run", str(run), "--name", "m", "--command", command, "--wall-s", "1",
                     "--models-dir", str(models)]) == 0
    metrics = json.loads((run / "metrics.json").read_text())
    seeds = tmp_path / "seeds"
    for seed, accuracy in (("1", 0.75), ("2", 0.8125)):
        other = {**metrics, "history": [{**e, "val_accuracy": accuracy} for e in metrics["history"]]}
        (seeds / f"weights_s{seed}").mkdir(parents=True)
        (seeds / f"weights_s{seed}" / "m.metrics.json").write_text(json.dumps(other))
    assert cli.main(["card", "--name", "m", "--models-dir", str(models), "--seeds", str(seeds)]) == 0
    card = (models / "m.md").read_text()
    assert "## Training seeds" in card and "| 0 (shipped) |" in card
    assert "| 1 | 1 | 75.0 % |" in card and "| 2 | 1 | 81.2 % |" in card
    assert cli.main(["card", "--name", "m", "--models-dir", str(models)]) == 0
    assert "## Training seeds" not in (models / "m.md").read_text()


def test_card_shows_what_each_seed_gave_in_the_simulator(trained, tmp_path):
    """`card --seeds DIR --seed-runs SEED=OUT ...`: the card carries each seed's paired margin from its evaluation
    folder (issue 49 item 1: "say in the cards what the other seeds gave"); --seed-runs alone is refused."""
    def seed_records(wins: int):   # 4 views of one object: the stiffness-aware model holds `wins` + view 3
        return [{"model": model, "object": "a", "object_set": "common", "youngs_modulus_pa": 2e4, "rank": view,
                 "task": "shake", "experiment": "main", "input_error_pct": 0.0, "status": "ok",
                 "success": view == 3 or (model == "defgg_cnn" and view < wins)}
                for view in range(4) for model in ("defgg_cnn", "ggcnn_depth_only")]

    root, data, run, command = trained
    models = tmp_path / "models"
    assert cli.main(["ship", "--run", str(run), "--name", "m", "--command", command, "--wall-s", "1",
                     "--models-dir", str(models)]) == 0
    seeds = tmp_path / "seeds"
    (seeds / "weights_s1").mkdir(parents=True)
    (seeds / "weights_s1" / "m.metrics.json").write_text((run / "metrics.json").read_text())
    folders = []
    for seed, wins in (("0", 2), ("1", 0)):
        folder = tmp_path / f"sim_s{seed}"
        folder.mkdir()
        (folder / "trials.jsonl").write_text("".join(
            json.dumps({**rec, "key": f"{seed}|{i}"}) + "\n" for i, rec in enumerate(seed_records(wins))))
        folders.append(f"{seed}={folder}")
    assert cli.main(["card", "--name", "m", "--models-dir", str(models), "--seeds", str(seeds),
                     "--seed-runs", *folders]) == 0
    card = (models / "m.md").read_text()
    assert "What each seed's pair gave in the simulator" in card
    assert "| common | 0 | 4 | 75.0 % / 25.0 % | 2 | 0 | +50.0 |" in card and "| common | 1 | 4 |" in card
    assert "mean of 2 seeds" in card
    assert cli.main(["card", "--name", "m", "--models-dir", str(models), "--seed-runs", *folders]) == 2


def test_shipping_refuses_files_of_two_runs(trained, tmp_path, capsys):
    """A fresh run into a used folder, killed before its first epoch ended, leaves the old best.pt and metrics.json
    beside its new state.pt: shipping them paired the old weights with the new run's manifest (wrong card)."""
    import shutil

    root, data, run, command = trained
    mixed = tmp_path / "mixed"
    shutil.copytree(run, mixed)
    metrics = json.loads((mixed / "metrics.json").read_text())
    metrics["data"]["fingerprint"] = "0123456789abcdef"
    (mixed / "metrics.json").write_text(json.dumps(metrics))
    assert cli.main(["ship", "--run", str(mixed), "--name", "m", "--command", command, "--wall-s", "1",
                     "--models-dir", str(tmp_path / "models")]) == 2
    assert "files of two runs" in capsys.readouterr().err
    assert not (tmp_path / "models" / "m.pt").exists()
