"""The real-cell node sets (FR3: real_cell, Panda: real_cell_fer) name franka_ros2 3.x's interfaces
consistently, set only parameters the nodes know, within their bounds; and an executor started with each
set's robot file picks a box in the simulated cell whose driver runs the same robot_type."""
from pathlib import Path

import pytest
import yaml

from defgg_ros.bringup.node_set import load_node_set
from defgg_ros.bringup.shared_parameters import effective_parameters, node_sections
from defgg_ros.ros import topics
from defgg_ros.ros.parameters import check_value, load_schema

CONFIG = Path(__file__).resolve().parents[2] / "sim_bringup" / "config"
ROBOTS = {"real_cell": ("fr3", CONFIG / "real_cell" / "fr3.yaml"),
          "real_cell_fer": ("fer", CONFIG / "real_cell" / "fer.yaml")}


@pytest.mark.unit
@pytest.mark.parametrize("set_name", sorted(ROBOTS))
def test_real_cell_sets_load_and_override_known_parameters_within_bounds(set_name):
    robot_type, robot_file = ROBOTS[set_name]
    node_set = load_node_set(set_name)
    assert node_set.ros_domain == "inherit" and not node_set.use_sim_time
    assert {n.name for n in node_set.nodes} == {"segmentation_node", "grasp_inference_node", "executor_node"}
    for entry in node_set.nodes:
        assert str(robot_file) in entry.params_files, entry.name
    overrides = node_sections(yaml.safe_load(robot_file.read_text()))
    for node, section in overrides.items():
        schema = load_schema(node)
        for name, value in section.items():
            assert name in schema, f"{robot_file.name}: {node} has no parameter {name}"
            assert check_value(schema[name], value) is None, check_value(schema[name], value)
    # what the nodes start with (schema defaults, then the node's file, then the robot file)
    effective = {entry.name: effective_parameters(entry) for entry in node_set.nodes}
    names = topics.robot_names(robot_type)
    executor = effective["executor_node"]
    assert executor["robot_type"] == robot_type
    assert executor["joint_limits"] in ("", names["joint_limits"])          # '' = the robot type's
    assert executor["base_frame"] == names["base_frame"]
    assert executor["arm_trajectory_action"] in ("", names["trajectory_action"])


@pytest.mark.unit
@pytest.mark.parametrize("set_name", sorted(ROBOTS))
def test_every_node_with_a_base_frame_gets_the_robots_base_frame(set_name):
    """A node left at the schema's fer_link0 on an FR3 finds no camera pose on TF."""
    robot_type, _ = ROBOTS[set_name]
    for entry in load_node_set(set_name).nodes:
        effective = effective_parameters(entry)
        if "base_frame" in effective:
            assert effective["base_frame"] == topics.robot_names(robot_type)["base_frame"], entry.name


def _box_grasp(base_frame: str):
    """Top-down grasp across rigid_box.yaml's 5 cm box (at (0.5, 0.05), yaw 0.3) on its top face."""
    from defgg_interfaces.msg import Grasp

    from defgg_ros.control.poses import matrix_to_quaternion, top_down_pose

    xyz = (0.5, 0.05, 0.05)
    grasp = Grasp()
    grasp.pose_base.header.frame_id = base_frame
    pose = grasp.pose_base.pose
    pose.position.x, pose.position.y, pose.position.z = xyz
    o = pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(top_down_pose(xyz, 0.3)[:3, :3])
    grasp.width_m, grasp.youngs_modulus_pa = 0.07, 2e9
    return grasp


@pytest.mark.e2e
@pytest.mark.parametrize("set_name, fingers", [("real_cell", "from_gripper"), ("real_cell_fer", "from_gripper"),
                                               ("real_cell", "urdf_default")],
                         ids=["fr3", "fer", "fr3_moveit_launch"])
def test_executor_with_the_robot_file_picks_in_a_cell_of_that_robot_type(executor, spin, set_name, fingers):
    """The set's executor (its node file + robot file, on sim time) against the fake driver with the same
    robot_type: it reads that type's joint states, finger width and wrench and picks the box into the bin; also
    under the MoveIt launch's joint states (fingers a constant 0.0: the width comes from franka_gripper's)."""
    from defgg_interfaces.action import PickAndPlace
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from support.executor_goals import send_goal

    from defgg_ros.nodes.executor_node import ExecutorNode
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver
    from defgg_ros.ros.action import ActionClient

    robot_type, robot_file = ROBOTS[set_name]
    names = topics.robot_names(robot_type)
    driver = FakePandaDriver(context=executor.context, parameter_overrides=[
        Parameter("scene_file", value=str(CONFIG.parent / "scenes" / "rigid_box.yaml")),
        Parameter("robot_type", value=robot_type), Parameter("depth_rate_hz", value=0.01),
        Parameter("joint_state_fingers", value=fingers)])
    executor.add_node(driver)
    node = ExecutorNode(context=executor.context, cli_args=[
        "--ros-args", "--params-file", str(CONFIG / "executor_node.yaml"), "--params-file", str(robot_file),
        "-p", "use_sim_time:=true"])
    executor.add_node(node)
    probe = Node("real_cell_probe", context=executor.context)
    executor.add_node(probe)
    try:
        assert node._arm_joints == names["joints"] and node._params()["base_frame"] == names["base_frame"]
        spin(executor, lambda: node._last_state is not None and node._last_state[0].gripper_width_m > 0.07, 30.0,
             f"{robot_type} joint states and finger width read by the executor")
        client = ActionClient(probe, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
        handle = send_goal(executor, spin, client, PickAndPlace.Goal(grasp=_box_grasp(names["base_frame"])))
        assert handle.accepted
        result = spin(executor, handle.get_result_async(), 240.0, "pick-and-place result").result
        assert result.success, result.failure_reason
        assert result.held_after_transfer and result.gripper_width_closed_m == pytest.approx(0.05, abs=0.005)
    finally:
        driver.shutdown()


