"""The simulated driver's frames are the real stack's (docs/franka_contract.md, "Frames"): realsense2_camera's TF
tree under the calibration, the frame ids franka_ros2 stamps its state topics with, current_pose at the Franka
Hand's TCP; and the perception node finds the camera through that chain."""
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from defgg_ros.ros import topics

pytestmark = pytest.mark.ros

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"
TIMEOUT_S = 30.0
TILTED_CAMERA = {"xyz": [0.62, -0.08, 0.55], "quat_xyzw": [0.9659258, 0.0, 0.2588190, 0.0]}  # 30 deg off vertical


def _driver(executor, tmp_path=None, **parameters):
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    scene = f"{SCENES}/rigid_box.yaml"
    if tmp_path is not None:   # the same scene, its camera tilted: a pose no default parameter has
        spec = yaml.safe_load(open(scene, encoding="utf-8"))
        spec["base_T_camera"] = TILTED_CAMERA
        scene = str(tmp_path / "tilted.yaml")
        with open(scene, "w", encoding="utf-8") as f:
            yaml.safe_dump(spec, f)
    node = FakePandaDriver(context=executor.context, parameter_overrides=[
        Parameter("scene_file", value=scene), Parameter("max_real_time_factor", value=0.0),
        *[Parameter(name, value=value) for name, value in parameters.items()]])
    executor.add_node(node)
    return node


def _probe(executor, name="frames_probe"):
    from rclpy.node import Node

    node = Node(name, context=executor.context)
    executor.add_node(node)
    return node


def _collect(node, msg_type, topic, qos_profile):
    box = []
    node.create_subscription(msg_type, topic, box.append, qos_profile)
    return box


def _publisher_of(driver, topic):
    resolved = driver.resolve_topic_name(topic)
    return next(p for p in driver.publishers if p.topic_name == resolved)


def _scene_pose(spec) -> np.ndarray:
    from defgg_ros.rotations import quaternion_xyzw_to_matrix

    pose = np.eye(4)
    pose[:3, :3] = quaternion_xyzw_to_matrix(spec["quat_xyzw"])
    pose[:3, 3] = spec["xyz"]
    return pose


def _rpy(roll, pitch, yaw) -> np.ndarray:
    """tf2's setRPY: R = Rz(yaw) Ry(pitch) Rx(roll) (rotations about the fixed axes)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


@pytest.mark.parametrize("camera_name, color", [("camera", False), ("d405", True)])
def test_the_camera_tree_is_realsenses_under_the_calibration(executor, spin, tmp_path, camera_name, color):
    """realsense2_camera (tfs.cpp): <name>_link -> <name>_depth_frame (identity: depth is the base stream) ->
    <name>_depth_optical_frame (setRPY(-pi/2, 0, -pi/2)), colour alike; the calibration base -> <name>_link; the
    images in their stream's optical frame; base -> optical frame only through the chain."""
    from sensor_msgs.msg import Image
    from tf2_msgs.msg import TFMessage

    from defgg_ros.ros import qos
    from defgg_ros.ros.tf import TransformTree, matrix_from_transform, tf_qos

    _driver(executor, tmp_path, camera_name=camera_name, publish_color=color, depth_rate_hz=5.0)
    probe = _probe(executor)
    static = _collect(probe, TFMessage, topics.TF_STATIC, tf_qos(static=True))
    depth = _collect(probe, Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
    colour = _collect(probe, Image, topics.COLOR_IMAGE, qos.SENSOR_DATA)
    spin(executor, lambda: static and depth and (colour or not color), TIMEOUT_S, "/tf_static and a frame")
    edges = {(t.header.frame_id, t.child_frame_id): matrix_from_transform(t.transform)
             for msg in static for t in msg.transforms}
    n = camera_name
    expected = {("fer_link0", f"{n}_link"), (f"{n}_link", f"{n}_depth_frame"),
                (f"{n}_depth_frame", f"{n}_depth_optical_frame"), ("base", "fer_link0")}
    if color:
        expected |= {(f"{n}_link", f"{n}_color_frame"), (f"{n}_color_frame", f"{n}_color_optical_frame")}
    assert set(edges) == expected
    optical = _rpy(-np.pi / 2, 0.0, -np.pi / 2)
    np.testing.assert_allclose(edges[(f"{n}_link", f"{n}_depth_frame")], np.eye(4), atol=1e-12)
    np.testing.assert_allclose(edges[(f"{n}_depth_frame", f"{n}_depth_optical_frame")][:3, :3], optical, atol=1e-12)
    np.testing.assert_allclose(edges[(f"{n}_depth_frame", f"{n}_depth_optical_frame")][:3, 3], 0.0, atol=1e-12)
    np.testing.assert_allclose(edges[("base", "fer_link0")], np.eye(4), atol=1e-12)
    tree = TransformTree()
    for msg in static:
        tree.add_message(msg, static=True)
    np.testing.assert_allclose(tree.lookup("fer_link0", f"{n}_depth_optical_frame"), _scene_pose(TILTED_CAMERA),
                               atol=1e-6)
    assert depth[-1].header.frame_id == f"{n}_depth_optical_frame"
    if color:
        assert colour[-1].header.frame_id == f"{n}_color_optical_frame"
        # a D435's colour camera: 15 mm along camera_link's +y (realsense2_description), the optical frames' -x
        depth_T_color = tree.lookup(f"{n}_depth_optical_frame", f"{n}_color_optical_frame")
        np.testing.assert_allclose(depth_T_color[:3, :3], np.eye(3), atol=1e-9)
        np.testing.assert_allclose(depth_T_color[:3, 3], [-0.015, 0.0, 0.0], atol=1e-9)


def test_the_perception_node_finds_the_camera_through_realsenses_chain(executor, spin, tmp_path):
    """The segmentation node looks base_frame -> the depth image's frame_id up along the chain the driver
    publishes (calibration, then realsense2_camera's frames), not as one transform."""
    from sensor_msgs.msg import Image

    from defgg_ros.nodes.segmentation_node import SegmentationNode
    from defgg_ros.ros import qos

    _driver(executor, tmp_path, camera_name="d405", depth_rate_hz=5.0)
    probe = _probe(executor)
    depth = _collect(probe, Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
    node = SegmentationNode(context=executor.context)
    executor.add_node(node)
    spin(executor, lambda: depth and "d405_link" in node._camera_pose._listener.tree.frames(), TIMEOUT_S,
         "a depth frame and the camera's frames on TF")
    header = depth[-1].header
    assert header.frame_id == "d405_depth_optical_frame"
    np.testing.assert_allclose(node.base_T_camera_for(header), _scene_pose(TILTED_CAMERA), atol=1e-6)
    assert node._camera_pose.source == "tf"
    tree = node._camera_pose._listener.tree
    assert tree.root_of("d405_depth_optical_frame")[0] == "base"    # via d405_link and fer_link0


def test_state_topics_carry_franka_ros2s_frame_ids(executor, spin):
    """joint_state_broadcaster: its frame_id parameter's default `base_link` (franka's controllers files set none);
    joint_state_publisher and franka_gripper: no frame id; franka_robot_state_broadcaster: the URDF's root link
    `base` (franka_semantic_components' link_names[0])."""
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from sensor_msgs.msg import JointState

    from defgg_ros.ros import qos

    _driver(executor)
    probe = _probe(executor)
    read = qos.ROBOT_STATE_READ
    seen = {topic: _collect(probe, msg_type, topic, read) for topic, msg_type in (
        (topics.JOINT_STATES, JointState), (topics.ARM_JOINT_STATES, JointState),
        (topics.GRIPPER_JOINT_STATES, JointState), (topics.EXTERNAL_WRENCH, WrenchStamped),
        (topics.CURRENT_POSE, PoseStamped), (topics.MEASURED_JOINT_STATES, JointState))}
    spin(executor, lambda: all(len(box) >= 3 for box in seen.values()), TIMEOUT_S, "3 messages on each topic")
    frames = {topic: {m.header.frame_id for m in box} for topic, box in seen.items()}
    assert frames == {topics.JOINT_STATES: {""}, topics.ARM_JOINT_STATES: {"base_link"},
                      topics.GRIPPER_JOINT_STATES: {""}, topics.EXTERNAL_WRENCH: {"base"},
                      topics.CURRENT_POSE: {"base"}, topics.MEASURED_JOINT_STATES: {"base"}}
    # the measured joint states stay the arm's, as the broadcaster's
    assert tuple(seen[topics.MEASURED_JOINT_STATES][-1].name) == topics.robot_names()["joints"]


def test_current_pose_is_the_franka_hands_tcp(executor, spin):
    """current_pose is libfranka's O_T_EE, with the Franka Hand the URDF's <robot_type>_hand_tcp: link8, turned
    -45 deg about its z (hand_joint), 0.1034 m along the hand's z (franka_hand.xacro's tcp_xyz), in `base` (=
    <robot_type>_link0). Checked against pinocchio's forward kinematics of the simulated Panda's URDF at the
    joint positions of the same control period."""
    import pinocchio as pin
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState

    from defgg_ros.constants import PANDA_JOINT_NAMES
    from defgg_ros.control.kinematics import panda_urdf_path
    from defgg_ros.ros import qos
    from defgg_ros.rotations import quaternion_xyzw_to_matrix

    _driver(executor)
    probe = _probe(executor)
    poses = _collect(probe, PoseStamped, topics.CURRENT_POSE, qos.ROBOT_STATE_READ)
    joints = _collect(probe, JointState, topics.MEASURED_JOINT_STATES, qos.ROBOT_STATE_READ)

    def stamp(msg):
        return (msg.header.stamp.sec, msg.header.stamp.nanosec)

    def pairs():
        by_stamp = {stamp(m): m for m in list(joints)}
        return [(p, by_stamp[stamp(p)]) for p in list(poses) if stamp(p) in by_stamp]

    spin(executor, lambda: len(pairs()) >= 3, TIMEOUT_S, "current_pose and joint states of the same periods")
    model = pin.buildModelFromUrdf(str(panda_urdf_path()))
    data = model.createData()
    link8 = model.getFrameId("panda_link8")
    link8_M_tcp = pin.SE3(pin.utils.rotate("z", -np.pi / 4), np.array([0.0, 0.0, 0.1034]))
    for pose_msg, joint_msg in pairs()[-3:]:
        q = pin.neutral(model)
        for name, position in zip(joint_msg.name, joint_msg.position):
            q[model.joints[model.getJointId(name.replace("fer_", "panda_"))].idx_q] = position
        assert set(n.replace("fer_", "panda_") for n in joint_msg.name) == set(PANDA_JOINT_NAMES)
        pin.framesForwardKinematics(model, data, q)
        tcp = data.oMf[link8] * link8_M_tcp
        p, o = pose_msg.pose.position, pose_msg.pose.orientation
        np.testing.assert_allclose([p.x, p.y, p.z], tcp.translation, atol=1e-4)   # panda_grasptarget: 1.6 mm off
        np.testing.assert_allclose(quaternion_xyzw_to_matrix([o.x, o.y, o.z, o.w]), tcp.rotation, atol=1e-4)
        assert pose_msg.header.frame_id == "base"


def test_the_camera_streams_are_realsenses_qos_and_colour_is_its_own_camera(executor, spin):
    """realsense2_camera 4.56: images with the middleware's default QoS (SYSTEM_DEFAULT; Fast DDS: reliable,
    transient local, keep last 1), camera_info reliable, volatile, keep last 10; the colour stream has its own
    camera_info (a D435's colour focal length, 621 px) and frame (15 mm beside the depth origin), and its frames
    carry their own stamps. The driver offered reliable, volatile, keep last 2 on all three, published no colour
    camera_info, rendered colour from the depth camera (identity extrinsics) and stamped both alike. The colour
    image must agree with its own camera_info and TF: the box's top face, projected through them, is where the box
    is in the image."""
    from rclpy.qos import qos_profile_system_default
    from sensor_msgs.msg import CameraInfo, Image
    from tf2_msgs.msg import TFMessage

    from defgg_ros.ros import qos
    from defgg_ros.ros.conversions import image_to_numpy, stamp_to_ns
    from defgg_ros.ros.tf import TransformTree, tf_qos

    driver = _driver(executor, publish_color=True, depth_rate_hz=5.0)
    probe = _probe(executor, "camera_contract_probe")
    reference = probe.create_publisher(Image, "camera_contract_reference", qos_profile_system_default)
    seen = {name: _collect(probe, kind, topic, qos.SENSOR_DATA if kind is Image else qos.REALSENSE_CAMERA_INFO)
            for name, kind, topic in (("depth", Image, topics.DEPTH_IMAGE), ("colour", Image, topics.COLOR_IMAGE),
                                      ("depth_info", CameraInfo, topics.DEPTH_CAMERA_INFO),
                                      ("colour_info", CameraInfo, topics.COLOR_CAMERA_INFO))}
    static = _collect(probe, TFMessage, topics.TF_STATIC, tf_qos(static=True))
    try:
        spin(executor, lambda: static and all(seen.values()), TIMEOUT_S, "a frame on every camera topic")
        system_default = probe.get_publishers_info_by_topic("/camera_contract_reference")[0].qos_profile
        del reference
        for topic in (topics.DEPTH_IMAGE, topics.COLOR_IMAGE):
            offered = probe.get_publishers_info_by_topic("/" + topic)[0].qos_profile
            assert (offered.reliability, offered.durability) == (system_default.reliability,
                                                                 system_default.durability), topic
            assert _publisher_of(driver, topic).qos_profile.depth == qos_profile_system_default.depth, topic
        for topic in (topics.DEPTH_CAMERA_INFO, topics.COLOR_CAMERA_INFO):
            offered = probe.get_publishers_info_by_topic("/" + topic)[0].qos_profile
            assert offered.reliability == ReliabilityPolicy.RELIABLE and offered.durability == DurabilityPolicy.VOLATILE
            assert _publisher_of(driver, topic).qos_profile.depth == 10, topic
        colour, info = seen["colour"][-1], seen["colour_info"][-1]
        assert info.header == colour.header and info.header.frame_id == "camera_color_optical_frame"
        assert info.k[0] == pytest.approx(621.0) and seen["depth_info"][-1].k[0] == pytest.approx(385.0)
        assert stamp_to_ns(colour.header.stamp) != stamp_to_ns(seen["depth"][-1].header.stamp)
        tree = TransformTree()
        for msg in static:
            tree.add_message(msg, static=True)
        color_T_base = np.linalg.inv(tree.lookup("fer_link0", "camera_color_optical_frame"))
        top_centre = color_T_base @ np.array([0.5, 0.05, 0.05, 1.0])   # rigid_box.yaml: the block's top face
        pixel = (np.array(info.k).reshape(3, 3) @ top_centre[:3])[:2] / top_centre[2]
        rgb = image_to_numpy(colour).astype(int)
        table = np.median(rgb.reshape(-1, 3), axis=0)
        box_v, box_u = np.nonzero(np.abs(rgb - table).sum(axis=2) > 60)
        near = (np.abs(box_u - pixel[0]) < 60) & (np.abs(box_v - pixel[1]) < 60)
        assert near.sum() > 500, f"no box around the projected top face at {pixel.round(1)}"
        centroid = np.array([box_u[near].mean(), box_v[near].mean()])
        assert np.abs(centroid - pixel).max() < 4.0, f"box centroid {centroid.round(1)}, projected {pixel.round(1)}"
    finally:
        driver.shutdown()


def test_a_frame_arrives_after_the_capture_it_is_stamped_with(executor, spin):
    """realsense2_camera stamps a frame with its capture time and publishes it once the host has it: the stamp is
    older than the clock at arrival. Stamped at publication (the driver until 2026-12-02), a reader that took a
    frame's stamp for 'now' (its age, the robot's state at capture) was never put to the test."""
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos

    latency_s = 0.4       # long beside the /clock period (10 ms), so that no delivery order between topics matters
    _driver(executor, depth_capture_latency_s=latency_s, depth_rate_hz=2.0)
    probe = _probe(executor)
    clock_s, arrivals = [0.0], []

    def on_clock(msg):
        clock_s[0] = msg.clock.sec + 1e-9 * msg.clock.nanosec

    def on_depth(msg):
        arrivals.append((msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec, clock_s[0]))

    probe.create_subscription(Clock, topics.CLOCK, on_clock, qos.STATE)
    probe.create_subscription(Image, topics.DEPTH_IMAGE, on_depth, qos.SENSOR_DATA)
    spin(executor, lambda: len(arrivals) >= 3, TIMEOUT_S, "three depth frames")
    ages = [arrived - stamp for stamp, arrived in arrivals]   # the probe's /clock may trail by a few periods
    assert all(age >= latency_s / 2 for age in ages) and latency_s - 0.02 <= max(ages) <= latency_s + 0.25, ages
