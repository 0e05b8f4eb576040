"""Frames from someone else's camera driver reach the nodes (issue 26, item 1).

A plain rclpy publisher in a child process, with Fast DDS's defaults (no profile of ours in its
environment) and rclpy's default QoS (reliable, keep last 10), sends 1280x720 16UC1 depth frames
(1.8 MB each) at 30 Hz. segmentation_node and grasp_inference_node run in this process. Before the
fix their best-effort readers got ~1 frame in 10 (bench/bench_transport.py; here 6 of 20 with the
subscription forced to best effort); now every frame must reach this process through the nodes'
kind of subscription, the nodes' readers must be reliable, and segmentation must process frames.
"""
import os
import subprocess
import sys

import pytest
from rclpy.parameter import Parameter

from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.ros import topics

pytestmark = pytest.mark.ros

FRAMES = 20
WIDTH, HEIGHT = 1280, 720

PUBLISHER = r"""
import sys, time
import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

frames, width, height, depth_topic, info_topic = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), \
    sys.argv[4], sys.argv[5]
rclpy.init()
node = Node("plain_camera_driver")
depth_pub = node.create_publisher(Image, depth_topic, 10)   # rclpy defaults: reliable, keep last 10
info_pub = node.create_publisher(CameraInfo, info_topic, 10)
# Wait until both nodes' depth readers are there and settled on a QoS (they follow the publisher's).
deadline = time.monotonic() + 30.0
while time.monotonic() < deadline:
    subs = node.get_subscriptions_info_by_topic(depth_topic)
    if len(subs) >= 2 and all(s.qos_profile.reliability == ReliabilityPolicy.RELIABLE for s in subs):
        break
    time.sleep(0.1)
time.sleep(0.5)
depth_mm = np.full((height, width), 400, np.uint16)            # the table, 0.4 m under the default camera pose
depth_mm[300:420, 560:720] = 350                               # a 5 cm tall box on it
fx = 631.0
for i in range(frames):
    stamp_ns = 1_000_000_000 + i * 33_333_333
    depth = Image(height=height, width=width, encoding="16UC1", step=width * 2, data=depth_mm.tobytes())
    depth.header.frame_id = "camera_depth_optical_frame"
    depth.header.stamp.sec, depth.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    info = CameraInfo(header=depth.header, height=height, width=width, distortion_model="plumb_bob",
                      d=[0.0] * 5, k=[fx, 0.0, width / 2, 0.0, fx, height / 2, 0.0, 0.0, 1.0],
                      p=[fx, 0.0, width / 2, 0.0, 0.0, fx, height / 2, 0.0, 0.0, 0.0, 1.0, 0.0])
    info_pub.publish(info)
    depth_pub.publish(depth)
    time.sleep(1.0 / 30.0)
time.sleep(5.0)  # stay while readers ask for missing fragments
"""


def _default_fastdds_env() -> dict:
    """This test process's ROS domain, without any Fast DDS profile: the publisher runs on the defaults."""
    return {k: v for k, v in os.environ.items()
            if k not in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
                         "RMW_FASTRTPS_USE_QOS_FROM_XML")}


def test_default_publisher_frames_reach_segmentation_and_inference(executor, spin):
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos

    segmentation = SegmentationNode(context=executor.context)
    inference = GraspInferenceNode(context=executor.context, parameter_overrides=[Parameter("num_threads", value=1)])
    counter = Node("frame_counter", context=executor.context)  # a reader whose callback is never slow
    for node in (segmentation, inference, counter):
        executor.add_node(node)
    stamps = set()
    counted = qos.SensorSubscription(counter, Image, topics.DEPTH_IMAGE,
                                     lambda m: stamps.add((m.header.stamp.sec, m.header.stamp.nanosec)),
                                     depth=FRAMES)  # keeps every frame even while the nodes hog the CPU
    seg_depth = segmentation._depth_sub
    inf_depth = inference._stream_subs[0]
    assert inf_depth.topic == topics.DEPTH_IMAGE
    publisher = subprocess.Popen(
        [sys.executable, "-c", PUBLISHER, str(FRAMES), str(WIDTH), str(HEIGHT), topics.DEPTH_IMAGE,
         topics.DEPTH_CAMERA_INFO], env=_default_fastdds_env())
    try:
        spin(executor, lambda: len(stamps) >= FRAMES or publisher.poll() is not None, 60.0, "the publisher's frames")
        spin(executor, lambda: len(stamps) >= FRAMES, 3.0, f"all {FRAMES} frames (got {len(stamps)})")
    finally:
        publisher.kill()
        publisher.wait()
    assert counted.reliability.name == seg_depth.reliability.name == inf_depth.reliability.name == "RELIABLE"
    # Every frame reached this process (the counter above) and the nodes read it with the same reliable
    # QoS. Their readers keep the last 5 frames, so a node busy with a 1280x720 frame skips some
    # (a camera's old frames are worthless): how many they take depends on the CPU, not on transport.
    assert seg_depth.messages_received >= 3, seg_depth.messages_received
    assert inf_depth.messages_received >= 3, inf_depth.messages_received
    # Each frame it got is perceived, rejected, or replaced by a newer one before perception took it (newest
    # frame wins: dropped).
    spin(executor, lambda: segmentation.frames_processed + segmentation.frames_rejected + segmentation.frames_dropped
         >= seg_depth.messages_received, 30.0, "segmentation to handle the frames it got")
    assert segmentation.frames_processed >= 1, segmentation.last_rejection


def test_reliability_follows_the_publishers():
    from rclpy.qos import ReliabilityPolicy as R

    from defgg_ros.ros.qos import reliability_for

    assert reliability_for([]) == R.BEST_EFFORT                      # nobody yet: match anyone
    assert reliability_for([R.RELIABLE, R.RELIABLE]) == R.RELIABLE    # repair lost fragments
    assert reliability_for([R.RELIABLE, R.BEST_EFFORT]) == R.BEST_EFFORT


def _rosout_of(node, name):
    """The /rosout lines (level, text) that node `name` logs from now on, as the cell's operator sees them."""
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    lines = []
    qos_profile = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(Log, "/rosout", lambda m: lines.append((m.level, m.msg)) if m.name == name else None,
                             qos_profile)
    return lines


def _logged(lines, level, words):
    return any(lv == level and words in text for lv, text in lines)


WARN, INFO = 30, 20   # rcl_interfaces/msg/Log levels


def test_a_silent_stream_is_reported_and_its_return_too(executor, spin):
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos

    node = Node("silence_watch", context=executor.context)
    executor.add_node(node)
    log = _rosout_of(node, "silence_watch")
    got = []
    watch = qos.SensorSubscription(node, Image, "silent_camera/depth", got.append, warn_after_s=1.0)
    spin(executor, lambda: _logged(log, WARN, "no message on /silent_camera/depth for"), 5.0, "the silence warning")
    assert watch._warned
    pub = node.create_publisher(Image, "silent_camera/depth", qos.IMAGE_PUBLISH)
    spin(executor, lambda: watch.reliability.name == "RELIABLE", 5.0, "the switch to a reliable reader")

    def delivered():
        pub.publish(Image(height=1, width=1, encoding="mono8", step=1, data=[1]))
        return bool(got)

    spin(executor, delivered, 5.0, "a message after the silence")
    spin(executor, lambda: _logged(log, INFO, "/silent_camera/depth: messages arrive again"), 5.0, "the return")
    assert not watch._warned


def test_a_best_effort_publisher_beside_a_reliable_one_is_warned_about(executor, spin):
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos

    node = Node("mixed_watch", context=executor.context)
    executor.add_node(node)
    log = _rosout_of(node, "mixed_watch")
    watch = qos.SensorSubscription(node, Image, "mixed_camera/depth", lambda m: None, warn_after_s=0.0)
    node.create_publisher(Image, "mixed_camera/depth", qos.IMAGE_PUBLISH)
    spin(executor, lambda: watch.reliability.name == "RELIABLE", 5.0, "a reliable reader for the camera")
    assert not watch.mixed_publishers and not _logged(log, WARN, "beside reliable ones")
    node.create_publisher(Image, "mixed_camera/depth", qos.SENSOR_DATA)      # someone's best-effort publisher
    spin(executor, lambda: watch.reliability.name == "BEST_EFFORT", 5.0, "the switch to best effort")
    assert watch.mixed_publishers
    spin(executor, lambda: _logged(log, WARN, "a best-effort publisher beside reliable ones"), 5.0, "the warning")


def test_the_cells_fastdds_profile_loads_without_errors_and_sets_a_short_heartbeat():
    """Fast DDS ignores a profile it cannot parse (only logging it): then the cell would run on the default
    transports and 3 s heartbeats again."""
    import xml.etree.ElementTree as ET

    from defgg_ros.ros.transport import FASTDDS_PROFILE, FASTDDS_PROFILE_VARIABLE

    ns = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    period = ET.parse(FASTDDS_PROFILE).getroot().find("f:data_writer[@is_default_profile='true']/f:times/"
                                                      "f:heartbeatPeriod", ns)
    assert period is not None and int(period.find("f:sec", ns).text) == 0
    assert 0 < int(period.find("f:nanosec", ns).text) <= 200_000_000
    code = ("import rclpy; from rclpy.node import Node; from std_msgs.msg import String; rclpy.init(); "
            "n = Node('profile_check'); n.create_publisher(String, 'profile_check', 10); n.destroy_node(); "
            "rclpy.shutdown()")
    env = {**os.environ, FASTDDS_PROFILE_VARIABLE: str(FASTDDS_PROFILE), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "XMLPARSER" not in done.stderr and "Error" not in done.stderr, done.stderr
