//! Timed verification (issue 18, "Time"): timers with literal durations expire in the order
//! their durations impose, outside events stay free, and the untimed analysis stays an option.

use petrel_diag::source::SourceMap;
use petrel_nets::compiled::CompiledProject;
use petrel_nets::project::{from_sources, load_and_check};
use petrel_verify::{verify, BoundFinding, BoundStatus, Report, VerifyOptions};
use std::path::Path;

fn run(c: &CompiledProject, timed: bool) -> Report {
    verify(
        c,
        VerifyOptions {
            timed,
            ..Default::default()
        },
    )
    .expect("verifies")
}

fn load(dir: &Path) -> CompiledProject {
    let (_, c, d) = load_and_check(dir).expect("loads");
    c.unwrap_or_else(|| panic!("{}: {d:?}", dir.display()))
}

#[test]
fn a_short_timer_expires_before_a_long_one_started_with_it() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/timed/race");
    let c = load(&dir);
    let untimed = run(&c, false);
    let timed = run(&c, true);
    // Untimed: the 10 min timeout may come before the 2 s watchdog, a false dead marking.
    let aborted = |r: &Report| {
        r.dead_markings
            .iter()
            .any(|d| !d.intended && d.marking.iter().any(|m| m.contains("aborted")))
    };
    assert!(aborted(&untimed), "{:?}", untimed.dead_markings);
    assert!(untimed.no_progress.is_some());
    assert!(!untimed.never_fired.contains(&"M.abort".to_string()));
    // Timed: it cannot happen.
    assert!(!aborted(&timed), "{:?}", timed.dead_markings);
    assert!(timed.is_clean(), "{timed:?}");
    assert!(timed.timed && !untimed.timed);
    assert_eq!(timed.never_fired, vec!["M.abort".to_string()]);
}

/// A timer of 5 s started by `go`, another of `later` started by the outside event `mid`, which
/// may come at any moment before the first expires (after, `too_late` takes it).
fn two_timers(later: &str) -> CompiledProject {
    let manifest = r#"
[project]
name = "orders"
files = ["t.pn"]
start = ["M"]
[events]
go = { category = "nominal" }
mid = { category = "nominal" }
a_exp = { category = "mission" }
b_exp = { category = "mission" }
[timers]
a = { event = "a_exp" }
b = { event = "b_exp" }
[verify]
final = [["M.a_first"], ["M.b_first"]]
"#;
    let nets = format!(
        r#"
net M {{
    place idle = 1
    place one
    place two
    place a_first
    place b_first
    place late
    transition go on go: idle -> one {{
        start a after 5s
    }}
    transition mid on mid: one -> two {{
        start b after {later}
    }}
    transition too_late on a_exp: one -> late
    transition take_a on a_exp: two -> a_first
    transition take_b on b_exp: two -> b_first
}}
"#
    );
    let (_, c, d, _) = from_sources(manifest, &[("t.pn", &nets)]);
    c.unwrap_or_else(|| panic!("{d:?}"))
}

#[test]
fn the_order_of_expiries_depends_on_when_outside_events_came() {
    // `mid` before 3 s: b (2 s) expires first; after 3 s: a does. Both orders are possible.
    let r = run(&two_timers("2s"), true);
    assert!(r.never_fired.is_empty(), "{:?}", r.never_fired);
    // b (6 s) outlasts what is left of a (at most 5 s): b never expires first.
    let r = run(&two_timers("6s"), true);
    assert_eq!(r.never_fired, vec!["M.take_b".to_string()]);
    // `mid` may also not come within 5 s: then a expires first.
    assert!(r
        .dead_markings
        .iter()
        .any(|d| !d.intended && d.marking.iter().any(|m| m.contains("late"))));
    // Untimed, b may come first whatever the durations.
    let r = run(&two_timers("6s"), false);
    assert!(r.never_fired.is_empty(), "{:?}", r.never_fired);
}

#[test]
fn the_missions_verify_clean_timed() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions");
    for m in ["auv", "redermor", "uav", "ugv"] {
        let c = load(&root.join(m));
        let r = run(&c, true);
        assert!(r.is_clean(), "{m}: {r:?}");
        assert_eq!(r.errors(), 0, "{m}");
    }
}

/// `go` starts `a` (5 s); `a`'s expiry, or the outside event `skip` before it, starts `b`
/// (3 s), whose expiry ends in `done`. By hand: from `go` to `M.done` at least 3 s (`skip` at
/// once, then `b`), at most 8 s (`a`, then `b`). `finish` (outside) is what `wait` waits for.
fn relay(bounds: &str) -> CompiledProject {
    relay_sources(bounds).1
}

fn relay_sources(bounds: &str) -> (petrel_nets::model::Project, CompiledProject, SourceMap) {
    let manifest = format!(
        r#"
[project]
name = "relay"
files = ["t.pn"]
start = ["M", "W"]
[events]
go = {{ category = "nominal" }}
skip = {{ category = "nominal" }}
finish = {{ category = "nominal" }}
a_exp = {{ category = "mission" }}
b_exp = {{ category = "mission" }}
tick = {{ category = "mission" }}
[timers]
a = {{ event = "a_exp" }}
b = {{ event = "b_exp" }}
t = {{ event = "tick" }}
[verify]
final = [["M.done", "W.over"]]
[verify.bounds]
{bounds}
"#
    );
    let nets = r#"
net M {
    place idle = 1
    place one
    place two
    place done
    transition go on go: idle -> one {
        start a after 5s
    }
    transition early on skip: one -> two {
        cancel a
        start b after 3s
    }
    transition late on a_exp: one -> two {
        start b after 3s
    }
    transition end on b_exp: two -> done
}
// A heartbeat every second until `finish`: a cycle that takes time.
net W {
    place beating
    place idle = 1
    place over
    transition begin on go: idle -> beating {
        start t after 1s
    }
    transition beat on tick: beating -> beating {
        start t after 1s
    }
    transition finish on finish: beating -> over {
        cancel t
    }
}
"#;
    let (project, c, d, sources) = from_sources(&manifest, &[("t.pn", nets)]);
    (project, c.unwrap_or_else(|| panic!("{d:?}")), sources)
}

fn bound<'r>(r: &'r Report, name: &str) -> &'r BoundFinding {
    r.bounds
        .iter()
        .find(|b| b.name == name)
        .unwrap_or_else(|| panic!("no bound {name}: {:?}", r.bounds))
}

#[test]
fn a_bound_computed_by_hand() {
    let c = relay(
        r#"relay = { from = "go", to = "M.done", within = "8s" }
by_event = { from = "go", to = "b_exp" }
second = { from = "M.two", to = "M.done" }"#,
    );
    let r = run(&c, true);
    let b = bound(&r, "relay");
    assert_eq!(b.status, BoundStatus::Bounded, "{b:?}");
    assert_eq!((b.min_seconds, b.max_seconds), (Some(3.0), Some(8.0)));
    assert_eq!(b.met, Some(true));
    // The longest, and the shortest path to it: the heartbeat lets at most 1 s pass in a
    // state, so `finish` stops it first; then `skip` comes at 5 s (or `a` expires), and `b`
    // 3 s later.
    assert_eq!(b.trace, vec!["go".to_string()]);
    assert_eq!(b.then.len(), 3, "{b:?}");
    assert_eq!(b.then[0], "finish");
    assert_eq!(b.then[2], "b_exp");
    // The same instant seen as the event that makes it.
    let b = bound(&r, "by_event");
    assert_eq!((b.min_seconds, b.max_seconds), (Some(3.0), Some(8.0)));
    // Once in `two`, `b` runs its 3 s whatever came before.
    let b = bound(&r, "second");
    assert_eq!((b.min_seconds, b.max_seconds), (Some(3.0), Some(3.0)));
    assert!(r.is_clean(), "{r:?}");
}

#[test]
fn a_bound_over_its_requirement_is_an_error() {
    let (project, c, sources) =
        relay_sources(r#"relay = { from = "go", to = "M.done", within = "7.5s" }"#);
    let r = run(&c, true);
    let b = bound(&r, "relay");
    assert_eq!(b.max_seconds, Some(8.0));
    assert_eq!(b.met, Some(false));
    assert_eq!(r.errors(), 1);
    assert!(!r.is_clean());
    // Located at the requirement in the manifest, with the path that takes too long.
    let d = petrel_verify::diagnostics(&project, &r);
    let e = d.iter().find(|x| x.code == "E0607").expect("E0607");
    let json = d.to_json(&sources).to_string();
    assert!(json.contains("E0607"), "{json}");
    assert!(
        e.message.contains("up to 8s, more than 7.5s"),
        "{}",
        e.message
    );
    let at = e.span.expect("located");
    let file = sources.get(at.file);
    assert_eq!(&file.text[at.start as usize..at.end as usize], "7.5s");
}

#[test]
fn an_unbounded_wait_says_what_it_waits_for() {
    let c = relay(
        r#"outside = { from = "go", to = "W.over", within = "1h" }
beating = { from = "W.beating", to = "not W.beating" }
never = { from = "M.done", to = "M.idle" }
nothing = { from = "finish", to = "M.idle" }"#,
    );
    let r = run(&c, true);
    // `finish` may never come; `t` keeps running, so time passes round the heartbeat: the
    // wait is a cycle that takes time.
    let b = bound(&r, "outside");
    assert_eq!(b.status, BoundStatus::Unbounded, "{b:?}");
    assert!(b.reason.as_deref().unwrap_or("").contains("cycle"), "{b:?}");
    assert_eq!(b.min_seconds, Some(0.0));
    assert_eq!(b.met, Some(false));
    assert!(b.then.iter().any(|e| e == "tick"), "{b:?}");
    assert_eq!(bound(&r, "beating").status, BoundStatus::Unbounded);
    // `M.idle` never holds again: the mission ends (a dead marking) without it.
    let b = bound(&r, "never");
    assert_eq!(b.status, BoundStatus::Unbounded);
    assert!(
        b.reason.as_deref().unwrap_or("").contains("dead marking"),
        "{b:?}"
    );
    assert_eq!(b.min_seconds, None);
    // `finish` is taken only in `W.beating`, after `go`: from there `M.idle` never comes.
    assert_eq!(bound(&r, "nothing").status, BoundStatus::Unbounded);
    assert_eq!(r.errors(), 1, "{:?}", r.bounds);
}

#[test]
fn a_wait_for_an_outside_event_without_a_timer_is_unbounded() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/timed/race");
    let mut c = load(&dir);
    let b = petrel_nets::check::command_line_bound(&c, "go..M.finished").expect("reads");
    c.bounds.push(b);
    c.bounds
        .push(petrel_nets::check::command_line_bound(&c, "go..M.working").expect("reads"));
    let r = run(&c, true);
    let b = &r.bounds[0];
    assert_eq!(b.status, BoundStatus::Unbounded);
    let reason = b.reason.as_deref().unwrap_or("");
    assert!(reason.contains("waits for done"), "{reason}");
    assert_eq!(b.min_seconds, Some(2.0));
    assert_eq!(r.bounds[1].min_seconds, Some(2.0));
    assert_eq!(r.bounds[1].max_seconds, Some(2.0));
    // Untimed, a bound is not decided.
    let r = run(&c, false);
    assert!(r
        .bounds
        .iter()
        .all(|b| b.status == BoundStatus::NotDecided && b.met.is_none()));
    // A bound that does not read says which end and why.
    let e = petrel_nets::check::command_line_bound(&c, "go..M.nowhere").unwrap_err();
    assert!(e.contains("unknown place `M.nowhere`"), "{e}");
    let e = petrel_nets::check::command_line_bound(&c, "gone..M.idle").unwrap_err();
    assert!(e.contains("not a declared event"), "{e}");
    assert!(petrel_nets::check::command_line_bound(&c, "go").is_err());
}

#[test]
fn a_bound_that_does_not_read_is_reported_where_it_is_written() {
    let manifest = r#"
[project]
name = "bad"
files = ["t.pn"]
start = ["M"]
[events]
go = { category = "nominal" }
[verify.bounds]
late = { from = "go", to = "M.idle", within = "soon" }
lost = { from = "gone", to = "M.nowhere", within = "1s" }
"#;
    let nets = "net M {\n    place idle = 1\n    transition go on go: idle -> idle\n}\n";
    let (_, c, d, _) = from_sources(manifest, &[("t.pn", nets)]);
    assert!(c.is_none());
    let codes: Vec<&str> = d.iter().map(|x| x.code).collect();
    assert_eq!(codes, vec!["E0420", "E0203", "E0211"], "{d:?}");
    // A formula that does not read stops at the manifest, at its place in the string.
    let manifest = manifest.replace("M.nowhere", "M.idle and");
    let (_, c, d, _) = from_sources(&manifest, &[("t.pn", nets)]);
    assert!(c.is_none());
    let codes: Vec<&str> = d.iter().map(|x| x.code).collect();
    assert_eq!(codes, vec!["E0108"], "{d:?}");
}
