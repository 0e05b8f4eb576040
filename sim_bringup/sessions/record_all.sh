#!/usr/bin/env bash
# Re-record the sessions of this folder from the simulated cell (a minute on 2 cores).
#   bash sim_bringup/sessions/record_all.sh [NAME ...]     # default: every session below
# Each session: bring up the sim cell on its scene in ROS_DOMAIN_ID (default 50: the bringup's range, locked while it runs; localhost-only discovery;
# defgg-bringup's own default, a private random domain, would hide it from defgg-record), then defgg-record
# drives it (stiffness from the scene, PlanGrasp calls, one pick in the rigid session). SESSIONS_OUT: where
# the recordings go (default: this folder). Exits 1 if any recording failed.
# To refresh only the expectations of existing sessions (same inputs), use instead:
#   .venv/bin/defgg-replay --update sim_bringup/sessions
set -euo pipefail
cd "$(dirname "$0")/../.."
HERE=sim_bringup/sessions
OUT=${SESSIONS_OUT:-$HERE}
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-50} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export FASTRTPS_DEFAULT_PROFILES_FILE=${FASTRTPS_DEFAULT_PROFILES_FILE:-$PWD/defgg_ros/ros/fastdds_profile.xml}
# rmw_fastrtps reads the profile's per-reader memory policy only with this set (docs/perception.md, input bounds)
export RMW_FASTRTPS_USE_QOS_FROM_XML=${RMW_FASTRTPS_USE_QOS_FROM_XML:-1}
failed=()

record() {  # name, then defgg-record options
  local name=$1; shift
  local scene=$HERE/scenes/$name.yaml
  .venv/bin/defgg-bringup --scene "$scene" --ros-domain "$ROS_DOMAIN_ID" > "/tmp/defgg_record_$name.bringup.log" 2>&1 &
  local bringup=$!
  rm -rf "${OUT:?}/$name"  # git keeps the previous recording
  .venv/bin/defgg-record "$OUT/$name" --scene "$scene" --stiffness-from-scene \
    --depth-period-s 1000 --top-k 3 "$@" \
    || { echo "recording $name FAILED (above; the cell's log: /tmp/defgg_record_$name.bringup.log)"; failed+=("$name"); }
  kill -INT "$bringup" 2>/dev/null; wait "$bringup" || true
}

declare -A OPTIONS=(
  [rigid_objects]='--plan 2 --pick 1 --note "two rigid cylinders: plan twice, pick with the second plan'"'"'s grasp"'
  [soft_objects]='--plan 2 --note "a sponge (2e4 Pa) and a foam cube (2e5 Pa): plan twice"'
  [mixed_objects]='--plan 2 --note "soft cube, rigid can, rigid block with a soft pad (multi-material): plan twice"'
)
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(rigid_objects soft_objects mixed_objects)
for name in "${names[@]}"; do
  [ -n "${OPTIONS[$name]+x}" ] || { echo "record_all.sh: unknown session $name (known: ${!OPTIONS[*]})" >&2; exit 2; }
  eval "record $name ${OPTIONS[$name]}"
done
[ ${#failed[@]} -eq 0 ] || { echo "record_all.sh: failed: ${failed[*]}" >&2; exit 1; }
