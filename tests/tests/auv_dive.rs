//! The AUV mission (`missions/auv`) flown by real processes over real iceoryx2: `petrel play`,
//! `auv-bridge --bus memory` (the CAN data server on an in-process bus with the simulated
//! AUV, which obeys the commands only while the heartbeat comes) and the guidance program
//! `auv-gui`, which commands the thrusters through the data server and reads its signals.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use petrel_tests::{petrel_bin, repo, unique_vehicle, vehicle_bin, Player, Processes, TempProject};

fn marked(s: &serde_json::Value, net: &str, place: &str) -> bool {
    s["marking"][net]
        .as_array()
        .is_some_and(|m| m.iter().any(|p| p == place))
}

/// missions/auv with its sensors' staleness bounds loosened from 300-500 ms to 30 s: they
/// count in wall-clock time, and on a loaded 2-core machine the data server's in-process
/// simulator once stalled long enough to raise `sensor_lost` mid-dive (the staleness rules have
/// tests of their own in can_bridge). The dive is what these tests are about.
fn auv_project() -> TempProject {
    TempProject::copy(&repo().join("missions/auv"), |name, text| {
        if name != "can.toml" {
            return text;
        }
        for bound in ["periods = 3 ", "timeout = \"500ms\""] {
            assert!(
                text.contains(bound),
                "missions/auv/can.toml has no `{bound}`"
            );
        }
        text.replace("periods = 3 ", "timeout = \"30s\" ")
            .replace("timeout = \"500ms\"", "timeout = \"30s\"")
    })
}

/// The data server (recording the bus to `log`, its standard error to `stderr`) and the
/// guidance program; returns once both are on the vehicle.
fn start_vehicle(
    project: &Path,
    vehicle: &str,
    log: &Path,
    stderr: &Path,
    bridge_flags: &[&str],
) -> Processes {
    let bridge = Command::new(vehicle_bin("auv-bridge"))
        .arg(project)
        .args(["--vehicle", vehicle, "--bus", "memory", "--record"])
        .arg(log)
        .args(bridge_flags)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(stderr).unwrap())
        .spawn()
        .expect("auv-bridge starts");
    let gui = Command::new(vehicle_bin("auv-gui"))
        .args(["--vehicle", vehicle])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("auv-gui starts");
    let processes = Processes(vec![gui, bridge]);
    let v = petrel_ipc::Vehicle::new(vehicle).unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        let can = petrel_ipc::is_program_alive(&v, "CAN").unwrap_or(false);
        let gui = petrel_ipc::is_program_alive(&v, "GUI").unwrap_or(false);
        if can && gui {
            return processes;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("the data server and the guidance program did not join {vehicle}");
}

/// The events the recorded bus gives offline (`petrel bridge --replay`), as (name, params).
fn replayed(project: &Path, log: &Path) -> Vec<(String, Vec<serde_json::Value>)> {
    let out = Command::new(petrel_bin())
        .arg("bridge")
        .arg(project)
        .arg("--replay")
        .arg(log)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            (
                v["event"].as_str().unwrap().to_owned(),
                v["params"].as_array().unwrap().clone(),
            )
        })
        .collect()
}

/// Flies the mission; returns the player's last status and the recorded bus's events.
fn dive(
    bridge_flags: &[&str],
    done: impl Fn(&serde_json::Value) -> bool,
) -> (serde_json::Value, Vec<(String, Vec<serde_json::Value>)>) {
    let vehicle = unique_vehicle("auv");
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("bus.log");
    let bridge_err = dir.path().join("bridge.err");
    let project = auv_project();
    let player = Player::start(project.path(), &vehicle);
    let vehicle_processes =
        start_vehicle(project.path(), &vehicle, &log, &bridge_err, bridge_flags);
    let o = player.send("start_mission", 1);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = player.wait_for(60.0, &done);
    // SIGTERM: the data server stops in good order (exit 0) and flushes its recording.
    let codes = vehicle_processes.stop();
    assert_eq!(codes, [Some(0), Some(0)], "auv-gui, auv-bridge");
    // Before leaving, the data server saw the player acknowledge every event it sent.
    let report = std::fs::read_to_string(&bridge_err).unwrap();
    assert!(
        report.contains("unacknowledged: false") && report.contains("events_dropped: 0"),
        "{report}"
    );
    assert!(player.stop().success());
    (s, replayed(project.path(), &log))
}

fn depth(params: &[serde_json::Value]) -> f64 {
    params[0].as_f64().unwrap()
}

#[test]
fn the_survey_dives_surveys_and_surfaces_through_the_can_bus() {
    let (s, bus_events) = dive(&[], |s| marked(s, "PHASES", "surfaced"));
    assert!(marked(&s, "PHASES", "surfaced"), "{s}");
    assert!(marked(&s, "SAFETY", "watching"), "{s}");
    let st = &s["stats"];
    assert_eq!(st["calls_failed"], 0, "{s}");
    assert_eq!(st["bad_messages"], 0, "{s}");
    assert_eq!(st["refused"], 0, "{s}");
    // start_mission, depth_reached, area_reached, survey_done, area_reached, depth_reached.
    assert!(st["processed"].as_u64().unwrap() >= 6, "{s}");
    // `petrel status` shows the data server too (its own heartbeat): a healthy bus, frames
    // from the simulated sensors, the commands of the nets and of GUI.
    let b = &s["can_bridge"];
    assert_eq!(b["interface"], "mem0", "{s}");
    assert_eq!(b["bus_state"], "error_active", "{s}");
    assert!(b["frames"].as_u64().unwrap() > 50, "{s}");
    assert_eq!(b["unknown_id"], 0, "{s}");
    // DepthCmd and ThrusterCmd to dive, GUI's three ThrusterCmd and its DepthCmd to surface.
    assert!(b["commands"].as_u64().unwrap() >= 6, "{s}");
    assert_eq!(b["commands_failed"], 0, "{s}");
    // The bus, recorded by the data server: the commanded 10 m reached going down (by the
    // nets' DepthCmd), the surface reached coming up (by GUI's own DepthCmd through CAN).
    let names: Vec<&str> = bus_events.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["depth_reached", "depth_reached"], "{bus_events:?}");
    let (down, up) = (depth(&bus_events[0].1), depth(&bus_events[1].1));
    assert!((9.5..=10.0).contains(&down), "{bus_events:?}");
    assert!((0.0..=0.5).contains(&up), "{bus_events:?}");
}

#[test]
fn a_leak_at_depth_aborts_the_mission_and_the_vehicle_surfaces() {
    let (s, bus_events) = dive(&["--leak-at", "5"], |s| marked(s, "SAFETY", "surfaced"));
    assert!(marked(&s, "SAFETY", "surfaced"), "{s}");
    assert!(
        s["marking"].get("PHASES").is_none(),
        "PHASES is inactive: {s}"
    );
    assert_eq!(s["stats"]["calls_failed"], 0, "{s}");
    // The leak held 200 ms on the bus, then the surface reached by SAFETY's DepthCmd(0).
    let names: Vec<&str> = bus_events.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["leak", "depth_reached"], "{bus_events:?}");
    assert!(depth(&bus_events[1].1) <= 0.5, "{bus_events:?}");
}
