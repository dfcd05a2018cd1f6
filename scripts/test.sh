#!/usr/bin/env bash
# The whole Petrel test suite, from a fresh Debian machine of the project's kind.
# It installs what it needs by itself, then runs formatting, lints and every test.
set -euo pipefail
cd "$(dirname "$0")/.."

# Debian packages the suite needs: graphviz checks that `petrel dot` output is real DOT and
# lays out `petrel monitor`'s drawing; chromium and its WebDriver (chromium-driver) load the
# monitor's page in a real headless browser (tests/tests/monitor.rs).
need=()
command -v dot >/dev/null 2>&1 || need+=(graphviz)
command -v chromium >/dev/null 2>&1 || need+=(chromium)
command -v chromedriver >/dev/null 2>&1 || need+=(chromium-driver)
# The Debian package and its unit (cli/tests/install.rs, docs/install.md): dpkg-shlibdeps
# (dpkg-dev) and strip (binutils) make it, debootstrap the Debian it is installed into,
# systemd-analyze (systemd) verifies the unit.
command -v dpkg-shlibdeps >/dev/null 2>&1 || need+=(dpkg-dev)
command -v strip >/dev/null 2>&1 || need+=(binutils)
command -v debootstrap >/dev/null 2>&1 || need+=(debootstrap)
command -v systemd-analyze >/dev/null 2>&1 || need+=(systemd)
# Installed above: the browser and package tests fail rather than skip if a tool is missing.
export PETREL_REQUIRE_BROWSER=1
export PETREL_REQUIRE_PACKAGE=1
if [ "${#need[@]}" -gt 0 ]; then
    echo "== installing ${need[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --locked -- -D warnings
# cargo test also runs the latency suite in its short mode (bench/tests/short.rs: a few hundred
# rounds of every part but the VM's, its report and plots written to a temporary folder, no time
# asserted), so that scripts/bench.sh cannot rot.
echo "== cargo test"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
cargo test --workspace --locked 2>&1 | tee "$log"

# Fuzzing: every target of fuzz/ built with libFuzzer on the stable toolchain and run a few
# seconds from a corpus seeded with the repository's files and every input that once crashed
# it (scripts/fuzz.sh; docs/testing.md has the long run). A crash fails the suite.
echo "== fuzz targets, ${PETREL_FUZZ_SECONDS:-5} s each"
fuzz_build=$(mktemp)
if ! scripts/fuzz.sh build >"$fuzz_build" 2>&1; then
    cat "$fuzz_build"
    exit 1
fi
tail -n 1 "$fuzz_build"
rm -f "$fuzz_build"
scripts/fuzz.sh run "${PETREL_FUZZ_SECONDS:-5}" 2>&1 | tee -a "$log"

# Real SocketCAN: this kernel has none, so the CAN bridge's socket tests run on a real vcan0
# inside a qemu VM (scripts/vcan-vm.sh installs and caches what it needs; on a machine whose
# kernel has vcan it runs them directly). A failure inside fails the suite.
echo "== CAN bridge on a real vcan0 (in the VM)"
for test in socketcan vcan; do
    PETREL_REQUIRE_VCAN=1 scripts/vcan-vm.sh cargo-test -p petrel-can-bridge --test "$test" 2>&1 | tee -a "$log"
done

# Redermor flown on a real vcan0 in the same VM (tests/tests/redermor_vcan.rs): scenarios 1, 2
# and 5 with `petrel up --file missions/redermor/vehicle-vcan.toml`, the simulator as its own
# process on the bus (redermor-sim) and `petrel bridge --bus vcan0` as the data server. Debug
# binaries (cargo test built most of them; this builds what is missing), the simulator 5 times
# faster than the wall clock; about 9 minutes under emulation (docs/vcan-vm.md). A failure
# inside fails the suite.
echo "== Redermor on a real vcan0 (in the VM)"
cargo build --locked -p petrel-cli -p redermor-live
PETREL_REQUIRE_VCAN=1 scripts/vcan-vm.sh cargo-test --timeout 900 \
    --include "$PWD/target/debug/petrel" --include "$PWD/target/debug/redermor-program" \
    --include "$PWD/target/debug/redermor-sim" --include "$PWD/missions/redermor" \
    -p petrel-tests --test redermor_vcan -- --nocapture 2>&1 | tee -a "$log"

# One closing line for the whole suite (every `test result:` line above, host and VM).
grep -E '^test result: ' "$log" | awk '{p += $4; f += $6} END {printf "%d passed, %d failed\n", p, f}'
