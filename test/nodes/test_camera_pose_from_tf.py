"""Perception takes the camera pose from TF (base -> the depth frame's frame_id), the parameter as fallback."""
import numpy as np
import pytest
from rclpy.node import Node
from std_msgs.msg import Header

from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.ros.tf import TfBroadcaster, transform_msg

pytestmark = pytest.mark.ros


def test_segmentation_node_uses_the_calibrated_camera_pose_on_tf(executor, spin):
    node = SegmentationNode(context=executor.context)
    calibration = Node("calibration_publisher", context=executor.context)
    executor.add_node(node)
    executor.add_node(calibration)
    header = Header(frame_id="camera_depth_optical_frame")
    parameter_pose = node.base_T_camera_for(header)      # nothing on TF yet: the parameter
    tilted = np.eye(4)
    tilted[:3, :3] = [[0.0, -0.8, 0.6], [-1.0, 0.0, 0.0], [0.0, -0.6, -0.8]]
    tilted[:3, 3] = [0.1, 0.05, 0.55]
    TfBroadcaster(calibration, static=True).send(transform_msg("panda_link0", "camera_depth_optical_frame", tilted))
    spin(executor, lambda: not np.allclose(node.base_T_camera_for(header), parameter_pose), 10.0,
         "the camera pose from /tf_static")
    np.testing.assert_allclose(node.base_T_camera_for(header), tilted, atol=1e-9)
    # a frame id TF does not know falls back to the parameter
    np.testing.assert_allclose(node.base_T_camera_for(Header(frame_id="other_camera")), parameter_pose)
