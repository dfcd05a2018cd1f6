//! Redermor's data server: `petrel bridge`'s command line with the Redermor simulator
//! ([`RedermorPlant`]) on the memory bus, as `petrel up missions/redermor` runs it:
//!
//! ```text
//! redermor-bridge missions/redermor --bus memory --mission missions/redermor/sim/mission.toml \
//!     --scenario missions/redermor/sim/nominal.toml --speed 20 --trace trace.csv
//! ```
//!
//! The simulator's options are `redermor-sim`'s (which runs the same plant as its own process
//! on a SocketCAN bus). Its files are read when the memory bus is opened, after the project
//! and its CAN files checked clean; an error names the file or the option (exit 2). On a
//! SocketCAN interface the vehicle is on the bus and this is the data server alone.
//!
//! [`RedermorPlant`]: redermor_live::plant::RedermorPlant

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use petrel_can_bridge::command::{main as bridge, BridgeArgs};
use petrel_can_bridge::plant::PlantFactory;
use redermor_live::plant::PlantFiles;

/// Redermor's CAN data server, with its simulator on the memory bus.
#[derive(Debug, Parser)]
#[command(name = "redermor-bridge")]
struct Args {
    #[command(flatten)]
    bridge: BridgeArgs,
    /// The mission file (where the vehicle starts, the seabed).
    #[arg(long, value_name = "FILE")]
    mission: PathBuf,
    /// The scenario file (current, faults at their times); default: a calm sea, no fault.
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// How many times faster than the wall clock the vehicle's time runs.
    #[arg(long, value_name = "FACTOR", default_value_t = 1.0)]
    speed: f64,
    /// Write the vehicle's true track here (CSV, one line a second of its time), for
    /// `petrel plot` and the tests.
    #[arg(long, value_name = "FILE")]
    trace: Option<PathBuf>,
}

fn main() -> ExitCode {
    let Args {
        bridge: args,
        mission,
        scenario,
        speed,
        trace,
    } = Args::parse();
    let plant: PlantFactory = Box::new(move |dbc| {
        let files = PlantFiles::read(&mission, scenario.as_deref(), speed, trace.as_deref())?;
        Ok(Box::new(files.build(dbc)) as _)
    });
    bridge("redermor-bridge", args, Some(plant))
}
