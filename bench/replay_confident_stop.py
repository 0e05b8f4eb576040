"""Replay the shake test's confident stop on recorded soft trials, for a grid of its two knobs.

Every soft trial of a dataset stores its per-direction held accelerations in the generator's order,
with a flag per direction saying whether it was measured. A stricter-or-looser confident stop decides
at some prefix of those directions: replaying the rule on the measured prefix gives the label it would
have given (a trial it does not stop keeps its label: the rest of the protocol is unchanged) and the
directions it would have skipped. Sources:
  - dataset folders (tuning): labels of the generator of the time;
  - bench/bench_datagen.py's naive sample (check): all 16 directions measured, full-protocol labels.
Cost is counted in shake time: a direction costs its ramp up to the loss (held / limit of the ramp)
plus a restore (RESTORE_COST, in ramps); the lift is not included (it does not change).
Prints per (min directions, margin): trials, labels changed, shake cost relative to no confident stop.

Command: .venv/bin/python bench/replay_confident_stop.py [--datasets datasets/fem_v1 datasets/fem_v2]
"""
import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from defgg_ros.constants import SHAKE_ACCEL_LIMIT_MPS2, SHAKE_POSITIVE_THRESHOLD_MPS2  # noqa: E402
from defgg_ros.data.format import read_jsonl  # noqa: E402
from defgg_ros.sim.trial import _confidently_decided  # noqa: E402

SOFT_BELOW_PA = 1e9
RESTORE_COST = 0.1   # a restore + re-settle, in units of one full ramp (measured steps: ~0.05-0.1)
GRID = [(4, 40.0), (3, 30.0), (3, 25.0), (3, 20.0), (4, 20.0), (3, 15.0), (4, 15.0), (2, 20.0),
        (4, 10.0), (3, 10.0)]


def dataset_trials(folder: Path):
    """(measured prefix of held accelerations, label) of every soft trial that reached the shake."""
    for path in sorted((folder / "trials").glob("*.jsonl*")):      # plain or sealed (.jsonl.gz)
        for r in read_jsonl(path):
            if r["status"] != "ok" or r["shake_accels_mps2"] is None or r["youngs_modulus_pa"] >= SOFT_BELOW_PA:
                continue
            measured = r["sim"].get("shake_measured") or [True] * len(r["shake_accels_mps2"])
            yield np.array(r["shake_accels_mps2"])[:sum(measured)], bool(r["label"]), r["yaw_rad"]


def naive_trials(path: Path):
    for r in read_jsonl(path) if path.is_file() else []:
        if r["protocol"] == "naive" and r["status"] == "ok" and r["E"] < SOFT_BELOW_PA and r["accels"]:
            yield np.array(r["accels"]), bool(r["label"]), None


def shake_cost(values) -> float:
    return float(sum(RESTORE_COST + v / SHAKE_ACCEL_LIMIT_MPS2 for v in values))


def replay(trials, min_directions, margin_mps2):
    """(labels changed, cost with the rule, cost with no confident stop)."""
    changed, cost, base = 0, 0.0, 0.0
    for values, label, _ in trials:
        base += shake_cost(values)
        stop = next((k for k in range(1, len(values)) if _confidently_decided(values[:k], min_directions,
                                                                                 margin_mps2)), None)
        if stop is None:
            cost += shake_cost(values)
            continue
        cost += shake_cost(values[:stop])
        changed += (float(np.mean(values[:stop])) >= SHAKE_POSITIVE_THRESHOLD_MPS2) != label
    return changed, cost, base


def prefix_error_table(trials):
    """How far the mean of the first k directions is from the 16-direction mean (fully measured trials)."""
    full = [v for v, _, _ in trials if len(v) == 16]
    print(f"\nprefix mean - full mean over {len(full)} fully measured soft trials (m/s^2):")
    print("| k | sd | max abs | margin 20/sqrt(k) |\n|---|---|---|---|")
    for k in range(2, 9):
        err = np.array([v[:k].mean() - v.mean() for v in full])
        print(f"| {k} | {err.std():.1f} | {np.abs(err).max():.1f} | {20.0 / math.sqrt(k):.1f} |")


def _shown(path: Path) -> str:
    return str(path.resolve().relative_to(ROOT)) if path.resolve().is_relative_to(ROOT) else str(path)


def friction_cone_held_mps2(capacity_mps2, normal_weight, yaw_rad):
    """Held acceleration per shake direction if the grasp fails when the load per kg it must carry,
    |t|^2 + (w n_part)^2 with t the part across the closing axis n, exceeds capacity^2: a friction
    cone (w = 0: the fingers carry any load along n) with the closing-axis load partly counted."""
    from defgg_ros.sim.trial import shake_directions

    accel = np.linspace(0.0, SHAKE_ACCEL_LIMIT_MPS2, 501)
    normal = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    held = []
    for d in shake_directions():
        load = np.array([0.0, 0.0, -9.81])[None, :] - accel[:, None] * d[None, :]
        along = load @ normal
        across = load - along[:, None] * normal
        over = np.nonzero(np.sum(across ** 2, 1) + (normal_weight * along) ** 2 > capacity_mps2 ** 2)[0]
        held.append(accel[over[0]] if len(over) else SHAKE_ACCEL_LIMIT_MPS2)
    return np.array(held)


def friction_cone_table(trials):
    """Predict the 16-direction mean from the first k directions: prefix mean vs a friction-cone fit."""
    full = [(v, yaw) for v, _, yaw in trials if len(v) == 16 and yaw is not None]
    grid = [(c, w) for c in np.arange(5.0, 61.0) for w in (0.0, 0.25, 0.5, 0.75, 1.0)]
    print(f"\npredicting the 16-direction mean from k directions ({len(full)} fully measured dataset trials):")
    print("| k | prefix mean: error SD | friction-cone fit: error SD |\n|---|---|---|")
    models = [{g: friction_cone_held_mps2(*g, yaw) for g in grid} for _, yaw in full]
    for k in (3, 4, 6, 8):
        plain, fitted = [], []
        for (values, _), model in zip(full, models):
            best = min(model.values(), key=lambda held: float(np.mean((held[:k] - values[:k]) ** 2)))
            plain.append(values[:k].mean() - values.mean())
            fitted.append(best.mean() - values.mean())
        print(f"| {k} | {np.std(plain):.1f} | {np.std(fitted):.1f} |")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--datasets", nargs="+", type=Path,
                        default=[ROOT / "datasets/fem_v1", ROOT / "datasets/fem_v2"])
    parser.add_argument("--naive-sample", type=Path, default=ROOT / "bench/results/datagen_sample_frozen.jsonl")
    args = parser.parse_args(argv)
    tuning = [t for folder in args.datasets for t in dataset_trials(folder)]
    check = list(naive_trials(args.naive_sample))
    if not tuning and not check:
        parser.error("no soft trials found in --datasets or --naive-sample")
    print(f"tuning: {len(tuning)} soft trials from {', '.join(_shown(d) for d in args.datasets)}; "
          f"check: {len(check)} naive soft trials from {_shown(args.naive_sample)}")
    print("| min directions | margin (m/s^2) | tuning: labels changed | tuning: shake cost | "
          "check: labels changed | check: shake cost |\n|---|---|---|---|---|---|")
    for min_directions, margin in GRID:
        row = []
        for trials in (tuning, check):
            changed, cost, base = replay(trials, min_directions, margin)
            row += [f"{changed}/{len(trials)}", f"{cost / base:.2f}" if base else "-"]
        print(f"| {min_directions} | {margin:g} | " + " | ".join(row) + " |")
    prefix_error_table(tuning + check)
    friction_cone_table(tuning)


if __name__ == "__main__":
    main()
