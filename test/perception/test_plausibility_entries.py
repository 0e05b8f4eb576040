"""One plausibility rule at every entry: byte-swapped 16UC1 depth and 1e30 Pa stiffness are refused
by PlanGrasp (request images), by the subscribed depth topic, and by SetStiffness, with the cause."""
import numpy as np
import pytest
from defgg_interfaces.msg import ObjectStiffness
from defgg_interfaces.srv import PlanGrasp, SetStiffness
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.perception.depth import DepthError, depth_to_metres
from defgg_ros.perception.plausibility import check_moduli_plausible
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render
from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info
from defgg_ros.stiffness import InvalidYoungsModulus

K = default_camera_k()
# A tilted table 0.45-0.59 m away, like the frames.
DEPTH_M, TRUTH = render(SyntheticScene(objects=(SceneObject((0.0, 0.0), 0.05, (0.05, 0.05)),),
                                       tilt_xy_rad=(0.25, 0.0), table_distance_m=0.52))
STIFFNESS_PA = np.where(TRUTH > 0, 2e5, 0.0).astype(np.float32)


def header():
    h = Header(frame_id="camera_depth_optical_frame")
    h.stamp.sec = 7
    return h


def byte_swapped_depth() -> Image:
    """Little-endian millimetres sent as big-endian data (is_bigendian=0 but the bytes swapped)."""
    msg = depth_metres_to_msg(DEPTH_M, "16UC1", header())
    msg.data = np.frombuffer(bytes(msg.data), "<u2").byteswap().tobytes()
    return msg


def flagged_big_endian_depth() -> Image:
    """Little-endian data flagged is_bigendian=1 (the other half of the issue's report)."""
    msg = depth_metres_to_msg(DEPTH_M, "16UC1", header())
    msg.is_bigendian = 1
    return msg


def test_the_rule_itself():
    raw = np.rint(DEPTH_M * 1000).astype(np.uint16)
    assert np.nanmedian(depth_to_metres(raw, "16UC1")) == pytest.approx(np.median(DEPTH_M), abs=1e-3)
    with pytest.raises(DepthError, match="byte order"):
        depth_to_metres(raw.byteswap(), "16UC1")
    with pytest.raises(DepthError, match="0.1 mm"):
        depth_to_metres(raw * 10, "16UC1")
    with pytest.raises(DepthError, match="millimetres"):
        depth_to_metres(DEPTH_M * 1000, "32FC1")
    for bad in (1e30, 2e12, 0.5):
        with pytest.raises(InvalidYoungsModulus, match=r"plausible range \[1, 1.2e\+12\] Pa"):
            check_moduli_plausible(np.where(TRUTH > 0, bad, 0.0))
    check_moduli_plausible(STIFFNESS_PA)   # background 0 and 2e5 Pa are fine


@pytest.fixture
def cell(inference_service):
    return inference_service("plausibility_client")


@pytest.mark.parametrize("depth,cause", [(byte_swapped_depth, "byte order"),
                                         (flagged_big_endian_depth, "is_bigendian")])
def test_plan_grasp_refuses_byte_swapped_16uc1(cell, executor, call, depth, cause):
    _, _, client = cell
    request = PlanGrasp.Request(depth=depth(), camera_info=make_camera_info(K, 640, 480, header()))
    response = call(executor, client, request, 20.0, "plan_grasp")
    assert not response.success and not response.grasps
    assert "beyond the camera's 2.0 m range" in response.message and cause in response.message, response.message
    # The same request carrying objects: the same rule.
    request.objects = [ObjectStiffness(name="box", youngs_modulus_pa=2e5)]
    response = call(executor, client, request, 20.0, "plan_grasp")
    assert not response.success and cause in response.message, response.message
    # And the node still serves a good request.
    good = PlanGrasp.Request(depth=depth_metres_to_msg(DEPTH_M, "16UC1", header()),
                             camera_info=make_camera_info(K, 640, 480, header()))
    assert call(executor, client, good, 20.0, "plan_grasp").success


def test_plan_grasp_and_set_stiffness_refuse_1e30_pa_alike(cell, executor, call, spin):
    _, client_node, client = cell
    request = PlanGrasp.Request(depth=depth_metres_to_msg(DEPTH_M, "16UC1", header()),
                                camera_info=make_camera_info(K, 640, 480, header()))
    # A request with objects at 1e30 Pa goes through SetStiffness's rule: refused with the same range.
    request.objects = [ObjectStiffness(name="box", youngs_modulus_pa=1e30)]
    response = call(executor, client, request, 20.0, "plan_grasp")
    assert not response.success and "plausible range [1, 1.2e+12] Pa" in response.message, response.message
    # SetStiffness on the cell's segmentation node (the fixture's): the same range.
    set_client = client_node.create_client(SetStiffness, topics.SET_STIFFNESS_SERVICE)
    assert set_client.wait_for_service(timeout_sec=10.0)
    answer = call(executor, set_client, SetStiffness.Request(objects=[ObjectStiffness(name="box",
                                                                                      youngs_modulus_pa=1e30)]),
                  20.0, "set_stiffness")
    assert not answer.success and "plausible range [1, 1.2e+12] Pa" in answer.message, answer.message


def test_subscribed_depth_topic_refuses_byte_swapped_frames(executor, spin):
    """The segmentation node's depth subscription over DDS: the frame is skipped with the cause."""
    segmentation = SegmentationNode(context=executor.context)
    executor.add_node(segmentation)
    publisher_node = Node("plausibility_publisher", context=executor.context)
    executor.add_node(publisher_node)
    depth_pub = publisher_node.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
    info_pub = publisher_node.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)

    def publish_until_rejected():
        info_pub.publish(make_camera_info(K, 640, 480, header()))
        depth_pub.publish(byte_swapped_depth())
        return segmentation.frames_rejected > 0 and "byte order" in segmentation.last_rejection

    spin(executor, publish_until_rejected, 20.0, "the byte-swapped frame to be rejected")
    assert segmentation.frames_processed == 0


def test_the_rule_on_a_1280x720_frame_reads_a_sample_of_its_pixels():
    """Frames of >= 200 k pixels take the median from every 4th pixel: the same verdicts as the full median."""
    from defgg_ros.perception import tabletop_scenes as ts

    frame = ts.render(ts.cluttered_table(1280, 720), seed=2)
    raw = np.where(np.isfinite(frame.depth_m), np.rint(frame.depth_m * 1000), 0).astype(np.uint16)
    assert raw.size >= 200_000
    assert np.array_equal(np.isnan(depth_to_metres(raw, "16UC1")), raw == 0)
    with pytest.raises(DepthError, match="byte order"):
        depth_to_metres(raw.byteswap(), "16UC1")
    with pytest.raises(DepthError, match="0.1 mm"):
        depth_to_metres(raw * 10, "16UC1")
    with pytest.raises(DepthError, match="millimetres"):
        depth_to_metres(raw.astype(np.float32), "32FC1")
    # A frame whose sampled pixels are all holes still gets a verdict, from all of its pixels.
    sparse = np.zeros_like(raw)
    sparse[1::4, 1::4] = raw[1::4, 1::4]
    assert np.count_nonzero(np.isfinite(depth_to_metres(sparse, "16UC1"))) == np.count_nonzero(sparse)
