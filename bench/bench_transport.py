"""Camera frames from someone else's driver: how many 1280x720 16UC1 frames (1.8 MB) reach a subscriber.

The publisher is a plain rclpy node in its own process with Fast DDS's defaults (no profile file, no
environment of ours) and the default QoS (reliable, keep last 10), 30 Hz, like realsense2_camera.
The subscriber, in another process, is varied: its QoS (best effort = qos_profile_sensor_data, as the
nodes used before issue 26; reliable; the adaptive choice of defgg_ros.ros.qos) and its own
Fast DDS set-up (defaults, or defgg_ros/ros/fastdds_profile.xml as the nodes now set for themselves).

    .venv/bin/python bench/bench_transport.py [--frames 60] [--width 1280 --height 720] [--rate-hz 30]
"""
import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PROFILE = REPO / "defgg_ros" / "ros" / "fastdds_profile.xml"
TOPIC = "/camera/camera/depth/image_rect_raw"


def publisher_child(frames: int, width: int, height: int, rate_hz: float) -> None:
    import numpy as np
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    rclpy.init()
    node = Node("plain_camera")
    pub = node.create_publisher(Image, TOPIC, 10)  # rclpy's default QoS: reliable, keep last 10
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)  # let the reader's discovery finish on both sides
    data = np.full((height, width), 500, np.uint16).tobytes()
    for i in range(frames):
        msg = Image(height=height, width=width, encoding="16UC1", step=width * 2, data=data)
        msg.header.frame_id = str(i)
        pub.publish(msg)
        time.sleep(1.0 / rate_hz)
    time.sleep(3.0)  # reliable repairs of the last frames
    node.destroy_node()
    rclpy.try_shutdown()


def subscriber_child(mode: str, frames: int, rate_hz: float) -> None:
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos

    rclpy.init()
    node = Node("counting_subscriber")
    seen = set()
    if mode == "best_effort":
        node.create_subscription(Image, TOPIC, lambda m: seen.add(m.header.frame_id), qos.SENSOR_DATA)
    elif mode == "reliable":
        node.create_subscription(Image, TOPIC, lambda m: seen.add(m.header.frame_id), qos.STATE)
    else:
        qos.SensorSubscription(node, Image, TOPIC, lambda m: seen.add(m.header.frame_id))
    end = time.monotonic() + 15.0 + frames / rate_hz  # discovery + the publisher's run + late repairs
    while time.monotonic() < end and len(seen) < frames:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(len(seen))
    node.destroy_node()
    rclpy.try_shutdown()


def run_pair(mode: str, own_profile: bool, args) -> int:
    from defgg_ros.ros.domain import pick_private_domain

    base = {k: v for k, v in os.environ.items() if k not in ("FASTRTPS_DEFAULT_PROFILES_FILE",
                                                             "FASTDDS_DEFAULT_PROFILES_FILE")}
    base.update(ROS_DOMAIN_ID=str(pick_private_domain()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    sub_env = dict(base)
    if own_profile:
        sub_env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(PROFILE)
    common = [str(args.frames), str(args.width), str(args.height), str(args.rate_hz)]
    sub = subprocess.Popen([sys.executable, __file__, "--child", "sub", mode, *common], env=sub_env,
                           stdout=subprocess.PIPE, text=True)
    pub = subprocess.Popen([sys.executable, __file__, "--child", "pub", mode, *common], env=base)
    out = sub.communicate(timeout=120)[0].split()
    pub.kill()
    pub.wait()
    return int(out[-1]) if out else -1


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        role, mode, frames, width, height, rate_hz = sys.argv[2:8]
        if role == "pub":
            publisher_child(int(frames), int(width), int(height), float(rate_hz))
        else:
            subscriber_child(mode, int(frames), float(rate_hz))
        return
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--rate-hz", type=float, default=30.0)
    parser.add_argument("--modes", default="best_effort,reliable,adaptive")
    args = parser.parse_args()
    print(f"{args.width}x{args.height} 16UC1 ({args.width * args.height * 2 / 1e6:.2f} MB) at {args.rate_hz:g} Hz, "
          f"{args.frames} frames, publisher: plain rclpy, default QoS, Fast DDS defaults")
    for mode in args.modes.split(","):
        for own_profile in (False, True):
            got = run_pair(mode, own_profile, args)
            print(f"subscriber {mode:11s} {'with' if own_profile else 'without'} our profile: "
                  f"{got} of {args.frames} frames")


if __name__ == "__main__":
    main()
