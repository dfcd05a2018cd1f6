//! The smallest program: prints every call it receives and answers `ping(...)` with
//! `pong(...)`, same arguments.
//!
//! `cargo run -p petrel-programs --example echo -- VEHICLE PROGRAM`; stop it with Ctrl-C.

use std::process::ExitCode;
use std::time::Duration;

use petrel_programs::Program;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [vehicle, name] = args.as_slice() else {
        eprintln!("usage: echo VEHICLE PROGRAM");
        return ExitCode::from(2);
    };
    let mut program = match Program::connect(vehicle, name) {
        Ok(program) => program,
        Err(e) => {
            eprintln!("echo: {e}");
            return ExitCode::from(2);
        }
    };
    println!("echo: {name} ready on vehicle {vehicle}");
    loop {
        match program.recv(None) {
            Ok(Some(call)) => {
                println!("echo: {call}");
                if call.function == "ping" {
                    if let Err(e) = program.emit("pong", call.args) {
                        eprintln!("echo: {e}");
                    }
                }
            }
            Ok(None) => {}
            Err(e) if e.is_termination() => break,
            Err(e) if e.is_fatal() => {
                eprintln!("echo: {e}");
                return ExitCode::FAILURE;
            }
            Err(e) => eprintln!("echo: {e}"),
        }
    }
    match program.close(Duration::from_millis(500)) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("echo: {e}");
            ExitCode::FAILURE
        }
    }
}
