//! The constructs for real missions, run by the engine: instances and their parameters,
//! activation arguments, guards, emptiness tests, addressed events, children, `finish` and the
//! recursive `deactivate`, invariants. Each test is one rule of docs/semantics.md.

use petrel_nets::compiled::{CompiledProject, Value};
use petrel_nets::project::from_sources;
use petrel_player::engine::{Engine, Sink};
use petrel_player::record::StepRecord;

fn compile(manifest: &str, nets: &str) -> CompiledProject {
    let (_, c, d, sources) = from_sources(manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{}", d.render_human(&sources));
    c.expect("compiles")
}

/// Marked places as `NET.place`, every active net as `NET+`.
fn marking(e: &Engine) -> Vec<String> {
    let mut out = Vec::new();
    for (net, places) in e.marking() {
        if net != "global" {
            out.push(format!("{net}+"));
        }
        for p in places {
            out.push(format!("{net}.{p}"));
        }
    }
    out
}

fn text(s: &str) -> Value {
    Value::Text(s.into())
}

/// Submits and processes one event (and what it queues), keeping the record of the steps.
fn send(e: &mut Engine, rec: &mut StepRecord, name: &str, params: Vec<Value>) {
    e.submit_named(name, params).expect("accepted");
    e.run_until_idle(rec);
}

const ROBOTS: &str = r#"
[project]
name = "robots"
files = ["a.pn"]
start = ["R1", "R2", "SYNC"]

[globals]
free = { initial = 1, nets = ["ROBOT"] }

[instances]
R1 = { net = "ROBOT", args = ["r1", 2] }
R2 = { net = "ROBOT", args = ["r2", 3] }

[events]
at_bottleneck = { category = "nominal", params = ["robot: text"] }
out = { category = "nominal", params = ["robot: text"] }
granted = { category = "nominal" }

[programs.NAV]
functions = { go = ["robot: text", "speed: int"] }

[invariants]
mutex = "not (R1.inside and R2.inside)"
"#;

const ROBOT_NETS: &str = r#"
net ROBOT(robot: text, speed: int) {
    place moving = 1
    place waiting
    place inside
    transition arrive on at_bottleneck(r) if r == self.robot: moving -> waiting {
        emit granted to SYNC
    }
    transition enter: waiting, free -> inside {
        call NAV.go(self.robot, self.speed)
    }
    transition leave on out(r) if r == self.robot: inside -> moving, free
}

net SYNC {
    place idle = 1
    transition seen on granted: idle -> idle
}
"#;

#[test]
fn instances_are_nets_with_their_parameters_fixed() {
    let p = compile(ROBOTS, ROBOT_NETS);
    let names: Vec<&str> = p.nets.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, ["R1", "R2", "SYNC"]);
    assert_eq!(p.nets[0].template, "ROBOT");
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    // The guard picks R1's transition only; R1 enters the bottleneck with its own parameters.
    send(&mut e, &mut rec, "at_bottleneck", vec![text("r1")]);
    let m = marking(&e);
    assert!(m.contains(&"R1.inside".into()), "{m:?}");
    assert!(m.contains(&"R2.moving".into()), "{m:?}");
    assert!(
        rec.actions.iter().any(|a| a == "call NAV.go(\"r1\", 2)"),
        "{:?}",
        rec.actions
    );
    // The addressed event reached SYNC (and SYNC alone would take it).
    assert!(
        rec.fired_names().contains(&"SYNC.seen".to_string()),
        "{:?}",
        rec.fired_names()
    );
    // R2 waits: the shared place is taken.
    rec.clear();
    send(&mut e, &mut rec, "at_bottleneck", vec![text("r2")]);
    let m = marking(&e);
    assert!(
        m.contains(&"R2.waiting".into()) && !m.contains(&"R2.inside".into()),
        "{m:?}"
    );
    // R1 leaves: R2 gets in, with its parameters.
    rec.clear();
    send(&mut e, &mut rec, "out", vec![text("r1")]);
    let m = marking(&e);
    assert!(
        m.contains(&"R2.inside".into()) && m.contains(&"R1.moving".into()),
        "{m:?}"
    );
    assert!(
        rec.actions.iter().any(|a| a == "call NAV.go(\"r2\", 3)"),
        "{:?}",
        rec.actions
    );
    // An event no guard accepts is unused.
    rec.clear();
    let before = e.stats().unused;
    send(&mut e, &mut rec, "at_bottleneck", vec![text("r9")]);
    assert_eq!(e.stats().unused, before + 1);
}

#[test]
fn an_invariant_that_stops_holding_raises_invariant_violated_once() {
    // Without the shared place, both robots get in.
    let manifest = ROBOTS.replace(
        "free = { initial = 1, nets = [\"ROBOT\"] }",
        "free = { initial = 1, nets = [\"ROBOT\"] }\nalways = 1",
    );
    let nets = ROBOT_NETS.replace(
        "waiting, free -> inside",
        "waiting, always -> inside, always",
    );
    let p = compile(&manifest, &nets);
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    send(&mut e, &mut rec, "at_bottleneck", vec![text("r1")]);
    assert_eq!(e.invariants_holding(), [true]);
    rec.clear();
    send(&mut e, &mut rec, "at_bottleneck", vec![text("r2")]);
    assert_eq!(e.invariants_holding(), [false]);
    assert!(
        rec.actions.iter().any(|a| a == "invariant mutex broken"),
        "{:?}",
        rec.actions
    );
    let raised = |rec: &StepRecord| {
        rec.taken
            .as_ref()
            .is_some_and(|(n, p)| n == "invariant_violated" && p == &vec![text("mutex")])
    };
    // The built-in event was queued and processed (no transition waits for it: unused).
    let unused = e.stats().unused;
    assert!(
        unused >= 1,
        "invariant_violated was processed as unused: {unused}"
    );
    // Still broken after another step: not raised again.
    rec.clear();
    send(&mut e, &mut rec, "at_bottleneck", vec![text("r9")]);
    assert!(!raised(&rec));
    assert!(
        !rec.actions.iter().any(|a| a.starts_with("invariant")),
        "{:?}",
        rec.actions
    );
}

const TREE: &str = r#"
[project]
name = "tree"
files = ["a.pn"]
start = ["TOP"]

[events]
go = { category = "nominal", params = ["heading: float"] }
done = { category = "nominal" }
stop = { category = "nominal" }

[programs.GUI]
functions = { turn = ["heading: float"] }
"#;

const TREE_NETS: &str = r#"
net TOP {
    children PHASE, TURN
    place idle = 1
    place phasing
    place finished
    transition begin on go(h): idle -> phasing {
        activate PHASE
        activate TURN(h)
    }
    transition next: phasing, PHASE.done -> finished
    transition abort on stop: phasing -> idle {
        deactivate PHASE
    }
}

net PHASE {
    children STEP
    place running = 1
    transition sub on go(h): running -> running {
        activate STEP
    }
    transition over on done: running -> {
        finish
    }
}

net STEP {
    place on = 1
}

net TURN(heading: float) {
    place on = 1
    transition turn on go(h) if self.heading > 90.0: on -> on {
        call GUI.turn(self.heading)
    }
}
"#;

#[test]
fn children_have_their_own_instances_and_go_down_with_their_parent() {
    let p = compile(TREE, TREE_NETS);
    let names: Vec<&str> = p.nets.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, ["TOP", "TOP/PHASE", "TOP/PHASE/STEP", "TOP/TURN"]);
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    send(&mut e, &mut rec, "go", vec![Value::Float(120.0)]);
    let m = marking(&e);
    assert!(
        m.contains(&"TOP/PHASE+".into()) && m.contains(&"TOP/TURN+".into()),
        "{m:?}"
    );
    // TURN keeps its activation argument: the guard and the call read it.
    rec.clear();
    send(&mut e, &mut rec, "go", vec![Value::Float(10.0)]);
    assert!(
        rec.actions.iter().any(|a| a == "call GUI.turn(120.0)"),
        "{:?}",
        rec.actions
    );
    assert!(marking(&e).contains(&"TOP/PHASE/STEP+".into()));
    // Deactivating PHASE takes its child STEP down first.
    rec.clear();
    send(&mut e, &mut rec, "stop", vec![]);
    let m = marking(&e);
    assert!(
        !m.iter().any(|x| x.starts_with("TOP/PHASE")),
        "PHASE and its subtree are down: {m:?}"
    );
    let order: Vec<&String> = rec
        .actions
        .iter()
        .filter(|a| a.starts_with("deactivate"))
        .collect();
    assert_eq!(order, ["deactivate TOP/PHASE/STEP", "deactivate TOP/PHASE"]);
}

#[test]
fn finish_marks_the_parents_completion_place() {
    let p = compile(TREE, TREE_NETS);
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    send(&mut e, &mut rec, "go", vec![Value::Float(0.0)]);
    rec.clear();
    send(&mut e, &mut rec, "done", vec![]);
    let m = marking(&e);
    // PHASE finished: TOP took its completion token and went on; PHASE is inactive.
    assert!(m.contains(&"TOP.finished".into()), "{m:?}");
    assert!(!m.contains(&"TOP/PHASE+".into()), "{m:?}");
    assert!(!m.contains(&"TOP.PHASE.done".into()), "consumed: {m:?}");
}

#[test]
fn finish_with_the_parent_inactive_marks_nothing_and_says_so() {
    let nets = TREE_NETS.replace(
        "transition begin on go(h): idle -> phasing {",
        "transition begin on go(h): idle -> phasing {\n        deactivate self",
    );
    let p = compile(TREE, &nets);
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    send(&mut e, &mut rec, "go", vec![Value::Float(0.0)]);
    // TOP deactivated itself, then activated PHASE; PHASE finishes with no parent running.
    rec.clear();
    send(&mut e, &mut rec, "done", vec![]);
    assert!(
        rec.actions
            .iter()
            .any(|a| a == "finish TOP/PHASE: its parent is not active"),
        "{:?}",
        rec.actions
    );
}

#[test]
fn a_second_finish_while_the_completion_place_is_marked_is_refused() {
    // TOP never takes the completion token; PHASE is activated again and finishes again.
    let nets = TREE_NETS
        .replace("transition next: phasing, PHASE.done -> finished", "")
        .replace(
            "transition abort on stop: phasing -> idle {\n        deactivate PHASE\n    }",
            "transition again on stop: phasing -> phasing {\n        activate PHASE\n    }",
        );
    let p = compile(TREE, &nets);
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    send(&mut e, &mut rec, "go", vec![Value::Float(0.0)]);
    send(&mut e, &mut rec, "done", vec![]);
    send(&mut e, &mut rec, "stop", vec![]);
    rec.clear();
    send(&mut e, &mut rec, "done", vec![]);
    assert!(
        rec.actions
            .iter()
            .any(|a| a == "refused TOP/PHASE.over: a second token in TOP.PHASE.done"),
        "{:?}",
        rec.actions
    );
}

const EMPTY: &str = r#"
[project]
name = "empty"
files = ["a.pn"]
start = ["A"]

[globals]
busy = 0

[events]
go = { category = "nominal" }
take = { category = "nominal" }
"#;

#[test]
fn an_emptiness_test_enables_only_while_the_place_is_empty() {
    let nets = r#"
net A {
    place idle = 1
    place done
    transition grab on take: idle -> idle, busy
    transition clear on go: idle, not busy -> done
}
"#;
    let p = compile(EMPTY, nets);
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    send(&mut e, &mut rec, "take", vec![]);
    let before = e.stats().unused;
    send(&mut e, &mut rec, "go", vec![]);
    assert_eq!(
        e.stats().unused,
        before + 1,
        "busy is marked: go finds nothing"
    );
    let p2 = compile(EMPTY, nets);
    let mut e2 = Engine::new(&p2);
    let mut rec2 = StepRecord::new(&p2);
    e2.start(0, &mut rec2);
    send(&mut e2, &mut rec2, "go", vec![]);
    assert!(marking(&e2).contains(&"A.done".into()));
}

#[test]
fn guards_compare_numbers_as_numbers_and_nan_with_nothing() {
    let manifest = r#"
[project]
name = "g"
files = ["a.pn"]
start = ["A"]

[events]
depth = { category = "nominal", params = ["d: float", "n: int"] }
"#;
    let nets = r#"
net A {
    place idle = 1
    place deep
    transition dive on depth(d, n) if d >= 10 and n != 0: idle -> deep
}
"#;
    let p = compile(manifest, nets);
    for (d, n, fires) in [
        (10.0, 1, true),
        (9.99, 1, false),
        (f64::NAN, 1, false),
        (12.0, 0, false),
    ] {
        let mut e = Engine::new(&p);
        let mut rec = StepRecord::new(&p);
        e.start(0, &mut rec);
        send(
            &mut e,
            &mut rec,
            "depth",
            vec![Value::Float(d), Value::Int(n)],
        );
        assert_eq!(marking(&e).contains(&"A.deep".into()), fires, "{d} {n}");
    }
}

/// A sink that counts nothing: the allocation-free steady state of guards is covered by
/// tests/alloc.rs; this one only checks guards run with no sink at all.
struct Quiet;
impl Sink for Quiet {}

#[test]
fn guards_run_with_any_sink() {
    let p = compile(ROBOTS, ROBOT_NETS);
    let mut e = Engine::new(&p);
    e.start(0, &mut Quiet);
    e.submit_named("at_bottleneck", vec![text("r2")]).unwrap();
    e.run_until_idle(&mut Quiet);
    assert!(marking(&e).contains(&"R2.inside".into()));
}

const UGV: &str = r#"
[project]
name = "ugv"
files = ["a.pn"]
start = ["R1", "R2"]

[instances]
R1 = { net = "ROBOT", args = ["r1", "MOVES_R1"] }
R2 = { net = "ROBOT", args = ["r2", "MOVES_R2"] }

[events]
next_move = { category = "nominal", params = ["robot: text", "kind: text"] }
move_done = { category = "nominal", params = ["robot: text"] }

[programs.MOVES_R1]
functions = { execute = ["kind: text", "speed: float"] }
[programs.MOVES_R2]
functions = { execute = ["kind: text", "speed: float"] }
"#;

const UGV_NETS: &str = r#"
net ROBOT(robot: text, moves: text) {
    children MOVE(self.robot, self.moves)
    place ready = 1
    place moving
    transition go on next_move(r, k) if r == self.robot: ready -> moving {
        activate MOVE(k)
    }
    transition moved: moving, MOVE.done -> ready
}

net MOVE(robot: text, moves: text, kind: text) {
    place order = 1
    place running
    transition send: order -> running {
        call self.moves.execute(self.kind, 1)
    }
    transition over on move_done(r) if r == self.robot: running -> {
        finish
    }
}
"#;

#[test]
fn instances_fix_leading_parameters_and_name_their_own_programs() {
    let p = compile(UGV, UGV_NETS);
    let names: Vec<&str> = p.nets.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, ["R1", "R1/MOVE", "R2", "R2/MOVE"]);
    // R1/MOVE keeps one parameter for its activations: `kind`.
    assert_eq!(
        p.nets[1].params,
        vec![("kind".to_string(), petrel_value::Type::Text)]
    );
    let mut e = Engine::new(&p);
    let mut rec = StepRecord::new(&p);
    e.start(0, &mut rec);
    send(
        &mut e,
        &mut rec,
        "next_move",
        vec![text("r2"), text("turn_left")],
    );
    assert!(
        rec.actions
            .iter()
            .any(|a| a == "call MOVES_R2.execute(\"turn_left\", 1.0)"),
        "{:?}",
        rec.actions
    );
    assert!(marking(&e).contains(&"R2/MOVE.running".into()));
    rec.clear();
    send(&mut e, &mut rec, "move_done", vec![text("r2")]);
    let m = marking(&e);
    assert!(
        m.contains(&"R2.ready".into()) && !m.contains(&"R2/MOVE+".into()),
        "{m:?}"
    );
    // R1 was never concerned.
    assert!(m.contains(&"R1.ready".into()), "{m:?}");
}

#[test]
fn a_program_named_by_a_parameter_must_exist_and_be_fixed() {
    let bad = UGV.replace("\"MOVES_R2\"", "\"MOVES_R9\"");
    let (_, c, d, _) = from_sources(&bad, &[("a.pn", UGV_NETS)]);
    assert!(c.is_none());
    let e = d
        .iter()
        .find(|x| x.code == "E0204")
        .expect("unknown program");
    assert!(e.message.contains("MOVES_R9"), "{}", e.message);
    // A parameter bound only at activation cannot name a program.
    let at_activation = UGV_NETS.replace(
        "children MOVE(self.robot, self.moves)",
        "children MOVE(self.robot)",
    );
    let at_activation = at_activation.replace("activate MOVE(k)", "activate MOVE(self.moves, k)");
    let (_, c, d, _) = from_sources(UGV, &[("a.pn", &at_activation)]);
    assert!(c.is_none());
    assert!(d.iter().any(|x| x.code == "E0418"), "{d:?}");
}
