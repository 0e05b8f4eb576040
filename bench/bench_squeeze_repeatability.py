"""How repeatable the cell's squeeze estimate is when the same object is squeezed again in place (issue 49 item 4:
"repeatable to 20 %").

  .venv/bin/python bench/bench_squeeze_repeatability.py [--times 3] [--objects NAME=E_PA ...] [--yaw 0.0]

The jig of bench_squeeze_stiffness.py (the arm set at a top-down grasp at half the object's height), but one jig
per object: the squeeze sequence (squeeze.GENTLE_FORCES_N, then FIRM_FORCES_N while unresolved) runs --times
times, the hand opening fully (0.08 m at 0.05 m/s) and the object resting 0.3 s between them. So the grasp, pose
and contacts are the same; what differs is what the previous squeeze left (the object settled, shifted or turned
between the pads). Over the cell's picks, each with its own pose and grasp, docs/squeeze.md has the spread too
(the cell report's "spread" column): that is reproducibility over grasps, this is repeatability.

Each estimate is the law the executor uses (the "section" column of bench_squeeze_stiffness.py: the perceived
contacts' law, the section's model where a pad is not flat). Spread: max / min of an object's estimates read as
numbers (the item's 20 % is <= 1.2). Every object's squeezes are one JSON line of --readings, reused on a rerun.
Default objects: the cell experiment's FEM objects at their moduli (evaluation objects: measured, nothing chosen).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bench_squeeze_stiffness as jigs  # noqa: E402

from defgg_ros.evaluation.cell_experiment import OBJECTS  # noqa: E402
from defgg_ros.squeeze import SqueezeError, SqueezeReading  # noqa: E402

OPEN_WIDTH_M, OPEN_SPEED_MPS, REST_S = 0.08, 0.05, 0.3
CELL_FEM_OBJECTS = tuple(f"{o.name}={o.youngs_modulus_pa:g}" for o in OBJECTS if o.youngs_modulus_pa < 1e7)


def squeezed_in_place(spec, times: int) -> list:
    """`times` squeezes of one object in one jig, the hand opened between them."""
    out = []
    with jigs.jig(spec) as cell:
        for i in range(times):
            if i:
                cell.gripper_move(OPEN_WIDTH_M, OPEN_SPEED_MPS)
                for _ in range(300):
                    if cell.advance(0.01):
                        break
                cell.advance(REST_S)
            out.append(jigs.squeeze_sequence(cell))
    return out


def cached(path: Path, name: str, modulus_pa: float, yaw_rad: float, times: int) -> list:
    key = {"object": name, "modulus_pa": modulus_pa, "yaw_rad": round(yaw_rad, 3), "times": times,
           "mesh": "shipped", "hand": "pressing"}
    if path.exists():
        for line in path.read_text().splitlines():
            row = json.loads(line)
            if all(row.get(k) == v for k, v in key.items()):
                return [[SqueezeReading(f, w) for f, w in zip(s["forces_n"], s["widths_m"])] for s in row["squeezes"]]
    squeezes = squeezed_in_place(jigs.scene_object(name, modulus_pa, yaw_rad), times)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as out:      # one whole line per object: a kill loses only the object in flight
        out.write(json.dumps({**key, "squeezes": [{"forces_n": [r.force_n for r in s],
                                                   "widths_m": [r.width_m for r in s]} for s in squeezes]}) + "\n")
    return squeezes


def parse_objects(specs) -> list:
    out = []
    for spec in specs:
        name, sep, value = spec.partition("=")
        try:
            modulus = float(value)
        except ValueError:
            modulus = math.nan
        if not sep or not name or not modulus > 0:
            raise SystemExit(f"--objects expects NAME=E_PA (e.g. common_ball=2e5), got {spec!r}")
        out.append((name, modulus))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--times", type=int, default=3, help="squeezes of each object in place (>= 2)")
    parser.add_argument("--objects", nargs="+", default=list(CELL_FEM_OBJECTS), metavar="NAME=E_PA")
    parser.add_argument("--yaw", type=float, default=0.0, help="the object's yaw (rad)")
    parser.add_argument("--readings", type=Path, default=ROOT / "results" / "squeeze" / "in_place.jsonl",
                        help="the squeezes' cache (JSON lines, one per object, appended)")
    args = parser.parse_args(argv)
    if args.times < 2:
        parser.error("--times must be >= 2: repeatability needs two squeezes at least")
    objects = parse_objects(args.objects)
    hand = jigs.calibration(jigs.ROOT / "results" / "squeeze" / "readings.jsonl")
    print(f"hand: {hand.describe()}")
    print(f"{'object':16s} {'E true':>8s}  estimates / true (each squeeze)      spread  first opening (mm)",
          flush=True)
    spreads = []
    for name, modulus in objects:
        spec = jigs.scene_object(name, modulus, args.yaw)
        contacts = jigs.contacts_of(spec)
        estimates, openings = [], []
        for readings in cached(args.readings, name, modulus, args.yaw, args.times):
            openings.append(readings[0].width_m * 1e3)
            try:
                estimates.append(jigs.estimates_of(readings, spec, hand, contacts)["section"])
            except SqueezeError as error:
                estimates.append(None)
                print(f"{name:16s} refused: {error}")
        values = [e.youngs_modulus_pa for e in estimates if e is not None and not e.rigid]
        spread = max(values) / min(values) if len(values) == len(estimates) else math.nan
        spreads.append(spread)
        text = " ".join("refused" if e is None else "rigid" if e.rigid else f"{e.youngs_modulus_pa / modulus:5.2f}"
                        for e in estimates)
        print(f"{name:16s} {modulus:8.2g}  {text:34s} {spread:7.2f}  "
              + " / ".join(f"{w:.2f}" for w in openings), flush=True)
    good = sum(s <= 1.2 for s in spreads if math.isfinite(s))
    print(f"within 20 % (spread <= 1.2): {good} of {len(spreads)} objects, {args.times} squeezes each in place")
    return 0


if __name__ == "__main__":
    sys.exit(main())
