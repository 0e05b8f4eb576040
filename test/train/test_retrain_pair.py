"""models/retrain_pair.sh end to end on a small synthetic dataset: freeze, both trainings, ship, cards."""
import os
import subprocess
from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def test_the_pair_is_trained_on_the_same_frozen_trials_and_shipped_at_the_best_validation_epoch(tmp_path):
    from defgg_ros.data.synthetic import write_synthetic_dataset

    write_synthetic_dataset(tmp_path / "data", n_objects=8, trials_per_scene=5)
    env = {**os.environ, "EPOCHS": "1", "MODELS_DIR": str(tmp_path / "models"), "RUNS_DIR": str(tmp_path / "runs"),
           "TRAIN_FLAGS": "--max-steps 2"}
    subprocess.run([str(REPO / "models" / "retrain_pair.sh"), str(tmp_path / "data"), "smoke", "a smoke run"],
                   env=env, check=True, capture_output=True, text=True, timeout=280)
    for name in ("defgg_cnn", "ggcnn_depth_only"):      # a line per epoch in each run's log
        log = (tmp_path / "runs" / f"{name}_smoke.log").read_text()   # a --max-steps stop says it stopped in it
        assert "defgg-train: epoch 1/1" in log and ": train loss" in log
    models = tmp_path / "models"
    assert (models / "train_data_smoke.tar.gz").is_file()
    cards = {name: (models / f"{name}.md").read_text() for name in ("defgg_cnn", "ggcnn_depth_only")}
    for name, card in cards.items():
        state = torch.load(models / f"{name}.pt", weights_only=True, map_location="cpu")
        assert state, name
        assert "**Shipped checkpoint**: best" in card and "a smoke run" in card
        assert f"--out {tmp_path / 'runs' / name}_smoke --max-steps 2" in card
    assert "--no-stiffness" in cards["ggcnn_depth_only"] and "--no-stiffness" not in cards["defgg_cnn"]
    fingerprints = {card.split("data fingerprint `")[1].split("`")[0] for card in cards.values()}
    assert len(fingerprints) == 1          # the same frozen trials
