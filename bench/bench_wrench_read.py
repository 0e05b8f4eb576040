"""What reading franka's 1 kHz external wrench costs: a callback per message against a reader taken at 100 Hz.

    .venv/bin/python bench/bench_wrench_read.py [--seconds 15]

The simulated driver runs as its own process (sim_bringup/scenes/rigid_box.yaml, sim time, real-time pace), as
in the cell; this process then reads franka_robot_state_broadcaster/external_wrench_in_base_frame three ways, one
after the other, and prints for each the messages it got per second and the CPU this process used (cores):
  callback   a subscription spun by rclpy's SingleThreadedExecutor (a pass of its wait loop per message)
  reader     LatestMessageReader taken every 10 ms (the executor node's control period), with the newest's age
  executor   an idle ExecutorNode (given grasps, no goal) on the cell's ThreadedExecutor: its inputs and timers
Nothing is asserted; the machine is shared, so compare rows of one run.
"""
import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.ros.domain import pick_private_domain  # noqa: E402

os.environ["ROS_DOMAIN_ID"] = str(pick_private_domain())

import rclpy  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from defgg_ros.ros import qos, topics  # noqa: E402
from defgg_ros.ros.latest_reader import LatestMessageReader  # noqa: E402

SCENE = ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"
WRENCH = "/" + topics.EXTERNAL_WRENCH.lstrip("/")


def start_driver() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "defgg_ros.nodes.fake_panda_driver_node", "--ros-args",
                             "-p", f"scene_file:={SCENE}", "-p", "use_sim_time:=true"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)


def by_callback(context, seconds: float) -> str:
    node = Node("bench_wrench_callback", context=context)
    count = [0]
    node.create_subscription(WrenchStamped, WRENCH, lambda _msg: count.__setitem__(0, count[0] + 1),
                             qos.ROBOT_STATE_READ)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    end_s = time.monotonic() + 1.0
    while time.monotonic() < end_s:   # matched and flowing before the count
        executor.spin_once(timeout_sec=0.1)
    count[0], cpu0, end_s = 0, time.process_time(), time.monotonic() + seconds
    while time.monotonic() < end_s:
        executor.spin_once(timeout_sec=0.1)
    cpu = (time.process_time() - cpu0) / seconds
    executor.shutdown()
    node.destroy_node()
    return f"callback  {count[0] / seconds:6.0f} messages/s   {cpu:.2f} cores"


def by_reader(context, seconds: float) -> str:
    owner = Node("bench_wrench_owner", context=context)
    reader = LatestMessageReader(owner, WrenchStamped, WRENCH, qos.ROBOT_STATE_READ, "wrench")
    time.sleep(1.0)
    reader.take()
    taken, ages_s, cpu0, end_s = 0, [], time.process_time(), time.monotonic() + seconds
    while time.monotonic() < end_s:
        time.sleep(0.01)
        got = reader.take()
        if got is not None:
            taken += 1
            ages_s.append(got[1])
    cpu = (time.process_time() - cpu0) / seconds
    reader.destroy()
    owner.destroy_node()
    median_ms = sorted(ages_s)[len(ages_s) // 2] * 1e3 if ages_s else float("nan")
    return f"reader    {taken / seconds:6.0f} takes/s      {cpu:.2f} cores   newest's age median {median_ms:.1f} ms"


def idle_executor(context, seconds: float) -> str:
    from defgg_ros.nodes.executor_node import ExecutorNode
    from defgg_ros.ros.executor import ThreadedExecutor

    node = ExecutorNode(context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
    executor = ThreadedExecutor(num_threads=4, context=context)
    executor.add_node(node)
    end_s = time.monotonic() + 2.0
    while time.monotonic() < end_s:
        executor.spin_once(timeout_sec=0.1)
    cpu0, end_s = time.process_time(), time.monotonic() + seconds
    while time.monotonic() < end_s:
        executor.spin_once(timeout_sec=0.1)
    cpu = (time.process_time() - cpu0) / seconds
    executor.remove_node(node)
    node.destroy_node()
    executor.shutdown(timeout_sec=2.0)
    return f"executor  idle ExecutorNode beside the driver    {cpu:.2f} cores"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=15.0, help="wall seconds measured per row")
    args = parser.parse_args()
    driver = start_driver()
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        time.sleep(8.0)   # the driver up and publishing
        if driver.poll() is not None:
            sys.exit(f"the simulated driver exited with {driver.returncode}")
        for row in (by_callback, by_reader, idle_executor):
            print(row(context, args.seconds), flush=True)
    finally:
        driver.terminate()
        driver.wait(timeout=10)
        rclpy.shutdown(context=context)


if __name__ == "__main__":
    main()
