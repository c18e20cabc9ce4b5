#!/usr/bin/env bash
# Run a plant and its twin side by side: sim_node (the feeder, on its default config),
# camera_node standing in for the camera (its particle_states made into detections with
# 2 mm of noise, misses, false detections, swapped track ids, 50-100 ms late) and twin_node
# following it (the camera's detections, sim_node's cone_state as the encoder, its
# exit_events as the channels' sensors); sim_node and twin_node record to runs/. Stop with
# Ctrl-C or SIGTERM: both finish their recordings. Then
# open both MCAP files together in Foxglove (Open local file, select both: one timeline), or
# watch live with foxglove_bridge where ROS 2 comes from apt (ros-jazzy-foxglove-bridge; it
# is not on PyPI). A perfect camera: CAMERA_ARGS="-p sigma:=0.0 -p miss:=0.0 -p
# false_rate:=0.0 -p swap:=0.0 -p delay:=0.0 -p jitter:=0.0". The twin with the plant's
# contact between pieces: TWIN_ARGS="-p interactions.enabled:=true" (doc/twin.md: its cost).
#   bash scripts/plant_and_twin.sh [seconds]     (default: until stopped)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${BIN:-.venv/bin}"
"$BIN/sim_node" --ros-args --params-file config/sim_node.yaml &
plant=$!
# shellcheck disable=SC2086  # CAMERA_ARGS: several words
"$BIN/camera_node" --ros-args ${CAMERA_ARGS:-} &
camera=$!
# shellcheck disable=SC2086  # TWIN_ARGS: several words
"$BIN/twin_node" --ros-args ${TWIN_ARGS:-} &
twin=$!
stop() {
  kill -TERM "$twin" "$camera" "$plant" 2>/dev/null || true
  wait "$twin" "$camera" "$plant" || true
}
trap stop INT TERM
if [ -n "${1:-}" ]; then
  sleep "$1"
  stop
else
  wait "$twin" "$camera" "$plant"
fi
