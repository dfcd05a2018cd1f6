//! Each rule of docs/semantics.md, on a small project, through the shared step function.

use petrel_nets::compiled::{Arg, CompiledProject, EventId, PlaceRef, TimerDuration};
use petrel_nets::project::from_sources;
use petrel_nets::semantics::{Effects, Notice, Scratch, Semantics, State, StepOutcome};

const MANIFEST: &str = r#"
[project]
name = "t"
files = ["a.pn"]
start = ["A", "B"]

[globals]
shared = 1
flag = 0

[events]
go = { category = "nominal" }
other = { category = "nominal" }
stop = { category = "catastrophic" }
value = { category = "mission", params = ["x: int"] }

[programs.P]
functions = { f = ["x: int"] }

[timers]
tick = { event = "other" }
"#;

fn compile(nets: &str) -> CompiledProject {
    let (_, c, d, _) = from_sources(MANIFEST, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{d:?}");
    c.expect("compiles")
}

#[derive(Default)]
struct Record {
    log: Vec<String>,
}

impl Effects for Record {
    fn fired(&mut self, rule: u32) {
        self.log.push(format!("fired {rule}"));
    }
    fn refused(&mut self, rule: u32, place: u32) {
        self.log.push(format!("refused {rule} at bit {place}"));
    }
    fn conflict(&mut self, rule: u32) {
        self.log.push(format!("conflict {rule}"));
    }
    fn call(&mut self, program: u32, function: u32, args: &[Arg]) {
        self.log.push(format!("call {program}.{function} {args:?}"));
    }
    fn emit(&mut self, event: EventId, _args: &[Arg], _target: Option<u32>) {
        self.log.push(format!("emit {event}"));
    }
    fn start_timer(&mut self, timer: u32, after: &TimerDuration) {
        self.log.push(format!("start {timer} {after:?}"));
    }
    fn cancel_timer(&mut self, timer: u32) {
        self.log.push(format!("cancel {timer}"));
    }
    fn notice(&mut self, n: Notice) {
        self.log.push(format!("{n:?}"));
    }
    fn livelock(&mut self) {
        self.log.push("livelock".into());
    }
}

struct Run<'p> {
    sem: Semantics<'p>,
    state: State,
    scratch: Scratch,
    fx: Record,
}

impl<'p> Run<'p> {
    fn new(p: &'p CompiledProject) -> Self {
        let sem = Semantics::new(p);
        let mut scratch = Scratch::default();
        let mut fx = Record::default();
        let state = sem.initial(&mut fx, &mut scratch);
        Run {
            sem,
            state,
            scratch,
            fx,
        }
    }

    fn event(&mut self, name: &str) -> StepOutcome {
        let e = self.sem.project.event_id(name).unwrap();
        self.sem
            .process_event(&mut self.state, e, None, &mut self.fx, &mut self.scratch)
    }

    /// The marked places, as `NET.place` and `global.place`, and the active nets.
    fn marking(&self) -> Vec<String> {
        let p = self.sem.project;
        let l = &self.sem.layout;
        let mut out = Vec::new();
        for (n, net) in p.nets.iter().enumerate() {
            if l.is_active(&self.state, n as u32) {
                out.push(format!("{}+", net.name));
            }
            for (i, pl) in net.places.iter().enumerate() {
                if l.is_marked(&self.state, n as u32, PlaceRef::Local(i as u32)) {
                    out.push(format!("{}.{}", net.name, pl.name));
                }
            }
        }
        for (g, gp) in p.globals.iter().enumerate() {
            if l.is_marked(&self.state, 0, PlaceRef::Global(g as u32)) {
                out.push(format!("global.{}", gp.name));
            }
        }
        out
    }

    fn take_log(&mut self) -> Vec<String> {
        std::mem::take(&mut self.fx.log)
    }
}

#[test]
fn initial_state_marks_globals_activates_start_nets_and_runs_immediates() {
    let p = compile(
        "net A { place a = 1  place b  transition t: a -> b }
         net B { place x = 1 }
         net C { place y = 1 }",
    );
    let r = Run::new(&p);
    // C is not a start net: inactive, no token, although its place is marked `= 1`.
    assert_eq!(r.marking(), ["A+", "A.b", "B+", "B.x", "global.shared"]);
}

#[test]
fn an_inactive_net_does_not_fire_even_with_its_global_inputs_marked() {
    let p = compile(
        "net A { place a = 1 }
         net B { place x = 1 }
         net C { transition take on go: shared -> flag }",
    );
    let mut r = Run::new(&p);
    assert_eq!(r.event("go"), StepOutcome::Unused);
    assert!(r.marking().contains(&"global.shared".to_string()));
}

#[test]
fn a_net_activated_by_an_event_does_not_see_that_event() {
    let p = compile(
        "net A { place a = 1  place b  transition t on go: a -> b { activate C } }
         net B { place x = 1 }
         net C { place c = 1  place d  transition u on go: c -> d }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    assert!(
        r.marking().contains(&"C.c".to_string()),
        "{:?}",
        r.marking()
    );
    r.event("go");
    assert!(
        r.marking().contains(&"C.d".to_string()),
        "{:?}",
        r.marking()
    );
}

#[test]
fn conflict_first_in_written_order_wins_and_the_loser_is_reported() {
    let p = compile(
        "net A { place a = 1  place b  place c
                 transition first on go: a -> b
                 transition second on go: a -> c }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    assert_eq!(r.marking(), ["A+", "A.b", "B+", "B.x", "global.shared"]);
    assert_eq!(r.take_log(), ["fired 0", "conflict 1"]);
}

#[test]
fn one_event_fires_each_transition_at_most_once_and_never_runs_through_a_chain() {
    let p = compile(
        "net A { place a = 1  place b  place c
                 transition t1 on go: a -> b
                 transition t2 on go: b -> c }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    assert!(r.marking().contains(&"A.b".to_string()));
    r.event("go");
    assert!(r.marking().contains(&"A.c".to_string()));
}

#[test]
fn independent_transitions_of_one_event_all_fire_in_dispatch_order() {
    let p = compile(
        "net A { place a = 1  place b  place c = 1  place d
                 transition t1 on go: a -> b { call P.f(1) }
                 transition t2 on go: c -> d { call P.f(2) } }
         net B { place x = 1  place y  transition t3 on go: x -> y { call P.f(3) } }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    let calls: Vec<_> = r
        .take_log()
        .into_iter()
        .filter(|l| l.starts_with("call"))
        .collect();
    assert_eq!(calls.len(), 3);
    assert!(
        calls[0].contains("Int(1)") && calls[1].contains("Int(2)") && calls[2].contains("Int(3)")
    );
}

#[test]
fn a_firing_that_would_put_a_second_token_is_refused_whole() {
    let p = compile(
        "net A { place a = 1  place b = 1
                 transition t on go: a -> b { call P.f(1) } }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    let before = r.marking();
    r.event("go");
    assert_eq!(r.marking(), before, "no token moved");
    let log = r.take_log();
    assert_eq!(log.len(), 1, "no action ran: {log:?}");
    assert!(log[0].starts_with("refused 0"));
}

#[test]
fn reading_a_place_on_both_sides_keeps_its_token() {
    let p = compile(
        "net A { place a = 1  place b
                 transition t on go: a, shared -> b, shared }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    assert_eq!(r.marking(), ["A+", "A.b", "B+", "B.x", "global.shared"]);
}

#[test]
fn immediate_transitions_run_to_a_fixpoint_after_each_event() {
    let p = compile(
        "net A { place a = 1  place b  place c  place d
                 transition t on go: a -> b
                 transition i1: b -> c
                 transition i2: c -> d }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    assert!(
        r.marking().contains(&"A.d".to_string()),
        "{:?}",
        r.marking()
    );
}

#[test]
fn a_livelock_of_immediate_transitions_stops_at_the_bound() {
    let p = compile(
        "net A { place a  place b
                 transition start on go: -> a
                 transition ab: a -> b
                 transition ba: b -> a }
         net B { place x = 1 }",
    );
    let mut sem = Semantics::new(&p);
    sem.fixpoint_bound = 50;
    let mut scratch = Scratch::default();
    let mut fx = Record::default();
    let mut s = sem.initial(&mut fx, &mut scratch);
    sem.process_event(
        &mut s,
        p.event_id("go").unwrap(),
        None,
        &mut fx,
        &mut scratch,
    );
    assert_eq!(fx.log.iter().filter(|l| l.starts_with("fired")).count(), 52);
    assert_eq!(fx.log.last().unwrap(), "livelock");
}

#[test]
fn a_refused_immediate_transition_is_not_retried_in_the_same_fixpoint() {
    let p = compile(
        "net A { place a  place b = 1
                 transition arm on go: -> a
                 transition i: a -> b }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    let log = r.take_log();
    assert_eq!(
        log.iter().filter(|l| l.starts_with("refused")).count(),
        1,
        "{log:?}"
    );
}

#[test]
fn activation_never_resets_and_deactivation_keeps_global_places() {
    let p = compile(
        "net A { place a = 1  place b
                 transition t on go: a -> b, flag { activate B }
                 transition u on other: b -> a { deactivate C } }
         net B { place x = 1  place y  transition v on go: x -> y }
         net C { place c = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    // B was active: its `go` moved x to y, and `activate B` did not put x back.
    assert!(r.marking().contains(&"B.y".to_string()));
    assert!(!r.marking().contains(&"B.x".to_string()));
    assert!(r.take_log().contains(&"AlreadyActive(1)".to_string()));
    r.event("other");
    assert!(r.take_log().contains(&"AlreadyInactive(2)".to_string()));
}

#[test]
fn a_net_deactivating_itself_still_runs_the_rest_of_its_actions() {
    let p = compile(
        "net A { place a = 1  place b
                 transition t on go: a -> b, flag { deactivate A  call P.f(7) } }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("go");
    assert!(
        !r.marking().iter().any(|m| m.starts_with("A")),
        "{:?}",
        r.marking()
    );
    assert!(
        r.marking().contains(&"global.flag".to_string()),
        "globals survive"
    );
    assert!(r
        .take_log()
        .iter()
        .any(|l| l.contains("call 0.0 [Literal(Int(7))]")));
}

#[test]
fn timers_and_emits_reach_the_effects_and_the_state() {
    let p = compile(
        "net A { place a = 1  place b  place c
                 transition t on value(x): a -> b { start tick after x  emit go  call P.f(x) }
                 transition u on other: b -> c { cancel tick } }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    r.event("value");
    assert!(r.sem.layout.timer_running(&r.state, 0));
    let log = r.take_log();
    assert!(
        log.contains(&"start 0 EventParamSeconds(0)".to_string()),
        "{log:?}"
    );
    assert!(log.contains(&format!("emit {}", p.event_id("go").unwrap())));
    assert!(log.contains(&"call 0.0 [EventParam(0)]".to_string()));
    r.event("other");
    assert!(!r.sem.layout.timer_running(&r.state, 0));
}

#[test]
fn after_a_catastrophic_event_nothing_more_is_processed() {
    let p = compile(
        "net A { place a = 1  place b  place c
                 transition t on stop: a -> b
                 transition u on go: b -> c }
         net B { place x = 1 }",
    );
    let mut r = Run::new(&p);
    assert_eq!(r.event("stop"), StepOutcome::Processed);
    assert_eq!(r.event("go"), StepOutcome::RefusedAfterCatastrophic);
    assert!(r.marking().contains(&"A.b".to_string()));
}

#[test]
fn an_event_nobody_waits_for_is_unused_and_changes_nothing() {
    let p = compile("net A { place a = 1 } net B { place x = 1 }");
    let mut r = Run::new(&p);
    let before = r.state.clone();
    assert_eq!(r.event("go"), StepOutcome::Unused);
    assert_eq!(r.state, before);
}
