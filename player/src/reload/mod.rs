//! A reload of the running project (`petrel reload`, docs/reload.md).

pub mod version;
