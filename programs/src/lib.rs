//! The SDK for software programs (PLN, GUI, DEC...) and the vehicle's simulated programs.
//!
//! Empty until the player's runtime is built (issue 4).
