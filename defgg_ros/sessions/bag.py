"""Session bags: rosbag2 (metadata.yaml + one .mcap file, zstd-compressed chunks).

Written with rosbags (no rosbag2 on these machines) so `ros2 bag info/play`
and Foxglove read them on a real install. Messages go in as CDR bytes (what
rclpy's raw subscriptions and `serialize_message` give) and come out as raw
bytes plus a lazy decoder. The session metadata (JSON) is stored twice: in
metadata.yaml's custom_data (for `ros2 bag info`) and as the first message on
/defgg/session/metadata (for players and Foxglove). Every read problem —
missing, truncated, corrupt — becomes a SessionBagError with the path and
the reason. No rclpy here.
"""
import json
import os
import re
import shutil
import struct
import tempfile
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import yaml
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from defgg_ros.atomic import write_text_atomic
from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.interfaces import PACKAGE, session_typestore

CUSTOM_DATA_KEY = "defgg_session"
BAG_VERSION = 9


class SessionBagError(RuntimeError):
    """A session bag that cannot be written or read (the message says which and why)."""


@dataclass(frozen=True)
class BagMessage:
    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes
    msgdef: str = field(default="", compare=False, repr=False)   # the definition the bag recorded

    def decode(self):
        """The message as a rosbags dataclass (same field names as the rclpy message). Our own interfaces
        decode with the definition the bag recorded: a bag made before a message gained fields (e.g. the
        PickAndPlace result's arm_state) still reads, with the fields it had."""
        if self.msgdef and self.msgtype.startswith(f"{PACKAGE}/"):
            return deserialize_cdr(recorded_typestore(self.msgtype, self.msgdef), self.raw, self.msgtype)
        return deserialize_cdr(session_typestore(), self.raw, self.msgtype)


def deserialize_cdr(store, raw: bytes, msgtype: str):
    """store.deserialize_cdr, but slack may follow the last field (rosbags allows 3 bytes): up to 7 bytes, and 4
    more per empty sequence of 8-byte numbers in the message. rclpy's serialize_message and rmw_fastrtps size
    the buffer by an estimate that aligns every sequence of 8-byte numbers to 8 after its length, also an empty
    one, which the serializer itself does not pad (measured: a Grasp whose contact_radii_m and
    contact_line_lengths_m, two float64[], are both empty ends 8 bytes short of its buffer; a PlanGrasp
    response 8 per such grasp; the bytes read the same values as rclpy's). rosbags refuses any of that
    ("CDR message size mismatch")."""
    if len(raw) < 4 or bytes(raw[:2]) not in (b"\x00\x00", b"\x00\x01"):
        raise SessionBagError(f"{msgtype}: not a CDR message (encapsulation {bytes(raw[:2]).hex()})")
    msgdef = store.get_msgdef(msgtype)
    read = msgdef.deserialize_cdr_le if raw[1] else msgdef.deserialize_cdr_be
    try:
        message, end = read(memoryview(raw)[4:], 0, msgdef.cls, store)
    except (struct.error, UnicodeDecodeError, ValueError, SerdeError) as exc:   # SerdeError: e.g. a bad length
        raise SessionBagError(f"{msgtype}: cannot be decoded: {exc}") from exc
    slack = len(raw) - 4 - end
    if slack > 7 and slack > 7 + 4 * empty_wide_sequences(message):
        raise SessionBagError(f"{msgtype}: {slack} bytes after the message's last field")
    return message


def empty_wide_sequences(message) -> int:
    """How many empty sequences of 8-byte numbers (float64[], int64[], uint64[]) a decoded rosbags message holds,
    in its nested messages too."""
    count = 0
    for name in getattr(message, "__dataclass_fields__", ()):
        value = getattr(message, name)
        if isinstance(value, np.ndarray):
            count += int(value.size == 0 and value.dtype.itemsize == 8)
        elif isinstance(value, list):
            count += sum(empty_wide_sequences(item) for item in value)
        else:
            count += empty_wide_sequences(value)
    return count


@lru_cache(maxsize=64)
def recorded_typestore(msgtype: str, msgdef: str):
    """Jazzy's types plus `msgtype` and the types it uses, as a bag's ros2msg definition gives them (the
    main definition, then '=====' separated 'MSG: pkg/Name' sections)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    sections = re.split(r"^=+\s*$", msgdef.replace("\r", ""), flags=re.M)
    types = {}
    for i, text in enumerate(sections):
        if i == 0:
            name, body = msgtype, text
        else:
            header, _, body = text.strip("\n").partition("\n")
            name = header.removeprefix("MSG:").strip()
            if name.count("/") == 1:
                name = name.replace("/", "/msg/")
        if name in store.fielddefs and not name.startswith(f"{PACKAGE}/"):
            continue                        # a standard type: Jazzy's definition
        package, _, stem = name.split("/")
        parsed = get_types_from_msg(body, f"{package}/msg/{stem}")   # relative field types resolve to msg/
        types.update({k: v for k, v in parsed.items() if k != f"{package}/msg/{stem}"})
        types[name] = parsed[f"{package}/msg/{stem}"]
    store.register(types)
    return store


def _qos(latched: bool) -> Qos:
    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1 if latched else 10, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
               zero, zero, QosLiveliness.AUTOMATIC, zero, False)


def serialize_string(text: str) -> bytes:
    store = session_typestore()
    return bytes(store.serialize_cdr(store.types["std_msgs/msg/String"](data=text), "std_msgs/msg/String"))


def write_custom_data(bag_dir, custom_data: dict) -> None:
    """Put `custom_data` into metadata.yaml so that every value reads back unchanged.

    rosbags writes metadata.yaml with ruamel's default line width, which folds a long double-quoted string;
    at a fold right after an escaped backslash the text reads back with a space inserted ("\\ n"): the
    session JSON of sim_bringup/sessions/rigid_objects came back as invalid JSON. Written here unfolded,
    atomically, and checked by reading it back.
    """
    path = Path(bag_dir) / "metadata.yaml"
    document = yaml.safe_load(path.read_text(encoding="utf-8"))
    document["rosbag2_bagfile_information"]["custom_data"] = dict(custom_data)
    out = yaml.safe_dump(document, default_flow_style=False, sort_keys=False, width=2 ** 30, allow_unicode=True)
    if yaml.safe_load(out)["rosbag2_bagfile_information"]["custom_data"] != custom_data:
        raise SessionBagError(f"{path}: custom_data does not read back as written")
    write_text_atomic(path, out)


class SessionWriter:
    """Write a session bag into a temporary folder; `close()` renames it into place.

    A crash or an exception leaves no half-written bag at `path`.
    """

    def __init__(self, path, metadata: dict, log_time_ns: int, overwrite: bool = False):
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise SessionBagError(f"{self.path} exists already (use a new path, or --update to replace a session)")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._overwrite = overwrite
        self._scratch = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent))
        self._tmp_bag = self._scratch / self.path.name
        self._writer = Writer(self._tmp_bag, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        # STORAGE mode = compressed MCAP chunks (zstd), what rosbag2's mcap plugin calls a storage preset.
        self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._writer.set_custom_data(CUSTOM_DATA_KEY, json.dumps(metadata, sort_keys=True))
        self._writer.open()
        self._connections = {}
        self.counts = {}
        self.write(st.METADATA, serialize_string(json.dumps(metadata, sort_keys=True)), log_time_ns)

    def write(self, topic: str, raw: bytes, log_time_ns: int, msgtype: str | None = None,
              msgdef: str = "") -> None:
        """Append one serialized message. `msgdef`: the definition `raw` was made with, when it is not the
        installed one (copying a recorded message of an older layout)."""
        msgtype = msgtype or st.TOPIC_TYPES.get(topic)
        if msgtype is None:
            raise SessionBagError(f"no message type known for topic {topic!r}; pass msgtype")
        if topic not in self._connections:
            typestore = recorded_typestore(msgtype, msgdef) if msgdef else session_typestore()
            self._connections[topic] = self._writer.add_connection(
                topic, msgtype, typestore=typestore, offered_qos_profiles=[_qos(topic in st.LATCHED_TOPICS)])
        self._writer.write(self._connections[topic], int(log_time_ns), bytes(raw))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def update_metadata(self, metadata: dict, log_time_ns: int) -> None:
        """Metadata learned while recording (e.g. node parameters): a newer metadata message wins."""
        text = json.dumps(metadata, sort_keys=True)
        self._writer.set_custom_data(CUSTOM_DATA_KEY, text)
        self.write(st.METADATA, serialize_string(text), log_time_ns)

    def close(self) -> Path:
        self._writer.close()
        write_custom_data(self._tmp_bag, self._writer.custom_data)   # what rosbags wrote folded, unfolded
        if self.path.exists():  # only with overwrite: swap folders, old one removed after
            old = self._scratch / "previous"
            os.rename(self.path, old)
        os.rename(self._tmp_bag, self.path)
        shutil.rmtree(self._scratch, ignore_errors=True)
        return self.path

    def abort(self) -> None:
        try:
            self._writer.close()
        except Exception:  # noqa: BLE001 - already failing; the scratch folder goes anyway
            pass
        shutil.rmtree(self._scratch, ignore_errors=True)


def read_bag(path) -> tuple[dict, list[BagMessage]]:
    """(metadata dict, all messages in log-time order) of a session bag."""
    path = Path(path)
    if not path.exists():
        raise SessionBagError(f"session {path} does not exist")
    if not (path / "metadata.yaml").is_file():
        raise SessionBagError(f"{path} is not a rosbag2 folder (no metadata.yaml)")
    try:
        with Reader(path) as reader:
            expected = reader.message_count
            messages = [BagMessage(c.topic, c.msgtype, t, bytes(raw), _definition(c))
                        for c, t, raw in reader.messages()]
    except SessionBagError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many types for damaged files
        raise SessionBagError(f"{path}: cannot read the bag ({type(exc).__name__}: {exc}); "
                              "it is truncated or corrupt — re-record it") from None
    if len(messages) != expected:
        raise SessionBagError(f"{path}: metadata.yaml announces {expected} messages but the storage holds "
                              f"{len(messages)}; the bag is truncated — re-record it")
    messages.sort(key=lambda m: m.log_time_ns)
    return _metadata(path, messages), messages


def _definition(connection) -> str:
    msgdef = getattr(connection, "msgdef", None)
    return getattr(msgdef, "data", "") or ""


def _metadata(path: Path, messages: list[BagMessage]) -> dict:
    latest = next((m for m in reversed(messages) if m.topic == st.METADATA), None)
    if latest is None:
        raise SessionBagError(f"{path}: no {st.METADATA} message; this is not a defgg session bag")
    try:
        metadata = json.loads(latest.decode().data)
    except Exception as exc:  # noqa: BLE001 - damaged CDR or JSON
        raise SessionBagError(f"{path}: session metadata unreadable ({exc})") from None
    if not isinstance(metadata, dict):
        raise SessionBagError(f"{path}: session metadata must be a JSON object")
    return metadata
