"""Timer and subscription pace under rclpy's MultiThreadedExecutor and defgg_ros's ThreadedExecutor.

A 100 Hz timer publishes joint states, a second node subscribes, both on one executor spun the
way the nodes and tests spin (`spin()` in a thread, or `spin_once(0.05)` in a loop). Printed per
executor: callbacks run against the nominal count, the largest gap between two timer callbacks,
how many gaps exceeded 0.1 s, and the process CPU time, for --rounds rounds: the stock executor
falls into its stall in some runs and not in others. Run it on an otherwise idle machine: load
hides the stock executor's problem (see defgg_ros/ros/executor.py).

    .venv/bin/python bench/bench_executor_jitter.py [--seconds 10] [--threads 2] [--rounds 3]
"""
import argparse
import threading
import time

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState

from defgg_ros.ros.executor import ThreadedExecutor

PERIOD_S = 0.01
EXECUTORS = {"rclpy MultiThreadedExecutor": MultiThreadedExecutor, "defgg ThreadedExecutor": ThreadedExecutor}


def run(executor_type, threads: int, seconds: float, spin_style: str) -> dict:
    context = Context()
    rclpy.init(context=context)
    executor = executor_type(num_threads=threads, context=context)
    talker, listener = Node("talker", context=context), Node("listener", context=context)
    publisher = talker.create_publisher(JointState, "bench_joint_states", 10)
    ticks, received = [], []
    talker.create_timer(PERIOD_S, lambda: (ticks.append(time.monotonic()), publisher.publish(JointState())))
    listener.create_subscription(JointState, "bench_joint_states", received.append, 10)
    executor.add_node(talker)
    executor.add_node(listener)
    cpu0, end = time.process_time(), time.monotonic() + seconds
    thread = None
    if spin_style == "spin":
        thread = threading.Thread(target=executor.spin, daemon=True)
        thread.start()
        time.sleep(seconds)
    else:
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
    cpu_s = time.process_time() - cpu0
    executor.shutdown(timeout_sec=2.0)
    if thread is not None:
        thread.join(timeout=5.0)
    for node in (talker, listener):
        node.destroy_node()
    context.try_shutdown()
    gaps = np.diff(ticks) if len(ticks) > 1 else np.array([seconds])
    return {"timer": len(ticks), "received": len(received), "max_gap_s": float(gaps.max()),
            "gaps_over_100ms": int((gaps > 0.1).sum()), "cpu_s": cpu_s}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="run time per case (default 10)")
    parser.add_argument("--threads", type=int, default=2, help="executor threads (default 2)")
    parser.add_argument("--rounds", type=int, default=3, help="runs of each case (default 3)")
    args = parser.parse_args()
    nominal = int(args.seconds / PERIOD_S)
    print(f"100 Hz timer + subscription, {args.seconds:.0f} s per case, {args.threads} threads, nominal {nominal}")
    header = ("executor", "spin", "timer", "recv", "max gap s", "gaps>0.1s", "cpu s")
    print("{:30s} {:10s} {:>6s} {:>6s} {:>10s} {:>10s} {:>6s}".format(*header))
    for name, executor_type in EXECUTORS.items():
        for spin_style in [style for style in ("spin", "spin_once") for _ in range(args.rounds)]:
            r = run(executor_type, args.threads, args.seconds, spin_style)
            print(f"{name:30s} {spin_style:10s} {r['timer']:6d} {r['received']:6d} {r['max_gap_s']:10.3f} "
                  f"{r['gaps_over_100ms']:10d} {r['cpu_s']:6.1f}")


if __name__ == "__main__":
    main()
