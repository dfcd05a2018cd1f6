//! The player process: the engine wired to iceoryx2 (`petrel play`).
//!
//! [`play`] builds a [`PlayerLoop`] and runs it. [`PlayerLoop::new`] (`start.rs`) joins the
//! vehicle, takes the journal directory (one player's, one vehicle's), rebuilds the engine
//! from the journal for `--resume`, opens the ports at the sizes of the project
//! ([`crate::sizing`]), opens the journal and starts the mission, or carries the restored one
//! on. [`PlayerLoop::run`] (`player_loop.rs`) is one reactor thread that waits, with the chosen
//! strategy, on the events service, the reload service, the next timer deadline, the heartbeat
//! and the liveness check. A round:
//!
//! 1. processes the queue: each step journaled and published as a marking delta
//!    (`publish.rs`), its calls sent as the engine makes them (`sink.rs`: a call that finds no
//!    receiver is held if its program's process lives, [`crate::held`], and becomes
//!    `call_failed` otherwise);
//! 2. publishes the heartbeat when it is due (`heartbeat.rs`): the live status as JSON, for
//!    people and tools ([`crate::status`]), and, typed, the acknowledgement of each sender
//!    ([`crate::ack`]), what senders wait for; a heartbeat that cannot be sent is logged and
//!    counted (`heartbeats_refused` in the status);
//! 3. writes the journal's batch, and waits;
//! 4. moves mission time forward (wall-clock time since the mission started, so that a resume
//!    after a crash expires the timers that fell due meanwhile), takes the events
//!    ([`crate::intake`]: decoded in place, the name looked up where it lies in the sample,
//!    the parameters moved from one kept buffer into one of the engine's; no event built),
//!    checks the programs' liveness (a program whose process went is `program_lost`, or a stop,
//!    journaled, when it said it leaves: the events are drained once more before a going is
//!    judged, so that a leave sent just before is read), and takes the reload requests and
//!    verdicts (`reload.rs`, [`crate::reload`]).
//!
//! # Invariants
//!
//! - **The journal before the engine**: an input is journaled before the engine takes it, so
//!   that replay and `--resume` see every input.
//! - **Written before sleeping**: what the loop journaled reaches the operating system before
//!   it sleeps (one copy into the mapped window, or one write, for an event and the steps it
//!   caused, after their calls went out); under a spinning wait strategy at most
//!   [`BATCH_DELAY`](crate::journal::BATCH_DELAY) (1 ms) after the oldest record it holds.
//! - **Flushed before the heartbeat**, so before any acknowledgement: an event acknowledged as
//!   settled is on record; what the recorder keeps in memory is pending, what it dropped is
//!   unrecorded.
//! - **The call before its text**: a step's call goes out before its text is built; the marking
//!   delta is built only when a monitor listens (the next one gets a snapshot), and names only
//!   the places that changed (`record::place_changes`).
//! - **The clock read twice a round**: before the wait (the heartbeat, the journal's hold, the
//!   wait's timeout) and after it (mission time, the ledger's clock).
//! - **Sized from the project**: every call sender, the events service, the marking and the
//!   heartbeat publishers ([`crate::sizing`]), so that no message this project can give is
//!   refused for its size.

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
