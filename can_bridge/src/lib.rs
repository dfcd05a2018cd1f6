//! The CAN data server of Petrel (the OA_NAVIO analogue of the ProCoSA paper): it owns the
//! vehicle's CAN bus, turns frames into signals and events for the player and the programs, and
//! turns the programs' commands into frames.
//!
//! Sans-I/O first, like the rest of Petrel: the bus and the clock are injected, and everything
//! but [`bus::SocketCanBus`] and [`runtime`] runs on any machine.
//!
//! ```text
//!  bus (SocketCAN | memory) --frames--> BridgeCore --EventOut--> runtime --EventMsg--> player
//!        ^                                |  decode (dbc)  rules  faults     ^
//!        |                                |  SignalTable (latest values)    | calls CAN.Msg(...)
//!        +-----frames (commands, heartbeat)+<---------------------------------+ (programs, nets)
//!  candump -L log <-- record    replay --> BridgeCore (same events, offline)
//! ```
//!
//! - [`frame`]: [`frame::Frame`], a CAN frame as a value (classic, remote, error, CAN FD).
//! - [`bus_state`]: [`bus_state::BusState`], the controller's state, from error frames and the
//!   interface.
//! - [`dbc`]: loading a DBC (can-dbc), decoding and encoding with cantools' semantics;
//!   [`dbc::DecodeOutcome`], what became of a frame.
//! - [`config`]: `can.toml`: [`config::CanConfig`] and the types under it, reading and checking
//!   it ([`config::check_rules`] for `petrel check`, [`config::load_project_can`]).
//! - [`event`]: [`event::EventOut`], what the bridge emits (name, parameters, time, cause).
//! - [`rules`]: the [`rules::RuleEngine`] that turns signals into events (thresholds with
//!   hysteresis, bands, debounce, edges, staleness).
//! - [`faults`]: bus state changes as events.
//! - [`log`]: the `candump -L` format, read and written.
//! - [`replay`]: a log back into the core, as fast as possible or time-faithfully.
//! - [`bus`]: the [`bus::Bus`] trait, [`bus::SocketCanBus`] and [`bus::MemoryBus`].
//! - [`bridge`]: [`bridge::BridgeCore`], the data server without I/O.
//! - [`runtime`]: the process loop over a bus and the vehicle's iceoryx2 services.
//! - [`serve`]: the data server as a process; offline replay of a log.
//! - [`command`]: its command line, `petrel bridge`'s and each vehicle's own data server's
//!   (`auv-bridge`, `redermor-bridge`, which give [`command::main`] their simulator).
//! - [`plant`]: the host of a vehicle's simulator on the bus ([`plant::Plant`]; the
//!   vehicles' simulators live in `vehicles/`, not here).
//! - [`clock`]: injected time.
//!
//! **Who may use `petrel_ipc`**: [`runtime`], [`serve`] and [`command`] only (and [`bus`] names its fd
//! source in a comment). The core (`bridge`, `config`, `event`, `rules`, `faults`, `bus_state`,
//! `dbc`, `frame`, `log`, `replay`, `clock`, `plant`) works on its own types, so that it builds and
//! is tested without the shared-memory transport; its values are `petrel_value::Value`, the one
//! value type the wire carries too. A unit test holds the line.
//!
//! Modules import one another without cycles. In the core, each imports only from those before
//! it: `frame`, `log`, `bus_state`, `dbc`, `config`, `event`, `rules`, `faults`, `bridge`,
//! `replay` (`clock` imports nothing); `plant` and `bus` use the frames, the DBC and the states;
//! `runtime`, `serve` and `command` sit on top.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod bridge;
pub mod bus;
pub mod bus_state;
pub mod clock;
pub mod command;
pub mod config;
pub mod dbc;
pub mod event;
pub mod faults;
pub mod frame;
pub mod log;
pub mod plant;
pub mod replay;
pub mod rules;
pub mod runtime;
pub mod serve;

pub use bridge::{BridgeCore, SignalTable};
pub use bus::{Bus, MemoryBus, MemoryHub, SocketCanBus};
pub use bus_state::BusState;
pub use clock::{Clock, ManualClock, SystemClock};
pub use config::{check_rules, load_project_can, CanConfig};
pub use dbc::Dbc;
pub use event::{EventCause, EventOut};
pub use frame::{CanId, Frame, FrameKind, TimedFrame};
pub use rules::RuleEngine;

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// The core's modules: none may name `petrel_ipc` outside comments.
    const CORE: [&str; 12] = [
        "bridge",
        "config",
        "event",
        "rules",
        "faults",
        "bus_state",
        "dbc",
        "frame",
        "log",
        "replay",
        "clock",
        "plant",
    ];

    fn sources(path: &Path, out: &mut Vec<(String, String)>) {
        if path.is_dir() {
            for entry in std::fs::read_dir(path).unwrap() {
                sources(&entry.unwrap().path(), out);
            }
        } else if path.is_file() && path.extension().is_some_and(|e| e == "rs") {
            out.push((
                path.display().to_string(),
                std::fs::read_to_string(path).unwrap(),
            ));
        }
    }

    #[test]
    fn the_core_does_not_use_the_transport() {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let mut checked = 0;
        for module in CORE {
            let mut files = Vec::new();
            sources(&src.join(format!("{module}.rs")), &mut files);
            sources(&src.join(module), &mut files);
            assert!(!files.is_empty(), "module `{module}` not found");
            for (path, text) in files {
                checked += 1;
                for (n, line) in text.lines().enumerate() {
                    let code = line.split("//").next().unwrap_or("");
                    assert!(
                        !code.contains("petrel_ipc"),
                        "{path}:{}: the core must not use petrel_ipc; convert in runtime.rs",
                        n + 1
                    );
                }
            }
        }
        assert!(checked >= CORE.len());
    }
}
