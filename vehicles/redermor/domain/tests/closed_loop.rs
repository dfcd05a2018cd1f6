//! Whole missions in closed loop, in pure simulation at 10 Hz: PLN plans, the simulator flies
//! the vehicle, its sensors feed GDD, GUI follows the legs, IDC commands the thrusters. The
//! properties are checked on the vehicle's true track.

mod common;

use common::*;
use geo::{Contains, Intersects, Line, Point};
use redermor::evt::{AlarmReason, MissionEvent, OperatorRequest};
use redermor::geom::{self, pos, Position};
use redermor::mission::{Current, Mission};
use redermor::plot::Trace;
use redermor::sensors::{Fault, Reading, Scenario, ScheduledFault, Sensor};
use redermor::sim::{MissionRun, RunConfig, RunOutcome, Simulator};
use redermor::vehicle::{Commands, VehicleConfig};

/// The vehicle's track never enters a forbidden zone: no recorded point inside one, and no
/// segment between consecutive points touching one.
fn assert_never_in_forbidden(mission: &Mission, trace: &Trace) {
    for w in trace.points.windows(2) {
        let (a, b) = (w[0].position, w[1].position);
        for z in &mission.forbidden {
            assert!(
                !z.polygon.contains(&Point(a)) && !Line::new(a, b).intersects(&z.polygon),
                "at {:.1} s the vehicle enters {} at {a:?}",
                w[0].time,
                z.name
            );
        }
    }
}

/// Every point of each area (on a 10 m grid) came within half a swath of the vehicle while it
/// flew that area's survey lines: the sonar imaged it.
fn assert_covered(mission: &Mission, trace: &Trace) {
    let half_swath = mission.vehicle.swath_width / 2.0;
    for (i, area) in mission.areas.iter().enumerate() {
        let track: Vec<Position> = trace
            .points
            .iter()
            .filter(|p| p.surveying == Some(i))
            .map(|p| p.position)
            .collect();
        assert!(!track.is_empty(), "{} never surveyed", area.name);
        let grid = grid_inside(&area.polygon, 10.0);
        let missed: Vec<Position> = grid
            .iter()
            .copied()
            .filter(|&p| !track.iter().any(|&t| geom::distance(p, t) <= half_swath))
            .collect();
        assert!(
            missed.is_empty(),
            "{}: {} of {} points not imaged, e.g. {:?}",
            area.name,
            missed.len(),
            grid.len(),
            missed.first()
        );
    }
}

/// The step budget: the plan's length at cruise speed, with half as much again for turns,
/// dives and current, at 10 Hz.
fn budget(mission: &Mission, run: &MissionRun) -> u64 {
    let length = run.plan().trajectory().length();
    (1.5 * length / mission.vehicle.cruise_speed * 10.0) as u64 + 3000
}

#[test]
fn nominal_missions_survey_every_area_and_end_in_the_end_area() {
    for mission in missions() {
        let run = MissionRun::new(&mission, &Scenario::default(), RunConfig::default()).unwrap();
        let budget = budget(&mission, &run);
        let report = run.run();
        assert_eq!(report.outcome, RunOutcome::Completed, "{}", mission.name);
        assert!(
            report.steps <= budget,
            "{}: {} steps for a budget of {budget}",
            mission.name,
            report.steps
        );
        let mut surveyed = report.surveyed.clone();
        surveyed.sort();
        let mut names: Vec<String> = mission.areas.iter().map(|a| a.name.clone()).collect();
        names.sort();
        assert_eq!(surveyed, names, "every area surveyed once");
        let last = report.trace.points.last().unwrap().position;
        assert!(
            mission.end.contains(last),
            "{}: ends at {last:?}",
            mission.name
        );
        assert_never_in_forbidden(&mission, &report.trace);
        assert_covered(&mission, &report.trace);
    }
}

#[test]
fn in_a_current_the_survey_is_replanned_along_it_and_still_covers() {
    let mission = mission(TWO_AREAS);
    let scenario = Scenario {
        current: Current::new(0.25, 0.1),
        ..Scenario::default()
    };
    let report = MissionRun::new(&mission, &scenario, RunConfig::default())
        .unwrap()
        .run();
    assert_eq!(report.outcome, RunOutcome::Completed);
    // alpha had no predicted current: on arrival the measured one differs, and its survey is
    // replanned; bravo's prediction was near enough.
    let differs: Vec<&str> = report
        .trace
        .events
        .iter()
        .filter(|e| e.label.starts_with("current in"))
        .map(|e| e.label.as_str())
        .collect();
    assert_eq!(differs.len(), 1, "{differs:?}");
    assert!(differs[0].starts_with("current in alpha"), "{differs:?}");
    assert_never_in_forbidden(&mission, &report.trace);
    assert_covered(&mission, &report.trace);
}

#[test]
fn the_leak_reading_shows_from_the_leak_time_on() {
    let mission = mission(TWO_AREAS);
    for step_us in [100_000u64, 300_000, 1_000_000] {
        let scenario = Scenario {
            faults: vec![ScheduledFault {
                at: 30.2,
                fault: Fault::Leak,
            }],
            ..Scenario::default()
        };
        let mut sim = Simulator::new(&mission, &scenario, VehicleConfig::default());
        let mut samples = Vec::new();
        let mut fired = Vec::new();
        while sim.time_us() < 40_000_000 {
            fired.extend(sim.step(step_us, Some(&Commands::default()), &mut samples));
        }
        assert_eq!(fired.len(), 1);
        let leaks: Vec<(u64, bool)> = samples
            .iter()
            .filter_map(|s| match s.reading {
                Reading::Leak { leak, .. } => Some((s.time_us, leak)),
                _ => None,
            })
            .collect();
        // 2 Hz: readings at 0, 0.5, ... 40 s; dry up to 30.0 s, wet from 30.5 s.
        assert_eq!(leaks.len(), 81, "step {step_us}");
        for (t, leak) in leaks {
            assert_eq!(
                leak,
                t >= 30_200_000,
                "leak reading at {t} µs, step {step_us}"
            );
        }
    }
}

#[test]
fn a_leak_sends_the_vehicle_to_the_end_area() {
    let mission = mission(TWO_AREAS);
    let scenario = Scenario::from_toml("[[fault]]\nat = 600.0\nkind = \"leak\"\n").unwrap();
    let report = MissionRun::new(&mission, &scenario, RunConfig::default())
        .unwrap()
        .run();
    assert_eq!(
        report.outcome,
        RunOutcome::Aborted(MissionEvent::Alarm(AlarmReason::Leak))
    );
    let alarm = report
        .trace
        .events
        .iter()
        .find(|e| e.label.contains("Leak") && e.label.starts_with("alarm"))
        .expect("the alarm is recorded");
    // The leak detector reads at 2 Hz: the alarm comes within one period.
    assert!(alarm.time >= 600.0 && alarm.time <= 600.6, "{}", alarm.time);
    assert!(
        report.surveyed.len() < mission.areas.len(),
        "the mission was cut short"
    );
    assert!(mission
        .end
        .contains(report.trace.points.last().unwrap().position));
    assert_never_in_forbidden(&mission, &report.trace);
    // The replanned trajectory to the end area was recorded for the map.
    assert!(report.trace.planned.len() >= 2);
}

#[test]
fn sensor_silence_thruster_fault_and_bus_off() {
    let mission = mission(ISLAND_PASSAGE);
    // The DVL falls silent: lost after the sensor timeout, and the vehicle goes home.
    let scenario =
        Scenario::from_toml("[[fault]]\nat = 100.0\nkind = \"sensor_silent\"\nsensor = \"dvl\"\n")
            .unwrap();
    let report = MissionRun::new(&mission, &scenario, RunConfig::default())
        .unwrap()
        .run();
    assert_eq!(
        report.outcome,
        RunOutcome::Aborted(MissionEvent::Alarm(AlarmReason::SensorLost(Sensor::Dvl)))
    );
    let alarm = report
        .trace
        .events
        .iter()
        .find(|e| e.label.starts_with("alarm"))
        .unwrap();
    // Its last reading was at 99.8 s (5 Hz); lost once silent for more than the 2 s timeout,
    // at the first 10 Hz step after 101.8 s.
    assert!((alarm.time - 101.9).abs() < 1e-6, "{}", alarm.time);

    // A thruster fault is reported by the thrusters and raises the alarm.
    let scenario = Scenario::from_toml(
        "[[fault]]\nat = 50.0\nkind = \"thruster\"\nthruster = \"left\"\nefficiency = 0.5\n",
    )
    .unwrap();
    let mut run = MissionRun::new(&mission, &scenario, RunConfig::default()).unwrap();
    for _ in 0..520 {
        run.step();
    }
    assert!(run
        .trace()
        .events
        .iter()
        .any(|e| e.label == "alarm (ThrusterFault)"));

    // Bus off: no reading comes out, commands no longer arrive and the thrusters stop.
    let scenario = Scenario {
        faults: vec![ScheduledFault {
            at: 20.0,
            fault: Fault::BusOff,
        }],
        ..Scenario::default()
    };
    let mut sim = Simulator::new(&mission, &scenario, VehicleConfig::default());
    let ahead = Commands {
        rpm_left: 1000.0,
        rpm_right: 1000.0,
        depth: 5.0,
        enable: true,
    };
    let mut samples = Vec::new();
    // 25 s: the bus goes off at 20 s; the thrusters spin down after the heartbeat timeout.
    for _ in 0..250 {
        sim.step(100_000, Some(&ahead), &mut samples);
    }
    assert!(sim.bus_off());
    assert!(samples.iter().all(|s| s.time_us < 20_000_000));
    assert!(samples.iter().any(|s| s.time_us >= 19_900_000));
    let rpm = sim.vehicle().state().rpm;
    assert!(rpm[0].abs() < 10.0 && rpm[1].abs() < 10.0, "{rpm:?}");
}

#[test]
fn an_inspection_goes_round_the_object_and_the_survey_resumes() {
    let mission = mission(TWO_AREAS);
    let mut run = MissionRun::new(&mission, &Scenario::default(), RunConfig::default()).unwrap();
    // Fly until the first survey has run a while.
    let mut steps = 0;
    while run
        .trace()
        .points
        .last()
        .is_none_or(|p| p.surveying.is_none())
        || steps < 6000
    {
        assert!(run.step().is_none(), "ended before surveying");
        steps += 1;
    }
    let here = run.nav().position;
    let object = here + pos(40.0, 0.0);
    run.request(OperatorRequest::Inspect { at: object });
    let report = run.run();
    assert_eq!(report.outcome, RunOutcome::Completed);
    let inspect = report
        .trace
        .events
        .iter()
        .find(|e| e.label.starts_with("inspect"))
        .unwrap();
    // The vehicle went round the object (every side of the square within reach) and came back.
    let after: Vec<Position> = report
        .trace
        .points
        .iter()
        .filter(|p| p.time >= inspect.time)
        .map(|p| p.position)
        .collect();
    for side in [
        pos(-25.0, 0.0),
        pos(25.0, 0.0),
        pos(0.0, 25.0),
        pos(0.0, -25.0),
    ] {
        let mid = object + side;
        assert!(
            after.iter().any(|&p| geom::distance(p, mid) < 10.0),
            "never near the side at {mid:?}"
        );
    }
    assert_never_in_forbidden(&mission, &report.trace);
    assert_covered(&mission, &report.trace);
}
