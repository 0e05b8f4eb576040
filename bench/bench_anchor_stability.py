"""A soft part anchored to a rigid one, at rest on the table: which moduli and time steps stay stable.

The multi-material mallet (`mallet_mm`: rigid 2e9 Pa handle, soft head of modulus E, the head's nodes on the
handle's face anchored to it; sim/objects.py) exploded at every grasp of the evaluations at E = 2e6 Pa
(results/sim_v4, results/sim_v5). This loads it alone on the table (no hand) and steps it for --seconds,
checked as a trial checks (RMS node speed over 5 ms above 30 m/s = exploded), for each head modulus and
time step given; "default" is the step the trials use for that modulus (sim/physics.time_step_for).

    .venv/bin/python bench/bench_anchor_stability.py
    .venv/bin/python bench/bench_anchor_stability.py --moduli 2e6 --steps default 1.25e-4 5e-5
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from defgg_ros.sim import objects, world  # noqa: E402
from defgg_ros.sim.trial import MAX_RMS_NODE_SPEED_MPS, rms_speed_mps  # noqa: E402

RIGID_PA = 2e9
CHECK_S = 0.005


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--object", default="mallet_mm", help="a two-part object of the library")
    p.add_argument("--moduli", nargs="+", type=float, default=[2e4, 2e5, 2e6], help="soft part's E (Pa)")
    p.add_argument("--steps", nargs="+", default=["default"], help="time steps (s), or 'default'")
    p.add_argument("--seconds", type=float, default=1.0, help="simulated time at rest")
    p.add_argument("--yaw", type=float, default=0.963, help="object yaw (rad; sim_v5's mallet view)")
    return p.parse_args(argv)


def at_rest(name: str, soft_pa: float, step, seconds: float, yaw_rad: float) -> dict:
    spec = objects.ObjectSpec(objects.get_shape(name), RIGID_PA, part_youngs_modulus_pa=soft_pa)
    client = world.connect()
    try:
        w = world.create_world(client, spec.part_moduli_pa(), None if step == "default" else float(step))
        obj = objects.load_object(client, spec, (0.0, 0.0), yaw_rad)
        n = max(1, round(CHECK_S / w.time_step_s))
        last, t0, t = obj.tracked_points(), time.process_time(), 0.0
        while t < seconds:
            for _ in range(n):
                w.step()
            t += n * w.time_step_s
            points = obj.tracked_points()
            speed = rms_speed_mps(last, points, n * w.time_step_s)
            last = points
            if speed > MAX_RMS_NODE_SPEED_MPS:
                return {"dt": w.time_step_s, "outcome": f"exploded at {t:.3f} s ({speed:.0f} m/s)",
                        "cpu_s": time.process_time() - t0}
        return {"dt": w.time_step_s, "outcome": f"at rest for {seconds:g} s (last {speed:.3f} m/s)",
                "cpu_s": time.process_time() - t0}
    finally:
        import pybullet as p

        p.disconnect(client)


def main(argv=None) -> int:
    args = parse_args(argv)
    print(f"{args.object}: rigid part {RIGID_PA:.0e} Pa, soft part anchored to it, on the table, no hand")
    print("| soft part E (Pa) | time step (s) | outcome | CPU s |")
    print("|---|---|---|---|")
    for soft_pa in args.moduli:
        for step in args.steps:
            r = at_rest(args.object, soft_pa, step, args.seconds, args.yaw)
            print(f"| {soft_pa:.0e} | {r['dt']:g}{' (default)' if step == 'default' else ''} | {r['outcome']} | "
                  f"{r['cpu_s']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
