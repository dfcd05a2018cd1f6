//! The data server as a process: what `petrel bridge` and the vehicles' own data servers run
//! ([`crate::command`]).
//!
//! [`serve`] opens the bus (a SocketCAN interface, or `memory`: an in-process bus, with the
//! vehicle's simulator as a [`crate::plant::Plant`] when the server has one, for machines
//! without CAN) and runs the bridge until SIGINT or SIGTERM; [`replay_log`] feeds a recorded
//! `candump -L` log through the bridge offline and returns the events it gives.

use crate::bridge::BridgeCore;
use crate::bus::{MemoryHub, SocketCanBus, SocketCanOptions};
use crate::clock::{Clock, ManualClock, SystemClock};
use crate::config::CanConfig;
use crate::dbc::Dbc;
use crate::plant::{spawn_plant, PlantFactory};
use crate::replay::{replay_counted, Pacing, Replayed};
use crate::runtime::{run, RunReport, RuntimeError, RuntimeOptions};
use petrel_ipc::{Vehicle, WaitStrategy};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// How to serve.
pub struct ServeOptions {
    /// `memory`, or a SocketCAN interface; `None`: can.toml's `[bus] interface`, else memory.
    pub bus: Option<String>,
    /// Record every frame in and out to this `candump -L` log.
    pub record: Option<std::path::PathBuf>,
    /// How the reactor waits.
    pub wait: WaitStrategy,
    /// The simulated vehicle of the memory bus, made from the DBC; `None`: the memory bus
    /// carries the data server alone (a SocketCAN bus never has one: the vehicle is there).
    pub plant: Option<PlantFactory>,
}

/// Why the server could not run.
#[derive(Debug)]
pub enum ServeError {
    /// A file could not be created or read.
    Io(String),
    /// The bus could not be opened.
    Bus(String),
    /// The bridge stopped on an error.
    Runtime(String),
    /// A log could not be replayed.
    Replay(String),
}

impl std::fmt::Display for ServeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ServeError::Io(e)
            | ServeError::Bus(e)
            | ServeError::Runtime(e)
            | ServeError::Replay(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for ServeError {}

/// Serves the bus for `vehicle` until SIGINT or SIGTERM.
pub fn serve(
    vehicle: &Vehicle,
    config: CanConfig,
    dbc: Dbc,
    opts: ServeOptions,
) -> Result<RunReport, ServeError> {
    let dbc = Arc::new(dbc);
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let record: Option<Box<dyn std::io::Write>> = match &opts.record {
        None => None,
        Some(p) => match std::fs::File::create(p) {
            Ok(f) => Some(Box::new(std::io::BufWriter::new(f))),
            Err(e) => {
                return Err(ServeError::Io(format!(
                    "cannot create {}: {e}",
                    p.display()
                )))
            }
        },
    };
    let run_opts = RuntimeOptions {
        wait: opts.wait,
        record,
        ..RuntimeOptions::default()
    };
    let stop = AtomicBool::new(false);
    let bus_name = opts
        .bus
        .or(config.interface.clone())
        .unwrap_or_else(|| "memory".to_owned());
    let fd = config.fd;
    let filters = if config.receive_only_dbc {
        dbc.socket_filters()
    } else {
        Vec::new()
    };
    let core = BridgeCore::new(dbc.clone(), config, clock.now_us());
    let result = if bus_name == "memory" {
        let hub = MemoryHub::new(clock.clone());
        let bus = hub
            .endpoint("mem0")
            .map_err(|e| ServeError::Bus(format!("cannot make a memory bus: {e}")))?;
        let sim_stop = Arc::new(AtomicBool::new(false));
        let sim = match opts.plant {
            Some(make) => {
                let plant = make(dbc).map_err(|e| {
                    ServeError::Bus(format!("cannot make the simulated vehicle: {e}"))
                })?;
                Some(spawn_plant(&hub, plant, sim_stop.clone()).map_err(|e| {
                    ServeError::Bus(format!("cannot start the simulated vehicle: {e}"))
                })?)
            }
            None => None,
        };
        let result = run(core, move || Ok(bus), clock, vehicle, run_opts, &stop);
        sim_stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if sim.is_some_and(|s| s.join().is_err()) {
            tracing::error!("the simulated vehicle's thread panicked");
        }
        result
    } else {
        let sock_opts = SocketCanOptions {
            fd,
            filters,
            ..SocketCanOptions::default()
        };
        // Opened by the loop once the vehicle is joined (see `run`).
        let open = || SocketCanBus::open(&bus_name, &sock_opts);
        return match run(core, open, clock, vehicle, run_opts, &stop) {
            Err(RuntimeError::Bus(e)) => Err(ServeError::Bus(e.to_string())),
            r => r.map_err(|e| ServeError::Runtime(e.to_string())),
        };
    };
    result.map_err(|e| ServeError::Runtime(e.to_string()))
}

/// Replays a recorded `candump -L` log through the bridge as fast as possible: the events it
/// gives, in order, and what the replay went through (counters, time going back).
pub fn replay_log(log: &Path, config: CanConfig, dbc: Dbc) -> Result<Replayed, ServeError> {
    let text = std::fs::read_to_string(log)
        .map_err(|e| ServeError::Io(format!("cannot read {}: {e}", log.display())))?;
    let start = text
        .lines()
        .find_map(|l| crate::log::parse_line(l.trim()).ok())
        .map_or(0, |r| r.time_us);
    let mut core = BridgeCore::new(Arc::new(dbc), config, start);
    replay_counted(
        &mut core,
        &text,
        Pacing::AsFastAsPossible,
        &ManualClock::new(0),
    )
    .map_err(|e| ServeError::Replay(format!("{}: {e}", log.display())))
}
