#!/usr/bin/env bash
# The seed study of issue 49: the fem_v5 pair (Def-GG-CNN and the depth-only GG-CNN) trained with more
# seeds on exactly the shipped pair's frozen trials, schedule and object split (--split-seed 0, so every
# seed is chosen on the same validation objects), then evaluated on the common and adversarial shake,
# five best grasps, under fem_v5's own trial protocol. Seed 0 is the shipped pair (results/sim_v5).
#
#   SEEDS="1 2" WORKERS=1 COMMIT_EVERY_TRIALS=246 setsid nohup results/run_seed_study.sh > results/seeds.log 2>&1 &
#
# Resumable at every step: rerun the same command after a kill (training resumes from its state file,
# the evaluation skips finished trials). Outputs: runs/seeds/<model>_s<seed>/ (training, not tracked),
# results/seeds/weights_s<seed>/<model>.pt (the best-validation checkpoints, small, tracked),
# results/sim_v5_s<seed>/ (trial records). With COMMIT_EVERY_TRIALS=N the evaluation folders are committed
# once N more records than the last commit holds have run (one commit per ~10 % of the plan:
# 2 seeds x 2 models x (135 common + 480 adversarial) = 2,460 trials). Run from a worktree pinned at a
# commit (code that does not move under the run) with COMMIT_IN=<main checkout> and results/sim_v5_s*,
# results/seeds linked to that checkout's: the commits then land there.
#
# Another dataset's pair (the same study on other labels): TAG names the frozen archive
# models/train_data_<TAG>.tar.gz (made by defgg-eval freeze), PROTOCOL_FROM the dataset whose trial
# protocol the evaluation runs (its labels' own), and the outputs go to results/seeds_<TAG>/ and
# results/sim_<TAG>_s<seed>/. The pressing hand's labels (issue 49; 3 seeds x 1,230 trials, so 369 is 10 %):
#
#   TAG=fem_v5p PROTOCOL_FROM=datasets/fem_v5p SEEDS="0 1 2" WORKERS=2 COMMIT_EVERY_TRIALS=369 \
#       setsid nohup results/run_seed_study.sh > results/seeds_fem_v5p.log 2>&1 &
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then
  sed -n '2,/^set -uo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'
  exit 0
fi
SEEDS=${SEEDS:-1 2}
EPOCHS=${EPOCHS:-40}
TAG=${TAG:-fem_v5}
PROTOCOL_FROM=${PROTOCOL_FROM:-datasets/fem_v5}
FROZEN=${FROZEN:-runs/frozen_$TAG}
if [ "$TAG" = fem_v5 ]; then   # the first study's folders keep their names
  WEIGHTS=results/seeds; OUT_PREFIX=results/sim_v5_s; RUNS=runs/seeds
else
  WEIGHTS=results/seeds_$TAG; OUT_PREFIX=results/sim_${TAG}_s; RUNS=runs/seeds_$TAG
fi
[ -d "$PROTOCOL_FROM" ] || { echo "no dataset $PROTOCOL_FROM (PROTOCOL_FROM)" >&2; exit 2; }
PY=${PY:-.venv/bin/python}
EVAL="$PY -m defgg_ros.evaluation.cli"

stored() { [ -f "$WEIGHTS/weights_s$1/defgg_cnn.pt" ] && [ -f "$WEIGHTS/weights_s$1/ggcnn_depth_only.pt" ]; }
for seed in $SEEDS; do stored "$seed" || NEED_DATA=1; done
[ -z "${NEED_DATA:-}" ] || [ -d "$FROZEN/train_data" ] \
  || { mkdir -p "$FROZEN" && tar xzf "models/train_data_$TAG.tar.gz" -C "$FROZEN"; } || exit 1

train() {   # model seed [flags]: one resumable run, one torch thread (skipped once its weights are stored)
  local model=$1 seed=$2 run=$RUNS/${1}_s${2}
  shift 2
  [ -f "$WEIGHTS/weights_s$seed/$model.pt" ] && [ ! -d "$run" ] && return 0
  mkdir -p "$RUNS"
  $PY -m defgg_ros.train.cli --data "$FROZEN/train_data" --epochs "$EPOCHS" --samples-per-scene 8 \
    --seed "$seed" --split-seed 0 --threads 1 --no-progress --out "$run" --resume "$@" > "$run.log" 2>&1 \
    || { echo "training $model seed $seed failed: $run.log" >&2; return 1; }
  mkdir -p "$WEIGHTS/weights_s$seed"
  cp "$run/best.pt" "$WEIGHTS/weights_s$seed/$model.pt"
  cp "$run/metrics.json" "$WEIGHTS/weights_s$seed/$model.metrics.json"
}

commit() {   # folder message: at most once per COMMIT_EVERY_TRIALS new records
  local out=$1 committed now
  local git="git -C ${COMMIT_IN:-.}"
  committed=$($git show "HEAD:$out/trials.jsonl" 2>/dev/null | wc -l)
  now=$(wc -l < "$out/trials.jsonl" 2>/dev/null || echo 0)
  [ "$now" -ge "$((committed + ${COMMIT_EVERY_TRIALS:-0}))" ] || return 0
  for _ in 1 2 3 4 5; do
    $git add "$out" "$WEIGHTS" 2>/dev/null && $git commit -q -m "$out: $2" -- "$out" "$WEIGHTS" && return 0
    sleep 5   # another commit holds .git/index.lock
  done
}

for seed in $SEEDS; do   # both models of a seed at once (2 cores)
  train defgg_cnn "$seed" & a=$!
  train ggcnn_depth_only "$seed" --no-stiffness & b=$!
  wait $a || exit 1
  wait $b || exit 1
done

run() {   # seed set ranks
  local out=$OUT_PREFIX$1 w=$WEIGHTS/weights_s$1
  $EVAL run --out "$out" --model "defgg_cnn=$w/defgg_cnn.pt" --model "ggcnn_depth_only=$w/ggcnn_depth_only.pt" \
    --workers "${WORKERS:-1}" --grasps 5 --ranks "$3" --no-progress --protocol-from "$PROTOCOL_FROM" \
    --sets "$2" --experiments main --tasks shake
  $EVAL report --out "$out" > /dev/null || true
  commit "$out" "seed $1, $2 set, shake, $3 best grasps"
}
# Rank-major over the seeds, so a stopped run covers every seed and set evenly.
for ranks in 1 3 5; do
  for set in common adversarial; do
    for seed in $SEEDS; do run "$seed" "$set" "$ranks"; done
  done
done
echo "seed study complete"
