"""The fake_panda_driver node over real DDS: state topics, trajectory execution, gripper actions, camera."""
import json
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter

from defgg_ros.constants import CAMERA_HEIGHT_PX, CAMERA_WIDTH_PX, PANDA_READY_Q_RAD
from defgg_ros.ros import topics

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"
TIMEOUT_S = 30.0


@pytest.fixture
def driver(executor, rclpy_context):
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    node = FakePandaDriver(context=rclpy_context, parameter_overrides=[
        Parameter("scene_file", value=str(SCENES / "rigid_box.yaml")),
        Parameter("max_real_time_factor", value=0.0),
        Parameter("depth_rate_hz", value=5.0),
    ])
    executor.add_node(node)
    yield node
    node.shutdown()


@pytest.fixture
def client(executor, rclpy_context):
    from rclpy.node import Node

    node = Node("driver_test_client", context=rclpy_context)
    executor.add_node(node)
    return node


def _latest(client, msg_type, topic, qos_profile):
    box = {"msgs": []}
    client.create_subscription(msg_type, topic, box["msgs"].append, qos_profile)
    return box["msgs"]


def test_joint_states_clock_and_wrench_flow(driver, client, executor, spin):
    from geometry_msgs.msg import WrenchStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from defgg_ros.nodes import qos

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    clocks = _latest(client, Clock, "/clock", qos.STATE)
    wrenches = _latest(client, WrenchStamped, topics.EXTERNAL_WRENCH, qos.STATE)
    spin(executor, lambda: len(joints) >= 20 and len(clocks) >= 20 and wrenches, TIMEOUT_S, "20 joint states")
    msg = joints[-1]
    assert list(msg.name)[:2] == ["panda_joint1", "panda_joint2"] and len(msg.position) == 9
    np.testing.assert_allclose(msg.position[:7], PANDA_READY_Q_RAD, atol=0.01)
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in joints]
    assert np.all(np.diff(stamps) > 0)
    # >= 50 Hz of sim time: consecutive stamps at most 20 ms apart.
    assert np.median(np.diff(stamps)) <= 0.02 + 1e-6
    assert wrenches[-1].header.frame_id == topics.BASE_FRAME


def test_trajectory_is_executed_in_sim_time(driver, client, executor, spin):
    from builtin_interfaces.msg import Duration
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.constants import PANDA_JOINT_NAMES
    from defgg_ros.nodes import qos

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    pub = client.create_publisher(JointTrajectory, topics.JOINT_TRAJECTORY, qos.COMMAND)
    spin(executor, lambda: joints and pub.get_subscription_count() > 0, TIMEOUT_S, "driver subscribed")
    goal = np.array(PANDA_READY_Q_RAD) + [0.2, 0.1, 0.0, 0.2, 0.0, -0.1, 0.2]
    # Joint order in the message differs from the arm's: the driver must map names.
    order = list(reversed(range(7)))
    msg = JointTrajectory(joint_names=[PANDA_JOINT_NAMES[i] for i in order])
    msg.points.append(JointTrajectoryPoint(positions=[float(goal[i]) for i in order],
                                           time_from_start=Duration(sec=1, nanosec=0)))
    pub.publish(msg)

    def arrived():
        return joints and np.abs(np.array(joints[-1].position[:7]) - goal).max() < 0.01

    spin(executor, arrived, TIMEOUT_S, "the arm to reach the trajectory's goal")


def test_gripper_actions(driver, client, executor, spin):
    from defgg_interfaces.action import GripperGrasp, GripperMove

    from defgg_ros.ros.action import ActionClient

    move = ActionClient(client, GripperMove, topics.GRIPPER_MOVE_ACTION)
    grasp = ActionClient(client, GripperGrasp, topics.GRIPPER_GRASP_ACTION)
    spin(executor, lambda: move.server_is_ready() and grasp.server_is_ready(), TIMEOUT_S, "gripper servers")

    def run(action, goal):
        handle = spin(executor, action.send_goal_async(goal), TIMEOUT_S, "goal accepted")
        assert handle.accepted
        return spin(executor, handle.get_result_async(), TIMEOUT_S, "gripper result").result

    result = run(move, GripperMove.Goal(width=0.03, speed=0.1))
    assert result.success, result.error
    assert result.width == pytest.approx(0.03, abs=0.002)
    # Nothing between the fingers: a grasp for a 5 cm object closes fully and fails.
    result = run(grasp, GripperGrasp.Goal(width=0.05, epsilon_inner=0.005, epsilon_outer=0.005, speed=0.1,
                                          force=20.0))
    assert not result.success and "outside" in result.error
    result = run(move, GripperMove.Goal(width=0.2, speed=0.1))
    assert not result.success and "width" in result.error


def test_camera_scene_and_object_poses(driver, client, executor, spin):
    from geometry_msgs.msg import PoseArray
    from sensor_msgs.msg import CameraInfo, Image
    from std_msgs.msg import String

    from defgg_ros.nodes import qos
    from defgg_ros.nodes.conversions import camera_info_to_k, depth_msg_to_metres
    from defgg_ros.nodes.fake_panda_driver_node import OBJECT_POSES_TOPIC, SCENE_TOPIC

    depth = _latest(client, Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
    info = _latest(client, CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)
    scene = _latest(client, String, SCENE_TOPIC, qos.LATCHED)
    poses = _latest(client, PoseArray, OBJECT_POSES_TOPIC, qos.STATE)
    spin(executor, lambda: depth and info and scene and poses, TIMEOUT_S, "depth, camera_info, scene, poses")
    assert depth[-1].encoding == "16UC1" and (depth[-1].width, depth[-1].height) == (CAMERA_WIDTH_PX,
                                                                                        CAMERA_HEIGHT_PX)
    assert depth[-1].header.frame_id == topics.CAMERA_OPTICAL_FRAME
    depth_m = depth_msg_to_metres(depth[-1])
    assert np.nanmin(depth_m) == pytest.approx(0.35, abs=0.003)      # top of the 5 cm box
    assert camera_info_to_k(info[-1])[0, 0] == pytest.approx(385.0)
    described = json.loads(scene[-1].data)
    assert [o["name"] for o in described["objects"]] == ["wooden_block"]
    assert described["objects_simulated_as"] == ["rigid"]
    assert poses[-1].poses[0].position.x == pytest.approx(0.5, abs=0.005)


def test_malformed_trajectory_is_rejected_and_the_driver_keeps_serving(driver, client, executor, spin):
    from builtin_interfaces.msg import Duration
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.constants import PANDA_JOINT_NAMES
    from defgg_ros.nodes import qos

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    pub = client.create_publisher(JointTrajectory, topics.JOINT_TRAJECTORY, qos.COMMAND)
    spin(executor, lambda: joints and pub.get_subscription_count() > 0, TIMEOUT_S, "driver subscribed")
    start = np.array(joints[-1].position[:7])
    bad = [JointTrajectory(joint_names=list(PANDA_JOINT_NAMES[:6]),            # a joint missing
                           points=[JointTrajectoryPoint(positions=[0.5] * 6, time_from_start=Duration(sec=1))]),
           JointTrajectory(joint_names=list(PANDA_JOINT_NAMES),                # NaN position
                           points=[JointTrajectoryPoint(positions=[float("nan")] * 7,
                                                        time_from_start=Duration(sec=1))])]
    for msg in bad:
        pub.publish(msg)
    count = len(joints)
    spin(executor, lambda: len(joints) > count + 100, TIMEOUT_S, "1 s of joint states after the bad commands")
    np.testing.assert_allclose(joints[-1].position[:7], start, atol=0.01)
    goal = start + 0.1
    pub.publish(JointTrajectory(joint_names=list(PANDA_JOINT_NAMES), points=[
        JointTrajectoryPoint(positions=goal.tolist(), time_from_start=Duration(sec=0, nanosec=500_000_000))]))
    spin(executor, lambda: np.abs(np.array(joints[-1].position[:7]) - goal).max() < 0.01, TIMEOUT_S,
         "the valid trajectory after the bad ones")
