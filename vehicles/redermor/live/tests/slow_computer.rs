//! NAV (GDD, GUI, IDC) on a slow or loaded vehicle computer: it steers once a second of the
//! vehicle's time, and the nets' answer to its `route_done` (`IDC.surface`) comes seconds
//! later. The vehicle, Redermor's simulator in this process, must still surface where its
//! route ended and stay there once its thrusters are off: that is where the boat recovers it.
//!
//! Closed loop, no process: the simulator's readings go to NAV as the CAN data server's
//! latest signals would (bench.rs's encoding), NAV's commands go back to the simulator, and
//! the player's part (the calls) is played by the test.

use std::collections::BTreeMap;

use petrel_programs::{Call, Value};
use redermor::geom::{self, Position};
use redermor::mission::Mission;
use redermor::sensors::{Sample, Scenario};
use redermor::sim::Simulator;
use redermor::vehicle::{Commands, VehicleConfig};
use redermor_live::bus::{encode, TIME_SIGNAL};
use redermor_live::programs::{Answer, Nav};

/// The simulator's step (µs): the data server repeats the last commands on the bus at this
/// rate or faster, so the thrusters' heartbeat stays fresh between NAV's steps.
const SIM_STEP_US: u64 = 100_000;

fn bench() -> Mission {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../missions/redermor/sim/mission.toml"
    );
    Mission::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The vehicle, NAV, and the data server's table of latest signal values between them.
struct Bench {
    sim: Simulator,
    nav: Nav,
    signals: BTreeMap<String, (f64, u64)>,
    received: u64,
    commands: Commands,
    /// NAV's answers, with the vehicle's time (µs) they were sent at.
    answers: Vec<(u64, Answer)>,
}

impl Bench {
    fn new(mission: &Mission) -> Bench {
        let scenario = Scenario::from_toml("seed = 7\n").unwrap();
        Bench {
            sim: Simulator::new(mission, &scenario, VehicleConfig::default()),
            nav: Nav::new(mission),
            signals: BTreeMap::new(),
            received: 0,
            commands: Commands::default(),
            answers: Vec::new(),
        }
    }

    fn call(&mut self, program: &str, function: &str, args: Vec<Value>) {
        let answers = self
            .nav
            .handle(&Call::new(program, function, args))
            .unwrap();
        let now = self.sim.time_us();
        self.answers.extend(answers.into_iter().map(|a| (now, a)));
    }

    /// Runs `period_us` of the vehicle's time, then one NAV control step.
    fn control_step(&mut self, period_us: u64) {
        let mut samples: Vec<Sample> = Vec::new();
        for _ in 0..period_us / SIM_STEP_US {
            self.sim
                .step(SIM_STEP_US, Some(&self.commands), &mut samples);
        }
        for s in &samples {
            let (message, signals) = encode(&s.reading);
            for (signal, value) in signals {
                self.received += 1;
                self.signals
                    .insert(format!("{message}.{signal}"), (value, self.received));
            }
        }
        self.received += 1;
        self.signals.insert(
            TIME_SIGNAL.to_owned(),
            (self.sim.time_us() as f64 / 1000.0, self.received),
        );
        let values: Vec<(String, f64, u64)> = self
            .signals
            .iter()
            .map(|(k, (v, t))| (k.clone(), *v, *t))
            .collect();
        let (answers, commands) = self.nav.tick(&values);
        if let Some(c) = commands {
            self.commands = c;
        }
        let now = self.sim.time_us();
        self.answers.extend(answers.into_iter().map(|a| (now, a)));
    }

    fn answered(&self, event: &str) -> Option<u64> {
        self.answers
            .iter()
            .find(|(_, a)| a.event == event)
            .map(|(t, _)| *t)
    }

    fn answered_since(&self, first: usize, event: &str) -> Option<u64> {
        self.answers[first..]
            .iter()
            .find(|(_, a)| a.event == event)
            .map(|(t, _)| *t)
    }

    fn position(&self) -> Position {
        self.sim.vehicle().state().position
    }

    /// Engages the thrusters and has GUI follow one leg from where the vehicle is to `end`,
    /// at transit depth.
    fn start_leg(&mut self, mission: &Mission, end: Position) {
        let start = self.position();
        self.call("IDC", "engage", vec![]);
        self.call(
            "GUI",
            "compute_course",
            vec![
                Value::FloatList(vec![start.x, start.y, end.x, end.y]),
                Value::Float(mission.vehicle.transit_depth),
                Value::Float(0.0),
            ],
        );
        self.call("GUI", "follow_leg", vec![]);
    }
}

/// Flies one transit leg north to `end` at transit depth with NAV stepping every
/// `period_us`, the nets answering `route_done` with `IDC.surface` `latency_us` later and
/// `surfaced` with `IDC.stop` as late; then lets the vehicle drift a minute with its
/// thrusters off.
fn fly_to_the_end_and_surface(
    mission: &Mission,
    end: Position,
    period_us: u64,
    latency_us: u64,
) -> Bench {
    let mut b = Bench::new(mission);
    b.start_leg(mission, end);
    let limit = 600_000_000;
    let mut surface_at = None;
    let mut stop_at = None;
    while b.sim.time_us() < limit {
        b.control_step(period_us);
        let now = b.sim.time_us();
        if surface_at.is_none() {
            surface_at = b.answered("route_done").map(|t| t + latency_us);
        }
        if surface_at.is_some_and(|t| now >= t) {
            surface_at = Some(u64::MAX);
            b.call("IDC", "surface", vec![]);
        }
        if stop_at.is_none() {
            stop_at = b.answered("surfaced").map(|t| t + latency_us);
        }
        if stop_at.is_some_and(|t| now >= t) {
            b.call("IDC", "stop", vec![]);
            break;
        }
    }
    assert!(
        stop_at.is_some(),
        "never surfaced; NAV answered {:?}",
        b.answers
    );
    // A minute at the surface, thrusters off, before the boat picks it up.
    let stopped = b.sim.time_us();
    while b.sim.time_us() < stopped + 60_000_000 {
        b.control_step(period_us);
    }
    b
}

#[test]
fn a_late_surface_order_still_brings_the_vehicle_up_where_its_route_ended() {
    let mission = bench();
    let end = geom::pos(0.0, 120.0);
    // One control step a second and the nets' answers 8 s late: at 1.5 m/s the vehicle
    // cruises 12 m past the end before it hears it is to surface.
    let b = fly_to_the_end_and_surface(&mission, end, 1_000_000, 8_000_000);
    let state = b.sim.vehicle().state();
    let off = geom::distance(state.position, end);
    // Within GUI's arrival radius of the end, and the little it drifts once stopped.
    assert!(
        off <= mission.vehicle.arrival_radius + 2.0,
        "the vehicle ended {off:.1} m from the route's end, at {:?}",
        state.position
    );
    assert!(state.depth < 0.5, "at the surface: {state:?}");
    assert!(state.surge.abs() < 0.1, "drifting at {} m/s", state.surge);
    // NAV said `surfaced` only once stopped: the thrusters went off then.
    let surfaced = b.answered("surfaced").unwrap();
    let route_done = b.answered("route_done").unwrap();
    assert!(surfaced > route_done);
}

#[test]
fn on_a_fast_computer_too_the_vehicle_surfaces_at_the_end_and_stays() {
    let mission = bench();
    let end = geom::pos(0.0, 120.0);
    let b = fly_to_the_end_and_surface(&mission, end, 100_000, 0);
    let off = geom::distance(b.position(), end);
    assert!(
        off <= mission.vehicle.arrival_radius + 2.0,
        "ended {off:.1} m from the route's end"
    );
}

/// A computer so slow or loaded that NAV steers only every 2 to 4 s of the vehicle's time
/// (the VM's emulation has such stalls): braking to a stop at the surface must not
/// depend on a control step seeing the speed within 0.05 m/s of zero. Before the pilot's
/// brake faded with the speed, a fixed astern order held between those steps drove the
/// vehicle astern past zero, NAV braked on for its 30 s limit and the vehicle coasted on
/// astern once stopped: 32 to 43 m from the route's end in these four runs.
#[test]
fn a_control_step_of_seconds_still_brakes_to_a_stop_at_the_route_end() {
    let mission = bench();
    let end = geom::pos(185.0, -20.0);
    for (period_us, latency_us) in [
        (2_000_000, 15_000_000),
        (3_000_000, 0),
        (4_000_000, 0),
        (4_000_000, 4_000_000),
    ] {
        let b = fly_to_the_end_and_surface(&mission, end, period_us, latency_us);
        let state = b.sim.vehicle().state();
        let off = geom::distance(state.position, end);
        assert!(
            off <= mission.vehicle.arrival_radius + 2.0,
            "steering every {} s, the nets {} s late: the vehicle ended {off:.1} m from the \
             route's end, at {:?}, drifting at {:.2} m/s",
            period_us / 1_000_000,
            latency_us / 1_000_000,
            state.position,
            state.surge
        );
    }
}

/// The operator's `return` mid-transit: the nets stop GUI (`GUI.stop`), ask GDD where the
/// vehicle is and PLN for a route from there, which on a slow computer takes minutes of the
/// vehicle's time (two and a half in a VM run). The vehicle must wait near where it was
/// stopped, at its depth: cruising on on its heading, as it did, it goes 270 m further here,
/// and in that VM run it crossed the buoy field and the new route started far behind it.
#[test]
fn stopped_mid_route_the_vehicle_waits_where_it_is_for_its_next_route() {
    let mission = bench();
    let mut b = Bench::new(&mission);
    b.start_leg(&mission, geom::pos(0.0, 500.0));
    // A minute along the leg, at cruise speed and transit depth.
    while b.sim.time_us() < 60_000_000 {
        b.control_step(500_000);
    }
    let stopped = b.position();
    assert!(stopped.y > 50.0, "under way: {stopped:?}");
    b.call("GUI", "stop", vec![]);
    // Three minutes of replanning, NAV stepping every second.
    while b.sim.time_us() < 240_000_000 {
        b.control_step(1_000_000);
    }
    let state = b.sim.vehicle().state();
    let off = geom::distance(state.position, stopped);
    assert!(
        off <= 15.0,
        "the vehicle went {off:.1} m on after GUI.stop, to {:?}",
        state.position
    );
    assert!(
        (state.depth - mission.vehicle.transit_depth).abs() < 1.0,
        "holding its depth: {state:?}"
    );
    // The next route is flown from there.
    let here = b.nav.gdd().state().position;
    b.call(
        "GUI",
        "compute_course",
        vec![
            Value::FloatList(vec![here.x, here.y, here.x + 100.0, here.y]),
            Value::Float(mission.vehicle.transit_depth),
            Value::Float(0.0),
        ],
    );
    b.call("GUI", "change_course", vec![]);
    let before = b.answers.len();
    while b.sim.time_us() < 400_000_000 && b.answered_since(before, "heading_reached").is_none() {
        b.control_step(500_000);
    }
    assert!(
        b.answered_since(before, "heading_reached").is_some(),
        "turned onto the next route"
    );
}
