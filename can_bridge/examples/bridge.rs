//! The CAN data server as a process.
//!
//! ```text
//! cargo run -p petrel-can-bridge --example bridge -- --vehicle auv --project can_bridge/tests/data/auv --bus memory
//! cargo run -p petrel-can-bridge --example bridge -- --vehicle auv --project DIR --bus vcan0 --record bus.log
//! cargo run -p petrel-can-bridge --example bridge -- --project DIR --replay bus.log
//! ```
//!
//! It checks the project and its can.toml like `petrel check` (exit 1 on errors), then serves
//! the bus: `memory` is an in-process bus with a simulated depth sensor diving to 30 m and an
//! AHRS, anything else a SocketCAN interface. Events go to the vehicle's player; calls to the
//! commands program (can.toml's [commands] program) become frames. `--replay` prints the events
//! a recorded log gives, one JSON line each, and exits. RUST_LOG=debug tells more.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use petrel_can_bridge::load_project_can;
use petrel_can_bridge::serve::{replay_log, serve, ServeOptions};
use petrel_ipc::{Value, Vehicle, WaitStrategy};
use petrel_nets::diag::Diagnostics;

#[derive(Parser)]
#[command(about = "Petrel's CAN data server")]
struct Args {
    /// The vehicle's name (its iceoryx2 services).
    #[arg(long, default_value = "auv")]
    vehicle: String,
    /// The mission project directory (petrel.toml, can.toml and the DBC).
    #[arg(long)]
    project: PathBuf,
    /// `memory`, or a SocketCAN interface (default: can.toml's [bus] interface).
    #[arg(long)]
    bus: Option<String>,
    /// Record every frame in and out to this candump -L log.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Replay this candump -L log instead of serving a bus, and print the events.
    #[arg(long)]
    replay: Option<PathBuf>,
    /// block, spin, or spin-then-block:<micros>.
    #[arg(long, default_value = "block")]
    wait: WaitStrategy,
}

fn value_json(v: &Value) -> String {
    match v {
        Value::Int(i) => i.to_string(),
        Value::Float(f) if f.is_finite() => f.to_string(),
        Value::Float(_) => "null".to_owned(),
        Value::Bool(b) => b.to_string(),
        Value::Text(t) => format!("{t:?}"),
        Value::FloatList(l) => format!(
            "[{}]",
            l.iter()
                .map(|f| f.to_string())
                .collect::<Vec<_>>()
                .join(",")
        ),
    }
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let args = Args::parse();
    let (loaded, compiled, mut diags) = match petrel_nets::project::load_and_check(&args.project) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let mut sources = loaded.sources;
    let Some(project) = compiled else {
        eprint!("{}", diags.render_human(&sources));
        return ExitCode::from(1);
    };
    let mut can_diags = Diagnostics::new();
    let loaded = match load_project_can(&args.project, &project, &mut sources, &mut can_diags) {
        Ok(x) => x,
        Err(e) => {
            eprintln!(
                "cannot read {}: {e}",
                args.project.join("can.toml").display()
            );
            return ExitCode::from(2);
        }
    };
    diags.extend(can_diags);
    if !diags.is_empty() {
        eprint!("{}", diags.render_human(&sources));
    }
    let Some((config, dbc)) = loaded else {
        if !diags.has_errors() {
            eprintln!("{} has no can.toml", args.project.display());
            return ExitCode::from(2);
        }
        return ExitCode::from(1);
    };
    if diags.has_errors() {
        return ExitCode::from(1);
    }
    if let Some(log) = &args.replay {
        return match replay_log(log, config, dbc) {
            Ok(events) => {
                for e in events {
                    let params: Vec<String> = e.msg.params.iter().map(value_json).collect();
                    println!(
                        "{{\"time_us\":{},\"event\":{:?},\"params\":[{}]}}",
                        e.time_us,
                        e.msg.name,
                        params.join(",")
                    );
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("{e}");
                ExitCode::from(1)
            }
        };
    }
    let vehicle = match Vehicle::new(&args.vehicle) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let opts = ServeOptions {
        bus: args.bus,
        record: args.record,
        wait: args.wait,
        sim_faults: Default::default(),
    };
    match serve(&vehicle, config, dbc, opts) {
        Ok(report) => {
            eprintln!("{report:?}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::from(2)
        }
    }
}
