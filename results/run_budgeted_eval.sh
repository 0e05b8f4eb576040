#!/usr/bin/env bash
# The budgeted evaluation that produced results/sim_v1 (one simulator worker, in the background):
#   nohup results/run_budgeted_eval.sh > results/sim_v1.log 2>&1 &
# Every step is resumable: rerunning this script skips every finished trial. The order puts the
# cheapest informative trials first: the multi-material object, then every common object's best
# grasp (shake, then twist), then the stiffness-error sensitivity of that best grasp, then the
# remaining ranks, then the adversarial set. The full experiment is the last two steps.
# After each step the tables, the report and (if git is free) a commit of results/ are refreshed.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=results/sim_v1
EVAL=".venv/bin/python -m defgg_ros.evaluation.cli"
RUN="$EVAL run --out $OUT --workers 1 --grasps 5 --no-progress"

refresh() {
  $EVAL report --out $OUT --docs docs/results.md --notes results/notes.md || return 0
  for _ in 1 2 3 4 5; do
    git add $OUT docs/results.md 2>/dev/null && \
      git commit -q -m "results/sim_v1: $1" -- $OUT docs/results.md && return 0
    sleep 5    # another engineer's commit holds .git/index.lock
  done
}

$RUN --sets common --only mallet_mm --experiments multimaterial --multimaterial-moduli 2e4 --tasks shake --ranks 2
refresh "multi-material, 2 best grasps, shake"
# objects whose best grasp moves most with E first (see the strategy figure), then the rest
$RUN --sets common --only common_toy_bone common_sponge common_ring --experiments main --tasks shake --ranks 1
refresh "toy bone, sponge, ring: best grasp, shake"
$RUN --sets common --experiments main --tasks shake --ranks 1
refresh "common set, best grasp, shake"
$RUN --sets common --experiments main --tasks twist --ranks 1
refresh "common set, best grasp, twist"
$RUN --sets common --experiments sensitivity --tasks shake --ranks 1
refresh "sensitivity, best grasp"
$RUN --sets common --experiments main --tasks shake twist
refresh "common set, 5 grasps"
$RUN --sets common --experiments main sensitivity multimaterial --tasks shake twist
refresh "common set, all experiments"
$RUN --sets adversarial --experiments main --tasks shake twist
refresh "adversarial set"
