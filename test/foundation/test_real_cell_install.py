"""The real cell's install (docs/real_cell.md, "1. Install") gives the three nodes every module they can import.

A module reachable from segmentation_node, grasp_inference_node or executor_node (their import closure inside
defgg_ros, lazy imports included) must come from rosdep, i.e. its key is an <exec_depend> of package.xml, has a
rule in rosdistro (or is a package built in the same workspace) and is not in the documented `--skip-keys`, or
from pip, i.e. its distribution is pinned in scripts/requirements-real-cell.txt. That file holds the lock's
versions and nothing the nodes do not import. The rosdep command must skip every key that has no rule (rosdep
would stop there).
"""
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from support.doc_commands import commands, option_value
from support.import_closure import third_party_imports
from test_package_deps import MODULE_KEYS

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "real_cell.md"
REQUIREMENTS = REPO / "scripts" / "requirements-real-cell.txt"
LOCK = REPO / "requirements.lock"
REAL_CELL_NODES = ("defgg_ros.nodes.segmentation_node", "defgg_ros.nodes.grasp_inference_node",
                   "defgg_ros.nodes.executor_node")
# Keys with a rosdep rule, read from ros/rosdistro (2026-08-22 snapshot): rosdep/python.yaml ...
ROSDEP_RULES = {"python3-torch", "python3-numpy", "python3-opencv", "python3-yaml", "python3-tqdm",
                "python3-matplotlib", "python3-pytest", "python3-hypothesis", "python3-pybullet-pip",
                "python3-rosbags-pip", "python3-pyvista-pip"}
# ... and jazzy/distribution.yaml (released ROS packages resolve by name)
JAZZY_RELEASED = {"rclpy", "rcl_interfaces", "rosgraph_msgs", "ament_index_python", "std_msgs", "sensor_msgs",
                  "geometry_msgs", "trajectory_msgs", "visualization_msgs", "std_srvs", "builtin_interfaces",
                  "action_msgs", "tf2_msgs", "control_msgs", "controller_manager_msgs", "lifecycle_msgs",
                  "diagnostic_msgs", "pinocchio", "ruckig"}
# Built from source in the same workspace: franka_ros2 (not released for Jazzy) and msg_defs/
WORKSPACE_PACKAGES = {"franka_msgs", "defgg_interfaces"}
# franka_ros2's own skip (its README's rosdep command)
FRANKA_SKIP_KEYS = {"zed_wrapper"}
# Python module -> the pip distribution that provides it
PIP_DISTRIBUTIONS = {"torch": "torch", "ruckig": "ruckig", "pybullet": "pybullet", "pybullet_data": "pybullet",
                     "numpy": "numpy", "cv2": "opencv-python-headless", "yaml": "PyYAML", "pinocchio": "pin"}
# pip must not shadow these: ROS's compiled modules and rosdep's apt packages are built against the OS's numpy
NEVER_FROM_PIP = {"numpy", "opencv-python-headless", "opencv-python", "pin"}


def documented_skip_keys() -> set[str]:
    rosdep = [c for c in commands(DOC) if c.argv[:2] == ("rosdep", "install")]
    assert len(rosdep) == 1, f"{DOC.name} must hold one rosdep install command, has {len(rosdep)}"
    value = option_value(rosdep[0].argv, "--skip-keys")
    assert value, f"{rosdep[0]}: no --skip-keys"
    return set(value.split())


def requirement_lines() -> dict[str, str]:
    """distribution (lower case) -> its specifier, from scripts/requirements-real-cell.txt."""
    out = {}
    for line in REQUIREMENTS.read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, specifier = re.match(r"^([A-Za-z0-9_.\-]+)\s*(.*)$", line).groups()
            out[name.lower()] = specifier.replace(" ", "")
    return out


def lock_pins() -> dict[str, str]:
    pins = {}
    for line in LOCK.read_text(encoding="utf-8").splitlines():
        if "==" in line and not line.lstrip().startswith("#"):
            name, version = line.split("#", 1)[0].strip().split("==")
            pins[name.lower()] = version
    return pins


def package_xml_keys() -> set[str]:
    root = ET.parse(REPO / "package.xml").getroot()
    return {e.text.strip() for tag in ("exec_depend", "depend") for e in root.iter(tag)}


def real_cell_modules() -> dict[str, set[str]]:
    return third_party_imports(*REAL_CELL_NODES)


def test_every_module_the_real_cell_nodes_import_is_installed_by_rosdep_or_pip():
    skipped, declared, pinned = documented_skip_keys(), package_xml_keys(), requirement_lines()
    uncovered = {}
    for module, importers in sorted(real_cell_modules().items()):
        assert module in MODULE_KEYS, f"{module} (imported by {sorted(importers)[:2]}) has no key in MODULE_KEYS"
        key = MODULE_KEYS[module]
        by_rosdep = (key in declared and key not in skipped
                     and (key in ROSDEP_RULES | JAZZY_RELEASED | WORKSPACE_PACKAGES))
        by_pip = PIP_DISTRIBUTIONS.get(module, "").lower() in pinned
        if not (by_rosdep or by_pip):
            uncovered[module] = (key, sorted(importers)[:2])
    assert not uncovered, f"imported by the real-cell nodes, installed by neither rosdep nor pip: {uncovered}"


def test_the_rosdep_command_skips_every_key_without_a_rule():
    keys = package_xml_keys() - WORKSPACE_PACKAGES
    no_rule = keys - ROSDEP_RULES - JAZZY_RELEASED
    assert no_rule == {"python3-trimesh", "python3-pytetwild-pip", "python3-ray-pip"}   # as read from rosdistro
    assert no_rule <= documented_skip_keys()
    unknown = documented_skip_keys() - package_xml_keys() - FRANKA_SKIP_KEYS
    assert not unknown, f"--skip-keys names keys no package.xml declares: {sorted(unknown)}"


def test_a_skipped_key_the_nodes_need_is_pinned_for_pip():
    modules_by_key = {}
    for module in real_cell_modules():
        modules_by_key.setdefault(MODULE_KEYS[module], set()).add(module)
    pinned = requirement_lines()
    for key in documented_skip_keys() & set(modules_by_key):
        for module in modules_by_key[key]:
            assert PIP_DISTRIBUTIONS[module].lower() in pinned, f"{key} skipped but {module} not in {REQUIREMENTS.name}"


def test_the_requirements_are_the_locks_pins_of_what_the_nodes_import():
    pins, lock = requirement_lines(), lock_pins()
    imported = {PIP_DISTRIBUTIONS.get(m, "").lower() for m in real_cell_modules()}
    for name, specifier in pins.items():
        if name == "setuptools":
            # not imported: torch 2.13 needs >= 77.0.3, colcon's --symlink-install < 80 (docs/real_cell.md)
            assert specifier == ">=77.0.3,<80"
            continue
        assert name in imported, f"{name} is not imported by the real-cell nodes (sim or training only?)"
        assert specifier == f"=={lock[name]}", f"{name}{specifier}: requirements.lock pins {lock[name]}"
    assert not (set(pins) & NEVER_FROM_PIP), "numpy, OpenCV and Pinocchio come from rosdep (docs/real_cell.md)"
    assert {"trimesh", "pytetwild", "ray", "pyvista", "rosbags"}.isdisjoint(pins)


def test_the_closure_sees_the_executors_lazy_and_nested_imports():
    modules = real_cell_modules()
    # the executor's arm model loads pybullet_data's Panda URDF; trajectories need ruckig; the network torch
    assert "defgg_ros.control.kinematics" in modules["pybullet_data"]
    assert "defgg_ros.control.trajectories" in modules["ruckig"]
    assert {"torch", "franka_msgs", "control_msgs", "tf2_msgs"} <= set(modules)
    # sim, dataset and training libraries are not reachable from the real-cell nodes
    assert {"trimesh", "pytetwild", "ray", "pyvista", "rosbags"}.isdisjoint(modules)
