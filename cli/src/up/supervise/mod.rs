//! The supervisor of `petrel up`: [`policy`] decides (sans I/O, the time injected: when each
//! process starts and is ready, restarts with doubling backoff, what a failure ends, the timed
//! sends, `--until` and the mission's end, the stop order), [`shell`] does (spawns through
//! `petrel __exec`, reaps, reads the signals, heartbeats, marking deltas and the programs'
//! nodes, sends, signals process groups, draws the status lines, tells systemd).

pub mod policy;
mod shell;

pub use shell::run;
