//! The documentation keeps up with the code: every diagnostic code the code can report is listed
//! in docs/diagnostics.md, and every code the documentation cites is one the code reports.

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

/// Every code the crates' sources report.
fn codes_of_the_code() -> BTreeSet<String> {
    let mut codes = BTreeSet::new();
    for krate in [
        "diag",
        "nets",
        "verify",
        "can_bridge",
        "player",
        "cli",
        "ipc",
        "programs",
    ] {
        codes_in(&repo().join(krate).join("src"), &mut codes);
    }
    assert!(codes.len() > 40, "the scan found too few codes: {codes:?}");
    codes
}

/// Words shaped like a code (`E0123`, `W0123`) in a text, with their line numbers.
fn codes_cited(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let bytes = line.as_bytes();
        for i in 0..bytes.len().saturating_sub(4) {
            let before = i.checked_sub(1).map(|b| bytes[b]);
            let after = bytes.get(i + 5);
            if (bytes[i] == b'E' || bytes[i] == b'W')
                && bytes[i + 1..i + 5].iter().all(u8::is_ascii_digit)
                && !before.is_some_and(|b| b.is_ascii_alphanumeric())
                && !after.is_some_and(u8::is_ascii_alphanumeric)
            {
                out.push((n + 1, line[i..i + 5].to_string()));
            }
        }
    }
    out
}

/// Before: docs/language.md cited E0605, E0610 and E0611 for errors the checker reports as
/// E0412, E0410 and E0417. A code the documentation cites must be one the code reports.
#[test]
fn every_code_the_docs_cite_exists() {
    let codes = codes_of_the_code();
    let mut pages = vec![repo().join("README.md"), repo().join("ARCHITECTURE.md")];
    for entry in std::fs::read_dir(repo().join("docs")).unwrap().flatten() {
        if entry.path().extension().is_some_and(|e| e == "md") {
            pages.push(entry.path());
        }
    }
    let mut unknown = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        for (line, code) in codes_cited(&text) {
            if !codes.contains(&code) {
                unknown.push(format!("{}:{line}: {code}", page.display()));
            }
        }
    }
    assert!(pages.len() > 5, "{pages:?}");
    assert!(
        unknown.is_empty(),
        "codes the docs cite that no code reports: {unknown:?}"
    );
}

#[test]
fn every_diagnostic_code_is_documented() {
    let codes = codes_of_the_code();
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
