#!/usr/bin/env bash
# Benchmarks Petrel's P/T explorer against Spin on the large MCC models, in one run on one
# machine, so the ratios mean something even on a shared, noisy machine.
#
#   scripts/bench-verify.sh [MODEL...]
#
# Default models: Dekker-PT-015 Anderson-PT-05 NeoElection-PT-3 Peterson-PT-3 SafeBus-PT-06
# NQueens-PT-10 (from verify/tests/data/mcc). For each, Petrel explores the PNML file
# (`petrel verify FILE --format json`, or the `explore` example of petrel-verify while the CLI lacks
# the subcommand) and Spin explores the same net translated to Promela by the peer script
# pnml2pml.py (compiled -DNOREDUCE -DSAFETY -DBFS, run `./pan -E`). Wall seconds and peak RSS
# come from /usr/bin/time -v. Spin's compile time is shown apart; its run time is what is
# compared. Spin counts one extra state and two extra transitions for its init step; the table
# shows Spin's numbers with those removed.
#
# Peer scripts are looked up in $ANCHORS, ../shared/anchors beside the repository, then
# /work/shared/anchors; they are called there, never copied. Without them Petrel runs alone.
# Prints one Markdown table on stdout; progress goes to stderr.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
MCC="$ROOT/verify/tests/data/mcc"

models=("$@")
if [ "${#models[@]}" -eq 0 ]; then
    models=(Dekker-PT-015 Anderson-PT-05 NeoElection-PT-3 Peterson-PT-3 SafeBus-PT-06 NQueens-PT-10)
fi

say() { echo "== $*" >&2; }

anchors=""
for d in "${ANCHORS:-}" "$ROOT/../shared/anchors" /work/shared/anchors; do
    if [ -n "$d" ] && [ -f "$d/pnml2pml.py" ]; then
        anchors=$(cd "$d" && pwd)
        break
    fi
done
if [ -z "$anchors" ]; then
    say "peer scripts (pnml2pml.py) not found in \$ANCHORS, ../shared/anchors or /work/shared/anchors: running Petrel only"
fi

# What the run needs: GNU time always, Spin (and a C compiler, present on the machine) for the
# comparison.
need=()
[ -x /usr/bin/time ] || need+=(time)
if [ -n "$anchors" ] && ! command -v spin >/dev/null 2>&1; then need+=(spin); fi
if [ "${#need[@]}" -gt 0 ]; then
    say "installing ${need[*]}"
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo=sudo
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
if [ -n "$anchors" ] && ! command -v gcc >/dev/null 2>&1; then
    say "gcc is missing: running Petrel only"
    anchors=""
fi

# Petrel: the CLI when it has `verify`, else the library's example (same explore + to_json).
say "building Petrel (release)"
petrel=()
# `verify` may exist for projects before it takes PNML: probe it on the smallest model.
# (`petrel verify` exits 1 on a net with a deadlock, as Sudoku-PT-AN01 has one: read its output.)
probe=$(cargo build --release --quiet --bin petrel >&2 2>/dev/null &&
    "$ROOT/target/release/petrel" verify "$MCC/Sudoku-PT-AN01.pnml" --format json 2>/dev/null || true)
if printf '%s' "$probe" | grep -q '"edges": *1,'; then
    petrel=("$ROOT/target/release/petrel" verify)
    petrel_args=(--format json)
    petrel_name="petrel verify FILE --format json"
else
    cargo build --release --quiet -p petrel-verify --example explore >&2
    petrel=("$ROOT/target/release/examples/explore")
    petrel_args=()
    petrel_name="petrel-verify example explore FILE (petrel verify does not take PNML yet)"
fi
say "Petrel runs as: $petrel_name"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# `/usr/bin/time -v` output -> "seconds megabytes".
time_of() {
    awk -F': ' '
        /Elapsed \(wall clock\)/ {
            n = split($2, t, ":"); s = 0
            for (i = 1; i <= n; i++) s = s * 60 + t[i]
        }
        /Maximum resident set size/ { kb = $2 }
        END { printf "%.2f %.0f\n", s, kb / 1024 }' "$1"
}

# A JSON number field from Petrel's one-line output.
json_num() { grep -o "\"$1\": *[0-9]*" "$2" | head -n1 | sed 's/.*: *//'; }

# A CSV column from answers.csv for a model.
answer() {
    awk -F, -v m="$1" -v c="$2" '
        NR == 1 { for (i = 1; i <= NF; i++) if ($i == c) col = i; next }
        $1 == m { print $col }' "$MCC/answers.csv"
}

ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (a == "" || b == "" || b + 0 == 0) print "-"; else printf "%.1f\n", a / b }'; }

rows=()
for m in "${models[@]}"; do
    pnml="$MCC/$m.pnml"
    if [ ! -f "$pnml" ]; then
        say "no such model: $pnml"
        exit 2
    fi
    mcc_states=$(answer "$m" states)
    mcc_edges=$(answer "$m" rg_edges)

    say "$m: Petrel"
    # `petrel verify` exits 1 when the net has a deadlock or an unsafe place: a finding, not a
    # failure. Only a missing report is one.
    /usr/bin/time -v -o "$work/$m.petrel.time" "${petrel[@]}" "$pnml" "${petrel_args[@]}" \
        >"$work/$m.json" 2>"$work/$m.petrel.err" || grep -q '"states"' "$work/$m.json" || {
        cat "$work/$m.petrel.err" >&2
        say "$m: Petrel failed"
    }
    p_states=$(json_num states "$work/$m.json" || true)
    p_edges=$(json_num edges "$work/$m.json" || true)
    read -r p_s p_mb < <(time_of "$work/$m.petrel.time")
    mcc_ok=no
    [ "$p_states" = "$mcc_states" ] && [ "$p_edges" = "$mcc_edges" ] && mcc_ok=yes

    s_states="" s_edges="" s_s="" s_mb="" s_build="" agree="-"
    if [ -n "$anchors" ]; then
        say "$m: Spin (translate, compile)"
        dir="$work/$m.spin"
        mkdir -p "$dir"
        start=$(date +%s.%N)
        python3 "$anchors/pnml2pml.py" "$pnml" "$dir/model.pml"
        # MEMLIM in MB: far above what these models need, so pan never stops early;
        # VECTORSZ: NeoElection-PT-3 has 972 places, one byte each in the state vector.
        (cd "$dir" && spin -a model.pml >/dev/null &&
            gcc -O2 -DNOREDUCE -DSAFETY -DBFS -DMEMLIM=16384 -DVECTORSZ=4096 -o pan pan.c)
        s_build=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
        say "$m: Spin (run)"
        (cd "$dir" && /usr/bin/time -v -o pan.time ./pan -E >pan.out 2>&1) || {
            tail -n 20 "$dir/pan.out" >&2
            say "$m: pan failed"
        }
        if grep -q "states, stored" "$dir/pan.out"; then
            stored=$(awk '/states, stored/ { print $1; exit }' "$dir/pan.out")
            trans=$(awk '/transitions \(= stored\+matched\)/ { print $1; exit }' "$dir/pan.out")
            s_states=$((stored - 1))
            s_edges=$((trans - 2))
            agree=no
            [ "$s_states" = "$p_states" ] && [ "$s_edges" = "$p_edges" ] && agree=yes
        fi
        read -r s_s s_mb < <(time_of "$dir/pan.time")
    fi
    rows+=("| $m | ${p_states:-?} | ${p_edges:-?} | $mcc_ok | ${s_states:--} | ${s_edges:--} | $agree | $p_s | ${s_s:--} | ${s_build:--} | $p_mb | ${s_mb:--} | $(ratio "$s_s" "$p_s") | $(ratio "$s_mb" "$p_mb") |")
done

echo
echo "Petrel: $petrel_name"
echo "Spin: $(spin -V 2>/dev/null || echo 'not run'); pan built with gcc -O2 -DNOREDUCE -DSAFETY -DBFS, run ./pan -E"
echo "Machine: $(nproc) cores, $(awk '/MemTotal/ { printf "%.0f GB", $2 / 1048576 }' /proc/meminfo), $(date -u +%Y-%m-%d)"
echo
echo "| model | states (Petrel) | edges (Petrel) | = MCC | states (Spin) | edges (Spin) | agree | Petrel s | Spin s | Spin build s | Petrel MB | Spin MB | time Spin/Petrel | memory Spin/Petrel |"
echo "|---|---:|---:|:-:|---:|---:|:-:|---:|---:|---:|---:|---:|---:|---:|"
printf '%s\n' "${rows[@]}"
