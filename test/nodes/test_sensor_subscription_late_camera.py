"""The first frames of a camera started after the nodes reach them (issue 46, item 7).

qos.SensorSubscription used to start best effort and switch to reliable only after it saw the publisher: a
reliable camera started later lost its first frames (a large frame through a best-effort reader loses
fragments; then the switch destroyed the old reader before the new one matched). A camera in a child
process (its own DDS participant, Fast DDS defaults, rclpy's reliable default QoS) waits until this
process's reader has matched it, then sends 1280x720 16UC1 frames: every one of them, the first included,
must arrive, each once."""
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.ros

FRAMES = 6
TOPIC = "late_camera/depth/image_rect_raw"

CAMERA = r"""
import sys, time
import numpy as np
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Image

frames, topic = int(sys.argv[1]), sys.argv[2]
rclpy.init()
node = Node("late_camera")
publisher = node.create_publisher(Image, topic, 10)   # rclpy's default: reliable, keep last 10
deadline = time.monotonic() + 30.0
while publisher.get_subscription_count() < 1 and time.monotonic() < deadline:   # a reader has matched us
    time.sleep(0.01)
data = np.full((720, 1280), 400, np.uint16).tobytes()
for i in range(frames):
    frame = Image(height=720, width=1280, encoding="16UC1", step=2560, data=data)
    frame.header.frame_id = "camera_depth_optical_frame"
    frame.header.stamp.sec = i + 1
    publisher.publish(frame)
    time.sleep(0.5)
time.sleep(5.0)   # stay while readers ask for missing fragments
"""


def test_a_camera_started_after_the_subscriber_loses_no_frame(executor, spin):
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos

    node = Node("late_camera_reader", context=executor.context)
    executor.add_node(node)
    stamps = []
    reader = qos.SensorSubscription(node, Image, TOPIC, lambda m: stamps.append(m.header.stamp.sec),
                                    warn_after_s=0.0, depth=FRAMES)
    env = {k: v for k, v in os.environ.items()
           if k not in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
                         "RMW_FASTRTPS_USE_QOS_FROM_XML")}
    camera = subprocess.Popen([sys.executable, "-c", CAMERA, str(FRAMES), TOPIC], env=env)
    try:
        spin(executor, lambda: len(stamps) >= FRAMES or camera.poll() is not None, 60.0, "the camera's frames")
        spin(executor, lambda: len(stamps) >= FRAMES, 3.0, f"all {FRAMES} frames (got {sorted(stamps)})")
    finally:
        camera.kill()
        camera.wait()
    assert stamps[0] == 1, f"the camera's first frame was lost: got {stamps}"
    assert sorted(stamps) == list(range(1, FRAMES + 1)), f"each frame once: got {stamps}"
    assert reader.reliability.name == "RELIABLE" and not reader.undecided
