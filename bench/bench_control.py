"""Motion planning costs: IK per solve, Ruckig/line planning per segment (median, p99).

Run: .venv/bin/python bench/bench_control.py [--grasps 200] [--seed 0]
Each grasp is a random top-down grasp in the workspace the camera sees; for
each one the bench times (wall clock, one thread):
- IK of the pre-grasp (top_down_ik: both symmetric yaws, from the ready pose),
- a single 6-D IK solve from the ready pose (kin.ik),
- the Ruckig joint motion ready -> pre-grasp (calculate + sampling),
- the straight-line descent (dense IK + 1-D Ruckig + per-sample IK),
- a jerk-limited stop from mid-motion,
- the limit/table check of the joint motion.
"""
import argparse
import time

import numpy as np
from tqdm import tqdm

from defgg_ros.constants import PREGRASP_HEIGHT_M
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.poses import top_down_pose
from defgg_ros.control.trajectories import check_trajectory, panda_limits, plan_joint_motion, plan_line, plan_stop

# The camera's footprint on the table (0.40 m high, fx 385 px over 640x480).
WORKSPACE_X_M = (0.35, 0.65)
WORKSPACE_Y_M = (-0.2, 0.2)
WORKSPACE_Z_M = (0.01, 0.08)


def timed(fn, *args):
    start = time.perf_counter()
    value = fn(*args)
    return value, time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grasps", type=int, default=200, help="random grasps to plan (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    args = parser.parse_args(argv)
    try:
        import torch
        torch.set_num_threads(1)
    except ImportError:
        pass
    kin, limits = PandaKinematics(seed=args.seed), panda_limits()
    rng = np.random.default_rng(args.seed)
    times = {k: [] for k in ("top_down_ik", "ik_single", "joint_motion", "line_descent", "stop", "check")}
    points = []
    for _ in tqdm(range(args.grasps), desc="grasps"):
        xyz = [rng.uniform(*WORKSPACE_X_M), rng.uniform(*WORKSPACE_Y_M), rng.uniform(*WORKSPACE_Z_M)]
        yaw = rng.uniform(-np.pi, np.pi)
        pregrasp_xyz = np.add(xyz, [0.0, 0.0, PREGRASP_HEIGHT_M])
        (solution, used_yaw), dt = timed(kin.top_down_ik, pregrasp_xyz, yaw, kin.q_ready_rad)
        times["top_down_ik"].append(dt)
        times["ik_single"].append(timed(kin.ik, top_down_pose(pregrasp_xyz, used_yaw), kin.q_ready_rad)[1])
        motion, dt = timed(plan_joint_motion, kin.q_ready_rad, solution.q_rad, limits)
        times["joint_motion"].append(dt)
        points.append(len(motion.times_s))
        times["line_descent"].append(timed(plan_line, kin, solution.q_rad, [0, 0, -PREGRASP_HEIGHT_M], limits)[1])
        q, qd, qdd = motion.state_at(0.5 * motion.duration_s)
        times["stop"].append(timed(plan_stop, q, qd, qdd, limits)[1])
        times["check"].append(timed(check_trajectory, motion, limits, kin, 0.0)[1])
    print(f"\nbench_control: {args.grasps} random top-down grasps, seed {args.seed}, wall clock per call")
    print(f"{'what':<14} {'median ms':>10} {'p99 ms':>10} {'max ms':>10}")
    for name, values in times.items():
        ms = 1000.0 * np.array(values)
        print(f"{name:<14} {np.median(ms):>10.3f} {np.percentile(ms, 99):>10.3f} {ms.max():>10.3f}")
    print(f"joint motion: median {np.median(points):.0f} sampled points per trajectory")


if __name__ == "__main__":
    main()
