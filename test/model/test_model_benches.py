"""The benchmark scripts run and print their figures (tiny settings; no timing asserted)."""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _run(script, *args):
    result = subprocess.run([sys.executable, str(ROOT / "bench" / script), *args], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    return result.stdout


def test_inference_bench_prints_figures(tmp_path):
    out = _run("bench_inference.py", "--runs", "3", "--threads", "1", "--json", str(tmp_path / "r.json"))
    assert "parameters: reference GG-CNN 62,420" in out
    assert "speed-up vs reference" in out and "predict" in out
    assert (tmp_path / "r.json").stat().st_size > 0


def test_training_bench_prints_figures():
    out = _run("bench_training.py", "--steps", "1", "--batch-size", "2", "--threads", "1")
    assert "ggcnn_bilinear" in out and "images/s" in out
