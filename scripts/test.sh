#!/usr/bin/env bash
# The whole Petrel test suite, from a fresh Debian machine of the project's kind.
# It installs what it needs by itself, then runs formatting, lints and every test.
set -euo pipefail
cd "$(dirname "$0")/.."

# System packages the suite needs (none yet beyond the Rust toolchain; later issues add the
# vcan bench's). apt is only touched when something is missing.
need=()
for pkg in "$@"; do :; done
if [ "${#need[@]}" -gt 0 ]; then
    apt-get update -qq && apt-get install -y -qq "${need[@]}"
fi

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --locked -- -D warnings
echo "== cargo test"
cargo test --workspace --locked
