//! The AUV's data server, `auv-bridge`, as a process: `petrel bridge`'s command line with the
//! simulated AUV on the memory bus, and its own option `--leak-at`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use petrel_can_bridge::dbc::DecodeOutcome;
use petrel_can_bridge::log::parse_line;
use petrel_can_bridge::Dbc;
use petrel_tests::programs::TestVehicle;
use petrel_tests::{repo, Processes, Workdir};

const BRIDGE: &str = env!("CARGO_BIN_EXE_auv-bridge");

fn auv() -> PathBuf {
    repo().join("missions/auv")
}

/// Serves missions/auv on the memory bus for `vehicle` with `flags`, recording the bus, until
/// the data server has been on the vehicle for a second; the recorded frames' `MESSAGE.signal`
/// values, in order.
fn recorded(vehicle: &TestVehicle, flags: &[&str]) -> Vec<(String, String, f64)> {
    let work = Workdir::new();
    let log = work.path().join("bus.log");
    let child = Command::new(BRIDGE)
        .arg(auv())
        .args(["--vehicle", vehicle.name(), "--bus", "memory", "--record"])
        .arg(&log)
        .args(flags)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .spawn()
        .expect("auv-bridge starts");
    let server = Processes(vec![child]);
    let deadline = Instant::now() + Duration::from_secs(20);
    while !petrel_ipc::is_program_alive(&vehicle.vehicle, "CAN").unwrap_or(false) {
        assert!(
            Instant::now() < deadline,
            "auv-bridge did not join the vehicle"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_secs(1));
    // SIGTERM: the server stops in good order (exit 0) and flushes its recording.
    assert_eq!(server.stop(), [Some(0)]);
    decode(&log)
}

fn decode(log: &Path) -> Vec<(String, String, f64)> {
    let dbc = Arc::new(Dbc::load(&auv().join("auv.dbc")).unwrap());
    let text = std::fs::read_to_string(log).unwrap();
    let mut values = Vec::new();
    for line in text.lines() {
        let record = parse_line(line).unwrap();
        if let DecodeOutcome::Message(dm) = dbc.decode(&record.frame) {
            let m = dbc.message(dm.message).unwrap();
            for s in &dm.signals {
                let name = m.signals[s.signal.signal].name.clone();
                values.push((m.name.clone(), name, s.physical));
            }
        }
    }
    values
}

fn last(values: &[(String, String, f64)], message: &str, signal: &str) -> Option<f64> {
    values
        .iter()
        .rev()
        .find(|(m, s, _)| m == message && s == signal)
        .map(|v| v.2)
}

#[test]
fn the_simulated_auv_is_on_the_memory_bus_and_its_hull_is_sound() {
    let v = TestVehicle::new();
    let values = recorded(&v, &[]);
    // The vehicle's sensors, ten a second: at the surface, thrusters off, no leak.
    let depths = values
        .iter()
        .filter(|(m, s, _)| m == "Depth" && s == "depth");
    assert!(depths.count() >= 5, "{values:?}");
    assert_eq!(last(&values, "Depth", "depth"), Some(0.0));
    assert_eq!(last(&values, "Leak", "leak"), Some(0.0));
    assert_eq!(last(&values, "Leak", "sensor_ok"), Some(1.0));
}

#[test]
fn leak_at_makes_the_hull_leak_from_that_depth() {
    let v = TestVehicle::new();
    // At the surface already: the leak detector is set from the first tick.
    let values = recorded(&v, &["--leak-at", "0"]);
    assert_eq!(last(&values, "Leak", "leak"), Some(1.0), "{values:?}");
}

#[test]
fn leak_at_must_be_a_finite_number() {
    for bad in ["nan", "inf", "deep"] {
        let o = Command::new(BRIDGE)
            .arg(auv())
            .args(["--leak-at", bad])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{bad}: {err}");
        assert!(err.contains("--leak-at"), "{bad}: {err}");
    }
}

#[test]
fn a_project_without_can_toml_is_refused_with_its_reason() {
    let o = Command::new(BRIDGE)
        .arg(repo().join("missions/uav"))
        .args(["--bus", "memory"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("has no can.toml"), "{err}");
}
