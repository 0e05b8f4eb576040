"""segmentation_node over real DDS: stiffness image + mask + latched assignments + SetStiffness."""
import numpy as np
import pytest
from defgg_interfaces.msg import ObjectStiffness, StiffnessAssignment
from defgg_interfaces.srv import SetStiffness
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render
from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import (
    depth_metres_to_msg,
    image_to_numpy,
    make_camera_info,
    numpy_to_image,
    stamp_to_ns,
)

K = default_camera_k()
SCENE = SyntheticScene(objects=(
    SceneObject(center_xy_m=(-0.1, 0.0), height_m=0.05, size_xy_m=(0.05, 0.04)),
    SceneObject(center_xy_m=(0.1, 0.02), height_m=0.04, radius_m=0.03),
))
DEPTH_M, TRUTH = render(SCENE)


class Harness:
    """A test-side node: publishes camera frames, collects the segmentation outputs."""

    def __init__(self, executor, spin, call):
        self.executor, self.spin, self.call = executor, spin, call
        self.node = Node("seg_test_harness", context=executor.context)
        executor.add_node(self.node)
        self.depth_pub = self.node.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
        self.info_pub = self.node.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)
        self.stiffness, self.masks, self.assignments = {}, {}, []
        self.node.create_subscription(Image, topics.STIFFNESS_IMAGE,
                                      lambda m: self.stiffness.setdefault(stamp_to_ns(m.header.stamp), m),
                                      qos.SENSOR_DATA)
        self.node.create_subscription(Image, topics.OBJECT_MASK,
                                      lambda m: self.masks.setdefault(stamp_to_ns(m.header.stamp), m),
                                      qos.SENSOR_DATA)
        self.set_client = self.node.create_client(SetStiffness, topics.SET_STIFFNESS_SERVICE)

    def frame(self, depth_msg, stamp_sec, timeout_s=15.0):
        """Publish a depth frame (and camera_info) until its outputs arrive; return (stiffness, mask)."""
        header = Header(frame_id="camera_depth_optical_frame")
        header.stamp.sec = stamp_sec
        depth_msg.header = header
        info = make_camera_info(K, depth_msg.width, depth_msg.height, header)
        key = stamp_sec * 1_000_000_000
        calls = [0]

        def done():
            calls[0] += 1
            if calls[0] % 4 == 1:  # best-effort + discovery: resend until it lands
                self.info_pub.publish(info)
                self.depth_pub.publish(depth_msg)
            return key in self.stiffness and key in self.masks

        self.spin(self.executor, done, timeout_s, f"segmentation outputs for stamp {stamp_sec}")
        return self.stiffness[key], self.masks[key]

    def set_stiffness(self, objects, default=0.0):
        assert self.set_client.wait_for_service(timeout_sec=10.0)
        request = SetStiffness.Request(objects=objects, default_youngs_modulus_pa=default)
        return self.call(self.executor, self.set_client, request, 10.0, "set_stiffness response")


def _entry(name, value, roi=(0, 0, 0, 0), region_only=False):
    entry = ObjectStiffness(name=name, youngs_modulus_pa=value, region_only=region_only)
    entry.roi.x_offset, entry.roi.y_offset, entry.roi.width, entry.roi.height = roi
    return entry


@pytest.fixture
def harness(executor, spin, call):
    node = SegmentationNode(context=executor.context,
                            parameter_overrides=[Parameter("default_youngs_modulus_pa", value=3e5)])
    executor.add_node(node)
    h = Harness(executor, spin, call)
    h.seg_node = node
    return h


def test_depth_to_stiffness_and_mask_with_same_header(harness):
    stiffness_msg, mask_msg = harness.frame(depth_metres_to_msg(DEPTH_M, "16UC1"), stamp_sec=5)
    assert stiffness_msg.encoding == "32FC1" and mask_msg.encoding == "mono8"
    assert stiffness_msg.header.frame_id == "camera_depth_optical_frame"
    stiffness, labels = image_to_numpy(stiffness_msg), image_to_numpy(mask_msg)
    assert stiffness.shape == DEPTH_M.shape
    assert set(np.unique(labels)) == {0, 1, 2}
    assert np.mean((labels > 0) == (TRUTH > 0)) > 0.995
    assert set(np.unique(stiffness)) == {0.0, np.float32(3e5)}


def test_set_stiffness_region_and_latched_assignments(harness, executor, spin):
    harness.frame(depth_metres_to_msg(DEPTH_M, "32FC1"), stamp_sec=6)  # lets the node learn the image size
    left = np.argwhere(TRUTH == 1).mean(axis=0)  # (v, u)
    right_u = int(np.argwhere(TRUTH == 2)[:, 1].mean())
    response = harness.set_stiffness([
        _entry("sponge", 2e4, (int(left[1]) - 3, int(left[0]) - 3, 6, 6)),
        _entry("stiff half", 2e9, (right_u, 0, 640 - right_u, 480), region_only=True),
    ])
    assert response.success, response.message
    stiffness = image_to_numpy(harness.frame(depth_metres_to_msg(DEPTH_M, "16UC1"), stamp_sec=7)[0])
    assert np.all(stiffness[TRUTH == 1] == np.float32(2e4))
    right = stiffness[TRUTH == 2]
    assert set(np.unique(right)) == {np.float32(3e5), np.float32(2e9)}
    # A late joiner still gets the assignments (transient local).
    got = []
    harness.node.create_subscription(StiffnessAssignment, topics.STIFFNESS_ASSIGNMENTS, got.append, qos.LATCHED)
    spin(executor, lambda: any(len(m.objects) == 2 for m in got), 10.0, "latched assignments")
    latest = [m for m in got if len(m.objects) == 2][-1]
    assert latest.default_youngs_modulus_pa == 3e5 and latest.objects[0].name == "sponge"
    assert harness.seg_node.get_parameter("objects_json").value.count("sponge") == 1


@pytest.mark.parametrize("objects,default,match", [
    ([_entry("bad", 0.0)], 0.0, "finite and > 0"),
    ([_entry("nan", float("nan"))], 0.0, "finite and > 0"),
    ([_entry("absurd", 1e20)], 0.0, "plausible"),
    ([], -5.0, "default"),
    ([_entry("off image", 2e5, (900, 10, 5, 5))], 0.0, "outside"),
    ([_entry("region", 2e5, region_only=True)], 0.0, "region_only"),
])
def test_bad_set_stiffness_is_refused_and_node_keeps_going(harness, objects, default, match):
    harness.frame(depth_metres_to_msg(DEPTH_M, "16UC1"), stamp_sec=8)
    response = harness.set_stiffness(objects, default)
    assert not response.success and match in response.message
    stiffness = image_to_numpy(harness.frame(depth_metres_to_msg(DEPTH_M, "16UC1"), stamp_sec=9)[0])
    assert set(np.unique(stiffness)) == {0.0, np.float32(3e5)}  # unchanged assignments


def test_bad_frames_are_skipped_and_node_keeps_running(harness, executor, spin):
    bad_frames = [
        numpy_to_image(np.full((480, 640), 1, np.uint16), "16UC1"),        # metres in a 16UC1 image
        numpy_to_image(np.full((480, 640), np.nan, np.float32), "32FC1"),  # no valid pixel
        numpy_to_image(np.zeros((480, 640, 3), np.uint8), "rgb8"),          # not depth
        depth_metres_to_msg(DEPTH_M[:240, :320], "16UC1"),                 # size differs from camera_info
    ]
    info = make_camera_info(K, 640, 480)
    for frame in bad_frames:
        harness.info_pub.publish(info)
        harness.depth_pub.publish(frame)
    spin(executor, lambda: harness.seg_node.frames_rejected >= 1, 15.0, "a rejected frame")
    harness.frame(depth_metres_to_msg(DEPTH_M, "16UC1"), stamp_sec=10)
    assert harness.seg_node.frames_processed >= 1


def test_bad_parameter_update_is_rejected(harness):
    result = harness.seg_node.set_parameters([Parameter("objects_json", value='[{"youngs_modulus_pa": -1}]')])
    assert not result[0].successful and "> 0" in result[0].reason
    result = harness.seg_node.set_parameters([Parameter("objects_json", value="not json")])
    assert not result[0].successful and "JSON" in result[0].reason


def test_shipped_yaml_config_loads(executor):
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "sim_bringup" / "config" / "segmentation_node.yaml"
    node = SegmentationNode(context=executor.context, cli_args=["--ros-args", "--params-file", str(path)])
    executor.add_node(node)
    assert node.get_parameter("default_youngs_modulus_pa").value == 2e6
    assert node.get_parameter("perceived_topic").value == topics.PERCEIVED_OBJECTS


def test_capture_background_removes_fixtures_that_are_not_table(harness, executor, spin, tmp_path):
    from std_srvs.srv import Trigger

    fixture = SceneObject(center_xy_m=(0.0, -0.12), height_m=0.06, size_xy_m=(0.12, 0.05))  # e.g. a bin wall
    background_m, _ = render(SyntheticScene(objects=(fixture,)))
    scene_m, truth = render(SyntheticScene(objects=(fixture,) + SCENE.objects))
    labels = image_to_numpy(harness.frame(depth_metres_to_msg(scene_m, "16UC1"), stamp_sec=20)[1])
    assert labels.max() == 3  # plane fit: the fixture counts as an object
    save = tmp_path / "background.npy"
    assert harness.seg_node.set_parameters([Parameter("background_save_file", value=str(save))])[0].successful
    harness.frame(depth_metres_to_msg(background_m, "16UC1"), stamp_sec=21)
    client = harness.node.create_client(Trigger, "/defgg/segmentation/capture_background")
    assert client.wait_for_service(timeout_sec=10.0)
    response = harness.call(executor, client, Trigger.Request(), 10.0, "capture response")
    assert response.success, response.message
    np.testing.assert_allclose(np.load(save, allow_pickle=False), background_m, atol=1e-3)
    labels = image_to_numpy(harness.frame(depth_metres_to_msg(scene_m, "16UC1"), stamp_sec=22)[1])
    assert labels.max() == 2 and not np.any(labels[truth == 1])  # only the two objects remain
