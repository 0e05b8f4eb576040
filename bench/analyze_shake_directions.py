"""Held acceleration per shake direction, by the direction's angle to the grasp's closing axis.

Reads a dataset or pilot folder's trial records (no simulation) and prints, per modulus, the mean held
acceleration of the measured directions in four bins of |cos| between the direction and the closing axis
(0 = across the fingers' closing line, 1 = along it), and the share of directions held to the ramp's limit.
If the grasp's geometry decided the label, directions along the closing axis (pads push) and across it
(friction only, unless the fingers sink in or cage) would differ.

  .venv/bin/python bench/analyze_shake_directions.py bench/pilots/a_defgraspsim
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

BINS = 4


def closing_axis_cosines(directions: np.ndarray, yaw_rad: float) -> np.ndarray:
    """|cos| between each world-frame direction and the closing axis of a top-down grasp of this yaw."""
    axis = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    return np.abs(directions @ axis)


def table(records, limit_mps2: float) -> dict:
    """{E: [(mean held, n, share held to the limit) per |cos| bin]} over measured directions of held trials."""
    from defgg_ros.sim.trial import shake_directions

    directions = shake_directions()
    per_e: dict = {}
    for r in records:
        if r.get("status") != "ok" or not r.get("shake_accels_mps2"):
            continue
        measured = r.get("sim", {}).get("shake_measured") or [True] * len(directions)
        cosines = closing_axis_cosines(directions, r["yaw_rad"])
        bins = per_e.setdefault(r["youngs_modulus_pa"], [[] for _ in range(BINS)])
        for cos, held, was_measured in zip(cosines, r["shake_accels_mps2"], measured):
            if was_measured:
                bins[min(int(cos * BINS), BINS - 1)].append(held)
    return {e: [(float(np.mean(v)) if v else float("nan"), len(v),
                 float(np.mean(np.asarray(v) >= limit_mps2 - 0.1)) if v else float("nan")) for v in bins]
            for e, bins in sorted(per_e.items())}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder", type=Path, help="dataset or pilot folder (trials/*.jsonl[.gz])")
    args = ap.parse_args(argv)
    from defgg_ros.constants import SHAKE_ACCEL_LIMIT_MPS2
    from defgg_ros.data.signal import read_trial_records

    rows = table(read_trial_records(args.folder), SHAKE_ACCEL_LIMIT_MPS2)
    if not rows:
        raise SystemExit(f"{args.folder}: no held trial with shake records")
    edges = [f"{k / BINS:.2f}-{(k + 1) / BINS:.2f}" for k in range(BINS)]
    print(f"{args.folder}: mean held acceleration (m/s^2) of measured directions by |cos| to the closing axis; "
          f"n; share held to {SHAKE_ACCEL_LIMIT_MPS2:.0f} m/s^2")
    print("| E (Pa) | " + " | ".join(f"|cos| {e}" for e in edges) + " |")
    print("|---|" + "---|" * BINS)
    for e, cells in rows.items():
        print(f"| {e:.0e} | " + " | ".join(f"{m:.1f} (n {n}, {s * 100:.0f} %)" for m, n, s in cells) + " |")


if __name__ == "__main__":
    main()
