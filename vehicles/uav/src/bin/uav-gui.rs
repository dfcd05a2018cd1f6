//! The simulated guidance (GUI) and payload manager (PLD) of the UAV mission
//! (`missions/uav`, the ProCoSA paper's example), in one process.
//!
//! Every GUI call starts a manoeuvre whose end is an event, after a simulated time scaled by
//! `--speed` (600 simulated seconds per second by default: a nominal flight over three
//! waypoints, 940 simulated seconds, takes about 1.6 s):
//!
//! | call | event | simulated time |
//! |---|---|---|
//! | `GUI.roll()` | `rotation_speed` | 8 s |
//! | `GUI.takeoff()` | `airborne` | 2 s |
//! | `GUI.climb(altitude)` | `altitude_reached` | altitude / 6 m/s |
//! | `GUI.transit(position)` | `waypoint_reached` | 240 s |
//! | `GUI.approach()` | `runway_aligned` | 100 s |
//! | `GUI.land()` | `touchdown` | 60 s |
//!
//! A new manoeuvre replaces the one under way (a diversion replaces the transit). PLD's
//! `use_payload(payload)` and `stop_payload()` only log. For tests, `--fail-payload-after N`
//! emits `payload_failure(payload)` (as PLD) half-way through the Nth transit, and
//! `--engine-failure-after N` emits `engine_failure` (as GUI, ending the manoeuvre under way)
//! half-way through the Nth transit. The process stops on SIGINT or SIGTERM, or after
//! `touchdown` with `--exit-after-land`.
//!
//! `cargo run -p uav --bin uav-gui -- --vehicle uav`

use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use petrel_programs::{
    event_text, Call, Program, ProgramConfig, ProgramError, Value, Vehicle, DEFAULT_OUTBOX_CAPACITY,
};

/// The simulated GUI and PLD programs of the UAV mission.
#[derive(Debug, Parser)]
#[command(name = "uav-gui")]
struct Args {
    /// The vehicle to join.
    #[arg(long, value_name = "NAME")]
    vehicle: String,
    /// Simulated seconds per second of wall-clock time.
    #[arg(long, default_value_t = 600.0, value_parser = positive)]
    speed: f64,
    /// Emit `payload_failure(PAYLOAD)` half-way through the Nth transit (from 1).
    #[arg(long, value_name = "N")]
    fail_payload_after: Option<u32>,
    /// The payload `--fail-payload-after` reports failed.
    #[arg(long, value_name = "PAYLOAD", default_value = "camera")]
    failing_payload: String,
    /// Emit `engine_failure` half-way through the Nth transit (from 1).
    #[arg(long, value_name = "N")]
    engine_failure_after: Option<u32>,
    /// Exit once `touchdown` is emitted (and delivered, or given up after 2 s).
    #[arg(long)]
    exit_after_land: bool,
    /// Events kept while no player receives them.
    #[arg(long, value_name = "EVENTS", default_value_t = DEFAULT_OUTBOX_CAPACITY)]
    outbox: usize,
}

fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("`{s}` is not a positive number")),
    }
}

/// Simulated durations, in seconds.
const ROLL: f64 = 8.0;
const TAKEOFF: f64 = 2.0;
const CLIMB_RATE: f64 = 6.0;
const TRANSIT: f64 = 240.0;
const APPROACH: f64 = 100.0;
const LAND: f64 = 60.0;

/// An event to emit at a given time.
#[derive(Debug)]
struct Scheduled {
    due: Instant,
    program: &'static str,
    event: &'static str,
    params: Vec<Value>,
}

#[derive(Debug)]
struct Simulator {
    args: Args,
    /// The end of the GUI manoeuvre under way.
    manoeuvre: Option<Scheduled>,
    /// Injected failures to come.
    failures: Vec<Scheduled>,
    transits: u32,
    payload: Option<String>,
    landed: bool,
}

impl Simulator {
    fn after(&self, simulated_seconds: f64) -> Instant {
        Instant::now() + Duration::from_secs_f64(simulated_seconds / self.args.speed)
    }

    fn manoeuvre(&mut self, seconds: f64, event: &'static str) {
        let due = self.after(seconds);
        if let Some(old) = self.manoeuvre.replace(Scheduled {
            due,
            program: "GUI",
            event,
            params: vec![],
        }) {
            println!(
                "uav-gui: GUI abandons the manoeuvre that would end with {}",
                old.event
            );
        }
    }

    fn handle(&mut self, call: &Call) -> Result<(), ProgramError> {
        match (call.program.as_str(), call.function.as_str()) {
            ("GUI", "roll") => {
                call.expect_arity(0)?;
                self.manoeuvre(ROLL, "rotation_speed");
            }
            ("GUI", "takeoff") => {
                call.expect_arity(0)?;
                self.manoeuvre(TAKEOFF, "airborne");
            }
            ("GUI", "climb") => {
                call.expect_arity(1)?;
                let altitude = call.float(0)?;
                self.manoeuvre(altitude.abs() / CLIMB_RATE, "altitude_reached");
            }
            ("GUI", "transit") => {
                call.expect_arity(1)?;
                call.floats(0)?;
                self.transits += 1;
                self.manoeuvre(TRANSIT, "waypoint_reached");
                let halfway = self.after(TRANSIT / 2.0);
                if self.args.fail_payload_after == Some(self.transits) {
                    let payload = self.args.failing_payload.clone();
                    self.failures.push(Scheduled {
                        due: halfway,
                        program: "PLD",
                        event: "payload_failure",
                        params: vec![Value::Text(payload)],
                    });
                }
                if self.args.engine_failure_after == Some(self.transits) {
                    self.failures.push(Scheduled {
                        due: halfway,
                        program: "GUI",
                        event: "engine_failure",
                        params: vec![],
                    });
                }
            }
            ("GUI", "approach") => {
                call.expect_arity(0)?;
                self.manoeuvre(APPROACH, "runway_aligned");
            }
            ("GUI", "land") => {
                call.expect_arity(0)?;
                self.manoeuvre(LAND, "touchdown");
            }
            ("PLD", "use_payload") => {
                call.expect_arity(1)?;
                let payload = call.text(0)?;
                println!("uav-gui: PLD uses the {payload}");
                self.payload = Some(payload.to_owned());
            }
            ("PLD", "stop_payload") => {
                call.expect_arity(0)?;
                match self.payload.take() {
                    Some(payload) => println!("uav-gui: PLD stops the {payload}"),
                    None => println!("uav-gui: PLD has no payload running"),
                }
            }
            _ => return Err(call.unknown_function()),
        }
        Ok(())
    }

    /// The next event due, taken from the schedule if its time has come.
    fn take_due(&mut self, now: Instant) -> Option<Scheduled> {
        let failure = self
            .failures
            .iter()
            .enumerate()
            .filter(|(_, s)| s.due <= now)
            .min_by_key(|(_, s)| s.due)
            .map(|(i, s)| (i, s.due));
        let manoeuvre = self.manoeuvre.as_ref().map(|s| s.due).filter(|d| *d <= now);
        match (failure, manoeuvre) {
            (Some((i, due)), Some(m)) if due <= m => Some(self.failures.remove(i)),
            (Some((i, _)), None) => Some(self.failures.remove(i)),
            (_, Some(_)) => self.manoeuvre.take(),
            (None, None) => None,
        }
    }

    fn next_due(&self) -> Option<Instant> {
        self.failures
            .iter()
            .map(|s| s.due)
            .chain(self.manoeuvre.as_ref().map(|s| s.due))
            .min()
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    let vehicle = match Vehicle::new(&args.vehicle) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("uav-gui: {e}");
            return ExitCode::from(2);
        }
    };
    let config = ProgramConfig {
        outbox_capacity: args.outbox,
        ..ProgramConfig::default()
    };
    let mut program = match Program::connect_with(&vehicle, &["GUI", "PLD"], config) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("uav-gui: {e}");
            return ExitCode::from(2);
        }
    };
    println!(
        "uav-gui: GUI and PLD ready on vehicle {} (speed x{})",
        args.vehicle, args.speed
    );
    let mut sim = Simulator {
        args,
        manoeuvre: None,
        failures: Vec::new(),
        transits: 0,
        payload: None,
        landed: false,
    };
    let mut status = ExitCode::SUCCESS;
    while !(sim.landed && sim.args.exit_after_land) {
        while let Some(due) = sim.take_due(Instant::now()) {
            println!(
                "uav-gui: {} emits {}",
                due.program,
                event_text(due.event, &due.params)
            );
            if due.event == "engine_failure" {
                if let Some(lost) = sim.manoeuvre.take() {
                    println!("uav-gui: the engine is lost, no {} to come", lost.event);
                }
            }
            sim.landed |= due.event == "touchdown";
            if let Err(e) = program.emit_as(due.program, due.event, due.params) {
                eprintln!("uav-gui: {e}");
            }
        }
        if sim.landed && sim.args.exit_after_land {
            break;
        }
        let timeout = sim
            .next_due()
            .map(|d| d.saturating_duration_since(Instant::now()));
        match program.recv(timeout) {
            Ok(Some(call)) => {
                println!("uav-gui: call {call}");
                if let Err(e) = sim.handle(&call) {
                    eprintln!("uav-gui: error: {e}; the call is ignored");
                }
            }
            Ok(None) => {}
            Err(e) if e.is_termination() => {
                println!("uav-gui: termination requested, leaving");
                break;
            }
            Err(e) if e.is_fatal() => {
                eprintln!("uav-gui: {e}");
                status = ExitCode::FAILURE;
                break;
            }
            Err(e) => eprintln!("uav-gui: error: {e}"),
        }
    }
    match program.close(Duration::from_secs(2)) {
        Ok(stats) => println!(
            "uav-gui: done: {} calls, {} events delivered, {} dropped, {} undelivered",
            stats.calls, stats.delivered, stats.dropped, stats.queued
        ),
        Err(e) => eprintln!("uav-gui: {e}"),
    }
    status
}
