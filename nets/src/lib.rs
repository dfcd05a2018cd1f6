//! The Petrel net language: the model of a mission project, its parser, checker and formatter,
//! and its PNML and DOT interchange.
//!
//! Pure library: it reads files and nothing else. Every other Petrel crate builds on it, and it
//! builds on none of them.

pub mod check;
pub mod compiled;
pub mod diag;
pub mod dot;
pub mod duration;
pub mod fmt;
mod follow_on;
pub mod formula;
pub mod instances;
pub mod manifest;
mod meant_event;
pub mod model;
pub mod names;
pub mod paths;
pub mod plural;
pub mod pnml;
pub mod project;
pub mod pt;
pub mod reach;
pub mod reload;
pub mod semantics;
pub mod source;
mod stubborn;
pub mod syntax;
pub mod verify;
