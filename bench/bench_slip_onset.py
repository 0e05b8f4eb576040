"""When does a held object start to slide, and when is it lost? One shake direction at a time.

Re-runs trials of a pilot or dataset folder under their recorded settings (the trial's own mesh, grasp and
protocol), and for a few shake directions logs, every check interval of the ramp, the commanded acceleration
and the object's displacement in the hand frame since the ramp began. Prints per trial and direction:
the friction limit mu * F_total / m, the acceleration at slip onset (displacement > --slip-mm) and at loss
(the trial's loss rule), and the displacement at loss. If the held acceleration were friction, onset and
loss would coincide near the friction limit; a gap between them is the slide.

  .venv/bin/python bench/bench_slip_onset.py bench/pilots/a_defgraspsim --per-object 1 --moduli 2e4 2e9
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

DIRECTIONS = (0, 1, 2, 3)     # the first four of the interleaved 16 (spread over the sphere)


def pick_records(folder: Path, per_object: int, moduli) -> list:
    from defgg_ros.data.signal import read_trial_records

    chosen, counts = [], {}
    for r in sorted(read_trial_records(folder), key=lambda r: r["trial_id"]):
        key = (r["object_name"], r["youngs_modulus_pa"])
        if r["status"] == "ok" and r["youngs_modulus_pa"] in moduli and counts.get(key, 0) < per_object:
            counts[key] = counts.get(key, 0) + 1
            chosen.append(r)
    return chosen


SLIDES_MM = (5.0, 10.0, 20.0)   # also logged: the acceleration at which the object had slid this far


def ramp_log(record: dict, directions, slip_m: float) -> list:
    """[(direction, friction limit, onset accel, loss accel, displacement at loss mm, {slide mm: accel})] of
    one record (accelerations None when not reached before the loss or the ramp's end)."""
    from defgg_ros.sim import objects, trial, world
    from defgg_ros.sim.trial import TrialSettings, WorldGrasp, shake_directions

    settings = TrialSettings.from_record(dict(record["sim"]["settings"]))
    shape = objects.simulation_shape(objects.get_shape(record["object_name"]), record["youngs_modulus_pa"], None)
    spec = objects.ObjectSpec(shape, record["youngs_modulus_pa"])
    grasp = WorldGrasp(tuple(record["position_m"]), record["yaw_rad"], record["width_m"])
    client = world.connect()
    try:
        run = trial._Trial(client, spec, grasp, settings, (0.0, 0.0), 0.0)
        run.grasp_and_lift()
        mu_f_over_m = run.material["effective_friction"] * 2 * run.force_n / run.obj.mass_kg
        rows = []
        for k in directions:
            d = shake_directions(settings.motion.shake_directions)[k]
            run.restore()
            start = run.object_in_hand()
            onset, lost_at, moved_mm, slid = None, None, None, {}
            n = run.seconds(settings.motion.shake_ramp_time_s)
            for step in range(0, n, run.check_steps):
                a = settings.evaluation.shake_limit_mps2 * min(1.0, (step + run.check_steps) / n)
                run.world.set_gravity(run.gravity - a * d)
                run.step(run.check_steps)
                moved = float(np.linalg.norm(run.object_in_hand() - start))
                if onset is None and moved > slip_m:
                    onset = a
                for mm in SLIDES_MM:
                    if mm not in slid and moved > mm * 1e-3:
                        slid[mm] = a
                if not run.held():
                    lost_at, moved_mm = a, moved * 1e3
                    break
            rows.append((k, mu_f_over_m, onset, lost_at, moved_mm, slid))
        return rows
    finally:
        import pybullet as p

        p.disconnect(client)


def _fmt(x, spec=".1f") -> str:
    return "-" if x is None else format(x, spec)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder", type=Path)
    ap.add_argument("--per-object", type=int, default=1, help="trials per object and modulus")
    ap.add_argument("--moduli", nargs="+", type=float, default=[2e4, 2e9])
    ap.add_argument("--slip-mm", type=float, default=1.0, help="displacement that counts as slip onset")
    args = ap.parse_args(argv)
    records = pick_records(args.folder, args.per_object, set(args.moduli))
    if not records:
        raise SystemExit(f"{args.folder}: no held trial at {args.moduli}")
    print(f"{args.folder}: accelerations in m/s^2 (ramp to the limit), slip onset = moved > {args.slip_mm} mm")
    slides = " | ".join(f"slid {mm:g} mm" for mm in SLIDES_MM)
    print(f"| trial | dir | friction limit 2 mu F / m | slip onset | {slides} | lost at (held) | moved at loss (mm) |")
    print("|---|---|---|---|" + "---|" * len(SLIDES_MM) + "---|---|")
    gaps = []
    for r in records:
        for k, limit, onset, lost, moved, slid in ramp_log(r, DIRECTIONS, args.slip_mm * 1e-3):
            at = " | ".join(_fmt(slid.get(mm)) for mm in SLIDES_MM)
            print(f"| {r['trial_id']} | {k} | {limit:.1f} | {_fmt(onset)} | {at} | {_fmt(lost)} | {_fmt(moved)} |")
            if onset is not None and lost is not None:
                gaps.append(lost - onset)
    if gaps:
        print(f"\nloss minus slip onset over {len(gaps)} lost directions: median {np.median(gaps):.1f} m/s^2, "
              f"range {min(gaps):.1f}-{max(gaps):.1f}")


if __name__ == "__main__":
    main()
