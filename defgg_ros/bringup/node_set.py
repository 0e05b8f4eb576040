"""Node sets of the cell (`sim_bringup/config/<set>.yaml`) and the commands that start them.

A set lists nodes: the Python module whose `main()` runs the node, its YAML
parameter files (`--ros-args --params-file`), extra parameter overrides, and
how to tell it is ready (a service, an action server or a publisher on a
topic becomes visible in the ROS graph). `use_sim_time: true` gives every
node of the set use_sim_time:=true (the simulated cell's clock is /clock).
`ros_domain:` private (the default: a random domain, localhost-only discovery,
so a simulated cell never reaches a real robot's controller) or inherit (the
shell's ROS_DOMAIN_ID and discovery: the real cell, whose drivers run apart);
`warn_if_present:` node names that must not share the set's domain (the real
cell warns when it finds the simulated driver).
Pure: no rclpy.
"""
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from defgg_ros.ros.domain import parse_domain_choice
from defgg_ros.ros.share import share_path

READY_KINDS = ("service", "action", "topic")


class NodeSetError(ValueError):
    """A node set file that cannot be started as written."""


@dataclass(frozen=True)
class ReadyCheck:
    kind: str   # service | action | topic
    name: str


@dataclass(frozen=True)
class NodeEntry:
    name: str
    module: str
    params_files: tuple
    ready: ReadyCheck
    overrides: dict = field(default_factory=dict)


@dataclass(frozen=True)
class NodeSet:
    name: str
    use_sim_time: bool
    nodes: tuple
    config_dir: Path
    ros_domain: str = "private"          # the --ros-domain default for this set
    warn_if_present: tuple = ()          # node names that must not be on the set's domain


def config_dir() -> Path:
    """sim_bringup/config of the source tree (or of the installed share folder)."""
    return share_path("sim_bringup", "config")


def resolve_set_path(set_name_or_path: str) -> Path:
    """'sim_cell' -> sim_bringup/config/sim_cell.yaml; a path is taken as is."""
    path = Path(set_name_or_path)
    if path.suffix in (".yaml", ".yml"):
        return path
    return config_dir() / f"{set_name_or_path}.yaml"


def _ready(raw, node_name) -> ReadyCheck:
    if not isinstance(raw, dict) or len(raw) != 1:
        raise NodeSetError(f"node {node_name}: ready must be one of {{service|action|topic: NAME}}, got {raw!r}")
    (kind, name), = raw.items()
    if kind not in READY_KINDS or not str(name).startswith("/"):
        raise NodeSetError(f"node {node_name}: ready needs {READY_KINDS} with an absolute name, got {raw!r}")
    return ReadyCheck(kind, str(name))


def _entry(raw, index, folder: Path) -> NodeEntry:
    if not isinstance(raw, dict) or not raw.get("name") or not raw.get("module"):
        raise NodeSetError(f"nodes[{index}] needs name and module, got {raw!r}")
    name = str(raw["name"])
    params = tuple(str((folder / p).resolve()) for p in raw.get("params", []) or [])
    for p in params:
        if not Path(p).is_file():
            raise NodeSetError(f"node {name}: parameter file {p} does not exist")
    overrides = raw.get("overrides") or {}
    if not isinstance(overrides, dict):
        raise NodeSetError(f"node {name}: overrides must be a mapping")
    return NodeEntry(name, str(raw["module"]), params, _ready(raw.get("ready"), name), dict(overrides))


def load_node_set(set_name_or_path: str) -> NodeSet:
    path = resolve_set_path(set_name_or_path)
    if not path.is_file():
        raise NodeSetError(f"node set {set_name_or_path!r}: {path} does not exist")
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise NodeSetError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(raw, dict) or not raw.get("nodes"):
        raise NodeSetError(f"{path}: needs a non-empty 'nodes' list")
    nodes = tuple(_entry(n, i, path.parent) for i, n in enumerate(raw["nodes"]))
    names = [n.name for n in nodes]
    if len(set(names)) != len(names):
        raise NodeSetError(f"{path}: node names must be unique, got {names}")
    domain = str(raw.get("ros_domain", "private"))
    try:
        parse_domain_choice(domain)
    except ValueError as exc:
        raise NodeSetError(f"{path}: ros_domain: {exc}") from None
    warn = raw.get("warn_if_present") or []
    if not isinstance(warn, list) or not all(isinstance(n, str) and n for n in warn):
        raise NodeSetError(f"{path}: warn_if_present must be a list of node names, got {warn!r}")
    return NodeSet(str(raw.get("name", path.stem)), bool(raw.get("use_sim_time", False)), nodes, path.parent,
                   domain, tuple(warn))


def _ros_value(value) -> str:
    """A `-p name:=value` value as rcl reads it (YAML). Strings quoted: an empty one, one with ': ' or '#', or
    one that reads as a number would not parse, or parse as another type, and the node died at start-up."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_ros_value(v) for v in value) + "]"
    if isinstance(value, str):
        return json.dumps(value)
    return str(value)


def node_command(entry: NodeEntry, use_sim_time: bool, extra_overrides: dict | None = None) -> list:
    """argv that runs one node in a fresh Python process with its parameters."""
    cmd = [sys.executable, "-c", f"from {entry.module} import main; main()", "--ros-args",
           "-r", f"__node:={entry.name}"]
    for params in entry.params_files:
        cmd += ["--params-file", params]
    overrides = dict(entry.overrides)
    if use_sim_time:
        overrides["use_sim_time"] = True
    overrides.update(extra_overrides or {})
    for key, value in overrides.items():
        cmd += ["-p", f"{key}:={_ros_value(value)}"]
    return cmd
