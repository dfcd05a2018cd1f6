//! The Redermor simulator as its own process on a SocketCAN bus (the vehicle of the bench of
//! section 3.1.4, on a real vcan0 or can0):
//!
//! ```text
//! redermor-sim --bus vcan0 --dbc missions/redermor/redermor.dbc \
//!     --mission missions/redermor/sim/mission.toml --scenario missions/redermor/sim/leak.toml \
//!     --speed 20 --trace trace.csv
//! ```
//!
//! It reads the commands the data server (`petrel bridge --bus vcan0`) sends (`ThrusterCmd`,
//! `DepthCmd`, `SupervisorHeartbeat`) and writes the sensors' frames at their rates, as the
//! vehicle's nodes would: the same plant ([`RedermorPlant`]) and the same host loop
//! ([`run_plant`]) as `redermor-bridge --bus memory` runs on a thread, with the same options.
//! It runs until killed (SIGTERM, SIGINT); the trace is written a line at a time, so nothing
//! is lost then.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use clap::Parser;
use petrel_can_bridge::bus::{SocketCanBus, SocketCanOptions};
use petrel_can_bridge::dbc::Dbc;
use petrel_can_bridge::plant::run_plant;
use petrel_can_bridge::SystemClock;
use redermor_live::plant::{PlantFiles, RedermorPlant, SimArgs};

/// The Redermor simulator on a SocketCAN interface.
#[derive(Debug, Parser)]
#[command(name = "redermor-sim")]
struct Args {
    /// The SocketCAN interface (vcan0, can0).
    #[arg(long, value_name = "INTERFACE")]
    bus: String,
    /// The bus's DBC (missions/redermor/redermor.dbc).
    #[arg(long, value_name = "FILE")]
    dbc: PathBuf,
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("redermor-sim: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<(), String> {
    let dbc = Dbc::load(&args.dbc).map_err(|e| format!("{}: {e}", args.dbc.display()))?;
    let files = PlantFiles::read(&args.sim)?;
    let mut plant: RedermorPlant = files.build(Arc::new(dbc));
    // The vehicle's nodes send no error frames and want none: the data server watches the
    // bus's health.
    let opts = SocketCanOptions {
        error_frames: false,
        ..SocketCanOptions::default()
    };
    let mut bus = SocketCanBus::open(&args.bus, &opts).map_err(|e| e.to_string())?;
    eprintln!(
        "redermor-sim: on {} at {} times the wall clock, waiting for the thrusters to be enabled",
        args.bus, args.sim.speed
    );
    // Never set: the process ends by a signal, as a vehicle's node is switched off.
    let stop = AtomicBool::new(false);
    run_plant(&mut bus, &mut plant, &SystemClock, &stop);
    Ok(())
}
