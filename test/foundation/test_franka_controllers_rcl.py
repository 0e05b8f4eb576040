"""sim_bringup/config/franka/controllers.yaml read by ROS's own parameter-file parser (rcl's, through an rclpy
node started with `--params-file`, as ros2_control_node and each controller read it): every node of the file
gets its parameters under the `/**` wildcard, with the values test_franka_controllers.py checks."""
import pytest
from test_franka_controllers import CONTROLLERS, JTC

from defgg_ros.constants import FRANKA_JTC_GAINS_PD

pytestmark = pytest.mark.ros


def rcl_parameters(context, node_name: str) -> dict:
    """The parameter overrides rcl parses from the file for a node of that name (in the root namespace)."""
    import rclpy

    node = rclpy.create_node(node_name, context=context, cli_args=["--ros-args", "--params-file", str(CONTROLLERS)],
                             automatically_declare_parameters_from_overrides=True, start_parameter_services=False)
    try:
        return {name: param.value for name, param in node._parameters.items() if name != "use_sim_time"}
    finally:
        node.destroy_node()


def test_the_controller_manager_gets_every_controller_type(rclpy_context):
    params = rcl_parameters(rclpy_context, "controller_manager")
    assert params["update_rate"] == 1000
    assert params["fr3_arm_controller.type"] == params["fer_arm_controller.type"] == JTC
    assert params["joint_state_broadcaster.type"] == "joint_state_broadcaster/JointStateBroadcaster"
    assert params["franka_robot_state_broadcaster.type"] == "franka_robot_state_broadcaster/FrankaRobotStateBroadcaster"


@pytest.mark.parametrize("robot_type", ["fer", "fr3"])
def test_each_arm_controller_gets_its_joints_interfaces_and_gains(rclpy_context, robot_type):
    params = rcl_parameters(rclpy_context, f"{robot_type}_arm_controller")
    joints = [f"{robot_type}_joint{i}" for i in range(1, 8)]
    assert list(params["joints"]) == joints
    assert list(params["command_interfaces"]) == ["effort"]
    assert list(params["state_interfaces"]) == ["position", "velocity"]
    for joint, (p, d) in zip(joints, FRANKA_JTC_GAINS_PD):
        assert (params[f"gains.{joint}.p"], params[f"gains.{joint}.d"]) == (p, d), joint


def test_the_robot_state_broadcaster_gets_frankas_publish_rate(rclpy_context):
    assert rcl_parameters(rclpy_context, "franka_robot_state_broadcaster")["convenience_publish_rate"] == 1000
