"""Which top-down grasps near the robot's base the pick sequence can make with straight lines.

Random grasps (seeded) between the workspace's near edge and 0.45 m, 1-5 cm above the table, any yaw; for
each, what the executor plans before it moves (control/pick_place.py, _check_straight_lines): the pre-grasp
by IK from the ready pose, the straight descent at the configured descent speed, then the straight 15 cm
lift at the line speed, each checked against every joint limit and the table. Prints how many plan, and
why the others are refused, per band of distance from the base; and for each refused grasp whether the same
point grasped at another yaw (8 evenly spaced) plans, which is what the executor's ranked alternatives
(plan_grasp_alternatives) can find when the network's next grasps on the object differ in angle.

    .venv/bin/python bench/bench_reach_near_base.py [--grasps 200] [--seed 1]
"""
import argparse
import collections
import time

import numpy as np

from defgg_ros.constants import PREGRASP_HEIGHT_M
from defgg_ros.control.kinematics import KinematicsError, PandaKinematics
from defgg_ros.control.sequence_types import SequenceConfig
from defgg_ros.control.trajectories import check_trajectory, panda_limits, plan_line
from defgg_ros.perception.tabletop import WorkspaceBox

BANDS_M = ((0.22, 0.30), (0.30, 0.38), (0.38, 0.45))
OTHER_YAWS = 8


def outcome(kin, limits, cfg, grasp) -> str:
    x, y, z, yaw = grasp
    try:
        pregrasp, _ = kin.top_down_ik([x, y, z + PREGRASP_HEIGHT_M], yaw, kin.q_ready_rad)
    except KinematicsError:
        return "pre-grasp out of reach"
    line = "descent"
    try:
        descent = plan_line(kin, pregrasp.q_rad, [0.0, 0.0, -PREGRASP_HEIGHT_M], limits, cfg.descent_speed_mps)
        check_trajectory(descent, limits, kin, cfg.table_z_m)
        line = "lift"
        lift = plan_line(kin, descent.final_q_rad, [0.0, 0.0, cfg.lift_height_m], limits, cfg.line_speed_mps)
        check_trajectory(lift, limits, kin, cfg.table_z_m)
    except KinematicsError as error:
        reason = "leaves the reach" if "reachable workspace" in str(error) else \
            "near a singularity" if "singularity" in str(error) else "over a joint limit"
        return f"{line}: {reason}"
    return "plans"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grasps", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    limits, cfg, kin = panda_limits(), SequenceConfig(), PandaKinematics()
    near_x_m = WorkspaceBox().x_m[0]
    rng = np.random.default_rng(args.seed)
    counts = collections.defaultdict(collections.Counter)
    another_yaw = collections.Counter()     # per band: refused grasps that plan at another yaw
    start = time.process_time()
    for _ in range(args.grasps):
        grasp = (rng.uniform(near_x_m, BANDS_M[-1][1]), rng.uniform(-0.25, 0.25), rng.uniform(0.01, 0.05),
                 rng.uniform(-np.pi, np.pi))
        band = next(b for b in BANDS_M if grasp[0] < b[1])
        result = outcome(kin, limits, cfg, grasp)
        counts[band][result] += 1
        if result != "plans":
            yaws = grasp[3] + np.arange(1, OTHER_YAWS) * np.pi / OTHER_YAWS   # a half turn is the same grasp
            another = any(outcome(kin, limits, cfg, (*grasp[:3], yaw)) == "plans" for yaw in yaws)
            another_yaw[band] += another
    cpu_s = time.process_time() - start
    print(f"{args.grasps} grasps (seed {args.seed}), x from {near_x_m:.2f} m, 1-5 cm high; {cpu_s:.1f} CPU s")
    print("| x (m) | grasps | plans | refused: why | of the refused: another yaw plans |")
    print("|---|---|---|---|---|")
    for band in BANDS_M:
        c = counts[band]
        refused = {k: n for k, n in c.items() if k != "plans"}
        why = ", ".join(f"{k} {n}" for k, n in sorted(refused.items())) or "-"
        print(f"| {band[0]:.2f}-{band[1]:.2f} | {c.total()} | {c['plans']} | {why} | "
              f"{another_yaw[band]} of {sum(refused.values())} |")


if __name__ == "__main__":
    main()
