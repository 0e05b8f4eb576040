"""defgg-replay end to end: real node processes over DDS, the real fake driver for the pick.

The committed sessions replay clean (this is CI's regression check of the
cell); a swapped model, shifted intrinsics, a damaged bag each give a
non-zero exit and a message naming the frames and the difference.
"""
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from support.replay_process import run_replay

from defgg_ros.provenance import file_sha256
from defgg_ros.ros.transport import FASTDDS_PROFILE, FASTDDS_PROFILE_VARIABLE
from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.bag import SessionWriter, read_bag
from defgg_ros.sessions.interfaces import session_typestore
from defgg_ros.sessions.session import load_session
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

REPO = Path(__file__).resolve().parents[2]
SESSIONS = REPO / "sim_bringup" / "sessions"
DEPTH_ONLY = REPO / "models" / "ggcnn_depth_only.pt"


@pytest.fixture(autouse=True)
def large_messages(monkeypatch):
    """The replay's Fast DDS profile, set (and restored) around each test instead of for the whole process."""
    monkeypatch.setenv(FASTDDS_PROFILE_VARIABLE, str(FASTDDS_PROFILE))


def test_committed_sessions_replay_clean_including_a_pick():
    sessions = sorted(p.name for p in SESSIONS.iterdir() if (p / "metadata.yaml").is_file())
    assert {"rigid_objects", "soft_objects", "mixed_objects"} <= set(sessions)
    assert all(sum(f.stat().st_size for f in (SESSIONS / s).iterdir()) < 3e6 for s in sessions)
    assert any(load_session(SESSIONS / s).picks for s in sessions)
    code, text = run_replay(SESSIONS)
    assert code == 0, text
    for name in sessions:
        assert f"{name}: all" in text
    pick_rows = re.findall(r"^pick 0 .*$", text, re.M)
    assert pick_rows and all(row.rstrip().endswith("ok") and "skipped" not in row for row in pick_rows)


def test_depth_only_model_is_a_regression_and_update_rerecords_it(tmp_path):
    session = shutil.copytree(SESSIONS / "mixed_objects", tmp_path / "mixed_objects")
    code, text = run_replay(session, "--model", DEPTH_ONLY)
    assert code == 1, text
    assert "REGRESSION in session mixed_objects" in text and "the model differs from the recording" in text
    assert "frame 0 @" in text.split("REGRESSION in session")[1]
    assert "position moved" in text or "angle changed" in text or "width changed" in text
    # On purpose: re-record with the depth-only model, then it replays clean with it.
    code, text = run_replay(session, "--model", DEPTH_ONLY, "--update")
    assert code == 0 and "expectations re-recorded" in text, text
    assert load_session(session).metadata["model"]["sha256"] == file_sha256(DEPTH_ONLY)
    code, text = run_replay(session, "--model", DEPTH_ONLY)
    assert code == 0, text


def shift_principal_point(source: Path, target: Path, shift_px: float) -> Path:
    """Copy a session with cx moved by shift_px in every camera_info (a changed calibration)."""
    store = session_typestore()
    meta, messages = read_bag(source)
    writer = SessionWriter(target, meta, messages[0].log_time_ns)
    for m in messages[1:]:
        raw = m.raw
        if m.topic == topics.DEPTH_CAMERA_INFO:
            info = m.decode()
            info.k, info.p = info.k.copy(), info.p.copy()  # decoded arrays are read-only views
            info.k[2] += shift_px
            info.p[2] += shift_px
            raw = bytes(store.serialize_cdr(info, m.msgtype))
        writer.write(m.topic, raw, m.log_time_ns, m.msgtype, m.msgdef)   # as recorded
    return writer.close()


def test_shifted_intrinsics_are_a_regression_naming_the_frames(tmp_path):
    session = shift_principal_point(SESSIONS / "soft_objects", tmp_path / "soft_objects", 30.0)
    def principal_points(path):
        return [m.decode().k[2] for m in read_bag(path)[1] if m.topic == topics.DEPTH_CAMERA_INFO]
    assert np.allclose(principal_points(session), np.array(principal_points(SESSIONS / "soft_objects")) + 30.0)
    code, text = run_replay(session, "--no-pick")
    assert code == 1, text
    report = text.split("REGRESSION in session soft_objects")[1]
    assert "frame 0 @" in report and "position moved" in report


@pytest.mark.parametrize("damage", ["truncate", "missing"])
def test_damaged_bag_is_a_clear_error_not_a_traceback(tmp_path, damage):
    session = shutil.copytree(SESSIONS / "soft_objects", tmp_path / "soft_objects")
    mcap = next(session.glob("*.mcap"))
    if damage == "truncate":
        mcap.write_bytes(mcap.read_bytes()[:5000])
    else:
        mcap.unlink()
    code, text = run_replay(session)
    assert code == 2
    assert "soft_objects: cannot replay:" in text and "re-record" in text
    assert "Traceback" not in text


def test_a_folder_without_sessions_is_an_error(tmp_path):
    code, text = run_replay(tmp_path)
    assert code == 2 and "holds no session bags" in text and "Traceback" not in text


def test_a_pick_that_no_longer_succeeds_is_a_regression(tmp_path):
    """The simulated world differs from the recording (objects 6 cm off where the frames show them): the pick misses."""
    meta, messages = read_bag(SESSIONS / "rigid_objects")
    moved = {"position_xy_m: [0.5, 0.0]": "position_xy_m: [0.5, 0.06]",
             "position_xy_m: [0.58, 0.08]": "position_xy_m: [0.58, 0.14]"}
    for old, new in moved.items():
        assert old in meta["scene"]["yaml"]
        meta["scene"]["yaml"] = meta["scene"]["yaml"].replace(old, new)
    writer = SessionWriter(tmp_path / "rigid_objects", meta, messages[0].log_time_ns)
    for m in messages:
        if m.topic != st.METADATA:
            writer.write(m.topic, m.raw, m.log_time_ns, m.msgtype, m.msgdef)
    code, text = run_replay(writer.close())
    assert code == 1, text
    report = text.split("REGRESSION in session rigid_objects")[1]
    assert "pick 0: pick failed but the recording succeeded" in report


@pytest.mark.parametrize("argv, says", [(["--timeout-s", "-1"], "--timeout-s must be > 0"),
                                        (["--width-tol-mm", "-0.5"], "--width-tol-mm must be >= 0 (0: exact)"),
                                        (["--domain-id", "999"], "--domain-id must be in 0..101")])
def test_options_out_of_range_are_an_error_not_a_regression(tmp_path, capsys, argv, says):
    """A negative timeout made every frame 'time out': reported as a REGRESSION with advice to re-record."""
    from defgg_ros.sessions import replay

    assert replay.main([str(tmp_path), *argv]) == replay.EXIT_ERROR
    assert capsys.readouterr().err.startswith(f"defgg-replay: error: {says}")


def test_a_session_with_nothing_to_compare_is_an_error_not_a_pass(tmp_path):
    """Recorded while the cell planned nothing (inference down): no frame has a grasp, no plan or pick call. It
    replayed as "all 0 item(s) match", exit 0, checking nothing."""
    meta, messages = read_bag(SESSIONS / "soft_objects")
    writer = SessionWriter(tmp_path / "passive", meta, messages[0].log_time_ns)
    dropped = {topics.BEST_GRASP, "/defgg/session/plan_grasp_request", "/defgg/session/plan_grasp_response"}
    for m in messages[1:]:
        if m.topic not in dropped:
            writer.write(m.topic, m.raw, m.log_time_ns, m.msgtype, m.msgdef)
    session = writer.close()
    code, text = run_replay(session)
    assert code == 2 and "nothing to compare" in text, text
