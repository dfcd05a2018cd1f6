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

use std::process::ExitCode;

use clap::Parser;
use petrel_can_bridge::command::{main as bridge, BridgeArgs};
use petrel_can_bridge::plant::PlantFactory;
use redermor_live::plant::{PlantFiles, SimArgs};

/// Redermor's CAN data server, with its simulator on the memory bus.
#[derive(Debug, Parser)]
#[command(name = "redermor-bridge")]
struct Args {
    #[command(flatten)]
    bridge: BridgeArgs,
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    let Args { bridge: args, sim } = Args::parse();
    let plant: PlantFactory = Box::new(move |dbc| {
        let files = PlantFiles::read(&sim)?;
        Ok(Box::new(files.build(dbc)) as _)
    });
    bridge("redermor-bridge", args, Some(plant))
}
