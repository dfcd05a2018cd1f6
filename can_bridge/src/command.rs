//! The data server's command line: what `petrel bridge` runs, and what each vehicle's own data
//! server runs with its simulator (`auv-bridge`, `redermor-bridge`: a few lines each, on
//! [`main`] with a [`PlantFactory`]).
//!
//! [`run`] loads and checks the project and its can.toml with the DBC (the diagnostics on
//! standard error, as `petrel check` renders them), then replays a recorded log (`--replay`:
//! its events as JSON lines on standard output) or serves the bus until SIGINT or SIGTERM.
//! Exit codes, as every `petrel` command's: 0 clean, 1 the project has errors, 2 usage or I/O.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use petrel_diag::plural::count;

use crate::config::load_project_can;
use crate::plant::PlantFactory;
use crate::serve::{replay_log, serve, ServeOptions};

/// The data server's arguments (`petrel bridge`'s, and a vehicle's data server's before its
/// simulator's own).
#[derive(clap::Args, Debug)]
pub struct BridgeArgs {
    /// The project directory (petrel.toml, can.toml and its DBC).
    pub dir: PathBuf,
    /// The vehicle; default: the project's name.
    #[arg(long)]
    pub vehicle: Option<String>,
    /// `memory` (an in-process bus, with the vehicle's simulator when this data server has
    /// one), or a SocketCAN interface such as vcan0; default: can.toml's [bus] interface.
    #[arg(long)]
    pub bus: Option<String>,
    /// Record every frame in and out to this candump -L log.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Instead of serving, replay this candump -L log and print the events it gives, one
    /// JSON document a line.
    #[arg(long)]
    pub replay: Option<PathBuf>,
    /// How the reactor waits: block, spin, or spin-then-block:<microseconds>.
    #[arg(long, default_value = "block")]
    pub wait: String,
}

/// Why [`run`] ended without serving to the end.
#[derive(Debug)]
pub enum Failure {
    /// The project or its CAN files have errors, already reported on standard error (exit 1).
    Errors,
    /// A usage or I/O error, to print as `error: ...` (exit 2).
    Usage(String),
}

/// The data server as a process's `main`: logs on standard error (`RUST_LOG` sets the level;
/// a host that set its own subscriber keeps it), then [`run`], and its exit code. `command`
/// names the program in messages (`petrel bridge`, `auv-bridge`).
pub fn main(command: &str, args: BridgeArgs, plant: Option<PlantFactory>) -> ExitCode {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
    match run(command, args, plant) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Errors) => ExitCode::from(1),
        Err(Failure::Usage(e)) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

/// Checks the project and its CAN files, then replays `args.replay` or serves the bus (with
/// `plant` on the memory bus) until SIGINT or SIGTERM.
pub fn run(command: &str, args: BridgeArgs, plant: Option<PlantFactory>) -> Result<(), Failure> {
    let (name, config, dbc) = load(&args.dir, command)?;
    if let Some(log) = &args.replay {
        return replay(log, config, dbc);
    }
    let wait = args.wait.parse().map_err(Failure::Usage)?;
    let name = args.vehicle.unwrap_or(name);
    let vehicle = petrel_ipc::Vehicle::new(&name)
        .map_err(|e| Failure::Usage(format!("bad vehicle name `{name}`: {e}")))?;
    let opts = ServeOptions {
        bus: args.bus,
        record: args.record,
        wait,
        plant,
    };
    match serve(&vehicle, config, dbc, opts) {
        Ok(r) => {
            eprintln!("bridge stopped: {r:?}");
            Ok(())
        }
        Err(e) => Err(Failure::Usage(e.to_string())),
    }
}

/// The project's name and its can.toml and DBC, checked against the project; every finding on
/// standard error.
fn load(dir: &Path, command: &str) -> Result<(String, crate::CanConfig, crate::Dbc), Failure> {
    let (mut loaded, compiled, mut diags) =
        petrel_nets::project::load_and_check(dir).map_err(|e| Failure::Usage(e.to_string()))?;
    let mut can = None;
    if let Some(c) = &compiled {
        can = load_project_can(dir, c, &mut loaded.sources, &mut diags)
            .map_err(|e| Failure::Usage(format!("cannot read the project's CAN files: {e}")))?;
        diags.sort();
    }
    if !diags.is_empty() {
        eprint!("{}", diags.render_human(&loaded.sources));
    }
    let Some(compiled) = compiled.filter(|_| !diags.has_errors()) else {
        eprintln!(
            "fix the errors above first: `{command}` needs a project that checks clean (`petrel check` lists them)"
        );
        return Err(Failure::Errors);
    };
    let Some((config, dbc)) = can else {
        return Err(Failure::Usage(format!(
            "{} has no can.toml: the CAN data server has nothing to serve",
            dir.display()
        )));
    };
    Ok((compiled.name, config, dbc))
}

/// Replays `log`: its events on standard output, one JSON document a line; what the replay
/// went through (time going back, frames of the wrong length, the counters) on standard error.
fn replay(log: &Path, config: crate::CanConfig, dbc: crate::Dbc) -> Result<(), Failure> {
    let replayed = replay_log(log, config, dbc).map_err(|e| {
        eprintln!("error: {e}");
        Failure::Errors
    })?;
    let s = &replayed.summary;
    for b in &s.backwards {
        eprintln!("warning: {}:{b}", log.display());
    }
    if s.time_backwards > s.backwards.len() as u64 {
        eprintln!(
            "warning: {}: time goes back {} more times",
            log.display(),
            s.time_backwards - s.backwards.len() as u64
        );
    }
    if s.counters.wrong_length > 0 {
        eprintln!(
            "warning: {}: {} had another length than the DBC gives their message: dropped, their signals not updated",
            log.display(),
            count(s.counters.wrong_length, "frame")
        );
    }
    eprintln!("{}: {s}", log.display());
    let mut text = String::new();
    for e in replayed.events {
        let params: Vec<serde_json::Value> = e.params.iter().map(|v| v.to_json()).collect();
        let doc = serde_json::json!({"time_us": e.time_us, "event": e.name, "params": params});
        text.push_str(&format!("{doc}\n"));
    }
    // A closed pipe (`... --replay bus.log | head`) ends the command quietly: the reader has
    // what it wanted.
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(Failure::Usage(format!(
            "cannot write to standard output: {e}"
        ))),
        _ => Ok(()),
    }
}
