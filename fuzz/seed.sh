#!/usr/bin/env bash
# Seeds the corpus of each fuzz target (or of the targets named) from the repository's own
# files: net files, manifests, can.toml files, PNML (the MCC models), DBCs, scripts, and a few
# hand-made candump lines, wire bodies and journal records, and the inputs that once crashed a
# target (fuzz/regressions/TARGET). libFuzzer then adds to
# fuzz/corpus/TARGET what it finds; the corpora are not committed (they grow and change),
# this script makes them again from a clean clone.
set -euo pipefail
cd "$(dirname "$0")"
repo=..
seed() { # seed TARGET FILE...
    local t=$1
    shift
    mkdir -p "corpus/$t"
    for f in "$@"; do
        [ -f "$f" ] && cp "$f" "corpus/$t/$(echo "$f" | sed 's|^\.\./||; s|/|_|g')"
    done
    return 0
}
for t in "${@:-net_parse net_check manifest can_toml pnml wire journal dbc candump script reload_mapping}"; do
  for t in $t; do
    case $t in
    net_parse | net_check)
        seed "$t" $(find "$repo/missions" "$repo/nets/tests/data" "$repo/verify/tests/data" "$repo/can_bridge/tests/data" -name '*.pn') ;;
    manifest)
        seed "$t" $(find "$repo/missions" "$repo/nets/tests/data" "$repo/verify/tests/data" "$repo/can_bridge/tests/data" -name petrel.toml) ;;
    can_toml)
        seed "$t" $(find "$repo/missions" "$repo/can_bridge/tests/data" -name can.toml) ;;
    pnml)
        # The small MCC models only: libFuzzer's inputs stay under -max_len.
        seed "$t" $(find "$repo/nets/tests/data" "$repo/verify/tests/data" -name '*.pnml' -size -60k) ;;
    dbc)
        # 64 bytes of payload first, then the DBC.
        mkdir -p corpus/dbc
        for f in "$repo/missions/auv/auv.dbc" "$repo/can_bridge/tests/data/auv/auv.dbc"; do
            { printf '%064d' 0; cat "$f"; } >"corpus/dbc/$(basename "$(dirname "$f")")_$(basename "$f")"
        done ;;
    script)
        seed "$t" $(find "$repo/missions/uav/scripts" -name '*.script') ;;
    candump)
        mkdir -p corpus/candump
        printf '(1700000000.000000) can0 100#0102030405060708\n(1700000000.010000) can0 101#R\n(1700000000.020000) can0 20000080#00FF\n(1700000000.030000) can0 123##1AABBCCDD\n(1700000000.040000) can0 200#DEADBEEF T\n' >corpus/candump/lines.log ;;
    wire)
        mkdir -p corpus/wire
        # An EventMsg: name "go", no parameter; one with an int, a float, a text, a list.
        printf '\x02go\x00' >corpus/wire/event_go
        printf '\x02at\x04\x00\x02\x01\x00\x00\x00\x00\x00\x00\xf0\x3f\x03\x01x\x04\x01\x00\x00\x00\x00\x00\x00\x00\x00' >corpus/wire/event_at ;;
    journal)
        mkdir -p corpus/journal
        printf '\x00PETRELJ1' >corpus/journal/magic_only
        printf '\x01\x04\x00\x01\x02go' >corpus/journal/one_record ;;
    reload_mapping)
        mkdir -p corpus/reload_mapping
        printf '[rename]\nnets = { MISSION = "MISSION" }\nplaces = { "MISSION.transiting" = "MISSION.transiting", "global.in_flight" = "global.in_flight" }\ntimers = { dec_answer = "dec_answer" }\n[vanished]\nplaces = ["EVENTS.watching"]\nnets = ["EVENTS"]\ntimers = ["dec_answer"]\n' >corpus/reload_mapping/every_key.toml ;;
    *) echo "seed.sh: unknown target $t" >&2; exit 2 ;;
    esac
    # Every input that once crashed a target runs again first (fuzz/regressions/TARGET).
    if [ -d "regressions/$t" ]; then
        mkdir -p "corpus/$t"
        cp regressions/"$t"/* "corpus/$t/"
    fi
  done
done
