//! The UAV mission flown by real processes over real iceoryx2: `petrel play`, and the GUI/PLD
//! and DEC programs of `petrel-programs`, each its own process.

use petrel_tests::{repo, unique_vehicle, vehicle_bin, Player, Processes};
use std::process::{Command, Stdio};

fn programs(vehicle: &str, gui_flags: &[&str]) -> Processes {
    let gui = Command::new(vehicle_bin("uav-gui"))
        .args(["--vehicle", vehicle])
        .args(gui_flags)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("uav-gui starts");
    let dec = Command::new(vehicle_bin("uav-dec"))
        .args(["--vehicle", vehicle])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("uav-dec starts");
    Processes(vec![gui, dec])
}

fn marked(s: &serde_json::Value, net: &str, place: &str) -> bool {
    s["marking"][net]
        .as_array()
        .is_some_and(|m| m.iter().any(|p| p == place))
}

/// Waits until both programs are seen alive by liveness (their nodes exist), so the first call
/// is not refused.
fn wait_programs(vehicle: &str) {
    let v = petrel_ipc::Vehicle::new(vehicle).unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while std::time::Instant::now() < deadline {
        let gui = petrel_ipc::is_program_alive(&v, "GUI").unwrap_or(false);
        let dec = petrel_ipc::is_program_alive(&v, "DEC").unwrap_or(false);
        if gui && dec {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    panic!("the UAV programs did not start");
}

fn fly(gui_flags: &[&str], done: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let vehicle = unique_vehicle("uav");
    let player = Player::start(&repo().join("missions/uav"), &vehicle);
    let programs = programs(&vehicle, gui_flags);
    wait_programs(&vehicle);
    let o = player.send("start_mission", 1);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = player.wait_for(30.0, &done);
    // Programs first, so the player's cleanup finds the vehicle empty.
    drop(programs);
    assert!(player.stop().success());
    s
}

#[test]
fn the_nominal_flight_lands_at_the_base() {
    let s = fly(&[], |s| marked(s, "MISSION", "landed"));
    assert!(marked(&s, "MISSION", "landed"), "{s}");
    assert!(marked(&s, "EVENTS", "watching"), "{s}");
    let st = &s["stats"];
    assert_eq!(st["calls_failed"], 0, "{s}");
    assert_eq!(st["bad_messages"], 0, "{s}");
    // roll, takeoff, climb, then 3 waypoints (next_waypoint, transit, use_payload, ...).
    assert!(st["calls_sent"].as_u64().unwrap() >= 15, "{s}");
}

#[test]
fn a_payload_failure_replans_and_still_lands_at_the_base() {
    let s = fly(&["--fail-payload-after", "1"], |s| {
        marked(s, "MISSION", "landed")
    });
    assert!(marked(&s, "MISSION", "landed"), "{s}");
    assert_eq!(s["stats"]["calls_failed"], 0, "{s}");
}

#[test]
fn an_engine_failure_diverts_to_the_emergency_site() {
    let s = fly(&["--engine-failure-after", "1"], |s| {
        marked(s, "EVENTS", "landed")
    });
    assert!(marked(&s, "EVENTS", "landed"), "{s}");
    assert!(
        s["marking"].get("MISSION").is_none(),
        "MISSION is inactive: {s}"
    );
}
