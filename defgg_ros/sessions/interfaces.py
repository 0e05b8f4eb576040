"""A rosbags typestore that knows ROS 2 Jazzy plus the cell's own interfaces.

rosbag2 stores every topic's message definition in the bag so that
`ros2 bag`, Foxglove and our reader can decode it without the package.
defgg_interfaces is not part of rosbags' built-in stores, so its .msg/.srv/
.action texts are parsed here. Services and actions are not topics: their
parts are registered as message types with rosidl's generated names
(`defgg_interfaces/srv/PlanGrasp_Request`, `.../action/PickAndPlace_Goal`),
the names rclpy's `PlanGrasp.Request` etc. carry, so the CDR bytes from
`rclpy.serialization.serialize_message` are exactly what these types decode.
No rclpy here.
"""
from functools import lru_cache
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from defgg_ros.ros.share import interface_definition_dirs

PACKAGE = "defgg_interfaces"
# Parts of a .srv / .action file, in file order, as rosidl names them.
SRV_PARTS = ("Request", "Response")
ACTION_PARTS = ("Goal", "Result", "Feedback")


class InterfaceError(RuntimeError):
    """The defgg_interfaces definitions cannot be found or parsed."""


def interface_dirs() -> list[Path]:
    """Where the .msg/.srv/.action texts may live: the installed share/, then the source tree."""
    return interface_definition_dirs()


def _split_parts(text: str, n_parts: int, path: Path) -> list[str]:
    parts, current = [], []
    for line in text.splitlines():
        if line.strip() == "---":
            parts.append("\n".join(current))
            current = []
        else:
            current.append(line)
    parts.append("\n".join(current))
    if len(parts) != n_parts:
        raise InterfaceError(f"{path}: expected {n_parts} sections separated by '---', found {len(parts)}")
    return parts


def interface_texts(root: Path) -> dict[str, str]:
    """{rosidl type name: message definition text} for every interface under `root`."""
    texts = {}
    for path in sorted((root / "msg").glob("*.msg")):
        texts[f"{PACKAGE}/msg/{path.stem}"] = path.read_text(encoding="utf-8")
    for kind, names in (("srv", SRV_PARTS), ("action", ACTION_PARTS)):
        for path in sorted((root / kind).glob(f"*.{kind}")):
            for suffix, body in zip(names, _split_parts(path.read_text(encoding="utf-8"), len(names), path)):
                texts[f"{PACKAGE}/{kind}/{path.stem}_{suffix}"] = body
    return texts


@lru_cache(maxsize=1)
def session_typestore():
    """Jazzy's standard types + defgg_interfaces (cached: parsing takes ~0.1 s)."""
    root = next((d for d in interface_dirs() if (d / "msg").is_dir()), None)
    if root is None:
        raise InterfaceError(f"defgg_interfaces definitions not found in {[str(d) for d in interface_dirs()]}")
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in interface_texts(root).items():
        # Parse under the msg namespace so relative field types (`Grasp[] grasps`) resolve to
        # defgg_interfaces/msg/Grasp, then file the type under its real srv/action name.
        package, _, stem = name.split("/")
        parsed = get_types_from_msg(text.replace("\r", ""), f"{package}/msg/{stem}")
        types[name] = parsed[f"{package}/msg/{stem}"]
    store.register(types)
    return store
