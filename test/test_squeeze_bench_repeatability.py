"""bench_squeeze_repeatability.py: the stored in-place squeezes reprint their spread without squeezing again, and
bad arguments are refused with the reason."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "bench_squeeze_repeatability.py"
STORED = ROOT / "results" / "squeeze" / "in_place.jsonl"

pytestmark = pytest.mark.sim     # renders the object for its perceived contacts (seconds)


def _bench(*args):
    return subprocess.run([sys.executable, str(BENCH), *args], capture_output=True, text=True, timeout=300)


def test_stored_in_place_squeezes_reprint_their_spread(tmp_path):
    readings = tmp_path / "in_place.jsonl"
    shutil.copy(STORED, readings)
    result = _bench("--objects", "egad_test_11_c3=2e4", "--readings", str(readings))
    assert result.returncode == 0, result.stderr
    assert readings.read_text() == STORED.read_text()          # read, not squeezed again
    row = next(line for line in result.stdout.splitlines() if line.startswith("egad_test_11_c3"))
    assert row.split()[2:6] == ["0.86", "0.86", "0.86", "1.00"]
    assert "within 20 % (spread <= 1.2): 1 of 1 objects" in result.stdout


@pytest.mark.parametrize("args, says", [(["--times", "1"], "--times must be >= 2"),
                                        (["--objects", "common_ball"], "NAME=E_PA")])
def test_bad_arguments_are_refused_with_the_reason(args, says):
    result = _bench(*args)
    assert result.returncode != 0 and says in result.stderr
