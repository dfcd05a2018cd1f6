//! What a live Redermor flight leaves (the final marking, the journal's steps, the vehicle's
//! true track) and the properties the scenarios check, shared by the flights on the in-memory
//! bus (redermor_live.rs) and on a real vcan0 (redermor_vcan.rs).
// Each test file uses its own part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use petrel_tests::{forget_vehicle, journal_json, petrel_bin, repo, unique_vehicle, TempProject};
use serde_json::Value;

/// The vehicle's true position and depth, one a second of its time (the trace's columns 1-3).
#[derive(Clone, Copy, Debug)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub depth: f64,
}

/// What a flight left.
pub struct Flight {
    pub marking: Value,
    /// The journal's steps: (event, params, actions).
    pub steps: Vec<(String, Vec<String>, Vec<String>)>,
    pub trace: Vec<Point>,
    pub output: String,
    pub logs: PathBuf,
    _project: TempProject,
}

impl Flight {
    pub fn marked(&self, net: &str, place: &str) -> bool {
        self.marking[net]
            .as_array()
            .is_some_and(|m| m.iter().any(|p| p == place))
    }

    pub fn took(&self, event: &str) -> usize {
        self.steps.iter().filter(|(e, _, _)| e == event).count()
    }

    /// The journal's steps, one per line (event, parameters, actions), for a failed
    /// assertion's message: the path the mission took, not only that it went wrong.
    pub fn story(&self) -> String {
        self.steps
            .iter()
            .map(|(e, p, a)| format!("{e}({}) -> {}\n", p.join(", "), a.join("; ")))
            .collect()
    }

    pub fn called(&self, action: &str) -> bool {
        self.steps
            .iter()
            .any(|(_, _, a)| a.iter().any(|a| a.starts_with(action)))
    }
}

/// The simulator's files: the mission, the scenarios, the operator's requests.
pub fn sim_files() -> PathBuf {
    repo().join("missions/redermor/sim")
}

pub fn read_trace(path: &Path) -> Vec<Point> {
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

/// Flies scenario `scenario` (sim/SCENARIO.toml, and sim/SCENARIO.requests for the
/// operator when `requests`) with `petrel up` on the in-memory bus (vehicle.toml).
pub fn fly(scenario: &str, requests: bool) -> Flight {
    fly_with("vehicle.toml", &[], scenario, requests)
}

/// Flies scenario `scenario` with `petrel up --file VEHICLE_FILE` (a vehicle file of
/// missions/redermor: vehicle.toml, or vehicle-vcan.toml on SocketCAN), with each
/// `(from, to)` of `edits` replaced in it.
pub fn fly_with(
    vehicle_file: &str,
    edits: &[(&str, &str)],
    scenario: &str,
    requests: bool,
) -> Flight {
    fly_and(vehicle_file, edits, scenario, requests, None)
}

/// Flies scenario `scenario` on the in-memory bus and, once the vehicle is `depth` metres down
/// (the simulator's trace), SIGKILLs the program process of role `role` (`--role ROLE`:
/// PLN, NAV, EVT): a crash mid-mission. `petrel up` then ends with status 1 (a process failed)
/// once the mission is over.
pub fn fly_killing(scenario: &str, role: &str, depth: f64) -> Flight {
    fly_and("vehicle.toml", &[], scenario, false, Some((role, depth)))
}

fn fly_and(
    vehicle_file: &str,
    edits: &[(&str, &str)],
    scenario: &str,
    requests: bool,
    kill: Option<(&str, f64)>,
) -> Flight {
    let sim = sim_files();
    let project = TempProject::copy(&repo().join("missions/redermor"), |name, text| {
        if name != vehicle_file {
            return text;
        }
        let mut text = text.replace("nominal.toml", &format!("{scenario}.toml"));
        for (from, to) in edits {
            assert!(text.contains(from), "{vehicle_file} has no {from}");
            text = text.replace(from, to);
        }
        if requests {
            text = text.replace(
                r#""--role", "EVT", "--mission", "{project}/sim/mission.toml"]"#,
                &format!(
                    r#""--role", "EVT", "--mission", "{{project}}/sim/mission.toml", "--requests", "{{project}}/sim/{scenario}.requests"]"#
                ),
            );
        }
        text.replace("{project}/sim/", &format!("{}/", sim.display()))
    });
    let logs = project.path().join("logs");
    let vehicle = unique_vehicle("rdm");
    let child = Command::new(petrel_bin())
        .arg("up")
        .arg(project.path())
        .arg("--file")
        .arg(project.path().join(vehicle_file))
        .args(["--vehicle", &vehicle, "--logs"])
        .arg(&logs)
        .args(["--timeout", "400"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("petrel up runs");
    let killed = kill.map(|(role, depth)| kill_when_down(&vehicle, &logs, role, depth));
    let out = child.wait_with_output().expect("petrel up ends");
    forget_vehicle(&vehicle);
    let output = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    match killed {
        None => assert!(
            out.status.success(),
            "petrel up failed:\n{output}\n{}",
            process_logs(&logs)
        ),
        Some(Err(why)) => panic!("{why}:\n{output}\n{}", process_logs(&logs)),
        // A process died of a signal `petrel up` did not send: the mission goes on, the
        // run ends with status 1.
        Some(Ok(())) => assert_eq!(
            out.status.code(),
            Some(1),
            "petrel up after the kill:\n{output}\n{}",
            process_logs(&logs)
        ),
    }
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

/// Waits (at most 200 s) until the simulator's trace has the vehicle `depth` metres down, then
/// SIGKILLs the program process of `vehicle` started with `--role ROLE`.
fn kill_when_down(vehicle: &str, logs: &Path, role: &str, depth: f64) -> Result<(), String> {
    let patience = Instant::now() + Duration::from_secs(200);
    loop {
        let down = std::fs::read_to_string(logs.join("trace.csv"))
            .map(|t| {
                t.lines().skip(1).any(|l| {
                    l.split(',')
                        .nth(3)
                        .and_then(|d| d.trim().parse::<f64>().ok())
                        .is_some_and(|d| d > depth)
                })
            })
            .unwrap_or(false);
        if down {
            break;
        }
        if Instant::now() > patience {
            return Err(format!("the vehicle never went {depth} m down"));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let pid = program_process(vehicle, role).ok_or(format!("no process of role {role}"))?;
    let status = Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status()
        .map_err(|e| format!("kill: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("kill -KILL {pid} failed"))
    }
}

/// The process whose command line has `--vehicle VEHICLE` and `--role ROLE`.
fn program_process(vehicle: &str, role: &str) -> Option<u32> {
    std::fs::read_dir("/proc").ok()?.find_map(|e| {
        let e = e.ok()?;
        let pid: u32 = e.file_name().to_str()?.parse().ok()?;
        let cmdline = std::fs::read(e.path().join("cmdline")).ok()?;
        let args: Vec<&[u8]> = cmdline.split(|b| *b == 0).collect();
        let has = |flag: &str, value: &str| {
            args.windows(2)
                .any(|w| w[0] == flag.as_bytes() && w[1] == value.as_bytes())
        };
        (has("--vehicle", vehicle) && has("--role", role)).then_some(pid)
    })
}

/// The end of each process's log in `logs` (`NAME.log`), to say why a flight failed.
fn process_logs(logs: &Path) -> String {
    let mut text = String::new();
    let mut names: Vec<PathBuf> = std::fs::read_dir(logs)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    names.sort();
    for path in names
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "log"))
    {
        let log = std::fs::read_to_string(path).unwrap_or_default();
        let lines: Vec<&str> = log.lines().collect();
        let tail = lines[lines.len().saturating_sub(15)..].join("\n");
        text.push_str(&format!("--- {}\n{tail}\n", path.display()));
    }
    text
}

/// The buoy field, as the mission file has it (the planner keeps 10 m more).
pub fn in_buoy_field(p: &Point) -> bool {
    (-40.0..=60.0).contains(&p.x) && (80.0..=130.0).contains(&p.y)
}

pub fn in_end_area(p: &Point) -> bool {
    (150.0..=220.0).contains(&p.x) && (-40.0..=0.0).contains(&p.y)
}

/// How far inside the end area `p` is (m, to its nearest edge; negative outside).
pub fn end_area_margin(p: &Point) -> f64 {
    (p.x - 150.0).min(220.0 - p.x).min(p.y + 40.0).min(-p.y)
}

/// The vehicle's last position is in the end area; says where it is either way (the VM's
/// runs report it).
pub fn assert_ends_in_the_end_area(f: &Flight) {
    let last = f.trace.last().expect("a trace");
    let margin = end_area_margin(last);
    eprintln!(
        "the vehicle ends at ({:.1}, {:.1}), {:.1} m deep, {margin:.1} m inside the end area",
        last.x, last.y, last.depth
    );
    assert!(
        in_end_area(last),
        "ends at {last:?}, {:.1} m outside",
        -margin
    );
}

/// Every point of the area (a 10 m grid) came within half a swath (20 m), and 2 m for the
/// track's error where a line starts after a turn, of the submerged vehicle (below 2 m).
pub fn assert_covered(f: &Flight, name: &str, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) {
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

pub fn assert_clear_of_the_buoys(f: &Flight) {
    let inside: Vec<&Point> = f.trace.iter().filter(|p| in_buoy_field(p)).collect();
    assert!(inside.is_empty(), "in the buoy field: {inside:?}");
}

pub fn assert_flown_and_stopped(f: &Flight) {
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

/// The thruster commands (rpm left, rpm right, enable) sent after the leak detector's first
/// wet reading, from a candump -L log.
pub fn thruster_commands_after_leak(log: &Path) -> Vec<(i16, i16, bool)> {
    thruster_commands_after(log, true)
}

/// Every thruster command (rpm left, rpm right, enable) on the bus, from a candump -L log.
pub fn thruster_commands(log: &Path) -> Vec<(i16, i16, bool)> {
    thruster_commands_after(log, false)
}

fn thruster_commands_after(log: &Path, leak: bool) -> Vec<(i16, i16, bool)> {
    let text = std::fs::read_to_string(log).expect("the bus was recorded");
    let mut wet = !leak;
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

/// Scenario 1: alpha and bravo surveyed (every point imaged), clear of the buoy field, the
/// end area reached, surfaced and stopped.
pub fn check_nominal(f: &Flight) {
    check_nominal_route(f);
    assert_covered(f, "alpha", (-20.0, 100.0), (200.0, 264.0));
    assert_covered(f, "bravo", (160.0, 260.0), (100.0, 164.0));
}

/// Scenario 1 but the survey's coverage: both areas' surveys flown (the events), clear of the
/// buoy field, the end area reached, surfaced and stopped.
pub fn check_nominal_route(f: &Flight) {
    assert_flown_and_stopped(f);
    let story = f.story();
    assert_eq!(f.took("next_area"), 2, "{story}");
    assert_eq!(f.took("areas_done"), 1, "{story}");
    assert_eq!(f.took("current_ok"), 2, "{story}");
    assert_eq!(
        f.took("alarm") + f.took("leak") + f.took("depth_sensor_lost"),
        0,
        "{story}"
    );
    assert_clear_of_the_buoys(f);
    assert_ends_in_the_end_area(f);
    let last = f.trace.last().expect("a trace");
    assert!(last.depth < 0.5, "at the surface: {last:?}");
}

/// Scenario 2: the operator's `return` in the first transit: a new itinerary and trajectory
/// to the end area, round the buoy field, no area surveyed.
pub fn check_alarm(f: &Flight) {
    assert_flown_and_stopped(f);
    assert_eq!(f.took("alarm"), 1);
    assert!(f.called("call PLN.itinerary([") && f.called("call PLN.trajectory(-1,"));
    // No area was surveyed: the vehicle never went below transit depth.
    assert!(f.trace.iter().all(|p| p.depth < 6.0));
    assert_eq!(f.took("areas_done"), 0);
    assert_clear_of_the_buoys(f);
    assert_ends_in_the_end_area(f);
}

/// EMERGENCY alone runs, in `place`: the nominal and non-nominal nets are gone.
pub fn assert_only_emergency(f: &Flight, place: &str) {
    assert!(f.marked("EMERGENCY", place), "{}", f.marking);
    for net in ["MISSION", "DECISION", "ACTION"] {
        assert!(
            f.marking.get(net).is_none(),
            "{net} still active: {}",
            f.marking
        );
    }
}

/// Scenario 5: the leak ends the mission (the nominal and non-nominal nets gone, the emergency
/// surfacing), nothing is called after it but the surfacing, and on the bus every thruster
/// command after the stop disables the thrusters.
pub fn check_leak(f: &Flight) {
    assert_only_emergency(f, "surfacing");
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
