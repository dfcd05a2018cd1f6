//! The Petrel player: the deterministic engine and the tools around it.
//!
//! - [`engine`]: sans-I/O; events in, actions out, time injected.
//! - [`record`]: the record of one step (event, firings, actions), which every reader of the
//!   player's steps goes through.
//! - [`script`]: missions as unit tests, in virtual time (`petrel run --script`); [`expect`]:
//!   what a script's `expect` lines say and how they are checked.
//! - [`runtime`]: the player process on iceoryx2 (`petrel play`), a thin shell around sans-I/O
//!   parts: [`intake`], what it does with each message it takes; [`held`], the calls it holds
//!   for programs joining; [`ack`], its ledger of what it took from each sender, refused and
//!   recorded (the acknowledgements of its heartbeat); [`reload`], the decisions of a reload
//!   (`petrel reload`; the mapping and verification are `petrel_nets::reload`'s) and the
//!   versions kept beside the journal; `status`, the status JSON of its heartbeat; `sizing`,
//!   the sizes of its services from the project.
//! - [`journal`], [`replay`]: the flight recorder and its replay (`--resume` too).
//! - [`shadow`]: the ground-station copy that follows a vehicle's steps.
//!
//! The command line is the `petrel-cli` crate (binary `petrel`).

pub mod ack;
pub mod engine;
pub mod expect;
pub mod held;
pub mod intake;
pub mod journal;
pub mod record;
pub mod reload;
pub mod replay;
pub mod runtime;
pub mod script;
pub mod shadow;
mod sizing;
mod status;
