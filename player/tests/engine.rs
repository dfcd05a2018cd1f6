//! The engine: dispatch priority, the catastrophic end, timers in injected time, refusals with
//! accounting, built-in events, and the UAV scripts.

use petrel_nets::compiled::{CompiledProject, Value};
use petrel_nets::project::{from_sources, load_and_check};
use petrel_nets::semantics::StepOutcome;
use petrel_player::engine::{Args, Engine, NullSink, Refusal, Sink};
use petrel_player::script::{parse_script, run_script};
use std::path::Path;

const MANIFEST: &str = r#"
[project]
name = "t"
files = ["a.pn"]
start = ["A"]

[events]
low = { category = "nominal" }
mid = { category = "mission" }
high = { category = "safety" }
doom = { category = "catastrophic" }
num = { category = "nominal", params = ["x: float", "n: int"] }
tock = { category = "nominal" }

[programs.P]
functions = { f = ["x: float", "n: int", "label: text"] }

[timers]
t = { event = "tock" }
"#;

fn compile(nets: &str) -> CompiledProject {
    let (_, c, d, _) = from_sources(MANIFEST, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{d:?}");
    c.unwrap()
}

#[derive(Default)]
struct Calls(Vec<String>);
impl Sink for Calls {
    fn call(&mut self, _p: u32, _f: u32, args: Args<'_>) {
        self.0
            .push(format!("{:?}", args.iter().collect::<Vec<_>>()));
    }
    fn fired(&mut self, net: u32, t: u32) {
        self.0.push(format!("fired {net}.{t}"));
    }
}

#[test]
fn events_are_taken_by_category_then_arrival() {
    let p = compile(
        "net A { place a = 1
        transition l on low: a -> a  transition m on mid: a -> a  transition h on high: a -> a }",
    );
    let mut e = Engine::new(&p);
    e.start(0, &mut NullSink);
    for name in ["low", "mid", "low", "high", "mid"] {
        e.submit_named(name, vec![]).unwrap();
    }
    let mut order = Vec::new();
    while let Some(s) = e.step(&mut NullSink) {
        order.push(p.events[s.event as usize].name.clone());
    }
    assert_eq!(order, ["high", "mid", "mid", "low", "low"]);
}

#[test]
fn after_a_catastrophic_event_every_event_is_refused_and_counted() {
    let p = compile(
        "net A { place a = 1  place b  transition d on doom: a -> b  transition l on low: b -> a }",
    );
    let mut e = Engine::new(&p);
    e.start(0, &mut NullSink);
    e.submit_named("low", vec![]).unwrap();
    e.submit_named("doom", vec![]).unwrap();
    // Catastrophic first, then `low` is refused when taken.
    assert_eq!(
        e.step(&mut NullSink).unwrap().outcome,
        StepOutcome::Processed
    );
    assert_eq!(
        e.step(&mut NullSink).unwrap().outcome,
        StepOutcome::RefusedAfterCatastrophic
    );
    assert!(matches!(
        e.submit_named("low", vec![]),
        Err(Refusal::AfterCatastrophic(_))
    ));
    // The one refused at its submission is received too: the counters balance.
    let s = e.stats();
    assert_eq!((s.received, s.processed, s.refused, s.unused), (3, 1, 2, 0));
    assert_eq!(s.received, s.processed + s.unused + s.refused);
}

#[test]
fn wrong_events_are_refused_with_reasons_and_accounted() {
    let p = compile("net A { place a = 1  transition n on num(x, k): a -> a }");
    let mut e = Engine::new(&p);
    e.start(0, &mut NullSink);
    assert!(matches!(
        e.submit_named("nope", vec![]),
        Err(Refusal::UnknownEvent(_))
    ));
    assert!(matches!(
        e.submit_named("num", vec![Value::Float(1.0)]),
        Err(Refusal::Arity { .. })
    ));
    let r = e
        .submit_named("num", vec![Value::Int(1), Value::Int(2)])
        .unwrap_err();
    assert_eq!(
        r.to_string(),
        "parameter `x` of event `num` is float, int given"
    );
    e.submit_named("num", vec![Value::Float(1.0), Value::Int(2)])
        .unwrap();
    e.submit_named("low", vec![]).unwrap();
    e.run_until_idle(&mut NullSink);
    // Every submission is received, refused or not.
    let s = e.stats();
    assert_eq!(
        s.received,
        s.processed + s.unused + s.refused + e.queued() as u64
    );
    assert_eq!((s.received, s.refused, s.processed, s.unused), (5, 3, 1, 1));
}

#[test]
fn timers_expire_in_injected_time_and_queue_their_event() {
    let p = compile(
        "net A { place a = 1  place b  place c
        transition arm on low: a -> b { start t after 1.5s }
        transition fire on tock: b -> c }",
    );
    let mut e = Engine::new(&p);
    e.start(0, &mut NullSink);
    e.submit_named("low", vec![]).unwrap();
    e.run_until_idle(&mut NullSink);
    assert_eq!(e.next_deadline(), Some(1_500_000));
    e.advance_to(1_499_999);
    assert_eq!(e.queued(), 0, "not yet");
    e.advance_to(2_000_000);
    assert_eq!(e.queued(), 1);
    assert_eq!(e.next_deadline(), None);
    e.run_until_idle(&mut NullSink);
    assert!(e.marking()[0].1.contains(&"c".to_string()));
}

#[test]
fn a_refused_firing_becomes_a_safety_violation_event_the_nets_can_handle() {
    let p = compile(
        "net A { place a = 1  place b = 1  place alarm
        transition bad on low: a -> b
        transition seen on safety_violation(net, tr, place): -> alarm }",
    );
    let mut e = Engine::new(&p);
    e.start(0, &mut NullSink);
    e.submit_named("low", vec![]).unwrap();
    e.run_until_idle(&mut NullSink);
    assert!(
        e.marking()[0].1.contains(&"alarm".to_string()),
        "{:?}",
        e.marking()
    );
}

#[test]
fn calls_receive_literals_and_event_parameters() {
    let p = compile(
        "net A { place a = 1  transition n on num(x, k): a -> a { call P.f(x, k, \"go\") } }",
    );
    let mut e = Engine::new(&p);
    e.start(0, &mut NullSink);
    e.submit_named("num", vec![Value::Float(2.5), Value::Int(7)])
        .unwrap();
    let mut calls = Calls::default();
    e.run_until_idle(&mut calls);
    assert_eq!(calls.0, ["fired 0.0", "[Float(2.5), Int(7), Text(\"go\")]"]);
}

#[test]
fn the_uav_scripts_pass() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav");
    let (_, c, _) = load_and_check(&dir).unwrap();
    let c = c.unwrap();
    for name in ["nominal", "payload_failure", "engine_failure"] {
        let text = std::fs::read_to_string(dir.join(format!("scripts/{name}.script"))).unwrap();
        let script = parse_script(&text, &c).unwrap();
        let out = run_script(&c, &script, |_| {});
        assert!(out.failure.is_none(), "{name}: {:?}", out.failure);
        assert!(out.steps.len() > 8);
    }
}

#[test]
fn a_failed_expectation_names_its_line_and_what_was_found() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav");
    let (_, c, _) = load_and_check(&dir).unwrap();
    let c = c.unwrap();
    let script = parse_script("0 start_mission\n\nexpect call GUI.takeoff()\n", &c).unwrap();
    let out = run_script(&c, &script, |_| {});
    let (line, msg) = out.failure.unwrap();
    assert_eq!(line, 3);
    assert_eq!(
        msg,
        "expected call GUI.takeoff()\n  found: calls GUI.roll()"
    );
}

#[test]
fn a_reloaded_engine_takes_over_the_queue_and_the_counters_and_the_accounting_holds() {
    let old = compile("net A {\n    place p = 1\n    transition t on low: p -> p\n    transition u on mid: p -> p\n}\n");
    // The new version no longer waits for `mid`, and does not declare `num` any more.
    let manifest = MANIFEST.replace(
        "num = { category = \"nominal\", params = [\"x: float\", \"n: int\"] }\n",
        "",
    );
    let (_, new, d, _) = from_sources(
        &manifest.replace(
            "[programs.P]\nfunctions = { f = [\"x: float\", \"n: int\", \"label: text\"] }\n",
            "",
        ),
        &[(
            "a.pn",
            "net A {\n    place p = 1\n    transition t on low: p -> p\n}\n",
        )],
    );
    assert!(!d.has_errors(), "{d:?}");
    let new = new.unwrap();
    let mut e = Engine::new(&old);
    e.start(0, &mut NullSink);
    e.submit_named("low", vec![]).unwrap();
    e.step(&mut NullSink).unwrap();
    e.submit_named("mid", vec![]).unwrap();
    e.submit_named("num", vec![Value::Float(1.0), Value::Int(2)])
        .unwrap();
    e.submit_named("low", vec![]).unwrap();
    let stats = e.stats();
    assert_eq!((stats.received, stats.processed, e.queued()), (4, 1, 3));
    let queued = e.take_queue();
    // Highest category first, then arrival.
    let names: Vec<&str> = queued.iter().map(|q| q.0.as_str()).collect();
    assert_eq!(names, ["mid", "num", "low"]);
    let mut next = Engine::new(&new);
    let refused = next
        .adopt(
            5,
            e.state(),
            &[None],
            vec![Vec::new()],
            stats,
            queued,
            &Default::default(),
        )
        .expect("same sizes");
    assert_eq!(refused.len(), 1);
    assert_eq!(refused[0].0, "num");
    assert!(
        matches!(refused[0].1, Refusal::Reloaded(_)),
        "{:?}",
        refused[0].1
    );
    let s = next.stats();
    assert_eq!((s.received, s.refused, next.queued()), (4, 1, 2));
    next.run_until_idle(&mut NullSink);
    let s = next.stats();
    // `mid` is unused in the new version, `low` processed.
    assert_eq!((s.processed, s.unused), (2, 1));
    assert_eq!(
        s.received,
        s.processed + s.unused + s.refused + next.queued() as u64
    );
    assert_eq!(next.now(), 5);
}
