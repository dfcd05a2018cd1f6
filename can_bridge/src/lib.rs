//! The CAN data server of Petrel (the OA_NAVIO analogue of the ProCoSA paper): it owns the
//! vehicle's CAN bus, turns frames into signals and events for the player and the programs, and
//! turns the programs' commands into frames.
//!
//! Sans-I/O first, like the rest of Petrel: the bus and the clock are injected, and everything
//! but [`bus::SocketCanBus`] and [`runtime`] runs on any machine.
//!
//! ```text
//!  bus (SocketCAN | memory) --frames--> BridgeCore --events--> runtime --EventMsg--> player
//!        ^                                |  decode (dbc)  rules  faults     ^
//!        |                                |  SignalTable (latest values)    | calls CAN.Msg(...)
//!        +-----frames (commands, heartbeat)+<---------------------------------+ (programs, nets)
//!  candump -L log <-- record    replay --> BridgeCore (same events, offline)
//! ```
//!
//! - [`frame`]: [`frame::Frame`], a CAN frame as a value (classic, remote, error, CAN FD).
//! - [`dbc`]: loading a DBC (can-dbc), decoding and encoding with cantools' semantics.
//! - [`rules`]: `can.toml` (its format, [`rules::check_rules`] for `petrel check`), and the
//!   [`rules::RuleEngine`] that turns signals into events (thresholds with hysteresis, bands,
//!   debounce, edges, staleness).
//! - [`faults`]: bus states from error frames and the interface, and their events.
//! - [`log`]: the `candump -L` format, read and written.
//! - [`replay`]: a log back into the core, as fast as possible or time-faithfully.
//! - [`bus`]: the [`bus::Bus`] trait, [`bus::SocketCanBus`] and [`bus::MemoryBus`].
//! - [`bridge`]: [`bridge::BridgeCore`], the data server without I/O.
//! - [`runtime`]: the process loop over a bus and the vehicle's iceoryx2 services.
//! - [`clock`]: injected time.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod bridge;
pub mod bus;
pub mod clock;
pub mod dbc;
pub mod faults;
pub mod frame;
pub mod log;
pub mod replay;
pub mod rules;
pub mod runtime;
pub mod serve;
pub mod sim;

pub use bridge::{BridgeCore, SignalTable};
pub use bus::{Bus, MemoryBus, MemoryHub, SocketCanBus};
pub use clock::{Clock, ManualClock, SystemClock};
pub use dbc::Dbc;
pub use frame::{CanId, Frame, FrameKind, TimedFrame};
pub use rules::{check_rules, load_project_can, CanConfig, EventOut, RuleEngine};
