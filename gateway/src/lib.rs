//! `petrel gateway`: a vehicle spread over several computers. Each computer runs its own
//! iceoryx2 services (shared memory does not leave a host); one gateway per computer joins
//! them to the others over zenoh, so that a program on another computer is called and heard
//! exactly as a local one.
//!
//! ```text
//!  computer A (player)                          computer B (programs)
//!  player --calls/PLN--> [stand-in program/PLN] ==zenoh==> gateway B --calls/PLN--> PLN
//!  player <--events----- gateway A <==zenoh== [gateway B: events receiver] <--events-- PLN
//!  player --heartbeat, marking--> gateway A ==zenoh==> [stand-in player] --> PLN, shadows
//! ```
//!
//! - [`link`]: the one message type on the link and its keys (`petrel/<vehicle>/link/<computer>`).
//! - [`core`]: the decisions, sans I/O: routing, peers lost and restored within the detection
//!   bound, which stand-ins to keep, counters accounting for every message.
//! - [`session`]: the zenoh session: endpoints, mutual TLS with the vehicle's keys, each peer
//!   bound by zenoh's access control to its certificate's computer.
//! - [`keys`]: the vehicle's keys (its certificate authority, a certificate per computer).
//! - [`reliable`]: events and calls carried on numbered streams, acknowledged, sent again, or
//!   given up with their senders told; [`ledger`]: the verdicts this computer's senders wait for
//!   on the events the link gave up.
//! - [`runtime`]: the process: one thread, a reactor over the iceoryx2 ports and the zenoh
//!   subscriber's wake-ups.
//!
//! docs/gateway.md describes the vehicle file's part and what a computer's loss does.

#![warn(missing_docs)]

pub mod core;
pub mod keys;
pub mod ledger;
pub mod link;
pub mod reliable;
pub mod runtime;
pub mod session;

pub use crate::core::{Core, Counts, PeerChange, PeerState, Plan};
pub use crate::runtime::{run, Credentials, GatewayError, LinkEvents, Settings};
pub use crate::session::Security;
