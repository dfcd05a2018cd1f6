#!/usr/bin/env bash
# Petrel's main job, on defaults that need nothing installed by hand: build the `petrel`
# command, check and verify the example UAV mission, fly its three scripted scenarios in
# virtual time (nominal, payload failure, engine failure), and draw its nets as Graphviz DOT.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet --bin petrel
petrel=target/release/petrel
mission=${1:-missions/uav}
echo "== petrel check $mission"
"$petrel" check "$mission"
echo "== petrel verify $mission"
"$petrel" verify "$mission"
for script in "$mission"/scripts/*.script; do
    [ -e "$script" ] || continue
    echo "== petrel run $mission --script $script"
    "$petrel" run "$mission" --script "$script" > "target/$(basename "$script" .script).jsonl"
    echo "   steps written to target/$(basename "$script" .script).jsonl"
done
"$petrel" dot "$mission" -o target/mission.dot
echo "== nets drawn in target/mission.dot; render with: dot -Tsvg target/mission.dot -o mission.svg"
