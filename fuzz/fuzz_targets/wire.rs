//! The ipc wire decoder on any body, for every message kind the services carry: what a
//! process of the vehicle reads out of shared memory written by another.
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_ipc::wire::{
    decode, CallMsg, EventMsg, Heartbeat, MarkingMsg, ReloadAnswer, ReloadRequest, SignalsMsg,
};

fuzz_target!(|data: &[u8]| {
    let _ = decode::<EventMsg>(data);
    let _ = decode::<CallMsg>(data);
    let _ = decode::<MarkingMsg>(data);
    let _ = decode::<Heartbeat>(data);
    let _ = decode::<SignalsMsg>(data);
    let _ = decode::<ReloadRequest>(data);
    let _ = decode::<ReloadAnswer>(data);
});
