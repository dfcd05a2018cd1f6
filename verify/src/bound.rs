//! Time bounds (`[verify.bounds]`, `petrel verify --timed --bound FROM..TO`): over every
//! occurrence of `from`, the least and greatest time until the next `to`, over every timed
//! path (docs/verification.md, "Time bounds").
//!
//! An observer's clock is added to the zone of [`super::timed`]: reset at the instant `from`
//! happens, never bounded nor tested, so it changes no behaviour and the zone graph stays exact
//! (the projection of an observer's zone on the timers' clocks is the zone of the graph's state;
//! every edge of the state is possible from it). From each edge where `from` happens (and each
//! initial state where the marking holds), the timed states are explored again along the graph's
//! edges, each step replayed with the firing code to learn its timers' operations, until `to`
//! happens: the observer's clock at that instant ranges over `[lo, hi]`, and the bound is the
//! least `lo` and the greatest `hi`. Where `to` may never come, the bound is unbounded, with the
//! reason and the path:
//!
//! - a dead marking (or the end of the mission after a catastrophic event) without `to`;
//! - a state with no running timer of known duration: time may pass forever there, the outside
//!   events it waits for may never come (or a timer whose duration is a parameter);
//! - a path that took longer than `(W + 1) * D` without `to`, `W` the states met while waiting
//!   and `D` the longest duration of a running timer: each state lets at most `D` pass, so it
//!   went round a cycle that takes time, and can go round it again.
//!
//! Runs with infinitely many events in a finite time (a loop of outside events at one instant)
//! are not counted: they do not happen.

use super::env::Env;
use super::explore::{run_step, Edges, Graph, Recorder};
use super::timed::{TimerOps, Timing, INF};
use crate::report::{BoundFinding, BoundStatus, Trace};
use petrel_nets::compiled::{Bound, CompiledProject, Occurrence};
use petrel_nets::semantics::{Scratch, Semantics};
use std::collections::HashMap;
use std::fmt::Write as _;

/// Timed states one bound may visit before it gives up (the report says so).
const MAX_VISITS: usize = 2_000_000;

/// How a visited timed state (with the observer's clock) was reached.
#[derive(Clone, Copy)]
enum Parent {
    /// `from` happened on the edge labelled `label` out of graph state `source` (`None`: at
    /// the start, in the initial state `source`).
    From { source: u32, label: Option<u32> },
    /// One step of the graph from visit `prev`.
    Step { prev: usize, label: u32 },
}

/// A timed state met while waiting for `to`.
struct Visit {
    node: u32,
    parent: Parent,
}

/// Where the longest wait or the reason it is unbounded was seen: a visit, and the label of
/// the step that made `to` happen from there, if any.
#[derive(Clone, Copy)]
struct Witness {
    visit: usize,
    last: Option<u32>,
    /// The wait went round a cycle that takes time.
    cycle: bool,
}

/// The bounds of `p` over the timed graph `g` (states laid out by `plain`).
pub(super) fn bounds(
    p: &CompiledProject,
    sem: &Semantics,
    env: &Env,
    g: &Graph,
    graph_edges: &Edges,
    plain: &Timing,
    describe: &dyn Fn(&[u64]) -> Vec<String>,
) -> Vec<BoundFinding> {
    let guards = super::explore::rule_guards(p, sem);
    // The compact graph names an edge's step kind; the search wants each edge whole (only
    // projects that declare bounds pay for this copy).
    let mut edges: Vec<BoundEdge> = Vec::with_capacity(g.edge_count());
    let mut out_edges: Vec<Vec<u32>> = vec![Vec::new(); g.states.len()];
    let mut buf = Vec::new();
    for i in 0..g.states.len() as u32 {
        graph_edges.of(i, &mut buf);
        for e in &buf {
            let (label, fired) = g.steps()[e.kind as usize];
            out_edges[i as usize].push(edges.len() as u32);
            edges.push(BoundEdge {
                from: i,
                to: e.to,
                label,
                fired,
            });
        }
    }
    let mut dead = vec![false; g.states.len()];
    for &i in &g.dead {
        dead[i as usize] = true;
    }
    let initial: Vec<u32> = (0..g.states.len() as u32)
        .filter(|&i| g.parent(i).is_none())
        .collect();
    let mut s = Search {
        p,
        sem,
        env,
        g,
        plain,
        tm: Timing::with_observer(p, plain.base),
        rec: Recorder::with_guards(guards),
        scratch: Scratch::default(),
        edges,
        out_edges,
        dead,
        initial,
        describe,
    };
    p.bounds.iter().map(|b| s.bound(b)).collect()
}

/// An edge of the explored graph, whole.
#[derive(Clone, Copy)]
struct BoundEdge {
    from: u32,
    to: u32,
    label: u32,
    /// Index in the graph's `fired_sets`.
    fired: u32,
}

struct Search<'a> {
    p: &'a CompiledProject,
    sem: &'a Semantics<'a>,
    env: &'a Env,
    g: &'a Graph,
    plain: &'a Timing,
    tm: Timing,
    rec: Recorder,
    scratch: Scratch,
    edges: Vec<BoundEdge>,
    out_edges: Vec<Vec<u32>>,
    dead: Vec<bool>,
    initial: Vec<u32>,
    describe: &'a dyn Fn(&[u64]) -> Vec<String>,
}

/// What one bound's search found so far.
#[derive(Default)]
struct Found {
    visits: Vec<Visit>,
    min: Option<i64>,
    max: Option<(i64, Witness)>,
    unbounded: Option<(String, Witness)>,
}

impl Search<'_> {
    /// The untimed words after the step labelled `label` from graph state `i`, with the expired
    /// timer and the timers' operations of that step.
    fn replay(&mut self, i: u32, label: u32) -> (Vec<u64>, Option<usize>, TimerOps) {
        let lab = &self.g.labels[label as usize];
        let d = &self.g.deliveries[lab.delivery as usize];
        let t = run_step(
            self.sem,
            self.env,
            &mut self.rec,
            &mut self.scratch,
            &self.g.states[i as usize],
            Some(d),
            &lab.choices,
            lab.counter,
        );
        // As the exploration: a timer's event from no counter is that timer's expiry.
        let expired = if lab.counter.is_none() {
            Timing::timer_of(self.p, d.event)
        } else {
            None
        };
        (
            t[..self.plain.base].to_vec(),
            expired,
            self.rec.timer_ops.clone(),
        )
    }

    /// Event `end` happens on edge `e`: its label's event, taken by some transition.
    fn event_on(&self, end: &Occurrence, e: u32) -> bool {
        let edge = &self.edges[e as usize];
        match end {
            Occurrence::Event(ev) => {
                self.g.labels[edge.label as usize].event == *ev
                    && !self.g.fired_sets[edge.fired as usize].is_empty()
            }
            Occurrence::Marking(_) => false,
        }
    }

    fn holds(&self, end: &Occurrence, s: &[u64]) -> bool {
        match end {
            Occurrence::Marking(f) => self.sem.layout.holds(f, s),
            Occurrence::Event(_) => false,
        }
    }

    /// `from` happens on edge `e`: its event is taken, or its marking starts to hold.
    fn starts_on(&self, b: &Bound, e: u32) -> bool {
        let edge = &self.edges[e as usize];
        match &b.from {
            Occurrence::Event(_) => self.event_on(&b.from, e),
            Occurrence::Marking(_) => {
                !self.holds(&b.from, &self.g.states[edge.from as usize])
                    && self.holds(&b.from, &self.g.states[edge.to as usize])
            }
        }
    }

    fn bound(&mut self, b: &Bound) -> BoundFinding {
        let mut f = Found::default();
        let mut seen: HashMap<Vec<u64>, usize> = HashMap::new();
        let mut waiting_nodes: HashMap<u32, ()> = HashMap::new();
        let mut longest = 0i64;
        let mut queue: std::collections::VecDeque<(usize, Vec<u64>)> = Default::default();
        let mut from_happens = false;
        let mut stopped = false;

        // The starts: each initial state holding the marking, each edge where `from` happens.
        for k in 0..self.initial.len() {
            let i = self.initial[k];
            let s = &self.g.states[i as usize];
            if !self.holds(&b.from, s) {
                continue;
            }
            from_happens = true;
            let mut t = self.tm.extend(self.plain, s);
            self.tm.at_start(&mut t);
            let parent = Parent::From {
                source: i,
                label: None,
            };
            self.start(b, &mut f, &mut seen, &mut queue, i, parent, t);
        }
        for e in 0..self.edges.len() as u32 {
            let edge = self.edges[e as usize];
            if self.g.labels[edge.label as usize].delivery == u32::MAX || !self.starts_on(b, e) {
                continue;
            }
            from_happens = true;
            let src = self
                .tm
                .extend(self.plain, &self.g.states[edge.from as usize]);
            let (untimed, expired, ops) = self.replay(edge.from, edge.label);
            let mut t = untimed;
            t.extend_from_slice(&src[self.plain.base..]);
            self.tm.apply(&self.sem.layout, &mut t, expired, &ops);
            self.tm.observer_reset(&mut t);
            let parent = Parent::From {
                source: edge.from,
                label: Some(edge.label),
            };
            self.start(b, &mut f, &mut seen, &mut queue, edge.to, parent, t);
        }

        while let Some((v, t)) = queue.pop_front() {
            if f.visits.len() > MAX_VISITS {
                stopped = true;
                break;
            }
            let node = f.visits[v].node;
            let s = &self.g.states[node as usize];
            waiting_nodes.insert(node, ());
            longest = longest.max(self.tm.longest(&t));
            let (lo, hi) = self.tm.observer_range(&t);
            let here = Witness {
                visit: v,
                last: None,
                cycle: false,
            };
            if self.dead[node as usize] {
                if f.unbounded.is_none() {
                    let what = if self.sem.layout.is_over(s) {
                        "the mission is over (a catastrophic event) and"
                    } else {
                        "a dead marking:"
                    };
                    let reason = format!(
                        "{what} {} never comes in {}",
                        b.to_text,
                        (self.describe)(s).join(" ")
                    );
                    f.unbounded = Some((reason, here));
                }
                continue;
            }
            if !self.tm.has_deadline(&t) && f.unbounded.is_none() {
                f.unbounded = Some((self.waits_for(node, &t), here));
            }
            let cap = (waiting_nodes.len() as i64 + 1).saturating_mul(longest.max(1));
            if hi < INF && hi > cap {
                if f.unbounded.is_none() {
                    f.unbounded = Some((
                        format!(
                            "a cycle without {} that takes time: the mission can go round it forever",
                            b.to_text
                        ),
                        Witness { cycle: true, ..here },
                    ));
                }
                continue;
            }
            if lo > cap {
                continue;
            }
            for k in 0..self.out_edges[node as usize].len() {
                let e = self.out_edges[node as usize][k];
                let edge = self.edges[e as usize];
                if self.g.labels[edge.label as usize].delivery == u32::MAX {
                    continue;
                }
                let (untimed, expired, ops) = self.replay(node, edge.label);
                debug_assert_eq!(
                    untimed[..],
                    self.g.states[edge.to as usize][..self.plain.base]
                );
                let mut n = untimed;
                n.extend_from_slice(&t[self.plain.base..]);
                self.tm.apply(&self.sem.layout, &mut n, expired, &ops);
                let to_now = self.event_on(&b.to, e) || self.holds(&b.to, &n);
                if to_now {
                    let w = Witness {
                        visit: v,
                        last: Some(edge.label),
                        cycle: false,
                    };
                    record(&mut f, self.tm.observer_range(&n), w);
                    continue;
                }
                self.tm.elapse(&mut n);
                if !seen.contains_key(&n) {
                    f.visits.push(Visit {
                        node: edge.to,
                        parent: Parent::Step {
                            prev: v,
                            label: edge.label,
                        },
                    });
                    let id = f.visits.len() - 1;
                    seen.insert(n.clone(), id);
                    queue.push_back((id, n));
                }
            }
        }

        let mut finding = BoundFinding {
            name: b.name.clone(),
            from: b.from_text.clone(),
            to: b.to_text.clone(),
            within_seconds: b.within_us.map(|us| us as f64 / 1e6),
            within: b.within_text.clone(),
            status: BoundStatus::Bounded,
            reason: None,
            min_seconds: f.min.map(seconds),
            max_seconds: None,
            trace: Vec::new(),
            then: Vec::new(),
            met: None,
        };
        if !from_happens {
            // Nothing to wait for: a requirement holds vacuously.
            finding.status = BoundStatus::FromNeverHappens;
            finding.met = b.within_us.map(|_| true);
            return finding;
        }
        if stopped {
            finding.status = BoundStatus::NotDecided;
            finding.reason = Some(format!(
                "the search stopped after {MAX_VISITS} timed states"
            ));
            return finding;
        }
        let witness = match (&f.unbounded, &f.max) {
            (Some((reason, w)), _) => {
                finding.status = BoundStatus::Unbounded;
                finding.reason = Some(reason.clone());
                *w
            }
            (None, Some((hi, w))) => {
                finding.max_seconds = Some(seconds(*hi));
                *w
            }
            (None, None) => {
                // Every wait was cut short by the cap: not expected (a cycle is reported).
                finding.status = BoundStatus::Unbounded;
                finding.reason = Some(format!("{} never comes after {}", b.to_text, b.from_text));
                finding.met = b.within_us.map(|_| false);
                return finding;
            }
        };
        let (trace, mut then, nodes) = self.path(&f, witness);
        if f.unbounded.as_ref().is_some_and(|(_, w)| w.cycle) {
            // The path up to the first state met again, and that turn of the cycle.
            if let Some((i, j)) = (0..nodes.len()).find_map(|j| {
                nodes[..j]
                    .iter()
                    .position(|&n| n == nodes[j])
                    .map(|i| (i, j))
            }) {
                let turn = then[i..j].join(" → ");
                then.truncate(j);
                if let Some(r) = &mut finding.reason {
                    let _ = write!(r, " (one turn: {turn})");
                }
            }
        }
        finding.trace = trace;
        finding.then = then;
        finding.met = b.within_us.map(|us| {
            f.unbounded.is_none()
                && f.max
                    .is_some_and(|(hi, _)| (hi as u128) * 1000 <= us as u128)
        });
        finding
    }

    /// Starts a wait at graph state `node` with the zone `t` at the instant `from` happened
    /// (time has not passed yet).
    #[allow(clippy::too_many_arguments)]
    fn start(
        &mut self,
        b: &Bound,
        f: &mut Found,
        seen: &mut HashMap<Vec<u64>, usize>,
        queue: &mut std::collections::VecDeque<(usize, Vec<u64>)>,
        node: u32,
        parent: Parent,
        mut t: Vec<u64>,
    ) {
        f.visits.push(Visit { node, parent });
        let id = f.visits.len() - 1;
        if self.holds(&b.to, &t) {
            record(
                f,
                self.tm.observer_range(&t),
                Witness {
                    visit: id,
                    last: None,
                    cycle: false,
                },
            );
            return;
        }
        self.tm.elapse(&mut t);
        if let std::collections::hash_map::Entry::Vacant(v) = seen.entry(t.clone()) {
            v.insert(id);
            queue.push_back((id, t));
        }
    }

    /// Why the wait in graph state `node` (zone `t`) may last forever: what it waits for.
    fn waits_for(&self, node: u32, t: &[u64]) -> String {
        let untimed = self.tm.untimed_running(t);
        if !untimed.is_empty() {
            let names: Vec<&str> = untimed
                .iter()
                .map(|&k| self.p.timers[k].name.as_str())
                .collect();
            return format!(
                "waits for timer {} (its duration is a parameter: not known statically)",
                names.join(", ")
            );
        }
        let mut events: Vec<&str> = Vec::new();
        for &e in &self.out_edges[node as usize] {
            let ev = self.g.labels[self.edges[e as usize].label as usize].event;
            let name = self.p.events[ev as usize].name.as_str();
            if !events.contains(&name) {
                events.push(name);
            }
        }
        format!(
            "waits for {} (outside events: they may never come), no timer running",
            events.join(", ")
        )
    }

    /// The witness's path: the events up to and including the step where `from` happened,
    /// then those after it (ending with the step where `to` happened, if it did), and the
    /// graph states met after `from` (one more than those events when `to` did not happen).
    fn path(&self, f: &Found, w: Witness) -> (Trace, Trace, Vec<u32>) {
        let text = |l: u32| self.g.labels[l as usize].text.clone();
        let mut then: Trace = w.last.map(text).into_iter().collect();
        let mut nodes = Vec::new();
        let mut v = w.visit;
        loop {
            nodes.push(f.visits[v].node);
            match f.visits[v].parent {
                Parent::Step { prev, label } => {
                    then.push(text(label));
                    v = prev;
                }
                Parent::From { source, label } => {
                    then.reverse();
                    nodes.reverse();
                    let mut trace = self.g.trace(source);
                    trace.extend(label.map(text));
                    return (trace, then, nodes);
                }
            }
        }
    }
}

/// `to` happened with the observer's clock in `[lo, hi]`.
fn record(f: &mut Found, (lo, hi): (i64, i64), w: Witness) {
    f.min = Some(f.min.map_or(lo, |m| m.min(lo)));
    if f.max.is_none_or(|(m, _)| hi > m) {
        f.max = Some((hi, w));
    }
}

fn seconds(v: i64) -> f64 {
    v as f64 / 1000.0
}
