#!/usr/bin/env bash
# Petrel's main job, on defaults that need nothing installed by hand: check and verify the
# example UAV mission, fly its scripted scenarios in virtual time, then fly it for real: the
# player and the vehicle's simulated programs (GUI+PLD, DEC) as separate processes exchanging
# events over iceoryx2 shared memory, until the aircraft lands. Then the AUV mission: the
# player, the AUV's CAN data server with its simulated vehicle on the bus, and the guidance
# program, until the vehicle is back at the surface; its recorded bus replays offline to the
# same events. The vehicles' programs and simulators are the crates of vehicles/.
set -euo pipefail
cd "$(dirname "$0")/.."
# The monitor lays its nets out with Graphviz; its screenshot needs Chromium and its WebDriver.
need=()
command -v dot >/dev/null 2>&1 || need+=(graphviz)
command -v chromium >/dev/null 2>&1 || need+=(chromium)
command -v chromedriver >/dev/null 2>&1 || need+=(chromium-driver)
if [ "${#need[@]}" -gt 0 ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "== installing ${need[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
mission=${1:-missions/uav}
cargo build --release --quiet --bin petrel -p petrel-cli
cargo build --release --quiet -p uav -p auv
cargo build --release --quiet -p petrel-tests --example monitor_shot
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
echo "== live flight on vehicle $vehicle: petrel play + uav-gui + uav-dec over iceoryx2"
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
# Waits until `petrel status` of mission $1 on vehicle $2 mentions $3 (up to 30 s).
wait_status() {
    for _ in $(seq 1 300); do
        if "$petrel" status "$1" --vehicle "$2" --json 2>/dev/null | grep -q "$3"; then
            return 0
        fi
        sleep 0.1
    done
    echo "== $1 on $2: no $3 after 30 s" >&2
    return 1
}
trap cleanup EXIT
RUST_LOG=${RUST_LOG:-warn} "$petrel" play "$mission" --vehicle "$vehicle" --run-for 60 \
    --journal "target/journal/$vehicle" &
pids+=($!)
until "$petrel" status "$mission" --vehicle "$vehicle" >/dev/null 2>&1; do sleep 0.1; done
target/release/uav-gui --vehicle "$vehicle" --speed 60 >/dev/null 2>&1 & pids+=($!)
target/release/uav-dec --vehicle "$vehicle" --speed 60 >/dev/null 2>&1 & pids+=($!)
# The web monitor of the flight (docs/monitor.md), and its screenshot mid-flight in
# target/screenshots/ when headless Chromium is there (this script changes no tracked file).
"$petrel" monitor "$mission" --vehicle "$vehicle" --listen 127.0.0.1:0 --run-for 60 \
    > "target/monitor-$vehicle.out" &
pids+=($!)
until grep -q listening "target/monitor-$vehicle.out" 2>/dev/null; do sleep 0.1; done
monitor_url=$(sed -n 's/^petrel monitor: listening on //p' "target/monitor-$vehicle.out")
echo "== petrel monitor: $monitor_url"
sleep 0.5
"$petrel" send "$mission" --vehicle "$vehicle" start_mission
if command -v chromedriver >/dev/null 2>&1; then
    mkdir -p target/screenshots
    # Headless Chromium under WebDriver: it waits for the page to be in step and to show 8
    # steps (the aircraft in transit) before the shot.
    target/release/examples/monitor_shot "$monitor_url" target/screenshots/monitor-uav.png 8 || true
else
    echo "== no chromium here: no screenshot of the monitor (apt-get install chromium chromium-driver)"
fi
wait_status "$mission" "$vehicle" '"landed"'
"$petrel" status "$mission" --vehicle "$vehicle"
# The monitor and the programs first, then the player: every process of the flight ends here.
kill "${pids[3]}" "${pids[2]}" "${pids[1]}" 2>/dev/null || true
wait "${pids[3]}" "${pids[2]}" "${pids[1]}" 2>/dev/null || true
kill "${pids[0]}" 2>/dev/null || true
wait "${pids[0]}" 2>/dev/null || true
echo "== the flight recorder: target/journal/$vehicle"
"$petrel" replay "target/journal/$vehicle"

red=missions/redermor
auv=missions/auv
echo "== petrel check $auv (nets, can.toml and its DBC)"
"$petrel" check "$auv"
for script in "$auv"/scripts/*.script; do
    out="target/auv-$(basename "$script" .script).jsonl"
    echo "== petrel run $auv --script $script  (steps in $out)"
    "$petrel" run "$auv" --script "$script" > "$out"
done
dive="dive$$"
echo "== live dive on vehicle $dive: petrel play + auv-bridge (memory bus, simulated AUV) + auv-gui"
pids=()
RUST_LOG=${RUST_LOG:-warn} "$petrel" play "$auv" --vehicle "$dive" --run-for 60 \
    --journal "target/journal/$dive" &
pids+=($!)
until "$petrel" status "$auv" --vehicle "$dive" >/dev/null 2>&1; do sleep 0.1; done
RUST_LOG=${RUST_LOG:-warn} target/release/auv-bridge "$auv" --vehicle "$dive" --bus memory \
    --record "target/$dive-bus.log" 2>/dev/null &
pids+=($!)
target/release/auv-gui --vehicle "$dive" &
pids+=($!)
sleep 0.5
"$petrel" send "$auv" --vehicle "$dive" start_mission
wait_status "$auv" "$dive" '"surfaced"'
"$petrel" status "$auv" --vehicle "$dive"
# The programs first (the data server waits for the player to acknowledge its last events).
kill "${pids[2]}" "${pids[1]}" 2>/dev/null || true
wait "${pids[2]}" "${pids[1]}" 2>/dev/null || true
kill "${pids[0]}" 2>/dev/null || true
wait "${pids[0]}" 2>/dev/null || true
echo "== the bus, recorded by the data server: target/$dive-bus.log ($(wc -l <"target/$dive-bus.log") frames); its events, replayed offline:"
"$petrel" bridge "$auv" --replay "target/$dive-bus.log"
echo "== the flight recorder: target/journal/$dive"
"$petrel" replay "target/journal/$dive"

# Redermor (issue 14), scenario 1 flown live: `petrel up` brings up the player, the CAN data
# server on the in-memory bus with the Redermor simulator (20 times the wall clock) and the
# programs PLN, NAV (GDD, GUI, IDC) and EVT, until the vehicle is stopped at the surface in the
# end area. A monitor follows it (screenshots of its overview, a net and the map under
# target/screenshots/); then `petrel plot` draws the run (its map.toml: areas, routes, track,
# events; and the depth profile).
cargo build --release --quiet -p redermor-live --bin redermor-program --bin redermor-bridge
run="target/redermor-run"
rm -rf "$run"
rv="rdm$$"
echo "== petrel up $red: scenario 1 (nominal), live"
RUST_LOG=${RUST_LOG:-warn} "$petrel" up "$red" --vehicle "$rv" --logs "$run" --timeout 300 &
up=$!
pids=("$up")
if command -v chromedriver >/dev/null 2>&1; then
    until "$petrel" status "$red" --vehicle "$rv" >/dev/null 2>&1; do sleep 0.2; done
    "$petrel" monitor "$red" --vehicle "$rv" --listen 127.0.0.1:0 --run-for 120 \
        > "target/monitor-$rv.out" &
    pids+=($!)
    until grep -q listening "target/monitor-$rv.out" 2>/dev/null; do sleep 0.1; done
    red_url=$(sed -n 's/^petrel monitor: listening on //p' "target/monitor-$rv.out")
    echo "== petrel monitor: $red_url"
    mkdir -p target/screenshots
    for shot in "view=overview:overview:12" "net=MISSION/MISSION_PHASES:net:14" "view=map:map:30"; do
        IFS=: read -r query name steps <<<"$shot"
        target/release/examples/monitor_shot "$red_url?$query" \
            "target/screenshots/monitor-redermor-$name.png" "$steps" || true
    done
    kill "${pids[1]}" 2>/dev/null || true
    wait "${pids[1]}" 2>/dev/null || true
fi
wait "$up"
"$petrel" plot "$run"
echo "== Redermor scenario 1: journal $run/journal (petrel replay $run/journal; petrel monitor --journal $run/journal), logs $run/*.log, bus $run/bus.log, track $run/trace.csv, plots $run/map.svg and $run/profile.svg"
"$petrel" replay "$run/journal"
