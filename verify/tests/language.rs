//! The verifier on the constructs for real missions: invariants proved or refuted with the
//! shortest trace, conflicts between guarded transitions, guards it cannot decide, and the
//! warnings a project says are intended.

use petrel_diag::report::Diagnostics;
use petrel_nets::check::{apply_allows, AllowPass};
use petrel_nets::compiled::CompiledProject;
use petrel_nets::model::Project;
use petrel_nets::project::from_sources;
use petrel_verify::{verify, VerifyOptions};

fn load(manifest: &str, nets: &str) -> (Project, CompiledProject, Diagnostics) {
    let (project, c, d, sources) = from_sources(manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{}", d.render_human(&sources));
    (project, c.expect("compiles"), d)
}

const ROBOTS: &str = r#"
[project]
name = "robots"
files = ["a.pn"]
start = ["R1", "R2"]

[globals]
free = 1

[instances]
R1 = { net = "ROBOT", args = ["r1"] }
R2 = { net = "ROBOT", args = ["r2"] }

[events]
at_bottleneck = { category = "nominal", params = ["robot: text"] }
out = { category = "nominal", params = ["robot: text"] }
shock = { category = "safety", params = ["robot: text"] }

[invariants]
mutex = "not (R1.inside and R2.inside)"
"#;

const ROBOT: &str = r#"
net ROBOT(robot: text) {
    place moving = 1
    place waiting
    place inside
    transition arrive on at_bottleneck(r) if r == self.robot: moving -> waiting
    transition enter: waiting, free -> inside
    transition leave on out(r) if r == self.robot: inside -> moving, free
}
"#;

#[test]
fn a_mutual_exclusion_invariant_is_proved() {
    let (_, p, _) = load(ROBOTS, ROBOT);
    let r = verify(&p, VerifyOptions::default()).unwrap();
    assert_eq!(r.invariants, ["mutex"]);
    assert!(
        r.invariant_violations.is_empty(),
        "{:?}",
        r.invariant_violations
    );
    assert!(r.is_clean());
    // The guards make one event per robot: R2 never leaves on R1's `out`.
    assert!(r.never_fired.is_empty(), "{:?}", r.never_fired);
}

#[test]
fn a_broken_mutex_is_refuted_with_the_shortest_trace() {
    // A shock while inside gives the mutex back without leaving: the other robot gets in.
    let nets = ROBOT.replace(
        "    transition leave",
        "    transition jolt on shock(r) if r == self.robot: inside -> inside, free\n    transition leave",
    );
    let (project, p, _) = load(ROBOTS, &nets);
    let r = verify(&p, VerifyOptions::default()).unwrap();
    assert!(!r.is_clean());
    let v = &r.invariant_violations[0];
    assert_eq!(v.invariant, "mutex");
    // Both arrive and one is jolted, in a shortest order: three events.
    assert_eq!(v.trace.len(), 3, "{:?}", v.trace);
    assert_eq!(
        v.trace
            .iter()
            .filter(|t| t.starts_with("at_bottleneck("))
            .count(),
        2,
        "{:?}",
        v.trace
    );
    assert!(
        v.trace.iter().any(|t| t.starts_with("shock(")),
        "{:?}",
        v.trace
    );
    let d = petrel_verify::diagnostics(&project, &r);
    let e = d.iter().find(|d| d.code == "E0604").expect("E0604");
    assert!(e.message.contains("mutex"), "{}", e.message);
    assert!(e.span.is_some(), "located at the invariant in the manifest");
    assert!(petrel_verify::render_human("robots", &r).contains("invariant `mutex` is broken"));
}

#[test]
fn guards_that_cannot_hold_together_do_not_conflict() {
    let manifest = r#"
[project]
name = "c"
files = ["a.pn"]
start = ["A"]

[events]
depth = { category = "nominal", params = ["d: float"] }
"#;
    let disjoint = r#"
net A {
    place idle = 1
    place shallow
    place deep
    transition s on depth(d) if d < 10.0: idle -> shallow
    transition g on depth(d) if d >= 10.0: idle -> deep
}
"#;
    let (_, p, _) = load(manifest, disjoint);
    let r = verify(&p, VerifyOptions::default()).unwrap();
    assert!(r.conflicts.is_empty(), "{:?}", r.conflicts);
    let overlapping = disjoint.replace("d >= 10.0", "d >= 5.0");
    let (_, p, _) = load(manifest, &overlapping);
    let r = verify(&p, VerifyOptions::default()).unwrap();
    assert_eq!(r.conflicts.len(), 1, "{:?}", r.conflicts);
    assert!(
        r.conflicts[0].trace[0].starts_with("depth("),
        "{:?}",
        r.conflicts
    );
}

#[test]
fn a_guard_the_verifier_cannot_decide_goes_both_ways() {
    // Two parameters compared with each other: the verifier explores both outcomes.
    let manifest = r#"
[project]
name = "u"
files = ["a.pn"]
start = ["A"]

[events]
pair = { category = "nominal", params = ["a: int", "b: int"] }
"#;
    let nets = r#"
net A {
    place idle = 1
    place same
    place different
    transition s on pair(a, b) if a == b: idle -> same
    transition d on pair(a, b) if a != b: idle -> different
}
"#;
    let (_, p, _) = load(manifest, nets);
    let r = verify(&p, VerifyOptions::default()).unwrap();
    assert!(r.never_fired.is_empty(), "{:?}", r.never_fired);
    assert_eq!(r.states, 3);
}

#[test]
fn an_intended_warning_is_silenced_and_an_idle_allow_is_reported() {
    let manifest = r#"
[project]
name = "w"
files = ["a.pn"]
start = ["A"]

[events]
go = { category = "nominal" }
"#;
    let nets = r#"
net A {
    place a = 1
    place b
    place never
    transition t on go: a -> b
    @allow(W0602, "an observer: it fires only if the mission breaks")
    transition watch on go: never -> never
    @allow(W0601, "nothing conflicts here")
    transition u on go: b -> a
}
"#;
    let (project, p, mut d) = load(manifest, nets);
    let r = verify(&p, VerifyOptions::default()).unwrap();
    assert_eq!(r.never_fired, ["A.watch"]);
    d.extend(petrel_verify::diagnostics(&project, &r));
    apply_allows(&project, &mut d, AllowPass::Final);
    let codes: Vec<&str> = d.iter().map(|x| x.code).collect();
    assert!(!codes.contains(&"W0602"), "silenced: {codes:?}");
    assert_eq!(
        codes.iter().filter(|c| **c == "W0105").count(),
        1,
        "{codes:?}"
    );
}
