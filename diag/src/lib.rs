//! The layer every checker of a Petrel project shares: source files and spans, diagnostics
//! with stable codes, "did you mean" hints, paths confined to their directory, durations as
//! files write them, counts of things in words (`plural`).
//!
//! The net language (petrel-nets), the CAN data server's `can.toml` checker and the CLI's
//! `vehicle.toml` checker all report through it, so a problem in any file of a project reads the
//! same. Pure library: it reads nothing itself.

pub mod duration;
pub mod names;
pub mod paths;
pub mod plural;
pub mod report;
pub mod source;
pub mod toml;
