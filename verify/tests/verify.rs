//! Project verification: each kind of finding on a small hand-made project, with its exact
//! shortest trace; and the UAV mission verifies clean.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::project::{from_sources, load_and_check};
use petrel_verify::{verify, Report, VerifyError, VerifyOptions};
use std::path::Path;

const MANIFEST: &str = r#"
[project]
name = "t"
files = ["a.pn"]
start = ["A"]

[globals]
g = 0
h = 0

[events]
go = { category = "nominal" }
more = { category = "nominal" }
done = { category = "nominal" }
never = { category = "nominal" }
halt = { category = "catastrophic" }

[timers]
tick = { event = "done" }
"#;

fn project(nets: &str, extra_manifest: &str) -> CompiledProject {
    let manifest = format!("{MANIFEST}{extra_manifest}");
    let (_, c, d, _) = from_sources(&manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{d:?}");
    c.expect("compiles")
}

fn run(nets: &str) -> Report {
    verify(&project(nets, ""), VerifyOptions::default()).expect("verifies")
}

#[test]
fn an_unsafe_place_with_the_shortest_sequence_that_reaches_it() {
    let r = run("net A {
        place a = 1  place b  place c
        transition t1 on go: a -> b, g
        transition t2 on more: b -> c
        transition t3 on done: c -> a
    }");
    assert!(!r.safe);
    assert_eq!(r.unsafe_places.len(), 1);
    let u = &r.unsafe_places[0];
    assert_eq!(u.transition, "A.t1");
    assert_eq!(u.place, "global.g");
    assert_eq!(u.trace, ["go", "more", "done", "go"]);
    // The player refuses the second token: no place ever holds two.
    assert_eq!(r.max_tokens_in_place, 1);
    assert!(!r.is_clean());
}

#[test]
fn a_dead_marking_unless_it_is_a_declared_final_marking() {
    let nets = "net A {
        place a = 1  place b  place c
        transition t1 on go: a -> b
        transition t2 on more: b -> c
    }";
    let r = run(nets);
    assert!(r.deadlock);
    assert_eq!(r.dead_markings.len(), 1);
    assert_eq!(r.dead_markings[0].marking, ["A{c}"]);
    assert_eq!(r.dead_markings[0].trace, ["go", "more"]);
    assert!(!r.dead_markings[0].intended);

    let p = project(nets, "\n[verify]\nfinal = [[\"A.c\"]]\n");
    let r = verify(&p, VerifyOptions::default()).unwrap();
    assert!(!r.deadlock && r.dead_markings[0].intended && r.is_clean());
}

#[test]
fn a_loop_of_immediate_transitions_is_an_error_with_its_cycle() {
    let r = run("net A {
        place a = 1  place b  place c
        transition arm on go: a -> b
        transition ping: b -> c
        transition pong: c -> b
    }");
    assert_eq!(r.livelocks.len(), 1);
    assert_eq!(r.livelocks[0].transitions, ["A.ping", "A.pong"]);
    assert_eq!(r.livelocks[0].trace, ["go"]);
    assert!(!r.is_clean());
}

#[test]
fn loops_that_need_events_are_information() {
    let r = run("net A {
        place a = 1  place b
        transition out on go: a -> b
        transition back on more: b -> a
    }");
    assert!(r.is_clean(), "{r:?}");
    assert_eq!(r.event_loops.len(), 1);
    assert_eq!(r.event_loops[0].events, ["go", "more"]);
    assert_eq!(r.event_loops[0].turn, ["go", "more"]);
    assert!(r.dead_markings.is_empty());
}

#[test]
fn a_conflict_between_two_transitions_on_one_event() {
    let r = run("net A {
        place a = 1  place b  place c
        transition left on go: a -> b
        transition right on go: a -> c
        transition l2 on more: b -> a
    }");
    assert_eq!(r.conflicts.len(), 1);
    let c = &r.conflicts[0];
    assert_eq!(
        (c.winner.as_str(), c.loser.as_str(), c.event.as_str()),
        ("A.left", "A.right", "go")
    );
    assert_eq!(c.trace, ["go"]);
    // The loser can never fire: written order always favours `left`.
    assert_eq!(r.never_fired, ["A.right"]);
}

#[test]
fn nets_never_activated_unused_events_and_dead_transitions() {
    let r = run("net A {
        place a = 1  place b
        transition t on go: a -> b
        transition ghost on more: b, g -> a
    }
    net Spare { place s = 1  transition u on done: s -> s }");
    assert_eq!(r.never_activated, ["Spare"]);
    assert_eq!(r.never_fired, ["A.ghost", "Spare.u"]);
    assert_eq!(r.unused_events, ["never", "halt"]);
}

#[test]
fn activation_makes_a_net_live_and_a_catastrophic_event_ends_the_mission() {
    let r = run("net A {
        place a = 1  place b
        transition t on go: a -> b { activate Spare }
        transition stop on halt: b -> a
    }
    net Spare { place s = 1  place z  transition u on done: s -> z }");
    assert!(r.never_activated.is_empty());
    let over: Vec<_> = r
        .dead_markings
        .iter()
        .filter(|d| d.after_catastrophic)
        .collect();
    assert!(!over.is_empty() && over.iter().all(|d| d.intended));
    assert_eq!(over[0].trace, ["go", "halt"]);
}

#[test]
fn a_timer_expiry_stops_the_timer() {
    let r = run("net A {
        place a = 1  place b  place c
        transition t on go: a -> b { start tick after 5s }
        transition u on done: b -> c
    }");
    let dead = &r.dead_markings[0];
    assert_eq!(
        dead.marking,
        ["A{c}"],
        "the timer no longer runs once its event came"
    );
}

#[test]
fn max_states_stops_with_a_clear_error() {
    let p = project(
        "net A { place a = 1  place b  transition t on go: a -> b  transition u on more: b -> a }",
        "",
    );
    let opts = VerifyOptions {
        max_states: Some(1),
        ..Default::default()
    };
    let e = verify(&p, opts).unwrap_err();
    assert_eq!(e, VerifyError::TooManyStates { limit: 1 });
    assert!(e.to_string().contains("--max-states"));
}

#[test]
fn one_net_alone_with_the_global_places_other_nets_write_free() {
    // A marks `g` after `go`; alone, B sees the environment mark it at any time: its
    // transition can fire. `h` no other net writes: alone, B never sees it change.
    let p = project(
        "net A { place a = 1  transition t on go: a -> a, g }
         net B { place b = 1  place c  place d
                 transition u on more: b, g -> c
                 transition v on more: c, h -> d }",
        "",
    );
    // (`h` is declared in the manifest below, marked by nobody.)
    let whole = verify(&p, VerifyOptions::default()).unwrap();
    assert!(whole.never_fired.contains(&"B.v".to_string()));
    let alone = verify(
        &p,
        VerifyOptions {
            only_net: Some("B".into()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(alone.never_fired, ["B.v"], "{:?}", alone.never_fired);
    assert!(matches!(
        verify(
            &p,
            VerifyOptions {
                only_net: Some("Z".into()),
                ..Default::default()
            }
        ),
        Err(VerifyError::UnknownNet(_))
    ));
}

#[test]
fn the_uav_mission_verifies_clean_with_only_its_expected_loop() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav");
    let (_, c, _) = load_and_check(&dir).unwrap();
    let r = verify(&c.unwrap(), VerifyOptions::default()).unwrap();
    assert!(r.is_clean(), "{r:?}");
    assert!(r.conflicts.is_empty() && r.never_fired.is_empty() && r.never_activated.is_empty());
    assert!(r.unused_events.is_empty());
    // The two planned ends: landed at the base, landed at an emergency site.
    assert_eq!(r.dead_markings.len(), 2);
    assert!(r.dead_markings.iter().all(|d| d.intended));
    // The waypoint loop is the one loop, and it needs DEC and GUI events to turn.
    assert_eq!(r.event_loops.len(), 1);
    for e in ["waypoint", "waypoint_reached"] {
        assert!(r.event_loops[0].events.contains(&e.to_string()));
    }
}
