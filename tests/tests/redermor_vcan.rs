//! Redermor flown live on a real SocketCAN bus (issue 14: scenarios 1, 2 and 5 on vcan0):
//! `petrel up missions/redermor --file vehicle-vcan.toml` brings up the player, the simulator
//! as its own process on vcan0 (`redermor-sim`), `petrel bridge --bus vcan0` as the data server
//! between it and Petrel, and the programs PLN, NAV and EVT. Each scenario checks what the
//! in-memory flights check (redermor_live.rs): the final marking, the journal's events and a
//! property of the vehicle's true track.
//!
//! Where there is no vcan0 (this project's machines: a kernel without SocketCAN), each test
//! says why it is skipped and passes; with `PETREL_REQUIRE_VCAN=1` that is a failure instead.
//! The test suite runs them in the qemu VM (docs/vcan-vm.md), with the binaries they
//! start and the mission's files:
//!
//! ```sh
//! cargo build -p petrel-cli -p redermor-live
//! PETREL_REQUIRE_VCAN=1 scripts/vcan-vm.sh cargo-test --timeout 900 \
//!     --include "$PWD/target/debug/petrel" --include "$PWD/target/debug/redermor-program" \
//!     --include "$PWD/target/debug/redermor-sim" --include "$PWD/missions/redermor" \
//!     -p petrel-tests --test redermor_vcan -- --nocapture
//! ```
//!
//! (about 9 minutes; `--nocapture` shows where each flight's vehicle ended.)
//!
//! The flights share vcan0, so they take turns (`BUS`).

mod redermor_flight;

use std::path::Path;
use std::sync::{Mutex, MutexGuard};

use redermor_flight::{check_alarm, check_leak, check_nominal_route, fly_with, Flight};

/// The vehicle file on SocketCAN (its interface is vcan0).
const VEHICLE_FILE: &str = "vehicle-vcan.toml";

/// One flight at a time on vcan0: two data servers on one bus would read each other's
/// vehicle.
static BUS: Mutex<()> = Mutex::new(());

/// `PETREL_REQUIRE_VCAN` set (and not `0`): a missing vcan0 fails the tests.
fn required() -> bool {
    std::env::var("PETREL_REQUIRE_VCAN").is_ok_and(|v| !v.is_empty() && v != "0")
}

/// The bus's turn when vcan0 is there; otherwise says why the test is skipped (or fails, when
/// the interface is required).
fn vcan0_or_skip(test: &str) -> Option<MutexGuard<'static, ()>> {
    // A vcan interface exists only where the kernel has SocketCAN: its sysfs entry says it.
    if Path::new("/sys/class/net/vcan0").exists() {
        // A flight that failed poisons the lock; the bus is free all the same.
        return Some(BUS.lock().unwrap_or_else(|e| e.into_inner()));
    }
    assert!(
        !required(),
        "PETREL_REQUIRE_VCAN is set but there is no vcan0 here"
    );
    eprintln!(
        "{test}: skipped: no SocketCAN interface vcan0 in this kernel; run it in the qemu VM \
         (tests/tests/redermor_vcan.rs says how, scripts/test.sh does it)"
    );
    None
}

/// Flies `scenario` with the simulator `speed` times faster than the wall clock.
fn fly(scenario: &str, requests: bool, speed: u32) -> Flight {
    fly_with(
        VEHICLE_FILE,
        &[("\"--speed\", \"5\"", &format!("\"--speed\", \"{speed}\""))],
        scenario,
        requests,
    )
}

#[test]
fn vcan_scenario_1_nominal_two_areas_surveyed_then_the_end_area() {
    let Some(_bus) = vcan0_or_skip("vcan_scenario_1") else {
        return;
    };
    let f = fly("nominal", false, 5);
    // The route, the events and the safety of the track; not the coverage of the survey lines
    // to the metre, which redermor_live.rs checks: under emulation NAV steers several times
    // less often than on the host, and a line's end may fall a few metres short.
    check_nominal_route(&f);
}

#[test]
fn vcan_scenario_2_alarm_in_the_first_transit_goes_to_the_end_area_round_the_buoys() {
    let Some(_bus) = vcan0_or_skip("vcan_scenario_2") else {
        return;
    };
    let f = fly("alarm", true, 5);
    check_alarm(&f);
}

#[test]
fn vcan_scenario_5_leak_stops_the_thrusters_and_nothing_else_runs() {
    let Some(_bus) = vcan0_or_skip("vcan_scenario_5") else {
        return;
    };
    let f = fly("leak", false, 5);
    check_leak(&f);
}
