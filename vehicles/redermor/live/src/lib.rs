//! The Redermor AUV on the bus: the domain of `redermor` carried by processes, as on the
//! bench of section 3.1.4 of the ProCoSA paper.
//!
//! ```text
//!   redermor-bridge  ── plant::RedermorPlant (sim::Simulator) on the memory bus
//!        │ signals (latest values)          ▲ CAN.ThrusterCmd, CAN.DepthCmd
//!        ▼                                  │
//!   redermor-program --role NAV (GDD, GUI, IDC: programs::Nav)
//!   redermor-program --role PLN (programs::Pln)      redermor-program --role EVT (programs::Evt)
//! ```
//!
//! - [`bus`]: the bus's messages (missions/redermor/redermor.dbc) to and from the domain's
//!   readings and commands, and the simulator's clock (it may run faster than the wall).
//! - [`plant`]: the Redermor simulator as a [`petrel_can_bridge::plant::Plant`].
//! - [`programs`]: what each program does with its calls (missions/redermor/INTERFACE.md),
//!   sans-I/O: calls and readings in, answers and commands out.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod bus;
pub mod plant;
pub mod programs;
