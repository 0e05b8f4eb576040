"""How much shake time the evaluation's exact stop saves (TrialSettings.shake_stop_when_decided), replayed on
fully measured soft trials, in its two parts:
  - stop: after the first direction k at which the mean over all 16 directions is certain to reach or miss
    25 m/s^2 (held values lie in [0, 50]) AND a measured direction was not held at 25 m/s^2 (so "held in
    every direction" is certain too);
  - cap: a direction's ramp also ends once held at the value that decides both outcomes
    (sim.trial.shake_outcome_cap: the rest of the mean's 400 m/s^2, and 25 m/s^2 while no direction failed).
Both outcomes are those of the full trial by construction (checked here on every trial); this prints what
each part skips. Cost model of bench/replay_confident_stop.py: a direction costs its ramp up to the loss (or
the cap) plus a restore.

    .venv/bin/python bench/archive/replay_eval_stop.py [bench/results/datagen_defgraspsim.jsonl]

The default sample is bench/bench_datagen.py's naive trials under defgraspsim (all 16 directions measured).
"""
import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from replay_confident_stop import naive_trials, shake_cost  # noqa: E402

from defgg_ros.constants import SHAKE_ACCEL_LIMIT_MPS2, SHAKE_POSITIVE_THRESHOLD_MPS2  # noqa: E402
from defgg_ros.evaluation.tasks import outcome_fields  # noqa: E402
from defgg_ros.sim.trial import label_decided_fill, shake_outcome_cap  # noqa: E402


def stop_index(values) -> int:
    """How many directions the exact two-outcome stop measures."""
    for k in range(1, len(values)):
        mean_certain = label_decided_fill(list(values[:k]), len(values), SHAKE_POSITIVE_THRESHOLD_MPS2,
                                          SHAKE_ACCEL_LIMIT_MPS2) is not None
        if mean_certain and min(values[:k]) < SHAKE_POSITIVE_THRESHOLD_MPS2:
            return k
    return len(values)


def capped_values(values) -> list:
    """The held values the full stop records (prefix stop and cap) for a fully measured trial."""
    kept = []
    for v in values[:stop_index(values)]:
        cap = shake_outcome_cap(kept, len(values), SHAKE_ACCEL_LIMIT_MPS2)
        kept.append(v if cap is None else min(v, cap))
    return kept


def outcomes(values, total) -> dict:
    """Both outcomes, the unmeasured rest filled as the trial fills it (0 once the mean is certain)."""
    fill = label_decided_fill(list(values), total, SHAKE_POSITIVE_THRESHOLD_MPS2, SHAKE_ACCEL_LIMIT_MPS2)
    return outcome_fields("shake", "ok", list(values) + [fill or 0.0] * (total - len(values)), "defgraspsim")


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
    capped = [capped_values(v) for v in trials]
    changed = sum(outcomes(c, 16) != outcomes(v, 16) for c, v in zip(capped, trials))
    with_cap = sum(shake_cost(c) for c in capped)
    print(f"{len(trials)} soft trials; stopped early: {sum(k < 16 for k in stops)}; directions measured "
          f"{sum(stops)} of {16 * len(trials)}; shake cost {kept / full:.3f} of the full shake "
          f"({100 * (1 - kept / full):.1f} % saved)")
    print(f"with the cap: directions capped {sum(sum(a < b for a, b in zip(c, v)) for c, v in zip(capped, trials))}; "
          f"shake cost {with_cap / full:.3f} of the full shake ({100 * (1 - with_cap / full):.1f} % saved); "
          f"outcomes changed {changed} of {len(trials)}")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
