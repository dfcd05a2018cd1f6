//! The simulated programs of the UGV pair (`missions/ugv`, section 3.3 of the ProCoSA paper),
//! for the mission live, each robot's movement program on its own computer.
//!
//! - `ugv planner VEHICLE`: PLANNER, the central planner. `PLANNER.next(robot)` emits
//!   `next_move(robot, kind)` for the robot's next elementary move, or `plan_done(robot)` once
//!   its plan is over; `PLANNER.replan(robot)` starts the robot's plan again from its next move.
//!   Each robot's plan brings it to the bottleneck at its second move: with moves of equal
//!   length, both robots reach it together.
//! - `ugv moves VEHICLE ROBOT PROGRAM [MS]`: a robot's interface layer (`MOVES_R1`...): the
//!   eight elementary moves (forward, backward, turn_right, turn_left, follow_right_wall,
//!   follow_left_wall, enter_bottleneck, exit_bottleneck); `execute(kind)` takes MS
//!   milliseconds (default 50), then emits `move_done(robot)`; `stop()` stops the move under way.
//!
//! Both stop on SIGINT or SIGTERM.

use std::collections::BTreeMap;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use petrel_programs::{Program, Value};

/// The eight elementary moves of the robots' movement library.
const MOVES: [&str; 8] = [
    "forward",
    "backward",
    "turn_right",
    "turn_left",
    "follow_right_wall",
    "follow_left_wall",
    "enter_bottleneck",
    "exit_bottleneck",
];

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["planner", vehicle] => planner(vehicle),
        ["moves", vehicle, robot, program] => moves(vehicle, robot, program, 50),
        ["moves", vehicle, robot, program, ms] => match ms.parse() {
            Ok(ms) => moves(vehicle, robot, program, ms),
            Err(_) => Err(format!("`{ms}` is not a number of milliseconds")),
        },
        _ => {
            eprintln!("usage: ugv planner VEHICLE | ugv moves VEHICLE ROBOT PROGRAM [MS]");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ugv: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Each robot's plan: to the bottleneck, through it, and on.
fn plan(robot: &str) -> Vec<&'static str> {
    match robot {
        "r1" => vec![
            "forward",
            "enter_bottleneck",
            "turn_left",
            "follow_right_wall",
        ],
        _ => vec![
            "forward",
            "enter_bottleneck",
            "turn_right",
            "follow_left_wall",
        ],
    }
}

fn planner(vehicle: &str) -> Result<(), String> {
    let mut program = Program::connect(vehicle, "PLANNER").map_err(|e| e.to_string())?;
    let mut next: BTreeMap<String, usize> = BTreeMap::new();
    loop {
        let call = match program.recv(None) {
            Ok(Some(call)) => call,
            Ok(None) => continue,
            Err(e) if e.is_termination() => break,
            Err(e) if e.is_fatal() => return Err(e.to_string()),
            Err(e) => {
                eprintln!("ugv planner: {e}");
                continue;
            }
        };
        let robot = match call.text(0) {
            Ok(r) => r.to_owned(),
            Err(e) => {
                eprintln!("ugv planner: {}: {e}", call.qualified_name());
                continue;
            }
        };
        let step = next.entry(robot.clone()).or_insert(0);
        let sent = match call.function.as_str() {
            // A replan goes on from the move that was stopped: the same plan here.
            "next" | "replan" => match plan(&robot).get(*step) {
                Some(kind) => {
                    *step += 1;
                    program.emit(
                        "next_move",
                        vec![Value::Text(robot.clone()), Value::Text((*kind).into())],
                    )
                }
                None => program.emit("plan_done", vec![Value::Text(robot.clone())]),
            },
            _ => {
                eprintln!("ugv planner: {}", call.unknown_function());
                continue;
            }
        };
        if let Err(e) = sent {
            eprintln!("ugv planner: {e}");
        }
    }
    program
        .close(Duration::from_millis(500))
        .map(|_| ())
        .map_err(|e| e.to_string())
}

fn moves(vehicle: &str, robot: &str, name: &str, ms: u64) -> Result<(), String> {
    let mut program = Program::connect(vehicle, name).map_err(|e| e.to_string())?;
    let length = Duration::from_millis(ms);
    // The move under way and when it ends.
    let mut under_way: Option<(String, Instant)> = None;
    loop {
        let timeout = under_way
            .as_ref()
            .map(|(_, end)| end.saturating_duration_since(Instant::now()));
        match program.recv(timeout) {
            Ok(Some(call)) => match call.function.as_str() {
                "execute" => match call.text(0) {
                    Ok(kind) if MOVES.contains(&kind) => {
                        println!("{robot}: {kind}");
                        under_way = Some((kind.to_owned(), Instant::now() + length));
                    }
                    Ok(kind) => eprintln!("ugv {robot}: `{kind}` is not an elementary move"),
                    Err(e) => eprintln!("ugv {robot}: execute: {e}"),
                },
                "stop" => {
                    if let Some((kind, _)) = under_way.take() {
                        println!("{robot}: {kind} stopped");
                    }
                }
                _ => eprintln!("ugv {robot}: {}", call.unknown_function()),
            },
            Ok(None) => {}
            Err(e) if e.is_termination() => break,
            Err(e) if e.is_fatal() => return Err(e.to_string()),
            Err(e) => eprintln!("ugv {robot}: {e}"),
        }
        if under_way
            .as_ref()
            .is_some_and(|(_, end)| Instant::now() >= *end)
        {
            under_way = None;
            if let Err(e) = program.emit("move_done", vec![Value::Text(robot.to_owned())]) {
                eprintln!("ugv {robot}: {e}");
            }
        }
    }
    program
        .close(Duration::from_millis(500))
        .map(|_| ())
        .map_err(|e| e.to_string())
}
