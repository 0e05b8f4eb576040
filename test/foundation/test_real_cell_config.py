"""The real-cell node sets (FR3: real_cell, Panda: real_cell_panda) name franka_ros2's interfaces
consistently, set only parameters the nodes know, within their bounds; and an executor started with
the FR3 file finds and reads a driver that speaks the FR3 names (the fake driver with arm_id fr3)."""
from pathlib import Path

import pytest
import yaml

from defgg_ros.bringup.node_set import load_node_set
from defgg_ros.bringup.shared_parameters import effective_parameters
from defgg_ros.ros import topics
from defgg_ros.ros.parameters import check_value, load_schema

CONFIG = Path(__file__).resolve().parents[2] / "sim_bringup" / "config"
ROBOTS = {"real_cell": ("fr3", CONFIG / "real_cell" / "fr3.yaml"),
          "real_cell_panda": ("panda", CONFIG / "real_cell" / "panda.yaml")}


@pytest.mark.unit
@pytest.mark.parametrize("set_name", sorted(ROBOTS))
def test_real_cell_sets_load_and_override_known_parameters_within_bounds(set_name):
    arm_id, robot_file = ROBOTS[set_name]
    node_set = load_node_set(set_name)
    assert node_set.ros_domain == "inherit" and not node_set.use_sim_time
    assert {n.name for n in node_set.nodes} == {"segmentation_node", "grasp_inference_node", "executor_node"}
    for entry in node_set.nodes:
        assert str(robot_file) in entry.params_files, entry.name
    overrides = yaml.safe_load(robot_file.read_text())
    for node, section in overrides.items():
        schema = load_schema(node)
        for name, value in (section["ros__parameters"] or {}).items():
            assert name in schema, f"{robot_file.name}: {node} has no parameter {name}"
            assert check_value(schema[name], value) is None, check_value(schema[name], value)
    # what the nodes start with (schema defaults, then the node's file, then the robot file)
    effective = {entry.name: effective_parameters(entry) for entry in node_set.nodes}
    names = topics.arm_names(arm_id)
    executor = effective["executor_node"]
    assert executor["arm_id"] == arm_id and executor["joint_limits"] == arm_id
    assert executor["base_frame"] == names["base_frame"] == effective["grasp_inference_node"]["base_frame"]
    assert executor["arm_trajectory_action"] == names["trajectory_action"]


@pytest.mark.unit
@pytest.mark.parametrize("set_name", sorted(ROBOTS))
def test_every_node_with_a_base_frame_gets_the_robots_base_frame(set_name):
    """A node left at the schema's panda_link0 on an FR3 finds no camera pose on TF."""
    arm_id, robot_file = ROBOTS[set_name]
    overrides = yaml.safe_load(robot_file.read_text())
    for entry in load_node_set(set_name).nodes:
        schema = load_schema(entry.name)
        if "base_frame" not in schema:
            continue
        section = (overrides.get(entry.name) or {}).get("ros__parameters") or {}
        effective = section.get("base_frame", schema["base_frame"].default)
        assert effective == topics.arm_names(arm_id)["base_frame"], entry.name


@pytest.mark.ros
def test_executor_with_the_fr3_file_drives_a_driver_speaking_fr3_names(executor, spin):
    from rclpy.parameter import Parameter

    from defgg_ros.nodes.executor_node import ExecutorNode
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    names = topics.arm_names("fr3")
    scene = CONFIG.parent / "scenes" / "rigid_box.yaml"
    driver = FakePandaDriver(context=executor.context, parameter_overrides=[
        Parameter("scene_file", value=str(scene)), Parameter("max_real_time_factor", value=0.0),
        Parameter("arm_id", value="fr3"), Parameter("base_frame", value=names["base_frame"]),
        Parameter("arm_trajectory_action", value=names["trajectory_action"])])
    executor.add_node(driver)
    node = ExecutorNode(context=executor.context, cli_args=[
        "--ros-args", "--params-file", str(CONFIG / "executor_node.yaml"),
        "--params-file", str(CONFIG / "real_cell" / "fr3.yaml")])
    executor.add_node(node)
    try:
        assert node._arm_joints == names["joints"]
        spin(executor, lambda: node._last_state is not None, 20.0, "fr3 joint states read by the executor")
        assert node._last_state[0].gripper_width_m > 0.0  # fr3_finger_joint1/2 found
        spin(executor, lambda: node._arm_client.server_is_ready() and node._grasp_client.server_is_ready(), 20.0,
             "fr3_arm_controller/follow_joint_trajectory and franka_gripper/grasp")
    finally:
        driver.shutdown()
