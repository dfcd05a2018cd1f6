//! The AUV of missions/auv, simulated: the vehicle on the bus ([`plant`]), which its data
//! server `auv-bridge` hosts on the memory bus, and the guidance program `auv-gui` that
//! commands it through the server (src/bin).
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod plant;
