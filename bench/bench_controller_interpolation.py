"""How far a joint_trajectory_controller's interpolation between our trajectory points exceeds what was checked.

The executor checks every point it sends (position, velocity, acceleration, jerk from the samples;
control/trajectories.check_trajectory). ros2_control's joint_trajectory_controller, given points with
positions, velocities and accelerations, interpolates each segment with a quintic that matches all three at
both ends; between the points that quintic can accelerate and jerk harder than the Ruckig profile the points
were sampled from. This samples the executor's own motions (a joint motion from the ready pose to a pre-grasp,
a straight descent and a straight lift, at limits_scale 1.0), fits the controller's quintic to every segment,
evaluates it on a fine grid, and prints, per sample period, the peak acceleration and jerk of the
interpolation as a multiple of the arm's limit (datasheet x limits_scale). A ratio above 1 / limits_scale means
the controller would command more than the datasheet allows at that scale.

    .venv/bin/python bench/bench_controller_interpolation.py [--dt 0.02 0.01 0.005]
"""
import argparse

import numpy as np

from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.trajectories import panda_limits, plan_joint_motion, plan_line

GRID = 50   # evaluation points per segment


def quintic_peaks(t0, t1, p0, v0, a0, p1, v1, a1) -> tuple[np.ndarray, np.ndarray]:
    """Peak |acceleration| and |jerk| per joint of the quintic matching (p, v, a) at both ends of [t0, t1]."""
    h = t1 - t0
    c2 = a0 / 2.0
    # the remaining three coefficients from the end conditions (the standard closed form)
    c3 = (20 * (p1 - p0) - (8 * v1 + 12 * v0) * h - (3 * a0 - a1) * h * h) / (2 * h ** 3)
    c4 = (30 * (p0 - p1) + (14 * v1 + 16 * v0) * h + (3 * a0 - 2 * a1) * h * h) / (2 * h ** 4)
    c5 = (12 * (p1 - p0) - (6 * v1 + 6 * v0) * h - (a0 - a1) * h * h) / (2 * h ** 5)
    s = np.linspace(0.0, h, GRID)[:, None]
    acc = 2 * c2 + 6 * c3 * s + 12 * c4 * s ** 2 + 20 * c5 * s ** 3
    jerk = 6 * c3 + 24 * c4 * s + 60 * c5 * s ** 2
    return np.abs(acc).max(axis=0), np.abs(jerk).max(axis=0)


def motions(kin, limits, dt_s):
    pregrasp = kin.top_down_ik([0.5, 0.05, 0.08], 0.4, kin.q_ready_rad)[0].q_rad
    joint = plan_joint_motion(kin.q_ready_rad, pregrasp, limits, dt_s=dt_s)
    descent = plan_line(kin, pregrasp, [0.0, 0.0, -0.05], limits, 0.03, dt_s)
    lift = plan_line(kin, descent.final_q_rad, [0.0, 0.0, 0.15], limits, 0.1, dt_s)
    return {"joint motion": joint, "descent": descent, "lift": lift}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dt", type=float, nargs="+", default=[0.02, 0.01, 0.005],
                    help="sample periods to compare (s; the executor's trajectory_sample_dt_s is 0.02)")
    ap.add_argument("--scale", type=float, default=1.0, help="limits_scale the motions are planned at")
    args = ap.parse_args(argv)
    kin, limits = PandaKinematics(), panda_limits(args.scale)
    print(f"limits_scale {args.scale}: peak of the controller's quintic interpolation / the scaled limit")
    print("| dt (s) | motion | acceleration | jerk | sampled acceleration | sampled jerk |")
    print("|---|---|---|---|---|---|")
    for dt_s in args.dt:
        for name, t in motions(kin, limits, dt_s).items():
            acc, jerk = np.zeros(7), np.zeros(7)
            for k in range(len(t.times_s) - 1):
                a, j = quintic_peaks(t.times_s[k], t.times_s[k + 1], t.q_rad[k], t.qd_radps[k], t.qdd_radps2[k],
                                     t.q_rad[k + 1], t.qd_radps[k + 1], t.qdd_radps2[k + 1])
                acc, jerk = np.maximum(acc, a), np.maximum(jerk, j)
            sampled_acc = np.abs(t.qdd_radps2).max(axis=0)
            sampled_jerk = (np.abs(np.diff(t.qdd_radps2, axis=0)) / np.diff(t.times_s)[:, None]).max(axis=0)
            print(f"| {dt_s:g} | {name} | {np.max(acc / limits.qdd_max_radps2):.2f} | "
                  f"{np.max(jerk / limits.qddd_max_radps3):.2f} | {np.max(sampled_acc / limits.qdd_max_radps2):.2f} | "
                  f"{np.max(sampled_jerk / limits.qddd_max_radps3):.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
