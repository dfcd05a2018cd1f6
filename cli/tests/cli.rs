//! The `petrel` command as a user runs it: exit codes, outputs, files written.

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

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A copy of a project in a fresh directory, so tests may change it.
fn copy_project(from: &Path) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
        }
    }
    dir
}

#[test]
fn check_on_the_uav_mission_exits_0_with_a_summary() {
    let o = petrel(&["check", &uav()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.contains("project `uav` checks clean: 2 nets (2 active at start)"),
        "{out}"
    );
    assert!(stderr(&o).is_empty());
}

#[test]
fn check_with_errors_exits_1_and_reports_every_error() {
    let case = repo().join("nets/tests/data/diagnostics/unknown_names");
    let o = petrel(&["check", &case.display().to_string()]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    for code in ["E0201", "E0202", "E0203", "E0204", "E0205", "E0206"] {
        assert!(err.contains(code), "{code} missing:\n{err}");
    }
    assert!(err.contains("a.pn:4:37"), "{err}");
    assert!(err.ends_with("7 errors, 0 warnings\n"), "{err}");
}

#[test]
fn check_json_lists_the_diagnostics_for_tools() {
    let case = repo().join("nets/tests/data/diagnostics/marking");
    let o = petrel(&["check", "--format", "json", &case.display().to_string()]);
    assert_eq!(o.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("valid JSON");
    assert_eq!(doc["errors"], 2);
    let d = &doc["diagnostics"][1];
    assert_eq!(d["code"], "E0405");
    assert_eq!(d["line"], 2);
    assert_eq!(d["column"], 18);
    assert!(d["file"].as_str().unwrap().ends_with("a.pn"));
}

#[test]
fn usage_and_io_errors_exit_2() {
    let o = petrel(&["check", "/nonexistent/project"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("has no petrel.toml"), "{}", stderr(&o));
    assert_eq!(petrel(&["check"]).status.code(), Some(2));
    assert_eq!(petrel(&["frobnicate"]).status.code(), Some(2));
    let o = petrel(&["import", "/nonexistent.pnml"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn fmt_rewrites_to_canonical_layout_and_a_second_run_changes_nothing() {
    let dir = copy_project(&repo().join("missions/uav"));
    let path = dir.path().join("mission.pn");
    let canonical = std::fs::read_to_string(&path).unwrap();
    // Squash the layout: every line's indentation gone, blank lines doubled.
    let messy: String = canonical
        .lines()
        .map(|l| format!("{}\n", l.trim_start()))
        .collect::<String>()
        .replace("\n\n", "\n\n\n");
    std::fs::write(&path, &messy).unwrap();
    let d = dir.path().display().to_string();

    let o = petrel(&["fmt", "--check", &d]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stdout(&o).contains("not in canonical layout"),
        "{}",
        stdout(&o)
    );
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        messy,
        "--check writes nothing"
    );

    let o = petrel(&["fmt", &d]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&path).unwrap(), canonical);

    let o = petrel(&["fmt", &d]);
    assert_eq!(o.status.code(), Some(0));
    assert!(
        stdout(&o).is_empty(),
        "second run formatted: {}",
        stdout(&o)
    );
    assert_eq!(petrel(&["fmt", "--check", &d]).status.code(), Some(0));
}

#[test]
fn fmt_leaves_a_file_with_syntax_errors_untouched() {
    let dir = copy_project(&repo().join("nets/tests/data/diagnostics/syntax"));
    let path = dir.path().join("a.pn");
    let before = std::fs::read_to_string(&path).unwrap();
    let o = petrel(&["fmt", &dir.path().display().to_string()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("E0001"));
    assert_eq!(std::fs::read_to_string(&path).unwrap(), before);
}

#[test]
fn dot_draws_the_mission_with_shared_global_places() {
    let o = petrel(&["dot", &uav()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let dot = stdout(&o);
    assert!(dot.starts_with("digraph"), "{dot}");
    assert!(dot.contains("cluster_MISSION") && dot.contains("cluster_EVENTS"));
    // The global place `replan` is one node, written by EVENTS and read by MISSION.
    assert_eq!(dot.matches("\"global.replan\" [shape").count(), 1, "{dot}");
    assert!(
        dot.contains("\"EVENTS.t.payload_lost\" -> \"global.replan\""),
        "{dot}"
    );
    assert!(
        dot.contains("\"global.replan\" -> \"MISSION.t.replanning\""),
        "{dot}"
    );

    let o = petrel(&["dot", &uav(), "--net", "EVENTS"]);
    assert_eq!(o.status.code(), Some(0));
    let only = stdout(&o);
    assert!(only.contains("cluster_EVENTS") && !only.contains("cluster_MISSION"));

    let o = petrel(&["dot", &uav(), "--net", "NOPE"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("MISSION"), "{}", stderr(&o));
}

#[test]
fn dot_draws_each_instance_and_the_tree_of_nets() {
    let language = repo()
        .join("nets/tests/data/language")
        .display()
        .to_string();
    let o = petrel(&["dot", &language]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let dot = stdout(&o);
    assert!(
        dot.contains("cluster_R1") && dot.contains("cluster_R2"),
        "{dot}"
    );
    assert!(dot.contains("arrowhead=odot"), "{dot}");

    let o = petrel(&["dot", &language, "--net", "ROBOT"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stdout(&o).contains("cluster_SYNC"));

    let o = petrel(&["dot", &language, "--tree"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let tree = stdout(&o);
    assert!(tree.contains("language: tree of nets"), "{tree}");
    assert!(tree.contains("\"PHASES\" -> \"PHASES/TRANSIT\";"), "{tree}");
    assert!(
        tree.contains("\"SYNC\" -> \"PLAN\" [style=dashed, label=\"activate\"];"),
        "{tree}"
    );

    // The tree is of the whole project: it does not take a net.
    let o = petrel(&["dot", &language, "--tree", "--net", "R1"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn verify_says_when_a_pnml_file_is_a_petrel_export() {
    let out = tempfile::tempdir().unwrap();
    let pnml = out.path().join("language.pnml").display().to_string();
    let language = repo()
        .join("nets/tests/data/language")
        .display()
        .to_string();
    let o = petrel(&["export", "--pnml", &language, "-o", &pnml]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));

    // The skeleton has no emptiness test: `SYNC.raise` marks `alarm` again and again.
    let o = petrel(&["verify", &pnml]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(
        err.starts_with(&format!("note: {pnml}: this file is a Petrel export")),
        "{err}"
    );
    assert!(
        err.contains("only its P/T skeleton is analysed")
            && err.contains("no emptiness tests")
            && err.contains("petrel verify DIR"),
        "{err}"
    );
    assert!(err.contains("unbounded"), "{err}");

    let o = petrel(&["verify", &pnml, "--format", "json"]);
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(doc["petrel_export"], true);
    assert!(doc["note"]
        .as_str()
        .is_some_and(|n| n.contains("P/T skeleton")));
    assert!(
        !stderr(&o).contains("note:"),
        "JSON says it in the document"
    );

    // A plain P/T net gets no note.
    let plain = repo()
        .join("verify/tests/data/mcc/Sudoku-PT-AN01.pnml")
        .display()
        .to_string();
    let o = petrel(&["verify", &plain]);
    assert!(!stderr(&o).contains("Petrel export"), "{}", stderr(&o));
    let o = petrel(&["verify", &plain, "--format", "json"]);
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(doc["petrel_export"], false);
    assert!(doc.get("note").is_none());
}

#[test]
fn export_then_import_gives_back_the_same_project() {
    let out = tempfile::tempdir().unwrap();
    let pnml = out.path().join("uav.pnml");
    let o = petrel(&[
        "export",
        "--pnml",
        &uav(),
        "-o",
        &pnml.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let xml = std::fs::read_to_string(&pnml).unwrap();
    assert!(xml.contains("<toolspecific tool=\"petrel\""));

    let back = out.path().join("uav");
    let o = petrel(&[
        "import",
        &pnml.display().to_string(),
        "-o",
        &back.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        petrel(&["check", &back.display().to_string()])
            .status
            .code(),
        Some(0)
    );

    let original = petrel_nets::project::load(&repo().join("missions/uav")).unwrap();
    let imported = petrel_nets::project::load(&back).unwrap();
    assert_eq!(imported.project, original.project);
    // Net files come back byte for byte (the manifest is rewritten canonically).
    for f in ["mission.pn", "events.pn"] {
        assert_eq!(
            std::fs::read_to_string(back.join(f)).unwrap(),
            std::fs::read_to_string(repo().join("missions/uav").join(f)).unwrap()
        );
    }

    // Importing again into the same directory refuses to overwrite without --force.
    let o = petrel(&[
        "import",
        &pnml.display().to_string(),
        "-o",
        &back.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--force"));
}

#[test]
fn verify_proves_the_uav_mission_and_lists_its_planned_ends() {
    let o = petrel(&["verify", &uav()]);
    assert_eq!(o.status.code(), Some(0), "{}{}", stdout(&o), stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("safe: yes"), "{out}");
    assert!(
        out.contains("dead markings: 2 (2 intended, 0 not)"),
        "{out}"
    );
    assert!(out.ends_with("result: verified, no error\n"), "{out}");

    let o = petrel(&["verify", &uav(), "--format", "json"]);
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    for key in [
        "states",
        "edges",
        "max_tokens_in_place",
        "max_tokens_per_marking",
        "safe",
        "deadlock",
    ] {
        assert!(doc.get(key).is_some(), "{key} missing");
    }
    assert_eq!(doc["safe"], true);
    assert_eq!(doc["deadlock"], false);
}

#[test]
fn verify_and_check_report_each_flaw_with_its_trace() {
    let flawed = repo()
        .join("verify/tests/data/verify/flawed")
        .display()
        .to_string();
    let o = petrel(&["verify", &flawed]);
    assert_eq!(o.status.code(), Some(1));
    let out = stdout(&o);
    for line in [
        "error[E0601]: A.begin would put a second token in global.busy, after go → done → go",
        "error[E0602]: dead marking: A{stuck}, after spare",
        "error[E0603]: immediate transitions loop forever: A.wob → A.ble, after go → more",
        "warning[W0601]: on done, A.end fires and A.stop does not (written order), after go → done",
        "nets never activated: Unused",
    ] {
        assert!(out.contains(line), "missing `{line}` in:\n{out}");
    }
    // Each finding is also shown where it is, as `petrel check` shows its own.
    for at in ["a.pn:9:16", "a.pn:15:16", "a.pn:6:11", "a.pn:21:5"] {
        assert!(out.contains(at), "missing `{at}` in:\n{out}");
    }

    // `check` runs the same verification and points at the transitions.
    let o = petrel(&["check", &flawed]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    for code in ["E0601", "E0602", "E0603", "W0601", "W0602", "W0603"] {
        assert!(err.contains(code), "{code} missing:\n{err}");
    }
    assert!(err.contains("a.pn:9:16"), "E0601 points at `begin`: {err}");
    // --no-verify keeps to the language.
    assert_eq!(
        petrel(&["check", "--no-verify", &flawed]).status.code(),
        Some(0)
    );

    let o = petrel(&["verify", &flawed, "--max-states", "2"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--max-states"), "{}", stderr(&o));
    let o = petrel(&["verify", &flawed, "--net", "Nope"]);
    assert_eq!(o.status.code(), Some(2));
}

fn progress_data(name: &str) -> String {
    repo()
        .join("verify/tests/data/progress")
        .join(name)
        .display()
        .to_string()
}

#[test]
fn verify_groups_findings_and_all_lists_each() {
    let leaked = progress_data("leaked_mutex");
    let o = petrel(&["verify", &leaked]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let out = stdout(&o);
    // One diagnostic for the three dead markings, located at the place, with a count.
    assert_eq!(out.matches("[E0602] Error").count(), 1, "{out}");
    assert!(out.contains("3 dead markings; the first"), "{out}");
    assert!(out.contains("robot.pn:3:11"), "{out}");
    // E0605 and E0606 with their traces, the events that do not matter elided.
    assert!(
        out.contains("[E0605] Error: the mission cannot finish"),
        "{out}"
    );
    assert_eq!(out.matches("[E0606] Error").count(), 2, "{out}");
    assert!(
        out.contains("error[E0602]: dead marking: R1{done} R2{waiting}, after start_mission → ... → granted(\"r2\") → shock(\"r2\")"),
        "{out}"
    );
    assert!(out.ends_with("result: 6 errors, 0 warnings\n"), "{out}");

    let o = petrel(&["verify", &leaked, "--all"]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stdout(&o).matches("[E0602] Error").count(),
        3,
        "{}",
        stdout(&o)
    );

    // A catastrophic event's ends: one line, or each with --all.
    let stuck = progress_data("stuck_transit");
    let o = petrel(&["verify", &stuck]);
    let out = stdout(&o);
    assert!(out.contains("3 end(s) after a catastrophic event"), "{out}");
    assert!(
        out.contains("mission.pn:5:11"),
        "E0605 at `transit1`: {out}"
    );
    let o = petrel(&["verify", &stuck, "--all"]);
    assert_eq!(
        stdout(&o)
            .matches("end after a catastrophic event:")
            .count(),
        3,
        "{}",
        stdout(&o)
    );
}

#[test]
fn verify_exits_1_for_errors_only_and_json_locates_each_finding() {
    // A warning (starvation) alone: exit 0.
    let o = petrel(&["verify", &progress_data("starvation")]);
    assert_eq!(o.status.code(), Some(0), "{}{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("[W0606] Warning"), "{}", stdout(&o));
    assert!(stdout(&o).ends_with("result: verified, no error, 1 warning\n"));

    // The lock-order deadlock: exit 1, and JSON with the resource cycle and the locations.
    let o = petrel(&["verify", &progress_data("lock_order"), "--format", "json"]);
    assert_eq!(o.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(doc["errors"], 2);
    assert_eq!(doc["warnings"], 0);
    assert_eq!(
        doc["stuck_nets"][0]["resource_cycle"][0],
        "A waits for global.y, which B holds"
    );
    let diags = doc["diagnostics"].as_array().expect("diagnostics");
    assert_eq!(diags.len(), 2);
    for (d, line) in diags.iter().zip([1, 11]) {
        assert_eq!(d["code"], "E0606");
        assert!(d["file"].as_str().unwrap().ends_with("nets.pn"), "{d}");
        assert_eq!(d["line"], line);
        assert_eq!(d["column"], 5);
    }
}

#[test]
fn verify_reduces_independent_nets_unless_told_not_to() {
    // lock_order: the two locking nets and the independent acknowledge loop beside them.
    let dir = progress_data("lock_order");
    let reduced = petrel(&["verify", &dir]);
    let full = petrel(&["verify", &dir, "--no-reduction"]);
    for o in [&reduced, &full] {
        assert_eq!(o.status.code(), Some(1), "{}", stdout(o));
        assert!(
            stdout(o).ends_with("result: 2 errors, 0 warnings\n"),
            "{}",
            stdout(o)
        );
    }
    let (reduced, full) = (stdout(&reduced), stdout(&full));
    assert!(reduced.contains("partial-order reduction: "), "{reduced}");
    assert!(reduced.contains("loops that need outside events: not checked"));
    assert!(!full.contains("partial-order reduction"), "{full}");
    assert!(full.contains("loops that need outside events (expected): "));
}

#[test]
fn verify_timed_drops_an_order_of_timers_that_cannot_happen() {
    // The 2 s watchdog always expires before the 10 min timeout started with it.
    let dir = format!(
        "{}/../verify/tests/data/timed/race",
        env!("CARGO_MANIFEST_DIR")
    );
    let untimed = petrel(&["verify", &dir]);
    assert_eq!(untimed.status.code(), Some(1), "{}", stdout(&untimed));
    let u = stdout(&untimed);
    assert!(
        u.contains("error[E0602]: dead marking: M{aborted}") && u.contains("go → mission_timeout"),
        "{u}"
    );
    let timed = petrel(&["verify", &dir, "--timed"]);
    let t = stdout(&timed);
    assert_eq!(timed.status.code(), Some(0), "{t}");
    assert!(t.contains("timed: timers expire in the order"), "{t}");
    assert!(!t.contains("M{aborted}"), "{t}");
    assert!(t.contains("transitions that never fire: M.abort"), "{t}");
}

#[test]
fn verify_reports_time_bounds_declared_and_asked_for() {
    let dir = repo()
        .join("verify/tests/data/timed/relay")
        .display()
        .to_string();
    // Declared in [verify.bounds]: decided with --timed, not without.
    let o = petrel(&["verify", &dir, "--timed"]);
    let t = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("bound relay (go .. M.done): 3s to 8s; the longest: after go, then finish → skip → b_exp; within 8s: met"),
        "{t}"
    );
    assert!(
        t.contains("bound heartbeat (go .. W.over): at least 0s, unbounded: a cycle"),
        "{t}"
    );
    let o = petrel(&["verify", &dir]);
    let t = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("bound relay (go .. M.done): not decided: needs --timed"),
        "{t}"
    );
    // Asked for on the command line: --timed is implied; JSON for tools.
    let o = petrel(&[
        "verify",
        &dir,
        "--bound",
        "M.two..b_exp",
        "--format",
        "json",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).expect("json");
    assert_eq!(doc["timed"], true);
    let bounds = doc["bounds"].as_array().expect("bounds");
    let asked = bounds
        .iter()
        .find(|b| b["name"] == "M.two..b_exp")
        .expect("asked");
    assert_eq!(asked["status"], "bounded");
    assert_eq!(
        (asked["min_seconds"].as_f64(), asked["max_seconds"].as_f64()),
        (Some(3.0), Some(3.0))
    );
    let relay = bounds
        .iter()
        .find(|b| b["name"] == "relay")
        .expect("declared");
    assert_eq!(relay["met"], true);
    assert_eq!(relay["within_seconds"].as_f64(), Some(8.0));
    assert_eq!(relay["within"], "8s");
    assert_eq!(relay["then"].as_array().map(Vec::len), Some(3));
    // A bound that does not read is a usage error naming it.
    let o = petrel(&["verify", &dir, "--bound", "go..M.nowhere"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("unknown place `M.nowhere`"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn verify_fails_on_a_bound_over_its_requirement() {
    let copy = copy_project(&repo().join("verify/tests/data/timed/relay"));
    let manifest = copy.path().join("petrel.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(
        &manifest,
        // Written in milliseconds: the report quotes the requirement as written.
        text.replace("within = \"8s\"", "within = \"7000ms\""),
    )
    .unwrap();
    let dir = copy.path().display().to_string();
    let o = petrel(&["verify", &dir, "--timed"]);
    let t = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("[E0607] Error: bound `relay` is not met: M.done after go can take up to 8s, more than 7000ms"),
        "{t}"
    );
    assert!(t.contains("petrel.toml:31:49 ]"), "{t}");
    assert!(
        t.contains("error[E0607]: bound relay (go .. M.done): 3s to 8s"),
        "{t}"
    );
    assert!(t.contains("within 7000ms: VIOLATED"), "{t}");
    // Untimed, the requirement is not decided: no error.
    let o = petrel(&["verify", &dir]);
    assert_eq!(o.status.code(), Some(0), "{}", stdout(&o));
}

#[test]
fn run_plays_the_mission_scripts_in_virtual_time_as_json_lines() {
    // Every script of every mission: a new one is covered as soon as it is written.
    let mut scripts = Vec::new();
    for mission in std::fs::read_dir(repo().join("missions"))
        .unwrap()
        .flatten()
    {
        let Ok(list) = std::fs::read_dir(mission.path().join("scripts")) else {
            continue;
        };
        for script in list.flatten() {
            if script.path().extension().is_some_and(|e| e == "script") {
                scripts.push((mission.path(), script.path()));
            }
        }
    }
    scripts.sort();
    assert!(scripts.len() >= 8, "{scripts:?}");
    let mut outcomes = std::collections::BTreeSet::new();
    for (dir, script) in &scripts {
        let name = script.display();
        let o = petrel(&[
            "run",
            &dir.display().to_string(),
            "--script",
            &script.display().to_string(),
        ]);
        assert_eq!(o.status.code(), Some(0), "{name}: {}", stderr(&o));
        let out = stdout(&o);
        for line in out.lines() {
            let step: serde_json::Value =
                serde_json::from_str(line).expect("one JSON document a line");
            for key in ["time", "event", "fired", "marking", "actions"] {
                assert!(step.get(key).is_some(), "{key} missing in {line}");
            }
            for key in ["line", "reason", "timers"] {
                assert!(step.get(key).is_some(), "{key} missing in {line}");
            }
            // One vocabulary: the journal's words (and `start` for the first line).
            let outcome = step["outcome"].as_str().unwrap_or_default();
            assert!(
                ["start", "processed", "unused", "refused"].contains(&outcome),
                "{line}"
            );
            outcomes.insert(outcome.to_string());
        }
        assert!(stderr(&o).contains("expectations met"), "{}", stderr(&o));
    }
    // The missions' scripts show every outcome (UGV's emergency stop, a catastrophic event,
    // makes the later events refused).
    assert_eq!(
        outcomes.into_iter().collect::<Vec<_>>(),
        ["processed", "refused", "start", "unused"]
    );
    // A failed expectation exits 1 and shows what was found.
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.script");
    std::fs::write(&bad, "0 start_mission\nexpect MISSION.climbing\n").unwrap();
    let o = petrel(&["run", &uav(), "--script", &bad.display().to_string(), "-q"]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(
        err.contains("bad.script:2: expectation failed: expected place MISSION.climbing marked"),
        "{err}"
    );
    assert!(err.contains("found: marking MISSION{rolling}"), "{err}");
    // A malformed script is a usage error naming each bad line.
    std::fs::write(&bad, "0 start_mision\n1 go(\n").unwrap();
    let o = petrel(&["run", &uav(), "--script", &bad.display().to_string()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains(
            "bad.script:1:3: unknown event `start_mision`: did you mean `start_mission`?"
        ),
        "{}",
        stderr(&o)
    );
    assert!(stderr(&o).contains("bad.script:2:"), "{}", stderr(&o));
    // `expect always` is checked after every later step; its failure names the `expect` line
    // and the step that broke it.
    std::fs::write(
        &bad,
        "0 start_mission\nexpect always MISSION.rolling\n8 rotation_speed\n",
    )
    .unwrap();
    let o = petrel(&["run", &uav(), "--script", &bad.display().to_string(), "-q"]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(
        err.contains("bad.script:2: expectation failed: expected always MISSION.rolling (from line 2 on)\n  found: broken at 8 by the step of `rotation_speed` (timed line 3)"),
        "{err}"
    );
    // An outcome expected after a `wait` is an error of the script: a wait sends no event.
    std::fs::write(&bad, "0 start_mission\n5 wait\nexpect refused\n").unwrap();
    let o = petrel(&["run", &uav(), "--script", &bad.display().to_string()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("bad.script:3:8: `expect refused` checks the event of the last timed line, and line 2 is a `wait`"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn check_reports_errors_in_the_can_rules_like_net_errors() {
    let bench = repo().join("can_bridge/tests/data/auv");
    let dir = copy_project(&bench);
    // The DBC sits beside the bench project.
    std::fs::copy(
        repo().join("can_bridge/tests/data/auv/auv.dbc"),
        dir.path().join("auv.dbc"),
    )
    .unwrap();
    let can = std::fs::read_to_string(dir.path().join("can.toml"))
        .unwrap()
        .replace("../auv.dbc", "auv.dbc");
    std::fs::write(dir.path().join("can.toml"), &can).unwrap();
    let d = dir.path().display().to_string();
    assert_eq!(
        petrel(&["check", &d]).status.code(),
        Some(0),
        "the bench checks clean"
    );
    std::fs::write(
        dir.path().join("can.toml"),
        can.replace("Depth.depth", "Depth.dpeth"),
    )
    .unwrap();
    let o = petrel(&["check", &d]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.contains("E0703") && err.contains("can.toml:"), "{err}");
}

#[test]
fn bridge_replays_a_recorded_bus_to_its_events() {
    let bench = repo().join("can_bridge/tests/data/auv");
    let dir = tempfile::tempdir().unwrap();
    // The leak detector (id 576 = 0x240) reports a leak for 300 ms: past the 200 ms debounce.
    let mut log = String::new();
    for i in 0..7 {
        log.push_str(&format!("(1000.{:06}) vcan0 240#03 R\n", i * 50_000));
    }
    let path = dir.path().join("bus.log");
    std::fs::write(&path, log).unwrap();
    let o = petrel(&[
        "bridge",
        &bench.display().to_string(),
        "--replay",
        &path.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let events: Vec<serde_json::Value> = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    let leaks: Vec<_> = events.iter().filter(|e| e["event"] == "leak").collect();
    assert_eq!(leaks.len(), 1, "{events:?}");
    assert_eq!(
        leaks[0]["time_us"], 1_000_200_000u64,
        "at the end of the debounce: {events:?}"
    );
    // A project without can.toml has nothing to serve.
    let o = petrel(&["bridge", &uav(), "--replay", &path.display().to_string()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no can.toml"), "{}", stderr(&o));
}

/// `@allow(CODE)` next to a construct silences the verifier's warning of that code on it when
/// `petrel check` runs its verification (W0601 on the transition that loses the conflict, W0602
/// on an observer that must never fire); an `@allow` that silences nothing is W0105.
#[test]
fn check_silences_the_verifiers_warnings_that_an_allow_intends() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("petrel.toml"),
        "[project]\nname = \"w\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\ngo = { category = \"nominal\" }\n",
    )
    .unwrap();
    let nets = |allows: bool| {
        let allow = |text: &str| {
            if allows {
                text.to_string()
            } else {
                String::new()
            }
        };
        format!(
            "net A {{\n    place a = 1\n    place b\n    place never\n    transition t on go: a -> b\n{}    transition t2 on go: a -> b\n{}    transition watch on go: never -> never\n{}    transition back on go: b -> a\n}}\n",
            allow("    @allow(W0601, \"t first, by written order\")\n"),
            allow("    @allow(W0602, \"an observer: fires only if the mission breaks\")\n"),
            allow("    @allow(W0603, \"nothing to silence here\")\n"),
        )
    };
    let codes = |o: &Output| -> Vec<String> {
        let json: serde_json::Value = serde_json::from_str(&stdout(o)).expect("JSON");
        json["diagnostics"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| {
                format!(
                    "{}@{}",
                    d["code"].as_str().unwrap(),
                    d["line"].as_u64().unwrap_or(0)
                )
            })
            .collect()
    };
    let a = dir.path().join("a.pn");
    let path = dir.path().display().to_string();
    // Without the allows: the verifier warns about t2 (conflict, and it never fires) and watch.
    std::fs::write(&a, nets(false)).unwrap();
    let o = petrel(&["check", &path, "--format", "json"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let before = codes(&o);
    for code in ["W0601@6", "W0602@6", "W0602@7"] {
        assert!(before.contains(&code.to_string()), "{code}: {before:?}");
    }
    // With them: the warnings they name are gone, W0602 of t2 (not allowed) stays, and the idle
    // allow is reported where it is written.
    std::fs::write(&a, nets(true)).unwrap();
    let o = petrel(&["check", &path, "--format", "json"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let after = codes(&o);
    assert_eq!(after, ["W0602@7", "W0105@10"], "{after:?}");
}

/// Each kind of expectation, failing on a mission, names its line, what it expected and what
/// the run found; a line that does not read names its line and what is wrong (exit 2).
#[test]
fn run_says_what_each_failed_expectation_expected_and_found() {
    let ugv = repo().join("missions/ugv").display().to_string();
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("s.script");
    let run = |text: &str, project: &str| {
        std::fs::write(&script, text).unwrap();
        petrel(&[
            "run",
            project,
            "--script",
            &script.display().to_string(),
            "-q",
        ])
    };
    let start = "0 start_mission\n1 next_move(\"r1\", \"enter_bottleneck\")\n";
    for (expect, found) in [
        // What became of the event: after the catastrophic emergency stop, refused.
        (
            "3 emergency_stop\n4 move_done(\"r1\")\nexpect processed\n",
            "expected event `move_done` (line 4) processed\n  found: refused: event `move_done` refused: a catastrophic event ended the mission",
        ),
        (
            "3 emergency_stop\nexpect refused\n",
            "expected event `emergency_stop` (line 3) refused\n  found: processed",
        ),
        // Calls: counted, in order.
        (
            "expect 2 calls MOVES_R1.execute(_)\n",
            "expected 2 calls MOVES_R1.execute(_) since line 2\n  found: 1, among calls MOVES_R1.execute(\"enter_bottleneck\")",
        ),
        (
            "3 emergency_stop\nexpect calls MOVES_R2.stop() then MOVES_R1.stop()\n",
            "expected calls MOVES_R2.stop() then MOVES_R1.stop() in this order since line 3\n  found: calls MOVES_R1.stop(), MOVES_R2.stop() (no MOVES_R1.stop() after MOVES_R2.stop())",
        ),
        // Emissions.
        (
            "expect emit granted(\"r2\")\n",
            "expected emit granted(\"r2\")\n  found: emits request(\"r1\"), granted(\"r1\")",
        ),
        // Always: broken by a later step, which is named.
        (
            "expect always active R1/PASS\n2 move_done(\"r1\")\n3 move_done(\"r1\")\n",
            "expected always active R1/PASS (from line 3 on)\n  found: broken at 3 by the step of `move_done` (timed line 5)",
        ),
    ] {
        let o = run(&format!("{start}{expect}"), &ugv);
        assert_eq!(o.status.code(), Some(1), "{expect}: {}", stderr(&o));
        assert!(stderr(&o).contains(found), "{expect}:\n{}", stderr(&o));
    }
    // A timer (the UAV has one).
    let o = run(
        "0 start_mission\n8 rotation_speed\n10 airborne\n60 altitude_reached\nexpect timer dec_answer expires at 80\n",
        &uav(),
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("s.script:5: expectation failed: expected timer dec_answer running, expiring at 80\n  found: running dec_answer (expires at 70)"),
        "{}",
        stderr(&o)
    );
    // Lines that do not read: each with its line and what is wrong.
    let o = run(
        "0 start_mission\nexpect 2 calls NOPE.f()\nexpect calls MOVES_R1.stop() then request(\"r1\")\nexpect timer t expires\nexpect always R1.nowhere\nexpect not always active R1\n",
        &ugv,
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let err = stderr(&o);
    for line in [
        "s.script:2:16: unknown program `NOPE`",
        "s.script:3:35: `request(\"r1\")` is not a call such as `PROGRAM.function(1, _)`",
        "s.script:4:8: expected `timer NAME` or `timer NAME expires at SECONDS`",
        "s.script:5:15: unknown place `R1.nowhere` in the formula",
        "s.script:6:8: `not always` does not read",
    ] {
        assert!(err.contains(line), "{line}:\n{err}");
    }
}

/// The example at the top of docs/scripts.md is a script that runs on missions/uav as shown.
#[test]
fn the_example_of_docs_scripts_md_runs_on_the_uav() {
    let doc = std::fs::read_to_string(repo().join("docs/scripts.md")).unwrap();
    let start = doc
        .find("```text\n# The nominal flight, abridged.")
        .expect("the example")
        + "```text\n".len();
    let end = start + doc[start..].find("```").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("example.script");
    std::fs::write(&script, &doc[start..end]).unwrap();
    let o = petrel(&[
        "run",
        &uav(),
        "--script",
        &script.display().to_string(),
        "-q",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("expectations met"), "{}", stderr(&o));
}

#[test]
fn verify_deadlocks_reduces_a_pnml_net_and_refuses_a_project() {
    let philo = repo()
        .join("verify/tests/data/mcc/Philosophers-PT-000010.pnml")
        .display()
        .to_string();
    let full = petrel(&["verify", &philo, "--format", "json"]);
    let reduced = petrel(&["verify", &philo, "--deadlocks", "--format", "json"]);
    let full: serde_json::Value = serde_json::from_slice(&full.stdout).expect("JSON");
    let doc: serde_json::Value = serde_json::from_slice(&reduced.stdout).expect("JSON");
    // The philosophers' two deadlocks (all left forks, all right forks), fewer markings.
    assert_eq!(doc["reduced"], true);
    assert_eq!(doc["deadlock"], true);
    assert_eq!(doc["dead_markings"], full["dead_markings"]);
    assert_eq!(full["states"], 59049);
    assert!(doc["states"].as_u64().unwrap() < 59049, "{doc}");
    assert!(doc["safe"].is_null(), "safety is not decided: {doc}");
    assert_eq!(
        reduced.status.code(),
        Some(1),
        "a deadlock fails the verification"
    );

    let o = petrel(&["verify", &philo, "--deadlocks"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("deadlocks only"), "{text}");
    assert!(
        text.contains("a witness, not necessarily the shortest"),
        "{text}"
    );

    let project = repo().join("missions/uav").display().to_string();
    let o = petrel(&["verify", &project, "--deadlocks"]);
    assert_eq!(o.status.code(), Some(2), "a usage error");
    assert!(
        stderr(&o).contains("--deadlocks explores a PNML file"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn verify_finds_the_same_with_edges_kept_or_replayed() {
    // Redermor explored in full, its edges kept or recomputed by the firing code: the same
    // report (but for the time taken), every finding and trace.
    let dir = repo().join("missions/redermor").display().to_string();
    let report = |edges: &str| {
        let o = petrel(&[
            "verify",
            &dir,
            "--no-reduction",
            "--edges",
            edges,
            "--format",
            "json",
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", stdout(&o));
        let mut v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        v["seconds"] = serde_json::Value::Null;
        v
    };
    let kept = report("keep");
    assert!(
        kept["states"].as_u64().unwrap() > 1000,
        "{}",
        kept["states"]
    );
    assert_eq!(kept, report("replay"));
    assert_eq!(kept, report("auto"));
    // A wrong value is a usage error naming the choices.
    let o = petrel(&["verify", &dir, "--edges", "some"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("keep"));
}

#[test]
fn the_top_level_help_groups_the_commands_one_line_each() {
    let o = petrel(&["--help"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    // The groups in order, each command on one line under its group (cli/src/help.rs checks
    // that every command is in exactly one group).
    let at = |text: &str| {
        out.find(text)
            .unwrap_or_else(|| panic!("no `{text}`:\n{out}"))
    };
    assert!(
        at("Design a mission:\n  check ") < at("Run a vehicle:\n  up "),
        "{out}"
    );
    assert!(
        at("Run a vehicle:\n  up ") < at("After a run:\n  replay "),
        "{out}"
    );
    assert!(
        out.contains("\n  plot     Draw a recorded run's map (map.svg) and depth profile"),
        "{out}"
    );
    assert!(out.lines().all(|l| l.chars().count() <= 100), "{out}");
    assert!(!out.contains("__exec"), "{out}");
    // `petrel help` is the same page; a command's own help keeps its details.
    assert_eq!(stdout(&petrel(&["help"])), out);
    let up = stdout(&petrel(&["up", "--help"]));
    assert!(up.contains("restart what fails (by policy)"), "{up}");
}
