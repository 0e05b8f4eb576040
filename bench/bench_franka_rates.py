"""The fake driver's franka_ros2 topics: the rate each is published at (sim and wall time), what a
best-effort depth-1 reader in the same process receives, and the driver's real-time factor.

    .venv/bin/python bench/bench_franka_rates.py [--seconds 10] [--max-rtf 1.0] [--robot-state-rate-hz 1000] [--moving]

franka_ros2 publishes the broadcasters' topics at its controller manager's update_rate, 1 kHz
(docs/franka_contract.md); the driver publishes them once per control period (robot_state_rate_hz).
--max-rtf 0 runs the simulation as fast as it can: its real-time factor is then the capacity.
--moving: the arm follows a FollowJointTrajectory goal (a slow quintic swing of joints 1 and 4) all the while, so the
controller's tracking, checks and goal task take their share, as in a pick.
Prints one line per topic; nothing is asserted.
"""
import argparse
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from builtin_interfaces.msg import Duration  # noqa: E402
from control_msgs.action import FollowJointTrajectory  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from trajectory_msgs.msg import JointTrajectoryPoint  # noqa: E402

from defgg_ros.constants import PANDA_READY_Q_RAD  # noqa: E402
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


def _swing_goal(joint_names, duration_s: float) -> FollowJointTrajectory.Goal:
    """Joints 1 and 4 swing +-0.3 rad about the ready pose with period 4 s (quintic points every 0.25 s)."""
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = list(joint_names)
    omega = 2 * np.pi / 4.0
    for t in np.arange(0.25, duration_s, 0.25):
        q, qd, qdd = np.array(PANDA_READY_Q_RAD), np.zeros(7), np.zeros(7)
        for j in (0, 3):
            q[j] += 0.3 * np.sin(omega * t)
            qd[j], qdd[j] = 0.3 * omega * np.cos(omega * t), -0.3 * omega**2 * np.sin(omega * t)
        goal.trajectory.points.append(JointTrajectoryPoint(
            positions=q.tolist(), velocities=qd.tolist(), accelerations=qdd.tolist(),
            time_from_start=Duration(sec=int(t), nanosec=int(round((t % 1) * 1e9)))))
    last = goal.trajectory.points[-1]   # the controller takes only a trajectory that ends at rest
    last.velocities, last.accelerations = [0.0] * 7, [0.0] * 7
    return goal


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="wall seconds measured (after 3 s warm-up)")
    parser.add_argument("--max-rtf", type=float, default=1.0)
    parser.add_argument("--robot-state-rate-hz", type=float, default=1000.0)
    parser.add_argument("--moving", action="store_true", help="the arm follows a trajectory goal meanwhile")
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
    if args.moving:   # long enough for the measurement at any real-time factor up to 5
        client = ActionClient(reader, FollowJointTrajectory, driver.cfg["arm_trajectory_action"])
        if not client.wait_for_server(timeout_sec=30.0):
            raise SystemExit("the arm controller's action did not appear")
        client.send_goal_async(_swing_goal(driver._arm_joints, 5.0 * (args.seconds + 5.0)))
    time.sleep(3.0)
    for counts in (published, received):
        counts.update(dict.fromkeys(counts, 0))
    wall0, sim0 = time.monotonic(), driver.cell.time_s
    time.sleep(args.seconds)
    wall_s, sim_s = time.monotonic() - wall0, driver.cell.time_s - sim0
    for topic, _, _ in TOPICS:
        print(f"{topic}: published {published[topic] / sim_s:.0f}/s sim ({published[topic] / wall_s:.0f}/s wall), "
              f"read {received[topic] / wall_s:.0f}/s wall")
    moving = ", arm moving" if args.moving else ""
    print(f"real-time factor {sim_s / wall_s:.2f} (max_real_time_factor {args.max_rtf}, "
          f"robot_state_rate_hz {args.robot_state_rate_hz:.0f}{moving})")
    executor.shutdown()
    driver.destroy_node()
    rclpy.shutdown(context=context)
    release_domain(domain_id)


if __name__ == "__main__":
    main()
