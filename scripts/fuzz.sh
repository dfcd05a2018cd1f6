#!/usr/bin/env bash
# Petrel's fuzz targets (fuzz/), coverage-guided by libFuzzer, on the stable toolchain.
#
#   scripts/fuzz.sh build                 build every target (instrumented, release)
#   scripts/fuzz.sh run SECONDS [TARGET]  run each target (or one) for SECONDS from its corpus
#   scripts/fuzz.sh list                  the targets
#
# libfuzzer-sys brings libFuzzer itself (compiled from its C++ source by the build), so
# nothing is installed: the instrumentation is the one `cargo fuzz build --sanitizer none`
# asks rustc for, and every flag it needs is a stable codegen option (-C passes, -C
# llvm-args). `cargo fuzz run TARGET` works on the same directory for those who have
# cargo-fuzz (it needs RUSTC_BOOTSTRAP=1 on stable for its default address sanitizer).
#
# The seed corpora are made from the repository's own files (fuzz/seed.sh), into
# fuzz/corpus/TARGET; libFuzzer adds what it finds there. A crash is written to
# fuzz/artifacts/TARGET/ and fails the run; a target listed in PETREL_FUZZ_EXPECT_FAIL
# (space-separated) is run and reported but does not fail it (a known bug fixed elsewhere).
set -euo pipefail
cd "$(dirname "$0")/../fuzz"

targets=(net_parse net_check manifest can_toml pnml wire journal dbc candump script reload_mapping)
target_dir=${CARGO_TARGET_DIR:-target}
triple=$(rustc -vV | sed -n 's/^host: //p')
bin_dir="$target_dir/$triple/release"

build() {
    # The workspace's lock file pins every dependency the targets share with Petrel; cargo
    # adds libfuzzer-sys and its few dependencies to the copy. (A lock file of the fuzz
    # crate's own would go stale whenever a workspace crate changes its dependencies.)
    cp ../Cargo.lock Cargo.lock
    RUSTFLAGS="${RUSTFLAGS:-} --cfg fuzzing -Cpasses=sancov-module \
        -Cllvm-args=-sanitizer-coverage-level=4 \
        -Cllvm-args=-sanitizer-coverage-inline-8bit-counters \
        -Cllvm-args=-sanitizer-coverage-pc-table \
        -Cllvm-args=-sanitizer-coverage-trace-compares \
        -Cllvm-args=-simplifycfg-branch-fold-threshold=0 \
        -Cdebug-assertions -Coverflow-checks" \
        cargo build --release --target "$triple" --bins
}

# The longest input libFuzzer makes: the PNML seeds are the MCC models (up to 60 KB); text
# formats are found at a few kilobytes, and shorter inputs run faster.
max_len() {
    case $1 in
    pnml) echo 65536 ;;
    *) echo 16384 ;;
    esac
}

run() {
    local seconds=$1 only=${2:-}
    local failed=() expected_fail=" ${PETREL_FUZZ_EXPECT_FAIL:-} "
    for t in "${targets[@]}"; do
        [ -n "$only" ] && [ "$t" != "$only" ] && continue
        mkdir -p "corpus/$t" "artifacts/$t"
        # Seeded every run, not only when the corpus is empty: a corpus of an earlier run
        # lacks the files added to the repository since (a new mission's nets once crashed
        # the checker on a clean clone while a kept local corpus passed), and the crashes
        # found since are replayed all the same.
        ./seed.sh "$t"
        local log
        log=$(mktemp)
        local status=0
        # -rss_limit_mb: an allocation a crafted length asks for is a finding, not an OOM of
        # the machine; -timeout: one input taking seconds is a finding too.
        "$bin_dir/$t" "corpus/$t" -max_total_time="$seconds" -rss_limit_mb=2048 \
            -timeout=10 -max_len="$(max_len "$t")" -print_final_stats=1 \
            -artifact_prefix="artifacts/$t/" >"$log" 2>&1 || status=$?
        local execs
        execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
        if [ "$status" -eq 0 ]; then
            echo "fuzz $t: ${execs:-?} executions in ${seconds}s, no crash"
        elif [[ "$expected_fail" == *" $t "* ]]; then
            echo "fuzz $t: crashed as expected (a known bug fixed elsewhere): $(grep -m1 -E 'panicked|memory allocation|ERROR' "$log" || true)"
        else
            echo "fuzz $t: FAILED after ${execs:-?} executions (artifact in fuzz/artifacts/$t):"
            grep -E -A6 'panicked|ERROR|SUMMARY' "$log" | head -30
            failed+=("$t")
        fi
        rm -f "$log"
    done
    if [ "${#failed[@]}" -gt 0 ]; then
        echo "fuzz: ${#failed[@]} target(s) failed: ${failed[*]}"
        return 1
    fi
}

case "${1:-}" in
    build) build ;;
    run) run "${2:?seconds}" "${3:-}" ;;
    list) printf '%s\n' "${targets[@]}" ;;
    *) sed -n '2,18p' "$0"; exit 2 ;;
esac
