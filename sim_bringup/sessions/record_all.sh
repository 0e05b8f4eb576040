#!/usr/bin/env bash
# Re-record the sessions of this folder from the simulated cell (a few minutes on 2 cores).
# Each session: bring up the sim cell on its scene (private ROS domain), then defgg-record
# drives it (stiffness from the scene, PlanGrasp calls, one pick in the rigid session).
# To refresh only the expectations of existing sessions (same inputs), use instead:
#   .venv/bin/defgg-replay --update sim_bringup/sessions
set -euo pipefail
cd "$(dirname "$0")/../.."
HERE=sim_bringup/sessions
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-97} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export FASTRTPS_DEFAULT_PROFILES_FILE=${FASTRTPS_DEFAULT_PROFILES_FILE:-$PWD/defgg_ros/ros/fastdds_profile.xml}

record() {  # name, then defgg-record options
  local name=$1; shift
  local scene=$HERE/scenes/$name.yaml
  .venv/bin/defgg-bringup --scene "$scene" --ros-domain "$ROS_DOMAIN_ID" > "/tmp/defgg_record_$name.bringup.log" 2>&1 &
  local bringup=$!
  rm -rf "${HERE:?}/$name"  # git keeps the previous recording
  .venv/bin/defgg-record "$HERE/$name" --scene "$scene" --stiffness-from-scene \
    --depth-period-s 1000 --top-k 3 "$@" || echo "recording $name FAILED (see above)"
  kill -INT "$bringup"; wait "$bringup" || true
}

record rigid_objects --plan 2 --pick 1 --note "two rigid cylinders: plan twice, pick with the second plan's grasp"
record soft_objects --plan 2 --note "a sponge (2e4 Pa) and a foam cube (2e5 Pa): plan twice"
record mixed_objects --plan 2 --note "soft cube, rigid can, rigid block with a soft pad (multi-material): plan twice"
