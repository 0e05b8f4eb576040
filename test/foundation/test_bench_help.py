"""Every benchmark and analysis script in bench/ still starts: `--help` exits 0 and explains what it measures.

A script that imports a renamed function or module fails here rather than on the day its figures are needed.
"""
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
SCRIPTS = sorted(BENCH.glob("*.py"))


def test_the_bench_folder_has_scripts():
    assert len(SCRIPTS) >= 20


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda path: path.name)
def test_help_exits_zero_and_describes_the_script(script):
    run = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120,
                         cwd=BENCH.parent)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.startswith("usage:"), run.stdout[:300]
    assert len(run.stdout.splitlines()) >= 5, f"{script.name} --help says too little:\n{run.stdout}"
