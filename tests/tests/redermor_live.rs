//! Redermor flown live (issue 14's six scenarios): `petrel up missions/redermor` brings up the
//! player, the CAN data server on the in-memory bus with the Redermor simulator (20 times
//! faster than the wall clock) and the programs PLN, NAV (GDD, GUI, IDC) and EVT, all real
//! processes over iceoryx2. Each scenario checks the final marking, the events in the journal
//! and a property of the vehicle's true track (the simulator's `--trace`).
//!
//! The mission is missions/redermor/sim/mission.toml: alpha (8 m deep) beyond the buoy
//! field, bravo (6 m above the seabed, 30 m deep), the end area south-east.

mod redermor_flight;

use std::process::Command;

use petrel_tests::petrel_bin;
use redermor_flight::{
    assert_clear_of_the_buoys, assert_covered, assert_flown_and_stopped, assert_only_emergency,
    check_alarm, check_leak, check_nominal, check_nominal_route, fly, fly_killing, fly_with,
    thruster_commands,
};

#[test]
fn scenario_1_nominal_two_areas_surveyed_then_the_end_area() {
    let f = fly("nominal", false);
    check_nominal(&f);

    // `petrel plot` draws the run from its journal and its bus recording, as map.toml says:
    // the areas, the planned routes (one polyline for each trajectory and sequence PLN gave),
    // the simulator's track, the events where they happened; and the depth profile.
    let o = Command::new(petrel_bin())
        .arg("plot")
        .arg(&f.logs)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let map = std::fs::read_to_string(f.logs.join("map.svg")).unwrap();
    let profile = std::fs::read_to_string(f.logs.join("profile.svg")).unwrap();
    assert!(map.starts_with("<svg") && profile.starts_with("<svg"));
    for area in ["alpha", "bravo", "buoy_field", "end"] {
        assert!(
            map.contains(&format!("data-area=\"{area}\"")),
            "{area} on the map"
        );
    }
    assert!(
        map.contains("surfaced") && map.contains("areas_done"),
        "events on the map"
    );
    let routes = f.took("trajectory") + f.took("sequence");
    assert!(
        map.contains(&format!("data-layer=\"routes\" data-count=\"{routes}\"")),
        "{routes} planned routes"
    );
    // The track is the simulator's, about one position a metre flown (the trace has one a
    // second of the vehicle's time, at 1.5 m/s).
    let points: usize = map
        .split("data-track=\"0\" data-points=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    assert!(
        points > f.trace.len(),
        "{points} positions, {} in the trace",
        f.trace.len()
    );
    assert!(map.contains("Legend") && map.contains("data-layer=\"scale\""));
    // Without a bus recording, the track from signals is empty, and said so; the map is
    // drawn from the journal alone.
    let o = Command::new(petrel_bin())
        .arg("plot")
        .arg(f.logs.join("journal"))
        .arg("--out")
        .arg(f.logs.join("journal-only"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no position in this run"));
}

/// A slow or loaded vehicle computer: the simulator three times faster than in vehicle.toml, so
/// that every wall-clock delay of the processes (NAV's control step, the player's answer to
/// `route_done`, the stop) is three times longer in the vehicle's time, as under the VM
/// VM's emulation. NAV still surfaces the vehicle where its route to the end area ended
/// and stops it there (before NAV did so, it surfaced on the move and coasted on, ending 15 m
/// outside the end area).
#[test]
fn scenario_1_on_a_slow_vehicle_computer_still_ends_in_the_end_area() {
    let f = fly_with(
        "vehicle.toml",
        &[("\"--speed\", \"20\"", "\"--speed\", \"60\"")],
        "nominal",
        false,
    );
    // The route and the end; the survey's coverage to the metre is scenario 1's, at the
    // vehicle's own pace.
    check_nominal_route(&f);
}

#[test]
fn scenario_2_alarm_in_the_first_transit_goes_to_the_end_area_round_the_buoys() {
    let f = fly("alarm", true);
    check_alarm(&f);
}

#[test]
fn scenario_3_current_on_arrival_replans_the_survey_which_still_covers() {
    let f = fly("current", false);
    assert_flown_and_stopped(&f);
    // Neither area predicted a current: both surveys are planned again for the measured one.
    assert_eq!(f.took("current_differs"), 2, "{:?}", f.steps);
    assert_eq!(f.took("current_ok"), 0);
    assert_clear_of_the_buoys(&f);
    assert_covered(&f, "alpha", (-20.0, 100.0), (200.0, 264.0));
    assert_covered(&f, "bravo", (160.0, 260.0), (100.0, 164.0));
}

#[test]
fn scenario_4_inspection_mid_survey_goes_round_the_object_and_the_survey_resumes() {
    let f = fly("inspection", true);
    assert_flown_and_stopped(&f);
    assert_eq!(f.took("inspect_request"), 1);
    assert_eq!(f.took("inspection_flown"), 1);
    assert!(f.called("call GUI.suspend") && f.called("call GUI.resume"));
    // Round the object at (50, 240): the sonar (half a swath, 20 m) saw the middle of each
    // side of the 25 m square flown round it.
    for (x, y) in [(25.0, 240.0), (75.0, 240.0), (50.0, 215.0), (50.0, 265.0)] {
        assert!(
            f.trace.iter().any(|p| (p.x - x).hypot(p.y - y) < 20.0),
            "never near ({x}, {y})"
        );
    }
    assert_clear_of_the_buoys(&f);
    assert_covered(&f, "alpha", (-20.0, 100.0), (200.0, 264.0));
    assert_covered(&f, "bravo", (160.0, 260.0), (100.0, 164.0));
}

#[test]
fn scenario_5_leak_stops_the_thrusters_and_nothing_else_runs() {
    let f = fly("leak", false);
    check_leak(&f);
}

#[test]
fn scenario_6_depth_sensor_silent_aborts_at_the_surface() {
    let f = fly("depth_sensor", false);
    assert_flown_and_stopped(&f);
    assert_eq!(f.took("depth_sensor_lost"), 1);
    assert!(f.called("call GUI.stop") && f.called("call IDC.surface"));
    assert_eq!(f.took("areas_done"), 0);
    let last = f.trace.last().expect("a trace");
    assert!(last.depth < 0.5, "at the surface: {last:?}");
}

/// The planner's process crashes (SIGKILL) during the first transit: the player's liveness
/// check raises `program_lost("PLN")`, DECISION gives the mission up and ACTION brings the
/// vehicle up where it is; it ends stopped at the surface, short of the survey.
#[test]
fn scenario_7_planner_crash_mid_transit_surfaces_where_the_vehicle_is() {
    let f = fly_killing("nominal", "PLN", 2.0);
    assert!(
        f.steps
            .iter()
            .any(|(e, p, _)| e == "program_lost" && p == &["\"PLN\""]),
        "{:?}",
        f.steps
    );
    assert_flown_and_stopped(&f);
    assert!(f.called("call GUI.stop") && f.called("call IDC.surface"));
    assert_eq!(f.took("areas_done"), 0, "the survey was given up");
    let last = f.trace.last().expect("a trace");
    assert!(last.depth < 0.5, "at the surface: {last:?}");
}

/// The navigation process (GDD, GUI, IDC: the pilot) crashes (SIGKILL) during the first
/// transit: with IDC lost, EMERGENCY takes every other net down and stops the thrusters itself
/// through the CAN data server (`CAN.ThrusterCmd(0, 0, false)`): the last thruster command on
/// the bus disables them (the buoyant vehicle rises).
#[test]
fn scenario_8_pilot_crash_stops_the_thrusters_through_the_data_server() {
    let f = fly_killing("nominal", "NAV", 2.0);
    assert_only_emergency(&f, "unpiloted");
    assert!(f.called("call CAN.ThrusterCmd(0.0, 0.0, false)"));
    // IDC's own commands enable the thrusters, and a killed IDC sends nothing more: the last
    // command on the bus is the supervisor's. (The run ends at that final marking, so the
    // simulator's trace stops before the vehicle has risen far.)
    let frames = thruster_commands(&f.logs.join("bus.log"));
    assert!(
        frames.iter().any(|c| c.2),
        "IDC flew the vehicle: {frames:?}"
    );
    assert_eq!(frames.last(), Some(&(0, 0, false)), "{frames:?}");
}
