"""Bounded soak of the simulated cell: goals, cancels and idle gaps; every goal must get a result and
every cancel an answer (issue 27.5; bench, not CI).

Run:  .venv/bin/python bench/bench_soak.py                       # 30 min, idle gaps up to 10 min
      .venv/bin/python bench/bench_soak.py --duration 180 --max-idle 60   # a 3-minute check
Starts the sim cell (`defgg-bringup`'s sim_cell: driver, segmentation, inference, executor) in a
private ROS domain on the one-block scene, and talks to it as a user's node does: the project's
ActionClient on a ThreadedExecutor spinning in a background thread (the combination that once left
a cancel and a get_result unanswered after ~390 s idle). The schedule (seeded) mixes
- pick goals with plan_grasp=true that put the block back on the table, alternating two spots in
  the camera's view (so the block is there for the next goal),
- the same goals canceled 1-15 s after acceptance,
- idle gaps drawn from 0 s to --max-idle (the longest one is always in the schedule).
Every goal must be answered within --result-timeout and every cancel within --cancel-timeout; a
node that dies fails the soak. Prints the counts, answer latencies, outcomes and where each goal
left the arm; exit code 1 if anything went unanswered or a node died.
"""
import argparse
import random
import sys
import threading
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"
# Release spots for the block (TCP position, base frame): both under the camera (x 0.35-0.65, y +-0.2).
# TCP 4.5 cm up: the 5 cm block, held at half height, is set down from ~2 cm, not pressed into the table.
PLACE_SPOTS_M = ((0.50, 0.05, 0.045), (0.50, -0.07, 0.045))
STATUS = {4: "succeeded", 5: "canceled", 6: "aborted"}


class Waiter:
    """Wait (wall clock) for an rclpy future done in the background executor thread."""

    @staticmethod
    def wait(future, timeout_s: float):
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout_s):
            return None
        return future.result()


def next_step(index: int, max_idle_s: float, cancel_fraction: float, rng: random.Random) -> tuple:
    """(kind, idle_after_s) of goal `index`: kind 'goal' or 'cancel'; the third goal is followed by the
    longest idle gap (max_idle_s), the others by gaps drawn from 0 s up to it."""
    gaps = [g for g in (0.0, 1.0, 5.0, 30.0, 120.0, 390.0, 600.0) if g < max_idle_s] + [max_idle_s]
    kind = "cancel" if rng.random() < cancel_fraction else "goal"
    return kind, max_idle_s if index == 2 else rng.choice(gaps)


def place_goal(index: int):
    from defgg_interfaces.action import PickAndPlace

    from defgg_ros.ros import topics

    goal = PickAndPlace.Goal(plan_grasp=True)
    goal.place_pose.header.frame_id = topics.BASE_FRAME
    p = goal.place_pose.pose
    p.position.x, p.position.y, p.position.z = PLACE_SPOTS_M[index % 2]
    p.orientation.w = 1.0
    return goal


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=1800.0, help="soak length, wall s (default 1800)")
    parser.add_argument("--max-idle", type=float, default=600.0, help="longest idle gap, s (default 600)")
    parser.add_argument("--cancel-fraction", type=float, default=0.3, help="share of goals canceled (default 0.3)")
    parser.add_argument("--result-timeout", type=float, default=600.0, help="wall s a goal may take to answer")
    parser.add_argument("--cancel-timeout", type=float, default=10.0, help="wall s a cancel may take to answer")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log", default="/tmp/bench_soak_cell.log", help="the cell's node logs")
    args = parser.parse_args(argv)

    from defgg_ros.ros.domain import apply_domain_choice

    print(f"bench_soak: {apply_domain_choice('private')}", flush=True)  # before any rclpy context
    import rclpy
    from defgg_interfaces.action import PickAndPlace
    from rclpy.context import Context
    from rclpy.node import Node

    from defgg_ros.bringup.node_set import load_node_set
    from defgg_ros.bringup.supervisor import Bringup
    from defgg_ros.ros import topics
    from defgg_ros.ros.action import ActionClient
    from defgg_ros.ros.executor import ThreadedExecutor

    rng = random.Random(args.seed)
    stats = Counter()
    result_s, cancel_s, arm_states, outcomes, problems = [], [], Counter(), Counter(), []
    started = time.monotonic()
    with open(args.log, "w") as log, Bringup(load_node_set("sim_cell"),
                                             {"fake_panda_driver": {"scene_file": str(SCENE)}}, out=log) as cell:
        print(f"bench_soak: cell ready in {cell.wait_ready(180.0):.1f} s; goals for "
              f"{args.duration:.0f} s, idle gaps up to {args.max_idle:.0f} s; node logs in {args.log}", flush=True)
        context = Context()
        rclpy.init(context=context)
        node = Node("bench_soak_client", context=context)
        client = ActionClient(node, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
        executor = ThreadedExecutor(num_threads=4, context=context)
        executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        try:
            if not client.wait_for_server(timeout_sec=60.0):
                raise SystemExit("bench_soak: the pick-and-place action server did not appear")
            index = -1
            while time.monotonic() - started < args.duration:
                index += 1
                kind, idle_s = next_step(index, args.max_idle, args.cancel_fraction, rng)
                dead = cell.failed_node()
                if dead is not None:
                    problems.append(dead.describe())
                    break
                stats["goals"] += 1
                sent = time.monotonic()
                handle = Waiter.wait(client.send_goal_async(place_goal(index)), 30.0)
                if handle is None or not handle.accepted:
                    problems.append(f"goal {index}: {'no goal response' if handle is None else 'rejected'}")
                    continue
                result_future = handle.get_result_async()
                if kind == "cancel":
                    time.sleep(rng.uniform(1.0, 15.0))  # the user's pause before canceling, not a wait on a message
                    stats["cancels"] += 1
                    asked = time.monotonic()
                    answer = Waiter.wait(handle.cancel_goal_async(), args.cancel_timeout)
                    if answer is None:
                        problems.append(f"goal {index}: cancel unanswered after {args.cancel_timeout:.0f} s")
                    else:
                        stats["cancel answers"] += 1
                        cancel_s.append(time.monotonic() - asked)
                response = Waiter.wait(result_future, args.result_timeout)
                if response is None:
                    problems.append(f"goal {index}: no result after {args.result_timeout:.0f} s")
                else:
                    stats["results"] += 1
                    result_s.append(time.monotonic() - sent)
                    outcomes[STATUS.get(response.status, str(response.status))] += 1
                    arm_states[response.result.arm_state or "(empty)"] += 1
                    if response.status != 4:
                        print(f"  goal {index} ({kind}): {STATUS.get(response.status)}: "
                              f"{response.result.failure_reason[:160]}; arm {response.result.arm_state}", flush=True)
                print(f"bench_soak: goal {index} ({kind}) answered; idle {idle_s:.0f} s "
                      f"(t = {time.monotonic() - started:.0f} s)", flush=True)
                stats["idle s"] += idle_s
                stats["longest idle s"] = max(stats["longest idle s"], idle_s)
                time.sleep(idle_s)  # the idle gap under test: nothing is sent while it lasts
        finally:
            executor.shutdown(timeout_sec=2.0)
            node.destroy_node()
            context.try_shutdown()
        dead = cell.failed_node()
        if dead is not None and dead.describe() not in problems:
            problems.append(dead.describe())
    wall = time.monotonic() - started

    def figures(values):
        return f"median {sorted(values)[len(values) // 2]:.2f} s, max {max(values):.2f} s" if values else "none"

    print(f"bench_soak: {wall:.0f} s wall; goals {stats['goals']}, results {stats['results']}; "
          f"cancels {stats['cancels']}, answered {stats['cancel answers']}; idle {stats['idle s']:.0f} s in total, "
          f"longest gap {stats['longest idle s']:.0f} s")
    print(f"bench_soak: result after sending: {figures(result_s)}; cancel answer: {figures(cancel_s)}")
    print(f"bench_soak: outcomes {dict(outcomes)}; arm left at {dict(arm_states)}")
    for problem in problems:
        print(f"bench_soak: PROBLEM: {problem}")
    ok = not problems and stats["results"] == stats["goals"] and stats["cancel answers"] == stats["cancels"]
    print(f"bench_soak: {'every goal answered and every cancel answered' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
