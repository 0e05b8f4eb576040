"""How often the executor's ranked alternatives rescue a pick the arm cannot make, with the network choosing.

bench_reach_near_base.py measures the kinematics alone (any yaw at a point). Here the grasps are the shipped
Def-GG-CNN's: one random object (box, upright or lying cylinder; 2-10 cm; a modulus of the paper's four) per
scene, at x 0.22-0.30 m (where straight lifts run out of reach) or, as a control, 0.30-0.45 m, seen from the sim
cell's camera pose (0.40 m above (0.5, 0)) through the synthetic D435 model (noise, shadows, the left invalid
band; perception/tabletop_scenes.py); the tabletop planner ranks 5 grasps (what the executor asks
for with plan_grasp_alternatives 5), and each is put to PickPlaceSequence.plan_failure from the observation
pose with the executor's default parameters, as the executor does before it moves. Prints, per band: scenes,
with a grasp, best grasp plans, best refused but a lower rank plans (which ranks), nothing plans; and the
refusal reasons of the best grasps, why the planner found none, and how much of each object the sensor model
hides has depth.

    .venv/bin/python bench/bench_near_base_alternatives.py [--scenes 100] [--seed 3]
"""
import argparse
import collections
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.control.pick_place import PickPlaceSequence  # noqa: E402
from defgg_ros.control.poses import top_down_yaw  # noqa: E402
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget  # noqa: E402
from defgg_ros.model.inference import GraspPredictor  # noqa: E402
from defgg_ros.nodes.executor_node import ExecutorNode  # noqa: E402
from defgg_ros.perception import tabletop_scenes as ts  # noqa: E402
from defgg_ros.planning.tabletop_grasps import base_T_grasp  # noqa: E402
from defgg_ros.planning.tabletop_planner import TabletopPlanner  # noqa: E402
from defgg_ros.ros.parameters import defaults  # noqa: E402

BANDS_M = ((0.22, 0.30), (0.30, 0.45))
MODULI_PA = (2e4, 2e5, 2e6, 2e9)
ALTERNATIVES = 5                      # the executor's plan_grasp_alternatives default

# sim_bringup/scenes/*.yaml base_T_camera: 0.40 m above (0.5, 0), a half turn about x (image u along base x)
CAMERA_BASE_T_CAMERA = np.array([[1.0, 0.0, 0.0, 0.5], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.40],
                                 [0.0, 0.0, 0.0, 1.0]])


def random_object(rng, x_range_m):
    """One graspable object at a random place and yaw in the band."""
    xy = (rng.uniform(*x_range_m), rng.uniform(-0.2, 0.2))
    yaw = rng.uniform(-np.pi, np.pi)
    kind = rng.integers(3)
    if kind == 0:
        return ts.Box(xy, (rng.uniform(0.03, 0.10), rng.uniform(0.03, 0.07), rng.uniform(0.02, 0.06)), yaw_rad=yaw)
    if kind == 1:
        return ts.Cylinder(xy, rng.uniform(0.02, 0.035), rng.uniform(0.03, 0.10))
    return ts.LyingCylinder(xy, rng.uniform(0.015, 0.035), rng.uniform(0.08, 0.18), yaw_rad=yaw)


def ranked_outcomes(planner, kin, cfg, place, q_obs, scene, modulus_pa, seed,
                    noise=True) -> tuple[str, list, float]:
    """(why the planner found no grasp, or ""; plan_failure of each ranked grasp ("" = it plans), best first;
    the share of the object's pixels with a depth return in the frame)."""
    frame = ts.render(scene, seed=seed, noise=noise)
    share = returned_share(frame)
    moduli = np.where(frame.labels == 1, modulus_pa, 0.0).astype(np.float32)
    try:
        grasps = planner.plan(frame.depth_m, frame.camera_k, frame.base_T_camera, top_k=ALTERNATIVES,
                              youngs_modulus_pa=moduli).grasps
    except ValueError as error:
        return str(error), [], share
    out = []
    for grasp in grasps:
        target = GraspTarget(tuple(grasp.position_base_m), top_down_yaw(base_T_grasp(grasp)), grasp.width_m,
                             grasp.youngs_modulus_pa)
        out.append(PickPlaceSequence(kin, cfg, target, place).plan_failure(q_obs))
    return "", out, share


def returned_share(frame) -> float:
    """Share of the object's pixels that have a depth return in the frame."""
    on_object = frame.labels == 1
    return float(np.isfinite(frame.depth_m[on_object]).mean()) if on_object.any() else 0.0


def refusal_kind(message: str) -> str:
    """A refusal message without its numbers, e.g. 'straight lift: leaves the reachable workspace'."""
    line = "lift" if "straight lift" in message else "descent" if "straight descent" in message else "other"
    why = "leaves the reachable workspace" if "reachable workspace" in message else \
        "near a singularity or joint limit" if "singularity" in message else message.split(":")[0]
    return f"straight {line}: {why}" if line != "other" else why


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=100, help="scenes per band")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--model", default=str(ROOT / "models" / "defgg_cnn.pt"))
    args = parser.parse_args()
    p = defaults("executor_node")
    cfg, kin = ExecutorNode._sequence_config(p), PandaKinematics()
    place, q_obs = PlaceTarget(tuple(p["place_position_m"]), None), np.asarray(p["observation_q_rad"])
    planner = TabletopPlanner(GraspPredictor.from_checkpoint(args.model, num_threads=1))
    camera = CAMERA_BASE_T_CAMERA
    rng = np.random.default_rng(args.seed)
    start = time.process_time()
    print(f"{args.scenes} scenes per band (seed {args.seed}), {ALTERNATIVES} ranked grasps each, "
          f"model {Path(args.model).name}")
    print("| x (m) | scenes | with a grasp | best plans | best refused, a lower rank plans (ranks) | none plans |")
    print("|---|---|---|---|---|---|")
    reasons, no_grasp_reasons, sensor_misses = collections.Counter(), collections.Counter(), []
    for band in BANDS_M:
        counts, rescue_ranks = collections.Counter(), collections.Counter()
        for i in range(args.scenes):
            scene = ts.TabletopScene((random_object(rng, band),), camera)
            modulus_pa = MODULI_PA[i % 4]
            no_grasp, outcomes, share = ranked_outcomes(planner, kin, cfg, place, q_obs, scene, modulus_pa, seed=i)
            counts["scenes"] += 1
            if no_grasp:
                # Does the sensor model decide (the D4xx's left invalid band cuts objects near the base)?
                clean, _, _ = ranked_outcomes(planner, kin, cfg, place, q_obs, scene, modulus_pa, i, False)
                why = no_grasp.split(":")[0].split("(")[0].strip()
                no_grasp_reasons[f"x {band[0]:.2f}-{band[1]:.2f}: {why}; "
                                 f"without sensor noise: {'the same' if clean else 'a grasp'}"] += 1
                if not clean:
                    sensor_misses.append(share)
                continue
            counts["with a grasp"] += 1
            if not outcomes[0]:
                counts["best plans"] += 1
                continue
            reasons[refusal_kind(outcomes[0])] += 1
            rank = next((r for r, failure in enumerate(outcomes, start=1) if not failure), None)
            counts["rescued" if rank else "none plans"] += 1
            if rank:
                rescue_ranks[rank] += 1
        ranks = ", ".join(f"rank {r}: {n}" for r, n in sorted(rescue_ranks.items())) or "-"
        print(f"| {band[0]:.2f}-{band[1]:.2f} | {counts['scenes']} | {counts['with a grasp']} | "
              f"{counts['best plans']} | {counts['rescued']} ({ranks}) | {counts['none plans']} |")
    print("Why the planner found no grasp:")
    for reason, n in no_grasp_reasons.most_common():
        print(f"  {n} x {reason}")
    if sensor_misses:
        print(f"Objects only the sensor model hides: {len(sensor_misses)}; share of the object's pixels with a depth "
              f"return: median {np.median(sensor_misses):.0%}, range {min(sensor_misses):.0%}-{max(sensor_misses):.0%}")
    print("Why the best grasps were refused:")
    for reason, n in reasons.most_common():
        print(f"  {n} x {reason}")
    print(f"{time.process_time() - start:.1f} CPU s")


if __name__ == "__main__":
    main()
