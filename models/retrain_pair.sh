#!/usr/bin/env bash
# Retrain and ship the model pair on one finished dataset: Def-GG-CNN (depth + stiffness) and the
# depth-only GG-CNN, on exactly the same frozen trials, schedule and seed; each shipped at its best
# validation epoch (validation objects only, never the evaluation sets), with its model card.
#
#   models/retrain_pair.sh datasets/fem_v5 fem_v5 "why this pair replaces the shipped one"
#
# Steps (rerun the same command after a kill: the archive is kept, training resumes):
#   1. defgg-eval freeze: $MODELS_DIR/train_data_<tag>.tar.gz (verified fingerprint), extracted to
#      $RUNS_DIR/frozen_<tag>/
#   2. defgg-train twice (--resume), one torch thread each, both at once (2 cores)
#   3. defgg-eval ship --checkpoint best for each, then defgg-eval card
# The shipped weights change only after both runs have finished, so a kill never ships half a pair.
# Environment: EPOCHS (40), MODELS_DIR (models), RUNS_DIR (runs), TRAIN_FLAGS (extra defgg-train flags,
# e.g. "--max-steps 2" for a smoke run; recorded in the card's command).
set -euo pipefail
cd "$(dirname "$0")/.."
usage="usage: models/retrain_pair.sh DATASET TAG NOTE"
DATA=${1:?$usage}
TAG=${2:?$usage}
NOTE=${3:?$usage}
EPOCHS=${EPOCHS:-40}
MODELS=${MODELS_DIR:-models}
RUNS=${RUNS_DIR:-runs}
ARCHIVE=$MODELS/train_data_${TAG}.tar.gz
FROZEN=$RUNS/frozen_${TAG}
EVAL=".venv/bin/python -m defgg_ros.evaluation.cli"

mkdir -p "$RUNS" "$MODELS"
if [ ! -f "$ARCHIVE" ]; then
  $EVAL freeze --data "$DATA" --archive "$ARCHIVE" --extract-to "$FROZEN"
elif [ ! -d "$FROZEN/train_data" ]; then
  mkdir -p "$FROZEN" && tar xzf "$ARCHIVE" -C "$FROZEN"
fi

train() {   # name, extra flags: one resumable run; its command and wall seconds go next to it
  local name=$1 run=$RUNS/${1}_${TAG}
  shift
  local cmd="defgg-train --data $FROZEN/train_data --epochs $EPOCHS --samples-per-scene 8 --seed 0 --threads 1"
  cmd="$cmd --no-progress --out $run${TRAIN_FLAGS:+ $TRAIN_FLAGS}${*:+ $*}"
  local start=$SECONDS
  # shellcheck disable=SC2086  # the command is split into its words on purpose
  .venv/bin/$cmd --resume > "$run.log" 2>&1 || { echo "training $name failed: see $run.log" >&2; return 1; }
  echo $((SECONDS - start)) >> "$run.wall_s"
  echo "$cmd" > "$run.command"
}
echo "retrain_pair: training both models at once ($EPOCHS epochs each); follow $RUNS/defgg_cnn_${TAG}.log and" \
  "$RUNS/ggcnn_depth_only_${TAG}.log (a line per epoch); a kill loses at most 25 steps, rerun to resume"
train defgg_cnn &
with_stiffness=$!
train ggcnn_depth_only --no-stiffness &
depth_only=$!
wait $with_stiffness
wait $depth_only

for name in defgg_cnn ggcnn_depth_only; do
  run=$RUNS/${name}_${TAG}
  $EVAL ship --run "$run" --name "$name" --command "$(cat "$run.command")" \
    --wall-s "$(awk '{s += $1} END {print s}' "$run.wall_s")" --checkpoint best --note "$NOTE" \
    --data-source "$DATA" --data-archive "$ARCHIVE" --models-dir "$MODELS"
done
$EVAL card --name defgg_cnn ggcnn_depth_only --models-dir "$MODELS"
echo "retrain_pair: shipped defgg_cnn and ggcnn_depth_only ($TAG) into $MODELS. Next, on purpose (docs/sessions.md):"
echo "  .venv/bin/defgg-replay --update sim_bringup/sessions   # the recorded sessions name the shipped weights"
echo "  make demo && make test"
