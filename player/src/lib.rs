//! The Petrel player: the deterministic engine and the tools around it.
//!
//! - [`engine`]: sans-I/O; events in, actions out, time injected.
//! - [`script`]: missions as unit tests, in virtual time (`petrel run --script`).
//! - [`runtime`]: the player process on iceoryx2 (`petrel play`).

pub mod engine;
pub mod journal;
pub mod replay;
pub mod runtime;
pub mod script;
pub mod shadow;
