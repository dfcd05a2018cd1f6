//! The verifier's zero-time cascade check (E0608, docs/verification.md, "Zero-time cascades"):
//! events the nets produce at one instant that never settle, whether a net emits its own event,
//! two nets answer each other, an immediate transition closes the loop, or a handler of the
//! player's reports does; and what must stay clean: a long cascade that ends, a ping-pong that
//! a place ends, values that no guard lets round.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::project::from_sources;
use petrel_nets::verify::{diagnostics, render_human, verify, Report, VerifyOptions};

const MANIFEST: &str = r#"
[project]
name = "loops"
files = ["a.pn"]
start = START

[events]
start_mission = { category = "nominal" }
health_check = { category = "nominal" INTERNAL }
ping = { category = "nominal" }
pong = { category = "nominal" }
go = { category = "nominal" }
step = { category = "nominal" }
a = { category = "nominal", params = ["x: int"] }
b = { category = "nominal", params = ["y: int"] }
c = { category = "nominal", params = ["x: float"] }
d = { category = "nominal", params = ["y: float"] }

[programs.NAV]
functions = { status = [] }
"#;

fn compile(start: &str, internal: bool, nets: &str) -> CompiledProject {
    let manifest = MANIFEST
        .replace("START", start)
        .replace("INTERNAL", if internal { ", internal = true" } else { "" });
    let (_, c, d, sources) = from_sources(&manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{}", d.render_human(&sources));
    c.expect("compiles")
}

fn run(c: &CompiledProject) -> Report {
    verify(c, VerifyOptions::default()).expect("verifies")
}

/// Without the partial-order reduction.
fn run_full(c: &CompiledProject) -> Report {
    verify(
        c,
        VerifyOptions {
            no_reduction: true,
            ..Default::default()
        },
    )
    .expect("verifies")
}

const HEALTH: &str = "
net MONITOR {
    place idle = 1
    place watching
    transition begin on start_mission: idle -> watching { emit health_check }
    transition check on health_check: watching -> watching {
        call NAV.status()
        emit health_check
    }
}
";

#[test]
fn a_net_that_emits_its_own_event_is_an_error_naming_the_loop() {
    for internal in [false, true] {
        let r = run(&compile(r#"["MONITOR"]"#, internal, HEALTH));
        assert_eq!(r.cascades.len(), 1, "internal: {internal}: {r:#?}");
        let c = &r.cascades[0];
        assert!(c.endless);
        assert_eq!(c.events, ["health_check"]);
        assert_eq!(c.transitions, ["MONITOR.check"]);
        assert_eq!(c.trace, ["start_mission"]);
        assert!(!r.is_clean());
        assert_eq!(r.errors(), 1, "{}", render_human("loops", &r));
        let text = render_human("loops", &r);
        assert!(
            text.contains("error: events produced at one instant loop for ever: health_check → health_check → ... (each turn fires MONITOR.check), after start_mission"),
            "{text}"
        );
    }
}

#[test]
fn the_diagnostic_points_at_the_transition_of_the_loop() {
    let manifest = MANIFEST
        .replace("START", r#"["MONITOR"]"#)
        .replace("INTERNAL", "");
    let (project, c, d, sources) = from_sources(&manifest, &[("a.pn", HEALTH)]);
    assert!(!d.has_errors());
    let r = run(&c.unwrap());
    let diags = diagnostics(&project, &r);
    let text = diags.render_human(&sources);
    assert!(
        text.contains("[E0608] Error: events produced at one instant loop for ever"),
        "{text}"
    );
    assert!(text.contains("a.pn:6:16"), "{text}");
    assert!(
        text.contains("the player would stop it after 10000 steps at one instant and raise livelock, after start_mission"),
        "{text}"
    );
}

#[test]
fn two_nets_that_answer_each_other_loop() {
    let c = compile(
        r#"["A", "B"]"#,
        false,
        "net A {
            place a = 1
            transition serve on ping: a -> a { emit pong to B }
        }
        net B {
            place b = 1
            transition answer on pong: b -> b { emit ping to A }
        }",
    );
    let r = run(&c);
    assert_eq!(r.cascades.len(), 1, "{r:#?}");
    let f = &r.cascades[0];
    assert!(f.endless);
    assert_eq!(f.events, ["ping to A", "pong to B"]);
    assert_eq!(f.transitions, ["A.serve", "B.answer"]);
    assert_eq!(f.trace.len(), 1);
}

#[test]
fn a_loop_through_an_immediate_transition() {
    let c = compile(
        r#"["A"]"#,
        false,
        "net A {
            place idle = 1
            place armed
            transition arm on go: idle -> armed
            transition fire: armed -> idle { emit go }
        }",
    );
    let r = run(&c);
    assert!(
        r.livelocks.is_empty(),
        "not a loop of immediate transitions alone"
    );
    assert_eq!(r.cascades.len(), 1, "{r:#?}");
    assert_eq!(r.cascades[0].events, ["go"]);
    assert_eq!(r.cascades[0].transitions, ["A.arm", "A.fire"]);
    assert_eq!(r.cascades[0].trace, ["go"]);
}

#[test]
fn a_handler_of_a_refusal_that_refuses_again_loops() {
    // `go` wants a token in `b`, which is marked: refused; the handler of the player's
    // `safety_violation` emits `go` again.
    let c = compile(
        r#"["A"]"#,
        false,
        "net A {
            place a = 1
            place b = 1
            transition t on go: a -> a, b
            transition retry on safety_violation(n, t, p): a -> a { emit go }
        }",
    );
    let r = run(&c);
    assert!(!r.safe);
    assert_eq!(r.cascades.len(), 1, "{r:#?}");
    let f = &r.cascades[0];
    // The turn reads from its step that fires the first transition.
    assert_eq!(f.events, ["safety_violation(\"A\", \"t\", \"A.b\")", "go"]);
    assert_eq!(f.transitions, ["A.retry"]);
}

#[test]
fn a_cascade_whose_queue_grows_reaches_the_bound() {
    let c = compile(
        r#"["A"]"#,
        false,
        "net A {
            place a = 1
            transition twice on step: a -> a { emit step  emit step }
        }",
    );
    let r = run(&c);
    assert_eq!(r.cascades.len(), 1, "{r:#?}");
    let f = &r.cascades[0];
    assert!(!f.endless);
    assert_eq!(f.events, ["step"]);
    assert_eq!(f.transitions, ["A.twice"]);
    let text = render_human("loops", &r);
    assert!(
        text.contains("events produced at one instant do not settle: the cascade of step takes 10000 steps with events still queued (it fires A.twice)"),
        "{text}"
    );
}

#[test]
fn a_long_cascade_that_ends_is_clean() {
    // A relay through 300 places: 300 steps at one instant after `step`, then it ends.
    let mut net = String::from("net A {\n place p0 = 1\n");
    for i in 1..=300 {
        net.push_str(&format!(" place p{i}\n"));
    }
    for i in 0..300 {
        net.push_str(&format!(
            " transition t{i} on step: p{i} -> p{} {{ emit step }}\n",
            i + 1
        ));
    }
    net.push_str("}\n");
    let r = run(&compile(r#"["A"]"#, false, &net));
    assert!(r.cascades.is_empty(), "{:?}", r.cascades);
    assert!(!r.cascades_incomplete);
    // The events do loop syntactically (`step` emits `step`): the search went through them.
    assert!(
        r.cascade_configurations >= 300,
        "{}",
        r.cascade_configurations
    );
}

#[test]
fn a_ping_pong_that_a_place_ends_is_clean() {
    let c = compile(
        r#"["A", "B"]"#,
        false,
        "net A {
            place ready = 1
            place served
            transition serve on ping: ready -> served { emit pong }
            transition reset on go: served -> ready
        }
        net B {
            place b = 1
            transition answer on pong: b -> b { emit ping }
        }",
    );
    let r = run(&c);
    assert!(r.cascades.is_empty(), "{:?}", r.cascades);
    assert!(r.cascade_configurations > 0);
}

#[test]
fn values_passed_along_are_followed_with_the_classes_of_every_guard_they_meet() {
    // `c(x)` hands x to `d` and back: it goes round for x between 2.5 and 3. Neither event's
    // own classes hold such a value (c's: 0, 1, 2, 3, 4; d's: 1.5, 2.5, 3.5): the classes of
    // a value handed along split it by every guard it meets.
    let looping = "net A {
            place p = 1
            transition pass on c(x) if x > 1.0 and x < 3.0: p -> p { emit d(x) }
            transition back on d(y) if y > 2.5: p -> p { emit c(y) }
        }";
    let r = run(&compile(r#"["A"]"#, false, looping));
    assert_eq!(r.cascades.len(), 1, "{r:#?}");
    assert_eq!(r.cascades[0].events, ["c(2.75)", "d(2.75)"]);
    // No value is both below 1 and above 2.5: nothing loops.
    let settles = looping.replace("x > 1.0 and x < 3.0", "x < 1.0");
    let r = run(&compile(r#"["A"]"#, false, &settles));
    assert!(r.cascades.is_empty(), "{:?}", r.cascades);
}

#[test]
fn without_a_cycle_of_emissions_nothing_is_searched() {
    let c = compile(
        r#"["A", "B"]"#,
        false,
        "net A {
            place a = 1
            transition serve on ping: a -> a { emit pong }
        }
        net B {
            place b = 1
            transition answer on pong: b -> b
        }",
    );
    let r = run(&c);
    assert!(r.cascades.is_empty());
    assert_eq!(r.cascade_configurations, 0);
}

#[test]
fn a_loop_at_start_has_an_empty_trace() {
    let c = compile(
        r#"["A"]"#,
        false,
        "net A {
            place a = 1
            place b
            transition boot: a -> b { emit go }
            transition again on go: b -> b { emit go }
        }",
    );
    let r = run(&c);
    assert_eq!(r.cascades.len(), 1, "{r:#?}");
    assert!(r.cascades[0].trace.is_empty());
    assert!(render_human("loops", &r).contains("(each turn fires A.again), at start"));
}

#[test]
fn reduced_and_full_explorations_find_the_same_loops() {
    // Two independent groups: the loop is in one of them.
    let c = compile(
        r#"["A", "B", "C"]"#,
        false,
        "net A {
            place a = 1
            transition serve on ping: a -> a { emit pong to B }
        }
        net B {
            place b = 1
            transition answer on pong: b -> b { emit ping to A }
        }
        net C {
            place c0 = 1
            place c1
            transition up on go: c0 -> c1
            transition down on step: c1 -> c0
        }",
    );
    let full = run_full(&c);
    let reduced = run(&c);
    assert!(reduced.partial, "the reduction applies");
    assert_eq!(full.cascades.len(), 1);
    assert_eq!(
        (
            reduced.cascades[0].events.clone(),
            reduced.cascades[0].transitions.clone()
        ),
        (
            full.cascades[0].events.clone(),
            full.cascades[0].transitions.clone()
        )
    );
}

/// Generated projects: two nets that emit events to themselves and to each other (immediate
/// transitions among them), beside a third they share nothing with. The reduced exploration
/// finds the cascades the full one finds.
#[test]
fn generated_loops_are_found_the_same_reduced_and_in_full() {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move |m: u64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state % m
    };
    let events = ["ping", "pong", "go"];
    let (mut looping, mut partial) = (0, 0);
    for round in 0..80 {
        let mut nets = String::new();
        for net in ["A", "B"] {
            nets.push_str(&format!("net {net} {{\n place p0 = 1\n place p1\n"));
            for t in 0..3 {
                let trigger = match next(4) {
                    0 => String::new(),
                    k => format!(" on {}", events[k as usize - 1]),
                };
                let emit = if next(3) < 2 {
                    format!(" {{ emit {} }}", events[next(3) as usize])
                } else {
                    String::new()
                };
                nets.push_str(&format!(
                    " transition t{t}{trigger}: p{} -> p{}{emit}\n",
                    next(2),
                    next(2)
                ));
            }
            nets.push_str("}\n");
        }
        nets.push_str("net C {\n place c0 = 1\n place c1\n transition up on step: c0 -> c1\n transition down on start_mission: c1 -> c0\n}\n");
        let c = compile(r#"["A", "B", "C"]"#, false, &nets);
        let key = |r: &Report| -> Vec<(Vec<String>, bool)> {
            let mut v: Vec<_> = r
                .cascades
                .iter()
                .map(|c| (c.transitions.clone(), c.endless))
                .collect();
            v.sort();
            v
        };
        let full = run_full(&c);
        let reduced = run(&c);
        assert_eq!(key(&reduced), key(&full), "round {round}:\n{nets}");
        looping += usize::from(!full.cascades.is_empty());
        partial += usize::from(reduced.partial);
    }
    eprintln!("{looping} of 80 loop, the reduction applies to {partial}");
    assert!(
        looping >= 15 && partial >= 15,
        "{looping} loop, {partial} reduced"
    );
}

#[test]
fn a_reload_is_refused_on_a_cascade_that_never_settles() {
    let r = run(&compile(r#"["MONITOR"]"#, false, HEALTH));
    let f = petrel_nets::reload::refusing_finding(&r).expect("a refusing finding");
    assert!(
        f.what.starts_with(
            "livelock: events produced at one instant do not settle (health_check; MONITOR.check)"
        ),
        "{}",
        f.what
    );
    assert_eq!(f.trace, ["start_mission"]);
}

#[test]
fn a_search_that_runs_out_of_its_budget_says_so() {
    // One stable state, but queues of 1 to 256 `step`s: more configurations than 100.
    let c = compile(
        r#"["A"]"#,
        false,
        "net A {
            place a = 1
            transition twice on step: a -> a { emit step  emit step }
        }",
    );
    let r = verify(
        &c,
        VerifyOptions {
            max_states: Some(100),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(r.cascades_incomplete);
    assert!(render_human("loops", &r)
        .contains("(not checked in full: stopped after 101 configurations)"));
    let manifest = MANIFEST
        .replace("START", r#"["A"]"#)
        .replace("INTERNAL", "");
    let (project, _, _, _) = from_sources(
        &manifest,
        &[(
            "a.pn",
            "net A { place a = 1 transition twice on step: a -> a { emit step  emit step } }",
        )],
    );
    let d = diagnostics(&project, &r);
    assert!(d.iter().any(|x| x.code == "W0607"), "{d:?}");
}
