//! `petrel` given crafted input (issue 10, items 3, 5 and 6): nothing writes outside its
//! directory, nothing crashes, every refusal says where and why, and a flood of errors gives
//! a short report.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn petrel(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_petrel"))
        .args(args)
        .output()
        .expect("petrel runs")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn uav() -> String {
    repo().join("missions/uav").display().to_string()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Before: the PNML's `<netfile path="../victim.pn">` overwrote the file, without `--force`.
#[test]
fn import_never_writes_outside_its_output_directory() {
    let work = tempfile::tempdir().unwrap();
    let victim = work.path().join("victim.pn");
    std::fs::write(&victim, "precious\n").unwrap();
    let o = petrel(&["export", "--pnml", &uav()]);
    assert_eq!(o.status.code(), Some(0));
    let pnml = String::from_utf8(o.stdout).unwrap();
    for bad in ["../victim.pn".to_string(), victim.display().to_string()] {
        let file = work.path().join("crafted.pnml");
        let crafted = pnml.replace("\"mission.pn\"", &format!("\"{bad}\""));
        std::fs::write(&file, &crafted).unwrap();
        // Every place the crafted path appears (the page's `<file>`, the Petrel block's
        // `<netfile>`) is reported at its own line.
        let lines: Vec<usize> = crafted
            .lines()
            .enumerate()
            .filter(|(_, l)| l.contains(&format!("\"{bad}\"")))
            .map(|(i, _)| i + 1)
            .collect();
        assert!(!lines.is_empty());
        let out = work.path().join("out");
        let o = petrel(&[
            "import",
            &file.display().to_string(),
            "--output",
            &out.display().to_string(),
        ]);
        assert_eq!(o.status.code(), Some(1), "{bad}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(err.contains("E0508"), "{err}");
        for line in &lines {
            assert!(
                err.contains(&format!("crafted.pnml:{line}:")),
                "{line}: {err}"
            );
        }
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious\n");
        assert!(!out.exists());
    }
}

/// Before: `petrel fmt` rewrote a manifest-listed file outside the project directory.
#[test]
fn fmt_never_rewrites_a_file_outside_the_project() {
    let work = tempfile::tempdir().unwrap();
    let outside = work.path().join("outside.pn");
    let original = "net A {\nplace    p = 1\n}\n";
    std::fs::write(&outside, original).unwrap();
    let dir = work.path().join("p");
    std::fs::create_dir(&dir).unwrap();
    for listed in ["../outside.pn".to_string(), outside.display().to_string()] {
        std::fs::write(
            dir.join("petrel.toml"),
            format!("[project]\nname = \"t\"\nfiles = [\"{listed}\"]\nstart = [\"A\"]\n"),
        )
        .unwrap();
        let o = petrel(&["fmt", &dir.display().to_string()]);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        let err = stderr(&o);
        assert!(
            err.contains("E0109") && err.contains("petrel.toml:3:"),
            "{err}"
        );
        assert_eq!(std::fs::read_to_string(&outside).unwrap(), original);
    }
}

/// Before: 40,000 bad characters on one line printed 790 MB in over 20 s.
#[test]
fn check_on_forty_thousand_bad_characters_prints_a_short_report() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("petrel.toml"),
        "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("a.pn"),
        format!("net A {{\n    place p = 1 {}\n}}\n", "$".repeat(40_000)),
    )
    .unwrap();
    let d = dir.path().display().to_string();
    let o = petrel(&["check", &d]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.len() < 200_000, "{} bytes", err.len());
    assert_eq!(err.matches("[E0001]").count(), 100);
    assert!(err.contains("... and 39900 more errors not shown"), "{err}");
    assert!(err.ends_with("40000 errors, 0 warnings\n"));
    let o = petrel(&["check", "--format", "json", &d]);
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(doc["errors"], 40_000);
    assert_eq!(doc["omitted"], 39_000);
}

/// Before: `--until nan` replayed to 0, `--max-states 0` was accepted, `--run-for 1e300`
/// panicked (exit 101). Each is now a usage error (exit 2) naming the option.
#[test]
fn numeric_options_are_exact_or_refused() {
    let journal = tempfile::tempdir().unwrap();
    let j = journal.path().display().to_string();
    let u = uav();
    let cases: [&[&str]; 7] = [
        &["replay", &j, "--until", "nan"],
        &["replay", &j, "--until=-1"],
        &["replay", &j, "--until", "inf"],
        &["verify", &u, "--max-states", "0"],
        &["play", &u, "--run-for", "1e300"],
        &["play", &u, "--rotate-mb", "0"],
        &["send", &u, "start_mission", "--count", "0"],
    ];
    for args in cases {
        let o = petrel(args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        let option = args.iter().rfind(|a| a.starts_with("--")).unwrap();
        let option = option.split('=').next().unwrap();
        assert!(err.contains(option), "{args:?}: {err}");
    }
}

/// Before: `waypoint([1e999], "x")` reached the player as `waypoint([0.0], "x")`, and 30,000
/// `[` aborted `petrel send` with a stack overflow. Both are refused before any vehicle is
/// joined.
#[test]
fn send_refuses_numbers_out_of_range_and_deep_nesting() {
    for (event, why) in [
        ("waypoint([1e999], \"x\")", "too large for a float"),
        (
            "waypoint([99999999999999999999], \"x\")",
            "does not fit in 64 bits",
        ),
        ("waypoint([1.0], \"x\") extra", "the end of the action"),
    ] {
        let o = petrel(&["send", &uav(), event, "--vehicle", "petrel_no_such_vehicle"]);
        assert_eq!(o.status.code(), Some(2), "{event}: {}", stderr(&o));
        assert!(stderr(&o).contains(why), "{event}: {}", stderr(&o));
    }
    let deep = format!(
        "waypoint({}1.0{}, \"x\")",
        "[".repeat(30_000),
        "]".repeat(30_000)
    );
    let o = petrel(&["send", &uav(), &deep, "--vehicle", "petrel_no_such_vehicle"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("nested more than"), "{}", stderr(&o));
}

/// A net file with lists nested 30,000 deep is an error, not a crash.
#[test]
fn check_refuses_deep_nesting_in_a_net_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("petrel.toml"),
        "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n[events]\ne = { category = \"nominal\", params = [\"w: [float]\"] }\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("a.pn"),
        format!(
            "net A {{\n    place p = 1\n    transition t: p -> p {{ emit e({}1.0{}) }}\n}}\n",
            "[".repeat(30_000),
            "]".repeat(30_000)
        ),
    )
    .unwrap();
    let o = petrel(&["check", &dir.path().display().to_string()]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("nested more than 32 deep"),
        "{}",
        stderr(&o)
    );
}

/// Before: `petrel bridge --replay` said nothing of time going back or of frames of the wrong
/// length. Now each is warned on standard error (time with its line), with the counters at the
/// end; standard output stays one JSON event a line.
#[test]
fn bridge_replay_warns_and_prints_its_counters_on_stderr() {
    let bench = repo().join("can_bridge/tests/data/auv");
    let dir = tempfile::tempdir().unwrap();
    let log = [
        "(1000.000000) vcan0 240#03 R",
        "(1000.050000) vcan0 240#03 R",
        "(1000.020000) vcan0 240#03 R",
        "(1000.100000) vcan0 230#3408 R",
        "(1000.300000) vcan0 240#03 R",
    ]
    .join("\n");
    let path = dir.path().join("bus.log");
    std::fs::write(&path, log).unwrap();
    let o = petrel(&[
        "bridge",
        &bench.display().to_string(),
        "--replay",
        &path.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("bus.log:line 3: time goes back from 1000.050000 s to 1000.020000 s"),
        "{err}"
    );
    assert!(err.contains("1 frame had another length"), "{err}");
    assert!(
        err.contains("replayed 5 records (5 received, 0 sent): 4 decoded, 1 of a length other than the DBC's (dropped)"),
        "{err}"
    );
    assert!(err.contains("time went back 1 times"), "{err}");
    for line in String::from_utf8(o.stdout).unwrap().lines() {
        let doc: serde_json::Value = serde_json::from_str(line).expect("one JSON event a line");
        assert!(doc["event"].is_string());
    }
}
