"""defgg-record against live segmentation + inference nodes fed by a stand-in camera (real rclpy, DDS)."""
import os
import random
import re
import threading

import pytest
from support.replay_process import run_replay
from support.session_synthetic_camera import SyntheticCamera

from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.ros.domain import pick_private_domain
from defgg_ros.ros.parameters import defaults
from defgg_ros.ros.transport import FASTDDS_PROFILE, FASTDDS_PROFILE_VARIABLE
from defgg_ros.sessions import record
from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.session import load_session, stamp_ns
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

PRIVATE_DOMAIN = pick_private_domain(rng=random.Random(os.getpid()))


@pytest.fixture
def large_messages(monkeypatch):
    """The Fast DDS profile for camera-sized messages, and a ROS domain of these tests' own.

    Set before the rclpy context exists; a domain other than the test process's keeps nodes left
    there by earlier tests from showing up in the recording.
    """
    monkeypatch.setenv(FASTDDS_PROFILE_VARIABLE, str(FASTDDS_PROFILE))
    monkeypatch.setenv("ROS_DOMAIN_ID", str(PRIVATE_DOMAIN))


@pytest.fixture
def live_cell(large_messages, executor):
    """Camera at 5 Hz + segmentation + inference (shipped model), spinning in a background thread.

    Yields a function that stops the cell early (idempotent; the fixture calls it at teardown).
    """
    for node in (SegmentationNode(context=executor.context), GraspInferenceNode(context=executor.context),
                 SyntheticCamera(0.2, context=executor.context)):
        executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()

    def stop():
        executor.shutdown(timeout_sec=2.0)
        thread.join(timeout=5.0)

    yield stop
    stop()


def test_driven_recording_holds_frames_calls_grasps_and_metadata(live_cell, tmp_path):
    out = tmp_path / "session"
    assert record.main([str(out), "--plan", "2", "--depth-period-s", "1000", "--no-color",
                        "--note", "test", "--param-timeout-s", "10"]) == 0
    session = load_session(out)
    meta = session.metadata
    assert meta["source"] == "real" and meta["scene"] is None and meta["note"] == "test"
    assert meta["model"]["file"] == "defgg_cnn.pt" and meta["model"]["use_stiffness"] is True
    assert meta["parameters"]["grasp_inference_node"]["use_stiffness"] is True
    assert meta["software"]["defgg_ros"]
    calls = session.of_kind("plan")
    assert len(calls) == 2 and all(c.response is not None and c.response.decode().success for c in calls)
    frames = {f.stamp_ns: f for f in session.frames}
    for call in calls:  # every planned-on frame is in the bag, with its published grasp
        planned = stamp_ns(call.response.decode().grasps[0].header.stamp)
        assert planned in frames and frames[planned].best_grasp is not None
    kinds = [e.kind for e in session.events]
    assert kinds[0] == "assignment" and kinds.index("frame") < kinds.index("plan")
    topics_in_bag = {m.topic for m in session.messages}
    assert {topics.DEPTH_IMAGE, topics.DEPTH_CAMERA_INFO, topics.STIFFNESS_ASSIGNMENTS,
            st.PLAN_REQUEST} <= topics_in_bag


def test_recording_without_a_cell_fails_clearly(tmp_path, large_messages, capsys, monkeypatch):
    # not the domain the other tests' cell used
    monkeypatch.setenv("ROS_DOMAIN_ID", str(pick_private_domain(exclude=(PRIVATE_DOMAIN,))))
    out = tmp_path / "session"
    assert record.main([str(out), "--plan", "1", "--wait-s", "1", "--param-timeout-s", "0.2"]) == 2
    err = capsys.readouterr().err
    # what the graph showed: the next such failure says whether discovery saw the cell at all (CI, 2026-12-03)
    assert "defgg/plan_grasp did not appear within 1 s; the graph lists no server of /defgg/plan_grasp; " in err, err
    assert re.search(r"\d+ node\(s\) seen: ", err), err
    assert not out.exists()


def test_a_fresh_recording_replays_clean(live_cell, tmp_path):
    """Record -> replay in a fresh graph of node processes: the real-cell path (no scene, no picks).

    The recording cell is stopped first and the replay runs in a process of its own, as a user would
    replay a session later (CI once saw the replayed frame get no grasp while both shared this process).
    """
    out = tmp_path / "fresh"
    assert record.main([str(out), "--plan", "1", "--depth-period-s", "1000", "--no-color"]) == 0
    # Driving, the recorder waits for the perception nodes' parameters even past --param-timeout-s (CI
    # once recorded none under load, and the replay ran the shipped YAML's contact_angle: true instead).
    session = load_session(out)
    assert {"segmentation_node", "grasp_inference_node"} <= set(session.metadata["parameters"])
    # The camera's pose came from the cell's calibration on /tf_static (base_T_camera not set): the bag keeps it,
    # and the replay latches it again (without it the replay's grasps came in the table frame, 90 mm away).
    assert session.metadata["parameters"]["segmentation_node"]["base_T_camera"] == [0.0] * 7
    assert any(t.child_frame_id == "camera_link" for m in session.static_transforms for t in m.decode().transforms)
    assert {g.pose_base.header.frame_id for c in session.of_kind("plan") for g in c.response.decode().grasps} == {
        defaults("segmentation_node")["base_frame"]}
    live_cell()
    code, text = run_replay(out)
    assert code == 0, text
    assert re.search(r"fresh: all \d+ item\(s\) match", text), text


@pytest.mark.parametrize("argv, says", [
    (["--duration-s", "-5"], "--duration-s must be >= 0, got -5"), (["--top-k", "0"], "--top-k must be >= 1"),
    (["--plan", "-1"], "--plan must be >= 0"), (["--width-tol-mm", "0"], "--width-tol-mm must be > 0"),
    (["--depth-period-s", "nan"], "--depth-period-s must be >= 0"),
    (["--stiffness-from-scene"], "--stiffness-from-scene needs --scene"),
    (["--pick", "0"], "--pick needs --plan N"), (["--plan", "2", "--pick", "2"], "--pick indices must be in 0..1"),
    (["--plan", "2", "--pick", "first"], "--pick needs plan indices like 0,2")])
def test_options_out_of_range_are_refused_before_anything_connects(tmp_path, capsys, argv, says):
    assert record.main([str(tmp_path / "bag"), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"defgg-record: error: {says}"), err
    assert not (tmp_path / "bag").exists()


def test_a_recording_missing_a_frame_the_cell_used_is_an_error():
    """The recorder noted a frame the cell planned on that never reached it; defgg-record said nothing about it
    and exited 0, and the session's replay then compared the cell's answer against another frame."""
    from defgg_ros.sessions.record import IncompleteRecording, check_complete

    check_complete("s.bag", [])
    missing = [f"frame @{i}.000s was used by the cell but never reached the recorder" for i in range(5)]
    with pytest.raises(IncompleteRecording, match=r"s.bag is incomplete: frame @0.000s .*\(5 in all\)"):
        check_complete("s.bag", missing)
