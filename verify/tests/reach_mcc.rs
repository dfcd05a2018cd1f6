//! The P/T explorer against the Model Checking Contest's published StateSpace answers, against a
//! plain reference explorer on random nets, and on small hand-made nets whose witnesses are
//! known (unsafe places, deadlocks, weights, state limits, unbounded nets).

use petrel_diag::report::Diagnostics;
use petrel_diag::source::{FileId, Span};
use petrel_nets::pnml::{parse_pnml, PtArc, PtNet, PtNode, PtPlace, PtTransition};
use petrel_verify::reach::{
    error_to_json, explore, render_error, render_human, to_json, ExploreError, ExploreOptions,
    PtReport, Representation, Trace,
};
use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;

// ---------------------------------------------------------------------------------------------
// MCC answers
// ---------------------------------------------------------------------------------------------

/// The three largest models, each in its own test so they run in parallel with the rest.
const LARGE: [&str; 3] = ["Peterson-PT-3", "SafeBus-PT-06", "NQueens-PT-10"];

fn mcc_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mcc")
}

/// One row of answers.csv: the columns the explorer must reproduce.
#[derive(Debug)]
struct Answer {
    model: String,
    file: String,
    states: u64,
    edges: u64,
    max_in_place: u64,
    max_per_marking: u64,
    safe: bool,
    deadlock: bool,
}

fn answers() -> Vec<Answer> {
    let text = std::fs::read_to_string(mcc_dir().join("answers.csv")).expect("answers.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("answers.csv has no column {name}"))
    };
    let yes_no = |s: &str| match s {
        "yes" => true,
        "no" => false,
        other => panic!("expected yes or no, found {other}"),
    };
    let cols = [
        col("model"),
        col("file"),
        col("states"),
        col("rg_edges"),
        col("max_tokens_in_place"),
        col("max_tokens_per_marking"),
        col("safe"),
        col("deadlock"),
    ];
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), header.len(), "bad CSV row {l}");
            let num = |i: usize| -> u64 { f[cols[i]].parse().expect("a number") };
            Answer {
                model: f[cols[0]].to_string(),
                file: f[cols[1]].to_string(),
                states: num(2),
                edges: num(3),
                max_in_place: num(4),
                max_per_marking: num(5),
                safe: yes_no(f[cols[6]]),
                deadlock: yes_no(f[cols[7]]),
            }
        })
        .collect()
}

fn load(file: &str) -> PtNet {
    let text = std::fs::read_to_string(mcc_dir().join(file)).unwrap_or_else(|e| panic!("{e}"));
    let mut diags = Diagnostics::new();
    let mut nets = parse_pnml(FileId(0), &text, &mut diags);
    assert!(!diags.has_errors(), "{file} does not parse");
    assert_eq!(nets.len(), 1, "{file}");
    nets.remove(0)
}

/// Explores one MCC model and checks every published number, then the witnesses.
fn check_answer(a: &Answer) {
    let net = load(&a.file);
    let r = explore(&net, ExploreOptions::default())
        .unwrap_or_else(|e| panic!("{}: {}", a.model, render_error(&net, &e)));
    let got = (
        r.states,
        r.edges,
        r.max_tokens_in_place,
        r.max_tokens_per_marking,
        r.safe,
        r.deadlock,
    );
    let want = (
        a.states,
        a.edges,
        a.max_in_place,
        a.max_per_marking,
        a.safe,
        a.deadlock,
    );
    assert_eq!(
        got, want,
        "{}: (states, edges, max in place, max per marking, safe, deadlock)",
        a.model
    );
    assert_eq!(r.deadlock, r.dead_markings > 0, "{}", a.model);
    let unit = net.max_arc_weight() <= 1 && net.max_initial_marking() <= 1;
    if a.safe && unit {
        assert_eq!(r.representation, Representation::Bits, "{}", a.model);
    }
    check_witnesses(&net, &r);
}

/// The traces in a report replay on the net and show what they claim.
fn check_witnesses(net: &PtNet, r: &PtReport) {
    let sim = Sim::new(net);
    match (&r.first_deadlock, r.deadlock) {
        (Some(t), true) => {
            let m = sim.replay(t).expect("the deadlock trace fires");
            assert!(sim.enabled(&m).is_empty(), "the deadlock trace ends dead");
            // Breadth first: no dead marking is closer than the trace's.
            assert_shortest(t, sim.shortest(|m| sim.enabled(m).is_empty(), 20_000));
        }
        (None, false) => {}
        other => panic!("deadlock trace and verdict disagree: {other:?}"),
    }
    match (&r.first_unsafe, r.safe) {
        (Some(u), false) => {
            let t = u.trace.as_ref().expect("traces were kept");
            let m = sim.replay(t).expect("the unsafe trace fires");
            assert_eq!(m[u.place], u.tokens);
            assert!(u.tokens > 1);
            assert_shortest(t, sim.shortest(|m| m.iter().any(|&x| x > 1), 20_000));
        }
        (None, true) => {}
        other => panic!("unsafe witness and verdict disagree: {other:?}"),
    }
}

/// A trace is as short as the reference search says (or longer than the depth it searched).
fn assert_shortest(t: &Trace, reference: Result<usize, usize>) {
    match reference {
        Ok(d) => assert_eq!(t.len(), d, "the trace is shortest"),
        Err(d) => assert!(t.len() >= d, "a shorter trace exists within {d} firings"),
    }
}

#[test]
fn models_up_to_a_million_states_match_the_mcc_answers() {
    let all = answers();
    assert_eq!(all.len(), 30);
    for name in LARGE {
        assert!(all.iter().any(|a| a.model == name), "{name} in answers.csv");
    }
    for a in all.iter().filter(|a| !LARGE.contains(&a.model.as_str())) {
        check_answer(a);
    }
}

fn check_large(model: &str) {
    let all = answers();
    let a = all
        .iter()
        .find(|a| a.model == model)
        .expect("in answers.csv");
    check_answer(a);
}

#[test]
fn peterson_pt_3_matches_the_mcc_answers() {
    check_large("Peterson-PT-3");
}

#[test]
fn safebus_pt_06_matches_the_mcc_answers() {
    check_large("SafeBus-PT-06");
}

#[test]
fn nqueens_pt_10_matches_the_mcc_answers() {
    check_large("NQueens-PT-10");
}

#[test]
fn traces_can_be_left_out_without_changing_the_verdicts() {
    let net = load("Philosophers-PT-000010.pnml");
    let with = explore(&net, ExploreOptions::default()).unwrap();
    let without = explore(
        &net,
        ExploreOptions {
            keep_traces: false,
            ..ExploreOptions::default()
        },
    )
    .unwrap();
    assert!(with.first_deadlock.is_some());
    assert_eq!(without.first_deadlock, None);
    assert!(without.store_bytes < with.store_bytes);
    assert_eq!(
        (with.states, with.edges, with.dead_markings),
        (without.states, without.edges, without.dead_markings)
    );

    let net = load("FMS-PT-00002.pnml");
    let r = explore(
        &net,
        ExploreOptions {
            keep_traces: false,
            ..ExploreOptions::default()
        },
    )
    .unwrap();
    let u = r.first_unsafe.expect("FMS is unsafe");
    assert_eq!(u.trace, None);
    assert_eq!(
        net.places[u.place].initial, u.tokens,
        "unsafe from the start"
    );
}

// ---------------------------------------------------------------------------------------------
// A reference explorer: plain, slow, obviously right
// ---------------------------------------------------------------------------------------------

/// The firing rule written out naively, over `Vec<u64>` markings.
struct Sim {
    initial: Vec<u64>,
    /// Per transition: (place, tokens taken), (place, tokens produced).
    pre: Vec<Vec<(usize, u64)>>,
    post: Vec<Vec<(usize, u64)>>,
}

impl Sim {
    fn new(net: &PtNet) -> Self {
        let mut pre = vec![Vec::new(); net.transitions.len()];
        let mut post = vec![Vec::new(); net.transitions.len()];
        for a in &net.arcs {
            match (a.source, a.target) {
                (PtNode::Place(p), PtNode::Transition(t)) => pre[t].push((p, a.weight)),
                (PtNode::Transition(t), PtNode::Place(p)) => post[t].push((p, a.weight)),
                _ => panic!("bad arc"),
            }
        }
        Sim {
            initial: net.places.iter().map(|p| p.initial).collect(),
            pre,
            post,
        }
    }

    fn fire(&self, m: &[u64], t: usize) -> Option<Vec<u64>> {
        let mut n = m.to_vec();
        for &(p, w) in &self.pre[t] {
            n[p] = n[p].checked_sub(w)?;
        }
        for &(p, w) in &self.post[t] {
            n[p] += w;
        }
        Some(n)
    }

    fn enabled(&self, m: &[u64]) -> Vec<usize> {
        (0..self.pre.len())
            .filter(|&t| self.fire(m, t).is_some())
            .collect()
    }

    fn replay(&self, t: &Trace) -> Option<Vec<u64>> {
        let mut m = self.initial.clone();
        for &x in &t.transitions {
            m = self.fire(&m, x)?;
        }
        Some(m)
    }

    /// Breadth first, level by level, over at most about `limit` markings: `Ok(d)` when the
    /// nearest marking satisfying `goal` is `d` firings away, `Err(d)` when none is within `d`
    /// firings (every marking that close was looked at) and the search stopped there.
    fn shortest(&self, goal: impl Fn(&[u64]) -> bool, limit: usize) -> Result<usize, usize> {
        let mut seen = std::collections::HashSet::from([self.initial.clone()]);
        let mut level = vec![self.initial.clone()];
        for d in 0.. {
            if level.iter().any(|m| goal(m)) {
                return Ok(d);
            }
            if level.is_empty() || seen.len() > limit {
                return Err(d);
            }
            let mut next = Vec::new();
            for m in &level {
                for t in self.enabled(m) {
                    let n = self.fire(m, t).unwrap();
                    if seen.insert(n.clone()) {
                        next.push(n);
                    }
                }
            }
            level = next;
        }
        unreachable!()
    }

    /// (states, edges, max in a place, max in a marking, dead markings), or `None` beyond
    /// `limit` markings.
    fn explore(&self, limit: usize) -> Option<(u64, u64, u64, u64, u64)> {
        let mut seen = HashMap::from([(self.initial.clone(), ())]);
        let mut queue = VecDeque::from([self.initial.clone()]);
        let (mut edges, mut max_p, mut max_m, mut dead) = (0, 0, 0, 0);
        while let Some(m) = queue.pop_front() {
            max_p = max_p.max(m.iter().copied().max().unwrap_or(0));
            max_m = max_m.max(m.iter().sum());
            let en = self.enabled(&m);
            if en.is_empty() {
                dead += 1;
            }
            for t in en {
                edges += 1;
                let n = self.fire(&m, t).unwrap();
                if !seen.contains_key(&n) {
                    if seen.len() >= limit {
                        return None;
                    }
                    seen.insert(n.clone(), ());
                    queue.push_back(n);
                }
            }
        }
        Some((seen.len() as u64, edges, max_p, max_m, dead))
    }
}

// ---------------------------------------------------------------------------------------------
// Hand-made nets
// ---------------------------------------------------------------------------------------------

type Arcs<'a> = &'a [(&'a str, u64)];

/// Arcs of one side of a generated transition: `(place, weight)`.
type ArcList<'a> = Vec<(&'a str, u64)>;

/// A net from places `(name, initial)` and transitions `(name, inputs, outputs)`.
fn net(places: &[(&str, u64)], transitions: &[(&str, Arcs, Arcs)]) -> PtNet {
    let place = |n: &str| {
        places
            .iter()
            .position(|p| p.0 == n)
            .unwrap_or_else(|| panic!("no place {n}"))
    };
    let mut arcs = Vec::new();
    for (t, (_, ins, outs)) in transitions.iter().enumerate() {
        for &(p, w) in ins.iter() {
            arcs.push(PtArc {
                id: format!("a{}", arcs.len()),
                source: PtNode::Place(place(p)),
                target: PtNode::Transition(t),
                weight: w,
                span: Span::default(),
            });
        }
        for &(p, w) in outs.iter() {
            arcs.push(PtArc {
                id: format!("a{}", arcs.len()),
                source: PtNode::Transition(t),
                target: PtNode::Place(place(p)),
                weight: w,
                span: Span::default(),
            });
        }
    }
    PtNet {
        id: "hand".into(),
        name: "hand".into(),
        places: places
            .iter()
            .map(|&(n, initial)| PtPlace {
                id: n.into(),
                name: n.into(),
                initial,
                span: Span::default(),
            })
            .collect(),
        transitions: transitions
            .iter()
            .map(|(n, _, _)| PtTransition {
                id: n.to_string(),
                name: n.to_string(),
                span: Span::default(),
            })
            .collect(),
        arcs,
        has_nupn: false,
        petrel_export: false,
    }
}

fn names(net: &PtNet, t: &Trace) -> Vec<String> {
    t.transitions
        .iter()
        .map(|&i| net.transitions[i].id.clone())
        .collect()
}

#[test]
fn an_unsafe_net_gives_its_place_and_a_shortest_witness() {
    // Two tokens race to `c`; the long way round (`slow1`, `slow2`) also gets there, later.
    let n = net(
        &[("a", 1), ("b", 1), ("c", 0), ("x", 0)],
        &[
            ("slow1", &[("a", 1)], &[("x", 1)]),
            ("toc_a", &[("a", 1)], &[("c", 1)]),
            ("toc_b", &[("b", 1)], &[("c", 1)]),
            ("slow2", &[("x", 1)], &[("a", 1)]),
        ],
    );
    let r = explore(&n, ExploreOptions::default()).unwrap();
    assert!(!r.safe);
    assert_eq!(r.max_tokens_in_place, 2);
    let u = r.first_unsafe.clone().expect("a witness");
    assert_eq!(n.places[u.place].id, "c");
    assert_eq!(u.tokens, 2);
    let t = u.trace.expect("a trace");
    assert_eq!(t.len(), 2);
    let mut got = names(&n, &t);
    got.sort();
    assert_eq!(got, ["toc_a", "toc_b"]);
    assert!(matches!(r.representation, Representation::Counts { .. }));
    let text = render_human(&n, &r);
    assert!(text.contains("safe (1-bounded):        no"), "{text}");
    assert!(text.contains("place `c` holds 2 tokens after firing 2 transitions"));
    let j = to_json(&n, &r);
    assert_eq!(j["safe"], false);
    assert_eq!(j["first_unsafe"]["place"]["id"], "c");
    assert_eq!(j["first_unsafe"]["trace"].as_array().unwrap().len(), 2);
    check_witnesses(&n, &r);
}

#[test]
fn a_deadlock_comes_with_its_shortest_trace() {
    // `loop` keeps the start alive; the short way to the dead end is go, stop; the long way is
    // detour1, detour2, detour3.
    let n = net(
        &[("start", 1), ("mid", 0), ("end", 0), ("d1", 0), ("d2", 0)],
        &[
            ("loop", &[("start", 1)], &[("start", 1)]),
            ("detour1", &[("start", 1)], &[("d1", 1)]),
            ("detour2", &[("d1", 1)], &[("d2", 1)]),
            ("detour3", &[("d2", 1)], &[("end", 1)]),
            ("go", &[("start", 1)], &[("mid", 1)]),
            ("stop", &[("mid", 1)], &[("end", 1)]),
        ],
    );
    let r = explore(&n, ExploreOptions::default()).unwrap();
    assert_eq!(r.states, 5);
    assert_eq!(r.edges, 3 + 1 + 1 + 1);
    assert!(r.deadlock && r.safe);
    assert_eq!(r.dead_markings, 1);
    assert_eq!(r.representation, Representation::Bits);
    assert_eq!(
        names(&n, r.first_deadlock.as_ref().unwrap()),
        ["go", "stop"]
    );
    let text = render_human(&n, &r);
    assert!(
        text.contains("shortest way to a deadlock: firing 2 transitions: `go` `stop`"),
        "{text}"
    );
    let j = to_json(&n, &r);
    for key in [
        "states",
        "edges",
        "max_tokens_in_place",
        "max_tokens_per_marking",
        "safe",
        "deadlock",
        "dead_markings",
        "seconds",
        "first_deadlock",
        "first_unsafe",
    ] {
        assert!(j.get(key).is_some(), "JSON lacks {key}");
    }
    assert_eq!(j["first_deadlock"][1]["id"], "stop");
    assert_eq!(j["first_unsafe"], serde_json::Value::Null);
}

#[test]
fn weighted_arcs_move_several_tokens() {
    let n = net(&[("p", 5), ("q", 0)], &[("t", &[("p", 2)], &[("q", 3)])]);
    let r = explore(&n, ExploreOptions::default()).unwrap();
    // (5,0) -> (3,3) -> (1,6), dead.
    assert_eq!((r.states, r.edges), (3, 2));
    assert_eq!((r.max_tokens_in_place, r.max_tokens_per_marking), (6, 7));
    assert!(!r.safe && r.deadlock);
    assert_eq!(names(&n, r.first_deadlock.as_ref().unwrap()), ["t", "t"]);
    let u = r.first_unsafe.as_ref().unwrap();
    assert_eq!((n.places[u.place].id.as_str(), u.tokens), ("p", 5));
    assert_eq!(r.representation, Representation::Counts { bits: 8 });
}

#[test]
fn unit_weights_on_a_safe_start_can_still_need_counts() {
    // Two input arcs from the same place weigh 2 together.
    let n = net(
        &[("p", 1), ("q", 0)],
        &[("t", &[("p", 1), ("p", 1)], &[("q", 1)])],
    );
    let r = explore(&n, ExploreOptions::default()).unwrap();
    assert_eq!((r.states, r.edges, r.dead_markings), (1, 0, 1));
    assert_eq!(r.representation, Representation::Counts { bits: 8 });
}

#[test]
fn counts_widen_past_255_tokens() {
    let n = net(
        &[("p", 1), ("q", 0)],
        &[
            ("fill", &[("p", 1)], &[("q", 300)]),
            ("drain", &[("q", 100)], &[]),
        ],
    );
    let r = explore(&n, ExploreOptions::default()).unwrap();
    assert_eq!((r.states, r.edges), (5, 4));
    assert_eq!(r.max_tokens_in_place, 300);
    assert_eq!(r.representation, Representation::Counts { bits: 16 });
    check_witnesses(&n, &r);
}

#[test]
fn max_states_stops_with_a_clear_error() {
    let net1 = load("Philosophers-PT-000010.pnml");
    let e = explore(
        &net1,
        ExploreOptions {
            max_states: Some(1000),
            ..ExploreOptions::default()
        },
    )
    .unwrap_err();
    assert_eq!(
        e,
        ExploreError::TooManyStates {
            limit: 1000,
            states_so_far: 1000
        }
    );
    assert!(e
        .to_string()
        .starts_with("more than 1000 reachable markings"));
    assert_eq!(error_to_json(&net1, &e)["error"], "too_many_states");
    // The limit is inclusive: exactly as many states as allowed is fine.
    let r = explore(
        &net1,
        ExploreOptions {
            max_states: Some(59049),
            ..ExploreOptions::default()
        },
    )
    .unwrap();
    assert_eq!(r.states, 59049);
    // Counts too.
    let fms = load("FMS-PT-00002.pnml");
    let e = explore(
        &fms,
        ExploreOptions {
            max_states: Some(100),
            ..ExploreOptions::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, ExploreError::TooManyStates { limit: 100, .. }));
}

/// The witness of an unbounded net replays: the pump strictly grows the marking.
fn check_unbounded(n: &PtNet, e: &ExploreError) {
    let ExploreError::Unbounded(w) = e else {
        panic!("expected unbounded, got {e}");
    };
    let sim = Sim::new(n);
    let m = sim.replay(&w.prefix).expect("the prefix fires");
    let mut m2 = m.clone();
    for &t in &w.pump.transitions {
        m2 = sim.fire(&m2, t).expect("the pump fires");
    }
    assert!(!w.pump.is_empty());
    assert!(m2.iter().zip(&m).all(|(a, b)| a >= b), "the pump covers");
    assert!(m2[w.place] > m[w.place], "the pump grows the place");
    let text = render_error(n, e);
    assert!(text.contains("unbounded"), "{text}");
    assert!(
        text.contains(&format!("`{}`", n.places[w.place].id)),
        "{text}"
    );
}

#[test]
fn a_source_transition_makes_the_net_unbounded_and_says_so() {
    let n = net(&[("p", 0)], &[("produce", &[], &[("p", 1)])]);
    let e = explore(&n, ExploreOptions::default()).unwrap_err();
    check_unbounded(&n, &e);
    let ExploreError::Unbounded(w) = &e else {
        unreachable!()
    };
    assert!(w.prefix.is_empty());
    assert_eq!(names(&n, &w.pump), ["produce"]);
    assert_eq!(error_to_json(&n, &e)["error"], "unbounded");

    // Ten independent sources: the state space explodes in breadth long before one place
    // overflows, and the covering proof still stops it at once.
    let places: Vec<(String, u64)> = (0..10).map(|i| (format!("p{i}"), 0)).collect();
    let place_refs: Vec<(&str, u64)> = places.iter().map(|(n, m)| (n.as_str(), *m)).collect();
    let outs: Vec<[(&str, u64); 1]> = place_refs.iter().map(|&(p, _)| [(p, 1)]).collect();
    let names_t: Vec<String> = (0..10).map(|i| format!("t{i}")).collect();
    let ts: Vec<(&str, Arcs, Arcs)> = (0..10)
        .map(|i| (names_t[i].as_str(), &[][..], &outs[i][..]))
        .collect();
    let n = net(&place_refs, &ts);
    let e = explore(&n, ExploreOptions::default()).unwrap_err();
    check_unbounded(&n, &e);
}

#[test]
fn a_net_that_copies_a_token_is_unbounded() {
    // `copy` keeps its token and adds one to `q` each time: unsafe first, then unbounded.
    let n = net(
        &[("p", 1), ("q", 0), ("r", 1)],
        &[
            ("copy", &[("p", 1)], &[("p", 1), ("q", 1)]),
            ("flip", &[("r", 1)], &[("r", 1)]),
        ],
    );
    let e = explore(&n, ExploreOptions::default()).unwrap_err();
    check_unbounded(&n, &e);
}

#[test]
fn degenerate_nets_explore() {
    // No places, no transitions: one dead marking, reached by the empty trace.
    let empty = net(&[], &[]);
    let r = explore(&empty, ExploreOptions::default()).unwrap();
    assert_eq!((r.states, r.edges, r.dead_markings), (1, 0, 1));
    assert_eq!(r.first_deadlock, Some(Trace::default()));
    assert!(render_human(&empty, &r).contains("no firing (the initial marking)"));
    // A transition without arcs fires forever without changing anything.
    let idle = net(&[("p", 0)], &[("tick", &[], &[])]);
    let r = explore(&idle, ExploreOptions::default()).unwrap();
    assert_eq!((r.states, r.edges, r.deadlock), (1, 1, false));
    assert_eq!(r.max_tokens_in_place, 0);
    // A zero limit stops before the initial marking.
    let e = explore(
        &idle,
        ExploreOptions {
            max_states: Some(0),
            ..ExploreOptions::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, ExploreError::TooManyStates { limit: 0, .. }));
    // An arc joining two places cannot come from PNML, but a hand-built net may hold one.
    let mut bad = net(&[("p", 1), ("q", 0)], &[]);
    bad.arcs.push(PtArc {
        id: "pq".into(),
        source: PtNode::Place(0),
        target: PtNode::Place(1),
        weight: 1,
        span: Span::default(),
    });
    let e = explore(&bad, ExploreOptions::default()).unwrap_err();
    assert!(matches!(e, ExploreError::InvalidNet { .. }), "{e}");
    // So may an out-of-range index.
    let mut bad = net(&[("p", 1)], &[("t", &[("p", 1)], &[])]);
    bad.arcs[0].source = PtNode::Place(7);
    assert!(explore(&bad, ExploreOptions::default()).is_err());
    // Huge counts overflow cleanly instead of wrapping.
    let huge = net(
        &[("p", u64::MAX), ("q", 1)],
        &[("t", &[("q", 1)], &[("p", 1), ("q", 1)])],
    );
    let e = explore(&huge, ExploreOptions::default()).unwrap_err();
    assert!(
        matches!(
            e,
            ExploreError::Unbounded(_) | ExploreError::TokenOverflow { .. }
        ),
        "{e}"
    );
}

#[test]
fn progress_is_reported_on_long_runs() {
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::sync::Arc;
    let calls = Arc::new(AtomicU64::new(0));
    let seen = calls.clone();
    let net = load("Anderson-PT-05.pnml");
    let start = std::time::Instant::now();
    let r = explore(
        &net,
        ExploreOptions {
            progress: Some(Box::new(move |p| {
                assert!(p.states >= p.expanded && p.states_per_second > 0.0);
                seen.fetch_add(1, Ordering::Relaxed);
            })),
            ..ExploreOptions::default()
        },
    )
    .unwrap();
    assert_eq!(r.states, 689_901);
    // Only runs longer than a second report; faster machines may finish first.
    if start.elapsed().as_secs_f64() > 2.5 {
        assert!(calls.load(Ordering::Relaxed) > 0);
    }
}

// ---------------------------------------------------------------------------------------------
// Random nets against the reference explorer
// ---------------------------------------------------------------------------------------------

/// xorshift64*: reproducible nets without a dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn random_net(rng: &mut Rng, safe_start: bool) -> PtNet {
    let places = 1 + rng.below(9) as usize;
    let transitions = rng.below(8) as usize;
    let names: Vec<String> = (0..places.max(transitions))
        .map(|i| format!("n{i}"))
        .collect();
    let marks: Vec<(&str, u64)> = (0..places)
        .map(|p| {
            let m = if safe_start {
                rng.below(2)
            } else {
                [0, 0, 1, 1, 2, 3][rng.below(6) as usize]
            };
            (names[p].as_str(), m)
        })
        .collect();
    let mut arcs: Vec<(ArcList, ArcList)> = Vec::new();
    for _ in 0..transitions {
        let side = |rng: &mut Rng| {
            (0..rng.below(3))
                .map(|_| {
                    let w = if safe_start || rng.below(4) > 0 { 1 } else { 2 };
                    (names[rng.below(places as u64) as usize].as_str(), w)
                })
                .collect::<Vec<_>>()
        };
        let ins = side(rng);
        let outs = side(rng);
        arcs.push((ins, outs));
    }
    let ts: Vec<(&str, Arcs, Arcs)> = arcs
        .iter()
        .enumerate()
        .map(|(i, (a, b))| (names[i].as_str(), &a[..], &b[..]))
        .collect();
    net(&marks, &ts)
}

#[test]
fn random_nets_agree_with_the_reference_explorer() {
    const LIMIT: usize = 3000;
    let mut rng = Rng(0x5EED_1234_ABCD_0001);
    let (mut finished, mut unbounded) = (0, 0);
    for case in 0..600 {
        let n = random_net(&mut rng, case % 2 == 0);
        let sim = Sim::new(&n);
        let want = sim.explore(LIMIT);
        let got = explore(
            &n,
            ExploreOptions {
                max_states: Some(LIMIT as u64),
                ..ExploreOptions::default()
            },
        );
        match (want, got) {
            (Some(w), Ok(r)) => {
                finished += 1;
                let safe = w.2 <= 1;
                assert_eq!(
                    (
                        r.states,
                        r.edges,
                        r.max_tokens_in_place,
                        r.max_tokens_per_marking
                    ),
                    (w.0, w.1, w.2, w.3),
                    "case {case}: {n:?}"
                );
                assert_eq!((r.dead_markings, r.safe), (w.4, safe), "case {case}");
                check_witnesses(&n, &r);
            }
            (Some(_), Err(e)) => panic!("case {case}: bounded net reported as {e}: {n:?}"),
            (None, Ok(r)) => panic!("case {case}: {} states, over the limit: {n:?}", r.states),
            (None, Err(e @ ExploreError::Unbounded(_))) => {
                unbounded += 1;
                check_unbounded(&n, &e);
            }
            (None, Err(ExploreError::TooManyStates { .. })) => {}
            (None, Err(e)) => panic!("case {case}: {e}"),
        }
    }
    // The generator must exercise both outcomes.
    assert!(finished > 200 && unbounded > 50, "{finished} {unbounded}");
}

// ---------------------------------------------------------------------------------------------
// Deadlocks only: the stubborn-set reduction
// ---------------------------------------------------------------------------------------------

fn deadlocks_only() -> ExploreOptions {
    ExploreOptions {
        deadlocks_only: true,
        ..ExploreOptions::default()
    }
}

/// A reduced report against the full one: the same deadlock verdict and dead markings, no more
/// markings, a witness that replays to a dead marking, an unsafe marking only if one is real.
fn check_reduced(net: &PtNet, full: &PtReport, reduced: &PtReport, what: &str) {
    assert!(reduced.reduced && !full.reduced, "{what}");
    assert_eq!(
        (reduced.deadlock, reduced.dead_markings),
        (full.deadlock, full.dead_markings),
        "{what}: the reduction keeps every dead marking"
    );
    assert!(reduced.states <= full.states, "{what}");
    let sim = Sim::new(net);
    match &reduced.first_deadlock {
        Some(t) => {
            let m = sim.replay(t).expect("the witness fires");
            assert!(sim.enabled(&m).is_empty(), "{what}: the witness ends dead");
        }
        None => assert!(!reduced.deadlock, "{what}: a deadlock comes with a witness"),
    }
    if let Some(u) = &reduced.first_unsafe {
        let m = sim
            .replay(u.trace.as_ref().expect("traces kept"))
            .expect("fires");
        assert_eq!(m[u.place], u.tokens, "{what}: the unsafe witness is real");
        assert!(!full.safe, "{what}");
    }
}

#[test]
fn deadlocks_only_finds_the_same_dead_markings_on_the_mcc_models() {
    // Measured on the models that run in full here; the large three against their verdict.
    let mut smaller = 0;
    for a in answers() {
        let net = load(&a.file);
        let reduced = explore(&net, deadlocks_only())
            .unwrap_or_else(|e| panic!("{}: {}", a.model, render_error(&net, &e)));
        assert_eq!(reduced.deadlock, a.deadlock, "{}: MCC's verdict", a.model);
        assert!(reduced.states <= a.states, "{}", a.model);
        smaller += usize::from(reduced.states < a.states);
        if LARGE.contains(&a.model.as_str()) {
            continue;
        }
        let full = explore(&net, ExploreOptions::default()).unwrap();
        check_reduced(&net, &full, &reduced, &a.model);
    }
    // The reduction must actually reduce on a benchmark of concurrent systems.
    assert!(
        smaller >= 15,
        "only {smaller} of 30 models explored fewer markings"
    );
}

#[test]
fn independent_components_cost_markings_linear_in_their_number() {
    // Twelve independent two-place cycles (2^12 markings in full) beside a component that can
    // deadlock: `go` takes the only token of `k` for good.
    let names: Vec<(String, String, String, String)> = (0..12)
        .map(|i| {
            (
                format!("a{i}"),
                format!("b{i}"),
                format!("up{i}"),
                format!("down{i}"),
            )
        })
        .collect();
    let mut places: Vec<(&str, u64)> = vec![("k", 1), ("gone", 0)];
    let mut arcs: Vec<(ArcList, ArcList)> = Vec::new();
    let mut tnames: Vec<&str> = Vec::new();
    for (a, b, up, down) in &names {
        places.push((a, 1));
        places.push((b, 0));
        arcs.push((vec![(a, 1), ("k", 1)], vec![(b, 1), ("k", 1)]));
        tnames.push(up);
        arcs.push((vec![(b, 1)], vec![(a, 1)]));
        tnames.push(down);
    }
    arcs.push((vec![("k", 1)], vec![("gone", 1)]));
    tnames.push("go");
    let ts: Vec<(&str, Arcs, Arcs)> = arcs
        .iter()
        .zip(&tnames)
        .map(|((i, o), n)| (*n, &i[..], &o[..]))
        .collect();
    let n = net(&places, &ts);
    let full = explore(&n, ExploreOptions::default()).unwrap();
    let reduced = explore(&n, deadlocks_only()).unwrap();
    check_reduced(&n, &full, &reduced, "components");
    // Full: every combination of the cycles, with `k` and after `go` (2 x 4096). After `go`
    // nothing goes up and every `down` still can: the one dead marking has every cycle at `a`.
    assert_eq!(full.states, 2 * 4096);
    assert_eq!(full.dead_markings, 1);
    assert!(
        reduced.states < 200,
        "{} markings explored for 12 components",
        reduced.states
    );
    let text = render_human(&n, &reduced);
    assert!(text.contains("deadlocks only"), "{text}");
    assert!(text.contains("not necessarily the shortest"), "{text}");
    assert!(
        text.contains("safe (1-bounded):        not decided"),
        "{text}"
    );
    let json = to_json(&n, &reduced);
    assert_eq!(json["reduced"], true);
    assert!(json["safe"].is_null(), "{json}");
}

#[test]
fn deadlocks_only_agrees_with_the_reference_explorer_on_random_nets() {
    const LIMIT: usize = 3000;
    let mut rng = Rng(0x5EED_1234_ABCD_0002);
    let (mut compared, mut smaller) = (0, 0);
    for case in 0..800 {
        // Larger nets than the other random test: concurrency is what the reduction works on.
        let n = random_wide_net(&mut rng, case % 2 == 0);
        let sim = Sim::new(&n);
        let Some(want) = sim.explore(LIMIT) else {
            continue;
        };
        let full = explore(&n, ExploreOptions::default()).unwrap();
        let reduced = explore(&n, deadlocks_only())
            .unwrap_or_else(|e| panic!("case {case}: a bounded net reported as {e}: {n:?}"));
        assert_eq!(full.dead_markings, want.4, "case {case}");
        check_reduced(&n, &full, &reduced, &format!("case {case}: {n:?}"));
        compared += 1;
        smaller += usize::from(reduced.states < full.states);
    }
    assert!(compared > 300 && smaller > 100, "{compared} {smaller}");
}

/// Up to 16 places and 14 transitions, arcs to few places each: several loosely coupled parts.
fn random_wide_net(rng: &mut Rng, safe_start: bool) -> PtNet {
    let places = 4 + rng.below(13) as usize;
    let transitions = 2 + rng.below(13) as usize;
    let names: Vec<String> = (0..places.max(transitions))
        .map(|i| format!("n{i}"))
        .collect();
    let marks: Vec<(&str, u64)> = (0..places)
        .map(|p| {
            let m = if safe_start {
                rng.below(2)
            } else {
                [0, 0, 1, 1, 2][rng.below(5) as usize]
            };
            (names[p].as_str(), m)
        })
        .collect();
    let mut arcs: Vec<(ArcList, ArcList)> = Vec::new();
    for _ in 0..transitions {
        // Each transition works in a window of nearby places, so distant ones are independent.
        let base = rng.below(places as u64) as usize;
        let side = |rng: &mut Rng, n: u64| {
            (0..n)
                .map(|_| {
                    let p = (base + rng.below(3) as usize) % places;
                    let w = if safe_start || rng.below(4) > 0 { 1 } else { 2 };
                    (names[p].as_str(), w)
                })
                .collect::<Vec<_>>()
        };
        let (n_in, n_out) = (1 + rng.below(2), rng.below(3));
        let ins = side(rng, n_in);
        let outs = side(rng, n_out);
        arcs.push((ins, outs));
    }
    let ts: Vec<(&str, Arcs, Arcs)> = arcs
        .iter()
        .enumerate()
        .map(|(i, (a, b))| (names[i].as_str(), &a[..], &b[..]))
        .collect();
    net(&marks, &ts)
}
