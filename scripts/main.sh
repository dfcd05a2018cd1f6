#!/usr/bin/env bash
# Petrel's main job, on defaults that need nothing installed by hand: build the `petrel`
# command, check the example UAV mission, and draw its nets as Graphviz DOT.
# (Until the player exists, checking and drawing the mission is the main job.)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet --bin petrel
petrel=target/release/petrel
mission=${1:-missions/uav}
"$petrel" check "$mission"
"$petrel" dot "$mission" -o target/mission.dot
echo "nets drawn in target/mission.dot ($(grep -c -- '->' target/mission.dot) arcs); render with: dot -Tsvg target/mission.dot -o mission.svg"
