//! The documentation keeps up with the code: every diagnostic code the code can report is listed
//! in docs/diagnostics.md.

use petrel_tests::repo;
use std::collections::BTreeSet;
use std::path::Path;

/// `"E0123"` / `"W0123"` string literals in the Rust files under `dir`.
fn codes_in(dir: &Path, out: &mut BTreeSet<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            codes_in(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap_or_default();
            let bytes = text.as_bytes();
            for i in 0..bytes.len().saturating_sub(6) {
                let w = &bytes[i..i + 7];
                if w[0] == b'"'
                    && (w[1] == b'E' || w[1] == b'W')
                    && w[2..6].iter().all(u8::is_ascii_digit)
                    && w[6] == b'"'
                {
                    out.insert(String::from_utf8_lossy(&w[1..6]).into_owned());
                }
            }
        }
    }
}

#[test]
fn every_diagnostic_code_is_documented() {
    let mut codes = BTreeSet::new();
    for krate in ["nets", "can_bridge", "player", "cli", "ipc", "programs"] {
        codes_in(&repo().join(krate).join("src"), &mut codes);
    }
    assert!(codes.len() > 40, "the scan found too few codes: {codes:?}");
    let docs = std::fs::read_to_string(repo().join("docs/diagnostics.md")).unwrap();
    let missing: Vec<&String> = codes
        .iter()
        .filter(|c| !docs.contains(&format!("| {c} |")))
        .collect();
    assert!(
        missing.is_empty(),
        "codes the code reports but docs/diagnostics.md does not list: {missing:?}"
    );
}
