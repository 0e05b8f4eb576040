"""Which place poses near the robot's base the pick sequence refuses for its straight lowering or retreat.

Random place poses (seeded) at x 0.20-0.45 m, y -0.3..0.3 m, 1.2-6 cm above the table, any yaw, with one fixed
reachable grasp; for each, what PickPlaceSequence.plan_failure says before the arm moves (the place checks of
control/pick_place.py: workspace, IK of the approach and the place pose, then the straight lowering between
them and the retreat back up). Prints how many plan, and counts the refusals by reason: "straight lowering"
and "straight retreat" are the places IK reaches whose lines fail, which until 2026-11-28 were found out only
after the grasp, with the object held.

    .venv/bin/python bench/bench_place_lines.py [--places 150] [--seed 1]
"""
import argparse
import collections

import numpy as np

from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget, SequenceConfig

GRASP = GraspTarget(position_m=(0.5, 0.05, 0.05), yaw_rad=0.4, width_m=0.05, youngs_modulus_pa=2e9)


def reason(why: str) -> str:
    for key in ("straight lowering", "straight retreat", "place pose unreachable", "grasp outside"):
        if key in why:
            return key
    return why[:60] or "plans"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--places", type=int, default=150, help="random place poses (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=1, help="random seed (default: %(default)s)")
    args = ap.parse_args(argv)
    kin, cfg, rng = PandaKinematics(), SequenceConfig(), np.random.default_rng(args.seed)
    counts = collections.Counter()
    for _ in range(args.places):
        x, y, z, yaw = rng.uniform(0.2, 0.45), rng.uniform(-0.3, 0.3), rng.uniform(0.012, 0.06), rng.uniform(-3, 3)
        sequence = PickPlaceSequence(kin, cfg, GRASP, PlaceTarget(position_m=(x, y, z), yaw_rad=yaw))
        counts[reason(sequence.plan_failure(np.array(kin.q_ready_rad)))] += 1
    print(f"{args.places} random place poses (seed {args.seed}):")
    for key, n in counts.most_common():
        print(f"  {key}: {n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
