//! The Redermor programs as processes on the programs SDK (missions/redermor/INTERFACE.md):
//!
//! ```text
//! redermor-program --vehicle redermor --role PLN --mission two_areas.toml
//! redermor-program --vehicle redermor --role NAV --mission two_areas.toml   # GDD, GUI, IDC
//! redermor-program --vehicle redermor --role EVT --mission two_areas.toml [--requests FILE]
//! ```
//!
//! NAV and EVT read the CAN data server's signals (`petrel bridge`) and run their control step
//! every `--period`; NAV commands the thrusters through the server (`CAN.ThrusterCmd`,
//! `CAN.DepthCmd`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, ValueEnum};
use petrel_programs::{Program, ProgramError, Value};
use redermor::mission::Mission;
use redermor_live::programs::{parse_requests, Answer, Evt, Nav, Pln};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
#[value(rename_all = "UPPER")]
enum Role {
    /// PLN, the planner.
    Pln,
    /// GDD, GUI and IDC: the state, guidance and the pilot.
    Nav,
    /// EVT, the event listener.
    Evt,
}

/// A Redermor program.
#[derive(Debug, Parser)]
#[command(name = "redermor-program")]
struct Args {
    /// The vehicle to join.
    #[arg(long, value_name = "NAME")]
    vehicle: String,
    /// Which program(s) this process plays.
    #[arg(long, value_enum)]
    role: Role,
    /// The mission file (missions/redermor/sim/mission.toml, vehicles/redermor/domain/missions/*.toml).
    #[arg(long, value_name = "FILE")]
    mission: PathBuf,
    /// EVT: the operator's requests, one a line: `SECONDS return` or `SECONDS inspect X Y`
    /// (the vehicle's time).
    #[arg(long, value_name = "FILE")]
    requests: Option<PathBuf>,
    /// NAV and EVT: the control step, in milliseconds of the wall clock.
    #[arg(long, default_value_t = 20)]
    period: u64,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("redermor-program: {e}");
            ExitCode::FAILURE
        }
    }
}

fn read(path: &PathBuf) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

enum Played {
    Pln(Box<Pln>),
    Nav(Box<Nav>),
    Evt(Box<Evt>),
}

fn emit(program: &mut Program, answers: Vec<Answer>) {
    for a in answers {
        eprintln!("redermor-program: {}.{} {:?}", a.program, a.event, a.params);
        if let Err(e) = program.emit_as(a.program, a.event, a.params) {
            eprintln!("redermor-program: {e}");
        }
    }
}

fn run(args: &Args) -> Result<(), String> {
    let text = read(&args.mission)?;
    let mission =
        Mission::from_toml(&text).map_err(|e| format!("{}: {e}", args.mission.display()))?;
    let (names, mut played): (&[&str], Played) = match args.role {
        Role::Pln => (&["PLN"], Played::Pln(Box::new(Pln::new(&mission)))),
        Role::Nav => (
            &["GDD", "GUI", "IDC"],
            Played::Nav(Box::new(Nav::new(&mission))),
        ),
        Role::Evt => {
            let requests = match &args.requests {
                Some(p) => parse_requests(&read(p)?).map_err(|e| format!("{}:{e}", p.display()))?,
                None => Vec::new(),
            };
            (
                &["EVT"],
                Played::Evt(Box::new(Evt::new(&mission, requests))),
            )
        }
    };
    let mut program = Program::connect_many(&args.vehicle, names).map_err(|e| e.to_string())?;
    let period = Duration::from_millis(args.period.max(1));
    let timeout = match played {
        Played::Pln(_) => None,
        _ => {
            // Subscribe now: the readings are there at the first step.
            program.signals().map_err(|e| e.to_string())?;
            Some(period)
        }
    };
    loop {
        match program.recv(timeout) {
            Ok(Some(call)) => {
                let answers = match &mut played {
                    Played::Pln(p) => p.handle(&call).map(|a| a.into_iter().collect()),
                    Played::Nav(n) => n.handle(&call),
                    Played::Evt(e) => e.handle(&call).map(|()| Vec::new()),
                };
                match answers {
                    Ok(a) => emit(&mut program, a),
                    Err(e) => eprintln!("redermor-program: {e}"),
                }
            }
            Ok(None) => {}
            Err(e) if e.is_termination() || e.is_fatal() => {
                if e.is_fatal() {
                    eprintln!("redermor-program: {e}");
                }
                break;
            }
            Err(e) => eprintln!("redermor-program: {e}"),
        }
        step(&mut program, &mut played);
    }
    program
        .close(Duration::from_secs(2))
        .map(|_| ())
        .map_err(|e: ProgramError| e.to_string())
}

/// A control step on the latest signals.
fn step(program: &mut Program, played: &mut Played) {
    if matches!(played, Played::Pln(_)) {
        return;
    }
    let values = match program.signals() {
        Ok(Some(s)) => s.values.clone(),
        Ok(None) => return,
        Err(e) => {
            eprintln!("redermor-program: {e}");
            return;
        }
    };
    match played {
        Played::Nav(nav) => {
            let (answers, commands) = nav.tick(&values);
            emit(program, answers);
            if let Some(c) = commands {
                let thrusters = vec![
                    Value::Float(c.rpm_left.round()),
                    Value::Float(c.rpm_right.round()),
                    Value::Bool(c.enable),
                ];
                let sent = program
                    .call("CAN", "ThrusterCmd", thrusters)
                    .and_then(|()| program.call("CAN", "DepthCmd", vec![Value::Float(c.depth)]));
                if let Err(e) = sent {
                    eprintln!("redermor-program: {e}");
                }
            }
        }
        Played::Evt(evt) => {
            let answers = evt.tick(&values);
            emit(program, answers);
        }
        Played::Pln(_) => {}
    }
}
