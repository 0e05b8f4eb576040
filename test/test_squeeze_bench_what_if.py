"""The squeeze bench's --what-if-hand: the stored FEM squeezes estimated with one hand compliance for every object
(docs/squeeze.md "Limits"), and a clear refusal where the stored readings cannot stand for it."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "bench_squeeze_stiffness.py"
STORED = ROOT / "results" / "squeeze" / "readings.jsonl"

pytestmark = pytest.mark.sim     # renders one object for its perceived contacts (seconds)


def _bench(tmp_path, *args):
    readings = tmp_path / "readings.jsonl"
    shutil.copy(STORED, readings)     # a stored row (the speed-driven hand's): nothing is squeezed or appended
    result = subprocess.run([sys.executable, str(BENCH), "--readings", str(readings), "--hand", "speed-driven", *args],
                            capture_output=True, text=True, timeout=300)
    assert readings.read_text() == STORED.read_text()
    return result


def _section_factor(stdout: str, name: str) -> str:
    row = next(line for line in stdout.splitlines() if line.startswith(name))
    return row.split()[7]       # object, E, then old hand point new perceived section


def test_a_stiff_hand_reads_the_stored_squeeze_with_less_taken_out(tmp_path):
    args = ("--objects", "common_ball", "--moduli", "1.5e6")
    present = _bench(tmp_path, *args)
    stiff = _bench(tmp_path, *args, "--what-if-hand", "2.3", "0.5")
    assert present.returncode == 0 and stiff.returncode == 0, stiff.stderr[-2000:]
    assert "what-if: 2.3 +- 0.5 um/N for every object" in stiff.stdout
    # the present calibration takes 74 um/N out of the ball's ~90 um/N: an over-read; 2.3 um/N much less
    assert float(_section_factor(present.stdout, "common_ball")) > 3 * float(_section_factor(stiff.stdout,
                                                                                              "common_ball"))


@pytest.mark.parametrize("args, says", [
    (("--moduli", "2e5", "2e9"), "the rigid bodies' squeezes (2e+09) were made with the present pads"),
    (("--moduli", "2e5", "--calibrate"), "the rigid bodies' squeezes (--calibrate)"),
])
def test_rigid_rows_are_refused_with_the_reason(tmp_path, args, says):
    result = _bench(tmp_path, "--objects", "common_ball", *args, "--what-if-hand", "2.3", "0.5")
    assert result.returncode == 2 and says in result.stderr


def test_a_compliance_that_is_not_positive_is_refused(tmp_path):
    result = _bench(tmp_path, "--objects", "common_ball", "--moduli", "2e5", "--what-if-hand", "0", "0.5")
    assert result.returncode == 2 and "needs a compliance > 0" in result.stderr
