//! A DBC of any text; when it parses, every message of it decodes a frame of a fuzzed payload
//! (the bit layouts, factors and ranges of crafted signals), of its own length and of others.
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_can_bridge::{Dbc, Frame};

fuzz_target!(|data: &[u8]| {
    // The first 64 bytes are a frame payload, the rest the DBC.
    let (payload, text) = data.split_at(data.len().min(64));
    let text = String::from_utf8_lossy(text);
    let Ok(dbc) = Dbc::parse(&text) else {
        return;
    };
    for m in dbc.messages() {
        for len in [m.size.min(payload.len()), payload.len().min(8)] {
            let bytes = &payload[..len];
            if let Ok(f) = Frame::data(m.id, bytes) {
                let _ = dbc.decode(&f);
            }
            if let Ok(f) = Frame::fd(m.id, bytes, 0) {
                let _ = dbc.decode(&f);
            }
        }
    }
});
