"""Output files get the mode of any other new file (0644 under umask 022), secrets 0600 (issue 27.8).

mkstemp creates 0600, so every atomically written file (run.json, summary.json, tables, report.md,
state.pt, checkpoints) used to be private while plain outputs beside it were 0644.
"""
import os
import stat

import pytest

from defgg_ros.atomic import SECRET_MODE, atomic_path, default_file_mode, write_json_atomic, write_text_atomic
from defgg_ros.bringup.demo_report import write_summary

pytestmark = pytest.mark.unit


@pytest.fixture
def umask():
    """Set the process umask for the test, restore it after."""
    previous = os.umask(0o022)
    os.umask(previous)
    yield lambda mask: os.umask(mask)
    os.umask(previous)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask, expected", [(0o022, 0o644), (0o027, 0o640), (0o002, 0o664)])
def test_atomic_files_get_the_mode_a_plain_file_gets(tmp_path, umask, mask, expected):
    umask(mask)
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    assert default_file_mode() == expected == mode(plain)
    write_json_atomic(tmp_path / "run.json", {"a": 1})
    write_text_atomic(tmp_path / "tables" / "shake.md", "| a |\n")
    write_summary(tmp_path / "summary.json", [], {"scene": "x"})
    with atomic_path(tmp_path / "state.pt") as tmp:
        tmp.write_bytes(b"\0" * 16)  # what torch.save writes through it
    for name in ("run.json", "tables/shake.md", "summary.json", "state.pt"):
        assert mode(tmp_path / name) == expected, name


def test_secret_files_stay_private_and_a_rewrite_changes_the_mode(tmp_path, umask):
    umask(0o022)
    write_text_atomic(tmp_path / "token", "s3cret", secret=True)
    assert mode(tmp_path / "token") == SECRET_MODE
    write_text_atomic(tmp_path / "token", "public now")  # replaced by a non-secret file: its own mode
    assert mode(tmp_path / "token") == 0o644


def test_a_failed_write_leaves_no_temporary_file(tmp_path, umask):
    umask(0o022)
    with pytest.raises(RuntimeError):
        with atomic_path(tmp_path / "report.md") as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash mid-write")
    assert list(tmp_path.iterdir()) == []
