//! Golden tests: one small project per class of diagnostic, under `tests/data/diagnostics/`.
//!
//! Each case directory holds a project and `expected.txt`, the exact report a user sees. Run
//! with `PETREL_BLESS=1` to rewrite the expected files after a deliberate change, then review
//! the diff.

use petrel_nets::project::load_and_check;
use std::path::{Path, PathBuf};

fn case_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/diagnostics")
        .join(name)
}

/// The human report of a case, with the machine-specific directory prefix removed.
fn report(name: &str) -> (String, serde_json::Value, Vec<&'static str>) {
    let dir = case_dir(name);
    let (loaded, compiled, d) = load_and_check(&dir).expect("case project reads");
    // A case of errors does not compile; a case of warnings only (W0108) does.
    assert_eq!(compiled.is_none(), d.has_errors(), "case {name}");
    let prefix = format!("{}/", dir.display());
    let text = d
        .render_human(&loaded.sources)
        .replace(&prefix, "")
        .replace(&dir.display().to_string(), "<project dir>");
    let json = d.to_json(&loaded.sources);
    let codes = d.iter().map(|d| d.code).collect();
    (text, json, codes)
}

fn golden(name: &str) -> Vec<&'static str> {
    let (text, _, codes) = report(name);
    let path = case_dir(name).join("expected.txt");
    if std::env::var_os("PETREL_BLESS").is_some() {
        std::fs::write(&path, &text).unwrap();
    }
    let expected = std::fs::read_to_string(&path)
        .unwrap_or_else(|_| panic!("{} missing: run with PETREL_BLESS=1", path.display()));
    assert_eq!(text, expected, "report of case {name} changed");
    codes
}

#[test]
fn syntax_errors_are_all_reported_with_line_and_caret() {
    let codes = golden("syntax");
    assert!(codes.len() >= 3, "{codes:?}");
    assert!(codes.iter().all(|c| *c == "E0001"));
}

#[test]
fn unknown_names_of_every_kind() {
    let codes = golden("unknown_names");
    for code in ["E0201", "E0202", "E0203", "E0204", "E0205", "E0206"] {
        assert!(codes.contains(&code), "{code} missing from {codes:?}");
    }
}

#[test]
fn duplicate_names() {
    let codes = golden("duplicates");
    assert_eq!(
        codes.iter().filter(|c| **c == "E0301").count(),
        4,
        "{codes:?}"
    );
}

#[test]
fn argument_count_and_type_mismatches_in_calls_and_emits() {
    let codes = golden("arguments");
    assert!(
        codes.contains(&"E0401") && codes.contains(&"E0402"),
        "{codes:?}"
    );
}

#[test]
fn names_the_event_does_not_bind() {
    let codes = golden("unbound");
    assert_eq!(
        codes.iter().filter(|c| **c == "E0207").count(),
        4,
        "{codes:?}"
    );
}

#[test]
fn initial_markings_above_one_token() {
    let codes = golden("marking");
    assert_eq!(codes, ["E0405", "E0405"]);
}

#[test]
fn manifest_naming_a_missing_file() {
    assert_eq!(golden("missing_file"), ["E0104"]);
}

/// Before: a renamed net file gave W0101, E0104, E0202 and E0208, none saying it followed
/// from the others.
#[test]
fn a_renamed_net_file_and_what_follows_from_it_name_each_other() {
    let codes = golden("renamed_file");
    assert_eq!(codes, ["W0101", "E0104", "E0202", "E0208"]);
    let expected = std::fs::read_to_string(case_dir("renamed_file").join("expected.txt")).unwrap();
    assert!(
        expected.contains("did you mean \"phase.pn\"?"),
        "{expected}"
    );
    assert!(
        expected.contains("if \"phase.pn\" is that file renamed"),
        "{expected}"
    );
    assert_eq!(
        expected
            .matches("this may follow from net file `phases.pn`")
            .count(),
        2
    );
}

#[test]
fn manifest_values_categories_types_timers() {
    let codes = golden("manifest_values");
    for code in ["E0102", "E0103", "E0407"] {
        assert!(codes.contains(&code), "{code} missing from {codes:?}");
    }
}

/// Before: a transition written without `on EVENT` checked clean, silently immediate.
#[test]
fn an_immediate_transition_named_like_an_unused_event() {
    assert_eq!(golden("immediate"), ["W0108", "W0108"]);
}

/// Before: each call of `NAV.goto` and the emission of `report` gave an E0401 ("takes 1
/// argument(s), 2 given") and the trigger an E0403 after the E0103 of the bad type.
#[test]
fn a_bad_type_gives_one_error_not_one_per_use() {
    assert_eq!(golden("manifest_types"), ["E0103", "E0103"]);
}

#[test]
fn manifest_that_is_not_toml() {
    assert_eq!(golden("manifest_toml"), ["E0101"]);
}

#[test]
fn trigger_bindings_count_and_types() {
    let codes = golden("bindings");
    assert!(
        codes.contains(&"E0403") && codes.contains(&"E0404"),
        "{codes:?}"
    );
}

#[test]
fn arcs_repeated_places_and_shadowed_globals() {
    let codes = golden("arcs");
    for code in ["E0406", "E0409", "E0302"] {
        assert!(codes.contains(&code), "{code} missing from {codes:?}");
    }
}

#[test]
fn json_report_names_file_line_and_column() {
    let (_, json, _) = report("unknown_names");
    let list = json["diagnostics"].as_array().unwrap();
    assert_eq!(json["errors"].as_u64().unwrap() as usize, list.len());
    let place = list
        .iter()
        .find(|d| d["code"] == "E0201")
        .expect("unknown place reported");
    assert!(place["file"].as_str().unwrap().ends_with("a.pn"));
    assert_eq!(place["line"], 4);
    assert_eq!(place["column"], 37);
    assert_eq!(place["end_column"], 42);
    assert_eq!(place["severity"], "error");
    assert!(place["help"]
        .as_str()
        .unwrap()
        .contains("did you mean `busy`?"));
}

#[test]
fn templates_instances_and_activation_arguments() {
    let codes = golden("templates");
    for code in [
        "E0209", "E0210", "E0303", "E0304", "E0401", "E0402", "E0412", "E0418",
    ] {
        assert!(codes.contains(&code), "{code} missing from {codes:?}");
    }
}

#[test]
fn children_completion_places_and_finish() {
    let codes = golden("hierarchy");
    for code in ["E0413", "E0414", "E0415"] {
        assert!(codes.contains(&code), "{code} missing from {codes:?}");
    }
}

#[test]
fn guards_and_emptiness_tests() {
    let codes = golden("guards");
    assert_eq!(
        codes.iter().filter(|c| **c == "E0410").count(),
        3,
        "{codes:?}"
    );
    for code in ["E0207", "E0416", "E0209"] {
        assert!(codes.contains(&code), "{code} missing from {codes:?}");
    }
}

#[test]
fn program_names_invariants_scoped_globals_and_allows() {
    let codes = golden("language");
    for code in ["E0107", "E0108", "E0211", "E0417", "W0106"] {
        assert!(codes.contains(&code), "{code} missing from {codes:?}");
    }
}

/// Issue 10, item 6: 40,000 bad characters on one line gave 40,000 reports, each printing the
/// whole line (790 MB, over 20 s; 3.2 GB and 188 s in a debug build of the test). The report
/// is now capped and each excerpt cut to a window: its size no longer grows with the square of
/// the line.
#[test]
fn forty_thousand_bad_characters_on_one_line_give_a_short_report() {
    let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n";
    let net = format!("net A {{\n    place p = 1 {}\n}}\n", "$".repeat(40_000));
    let (_, compiled, d, sources) = petrel_nets::project::from_sources(manifest, &[("a.pn", &net)]);
    assert!(compiled.is_none());
    assert_eq!(d.error_count(), 40_000);
    let text = d.render_human(&sources);
    assert!(
        text.len() < 200_000,
        "the report is {} bytes long",
        text.len()
    );
    assert_eq!(
        text.matches("[E0001] Error").count(),
        petrel_diag::report::MAX_HUMAN
    );
    assert!(
        text.contains("... and 39900 more errors not shown"),
        "{}",
        &text[text.len() - 300..]
    );
    assert!(text.ends_with("40000 errors, 0 warnings\n"));
    // Each excerpt points at its own character: the columns stay exact.
    assert!(text.contains("a.pn:2:17 ]"), "{}", &text[..600]);
    assert!(text.contains("a.pn:2:116 ]"));
    let json = d.to_json(&sources);
    assert_eq!(json["errors"], 40_000);
    assert_eq!(json["omitted"], 40_000 - petrel_diag::report::MAX_JSON);
    assert_eq!(
        json["diagnostics"].as_array().map(Vec::len),
        Some(petrel_diag::report::MAX_JSON)
    );
}

/// A long line shows a window around its caret, with the true line and column.
#[test]
fn a_finding_on_a_long_line_shows_a_window_of_it() {
    let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n";
    let long = format!(
        "net A {{\n    place p = 1\n    transition t: p -> p {{ emit e({}, $) }}\n}}\n",
        "1.0, ".repeat(100)
    );
    let (_, _, d, sources) = petrel_nets::project::from_sources(manifest, &[("a.pn", &long)]);
    let text = d.render_human(&sources);
    let col = long.lines().nth(2).unwrap().find('$').unwrap() + 1;
    assert!(text.contains(&format!("a.pn:3:{col} ]")), "{text}");
    assert!(text.contains("...1.0, 1.0,"), "{text}");
    assert!(text.contains("a part is shown"), "{text}");
    // The caret sits under the `$`.
    let lines: Vec<&str> = text.lines().collect();
    let at = lines.iter().position(|l| l.contains("$)")).unwrap();
    let dollar = lines[at].find('$').unwrap();
    assert_eq!(lines[at + 1].find('^'), Some(dollar), "{text}");
}
