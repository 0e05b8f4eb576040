"""package.xml declares every runtime import of defgg_ros (and nothing it no longer imports).

Every third-party top-level module imported anywhere under defgg_ros/ (found with the AST, so lazy
imports inside functions count too) maps to a rosdep key that must be an <exec_depend>; a module
missing from MODULE_KEYS fails the test, naming it, so a new dependency cannot slip in unnoticed.
"""
import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[2]
# Python module -> rosdep key. ROS packages keep their name; pip-only libraries use the -pip keys.
MODULE_KEYS = {
    "ament_index_python": "ament_index_python",
    "builtin_interfaces": "builtin_interfaces",
    "control_msgs": "control_msgs",
    "controller_manager_msgs": "controller_manager_msgs",
    "cv2": "python3-opencv",
    "defgg_interfaces": "defgg_interfaces",
    "diagnostic_msgs": "diagnostic_msgs",
    "franka_msgs": "franka_msgs",
    "geometry_msgs": "geometry_msgs",
    "lifecycle_msgs": "lifecycle_msgs",
    "matplotlib": "python3-matplotlib",
    "numpy": "python3-numpy",
    "pinocchio": "pinocchio",
    "pybullet": "python3-pybullet-pip",
    "pybullet_data": "python3-pybullet-pip",
    "pytetwild": "python3-pytetwild-pip",
    "pyvista": "python3-pyvista-pip",
    "ray": "python3-ray-pip",
    "rcl_interfaces": "rcl_interfaces",
    "rclpy": "rclpy",
    "rosbags": "python3-rosbags-pip",
    "rosgraph_msgs": "rosgraph_msgs",
    "ruckig": "ruckig",
    "sensor_msgs": "sensor_msgs",
    "std_msgs": "std_msgs",
    "std_srvs": "std_srvs",
    "tf2_msgs": "tf2_msgs",
    "torch": "python3-torch",
    "tqdm": "python3-tqdm",
    "trajectory_msgs": "trajectory_msgs",
    "trimesh": "python3-trimesh",
    "visualization_msgs": "visualization_msgs",
    "yaml": "python3-yaml",
}
# Declared without a direct import: the wire types rclpy's action client and server use.
INDIRECT_KEYS = {"action_msgs"}


def runtime_imports() -> dict[str, set[str]]:
    """Third-party top-level module -> files of defgg_ros/ importing it."""
    found: dict[str, set[str]] = {}
    for path in sorted((REPO / "defgg_ros").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top != "defgg_ros":
                    found.setdefault(top, set()).add(str(path.relative_to(REPO)))
    return found


def exec_depends() -> set[str]:
    root = ET.parse(REPO / "package.xml").getroot()
    return {e.text.strip() for tag in ("exec_depend", "depend") for e in root.iter(tag)}


def test_every_runtime_import_has_its_exec_depend():
    imports = runtime_imports()
    unmapped = {m: sorted(files)[:3] for m, files in imports.items() if m not in MODULE_KEYS}
    assert not unmapped, f"imports without a rosdep key in MODULE_KEYS (add it and an <exec_depend>): {unmapped}"
    declared = exec_depends()
    missing = {MODULE_KEYS[m]: sorted(files)[:3] for m, files in imports.items() if MODULE_KEYS[m] not in declared}
    assert not missing, f"package.xml lacks <exec_depend> for {missing}"


def test_no_exec_depend_is_left_over():
    used = {MODULE_KEYS[m] for m in runtime_imports() if m in MODULE_KEYS} | INDIRECT_KEYS
    assert exec_depends() - used == set(), "package.xml declares dependencies nothing imports"


def test_the_scan_sees_lazy_imports():
    # tf2_msgs is imported inside functions only (defgg_ros/ros/tf.py): the scan must still find it.
    assert "defgg_ros/ros/tf.py" in runtime_imports()["tf2_msgs"]
