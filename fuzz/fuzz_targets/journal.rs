//! Journal segments read through the public reader (`petrel replay`, `petrel journal show` and
//! `--resume` all start there).
//!
//! Half the inputs are whole segments as they are; the other half are record bodies (each
//! prefixed by a 2-byte length in the input) that the target frames as the writer does, with
//! the magic, each body's length and a valid CRC-32: random bytes would almost never pass the
//! checksum, and the bodies are what a crafted journal controls (issue 10, item 4).
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::io::Write;

fn framed(data: &[u8]) -> Vec<u8> {
    let mut out = b"PETRELJ1".to_vec();
    let mut rest = data;
    while rest.len() >= 2 {
        let len = usize::from(u16::from_le_bytes([rest[0], rest[1]])).min(rest.len() - 2);
        let body = &rest[2..2 + len];
        out.extend_from_slice(&(body.len() as u32).to_le_bytes());
        out.extend_from_slice(&crc32fast::hash(body).to_le_bytes());
        out.extend_from_slice(body);
        rest = &rest[2 + len..];
    }
    out
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, data)) = data.split_first() else {
        return;
    };
    let bytes = if mode & 1 == 1 {
        framed(data)
    } else {
        data.to_vec()
    };
    let path = std::env::temp_dir().join(format!("petrel-fuzz-journal-{}.pj", std::process::id()));
    let written = std::fs::File::create(&path).and_then(|mut f| f.write_all(&bytes));
    if written.is_ok() {
        let _ = petrel_player::journal::read_journal(&path);
    }
    let _ = std::fs::remove_file(&path);
});
