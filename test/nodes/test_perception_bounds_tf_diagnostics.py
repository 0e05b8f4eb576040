"""Issue 47 items 5-6 and issue 46 item 7 on real rclpy nodes: image size limit, /diagnostics, camera pose
published on TF only when asked to, and a configured pose that disagrees with TF stops planning."""
import time

import numpy as np
import pytest
from defgg_interfaces.srv import PlanGrasp
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.perception.geometry import transform_to_xyz_quaternion
from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info
from defgg_ros.ros.diagnostics import DIAGNOSTICS_TOPIC
from defgg_ros.ros.parameters import defaults
from defgg_ros.ros.tf import TfBroadcaster, TfListener, pose_difference, transform_msg

pytestmark = pytest.mark.ros
CAMERA_FRAME = "camera_depth_optical_frame"
BASE_FRAME = defaults("segmentation_node")["base_frame"]


def _frame(width=640, height=480, seed=7, fx_px=None):
    scene = ts.cluttered_table(width, height)
    if fx_px is not None:
        import dataclasses

        scene = dataclasses.replace(scene, fx_px=fx_px)
    frame = ts.render(scene, seed=seed)
    header = Header(frame_id=CAMERA_FRAME)
    return (depth_metres_to_msg(frame.depth_m, "16UC1", header),
            make_camera_info(frame.camera_k, width, height, header), frame.base_T_camera)


def _pose_list(pose):
    xyz, quaternion = transform_to_xyz_quaternion(pose)
    return [*xyz.tolist(), *quaternion.tolist()]


def _shifted(pose, dx_m=0.0, yaw_deg=0.0):
    out = np.array(pose, float)
    out[0, 3] += dx_m
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    out[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ out[:3, :3]
    return out


def _calibration(executor, base_T_camera, base_frame=BASE_FRAME):
    node = Node("calibration_publisher", context=executor.context)
    executor.add_node(node)
    TfBroadcaster(node, static=True).send(transform_msg(base_frame, CAMERA_FRAME, base_T_camera))
    return node


def test_a_request_image_larger_than_the_limit_is_refused_and_the_node_keeps_serving(inference_service, executor,
                                                                                      call):
    depth, info, base_T_camera = _frame()
    node, _, client = inference_service("bounds_probe", base_T_camera=_pose_list(base_T_camera),
                                        max_image_size_px=[640, 480])
    big_depth, big_info, _ = _frame(848, 480)
    refused = call(executor, client, PlanGrasp.Request(depth=big_depth, camera_info=big_info), 60.0, "plan_grasp")
    assert not refused.success
    assert "848x480" in refused.message and "640x480" in refused.message and "max_image_size_px" in refused.message
    small_depth, small_info = depth, info
    answered = call(executor, client, PlanGrasp.Request(depth=small_depth, camera_info=small_info), 60.0,
                    "plan_grasp at the limit")
    assert answered.success, answered.message


def test_the_default_limit_takes_every_realsense_depth_mode(inference_service, executor, call):
    _, client_node, client = inference_service("bounds_default_probe")
    for width, height, fx_px in ((1280, 720, None), (1024, 768, 520.0)):      # D4xx's largest, L515's
        depth, info, _ = _frame(width, height, fx_px=fx_px)
        response = call(executor, client, PlanGrasp.Request(depth=depth, camera_info=info), 120.0, "plan_grasp")
        assert "max_image_size_px" not in response.message


def test_the_segmentation_node_skips_an_oversized_frame_and_reports_it_on_diagnostics(executor, spin):
    node = SegmentationNode(context=executor.context, parameter_overrides=[])
    probe = Node("diagnostics_probe", context=executor.context)
    executor.add_node(node)
    executor.add_node(probe)
    seen = []
    probe.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, seen.append, 10)
    depth_pub = probe.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
    info_pub = probe.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)
    big = depth_metres_to_msg(np.full((900, 1400), 0.5, np.float32), "16UC1", Header(frame_id=CAMERA_FRAME))
    info = make_camera_info(np.array([[600.0, 0, 700], [0, 600.0, 450], [0, 0, 1]]), 1400, 900, big.header)

    calls = [0]

    def rejected():
        calls[0] += 1
        if calls[0] % 4 == 1:       # best effort + discovery: resend until one lands, without flooding
            info_pub.publish(info)
            depth_pub.publish(big)
        return node.frames_rejected > 0

    spin(executor, rejected, 20.0, "the oversized frame's rejection")
    assert "1400x900" in node.last_rejection and "1280x800" in node.last_rejection

    def reported():
        return any(kv.key == "last error" and "1400x900" in kv.value
                   for msg in seen for status in msg.status for kv in status.values)

    spin(executor, reported, 10.0, "/diagnostics naming the rejection")
    status = seen[-1].status[0]
    keys = {kv.key for kv in status.values}
    assert {"frames in", "frames perceived", "frames rejected", "camera pose source", "last error"} <= keys
    assert status.name.endswith("segmentation_node") and status.level == status.WARN


def test_the_inference_node_publishes_diagnostics_with_latencies(inference_service, executor, spin, call):
    depth, info, base_T_camera = _frame()
    _, client_node, client = inference_service("diagnostics_inference_probe", base_T_camera=_pose_list(base_T_camera))
    seen = []
    client_node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, seen.append, 10)
    assert call(executor, client, PlanGrasp.Request(depth=depth, camera_info=info), 60.0, "plan_grasp").success

    def latency_reported():
        return any(kv.key == "plan_grasp p99 ms" and kv.value != "nan"
                   for msg in seen for status in msg.status if status.name.endswith("grasp_inference_node")
                   for kv in status.values)

    spin(executor, latency_reported, 10.0, "plan_grasp latency on /diagnostics")


def test_a_configured_pose_is_not_published_on_tf_unless_asked(inference_service, executor, spin, call):
    depth, info, base_T_camera = _frame()
    listener_node = Node("tf_probe", context=executor.context)
    executor.add_node(listener_node)
    listener = TfListener(listener_node)
    _, _, client = inference_service("no_tf_probe", base_T_camera=_pose_list(base_T_camera))
    for _ in range(3):      # past FALLBACK_PUBLISH_DELAY_S: the old default published here
        assert call(executor, client, PlanGrasp.Request(depth=depth, camera_info=info), 60.0, "plan_grasp").success
        executor.spin_once(timeout_sec=1.0)
    assert CAMERA_FRAME not in listener.tree.frames()


def test_a_configured_pose_that_disagrees_with_tf_stops_planning_naming_both(inference_service, executor, call):
    depth, info, base_T_camera = _frame()
    _calibration(executor, base_T_camera)                  # TF: the true pose
    stale = _shifted(base_T_camera, dx_m=0.012)            # the parameter: 12 mm off
    node, _, client = inference_service("conflict_probe", base_T_camera=_pose_list(stale))
    request = PlanGrasp.Request(depth=depth, camera_info=info)
    deadline_calls = 20
    for _ in range(deadline_calls):
        response = call(executor, client, request, 60.0, "plan_grasp")
        if "TF" in response.message:
            break
        executor.spin_once(timeout_sec=0.2)
    assert not response.success
    assert "TF" in response.message and "base_T_camera parameter" in response.message
    assert "12.0 mm" in response.message
    assert node.segmentation_node._camera_pose.source == "conflict"


def test_a_configured_pose_within_tolerance_of_tf_plans(inference_service, executor, spin, call):
    depth, info, base_T_camera = _frame()
    _calibration(executor, base_T_camera)
    close = _shifted(base_T_camera, dx_m=0.003, yaw_deg=0.3)
    distance_m, angle_deg = pose_difference(close, base_T_camera)
    assert distance_m < 0.005 and angle_deg < 0.5
    node, _, client = inference_service("agree_probe", base_T_camera=_pose_list(close))
    tree = node.segmentation_node._camera_pose._listener.tree
    spin(executor, lambda: CAMERA_FRAME in tree.frames(), 10.0, "the calibration")
    response = call(executor, client, PlanGrasp.Request(depth=depth, camera_info=info), 60.0, "plan_grasp")
    assert response.success, response.message
    assert node.segmentation_node._camera_pose.source == "tf"


def test_the_segmentation_node_rejects_frames_while_the_poses_disagree(executor, spin):
    from rclpy.parameter import Parameter

    depth, info, base_T_camera = _frame()
    _calibration(executor, base_T_camera)
    stale = _shifted(base_T_camera, yaw_deg=1.0)
    node = SegmentationNode(context=executor.context,
                            parameter_overrides=[Parameter("base_T_camera", value=_pose_list(stale))])
    probe = Node("conflict_camera", context=executor.context)
    executor.add_node(node)
    executor.add_node(probe)
    depth_pub = probe.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
    info_pub = probe.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)

    calls = [0]

    def conflict_seen():
        calls[0] += 1
        if calls[0] % 4 == 1:       # best effort + discovery: resend until one lands, without flooding
            info_pub.publish(info)
            depth_pub.publish(depth)
        return "base_T_camera parameter" in node.last_rejection

    spin(executor, conflict_seen, 20.0, f"the pose conflict ({node.frames_processed} frames perceived, "
                                        f"{node.frames_rejected} rejected: {node.last_rejection})")
    assert "1.00 deg" in node.last_rejection and "TF" in node.last_rejection
    assert node._camera_pose.source == "conflict"


def test_the_executor_publishes_diagnostics_too(executor_cell):
    ex, executor_node, _, _ = executor_cell
    probe = Node("executor_diagnostics_probe", context=ex.context)
    ex.add_node(probe)
    seen = []
    probe.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, seen.append, 10)

    def reported():
        ex.spin_once(timeout_sec=0.1)
        return any(status.name.endswith("executor_node") and any(kv.key == "busy" for kv in status.values)
                   for msg in seen for status in msg.status)

    deadline = time.monotonic() + 10.0
    while not reported():
        assert time.monotonic() < deadline, "no /diagnostics status from the executor within 10 s"
