#!/usr/bin/env bash
# Petrel's main job, on defaults that need nothing installed by hand: check and verify the
# example UAV mission, fly its scripted scenarios in virtual time, then fly it for real: the
# player and the vehicle's simulated programs (GUI+PLD, DEC) as separate processes exchanging
# events over iceoryx2 shared memory, until the aircraft lands.
set -euo pipefail
cd "$(dirname "$0")/.."
mission=${1:-missions/uav}
cargo build --release --quiet --bin petrel -p petrel-player
cargo build --release --quiet -p petrel-programs --example uav_gui --example uav_dec
petrel=target/release/petrel
echo "== petrel check $mission"
"$petrel" check "$mission"
echo "== petrel verify $mission"
"$petrel" verify "$mission"
for script in "$mission"/scripts/*.script; do
    [ -e "$script" ] || continue
    out="target/$(basename "$script" .script).jsonl"
    echo "== petrel run $mission --script $script  (steps in $out)"
    "$petrel" run "$mission" --script "$script" > "$out"
done
"$petrel" dot "$mission" -o target/mission.dot
echo "== nets drawn in target/mission.dot (render: dot -Tsvg target/mission.dot -o mission.svg)"

vehicle="demo$$"
echo "== live flight on vehicle $vehicle: petrel play + uav_gui + uav_dec over iceoryx2"
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT
RUST_LOG=${RUST_LOG:-warn} "$petrel" play "$mission" --vehicle "$vehicle" --run-for 60 \
    --journal "target/journal/$vehicle" &
pids+=($!)
until "$petrel" status "$mission" --vehicle "$vehicle" >/dev/null 2>&1; do sleep 0.1; done
target/release/examples/uav_gui --vehicle "$vehicle" >/dev/null 2>&1 & pids+=($!)
target/release/examples/uav_dec --vehicle "$vehicle" >/dev/null 2>&1 & pids+=($!)
sleep 0.5
"$petrel" send "$mission" --vehicle "$vehicle" start_mission
for _ in $(seq 1 300); do
    if "$petrel" status "$mission" --vehicle "$vehicle" --json 2>/dev/null | grep -q '"landed"'; then
        break
    fi
    sleep 0.1
done
"$petrel" status "$mission" --vehicle "$vehicle"
kill "${pids[0]}" 2>/dev/null || true
wait "${pids[0]}" 2>/dev/null || true
echo "== the flight recorder: target/journal/$vehicle"
"$petrel" replay "target/journal/$vehicle"
