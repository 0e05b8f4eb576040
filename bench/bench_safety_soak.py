"""Safety soak of the executor (issue 48.5; bench, not CI): mixed goals, cancels in every phase, bad requests and
one driver restart on the simulated arm; after every terminal result the arm must not move.

Run:  .venv/bin/python bench/bench_safety_soak.py                    # 30 min
      .venv/bin/python bench/bench_safety_soak.py --duration 600     # 10 min
Starts the simulated driver (rigid_box.yaml: one 5 cm block) and the executor as processes in a private ROS domain
(no perception: each goal carries the block's top-down grasp from the simulator's true pose). The schedule cycles:
- a pick with an empty place_pose (into the bin's next free slot) while the block is on the table; from the bin
  back onto the table (an explicit place pose, after defgg/reset_bin) when it is in the bin;
- every third of those goals measures the block's stiffness first (measure_stiffness: the squeeze, then the pick),
  every sixth only measures (measure_only: squeeze, open, back to the observation pose);
- the same goals canceled once they reach a phase, the phases in turn (pre_grasp ... retreat; "squeeze" with a
  measuring goal);
- every fourth step a bad goal (grasp in another frame, a NaN grasp, a place pose in another frame): it must be
  refused with a reason within a few seconds;
- once, at half time, the driver is killed (SIGKILL) mid-goal and started again (a fresh simulation).
After every result the joint states are watched for --watch-s: the fastest joint must stay at most 0.01 rad/s
("no arm motion after a terminal result"). The executor's resident memory is read at the first and the last goal
(/proc/<pid>/status VmRSS). Exit code 1 when a goal went unanswered, the arm moved after a result, memory grew by
more than 50 MB, or the executor did not exit 0 at the end (its stop confirmed).
"""
import argparse
import math
import sys
import threading
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"
BLOCK_M = 0.05
TABLE_SPOTS_M = ((0.50, 0.05), (0.45, -0.10))   # where a block taken out of the bin goes (under the camera)
PHASES = ("pre_grasp", "descend", "squeeze", "close", "lift", "transfer", "place", "retreat")
STATUS = {4: "succeeded", 5: "canceled", 6: "aborted"}
REST_RADPS = 0.01
MEMORY_LIMIT_MB = 50.0


def node_set(folder: Path):
    import yaml

    from defgg_ros.bringup.node_set import config_dir, load_node_set

    config = config_dir()
    text = {"name": "safety_soak", "use_sim_time": True, "nodes": [
        {"name": "fake_panda_driver", "module": "defgg_ros.nodes.fake_panda_driver_node",
         "params": [str(config / "fake_panda_driver.yaml")], "ready": {"action": "/franka_gripper/grasp"},
         "overrides": {"scene_file": str(SCENE), "depth_rate_hz": 0.5}},
        {"name": "executor_node", "module": "defgg_ros.nodes.executor_node",
         "params": [str(config / "executor_node.yaml")], "ready": {"action": "/defgg/pick_and_place"}}]}
    path = folder / "safety_soak_set.yaml"
    path.write_text(yaml.safe_dump(text))
    return load_node_set(str(path))


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return float(line.split()[1]) / 1024.0
    return math.nan


def block_grasp(pose):
    """Top-down grasp across the block's top face, fingers along a face normal (from the simulator's pose)."""
    from defgg_interfaces.msg import Grasp

    from defgg_ros.control.poses import matrix_to_quaternion, top_down_pose
    from defgg_ros.ros import topics

    q = pose.orientation
    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    xyz = (pose.position.x, pose.position.y, pose.position.z + BLOCK_M / 2)
    msg = Grasp()
    msg.pose_base.header.frame_id = topics.BASE_FRAME
    msg.pose_base.pose.position.x, msg.pose_base.pose.position.y, msg.pose_base.pose.position.z = xyz
    o = msg.pose_base.pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(top_down_pose(xyz, yaw)[:3, :3])
    msg.width_m, msg.youngs_modulus_pa = 0.07, 2e9
    return msg


def in_bin(pose) -> bool:
    return abs(pose.position.x - 0.35) < 0.1 and abs(pose.position.y + 0.45) < 0.1


def bad_goal(index: int):
    from defgg_interfaces.action import PickAndPlace

    from defgg_ros.ros import topics

    goal = PickAndPlace.Goal(grasp=block_grasp_stub())
    kind = index % 3
    if kind == 0:
        goal.grasp.pose_base.header.frame_id = "camera_color_optical_frame"
    elif kind == 1:
        goal.grasp.pose_base.pose.position.x = math.nan
    else:
        goal.place_pose.header.frame_id = "world"
        goal.place_pose.pose.orientation.w = 1.0
    goal.grasp.pose_base.header.frame_id = goal.grasp.pose_base.header.frame_id or topics.BASE_FRAME
    return goal


def block_grasp_stub():
    from geometry_msgs.msg import Pose

    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z, pose.orientation.w = 0.5, 0.05, BLOCK_M / 2, 1.0
    return block_grasp(pose)


class Cell:
    """The client side: action client, reset_bin, joint states and object poses, spun in a background thread."""

    def __init__(self):
        import rclpy
        from defgg_interfaces.action import PickAndPlace
        from geometry_msgs.msg import PoseArray
        from rclpy.context import Context
        from rclpy.node import Node
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger

        from defgg_ros.ros import qos, topics
        from defgg_ros.ros.action import ActionClient
        from defgg_ros.ros.executor import ThreadedExecutor

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node("bench_safety_soak", context=self.context)
        self.client = ActionClient(self.node, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
        self.reset_bin = self.node.create_client(Trigger, "defgg/reset_bin")
        self.joints, self.poses = [], None
        self.node.create_subscription(JointState, topics.JOINT_STATES, self._on_joints, qos.STATE)
        self.node.create_subscription(PoseArray, topics.FAKE_OBJECT_POSES, self._on_poses, qos.STATE)
        self.executor = ThreadedExecutor(num_threads=4, context=self.context)
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def _on_joints(self, msg):
        speed = max(abs(v) for v in msg.velocity[:7]) if len(msg.velocity) >= 7 else math.inf
        self.joints.append((time.monotonic(), speed))
        del self.joints[:-5000]

    def _on_poses(self, msg):
        self.poses = msg

    @staticmethod
    def wait(future, timeout_s: float):
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        return future.result() if done.wait(timeout_s) else None

    def max_speed_after(self, since: float, watch_s: float) -> float:
        time.sleep(watch_s)
        speeds = [s for t, s in self.joints if t >= since]
        return max(speeds) if speeds else math.inf

    def close(self):
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        self.context.try_shutdown()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=1800.0, help="soak length, wall s (default 1800)")
    parser.add_argument("--watch-s", type=float, default=1.5, help="joint states watched after each result (s)")
    parser.add_argument("--result-timeout", type=float, default=300.0, help="wall s a goal may take to answer")
    parser.add_argument("--log", default="/tmp/bench_safety_soak_cell.log", help="the nodes' logs")
    args = parser.parse_args(argv)

    from defgg_ros.ros.domain import apply_domain_choice

    print(f"bench_safety_soak: {apply_domain_choice('private')}", flush=True)  # before any rclpy context
    from defgg_interfaces.action import PickAndPlace
    from std_srvs.srv import Trigger

    from defgg_ros.bringup.supervisor import Bringup
    from defgg_ros.ros import topics
    from defgg_ros.ros.launcher import NodeProcess

    stats, outcomes, problems = Counter(), Counter(), []
    moved_after, memory = [], []
    started = time.monotonic()
    restarted = False
    with open(args.log, "w") as log, Bringup(node_set(Path(args.log).parent), out=log) as bringup:
        print(f"bench_safety_soak: cell ready in {bringup.wait_ready(180.0):.1f} s; node logs in {args.log}",
              flush=True)
        cell = Cell()
        executor_pid = bringup.processes["executor_node"].pid
        try:
            if not cell.client.wait_for_server(timeout_sec=60.0):
                raise SystemExit("bench_safety_soak: no pick-and-place action server")
            index = -1
            while time.monotonic() - started < args.duration:
                index += 1
                dead = bringup.failed_node()
                if dead is not None:
                    problems.append(dead.describe())
                    break
                restart_now = not restarted and time.monotonic() - started > args.duration / 2
                kind = "bad" if index % 4 == 3 else ("cancel" if index % 2 == 1 else "goal")
                if restart_now:
                    kind = "restart"
                if kind == "bad":
                    goal = bad_goal(index // 4)
                else:
                    waited = time.monotonic()
                    while cell.poses is None and time.monotonic() - waited < 120.0:
                        time.sleep(0.1)
                    if cell.poses is None:   # a driver that publishes nothing: say so, do not wait forever
                        problems.append(f"step {index}: no object poses from the driver for 120 s")
                        break
                    block = cell.poses.poses[0]
                    goal = PickAndPlace.Goal(grasp=block_grasp(block))
                    measures = stats["goal"] % 3 == 2 if kind == "goal" else (
                        kind == "cancel" and PHASES[stats["cancel"] % len(PHASES)] == "squeeze")
                    goal.measure_stiffness = measures
                    goal.measure_only = kind == "goal" and stats["goal"] % 6 == 5
                    stats["measuring"] += measures
                    if in_bin(block):   # out of the bin, back onto the table (the bin is empty again)
                        cell.wait(cell.reset_bin.call_async(Trigger.Request()), 10.0)
                        goal.place_pose.header.frame_id = topics.BASE_FRAME
                        spot = TABLE_SPOTS_M[index % 2]
                        goal.place_pose.pose.position.x, goal.place_pose.pose.position.y = spot
                        goal.place_pose.pose.position.z = 0.045
                        goal.place_pose.pose.orientation.w = 1.0
                feedback = []
                sent = time.monotonic()
                handle = cell.wait(cell.client.send_goal_async(
                    goal, feedback_callback=lambda f, into=feedback: into.append(f.feedback.phase)), 30.0)
                if handle is None or not handle.accepted:
                    problems.append(f"step {index} ({kind}): {'no goal response' if handle is None else 'rejected'}")
                    continue
                result = handle.get_result_async()
                phase = PHASES[stats["cancel"] % len(PHASES)]   # counted before: each cancel the next phase
                stats[kind] += 1
                if kind in ("cancel", "restart"):
                    target = "descend" if kind == "restart" else phase
                    deadline = time.monotonic() + args.result_timeout
                    while not result.done() and target not in feedback and time.monotonic() < deadline:
                        time.sleep(0.02)
                    if kind == "cancel" and not result.done():
                        answer = cell.wait(handle.cancel_goal_async(), 10.0)
                        stats["cancel answered"] += answer is not None
                    if kind == "restart" and not result.done():
                        driver = bringup.processes["fake_panda_driver"]
                        argv = driver.argv
                        driver.popen.kill()
                        driver.popen.wait()
                        bringup.processes["fake_panda_driver"] = NodeProcess("fake_panda_driver", argv, out=log)
                        restarted = True
                response = cell.wait(result, args.result_timeout)
                answered = time.monotonic()
                if response is None:
                    problems.append(f"step {index} ({kind}): no result after {args.result_timeout:.0f} s")
                    continue
                stats["results"] += 1
                status = STATUS.get(response.status, str(response.status))
                outcomes[f"{kind}: {status}"] += 1
                if kind == "restart":   # the new driver must come up before anything can be watched
                    cell.joints.clear()
                    while not cell.joints and time.monotonic() - answered < 120:
                        time.sleep(0.2)
                    cell.client.wait_for_server(timeout_sec=60.0)
                    print(f"bench_safety_soak: driver restarted mid-{target}: the goal {status} "
                          f"({response.result.failure_reason[:100]}); joint states again after "
                          f"{time.monotonic() - answered:.1f} s", flush=True)
                    continue
                speed = cell.max_speed_after(answered, args.watch_s)
                if speed > REST_RADPS:
                    moved_after.append((index, kind, status, speed))
                if index in (0,) or time.monotonic() - started >= args.duration:
                    memory.append(rss_mb(executor_pid))
                measured = (f"; E {response.result.measured_youngs_modulus_pa:.2e} Pa"
                            if response.result.stiffness_measured else "")
                print(f"bench_safety_soak: step {index} {kind}{' at ' + phase if kind == 'cancel' else ''}"
                      f"{' (measure only)' if goal.measure_only else ''}: "
                      f"{status} in {answered - sent:.1f} s ({response.result.failure_reason[:80]}{measured}); arm "
                      f"{response.result.arm_state}; max joint speed {speed:.4f} rad/s in the {args.watch_s} s "
                      f"after (t = {time.monotonic() - started:.0f} s)", flush=True)
            memory.append(rss_mb(executor_pid))
        finally:
            cell.close()
        codes = bringup.stop()
    wall = time.monotonic() - started
    grew = memory[-1] - memory[0] if len(memory) >= 2 else math.nan
    print(f"bench_safety_soak: {wall:.0f} s wall; steps {dict(stats)}; outcomes {dict(outcomes)}")
    print(f"bench_safety_soak: arm motion over {REST_RADPS} rad/s after a result: {len(moved_after)} "
          f"{moved_after[:5]}; executor RSS {memory[0]:.0f} -> {memory[-1]:.0f} MB ({grew:+.1f} MB); "
          f"exit codes {codes}")
    for problem in problems:
        print(f"bench_safety_soak: PROBLEM: {problem}")
    ok = (not problems and not moved_after and not grew > MEMORY_LIMIT_MB and codes.get("executor_node") == 0)
    print(f"bench_safety_soak: {'OK' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
