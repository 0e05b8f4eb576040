"""A real 2-process DDP run (torchrun, gloo on CPU) for a few steps."""
import json
import os
import subprocess
import sys

from defgg_ros.model.inference import GraspPredictor


def test_torchrun_two_processes(tiny_dataset, tmp_path):
    out = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
           "-m", "defgg_ros.train.cli", "--data", str(tiny_dataset), "--out", str(out), "--epochs", "1",
           "--max-steps", "2", "--batch-size", "1", "--samples-per-scene", "1", "--no-progress",
           "--val-fraction", "0.3", "--test-fraction", "0.3"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=240, env=env)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["world_size"] == 2
    assert metrics["history"][0]["step"] == 2
    assert metrics["history"][0]["train_images"] == 4   # 2 steps x 1 image x 2 processes
    assert GraspPredictor.from_checkpoint(out / "model.pt").uses_stiffness
