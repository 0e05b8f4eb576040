"""Checkpoint every epoch/step, kill, resume: same weights as an uninterrupted run."""
import json
import os
import signal
import subprocess
import sys
import time

import torch

from defgg_ros.model.checkpoint import load_checkpoint
from defgg_ros.model.inference import GraspPredictor
from defgg_ros.train.cli import main

ARGS = ["--epochs", "3", "--batch-size", "2", "--samples-per-scene", "1", "--seed", "5", "--no-progress",
        "--val-fraction", "0.3", "--test-fraction", "0.3"]


def _weights(run):
    return load_checkpoint(run / "model.pt")["weights_sha256"]


def test_killed_run_resumes_to_the_same_result(tiny_dataset, tmp_path):
    torch.set_num_threads(1)
    assert main(["--data", str(tiny_dataset), "--out", str(tmp_path / "straight"), *ARGS]) == 0

    killed = tmp_path / "killed"
    cmd = [sys.executable, "-m", "defgg_ros.train.cli", "--data", str(tiny_dataset), "--out", str(killed),
           "--checkpoint-every", "1", *ARGS]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env={**os.environ})
    deadline = time.monotonic() + 120
    while not (killed / "state.pt").exists():
        assert proc.poll() is None, proc.stderr.read().decode()
        assert time.monotonic() < deadline, "no state file written"
        time.sleep(0.05)  # polling a file written by another process; nothing to wait on instead
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    state = torch.load(killed / "state.pt", weights_only=True)
    assert state["epoch"] < 3, "the run finished before it could be killed"

    assert main(["--data", str(tiny_dataset), "--out", str(killed), "--resume", *ARGS]) == 0
    assert _weights(killed) == _weights(tmp_path / "straight")
    metrics = json.loads((killed / "metrics.json").read_text())
    assert [h["epoch"] for h in metrics["history"]] == [1, 2, 3]
    for name in ("best.pt", "curves.png", "stiffness_response.png"):
        assert (killed / name).stat().st_size > 0
    assert GraspPredictor.from_checkpoint(killed / "best.pt").uses_stiffness


def test_resume_refuses_changed_hyper_parameters(tiny_dataset, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["--data", str(tiny_dataset), "--out", str(run), *ARGS, "--max-steps", "1"]) == 0
    assert main(["--data", str(tiny_dataset), "--out", str(run), "--resume", *ARGS, "--lr", "0.1"]) == 2
    assert "learning_rate" in capsys.readouterr().err


def test_resume_refuses_another_number_of_processes(tiny_dataset, tmp_path, capsys):
    """A run started under torchrun with 2 processes and resumed with 1 (or the other way) trained on another shard
    layout and global batch from the stored batch index: some items twice, others never, without a word."""
    run = tmp_path / "run"
    assert main(["--data", str(tiny_dataset), "--out", str(run), *ARGS, "--max-steps", "1"]) == 0
    state = torch.load(run / "state.pt", weights_only=True)
    assert state["world"] == 1
    state["world"] = 2                                   # as a 2-process run stores it
    torch.save(state, run / "state.pt")
    assert main(["--data", str(tiny_dataset), "--out", str(run), "--resume", *ARGS]) == 2
    assert "started with 2 process(es), this is 1" in capsys.readouterr().err


def test_a_step_limit_mid_epoch_resumes_within_that_epoch(tiny_dataset, tmp_path):
    """--max-steps stopping inside an epoch used to close the epoch: the resume started the next one, and the
    rest of the stopped epoch's batches were never trained on."""
    torch.set_num_threads(1)
    assert main(["--data", str(tiny_dataset), "--out", str(tmp_path / "straight"), *ARGS]) == 0
    run = tmp_path / "stepped"
    assert main(["--data", str(tiny_dataset), "--out", str(run), *ARGS, "--max-steps", "1"]) == 0
    state = torch.load(run / "state.pt", weights_only=True)
    assert (state["epoch"], state["batch"]) == (0, 1), "the tiny dataset's epoch must have more than one batch"
    stopped = json.loads((run / "metrics.json").read_text())["history"]
    assert [(h["epoch"], h.get("partial")) for h in stopped] == [(1, True)]
    assert (run / "best.pt").stat().st_size > 0          # a smoke run still leaves a model

    assert main(["--data", str(tiny_dataset), "--out", str(run), "--resume", *ARGS]) == 0
    assert _weights(run) == _weights(tmp_path / "straight")
    history = json.loads((run / "metrics.json").read_text())["history"]
    assert [(h["epoch"], h.get("partial")) for h in history] == [(1, None), (2, None), (3, None)]
    straight = json.loads((tmp_path / "straight" / "metrics.json").read_text())["history"]
    assert [h["train_images"] for h in history] == [h["train_images"] for h in straight]
