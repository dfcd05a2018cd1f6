//! `petrel bridge`: the CAN data server, serving a bus or replaying a recorded one. It is
//! petrel-can-bridge's command line ([`petrel_can_bridge::command`]) with no simulated vehicle:
//! a vehicle's simulator comes with that vehicle's own data server (`auv-bridge`,
//! `redermor-bridge` in vehicles/), on the same command line.

use crate::common::Outcome;
use petrel_can_bridge::command::{run, BridgeArgs, Failure};

/// Serves the vehicle's CAN bus (or replays a log of it).
pub fn bridge(a: BridgeArgs) -> Outcome {
    match run("petrel bridge", a, None) {
        Ok(()) => Outcome::Clean,
        Err(Failure::Errors) => Outcome::Errors,
        Err(Failure::Usage(e)) => Outcome::Usage(e),
    }
}
