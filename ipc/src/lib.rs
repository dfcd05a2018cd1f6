//! The one place that knows iceoryx2: service names for a vehicle, `#[repr(C)]` message types,
//! parameter encoding into loaned shared memory.
//!
//! Empty until the player's runtime is built (issue 4): no code here pretends to exist before
//! it does.
