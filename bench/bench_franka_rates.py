"""The fake driver's franka_ros2 topics: the rate each is published at (sim and wall time), what a
best-effort depth-1 reader in the same process receives, and the driver's real-time factor.

    .venv/bin/python bench/bench_franka_rates.py [--seconds 10] [--max-rtf 1.0] [--robot-state-rate-hz 1000]

franka_ros2 publishes the broadcasters' topics at its controller manager's update_rate, 1 kHz
(docs/franka_contract.md); the driver publishes them once per control period (robot_state_rate_hz).
--max-rtf 0 runs the simulation as fast as it can: its real-time factor is then the capacity.
Prints one line per topic; nothing is asserted.
"""
import argparse
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver  # noqa: E402
from defgg_ros.ros import (
    qos,  # noqa: E402
    topics,  # noqa: E402
)
from defgg_ros.ros.domain import pick_private_domain, release_domain  # noqa: E402

TOPICS = ((topics.EXTERNAL_WRENCH, WrenchStamped, "pub_wrench"),
          (topics.ARM_JOINT_STATES, JointState, "pub_arm_joints"),
          (topics.JOINT_STATES, JointState, "pub_joints"),
          (topics.GRIPPER_JOINT_STATES, JointState, "pub_gripper_joints"))


def _counting(publisher, counts, key):
    publish = publisher.publish

    def counted(msg):
        counts[key] += 1
        publish(msg)
    return counted


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="wall seconds measured (after 3 s warm-up)")
    parser.add_argument("--max-rtf", type=float, default=1.0)
    parser.add_argument("--robot-state-rate-hz", type=float, default=1000.0)
    args = parser.parse_args()
    context = rclpy.Context()
    domain_id = pick_private_domain()
    rclpy.init(context=context, domain_id=domain_id)
    executor = MultiThreadedExecutor(4, context=context)
    driver = FakePandaDriver(context=context, parameter_overrides=[
        Parameter("max_real_time_factor", value=args.max_rtf),
        Parameter("robot_state_rate_hz", value=args.robot_state_rate_hz), Parameter("depth_rate_hz", value=0.01)])
    reader = Node("rate_reader", context=context)
    names = [topic for topic, _, _ in TOPICS]
    published, received = dict.fromkeys(names, 0), dict.fromkeys(names, 0)
    for topic, msg_type, attribute in TOPICS:
        getattr(driver, attribute).publish = _counting(getattr(driver, attribute), published, topic)
        reader.create_subscription(msg_type, topic, lambda _m, t=topic: received.__setitem__(t, received[t] + 1),
                                   qos.ROBOT_STATE_READ)
    executor.add_node(driver)
    executor.add_node(reader)
    threading.Thread(target=executor.spin, daemon=True).start()
    time.sleep(3.0)
    for counts in (published, received):
        counts.update(dict.fromkeys(counts, 0))
    wall0, sim0 = time.monotonic(), driver.cell.time_s
    time.sleep(args.seconds)
    wall_s, sim_s = time.monotonic() - wall0, driver.cell.time_s - sim0
    for topic, _, _ in TOPICS:
        print(f"{topic}: published {published[topic] / sim_s:.0f}/s sim ({published[topic] / wall_s:.0f}/s wall), "
              f"read {received[topic] / wall_s:.0f}/s wall")
    print(f"real-time factor {sim_s / wall_s:.2f} (max_real_time_factor {args.max_rtf}, "
          f"robot_state_rate_hz {args.robot_state_rate_hz:.0f})")
    executor.shutdown()
    driver.destroy_node()
    rclpy.shutdown(context=context)
    release_domain(domain_id)


if __name__ == "__main__":
    main()
