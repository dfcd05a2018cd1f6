//! Timed verification (issue 18, "Time"): timers with literal durations expire in the order
//! their durations impose, outside events stay free, and the untimed analysis stays an option.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::project::{from_sources, load_and_check};
use petrel_nets::verify::{verify, Report, VerifyOptions};
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
