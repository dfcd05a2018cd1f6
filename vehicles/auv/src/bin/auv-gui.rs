//! The simulated guidance (GUI) of the AUV mission (`missions/auv`): it answers the nets'
//! calls with events, commands the thrusters itself through the CAN data server
//! ([`Program::call`] to the `CAN` program, which the server encodes with the DBC and sends on
//! the bus), and reads the vehicle's depth from the server's decoded signals
//! ([`Program::signals`]).
//!
//! | call | commands (through CAN) | event |
//! |---|---|---|
//! | `GUI.transit(area)` | `ThrusterCmd(1200, 1200, true)` | `area_reached(area)` after `--transit` |
//! | `GUI.survey(area)` | `ThrusterCmd(600, 600, true)` (survey speed) | `survey_done(area)` after `--survey` |
//! | `GUI.surface()` | `DepthCmd(0)`, `ThrusterCmd(1000, 1000, true)` | (the server's `depth_reached`) |
//! | `GUI.stop()` | | the manoeuvre under way is dropped |
//!
//! A command the server does not take (no server running) is reported on standard error and
//! answered with no event: the mission then waits, and its supervisor sees why in the log.
//!
//! `cargo run -p auv --bin auv-gui -- --vehicle auv`

use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use petrel_programs::{Call, Program, ProgramError, Value};

/// The simulated GUI program of the AUV mission.
#[derive(Debug, Parser)]
#[command(name = "auv-gui")]
struct Args {
    /// The vehicle to join.
    #[arg(long, value_name = "NAME")]
    vehicle: String,
    /// How long a transit takes, in seconds.
    #[arg(long, default_value_t = 1.5)]
    transit: f64,
    /// How long a survey takes, in seconds.
    #[arg(long, default_value_t = 2.0)]
    survey: f64,
}

/// The manoeuvre under way: the event that ends it, and when.
struct Manoeuvre {
    due: Instant,
    event: &'static str,
    area: String,
}

fn depth(program: &mut Program) -> String {
    match program.signals() {
        Ok(Some(s)) => s
            .get("Depth.depth")
            .map_or_else(|| "unknown".to_owned(), |d| format!("{d:.1} m")),
        Ok(None) => "unknown (no signals yet)".to_owned(),
        Err(e) => format!("unknown ({e})"),
    }
}

/// Sends the commands through CAN; false (and a message) if one was not delivered.
fn command(program: &mut Program, commands: &[(&str, Vec<Value>)]) -> bool {
    for (function, args) in commands {
        if let Err(e) = program.call("CAN", function, args.clone()) {
            eprintln!("auv-gui: {e}");
            return false;
        }
    }
    true
}

fn thrusters(rpm: i64) -> (&'static str, Vec<Value>) {
    (
        "ThrusterCmd",
        vec![Value::Int(rpm), Value::Int(rpm), Value::Bool(true)],
    )
}

fn handle(
    program: &mut Program,
    call: &Call,
    args: &Args,
    under_way: &mut Option<Manoeuvre>,
) -> Result<(), ProgramError> {
    let start = |event, area: &str, secs: f64| Manoeuvre {
        due: Instant::now() + Duration::from_secs_f64(secs),
        event,
        area: area.to_owned(),
    };
    match call.function.as_str() {
        "transit" => {
            let area = call.text(0)?.to_owned();
            if command(program, &[thrusters(1200)]) {
                eprintln!("auv-gui: transit to {area} at {}", depth(program));
                *under_way = Some(start("area_reached", &area, args.transit));
            }
        }
        "survey" => {
            let area = call.text(0)?.to_owned();
            if command(program, &[thrusters(600)]) {
                eprintln!("auv-gui: survey of {area} at {}", depth(program));
                *under_way = Some(start("survey_done", &area, args.survey));
            }
        }
        "surface" => {
            *under_way = None;
            if command(
                program,
                &[("DepthCmd", vec![Value::Float(0.0)]), thrusters(1000)],
            ) {
                eprintln!("auv-gui: surfacing from {}", depth(program));
            }
        }
        "stop" => {
            *under_way = None;
            eprintln!("auv-gui: stopped at {}", depth(program));
        }
        _ => return Err(call.unknown_function()),
    }
    Ok(())
}

fn main() -> ExitCode {
    let args = Args::parse();
    let mut program = match Program::connect(&args.vehicle, "GUI") {
        Ok(p) => p,
        Err(e) => {
            eprintln!("auv-gui: {e}");
            return ExitCode::from(2);
        }
    };
    // Subscribe now: the depth is there when the first call asks for it.
    if let Err(e) = program.signals() {
        eprintln!("auv-gui: {e}");
    }
    let mut under_way: Option<Manoeuvre> = None;
    loop {
        let timeout = under_way
            .as_ref()
            .map(|m| m.due.saturating_duration_since(Instant::now()));
        match program.recv(timeout) {
            Ok(Some(call)) => {
                if let Err(e) = handle(&mut program, &call, &args, &mut under_way) {
                    eprintln!("auv-gui: {e}");
                }
            }
            Ok(None) => {}
            Err(e) if e.is_termination() || e.is_fatal() => {
                if e.is_fatal() {
                    eprintln!("auv-gui: {e}");
                }
                break;
            }
            Err(e) => eprintln!("auv-gui: {e}"),
        }
        if under_way.as_ref().is_some_and(|m| Instant::now() >= m.due) {
            if let Some(m) = under_way.take() {
                if let Err(e) = program.emit(m.event, vec![Value::Text(m.area)]) {
                    eprintln!("auv-gui: {e}");
                }
            }
        }
    }
    match program.close(Duration::from_secs(2)) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("auv-gui: {e}");
            ExitCode::FAILURE
        }
    }
}
