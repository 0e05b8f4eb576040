"""The robot sees itself: the arm in view (drawn by PyBullet from the Panda's visual meshes) is removed
by the self-filter (Pinocchio frames + collision meshes), and no grasp lands on it; also through
grasp_inference_node with the joint states published over DDS."""
import numpy as np
import pytest
from defgg_interfaces.srv import PlanGrasp
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from defgg_ros.constants import PANDA_JOINT_NAMES
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.geometry import transform_to_xyz_quaternion
from defgg_ros.perception.self_filter import RobotSelfFilter
from defgg_ros.perception.tabletop import perceive
from defgg_ros.planning.tabletop_grasps import image_projection, plan_tabletop_grasps
from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info

MODEL_PATH = __import__("pathlib").Path(__file__).resolve().parents[2] / "models" / "defgg_cnn.pt"
BLOCK = ts.Box((0.56, -0.08), (0.05, 0.04, 0.05), yaw_rad=0.4, name="block")


@pytest.fixture(scope="module")
def arm_in_view():
    """An overhead frame of one block with the hand low over the table beside it (fingers, hand and
    forearm in view, like the issue's frames with the robot's fingers at the image edge)."""
    q = PandaKinematics().top_down_ik([0.42, 0.22, 0.06], 0.3)[0].q_rad
    scene = ts.overhead_single(BLOCK)
    frame = ts.render(scene, seed=3, arm_q_rad=q)
    joints = dict(zip(PANDA_JOINT_NAMES, q))
    joints.update({"panda_finger_joint1": 0.04, "panda_finger_joint2": 0.04})
    return scene, frame, joints


def _on_arm(frame, grasp) -> bool:
    uv = image_projection(grasp, frame.base_T_camera, frame.camera_k)
    u, v = int(round(uv["u_px"])), int(round(uv["v_px"]))
    window = frame.labels[max(v - 3, 0):v + 4, max(u - 3, 0):u + 4]
    return bool(np.any(window == ts.ROBOT_LABEL))


def test_the_arm_is_masked_and_only_the_block_is_an_object(arm_in_view):
    scene, frame, joints = arm_in_view
    arm = frame.labels == ts.ROBOT_LABEL
    assert arm.sum() > 5000, "the arm must be in view for this test"
    mask = RobotSelfFilter(margin_m=0.02).mask(joints, frame.base_T_camera, frame.camera_k, frame.depth_m)
    assert np.mean(mask[arm]) > 0.99
    assert not np.any(mask & (frame.labels == 1)), "the block is not the robot"
    unfiltered = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    # Without the filter part of the arm is foreground (in the workspace, at object heights): what it removes.
    assert np.mean(unfiltered.foreground[arm]) > 0.1, "the arm must be in the workspace (the test can fail)"
    filtered = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera, robot_mask=mask)
    assert not np.any(filtered.labels[arm] > 0) and len(filtered.object_ids) == 1
    grasps = plan_tabletop_grasps(filtered, GraspPredictor.from_checkpoint(MODEL_PATH), None, top_k=5)
    assert grasps and not any(_on_arm(frame, g) for g in grasps)
    for g in grasps:
        uv = image_projection(g, frame.base_T_camera, frame.camera_k)
        assert frame.labels[int(round(uv["v_px"])), int(round(uv["u_px"]))] == 1


def test_an_object_in_front_of_the_arm_stays_visible(arm_in_view):
    _, frame, joints = arm_in_view
    robot = RobotSelfFilter(margin_m=0.02)
    arm = frame.labels == ts.ROBOT_LABEL
    assert np.nanmin(frame.clean_depth_m[arm]) > 0.08
    near = np.where(arm, 0.02, frame.depth_m)    # something 2 cm from the lens, in front of every drawn link
    assert not np.any(robot.mask(joints, frame.base_T_camera, frame.camera_k, near)[arm])
    assert np.mean(robot.mask(joints, frame.base_T_camera, frame.camera_k, frame.depth_m)[arm]) > 0.99


def test_joint_names_with_another_prefix_place_the_same_links():
    robot = RobotSelfFilter()
    q = [0.3, -0.2, 0.1, -2.0, 0.0, 1.8, 0.7]
    panda = robot.link_points_base(dict(zip(PANDA_JOINT_NAMES, q)))
    fr3 = robot.link_points_base({f"fr3_joint{i + 1}": value for i, value in enumerate(q)})
    for a, b in zip(panda, fr3):
        np.testing.assert_allclose(a, b)


def test_two_threads_masking_at_once_each_get_their_own_arm():
    """The node's stream and its Perceive service mask frames at once: each call's link poses are its own joint
    positions' (a shared pinocchio Data gave one call the other's: 5 in 600)."""
    import threading

    robot = RobotSelfFilter()
    poses = [dict(zip(PANDA_JOINT_NAMES, q)) for q in ([0.3, -0.2, 0.1, -2.0, 0.0, 1.8, 0.7],
                                                        [-0.6, 0.4, -0.3, -1.2, 0.5, 2.4, -0.4])]
    expected = [robot.link_points_base(p) for p in poses]
    wrong = []

    def hammer(i):
        for _ in range(1500):
            got = robot.link_points_base(poses[i])
            wrong.extend(i for a, b in zip(got, expected[i]) if not np.allclose(a, b))

    threads = [threading.Thread(target=hammer, args=(i,)) for i in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not wrong


def test_the_node_filters_the_arm_from_joint_states(arm_in_view, executor, inference_service, call, spin):
    scene, frame, joints = arm_in_view
    xyz, quat = transform_to_xyz_quaternion(frame.base_T_camera)
    _, client_node, client = inference_service("self_filter_client", model_path=str(MODEL_PATH),
                                               base_T_camera=[*xyz.tolist(), *quat.tolist()])
    header = Header(frame_id="camera_depth_optical_frame")
    h, w = frame.depth_m.shape
    request = PlanGrasp.Request(depth=depth_metres_to_msg(frame.depth_m, "16UC1", header),
                                camera_info=make_camera_info(frame.camera_k, w, h, header), top_k=5)
    publisher = client_node.create_publisher(JointState, topics.JOINT_STATES, qos.SENSOR_DATA)
    state = JointState(name=list(joints), position=[float(v) for v in joints.values()])
    responses = []

    def served_without_arm():
        publisher.publish(state)
        response = call(executor, client, request, 20.0, "plan_grasp")
        responses.append(response)
        return response.success and len({g.object_id for g in response.grasps}) == 1 \
            and not any(_on_arm_msg(frame, g) for g in response.grasps)

    spin(executor, served_without_arm, 30.0, "a plan without the arm once joint states arrived")
    for grasp in responses[-1].grasps:
        u, v = int(round(grasp.center_u_px)), int(round(grasp.center_v_px))
        assert frame.labels[v, u] == 1, f"grasp at ({u}, {v}) is not on the block"


def _on_arm_msg(frame, grasp) -> bool:
    u, v = int(round(grasp.center_u_px)), int(round(grasp.center_v_px))
    window = frame.labels[max(v - 3, 0):v + 4, max(u - 3, 0):u + 4]
    return bool(np.any(window == ts.ROBOT_LABEL))
