#!/usr/bin/env bash
# Run a plant and its twin side by side: sim_node (the feeder, on its default config) and
# twin_node following it (sim_node's particle_states as the camera's detections, its
# cone_state as the encoder), both recording to runs/. Stop with Ctrl-C or SIGTERM: both
# nodes finish their recordings. Then open both MCAP files together in Foxglove (Open local
# file, select both: one timeline), or watch live with foxglove_bridge where ROS 2 comes
# from apt (ros-jazzy-foxglove-bridge; it is not on PyPI).
#   bash scripts/plant_and_twin.sh [seconds]     (default: until stopped)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${BIN:-.venv/bin}"
"$BIN/sim_node" --ros-args --params-file config/sim_node.yaml &
plant=$!
"$BIN/twin_node" --ros-args -r detections:=particle_states &
twin=$!
stop() { kill -TERM "$twin" "$plant" 2>/dev/null || true; wait "$twin" "$plant" || true; }
trap stop INT TERM
if [ -n "${1:-}" ]; then
  sleep "$1"
  stop
else
  wait "$twin" "$plant"
fi
