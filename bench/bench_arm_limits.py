"""What the FR3's limits cost a pick: motion time and refusals with joint_limits panda vs fr3.

Run: .venv/bin/python bench/bench_arm_limits.py [--grasps 100] [--seed 0] [--limits-scale 0.4]
For random top-down grasps in the camera's footprint (as bench_control.py), each arm model plans the pick's
motions from the ready pose with the executor's planners at --limits-scale: the joint motion to the pre-grasp,
the 25 mm descent, the 15 cm lift, the joint motion to a place pose over the bin. Prints, per arm model, how
many grasps plan, the median and 90th percentile of the summed motion time (grasps both plan), and the
refusal reasons, and for the FR3 how much of its position-dependent velocity bound (constants.FR3_VELOCITY_ENVELOPE,
unscaled: where the controller aborts) the motions use at most: above 1, the executor's check refuses the motion.
Also how close the planned motions come to a joint's position limit: on franka's controller gains the arm lags and
overshoots its command by up to ~15 mrad (bench_arm_tracking.py), so a plan ending nearer than that can take the
joint past its limit (docs/franka_contract.md, "How the arm follows it").
Kinematics only (no physics): what the limits change, not what the gripper or object does.
"""
import argparse
import collections
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.constants import PREGRASP_HEIGHT_M  # noqa: E402
from defgg_ros.control.kinematics import KinematicsError, PandaKinematics  # noqa: E402
from defgg_ros.control.trajectories import (  # noqa: E402
    arm_limits,
    envelope_velocity_bounds,
    plan_joint_motion,
    plan_line,
)

WORKSPACE_X_M = (0.35, 0.65)     # the camera's footprint on the table (bench_control.py)
WORKSPACE_Y_M = (-0.2, 0.2)
WORKSPACE_Z_M = (0.01, 0.08)
PLACE_XYZ_M = (0.35, -0.45, 0.12)   # the demo bin's centre, the executor's default release height
LIFT_M = 0.15


def pick_motions(kin: PandaKinematics, limits, xyz, yaw) -> list:
    """The pick's motions (KinematicsError when one cannot be planned)."""
    pregrasp, used_yaw = kin.top_down_ik(np.add(xyz, [0.0, 0.0, PREGRASP_HEIGHT_M]), yaw, kin.q_ready_rad)
    approach = plan_joint_motion(kin.q_ready_rad, pregrasp.q_rad, limits)
    descent = plan_line(kin, pregrasp.q_rad, [0.0, 0.0, -PREGRASP_HEIGHT_M], limits)
    lift = plan_line(kin, descent.final_q_rad, [0.0, 0.0, LIFT_M], limits, max_speed_mps=0.1)
    place, _ = kin.top_down_ik(PLACE_XYZ_M, used_yaw, lift.final_q_rad)
    transfer = plan_joint_motion(lift.final_q_rad, place.q_rad, limits)
    return [approach, descent, lift, transfer]


def envelope_use(motions, limits) -> float:
    """Largest |velocity| / position-dependent bound over the motions' samples (0 without such a bound)."""
    if limits.velocity_envelope is None:
        return 0.0
    use = 0.0
    for m in motions:
        lower, upper = envelope_velocity_bounds(limits.velocity_envelope, m.q_rad)
        bound = np.where(m.qd_radps >= 0, upper, -lower)
        moving = np.abs(m.qd_radps) > 1e-9
        if np.any(moving & (bound <= 0)):
            return np.inf
        use = max(use, float(np.max(np.abs(m.qd_radps)[moving] / bound[moving], initial=0.0)))
    return use


OVERSHOOT_RAD = 0.015   # franka_jtc: a stop's end 14.5 mrad off its command, a transfer's 8.7 (bench_arm_tracking.py)


def limit_clearance_rad(motions, limits) -> float:
    """The smallest distance of any sample of the motions from a joint's position limit (rad)."""
    return min(float(np.min(np.minimum(m.q_rad - limits.q_min_rad, limits.q_max_rad - m.q_rad))) for m in motions)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grasps", type=int, default=100, help="random grasps (default 100)")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument("--limits-scale", type=float, default=0.4, help="the executor's limits_scale (default 0.4)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    grasps = [([rng.uniform(*WORKSPACE_X_M), rng.uniform(*WORKSPACE_Y_M), rng.uniform(*WORKSPACE_Z_M)],
               rng.uniform(-np.pi, np.pi)) for _ in range(args.grasps)]
    durations, refusals, uses, clearances = {}, {}, [], {}
    for arm in ("panda", "fr3"):
        kin, limits = PandaKinematics(seed=args.seed, arm=arm), arm_limits(arm, args.limits_scale)
        durations[arm], refusals[arm], clearances[arm] = [], collections.Counter(), []
        for xyz, yaw in grasps:
            try:
                motions = pick_motions(kin, limits, xyz, yaw)
                durations[arm].append(sum(m.duration_s for m in motions))
                clearances[arm].append(limit_clearance_rad(motions, limits))
                if arm == "fr3":
                    uses.append(envelope_use(motions, limits))
            except (KinematicsError, ValueError) as error:
                durations[arm].append(np.nan)
                refusals[arm][str(error).split(":")[0][:70]] += 1
    both = ~np.isnan(durations["panda"]) & ~np.isnan(durations["fr3"])
    print(f"bench_arm_limits: {args.grasps} random top-down grasps, seed {args.seed}, limits_scale {args.limits_scale}")
    print(f"{'arm':<6} {'plan':>6} {'median s':>9} {'p90 s':>7}   (motion time of the {both.sum()} grasps both plan)")
    for arm in ("panda", "fr3"):
        d = np.array(durations[arm])[both]
        print(f"{arm:<6} {np.isfinite(durations[arm]).sum():>6} {np.median(d):>9.2f} {np.percentile(d, 90):>7.2f}")
    ratio = np.array(durations["fr3"])[both] / np.array(durations["panda"])[both]
    print(f"fr3 / panda per grasp: median {np.median(ratio):.3f}, min {ratio.min():.3f}, max {ratio.max():.3f}")
    uses = np.array(uses)
    print(f"fr3 position-dependent velocity bound, most used per grasp: median {np.median(uses):.3f}, "
          f"max {uses.max():.3f}; over it (refused): {(uses > 1 + 1e-6).sum()} of {len(uses)}")
    for arm in ("panda", "fr3"):
        c = np.array(clearances[arm]) * 1e3
        print(f"{arm} closest to a joint's position limit per grasp (mrad): median {np.median(c):.0f}, "
              f"min {c.min():.1f}; within {OVERSHOOT_RAD * 1e3:.0f} mrad: {(c < OVERSHOOT_RAD * 1e3).sum()} of "
              f"{len(c)}")
    for arm in ("panda", "fr3"):
        for reason, n in refusals[arm].most_common():
            print(f"refused ({arm}): {n} x {reason}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
