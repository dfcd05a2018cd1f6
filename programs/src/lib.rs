//! The SDK of Petrel's software programs: a process that plays one or several programs of a
//! vehicle (GUI, DEC, PLD...) receives the calls the player's nets make
//! (`call GUI.climb(300)`) and answers with events (`altitude_reached`), over iceoryx2 shared
//! memory (the `petrel-ipc` crate).
//!
//! ```text
//!   player --CallMsg--> petrel/<vehicle>/calls/<PROGRAM> --> Program::recv -> Call
//!   player <--EventMsg-- petrel/<vehicle>/events <---------- Program::emit(name, params)
//! ```
//!
//! - [`Program`] joins a vehicle as one or several programs ([`Program::connect`],
//!   [`Program::connect_many`]), hands over calls one at a time ([`Program::recv`]) and sends
//!   events ([`Program::emit`], [`Program::emit_as`]).
//! - Which receive: [`Program::recv`] returns each call as a new [`Call`], the simplest to
//!   use and keep; [`Program::recv_into`] writes it into a `Call` the program keeps, reusing
//!   its buffers (names, arguments, a text's or a `[float]`'s), so that a call costs no
//!   allocation: for a program on the latency-critical path (a controller answering calls
//!   thousands of times a second). Both wait, deliver queued events and fail alike.
//! - [`Call`] is a call, with typed accessors for its arguments ([`Call::float`],
//!   [`Call::text`], [`Call::floats`]...) whose errors ([`ArgError`]) name the function, the
//!   position and the types.
//! - Events emitted while no player runs wait in a bounded outbox ([`ProgramConfig`]) and are
//!   delivered in order when a player is there again; beyond the bound the oldest are dropped,
//!   counted ([`ProgramStats`]) and reported ([`ProgramError::EventsDropped`]). A program
//!   outlives the player: the calls of a restarted player arrive like the first one's.
//! - SIGINT and SIGTERM end [`Program::recv`] with [`ProgramError::Terminated`], so that a
//!   program leaves the vehicle in good order.
//! - Memory: a program's events sender is sized from the project the player runs (the player
//!   records its longest event in the events service when it creates it): one fixed segment of
//!   samples, about 4 MB less than the growing default; a longer event still goes, in pieces.
//!   A program started before the player creates the service itself, with no bound: its
//!   samples are 512 bytes, longer events go in pieces (never the growing default, whose
//!   unread events would go with the program if it left before the player read them); under
//!   `petrel up` the player starts first.
//!
//! The example is a minimal program (`echo`); the vehicles' programs built on this SDK live in
//! vehicles/ (the simulated UAV of the ProCoSA mission: `uav-gui` playing GUI and PLD,
//! `uav-dec` playing DEC, in vehicles/uav).
//!
//! What a restart of the player can still lose: events the old player had received but not yet
//! processed when it died, and events sent in the instant between its death and the liveness
//! check. Everything else is delivered or counted.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

mod call;
mod error;
mod outbox;
mod program;

pub use call::{write_invocation, write_value, ArgError, Call};
pub use error::ProgramError;
pub use program::{
    event_text, PlayerCheck, Program, ProgramConfig, ProgramStats, DEFAULT_OUTBOX_CAPACITY,
    DEFAULT_RETRY_PERIOD, LEAVE_GRACE,
};

/// The values that calls and events carry, and the wait strategies, re-exported so that a
/// program needs no other dependency.
pub use petrel_ipc::{EventMsg, Value, Vehicle, WaitStrategy};
