//! The AUV's data server: `petrel bridge`'s command line with the simulated AUV
//! ([`auv::plant`]) on the memory bus, for machines without CAN:
//!
//! ```text
//! auv-bridge missions/auv --vehicle auv --bus memory                  # the simulated AUV
//! auv-bridge missions/auv --vehicle auv --bus memory --leak-at 5      # its hull leaks at 5 m
//! ```
//!
//! On a SocketCAN interface (`--bus vcan0`) the vehicle is on the bus and this is the data
//! server alone, as `petrel bridge` is.

use std::process::ExitCode;

use auv::plant::{factory, SimFaults};
use clap::Parser;
use petrel_can_bridge::command::{main as bridge, BridgeArgs};

/// The AUV's CAN data server, with its simulator on the memory bus.
#[derive(Debug, Parser)]
#[command(name = "auv-bridge")]
struct Args {
    #[command(flatten)]
    bridge: BridgeArgs,
    /// On the memory bus: the vehicle's hull leaks once it is this deep (metres).
    #[arg(long, value_name = "METRES", value_parser = finite)]
    leak_at: Option<f64>,
}

/// A finite number: `nan` and `inf` are refused with the option's usage.
fn finite(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{text}` is not a finite number")),
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    let faults = SimFaults {
        leak_at_depth: args.leak_at,
    };
    bridge("auv-bridge", args.bridge, Some(factory(faults)))
}
