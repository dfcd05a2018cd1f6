//! Zero-time cascades (docs/semantics.md, "Zero-time cascades"): the engine stops a cascade of
//! produced events at its bound, drops what it still queued (counted as refused), raises
//! `livelock` once, and goes on with the events from outside; a long cascade that ends is left
//! alone.

use petrel_nets::compiled::{CompiledProject, Value};
use petrel_nets::project::from_sources;
use petrel_nets::semantics::CASCADE_BOUND;
use petrel_player::engine::{Engine, Sink, Stats};

const MANIFEST: &str = r#"
[project]
name = "loops"
files = ["a.pn"]
start = START

[events]
start_mission = { category = "nominal" }
health_check = { category = "nominal" }
ping = { category = "nominal" }
pong = { category = "nominal" }
go = { category = "nominal" }
step = { category = "nominal" }
other = { category = "mission" }

[programs.NAV]
functions = { status = [] }
"#;

fn compile(nets: &str) -> CompiledProject {
    compile_started(r#"["MONITOR", "SAFE"]"#, nets)
}

fn compile_started(start: &str, nets: &str) -> CompiledProject {
    let manifest = MANIFEST.replace("START", start);
    let (_, c, d, sources) = from_sources(&manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{}", d.render_human(&sources));
    c.expect("compiles")
}

/// The safety net every project below has: it counts the `livelock` events it takes.
const SAFE: &str = "
net SAFE {
    place ok = 1
    place alarmed
    transition first on livelock(n, t): ok -> alarmed
    transition again on livelock(n, t): alarmed -> alarmed
}
";

/// What the engine told its sink: each stop of a cascade, calls, and the livelocks taken.
#[derive(Default)]
struct Seen {
    livelock: u32,
    stops: Vec<(u32, u64)>,
    calls: u64,
    livelocks: Vec<Vec<Value>>,
}

impl Seen {
    fn new(p: &CompiledProject) -> Seen {
        Seen {
            livelock: p.event_id("livelock").expect("a built-in event"),
            ..Seen::default()
        }
    }
}

impl Sink for Seen {
    fn taken(&mut self, event: u32, params: &[Value]) {
        if event == self.livelock {
            self.livelocks.push(params.to_vec());
        }
    }
    fn call(&mut self, _: u32, _: u32, _: petrel_player::engine::Args<'_>) {
        self.calls += 1;
    }
    fn cascade_stopped(&mut self, steps: u32, dropped: u64) {
        self.stops.push((steps, dropped));
    }
}

fn balanced(s: Stats, queued: usize) {
    assert_eq!(
        s.received,
        s.processed + s.unused + s.refused + queued as u64,
        "{s:?}, {queued} queued"
    );
}

fn run<'p>(p: &'p CompiledProject, bound: Option<u32>, events: &[&str]) -> (Engine<'p>, Seen, u64) {
    let mut e = Engine::new(p);
    if let Some(b) = bound {
        e.set_cascade_bound(b);
    }
    let mut seen = Seen::new(p);
    e.start(0, &mut seen);
    for ev in events {
        e.submit_named(ev, vec![]).unwrap();
    }
    let steps = e.run_until_idle(&mut seen);
    balanced(e.stats(), e.queued());
    (e, seen, steps)
}

#[test]
fn a_net_that_emits_its_own_event_is_stopped_at_the_bound_and_livelock_raised() {
    let p = compile(&format!(
        "net MONITOR {{
            place idle = 1
            place watching
            transition begin on start_mission: idle -> watching {{ emit health_check }}
            transition check on health_check: watching -> watching {{
                call NAV.status()
                emit health_check
            }}
        }}
        {SAFE}"
    ));
    let (e, seen, steps) = run(&p, None, &["start_mission"]);
    // The outside event, CASCADE_BOUND steps of health_check, then the livelock.
    assert_eq!(steps, 1 + u64::from(CASCADE_BOUND) + 1);
    assert_eq!(seen.stops, [(CASCADE_BOUND, 1)]);
    assert_eq!(seen.calls, u64::from(CASCADE_BOUND));
    assert_eq!(
        seen.livelocks,
        [vec![
            Value::Text("MONITOR".into()),
            Value::Text("check".into())
        ]]
    );
    let s = e.stats();
    // The health_check still queued was dropped, counted as refused.
    assert_eq!(s.refused, 1);
    assert_eq!(e.queued(), 0);
    assert_eq!(e.cascade_steps(), 0);
    assert!(e
        .marking()
        .contains(&("SAFE".to_string(), vec!["alarmed".to_string()])));
}

#[test]
fn two_nets_that_answer_each_other_are_stopped() {
    let p = compile_started(
        r#"["MONITOR", "PEER", "SAFE"]"#,
        &format!(
            "net MONITOR {{
            place a = 1
            transition serve on ping: a -> a {{ emit pong to PEER }}
        }}
        net PEER {{
            place b = 1
            transition answer on pong: b -> b {{ emit ping }}
        }}
        {SAFE}"
        ),
    );
    let (_, seen, _) = run(&p, Some(100), &["ping"]);
    assert_eq!(seen.stops, [(100, 1)]);
    // The 100th step took a ping, which PEER's answer had emitted.
    assert_eq!(
        seen.livelocks,
        [vec![
            Value::Text("PEER".into()),
            Value::Text("answer".into())
        ]]
    );
}

#[test]
fn a_cycle_through_an_immediate_transition_is_stopped() {
    // `go` arms the net; the immediate transition disarms it and emits `go` again.
    let p = compile(&format!(
        "net MONITOR {{
            place idle = 1
            place armed
            transition arm on go: idle -> armed
            transition fire: armed -> idle {{ emit go }}
        }}
        {SAFE}"
    ));
    let (_, seen, steps) = run(&p, Some(50), &["go"]);
    assert_eq!(seen.stops, [(50, 1)]);
    assert_eq!(steps, 1 + 50 + 1);
    assert_eq!(
        seen.livelocks,
        [vec![
            Value::Text("MONITOR".into()),
            Value::Text("fire".into())
        ]]
    );
}

/// A relay through `n` places: each `step` moves the token on and emits the next `step`, so
/// the outside `step` starts a cascade of `n` steps on emitted events (the last unused).
fn relay(n: usize) -> CompiledProject {
    let mut net = String::from("net MONITOR {\n place p0 = 1\n");
    for i in 1..=n {
        net.push_str(&format!(" place p{i}\n"));
    }
    for i in 0..n {
        net.push_str(&format!(
            " transition t{i} on step: p{i} -> p{} {{ emit step }}\n",
            i + 1
        ));
    }
    net.push_str("}\n");
    compile(&format!("{net}{SAFE}"))
}

#[test]
fn a_long_cascade_that_ends_is_left_alone_up_to_the_bound() {
    // 300 emitted steps at one instant: far below the default bound, nothing is stopped.
    let p = relay(300);
    let (e, seen, steps) = run(&p, None, &["step"]);
    assert_eq!(steps, 301);
    assert!(seen.stops.is_empty() && seen.livelocks.is_empty());
    assert_eq!(e.stats().refused, 0);
    assert!(e
        .marking()
        .contains(&("MONITOR".to_string(), vec!["p300".to_string()])));
    // The bound counts steps on produced events: 300 of them, the last one finding nothing
    // queued after it. A bound of 300 lets the cascade end; 299 stops it with one dropped.
    let (_, seen, _) = run(&p, Some(300), &["step"]);
    assert!(seen.stops.is_empty());
    let (e, seen, steps) = run(&p, Some(299), &["step"]);
    assert_eq!(seen.stops, [(299, 1)]);
    // The relay had moved on to its end; the last `step`, which nothing takes, was dropped.
    assert_eq!(steps, 1 + 299 + 1);
    assert_eq!(e.stats().refused, 1);
    assert!(e
        .marking()
        .contains(&("MONITOR".to_string(), vec!["p300".to_string()])));
}

#[test]
fn outside_events_are_kept_at_the_bound_and_the_mission_goes_on() {
    let p = compile(&format!(
        "net MONITOR {{
            place watching = 1
            place log = 1
            place logged
            place noted
            transition check on health_check: watching -> watching {{ emit health_check }}
            transition seen on step: log -> logged
            transition note on other: log -> noted
        }}
        {SAFE}"
    ));
    let mut e = Engine::new(&p);
    e.set_cascade_bound(20);
    let mut seen = Seen::new(&p);
    e.start(0, &mut seen);
    e.submit_named("health_check", vec![]).unwrap();
    // The outside health_check, then 19 steps on emitted ones.
    while e.cascade_steps() < 19 {
        e.step(&mut seen).unwrap();
    }
    // An outside event arrives behind the emitted health_check of the same category.
    e.submit_named("step", vec![]).unwrap();
    let stop = e.step(&mut seen).unwrap();
    assert_eq!(p.events[stop.event as usize].name, "health_check");
    assert_eq!(seen.stops, [(20, 1)]);
    // The emitted health_check was dropped, `step` kept, and `livelock` (safety) comes first.
    assert_eq!(e.queued(), 2);
    balanced(e.stats(), e.queued());
    let names: Vec<String> = std::iter::from_fn(|| e.step(&mut seen))
        .map(|s| p.events[s.event as usize].name.clone())
        .collect();
    assert_eq!(names, ["livelock", "step"]);
    balanced(e.stats(), e.queued());
    let marking = e.marking();
    assert!(
        marking.contains(&(
            "MONITOR".to_string(),
            vec!["watching".into(), "logged".into()]
        )),
        "{marking:?}"
    );
    // The mission goes on: the next health_check starts a new cascade, stopped again.
    e.submit_named("health_check", vec![]).unwrap();
    e.run_until_idle(&mut seen);
    assert_eq!(seen.stops, [(20, 1), (20, 1)]);
    assert_eq!(seen.livelocks.len(), 2);
    balanced(e.stats(), e.queued());
}

#[test]
fn a_reaction_to_livelock_that_loops_again_is_dropped_without_a_second_livelock() {
    // The safety net restarts the loop on `livelock`: the cascade goes on through the
    // livelock's step, whose emission is dropped; one livelock only, and the engine settles.
    let p = compile(
        "net MONITOR {
            place watching = 1
            transition check on health_check: watching -> watching { emit health_check }
        }
        net SAFE {
            place ok = 1
            transition restart on livelock(n, t): ok -> ok { emit health_check }
        }",
    );
    let (e, seen, steps) = run(&p, Some(10), &["health_check"]);
    assert_eq!(seen.stops, [(10, 1), (11, 1)]);
    assert_eq!(seen.livelocks.len(), 1);
    assert_eq!(steps, 1 + 10 + 1);
    assert_eq!(e.stats().refused, 2);
}

#[test]
fn petrel_run_says_where_the_bound_was_reached() {
    let p = compile(&format!(
        "net MONITOR {{
            place watching = 1
            transition check on health_check: watching -> watching {{ emit health_check }}
        }}
        {SAFE}"
    ));
    let script = petrel_player::script::parse_script("0 health_check\n1 other\n", &p).unwrap();
    let out = petrel_player::script::run_script(&p, &script, |_| {});
    assert!(out.failure.is_none());
    let stopped: Vec<_> = out
        .steps
        .iter()
        .filter(|s| !s["cascade_stopped"].is_null())
        .collect();
    assert_eq!(stopped.len(), 1, "one step reached the bound");
    let s = stopped[0];
    assert_eq!(s["cascade_stopped"]["steps"], CASCADE_BOUND);
    assert_eq!(s["cascade_stopped"]["dropped"], 1);
    assert_eq!(s["time"], 0.0);
    assert!(s["actions"].as_array().unwrap().iter().any(|a| a
        .as_str()
        .unwrap()
        .starts_with("cascade stopped: 10000 steps")));
    // Then the livelock at time 0, and the next line's event at 1 s.
    let after: Vec<(&str, f64)> = out
        .steps
        .iter()
        .skip_while(|s| s["cascade_stopped"].is_null())
        .skip(1)
        .map(|s| (s["event"].as_str().unwrap(), s["time"].as_f64().unwrap()))
        .collect();
    assert_eq!(after, [("livelock", 0.0), ("other", 1.0)]);
    // Every other step says null.
    assert!(out.steps.iter().all(|s| s.get("cascade_stopped").is_some()));
}
