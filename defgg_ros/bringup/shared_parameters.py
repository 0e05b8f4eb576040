"""Parameters that describe one physical cell and so must agree between the nodes that declare them.

The table height, the base frame and the arm are each declared by two or three nodes (their own schemas),
and a deployment sets them per node. A cell where the executor
believes the table is at z = 0.02 m and the perception at 0.0 m plans grasps 2 cm into the table or
above the object, without any node noticing. So the bringup resolves each node's effective value
(schema default, then its parameter files in order, then the set's overrides, then -p) and refuses to
start when they differ. Pure: no rclpy.
"""
from __future__ import annotations

from pathlib import Path

import yaml

from defgg_ros.ros.parameters import defaults, schema_path
from defgg_ros.ros.topics import robot_names

# One cell, one value: names declared by more than one node that describe the same physical thing.
# (Topic and action names are left out: a deployment may remap one node's on purpose.)
# The perception parameters (camera pose, object heights) are the segmentation node's alone since it is the only
# perceiver (the inference node reads them from its PerceivedObjects); the workspace box is also the executor's
# (its recovery drop point lies in it), and a box that differs would drop objects where perception ignores them.
# The grasp height rule is the executor's, and the grasp search must put the fingertips where the executor takes
# them: the inference node declares the same two names.
CELL_PARAMETERS = ("robot_type", "base_frame", "table_z_m", "grasp_height_rule", "grasp_depth_below_surface_m",
                   "workspace_box_m")


# A node's section in a parameter file: keyed /**/<node> in the shipped files, so it holds in any namespace
# (real_cell.launch.py's namespace:=, -r __ns:=); a plain <node> key holds only for /<node>.
NODE_KEYS = ("{node}", "/{node}", "/**/{node}")


def node_sections(raw: dict) -> dict:
    """{node name: its ros__parameters} of a loaded parameter file, whichever key form names the node."""
    out = {}
    for key, section in (raw or {}).items():
        if key != "/**" and isinstance(section, dict) and "ros__parameters" in section:
            out[key.removeprefix("/**/").removeprefix("/")] = section["ros__parameters"] or {}
    return out


def _file_section(path: str, node: str) -> dict:
    raw = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    params = dict((raw.get("/**") or {}).get("ros__parameters") or {})   # the wildcard first, then the node's own
    for key in NODE_KEYS:
        params.update((raw.get(key.format(node=node)) or {}).get("ros__parameters") or {})
    return params


def effective_parameters(entry, extra: dict | None = None) -> dict:
    """A node entry's parameter values as the node will see them at start-up (only those its schema declares;
    {} for a node without a schema)."""
    if not schema_path(entry.name).is_file():
        return {}
    declared = defaults(entry.name)
    values = dict(declared)
    for path in entry.params_files:
        values.update(_file_section(path, entry.name))
    values.update(entry.overrides)
    values.update(extra or {})
    return _with_robot_type_names({name: value for name, value in values.items() if name in declared})


def _with_robot_type_names(values: dict) -> dict:
    """A name left empty is the node's robot_type's (base_frame '' = <robot_type>_link0), as the node fills it."""
    if values.get("base_frame") == "" and "robot_type" in values:
        try:
            values["base_frame"] = robot_names(values["robot_type"])["base_frame"]
        except ValueError:
            pass   # the node refuses an unknown robot_type at start-up, naming it
    return values


def _comparable(value):
    # 0 and 0.0 are one table height; a YAML list and a tuple one box
    if isinstance(value, (list, tuple)):
        return tuple(_comparable(v) for v in value)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else value


def disagreements(node_set, overrides_by_node: dict | None = None) -> list[str]:
    """One line per cell parameter whose effective value differs between the set's nodes."""
    overrides_by_node = overrides_by_node or {}
    values = {entry.name: effective_parameters(entry, overrides_by_node.get(entry.name))
              for entry in node_set.nodes}
    lines = []
    for name in CELL_PARAMETERS:
        seen = {node: params[name] for node, params in values.items() if name in params}
        if len({_comparable(v) for v in seen.values()}) > 1:
            lines.append(f"{name}: " + ", ".join(f"{node}={value!r}" for node, value in seen.items()))
    return lines
