"""The shipped parameter files hold in a namespace (real_cell.launch.py namespace:=left, `-r __ns:=/left`).

A section keyed `executor_node:` matches only /executor_node: under /left the robot file's robot_type, limits
and frames were dropped without a word (an FR3 cell ran the Panda's names and the default limits). Real rclpy
nodes read the files as ROS does."""
from pathlib import Path

import pytest
from rclpy.node import Node

pytestmark = pytest.mark.ros
CONFIG = Path(__file__).resolve().parents[2] / "sim_bringup" / "config"


@pytest.mark.parametrize("namespace", ["", "left"])
def test_the_robot_file_reaches_the_nodes_in_any_namespace(rclpy_context, namespace):
    expected = {"executor_node": {"robot_type": "fr3", "limits_scale": 0.3},
                "segmentation_node": {"base_frame": "fr3_link0"}}
    for name, values in expected.items():
        files = [CONFIG / f"{name}.yaml", CONFIG / "real_cell" / "fr3.yaml"]
        args = ["--ros-args"] + [a for f in files for a in ("--params-file", str(f))]
        node = Node(name, namespace=namespace, context=rclpy_context, cli_args=args,
                    automatically_declare_parameters_from_overrides=True)
        try:
            got = {key: node.get_parameter(key).value for key in values if node.has_parameter(key)}
            assert got == values, f"{node.get_fully_qualified_name()}: {got}"
        finally:
            node.destroy_node()
