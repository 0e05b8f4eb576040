"""Perception takes the camera pose from TF (base -> the depth frame's frame_id), the parameter as fallback."""
import time

import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Header

from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.ros.tf import CameraPoseUnknown, TfBroadcaster, transform_msg

pytestmark = pytest.mark.ros


def _has_pose(node, header) -> bool:
    try:
        node.base_T_camera_for(header)
    except CameraPoseUnknown:
        return False
    return True


def test_segmentation_node_uses_the_calibrated_camera_pose_on_tf(executor, spin):
    node = SegmentationNode(context=executor.context)      # base_T_camera not set
    calibration = Node("calibration_publisher", context=executor.context)
    executor.add_node(node)
    executor.add_node(calibration)
    header = Header(frame_id="camera_depth_optical_frame")
    with pytest.raises(CameraPoseUnknown, match="TF has none"):   # nothing on TF yet, and no parameter
        node.base_T_camera_for(header)
    tilted = np.eye(4)
    tilted[:3, :3] = [[0.0, -0.8, 0.6], [-1.0, 0.0, 0.0], [0.0, -0.6, -0.8]]
    tilted[:3, 3] = [0.1, 0.05, 0.55]
    TfBroadcaster(calibration, static=True).send(transform_msg(node.get_parameter("base_frame").value,
                                                               "camera_depth_optical_frame", tilted))
    spin(executor, lambda: _has_pose(node, header), 10.0, "the camera pose from /tf_static")
    np.testing.assert_allclose(node.base_T_camera_for(header), tilted, atol=1e-9)
    with pytest.raises(CameraPoseUnknown):                 # a frame id TF does not know
        node.base_T_camera_for(Header(frame_id="other_camera"))


def test_a_parameter_pose_stands_in_for_tf_only_when_set(executor, spin):
    pose = [0.5, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0]
    node = SegmentationNode(context=executor.context, parameter_overrides=[Parameter("base_T_camera", value=pose)])
    executor.add_node(node)
    top_down = np.array([[1.0, 0, 0, 0.5], [0, -1.0, 0, 0.0], [0, 0, -1.0, 0.4], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(node.base_T_camera_for(Header(frame_id="camera_depth_optical_frame")), top_down,
                               atol=1e-12)


def _frame_request():
    """A tilted cluttered-table frame as a PlanGrasp request, and its true base_T_camera."""
    from defgg_interfaces.srv import PlanGrasp

    from defgg_ros.perception import tabletop_scenes as ts
    from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info

    frame = ts.render(ts.cluttered_table(640, 480), seed=7)
    header = Header(frame_id="camera_depth_optical_frame")
    request = PlanGrasp.Request(depth=depth_metres_to_msg(frame.depth_m, "16UC1", header),
                                camera_info=make_camera_info(frame.camera_k, 640, 480, header), top_k=1)
    return request, frame.base_T_camera


def _tf_probe(executor):
    from defgg_ros.ros.tf import TfListener

    probe = Node("tf_probe", context=executor.context)
    executor.add_node(probe)
    return TfListener(probe)


def test_the_configured_camera_pose_is_published_under_the_cameras_own_tree(inference_service, executor, spin,
                                                                            call):
    """base_T_camera set, no calibration on TF, realsense2_camera's own camera_link -> optical frame on
    /tf_static: the node publishes base -> camera_link so that base -> optical frame is its parameter."""
    from defgg_ros.perception.geometry import transform_to_xyz_quaternion
    from defgg_ros.ros.tf import TfBroadcaster, transform_msg

    request, base_T_camera = _frame_request()
    driver = Node("realsense_like", context=executor.context)
    executor.add_node(driver)
    link_T_optical = np.eye(4)
    link_T_optical[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    link_T_optical[:3, 3] = [0.0, 0.015, 0.0]
    TfBroadcaster(driver, static=True).send(transform_msg("camera_link", "camera_depth_optical_frame",
                                                          link_T_optical))
    listener = _tf_probe(executor)
    xyz, quaternion = transform_to_xyz_quaternion(base_T_camera)
    node, _, client = inference_service("pose_publisher_probe", base_T_camera=[*xyz.tolist(), *quaternion.tolist()],
                                        base_frame="fr3_link0", publish_camera_tf=True)
    spin(executor, lambda: "camera_link" in node.segmentation_node._camera_pose._listener.tree.frames(), 10.0,
         "the node knows realsense's tree")
    def connected():
        try:
            listener.lookup("fr3_link0", "camera_depth_optical_frame")
        except LookupError:
            return False
        return True

    # The parameter goes on TF once TF had FALLBACK_PUBLISH_DELAY_S to give a calibration instead.
    deadline = time.monotonic() + 20.0
    while not connected() and time.monotonic() < deadline:
        assert call(executor, client, request, 60.0, "plan_grasp").success
        executor.spin_once(timeout_sec=0.5)
    assert connected(), "base -> camera never appeared on /tf_static"
    np.testing.assert_allclose(listener.lookup("fr3_link0", "camera_depth_optical_frame"), base_T_camera, atol=1e-6)
    assert listener.tree.root_of("camera_link")[0] == "fr3_link0"       # base -> camera_link, not -> optical


def test_without_a_pose_none_is_published_as_a_calibration_but_a_table_frame_is(inference_service, executor, spin,
                                                                                call):
    request, _ = _frame_request()
    listener = _tf_probe(executor)
    _, _, client = inference_service("pose_publisher_probe", publish_camera_tf=True)   # base_T_camera: default
    response = call(executor, client, request, 60.0, "plan_grasp")
    assert response.success and response.grasps[0].pose_base.header.frame_id == "defgg_table_estimate"
    spin(executor, lambda: "defgg_table_estimate" in listener.tree.frames(), 10.0, "the table frame on TF")
    assert listener.tree.root_of("defgg_table_estimate")[0] == "camera_depth_optical_frame"
    assert "panda_link0" not in listener.tree.frames()


def test_the_table_frame_uses_the_nodes_own_table_height_and_workspace(executor):
    """The table-frame fallback puts the table at the node's table_z_m and the view's centre at its workspace
    box's centre (it used PoseFromTable's defaults: table at z 0, centre (0.535, 0.0), whatever the node's
    TabletopConfig said, so a cell with its table at 0.75 m found no table in that frame)."""
    from defgg_ros.perception import tabletop_scenes as ts
    from defgg_ros.perception.table_pose import PoseFromTable
    from defgg_ros.perception.tabletop import TabletopConfig, WorkspaceBox, perceive
    from defgg_ros.ros.tf import CameraPose

    frame = ts.render(ts.cluttered_table(640, 480), seed=4)
    node = Node("table_frame_probe", context=executor.context)
    executor.add_node(node)
    poses = CameraPose(node, None, table_poses=PoseFromTable(recheck_s=0.0))
    config = TabletopConfig(table_z_m=0.75, workspace=WorkspaceBox(x_m=(0.30, 0.50), y_m=(0.10, 0.40)))
    pose, source = poses.resolve("panda_link0", "camera_depth_optical_frame", frame.depth_m, frame.camera_k, config)
    assert source == "table"
    view = perceive(frame.depth_m, frame.camera_k, pose, config)
    assert abs(view.table_z_at(0.40, 0.25) - 0.75) < 0.005
