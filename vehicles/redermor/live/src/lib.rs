//! The Redermor AUV on the bus: the domain of `petrel-redermor` carried by processes, as on the
//! bench of section 3.1.4 of the ProCoSA paper.
//!
//! ```text
//!   petrel bridge --sim redermor  ── plant::RedermorPlant (sim::Simulator) on the memory bus
//!        │ signals (latest values)          ▲ CAN.ThrusterCmd, CAN.DepthCmd
//!        ▼                                  │
//!   redermor-program --role NAV (GDD, GUI, IDC: programs::Nav)
//!   redermor-program --role PLN (programs::Pln)      redermor-program --role EVT (programs::Evt)
//! ```
//!
//! - [`bench`](mod@bench): the bus's messages (missions/redermor/redermor.dbc) to and from the domain's
//!   readings and commands, and the bench clock (the simulator may run faster than the wall).
//! - [`plant`]: the Redermor simulator as a [`petrel_can_bridge::sim::Plant`].
//! - [`programs`]: what each program does with its calls (missions/redermor/INTERFACE.md),
//!   sans-I/O: calls and readings in, answers and commands out.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod bench;
pub mod plant;
pub mod programs;
