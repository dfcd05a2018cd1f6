//! The supervisor of `petrel up`.

mod shell;

pub use shell::run;
