"""segmentation_node: every kind of bad frame is skipped with its reason, and the next good frame is served.

The existing node test sends a batch of bad frames and checks that at least
one was rejected; here each fault is sent on its own, its reason is checked,
no output may appear under its stamp, and a good frame must still come out.
A hypothesis fuzz drives the real depth callback with random Image messages:
it must never raise (an exception in a callback would end the node's spin).
"""
import numpy as np
import pytest
from defgg_interfaces.msg import ObjectStiffness
from defgg_interfaces.srv import SetStiffness
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
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
DEPTH_M, TRUTH = render(SyntheticScene(objects=(SceneObject((0.0, 0.0), 0.05, (0.05, 0.04)),)))
EMPTY_M, _ = render(SyntheticScene(objects=()))
DEFAULT_PA = 3e5

BAD_FRAMES = {
    "empty image": (Image(encoding="16UC1"), "depth is 0x0"),
    "colour image": (numpy_to_image(np.zeros((480, 640, 3), np.uint8), "rgb8"), "16UC1 (mm) or 32FC1 (m)"),
    "unknown encoding": (Image(encoding="bayer_rggb8", width=640, height=480, step=640, data=bytes(640 * 480)),
                         "16UC1 (mm) or 32FC1 (m)"),
    "truncated data": (Image(encoding="16UC1", width=640, height=480, step=1280, data=bytes(1000)), "B, expected"),
    "size differs from camera_info": (depth_metres_to_msg(DEPTH_M[:240, :320], "16UC1"), "camera_info is 640x480"),
    "all-NaN depth": (numpy_to_image(np.full((480, 640), np.nan, np.float32), "32FC1"), "no valid pixel"),
    "all-zero depth": (numpy_to_image(np.zeros((480, 640), np.uint16), "16UC1"), "no valid pixel"),
    "metres in 16UC1": (numpy_to_image(np.ones((480, 640), np.uint16), "16UC1"), "look like metres"),
    "millimetres in 32FC1": (numpy_to_image(DEPTH_M * 1000.0, "32FC1"), "look like millimetres"),
}


class Harness:
    def __init__(self, executor, spin, call, node):
        self.executor, self.spin, self.call, self.seg = executor, spin, call, node
        self.node = Node("seg_fault_harness", context=executor.context)
        executor.add_node(self.node)
        self.depth_pub = self.node.create_publisher(Image, topics.DEPTH_IMAGE, qos.SENSOR_DATA)
        self.info_pub = self.node.create_publisher(CameraInfo, topics.DEPTH_CAMERA_INFO, qos.SENSOR_DATA)
        self.stiffness = {}
        self.node.create_subscription(Image, topics.STIFFNESS_IMAGE,
                                      lambda m: self.stiffness.setdefault(stamp_to_ns(m.header.stamp), m),
                                      qos.SENSOR_DATA)
        self.set_client = self.node.create_client(SetStiffness, topics.SET_STIFFNESS_SERVICE)

    def publish_until(self, depth_msg, stamp_sec, done, what, with_info=True, timeout_s=15.0):
        header = Header(frame_id="camera_depth_optical_frame")
        header.stamp.sec = stamp_sec
        depth_msg.header = header
        info = make_camera_info(K, 640, 480, header)
        ticks = [0]

        def check():
            ticks[0] += 1
            if ticks[0] % 4 == 1:  # best effort + discovery: resend until it lands
                if with_info:
                    self.info_pub.publish(info)
                self.depth_pub.publish(depth_msg)
            return done()

        self.spin(self.executor, check, timeout_s, what)

    def good_frame(self, stamp_sec):
        key = stamp_sec * 10**9
        self.publish_until(depth_metres_to_msg(DEPTH_M, "16UC1"), stamp_sec, lambda: key in self.stiffness,
                           f"stiffness image for stamp {stamp_sec}")
        return image_to_numpy(self.stiffness[key])

    def rejected(self, depth_msg, stamp_sec, reason, with_info=True):
        """Publish a bad frame until the node reports this reason; nothing may be published for it."""
        self.seg.last_rejection = ""
        self.publish_until(depth_msg, stamp_sec, lambda: reason in self.seg.last_rejection,
                           f"rejection {reason!r} (last: {self.seg.last_rejection!r})", with_info)
        assert stamp_sec * 10**9 not in self.stiffness

    def set_stiffness(self, objects, default=0.0):
        assert self.set_client.wait_for_service(timeout_sec=10.0)
        request = SetStiffness.Request(objects=objects, default_youngs_modulus_pa=default)
        return self.call(self.executor, self.set_client, request, 10.0, "set_stiffness response")


@pytest.fixture
def harness(executor, spin, call):
    node = SegmentationNode(context=executor.context,
                            parameter_overrides=[Parameter("default_youngs_modulus_pa", value=DEFAULT_PA)])
    executor.add_node(node)
    return Harness(executor, spin, call, node)


def test_each_bad_frame_is_skipped_with_its_reason_and_the_next_good_frame_is_served(harness):
    # Before any camera_info: depth alone cannot be segmented.
    harness.rejected(depth_metres_to_msg(DEPTH_M, "16UC1"), 100, "no camera_info", with_info=False)
    for index, (msg, reason) in enumerate(BAD_FRAMES.values()):
        harness.rejected(msg, 101 + index, reason)
    assert harness.seg.frames_rejected >= len(BAD_FRAMES) + 1
    stiffness = harness.good_frame(200)
    assert set(np.unique(stiffness)) == {0.0, np.float32(DEFAULT_PA)}
    assert np.mean((stiffness > 0) == (TRUTH > 0)) > 0.99


def test_an_empty_scene_gives_an_all_background_image_not_an_error(harness):
    key = 300 * 10**9
    harness.publish_until(depth_metres_to_msg(EMPTY_M, "16UC1"), 300, lambda: key in harness.stiffness,
                          "stiffness image of the empty table")
    assert not np.any(image_to_numpy(harness.stiffness[key]))
    assert harness.good_frame(301).max() == np.float32(DEFAULT_PA)


def _entry(name, value):
    return ObjectStiffness(name=name, youngs_modulus_pa=value)


@pytest.mark.parametrize("objects,default,reason", [
    ([], float("nan"), "default"),
    ([], float("inf"), "default"),
    ([], 1e30, "plausible"),
    ([_entry("negative", -2e5)], 0.0, "> 0"),
    ([_entry("inf", float("inf"))], 0.0, "> 0"),
    ([_entry("unit slip", 2e-3)], 0.0, "plausible"),  # GPa typed as Pa
])
def test_set_stiffness_with_bad_moduli_is_refused_and_the_assignment_kept(harness, objects, default, reason):
    response = harness.set_stiffness(objects, default)
    assert not response.success and reason in response.message, response.message
    assert harness.seg.get_parameter("default_youngs_modulus_pa").value == DEFAULT_PA
    assert set(np.unique(harness.good_frame(400))) == {0.0, np.float32(DEFAULT_PA)}


def test_missing_background_file_refuses_to_start_with_the_path(executor, tmp_path):
    missing = tmp_path / "no_such_background.npy"
    with pytest.raises(OSError, match="no_such_background"):
        SegmentationNode(context=executor.context,
                         parameter_overrides=[Parameter("background_depth_file", value=str(missing))])


def test_a_pickled_background_file_is_refused(executor, tmp_path):
    path = tmp_path / "background.npy"
    np.save(path, np.array([{"not": "an image"}], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="pickle"):
        SegmentationNode(context=executor.context,
                         parameter_overrides=[Parameter("background_depth_file", value=str(path))])


random_images = st.builds(
    lambda enc, w, h, step, data, be: Image(encoding=enc, width=w, height=h, step=step, data=data, is_bigendian=be),
    st.sampled_from(["16UC1", "32FC1", "mono16", "mono8", "rgb8", "", "32FC3"]),
    st.integers(0, 24), st.integers(0, 24), st.integers(0, 100), st.binary(max_size=1200), st.integers(0, 1))


def test_fuzzed_frames_are_refused_with_a_reason_and_never_raise_anything_else(executor):
    """The perception of a frame (what the worker thread runs for each frame the callback hands it) refuses a
    malformed one with a ValueError (counted, published as the frame's error) and raises nothing else."""
    from defgg_ros.perception.frame_worker import WorkerResult

    node = SegmentationNode(context=executor.context)
    executor.add_node(node)

    @settings(max_examples=200, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(random_images, st.integers(0, 30), st.integers(0, 30))
    def fuzz(msg, info_w, info_h):
        node._on_camera_info(make_camera_info(K, max(info_w, 1), max(info_h, 1)))
        before = node.frames_rejected + node.frames_processed
        item = (msg, node._camera_k, 0.0)
        try:
            result = WorkerResult(1, item, 0.0, node._perceive_stream_frame(item, lambda: None))
        except ValueError as exc:
            result = WorkerResult(1, item, 0.0, error=exc)
        node._publish_perceived(result, lambda: None)
        assert node.frames_rejected + node.frames_processed == before + 1

    fuzz()
    assert node.frames_rejected > 100
