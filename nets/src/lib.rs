//! The Petrel net language: the model of a mission project, its parser, checker and formatter,
//! and its PNML and DOT interchange.
//!
//! Pure library: it reads files and nothing else. It builds on `petrel-value` (the typed values)
//! and `petrel-diag` (spans and diagnostics) only.

pub mod check;
pub mod compiled;
pub mod dot;
pub mod fmt;
mod follow_on;
pub mod formula;
pub mod instances;
pub mod manifest;
mod meant_event;
pub mod model;
pub mod pnml;
pub mod project;
pub mod pt;
pub mod reload;
pub mod semantics;
pub mod syntax;
