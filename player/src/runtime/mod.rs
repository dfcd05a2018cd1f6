//! The player process: the engine wired to iceoryx2 (`petrel play`).
//!
//! [`play`] builds a [`PlayerLoop`] and runs it. One reactor thread waits, with the chosen
//! strategy, on the events service, the next timer deadline, the heartbeat and the liveness
//! check. On each wake-up it moves time forward, drains incoming events into the engine
//! (refusing malformed ones, and built-in events that other processes send, with a
//! `bad_message` event), turns dead programs into
//! `program_lost`, processes the queue, sends calls (an absent program gives `call_failed`),
//! journals every input and step, and publishes marking deltas and a heartbeat carrying the
//! live status (JSON, for people and tools) and, typed, the acknowledgement of each sender
//! ([`crate::ack`]). The heartbeat is the acknowledgement senders wait for, and an event is
//! acknowledged as settled only after the journal holding it is flushed: an acknowledged event
//! is on record. The heartbeat's publisher is sized from the project, so that the status of
//! the largest marking and the fullest ledger always fit; a heartbeat that cannot be sent
//! anyway is logged and counted (`heartbeats_refused` in the status).

mod heartbeat;
mod options;
mod player_loop;
mod ports;
mod publish;
mod reload;
mod sink;
mod start;

pub use options::{PlayError, PlayOptions, PlayReport};
pub use player_loop::PlayerLoop;

use petrel_nets::compiled::CompiledProject;

/// Runs the player until SIGINT/SIGTERM (or `run_for`).
pub fn play(project: &CompiledProject, opts: &PlayOptions) -> Result<PlayReport, PlayError> {
    PlayerLoop::new(project, opts)?.run()
}

#[cfg(test)]
mod tests;
