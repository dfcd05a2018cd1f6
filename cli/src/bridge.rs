//! `petrel bridge`: the CAN data server, serving a bus or replaying a recorded one.

use crate::common::{out, require_clean, vehicle_of, wait_strategy, Outcome, Scope};
use petrel_diag::plural::count;
use std::path::PathBuf;

/// `petrel bridge`.
#[derive(clap::Args)]
pub struct BridgeArgs {
    /// The project directory (petrel.toml, can.toml and its DBC).
    dir: PathBuf,
    /// The vehicle; default: the project's name.
    #[arg(long)]
    vehicle: Option<String>,
    /// `memory` (an in-process bus with a simulated AUV that obeys the commands), or a
    /// SocketCAN interface such as vcan0; default: can.toml's [bus] interface.
    #[arg(long)]
    bus: Option<String>,
    /// On the memory bus: the simulated vehicle's hull leaks once it is this deep (metres).
    #[arg(long, value_name = "METRES", value_parser = crate::common::finite)]
    sim_leak_at: Option<f64>,
    /// On the memory bus: the simulated vehicle, `auv` (the default) or `redermor` (the
    /// Redermor simulator of `petrel-redermor`, which needs --sim-mission).
    #[arg(long, value_name = "VEHICLE", default_value = "auv")]
    sim: String,
    /// `--sim redermor`: the mission file (where the vehicle starts, the seabed).
    #[arg(long, value_name = "FILE")]
    sim_mission: Option<PathBuf>,
    /// `--sim redermor`: the scenario file (current, faults at their times).
    #[arg(long, value_name = "FILE")]
    sim_scenario: Option<PathBuf>,
    /// `--sim redermor`: how many times faster than the wall clock the vehicle's time runs.
    #[arg(long, value_name = "FACTOR", default_value_t = 1.0, value_parser = crate::common::finite)]
    sim_speed: f64,
    /// `--sim redermor`: write the vehicle's true track here (CSV, one line a second of its
    /// time), for `petrel plot` and the tests.
    #[arg(long, value_name = "FILE")]
    sim_trace: Option<PathBuf>,
    /// Record every frame in and out to this candump -L log.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Instead of serving, replay this candump -L log and print the events it gives, one
    /// JSON document a line.
    #[arg(long)]
    replay: Option<PathBuf>,
    /// How the reactor waits: block, spin, or spin-then-block:<microseconds>.
    #[arg(long, default_value = "block")]
    wait: String,
}

/// Serves the vehicle's CAN bus (or replays a log of it).
pub fn bridge(a: BridgeArgs) -> Outcome {
    use petrel_can_bridge::serve::{replay_log as replay_can, serve, ServeOptions};
    let checked = match require_clean(
        &a.dir,
        Scope {
            can: true,
            quick_verify: false,
            vehicle: false,
            map: false,
        },
        "bridge",
    ) {
        Ok(c) => c,
        Err(o) => return o,
    };
    let Some(c) = checked.compiled else {
        return Outcome::Errors;
    };
    let Some((config, dbc)) = checked.can else {
        return Outcome::Usage(format!(
            "{} has no can.toml: the CAN data server has nothing to serve",
            a.dir.display()
        ));
    };
    if let Some(log) = a.replay {
        return match replay_can(&log, config, dbc) {
            Ok(replayed) => {
                // Standard output stays one JSON event a line; what the replay went through
                // goes to standard error.
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
                    let params: Vec<serde_json::Value> =
                        e.params.iter().map(|v| v.to_json()).collect();
                    let doc = serde_json::json!({"time_us": e.time_us, "event": e.name, "params": params});
                    text.push_str(&format!("{doc}\n"));
                }
                out(&text);
                Outcome::Clean
            }
            Err(e) => {
                eprintln!("error: {e}");
                Outcome::Errors
            }
        };
    }
    let strategy = match wait_strategy(&a.wait) {
        Ok(s) => s,
        Err(o) => return o,
    };
    let v = match vehicle_of(&c, a.vehicle) {
        Ok(v) => v,
        Err(o) => return o,
    };
    let plant = match redermor_plant(
        &a.sim,
        a.sim_mission,
        a.sim_scenario,
        a.sim_speed,
        a.sim_trace,
    ) {
        Ok(p) => p,
        Err(e) => return Outcome::Usage(e),
    };
    let opts = ServeOptions {
        plant,
        bus: a.bus,
        record: a.record,
        wait: strategy,
        sim_faults: petrel_can_bridge::sim::SimFaults {
            leak_at_depth: a.sim_leak_at,
        },
    };
    match serve(&v, config, dbc, opts) {
        Ok(r) => {
            eprintln!("bridge stopped: {r:?}");
            Outcome::Clean
        }
        Err(e) => Outcome::Usage(e.to_string()),
    }
}

/// The simulated vehicle `--sim` names, with its files read and checked now (an error names
/// the file and the field).
fn redermor_plant(
    sim: &str,
    mission: Option<PathBuf>,
    scenario: Option<PathBuf>,
    speed: f64,
    trace: Option<PathBuf>,
) -> Result<Option<petrel_can_bridge::serve::PlantFactory>, String> {
    use petrel_redermor_live::plant::PlantFiles;
    match sim {
        "auv" => {
            if mission.is_some() || scenario.is_some() || trace.is_some() {
                return Err(
                    "--sim-mission, --sim-scenario and --sim-trace go with --sim redermor".into(),
                );
            }
            Ok(None)
        }
        "redermor" => {
            let Some(mission) = mission else {
                return Err("--sim redermor needs --sim-mission FILE".into());
            };
            let files = PlantFiles::read(
                &mission,
                scenario.as_deref(),
                speed,
                trace.as_deref(),
                "--sim-",
            )?;
            Ok(Some(Box::new(move |dbc| {
                Ok(Box::new(files.build(dbc)) as _)
            })))
        }
        other => Err(format!(
            "--sim {other}: the simulated vehicles are auv and redermor"
        )),
    }
}
