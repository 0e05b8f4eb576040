"""Nodes without a camera pose (no TF, base_T_camera not set) on a tilted camera's frame, over real
DDS: the grasp service answers with grasps in the table frame (which the executor refuses), the segmentation
node segments the frame; a configured pose that finds no table is still refused, never second-guessed."""
from pathlib import Path

import numpy as np
from defgg_interfaces.srv import PlanGrasp
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from defgg_ros.nodes.executor_node import grasp_target
from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.table_pose import TABLE_FRAME_ID
from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import depth_metres_to_msg, image_to_numpy, make_camera_info

MODEL_PATH = Path(__file__).resolve().parents[2] / "models" / "defgg_cnn.pt"
TIMEOUT_S = 60.0
FRAME = ts.render(ts.cluttered_table(848, 480), seed=11)
MODULI = np.zeros(256, np.float32)
MODULI[1:9] = 2e5


def _request(top_k=5):
    header = Header(frame_id="camera_depth_optical_frame")
    h, w = FRAME.depth_m.shape
    return PlanGrasp.Request(depth=depth_metres_to_msg(FRAME.depth_m, "16UC1", header),
                             camera_info=make_camera_info(FRAME.camera_k, w, h, header), top_k=top_k)


def test_without_a_pose_the_grasps_come_in_the_table_frame(inference_service, executor, call):
    _, _, client = inference_service("table_frame_probe", model_path=str(MODEL_PATH))
    response = call(executor, client, _request(), TIMEOUT_S, "plan_grasp response")
    assert response.success, response.message
    assert len(response.grasps) >= 3
    assert {g.pose_base.header.frame_id for g in response.grasps} == {TABLE_FRAME_ID}
    objects = [g.object_id for g in response.grasps]
    assert len(set(objects[:3])) == 3, objects
    # The grasps lie on the table frame's table: ~0 to 0.25 m above it.
    assert all(0.0 < g.pose_base.pose.position.z < 0.25 for g in response.grasps)
    try:
        grasp_target(response.grasps[0], "base", 2e6)
    except ValueError as exc:
        assert TABLE_FRAME_ID in str(exc) and "publish the hand-eye calibration" in str(exc), str(exc)
    else:
        raise AssertionError("the executor accepted a grasp in the table frame")


def test_a_configured_pose_without_table_is_refused(inference_service, executor, call):
    overhead = [0.5, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]        # set, and wrong
    _, _, client = inference_service("table_frame_probe", model_path=str(MODEL_PATH), base_T_camera=overhead)
    response = call(executor, client, _request(), TIMEOUT_S, "plan_grasp response")
    assert not response.success and "table" in response.message, response.message


def test_the_segmentation_node_segments_a_frame_without_pose(executor, spin):
    node = SegmentationNode(context=executor.context)
    executor.add_node(node)
    probe = Node("segmentation_table_frame_probe", context=executor.context)
    executor.add_node(probe)
    masks = []
    probe.create_subscription(Image, topics.OBJECT_MASK, masks.append, qos.SENSOR_DATA)
    depth_pub = probe.create_publisher(Image, topics.DEPTH_IMAGE, qos.IMAGE_PUBLISH)
    info_pub = probe.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.IMAGE_PUBLISH)
    header = Header(frame_id="camera_depth_optical_frame")
    h, w = FRAME.depth_m.shape
    ticks = [0]

    def published_and_masked():
        ticks[0] += 1
        if ticks[0] % 20 == 1:
            info_pub.publish(make_camera_info(FRAME.camera_k, w, h, header))
            depth_pub.publish(depth_metres_to_msg(FRAME.depth_m, "16UC1", header))
        return bool(masks)

    spin(executor, published_and_masked, TIMEOUT_S, "a mask of the frame")
    labels = image_to_numpy(masks[-1])
    assert node.frames_rejected == 0, node.last_rejection
    # Each true object is mostly one label of its own.
    found = set()
    for index in range(1, len(ts.cluttered_objects()) + 1):
        mine = labels[FRAME.labels == index]
        mine = mine[mine > 0]
        if mine.size:
            found.add(int(np.bincount(mine).argmax()))
    assert len(found) >= 6, found
