//! Redermor flown live (issue 14's six scenarios): `petrel up missions/redermor` brings up the
//! player, the CAN data server on the in-memory bus with the Redermor simulator (20 times
//! faster than the wall clock) and the programs PLN, NAV (GDD, GUI, IDC) and EVT, all real
//! processes over iceoryx2. Each scenario checks the final marking, the events in the journal
//! and a property of the vehicle's true track (the simulator's `--sim-trace`).
//!
//! The bench mission is missions/redermor/bench/mission.toml: alpha (8 m deep) beyond the buoy
//! field, bravo (6 m above the seabed, 30 m deep), the end area south-east.

use std::path::{Path, PathBuf};
use std::process::Command;

use petrel_tests::{forget_vehicle, journal_json, petrel_bin, repo, unique_vehicle, TempProject};
use serde_json::Value;

/// The vehicle's true position and depth, one a second of its time (the trace's columns 1-3).
#[derive(Clone, Copy, Debug)]
struct Point {
    x: f64,
    y: f64,
    depth: f64,
}

/// What a flight left.
struct Flight {
    marking: Value,
    /// The journal's steps: (event, params, actions).
    steps: Vec<(String, Vec<String>, Vec<String>)>,
    trace: Vec<Point>,
    output: String,
    logs: PathBuf,
    _project: TempProject,
}

impl Flight {
    fn marked(&self, net: &str, place: &str) -> bool {
        self.marking[net]
            .as_array()
            .is_some_and(|m| m.iter().any(|p| p == place))
    }

    fn took(&self, event: &str) -> usize {
        self.steps.iter().filter(|(e, _, _)| e == event).count()
    }

    fn called(&self, action: &str) -> bool {
        self.steps
            .iter()
            .any(|(_, _, a)| a.iter().any(|a| a.starts_with(action)))
    }
}

fn bench() -> PathBuf {
    repo().join("missions/redermor/bench")
}

fn read_trace(path: &Path) -> Vec<Point> {
    let text = std::fs::read_to_string(path).expect("the simulator wrote its trace");
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|f| f.parse().expect("a number")).collect();
            Point {
                x: v[1],
                y: v[2],
                depth: v[3],
            }
        })
        .collect()
}

/// Flies scenario `scenario` (bench/SCENARIO.toml, and bench/SCENARIO.requests for the
/// operator when `requests`) with `petrel up`.
fn fly(scenario: &str, requests: bool) -> Flight {
    let bench = bench();
    let project = TempProject::copy(&repo().join("missions/redermor"), |name, text| {
        if name != "vehicle.toml" {
            return text;
        }
        let mut text = text.replace("nominal.toml", &format!("{scenario}.toml"));
        if requests {
            text = text.replace(
                r#""--role", "EVT", "--mission", "{project}/bench/mission.toml"]"#,
                &format!(
                    r#""--role", "EVT", "--mission", "{{project}}/bench/mission.toml", "--requests", "{{project}}/bench/{scenario}.requests"]"#
                ),
            );
        }
        text.replace("{project}/bench/", &format!("{}/", bench.display()))
    });
    let logs = project.path().join("logs");
    let vehicle = unique_vehicle("rdm");
    let out = Command::new(petrel_bin())
        .arg("up")
        .arg(project.path())
        .args(["--vehicle", &vehicle, "--logs"])
        .arg(&logs)
        .args(["--timeout", "400"])
        .output()
        .expect("petrel up runs");
    forget_vehicle(&vehicle);
    let output = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "petrel up failed:\n{output}");
    let marking = output
        .lines()
        .rev()
        .find_map(|l| l.split_once("last player status: ").map(|(_, s)| s))
        .and_then(|s| s.split_once("marking ").map(|(_, m)| m))
        .and_then(|m| serde_json::from_str(m).ok())
        .unwrap_or_else(|| panic!("no final marking in:\n{output}"));
    let (docs, o) = journal_json(&logs.join("journal"));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let strings = |v: &Value| -> Vec<String> {
        v.as_array()
            .map(|a| {
                a.iter()
                    .map(|x| x.as_str().unwrap_or("").to_owned())
                    .collect()
            })
            .unwrap_or_default()
    };
    let steps = docs
        .iter()
        .filter(|d| d["kind"] == "step")
        .map(|d| {
            (
                d["event"].as_str().unwrap_or("").to_owned(),
                strings(&d["params"]),
                strings(&d["actions"]),
            )
        })
        .collect();
    let trace = read_trace(&logs.join("trace.csv"));
    Flight {
        marking,
        steps,
        trace,
        output,
        logs,
        _project: project,
    }
}

/// The buoy field, as the mission file has it (the planner keeps 10 m more).
fn in_buoy_field(p: &Point) -> bool {
    (-40.0..=60.0).contains(&p.x) && (80.0..=130.0).contains(&p.y)
}

fn in_end_area(p: &Point) -> bool {
    (150.0..=220.0).contains(&p.x) && (-40.0..=0.0).contains(&p.y)
}

/// Every point of the area (a 10 m grid) came within half a swath (20 m), and 2 m for the
/// track's error where a line starts after a turn, of the submerged vehicle (below 2 m).
fn assert_covered(f: &Flight, name: &str, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) {
    let survey: Vec<&Point> = f.trace.iter().filter(|p| p.depth > 2.0).collect();
    let mut missed = Vec::new();
    let mut x = x0 + 5.0;
    while x < x1 {
        let mut y = y0 + 5.0;
        while y < y1 {
            if !survey.iter().any(|p| (p.x - x).hypot(p.y - y) <= 22.0) {
                missed.push((x, y));
            }
            y += 10.0;
        }
        x += 10.0;
    }
    assert!(missed.is_empty(), "{name}: not imaged at {missed:?}");
}

fn assert_clear_of_the_buoys(f: &Flight) {
    let inside: Vec<&Point> = f.trace.iter().filter(|p| in_buoy_field(p)).collect();
    assert!(inside.is_empty(), "in the buoy field: {inside:?}");
}

fn assert_flown_and_stopped(f: &Flight) {
    assert!(
        f.marked("MISSION", "stop") && f.marked("global", "flown"),
        "final marking {}\n{}",
        f.marking,
        f.output
    );
    assert!(!f.marked("global", "thrusters_on"), "{}", f.marking);
    assert_eq!(f.took("surfaced"), 1);
    assert!(f.called("call IDC.stop"));
}

#[test]
fn scenario_1_nominal_two_areas_surveyed_then_the_end_area() {
    let f = fly("nominal", false);
    assert_flown_and_stopped(&f);
    assert_eq!(f.took("next_area"), 2);
    assert_eq!(f.took("areas_done"), 1);
    assert_eq!(f.took("current_ok"), 2);
    assert_eq!(
        f.took("alarm") + f.took("leak") + f.took("depth_sensor_lost"),
        0
    );
    assert_clear_of_the_buoys(&f);
    assert_covered(&f, "alpha", (-20.0, 100.0), (200.0, 264.0));
    assert_covered(&f, "bravo", (160.0, 260.0), (100.0, 164.0));
    let last = f.trace.last().expect("a trace");
    assert!(in_end_area(last), "ends at {last:?}");
    assert!(last.depth < 0.5, "at the surface: {last:?}");

    // `petrel plot` draws the run: the map with the planned routes (one polyline for each
    // trajectory and sequence PLN gave) and the track, and the depth plot.
    let mission = bench().join("mission.toml");
    let o = Command::new(petrel_bin())
        .arg("plot")
        .arg(&f.logs)
        .arg("--mission")
        .arg(&mission)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let map = std::fs::read_to_string(f.logs.join("map.svg")).unwrap();
    let depth = std::fs::read_to_string(f.logs.join("depth.svg")).unwrap();
    assert!(map.starts_with("<svg") && depth.starts_with("<svg"));
    assert!(
        map.contains("surfaced") && map.contains("areas_done"),
        "events on the map"
    );
    // Without a trace, a clear refusal naming the file.
    let o = Command::new(petrel_bin())
        .arg("plot")
        .arg(f.logs.join("journal"))
        .arg("--mission")
        .arg(&mission)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("trace.csv"));
}

#[test]
fn scenario_2_alarm_in_the_first_transit_goes_to_the_end_area_round_the_buoys() {
    let f = fly("alarm", true);
    assert_flown_and_stopped(&f);
    assert_eq!(f.took("alarm"), 1);
    assert!(f.called("call PLN.itinerary([") && f.called("call PLN.trajectory(-1,"));
    // No area was surveyed: the vehicle never went below transit depth.
    assert!(f.trace.iter().all(|p| p.depth < 6.0));
    assert_eq!(f.took("areas_done"), 0);
    assert_clear_of_the_buoys(&f);
    let last = f.trace.last().expect("a trace");
    assert!(in_end_area(last), "ends at {last:?}");
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
    assert!(f.marked("EMERGENCY", "surfacing"), "{}", f.marking);
    for net in ["MISSION", "DECISION", "ACTION"] {
        assert!(
            f.marking.get(net).is_none(),
            "{net} still active: {}",
            f.marking
        );
    }
    assert_eq!(f.took("leak"), 1);
    assert!(f.called("call IDC.emergency_surface"));
    // Nothing was called after the leak but the emergency surfacing.
    let leak = f.steps.iter().position(|(e, _, _)| e == "leak").unwrap();
    for (e, _, actions) in &f.steps[leak + 1..] {
        assert!(
            actions.iter().all(|a| !a.starts_with("call")),
            "{e} called {actions:?}"
        );
    }
    // On the bus (the data server's record): from the first command after the leak was seen
    // that disables the thrusters, every thruster command disables them, at 0 rpm.
    let frames = thruster_commands_after_leak(&f.logs.join("bus.log"));
    let first_off = frames
        .iter()
        .position(|c| !c.2)
        .expect("the thrusters were disabled after the leak");
    assert!(first_off < frames.len());
    for c in &frames[first_off..] {
        assert_eq!(*c, (0, 0, false), "a thruster command after the stop");
    }
}

/// The thruster commands (rpm left, rpm right, enable) sent after the leak detector's first
/// wet reading, from a candump -L log.
fn thruster_commands_after_leak(log: &Path) -> Vec<(i16, i16, bool)> {
    let text = std::fs::read_to_string(log).expect("the bus was recorded");
    let mut wet = false;
    let mut out = Vec::new();
    for line in text.lines() {
        let Some((id, data)) = line
            .split_whitespace()
            .nth(2)
            .and_then(|f| f.split_once('#'))
        else {
            continue;
        };
        let bytes: Vec<u8> = (0..data.len() / 2)
            .filter_map(|i| u8::from_str_radix(&data[2 * i..2 * i + 2], 16).ok())
            .collect();
        match id {
            // Leak: bit 0 is water in the hull.
            "240" if bytes.first().is_some_and(|b| b & 1 == 1) => wet = true,
            // ThrusterCmd: two little-endian i16, then the enable bit.
            "100" if wet && bytes.len() == 5 => out.push((
                i16::from_le_bytes([bytes[0], bytes[1]]),
                i16::from_le_bytes([bytes[2], bytes[3]]),
                bytes[4] & 1 == 1,
            )),
            _ => {}
        }
    }
    out
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
