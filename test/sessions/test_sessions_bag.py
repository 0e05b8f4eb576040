"""Session bags: MCAP + metadata round trip, atomic writing, and clear errors on damaged bags."""
import shutil
from pathlib import Path

import pytest
import yaml
from support.session_bag_helpers import GRASP_BEFORE_LINE_LENGTHS, metadata, write_small_session

from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.bag import SessionBagError, SessionWriter, read_bag
from defgg_ros.sessions.session import load_session
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

GRASP = "defgg_interfaces/msg/Grasp"


def test_round_trip_is_mcap_with_zstd_chunks_and_metadata_twice(tmp_path):
    path = write_small_session(tmp_path / "s")
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap"
    assert "defgg_session" in info["custom_data"]
    mcap = (path / info["relative_file_paths"][0]).read_bytes()
    assert mcap.startswith(b"\x89MCAP0\r\n") and b"zstd" in mcap
    meta, messages = read_bag(path)
    assert meta["format"] == "defgg_session/2" and meta["model"]["file"] == "defgg_cnn.pt"
    assert len(meta["model"]["sha256"]) == 64 and meta["software"]["defgg_ros"]
    assert [m.topic for m in messages].count(topics.DEPTH_IMAGE) == 3
    grasp = next(m for m in messages if m.topic == st.PLAN_RESPONSE).decode().grasps[0]
    assert grasp.header.stamp.sec == 3 and grasp.width_m == pytest.approx(0.03)


def _custom_data(path):
    return yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]["custom_data"][
        "defgg_session"]


def test_custom_data_reads_back_as_the_session_metadata_even_long_and_multiline(tmp_path):
    # rosbags folds long quoted strings; a fold after an escaped backslash read back as "\\ n" (invalid JSON)
    import json

    meta = metadata()
    meta["note"] = "\n".join(f"# line {i}: a scene file's comment, long enough to be folded by YAML" for i in range(60))
    writer = SessionWriter(tmp_path / "long", meta, 0)
    meta["parameters"] = {"executor_node": {f"p{i}": "x" * (i % 17) for i in range(200)}}
    writer.update_metadata(meta, 1)
    path = writer.close()
    assert json.loads(_custom_data(path)) == read_bag(path)[0] == meta
    for session in sorted(Path(__file__).resolve().parents[2].joinpath("sim_bringup", "sessions").iterdir()):
        if (session / "metadata.yaml").is_file():   # the shipped sessions too
            assert json.loads(_custom_data(session)) == read_bag(session)[0], session.name


def test_session_timeline_pairs_frames_grasps_and_calls(tmp_path):
    session = load_session(write_small_session(tmp_path / "s"))
    assert [e.kind for e in session.events] == ["assignment", "frame", "frame", "frame", "plan"]
    assert [f.stamp_ns for f in session.frames] == [1e9, 2e9, 3e9]
    assert session.frames[2].best_grasp.decode().pose_base.pose.position.x == pytest.approx(0.52)
    assert session.of_kind("plan")[0].response is not None


def test_writer_refuses_to_overwrite_and_abort_leaves_nothing(tmp_path):
    path = write_small_session(tmp_path / "s")
    with pytest.raises(SessionBagError, match="exists already"):
        SessionWriter(path, metadata(), 0)
    writer = SessionWriter(tmp_path / "t", metadata(), 0)
    writer.write(topics.BEST_GRASP, b"\x00\x01\x00\x00" + bytes(200), 1)
    writer.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]


def test_unknown_topic_needs_a_type(tmp_path):
    writer = SessionWriter(tmp_path / "t", metadata(), 0)
    with pytest.raises(SessionBagError, match="no message type known"):
        writer.write("/made/up", b"", 1)
    writer.abort()


def _mcap(path):
    return next(path.glob("*.mcap"))


@pytest.mark.parametrize("damage, message", [
    ("truncate", "truncated or corrupt"),
    ("garble", "truncated or corrupt"),
    ("no_yaml", "not a rosbag2 folder"),
    ("missing", "does not exist"),
])
def test_damaged_bags_give_a_clear_error(tmp_path, damage, message):
    path = write_small_session(tmp_path / "s")
    mcap = _mcap(path)
    data = mcap.read_bytes()
    if damage == "truncate":
        mcap.write_bytes(data[: len(data) // 2])
    elif damage == "garble":
        mcap.write_bytes(data[:40] + bytes(len(data) - 80) + data[-40:])
    elif damage == "no_yaml":
        (path / "metadata.yaml").unlink()
    else:
        shutil.rmtree(path)
    with pytest.raises(SessionBagError, match=message):
        load_session(path)


def test_a_bag_without_session_metadata_is_rejected(tmp_path):
    writer = SessionWriter(tmp_path / "s", metadata(), 0)
    path = writer.close()
    # Rewrite the bag without its metadata message: a foreign rosbag2 bag.
    _, messages = read_bag(path)
    other = tmp_path / "other"
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin

    from defgg_ros.sessions.interfaces import session_typestore
    with Writer(other, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        w.add_connection(topics.BEST_GRASP, "defgg_interfaces/msg/Grasp", typestore=session_typestore())
    assert messages and messages[0].topic == st.METADATA
    with pytest.raises(SessionBagError, match="not a defgg session bag"):
        load_session(other)


def test_a_frame_whose_camera_info_was_lost_gets_the_nearest_one_restamped(tmp_path):
    path = write_small_session(tmp_path / "s")
    meta, messages = read_bag(path)
    lost = [m for m in messages if not (m.topic == topics.DEPTH_CAMERA_INFO and m.decode().header.stamp.sec == 2)]
    writer = SessionWriter(tmp_path / "lossy", meta, 0)
    for m in lost[1:]:
        writer.write(m.topic, m.raw, m.log_time_ns, m.msgtype)
    frame = load_session(writer.close()).frames[1]
    info = frame.camera_info.decode()
    assert info.header.stamp.sec == 2 and info.k[0] == pytest.approx(385.0) and info.width == 64


def test_committed_sessions_decode_with_an_independent_mcap_ros2_reader():
    """mcap + mcap-ros2-support (not rosbags): ros2msg schemas, cdr messages, zstd chunks, every message decodes."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    sessions = Path(__file__).resolve().parents[2] / "sim_bringup" / "sessions"
    for mcap_path in sorted(sessions.glob("*/*.mcap")):
        with open(mcap_path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
            assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
            assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
            decoded = {channel.topic: message for _, channel, _, message in reader.iter_decoded_messages()}
        assert decoded[topics.DEPTH_IMAGE].encoding in ("16UC1", "32FC1")
        assert decoded[st.PLAN_RESPONSE].grasps[0].width_m > 0


def test_a_grasp_as_rclpy_serialises_it_decodes_with_or_without_contact_radii_and_line_lengths():
    # Fast CDR sizes the buffer up to 4 bytes past each empty float64[] (8 for a Grasp with neither radii nor
    # line lengths, 8 per such grasp in a PlanGrasp response); rosbags' own reader refused that.
    from defgg_interfaces.msg import Grasp
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.serialization import serialize_message

    from defgg_ros.sessions.bag import BagMessage

    for radii, lines in (([], []), ([0.02, 0.03], []), ([0.02, 0.03], [0.0, 0.018]), ([], [0.0, 0.018])):
        raw = bytes(serialize_message(Grasp(finger_force_n=1.5, contact_radii_m=radii, contact_line_lengths_m=lines)))
        decoded = BagMessage(topics.BEST_GRASP, GRASP, 0, raw).decode()
        assert decoded.finger_force_n == 1.5 and list(decoded.contact_radii_m) == radii
        assert list(decoded.contact_line_lengths_m) == lines
    grasps = [Grasp(finger_force_n=float(i)) for i in range(3)]
    raw = bytes(serialize_message(PlanGrasp.Response(success=True, grasps=grasps, inference_time_s=0.25)))
    decoded = BagMessage(st.PLAN_RESPONSE, "defgg_interfaces/srv/PlanGrasp_Response", 0, raw).decode()
    assert [g.finger_force_n for g in decoded.grasps] == [0.0, 1.0, 2.0] and decoded.inference_time_s == 0.25
    for grasp in (Grasp(), Grasp(contact_radii_m=[0.02, 0.03], contact_line_lengths_m=[0.0, 0.018])):
        with pytest.raises(SessionBagError, match="bytes after"):      # 8 bytes more than Fast CDR leaves
            BagMessage(topics.BEST_GRASP, GRASP, 0, bytes(serialize_message(grasp)) + bytes(8)).decode()
    with pytest.raises(SessionBagError, match="cannot be decoded"):   # a string without its terminator
        BagMessage(topics.BEST_GRASP, GRASP, 0, b"\x00\x01\x00\x00" + bytes(400)).decode()


def test_a_grasp_recorded_before_contact_line_lengths_reads_and_replays_as_point_contacts(tmp_path):
    """The bag keeps the definition it recorded: a grasp of the old layout decodes with it (its radii kept) and
    goes back into the graph as today's Grasp without line lengths (all point contacts); today's round-trips."""
    from defgg_interfaces.msg import Grasp
    from rclpy.serialization import serialize_message

    from defgg_ros.sessions.bag import recorded_typestore
    from defgg_ros.sessions.interfaces import session_typestore
    from defgg_ros.sessions.live_message import live_message

    today = Grasp(width_m=0.04, finger_force_n=1.5, contact_radii_m=[0.02, 0.03], contact_line_lengths_m=[0.0, 0.018])
    fields = session_typestore().deserialize_cdr(bytes(serialize_message(today)), GRASP).__dict__
    old_store = recorded_typestore(GRASP, GRASP_BEFORE_LINE_LENGTHS)
    old_cls = old_store.types[GRASP]
    old = old_cls(**{name: fields[name] for name in old_cls.__dataclass_fields__})
    recorded = _recorded_grasp(tmp_path / "old", old_store.serialize_cdr(old, GRASP), GRASP_BEFORE_LINE_LENGTHS)
    current = _recorded_grasp(tmp_path / "today", serialize_message(today), "")
    assert "contact_line_lengths_m" not in recorded.msgdef and "contact_line_lengths_m" in current.msgdef
    assert list(recorded.decode().contact_radii_m) == [0.02, 0.03]
    replayed = live_message(recorded, Grasp)
    assert (replayed.width_m, replayed.finger_force_n, list(replayed.contact_radii_m)) == (0.04, 1.5, [0.02, 0.03])
    assert list(replayed.contact_line_lengths_m) == []
    assert live_message(current, Grasp) == today


def _recorded_grasp(path, raw, msgdef: str):
    """A one-grasp session at `path` (recorded with `msgdef`; "": the installed definition), read back."""
    writer = SessionWriter(path, metadata(), 0)
    writer.write(topics.BEST_GRASP, bytes(raw), 1, msgdef=msgdef)
    return next(m for m in read_bag(writer.close())[1] if m.topic == topics.BEST_GRASP)
