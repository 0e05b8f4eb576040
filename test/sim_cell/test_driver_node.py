"""The fake_panda_driver node over real DDS: state topics, trajectory execution, gripper actions, camera."""
import json
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter
from support.cell_faults import put_beyond_the_table_edge

from defgg_ros.constants import CAMERA_HEIGHT_PX, CAMERA_WIDTH_PX, PANDA_READY_Q_RAD
from defgg_ros.ros import topics

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"
ARM_JOINTS = topics.robot_names()["joints"]   # the default robot type's: fer_joint1..7
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

    from defgg_ros.ros import qos

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.ROBOT_STATE_READ)
    clocks = _latest(client, Clock, "/clock", qos.STATE)
    wrenches = _latest(client, WrenchStamped, topics.EXTERNAL_WRENCH, qos.ROBOT_STATE_READ)
    spin(executor, lambda: len(joints) >= 20 and len(clocks) >= 20 and wrenches, TIMEOUT_S, "20 joint states")
    msg = joints[-1]
    assert list(msg.name)[:2] == ["fer_joint1", "fer_joint2"] and len(msg.position) == 9
    np.testing.assert_allclose(msg.position[:7], PANDA_READY_Q_RAD, atol=0.01)
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in joints]
    assert np.all(np.diff(stamps) > 0)
    # joint_state_publisher's 30 Hz of sim time (on the 1 ms control grid); the reader keeps the newest only
    assert np.min(np.diff(stamps)) == pytest.approx(1 / 30, abs=1.1e-3)
    assert wrenches[-1].header.frame_id == topics.FRANKA_STATE_FRAME   # franka_robot_state_broadcaster: URDF root


def test_a_reliable_reader_gets_no_wrench_and_a_best_effort_one_does(driver, client, executor, spin):
    """franka_robot_state_broadcaster (>= 3.3.0) offers its wrench best effort: the QoS the executor reads with
    before issue 46 (reliable, keep last 10) gets nothing; qos.ROBOT_STATE_READ gets it."""
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState

    from defgg_ros.ros import qos

    reliable = _latest(client, WrenchStamped, topics.EXTERNAL_WRENCH, qos.STATE)
    best_effort = _latest(client, WrenchStamped, topics.EXTERNAL_WRENCH, qos.ROBOT_STATE_READ)
    joints = _latest(client, JointState, topics.JOINT_STATES, qos.ROBOT_STATE_READ)
    spin(executor, lambda: len(best_effort) >= 50 and len(joints) >= 20, TIMEOUT_S, "50 wrenches, 20 joint states")
    assert reliable == []


def test_trajectory_is_executed_in_sim_time(driver, client, executor, spin):
    from builtin_interfaces.msg import Duration
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.ros import qos

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    pub = client.create_publisher(JointTrajectory, topics.JOINT_TRAJECTORY, qos.COMMAND)
    spin(executor, lambda: joints and pub.get_subscription_count() > 0, TIMEOUT_S, "driver subscribed")
    goal = np.array(PANDA_READY_Q_RAD) + [0.2, 0.1, 0.0, 0.2, 0.0, -0.1, 0.2]
    # Joint order in the message differs from the arm's: the driver must map names.
    order = list(reversed(range(7)))
    msg = JointTrajectory(joint_names=[ARM_JOINTS[i] for i in order])
    msg.points.append(JointTrajectoryPoint(positions=[float(goal[i]) for i in order],
                                           time_from_start=Duration(sec=1, nanosec=0)))
    sent_at = len(joints)
    pub.publish(msg)

    def arrived():
        return joints and np.abs(np.array(joints[-1].position[:7]) - goal).max() < 0.01

    spin(executor, arrived, TIMEOUT_S, "the arm to reach the trajectory's goal")
    # on the sim clock the move takes the trajectory's 1 s (within 0.01 rad a little before its end), not at once
    def stamp(m):
        return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
    took_s = stamp(joints[-1]) - stamp(joints[sent_at - 1])
    assert 0.7 <= took_s <= 1.5, took_s


def test_gripper_actions(driver, client, executor, spin):
    """franka_ros2's gripper contract: franka_msgs Move/Grasp/Homing, result (success, error), feedback width."""
    from franka_msgs.action import Grasp, Homing, Move
    from franka_msgs.msg import GraspEpsilon
    from sensor_msgs.msg import JointState

    from defgg_ros.ros import qos
    from defgg_ros.ros.action import ActionClient

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    move = ActionClient(client, Move, topics.GRIPPER_MOVE_ACTION)
    grasp = ActionClient(client, Grasp, topics.GRIPPER_GRASP_ACTION)
    homing = ActionClient(client, Homing, topics.GRIPPER_HOMING_ACTION)
    spin(executor, lambda: joints and move.server_is_ready() and grasp.server_is_ready() and homing.server_is_ready(),
         TIMEOUT_S, "gripper servers")
    widths = []

    def run(action, goal):
        handle = spin(executor, action.send_goal_async(goal, feedback_callback=lambda f: widths.append(
            f.feedback.current_width)), TIMEOUT_S, "goal accepted")
        assert handle.accepted
        return spin(executor, handle.get_result_async(), TIMEOUT_S, "gripper result").result

    def finger_width():
        return sum(joints[-1].position[7:9])

    result = run(move, Move.Goal(width=0.03, speed=0.1))
    assert result.success, result.error
    assert widths
    # The result can overtake the last joint state: wait for a state that shows the reached width.
    spin(executor, lambda: abs(finger_width() - 0.03) < 0.002, TIMEOUT_S, "a joint state at the moved width")
    # Nothing between the fingers: a grasp for a 5 cm object closes fully and fails.
    result = run(grasp, Grasp.Goal(width=0.05, epsilon=GraspEpsilon(inner=0.005, outer=0.005), speed=0.1,
                                   force=20.0))
    assert not result.success and result.error == ""      # libfranka's grasp() returned false: no error text
    result = run(move, Move.Goal(width=0.2, speed=0.1))
    assert not result.success and "width" in result.error
    result = run(homing, Homing.Goal())
    assert result.success, result.error
    spin(executor, lambda: finger_width() > 0.07, TIMEOUT_S, "the fingers fully open after homing")


def test_follow_joint_trajectory_action(driver, client, executor, spin):
    """The joint_trajectory_controller's contract: accept, follow in sim time, succeed; reject bad goals."""
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.ros import qos
    from defgg_ros.ros.action import ActionClient

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    arm = ActionClient(client, FollowJointTrajectory, topics.ARM_TRAJECTORY_ACTION)
    spin(executor, lambda: joints and arm.server_is_ready(), TIMEOUT_S, "the arm's trajectory action")
    goal_q = np.array(joints[-1].position[:7]) + [0.1, -0.1, 0.0, 0.1, 0.0, 0.1, -0.1]
    feedback = []
    goal = FollowJointTrajectory.Goal(trajectory=JointTrajectory(
        joint_names=list(ARM_JOINTS),
        points=[JointTrajectoryPoint(positions=goal_q.tolist(), time_from_start=Duration(sec=1))]))
    handle = spin(executor, arm.send_goal_async(goal, feedback_callback=feedback.append), TIMEOUT_S, "acceptance")
    assert handle.accepted
    result = spin(executor, handle.get_result_async(), TIMEOUT_S, "the trajectory's result").result
    assert result.error_code == FollowJointTrajectory.Result.SUCCESSFUL, result.error_string
    assert feedback and list(feedback[-1].feedback.joint_names) == list(ARM_JOINTS)
    spin(executor, lambda: np.abs(np.array(joints[-1].position[:7]) - goal_q).max() < 0.01, TIMEOUT_S,
         "the arm at the goal")
    for bad in (JointTrajectory(joint_names=[f"fr3_joint{i}" for i in range(1, 8)],     # another arm's joints
                                points=[JointTrajectoryPoint(positions=[0.0] * 7, time_from_start=Duration(sec=1))]),
                JointTrajectory(joint_names=list(ARM_JOINTS)),                   # no points
                JointTrajectory(joint_names=list(ARM_JOINTS), points=[             # still moving at its end
                    JointTrajectoryPoint(positions=goal_q.tolist(), velocities=[0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0],
                                         time_from_start=Duration(sec=1))])):
        handle = spin(executor, arm.send_goal_async(FollowJointTrajectory.Goal(trajectory=bad)), TIMEOUT_S,
                      "the goal response")
        assert not handle.accepted


def test_fr3_robot_type_names_the_joints_and_the_camera_pose_is_on_tf_static(executor, rclpy_context, client, spin):
    """robot_type fr3: fr3_joint* in joint states and the FR3 controller's action name; the camera's extrinsic
    (the scene's base_T_camera) comes latched on /tf_static like a calibrated cell's."""
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from sensor_msgs.msg import JointState
    from tf2_msgs.msg import TFMessage
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver
    from defgg_ros.ros import qos
    from defgg_ros.ros.action import ActionClient
    from defgg_ros.ros.tf import TransformTree, quaternion_from_matrix
    from defgg_ros.sim.scene_spec import load_scene

    names = topics.robot_names("fr3")
    node = FakePandaDriver(context=rclpy_context, parameter_overrides=[
        Parameter("scene_file", value=str(SCENES / "rigid_box.yaml")), Parameter("max_real_time_factor", value=0.0),
        Parameter("robot_type", value="fr3")])
    executor.add_node(node)
    try:
        joints = _latest(client, JointState, topics.JOINT_STATES, qos.ROBOT_STATE_READ)
        static = _latest(client, TFMessage, topics.TF_STATIC, qos.LATCHED)
        arm = ActionClient(client, FollowJointTrajectory, "fr3_arm_controller/follow_joint_trajectory")
        spin(executor, lambda: joints and static and arm.server_is_ready(), TIMEOUT_S, "fr3 joint states, tf, action")
        assert list(joints[-1].name) == [*names["joints"], *names["fingers"]]
        goal_q = np.array(joints[-1].position[:7]) + 0.05
        handle = spin(executor, arm.send_goal_async(FollowJointTrajectory.Goal(trajectory=JointTrajectory(
            joint_names=list(names["joints"]),
            points=[JointTrajectoryPoint(positions=goal_q.tolist(), time_from_start=Duration(sec=1))]))),
            TIMEOUT_S, "acceptance")
        assert handle.accepted
        spin(executor, lambda: np.abs(np.array(joints[-1].position[:7]) - goal_q).max() < 0.01, TIMEOUT_S,
             "the fr3-named goal executed")
        # the calibration under the fr3's base, realsense2_camera's frames below it (test_driver_frames.py)
        tree = TransformTree()
        tree.add_message(static[-1], static=True)
        assert tree.root_of("camera_link")[0] == "base" and ("fr3_link0", "camera_link") in {
            (t.header.frame_id, t.child_frame_id) for t in static[-1].transforms}
        scene = load_scene(SCENES / "rigid_box.yaml")
        base_T_camera = tree.lookup("fr3_link0", topics.CAMERA_OPTICAL_FRAME)
        np.testing.assert_allclose(base_T_camera[:3, 3], scene.base_xyz_camera_m, atol=1e-9)
        np.testing.assert_allclose(quaternion_from_matrix(base_T_camera[:3, :3]), scene.base_quat_camera_xyzw,
                                   atol=1e-9)
    finally:
        node.shutdown()


def test_camera_scene_and_object_poses(driver, client, executor, spin):
    from geometry_msgs.msg import PoseArray
    from sensor_msgs.msg import CameraInfo, Image
    from std_msgs.msg import String

    from defgg_ros.nodes.fake_panda_driver_node import OBJECT_POSES_TOPIC, SCENE_TOPIC
    from defgg_ros.ros import qos
    from defgg_ros.ros.conversions import camera_info_to_k, depth_msg_to_metres

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


def test_an_empty_trajectory_on_the_topic_does_not_stop_the_arm(driver, client, executor, spin):
    """The joint_trajectory_controller drops an empty JointTrajectory ("Empty trajectory received"): a client
    that "stops" the arm so stops nothing on the real arm (the driver held the arm on it)."""
    from builtin_interfaces.msg import Duration
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.ros import qos

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    pub = client.create_publisher(JointTrajectory, topics.JOINT_TRAJECTORY, qos.COMMAND)
    spin(executor, lambda: joints and pub.get_subscription_count() > 0, TIMEOUT_S, "driver subscribed")
    goal = np.array(joints[-1].position[:7]) + 0.2
    pub.publish(JointTrajectory(joint_names=list(ARM_JOINTS), points=[
        JointTrajectoryPoint(positions=goal.tolist(), time_from_start=Duration(sec=2))]))
    count = len(joints)
    spin(executor, lambda: len(joints) > count + 10, TIMEOUT_S, "the arm under way")
    pub.publish(JointTrajectory(joint_names=list(ARM_JOINTS)))
    spin(executor, lambda: np.abs(np.array(joints[-1].position[:7]) - goal).max() < 0.01, TIMEOUT_S,
         "the arm at the goal after the empty trajectory")


def test_malformed_trajectory_is_rejected_and_the_driver_keeps_serving(driver, client, executor, spin):
    from builtin_interfaces.msg import Duration
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from defgg_ros.ros import qos

    joints = _latest(client, JointState, topics.JOINT_STATES, qos.STATE)
    pub = client.create_publisher(JointTrajectory, topics.JOINT_TRAJECTORY, qos.COMMAND)
    spin(executor, lambda: joints and pub.get_subscription_count() > 0, TIMEOUT_S, "driver subscribed")
    start = np.array(joints[-1].position[:7])
    bad = [JointTrajectory(joint_names=list(ARM_JOINTS[:6]),            # a joint missing
                           points=[JointTrajectoryPoint(positions=[0.5] * 6, time_from_start=Duration(sec=1))]),
           JointTrajectory(joint_names=list(ARM_JOINTS),                # NaN position
                           points=[JointTrajectoryPoint(positions=[float("nan")] * 7,
                                                        time_from_start=Duration(sec=1))])]
    for msg in bad:
        pub.publish(msg)
    count = len(joints)
    spin(executor, lambda: len(joints) > count + 100, TIMEOUT_S, "1 s of joint states after the bad commands")
    np.testing.assert_allclose(joints[-1].position[:7], start, atol=0.01)
    goal = start + 0.1
    pub.publish(JointTrajectory(joint_names=list(ARM_JOINTS), points=[
        JointTrajectoryPoint(positions=goal.tolist(), time_from_start=Duration(sec=0, nanosec=500_000_000))]))
    spin(executor, lambda: np.abs(np.array(joints[-1].position[:7]) - goal).max() < 0.01, TIMEOUT_S,
         "the valid trajectory after the bad ones")


def test_an_object_that_leaves_the_table_is_reported_once_on_rosout(driver, client, executor, spin):
    from rcl_interfaces.msg import Log
    from rosgraph_msgs.msg import Clock

    from defgg_ros.ros import qos
    from defgg_ros.ros.conversions import stamp_to_ns

    logs = []
    client.create_subscription(Log, "/rosout", logs.append, 100)
    clocks = _latest(client, Clock, "/clock", qos.STATE)
    spin(executor, lambda: clocks, TIMEOUT_S, "the clock")
    with driver._lock:
        put_beyond_the_table_edge(driver.cell)

    def reports():
        return [m for m in logs if m.name == "fake_panda_driver" and "left the table" in m.msg]

    spin(executor, reports, TIMEOUT_S, "an error on /rosout")
    reported_ns = stamp_to_ns(clocks[-1].clock)
    spin(executor, lambda: stamp_to_ns(clocks[-1].clock) > reported_ns + 1_000_000_000, TIMEOUT_S,
         "1 s of sim time after the report")
    (report,) = reports()                   # once, though it is still under the table at every check since
    assert report.level == Log.ERROR
    assert "wooden_block" in report.msg


def test_a_bin_over_the_table_edge_is_warned_about_at_start_up(executor, rclpy_context, client, spin, tmp_path):
    """A warning, not a refusal: a recorded session replays the scene it was recorded with (docs/sessions.md)."""
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    scene = tmp_path / "bin_over_the_edge.yaml"
    scene.write_text((SCENES / "rigid_box.yaml").read_text().replace(
        "table: {size_m: [1.2, 1.2, 0.05], center_xy_m: [0.45, -0.1]}", "table: {size_m: [1.2, 1.0, 0.05]}"))
    logs = []
    client.create_subscription(Log, "/rosout", logs.append,
                               QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    node = FakePandaDriver(context=rclpy_context, parameter_overrides=[
        Parameter("scene_file", value=str(scene)), Parameter("max_real_time_factor", value=0.0)])
    executor.add_node(node)
    try:
        def warnings():
            return [m for m in logs if m.name == "fake_panda_driver" and "bin's walls" in m.msg]

        spin(executor, warnings, TIMEOUT_S, "the start-up warning on /rosout")
        (warning,) = warnings()
        assert warning.level == Log.WARN and "y -0.620 ... -0.280 m) reach beyond the table's top" in warning.msg
    finally:
        node.shutdown()


def test_a_robot_type_franka_ros2_does_not_have_is_refused_naming_the_choices(rclpy_context):
    """Jazzy's franka_ros2 has no 'panda' robot type (the Panda is 'fer'): the driver refuses it at start-up."""
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    with pytest.raises(ValueError, match=r"robot_type = 'panda' must be one of \['fer', 'fr3'\]"):
        FakePandaDriver(context=rclpy_context, parameter_overrides=[Parameter("robot_type", value="panda")])
    with pytest.raises(ValueError, match="franka_ros2 on Jazzy names the Panda 'fer'"):
        topics.robot_names("panda")


@pytest.mark.parametrize("name", ["gripper_stop_service", "gripper_command_action", "depth_topic"])
def test_an_empty_interface_name_is_refused_in_one_line(rclpy_context, name):
    """An empty service name raised rclpy's InvalidServiceNameException (not a ValueError): a traceback and exit 1
    instead of the one-line refusal every other bad parameter gets."""
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    with pytest.raises(ValueError, match=rf"{name} = .. must be not empty"):
        FakePandaDriver(context=rclpy_context, parameter_overrides=[Parameter(name, value="")])


def test_the_wrench_is_published_as_the_robot_applies_it_to_the_environment():
    """libfranka's O_F_ext_hat_K (what franka_robot_state_broadcaster publishes): forces the robot applies to the
    environment are positive. The cell's contacts push the hand up when it presses on the table (+z on the hand):
    the topic must read Fz < 0 there, as the real arm does (it read +z: a client's signed threshold passed in
    simulation and failed on the real cell)."""
    from std_msgs.msg import Header

    from defgg_ros.nodes.fake_panda_driver_node import franka_wrench_msg

    msg = franka_wrench_msg(Header(frame_id="fer_link0"), np.array([0.5, 0.0, 8.0]), np.array([0.0, 0.1, 0.0]))
    force, torque = msg.wrench.force, msg.wrench.torque
    assert (force.x, force.y, force.z) == (-0.5, 0.0, -8.0) and (torque.x, torque.y, torque.z) == (0.0, -0.1, 0.0)
    assert msg.header.frame_id == "fer_link0"
