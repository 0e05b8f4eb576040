"""Where a soft grasp trial's CPU goes, and which engine settings change the FEM step cost.

1. One labelled trial (the generator's protocol) of the first candidate grasp on --object at
   --modulus, under cProfile: CPU seconds in total and inside pybullet.stepSimulation.
2. The same grasp lifted, then --steps steps timed (CPU) with the engine as the generator runs it,
   with numSolverIterations 10 and 200, and with the object's collisions with the table off.
   The object's centroid after the steps is printed too: a setting that changes it changes physics.

    PYTHONPATH=bench .venv/bin/python bench/archive/bench_fem_step.py [--object box_small] [--modulus 2e4] [--steps 400]
"""
import argparse
import cProfile
import pstats
import time

import pybullet as p
from bench_datagen import sample_jobs

from defgg_ros.sim import objects, world
from defgg_ros.sim.trial import TrialSettings, _Trial, run_grasp_trial

VARIANTS = ("generator", "iterations_10", "iterations_200", "no_table_contact")


def profile_trial(client, spec, grasp) -> tuple:
    profiler = cProfile.Profile()
    profiler.enable()
    outcome = run_grasp_trial(spec, grasp, ("shake",), TrialSettings.fast(), client=client)
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    in_step = sum(v[3] for k, v in stats.items() if k[2] == "<built-in method pybullet.stepSimulation>")
    return outcome, in_step


def step_cost(client, spec, grasp, variant: str, steps: int) -> tuple:
    trial = _Trial(client, spec, grasp, TrialSettings.fast(), (0.0, 0.0), 0.0)
    if variant.startswith("iterations_"):
        p.setPhysicsEngineParameter(numSolverIterations=int(variant.split("_")[1]), physicsClientId=client)
    trial.grasp_and_lift()
    if variant == "no_table_contact":
        for body in trial.obj.body_ids:
            p.setCollisionFilterPair(trial.world.table_id, body, -1, -1, 0, physicsClientId=client)
    trial.restore()
    start = time.process_time()
    trial.step(steps)
    per_step_s = (time.process_time() - start) / steps
    return per_step_s, trial.obj.centroid_m()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--object", default="box_small")
    parser.add_argument("--modulus", type=float, default=2e4, help="Young's modulus (Pa), a soft one")
    parser.add_argument("--steps", type=int, default=400)
    args = parser.parse_args(argv)
    _, e, _, grasp = sample_jobs([args.object], [args.modulus], 1, 0)[0]
    spec = objects.ObjectSpec(objects.get_shape(args.object), e)
    client = world.connect()
    outcome, in_step_s = profile_trial(client, spec, grasp)
    print(f"{args.object} at {e:.0e} Pa, one trial ({outcome.status}, {outcome.sim_steps} steps): "
          f"{outcome.cpu_s:.1f} s CPU, {in_step_s:.1f} s of it in stepSimulation "
          f"({100 * in_step_s / outcome.cpu_s:.0f} %)")
    print(f"{'variant':18s} {'ms CPU/step':>12s}  object centroid after {args.steps} steps (m)")
    for variant in VARIANTS:
        per_step_s, centroid = step_cost(client, spec, grasp, variant, args.steps)
        print(f"{variant:18s} {per_step_s * 1e3:12.2f}  {centroid.round(5).tolist()}")


if __name__ == "__main__":
    main()
