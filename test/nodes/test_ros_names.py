"""ROS names and TF of grasp_inference_node (issue 26.5, 26.6).

- Names are relative: two instances (each with its segmentation node) started with `-r __ns:=/left` and
  `-r __ns:=/right` serve /left/defgg/plan_grasp and /right/defgg/plan_grasp side by side, nothing at the root, and each
  answers with its own configuration.
- The planned grasp is published as a TF frame (grasp_frame, child of the base frame on /tf) whose
  pose is the returned grasp's pose_base.
"""
import numpy as np
import pytest
from defgg_interfaces.srv import PlanGrasp
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Header

from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render
from defgg_ros.ros import topics
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info, transform_from_pose
from defgg_ros.ros.tf import TfListener

pytestmark = pytest.mark.ros

K = default_camera_k()
DEPTH_M, TRUTH = render(SyntheticScene(objects=(
    SceneObject(center_xy_m=(0.0, 0.0), height_m=0.05, size_xy_m=(0.05, 0.04), yaw_rad=0.3),)))
CAMERA_AT = {"left": [0.5, 0.3, 0.40, 1.0, 0.0, 0.0, 0.0], "right": [0.5, -0.3, 0.40, 1.0, 0.0, 0.0, 0.0]}


def _request() -> PlanGrasp.Request:
    header = Header(frame_id=topics.CAMERA_OPTICAL_FRAME)
    header.stamp.sec = 1
    return PlanGrasp.Request(depth=depth_metres_to_msg(DEPTH_M, "16UC1", header),
                             camera_info=make_camera_info(K, DEPTH_M.shape[1], DEPTH_M.shape[0], header), top_k=1)


def _nodes(executor, namespace, base_T_camera, grasp_frame):
    """A segmentation node (the camera's pose) and an inference node in one namespace."""
    args = ["--ros-args", "-r", f"__ns:=/{namespace}"]
    segmentation = SegmentationNode(context=executor.context, cli_args=args,
                                    parameter_overrides=[Parameter("base_T_camera", value=base_T_camera)])
    node = GraspInferenceNode(context=executor.context, cli_args=args,
                              parameter_overrides=[Parameter("grasp_frame", value=grasp_frame)])
    executor.add_node(segmentation)
    executor.add_node(node)
    return node


def test_two_namespaced_inference_nodes_serve_separately(executor, call, spin):
    nodes = {side: _nodes(executor, side, CAMERA_AT[side], f"{side}/defgg_grasp") for side in ("left", "right")}
    assert nodes["left"].get_namespace() == "/left"
    client_node = Node("names_test_client", context=executor.context)
    executor.add_node(client_node)
    clients = {side: client_node.create_client(PlanGrasp, f"/{side}/{topics.PLAN_GRASP_SERVICE}")
               for side in ("left", "right")}
    for side, client in clients.items():
        spin(executor, client.service_is_ready, 20.0, f"/{side}/{topics.PLAN_GRASP_SERVICE}")
    services = {name for name, _ in client_node.get_service_names_and_types()}
    assert {"/left/defgg/plan_grasp", "/right/defgg/plan_grasp"} <= services
    assert "/defgg/plan_grasp" not in services
    topics_seen = {name for name, _ in client_node.get_topic_names_and_types()}
    assert "/left/defgg/best_grasp" in topics_seen and "/left/camera/camera/depth/image_rect_raw" in topics_seen
    listener = TfListener(client_node)
    poses = {}
    for side, client in clients.items():
        response = call(executor, client, _request(), 30.0, f"{side} plan_grasp")
        assert response.success, response.message
        poses[side] = transform_from_pose(response.grasps[0].pose_base.pose)
    # The same image through each camera pose: the grasps lie 0.6 m apart in y, each node its own.
    assert poses["left"][1, 3] - poses["right"][1, 3] == pytest.approx(0.6, abs=1e-3)

    def frames_known():
        return {"left/defgg_grasp", "right/defgg_grasp"} <= listener.tree.frames()

    spin(executor, frames_known, 10.0, "both planned grasps as TF frames")
    for side in ("left", "right"):
        np.testing.assert_allclose(listener.lookup(topics.BASE_FRAME, f"{side}/defgg_grasp"), poses[side], atol=1e-6)
