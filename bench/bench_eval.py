"""Cost of the evaluation's simulator trials, per modulus and task, from a results folder.

    .venv/bin/python bench/bench_eval.py results/sim_v1            # figures from the trials that ran
    .venv/bin/python bench/bench_eval.py results/sim_v1 --plan 7 4 5 2 2
        # + CPU-hours the full experiment would need (objects, moduli, grasps, models, tasks)

Only trials that really ran are timed (reused ones cost nothing and are
counted apart). CPU seconds are the trial process's own (time.process_time),
so they do not depend on how loaded the machine was; wall seconds do.
"""
from __future__ import annotations

import argparse
import statistics
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from defgg_ros.evaluation.store import read_results, results_path  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("results", help="evaluation folder with trials.jsonl")
    p.add_argument("--plan", nargs=5, type=int, metavar=("OBJECTS", "MODULI", "GRASPS", "MODELS", "TASKS"),
                   help="size of a full experiment to extrapolate CPU-hours for")
    args = p.parse_args(argv)
    records = read_results(results_path(args.results))
    ran = [r for r in records if r.get("reused_from") is None and r.get("cpu_s") is not None]
    groups = defaultdict(list)
    for r in ran:
        groups[(r["youngs_modulus_pa"], r["task"])].append(r)
    print(f"{len(records)} records, {len(ran)} simulated, "
          f"{sum(1 for r in records if r.get('reused_from'))} reused, "
          f"{sum(1 for r in records if r.get('status') == 'no_grasp')} without a grasp")
    print(f"{'E (Pa)':>8} {'task':>6} {'n':>4} {'CPU s mean':>10} {'median':>7} {'max':>6} {'wall s mean':>11} "
          f"{'trials/CPU-h':>12}  statuses")
    per_trial = []
    for (e, task), rs in sorted(groups.items()):
        cpu = [r["cpu_s"] for r in rs]
        wall = [r.get("wall_s") or 0.0 for r in rs]
        statuses = defaultdict(int)
        for r in rs:
            statuses[r["status"]] += 1
        per_trial += cpu
        print(f"{e:>8.0e} {task:>6} {len(rs):>4} {statistics.mean(cpu):>10.1f} {statistics.median(cpu):>7.1f} "
              f"{max(cpu):>6.1f} {statistics.mean(wall):>11.1f} {3600 / max(statistics.mean(cpu), 1e-9):>12.0f}  "
              f"{dict(statuses)}")
    if args.plan and per_trial:
        n = 1
        for k in args.plan:
            n *= k
        mean = statistics.mean(per_trial)
        print(f"full experiment {args.plan}: {n} trials x {mean:.1f} s (mean over all trials that ran) = "
              f"{n * mean / 3600:.1f} CPU-hours")
    return 0


if __name__ == "__main__":
    sys.exit(main())
