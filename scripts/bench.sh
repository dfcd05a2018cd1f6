#!/usr/bin/env bash
# The latency benchmark suite, one command, one report (docs/benchmarks.md, "Latency").
#
#   scripts/bench.sh                   # everything, about 10 minutes on 2 cores: rewrites the
#                                      # latency section of docs/benchmarks.md and docs/bench/*.svg
#   scripts/bench.sh --only transport  # one part (transport, vehicle, load, footprint, scale),
#                                      # printed only
#   scripts/bench.sh --short           # a few hundred rounds each, printed only (a smoke run;
#                                      # the test suite runs the same through cargo test)
#   scripts/bench.sh --no-vm           # without the vcan part (which boots the qemu VM)
#
# It builds `petrel`, the SDK's `echo` example and `petrel-bench` in release mode, then runs
# `petrel-bench run` with the given options (see `petrel-bench run --help`).
set -euo pipefail
cd "$(dirname "$0")/.."
echo "== building (release): petrel, examples/echo, petrel-bench" >&2
cargo build --release --locked -q -p petrel-cli -p petrel-programs -p petrel-bench \
    --bin petrel --bin petrel-bench --example echo
exec target/release/petrel-bench run "$@"
