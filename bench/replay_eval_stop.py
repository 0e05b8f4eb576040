"""How much shake time the evaluation's exact stop saves (TrialSettings.shake_stop_when_decided), replayed on
fully measured soft trials: stop after the first direction k at which the mean over all 16 directions is
certain to reach or miss 25 m/s^2 (held values lie in [0, 50]) AND a measured direction was not held at
25 m/s^2 (so "held in every direction" is certain too). Both outcomes are those of the full trial by
construction; this prints what the stop skips. Cost model of bench/replay_confident_stop.py: a direction
costs its ramp up to the loss plus a restore.

    .venv/bin/python bench/replay_eval_stop.py [bench/results/datagen_defgraspsim.jsonl]

The default sample is bench/bench_datagen.py's naive trials under defgraspsim (all 16 directions measured).
"""
import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from replay_confident_stop import naive_trials, shake_cost  # noqa: E402

from defgg_ros.constants import SHAKE_ACCEL_LIMIT_MPS2, SHAKE_POSITIVE_THRESHOLD_MPS2  # noqa: E402
from defgg_ros.sim.trial import label_decided_fill  # noqa: E402


def stop_index(values) -> int:
    """How many directions the exact two-outcome stop measures."""
    for k in range(1, len(values)):
        mean_certain = label_decided_fill(list(values[:k]), len(values), SHAKE_POSITIVE_THRESHOLD_MPS2,
                                          SHAKE_ACCEL_LIMIT_MPS2) is not None
        if mean_certain and min(values[:k]) < SHAKE_POSITIVE_THRESHOLD_MPS2:
            return k
    return len(values)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="?", type=Path, default=ROOT / "bench/results/datagen_defgraspsim.jsonl")
    args = ap.parse_args(argv)
    trials = [values for values, _, _ in naive_trials(args.results) if len(values) == 16]
    if not trials:
        print(f"replay_eval_stop: no fully measured soft trial in {args.results}", file=sys.stderr)
        return 2
    stops = [stop_index(v) for v in trials]
    full = sum(shake_cost(v) for v in trials)
    kept = sum(shake_cost(v[:k]) for v, k in zip(trials, stops))
    print(f"{len(trials)} soft trials; stopped early: {sum(k < 16 for k in stops)}; directions measured "
          f"{sum(stops)} of {16 * len(trials)}; shake cost {kept / full:.3f} of the full shake "
          f"({100 * (1 - kept / full):.1f} % saved)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
