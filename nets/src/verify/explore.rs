//! The exploration: breadth first over the stable states, with the firing code the player
//! runs, every delivery the environment may make ([`super::env`]) from every state.
//!
//! It builds the graph the analyses read ([`Graph`]: the states with a parent pointer each, for
//! the shortest traces, and every edge with what fired on it) and collects on the way what a
//! single step shows: firings refused for safety, loops of immediate transitions, conflicts,
//! invariants broken.

use super::env::{
    deliveries, Delivery, Env, Gate, MayHold, Oracle, Requests, Truth, MAX_GUARD_RUNS,
};
use super::{ConflictFinding, LivelockFinding, Trace, UnsafeFinding, VerifyError, VerifyOptions};
use crate::compiled::{Arg, CompiledProject, EventId, FunctionId, Guard, NetId, ProgramId};
use crate::semantics::{Effects, Layout, Scratch, Semantics, State};
use petrel_value::Value;
use std::collections::HashMap;
use std::time::Instant;

/// How a stable state was first reached: the parent pointer of the shortest trace.
#[derive(Clone, Copy, Debug)]
pub(super) enum Via {
    Start,
    /// From state `.0` by the step labelled `.1`.
    Step(u32, u32),
    /// Single-net mode: from state `.0`, the environment marked or emptied a place that other
    /// nets change (the label `.1` says which).
    Env(u32, u32),
}

/// One step the environment can make happen: a delivery, with the outcomes of the guards the
/// verifier could not decide, and the counter of an answer or emission it consumes.
#[derive(Clone, Debug)]
pub(super) struct Label {
    pub text: String,
    pub event: EventId,
    pub delivery: u32,
    pub choices: Vec<bool>,
    pub counter: Option<u32>,
}

/// A place the environment changes in single-net mode (`--net`): a global place other nets
/// put a token in (`mark`) or take one from (`empty`), or a child's completion place (the
/// child is not modelled: it may finish at any time).
#[derive(Clone, Debug)]
pub(super) struct FreePlace {
    /// Its bit in the state.
    pub bit: u32,
    /// `global.place` or `NET.CHILD.done`.
    pub name: String,
    /// The environment may put a token in it when it is empty.
    pub mark: bool,
    /// The environment may take its token.
    pub empty: bool,
}

/// The event of a label that is no event: the environment changed a global place (`--net`).
pub(super) const NO_EVENT: EventId = EventId::MAX;

/// An edge of the graph: a step from one stable state to another (or the same).
#[derive(Clone, Copy, Debug)]
pub(super) struct Edge {
    pub from: u32,
    pub to: u32,
    pub label: u32,
    /// Index in [`Graph::fired_sets`] of the transitions (rules) that fired.
    pub fired: u32,
}

/// Everything the exploration found.
pub(super) struct Graph {
    pub states: Vec<State>,
    pub via: Vec<Via>,
    pub edges: Vec<Edge>,
    pub labels: Vec<Label>,
    pub fired_sets: Vec<Vec<u32>>,
    /// States where no delivery is possible.
    pub dead: Vec<u32>,
    pub deliveries: Vec<Delivery>,
    pub unsafe_places: Vec<UnsafeFinding>,
    pub livelocks: Vec<LivelockFinding>,
    pub conflicts: Vec<ConflictFinding>,
    pub ever_fired: Vec<bool>,
    pub ever_active: Vec<bool>,
    pub max_tokens_per_marking: u64,
    /// One net verified alone (`--net`): its end is to be inactive (it finished, or
    /// deactivated itself).
    pub alone: bool,
}

impl Graph {
    /// The shortest trace to state `s`.
    pub fn trace(&self, mut s: u32) -> Trace {
        let mut out = Vec::new();
        loop {
            match self.via[s as usize] {
                Via::Start => break,
                Via::Step(prev, l) => {
                    out.push(self.labels[l as usize].text.clone());
                    s = prev;
                }
                Via::Env(prev, l) => {
                    out.push(self.labels[l as usize].text.clone());
                    s = prev;
                }
            }
        }
        out.reverse();
        out
    }

    /// The steps (labels) of the shortest trace to `s`, `None` where the environment changed a
    /// global place.
    pub fn steps(&self, mut s: u32) -> Vec<Option<u32>> {
        let mut out = Vec::new();
        loop {
            match self.via[s as usize] {
                Via::Start => break,
                Via::Step(prev, l) => {
                    out.push(Some(l));
                    s = prev;
                }
                Via::Env(prev, _) => {
                    out.push(None);
                    s = prev;
                }
            }
        }
        out.reverse();
        out
    }
}

/// Collects what one event step did, for the exploration.
#[derive(Default)]
pub(super) struct Recorder {
    /// The guards of the rules, and the parameters of the event being delivered.
    pub guards: Vec<Option<Guard>>,
    pub params: Vec<Value>,
    pub oracle: Oracle,
    pub fired: Vec<u32>,
    pub refused: Vec<(u32, u32)>,
    pub requests: Requests,
    /// States seen during the current fixpoint (with the number of immediate firings before
    /// each), to find cycles of immediate transitions.
    fixpoint_states: HashMap<State, usize>,
    fixpoint_rules: Vec<u32>,
    pub livelock: Option<Vec<u32>>,
}

impl Effects for Recorder {
    fn fired(&mut self, rule: u32) {
        self.fired.push(rule);
        self.fixpoint_rules.push(rule);
    }
    fn refused(&mut self, rule: u32, place: u32) {
        self.refused.push((rule, place));
    }
    fn call(&mut self, program: ProgramId, function: FunctionId, _args: &[Arg]) {
        self.requests.calls.push((program, function));
    }
    fn emit(&mut self, event: EventId, _args: &[Arg], target: Option<NetId>) {
        self.requests.emits.push((event, target));
    }
    fn immediate_step(&mut self, state: &[u64]) -> bool {
        if let Some(&at) = self.fixpoint_states.get(state) {
            // The immediate firings since that state form the cycle.
            let mut cycle = self.fixpoint_rules[at..].to_vec();
            // Start the cycle at its first transition in dispatch order, so it reads the same
            // whichever state the search entered it by.
            if let Some(first) = cycle
                .iter()
                .enumerate()
                .min_by_key(|(_, r)| **r)
                .map(|(i, _)| i)
            {
                cycle.rotate_left(first);
            }
            self.livelock = Some(cycle);
            return false;
        }
        self.fixpoint_states
            .insert(state.to_vec(), self.fixpoint_rules.len());
        true
    }
    fn livelock(&mut self) {
        if self.livelock.is_none() {
            self.livelock = Some(self.fixpoint_rules.clone());
        }
    }
    fn guard(&mut self, rule: u32) -> bool {
        let Some(Some(g)) = self.guards.get(rule as usize) else {
            return true;
        };
        match super::env::truth(g, &self.params) {
            Truth::True => true,
            Truth::False => false,
            Truth::Unknown => self.oracle.choose(),
        }
    }
}

impl Recorder {
    /// A recorder for rules whose guards are `guards`.
    pub fn with_guards(guards: Vec<Option<Guard>>) -> Self {
        Recorder {
            guards,
            ..Recorder::default()
        }
    }

    pub fn reset(&mut self) {
        self.oracle.used = 0;
        self.fired.clear();
        self.refused.clear();
        self.requests.clear();
        self.fixpoint_states.clear();
        self.fixpoint_rules.clear();
        self.livelock = None;
    }
}

/// Runs one step of `sem` from `state`: delivery `d` (the initial activation for `None`), with
/// the guards' undecided outcomes from `choices`, consuming `counter`. Returns the state after,
/// with the environment's counters updated.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_step(
    sem: &Semantics,
    env: &Env,
    rec: &mut Recorder,
    scratch: &mut Scratch,
    state: &[u64],
    d: Option<&Delivery>,
    choices: &[bool],
    counter: Option<u32>,
) -> State {
    rec.reset();
    rec.oracle.prefix = choices.to_vec();
    let mut t = match d {
        None => {
            rec.params.clear();
            let mut s = sem.initial(rec, scratch);
            s.resize(env.words, 0);
            s
        }
        Some(d) => {
            let mut t = state.to_vec();
            // A timer's event arriving is that timer expiring: it no longer runs.
            for (k, timer) in sem.project.timers.iter().enumerate() {
                if timer.event == d.event {
                    sem.timer_expired(&mut t, k as u32);
                }
            }
            if let Some(c) = counter {
                env.down(&mut t, c);
            }
            rec.params.clone_from(&d.params);
            sem.process_event(&mut t, d.event, d.target, rec, scratch);
            t
        }
    };
    env.apply(&mut t, &rec.requests);
    t
}

/// A state reached from the one being expanded, how, and the edge's label and fired set.
type Successor = (State, Via, Option<(u32, u32)>);

/// Explores every stable state of `p`.
pub(super) fn explore(
    p: &CompiledProject,
    sem: &Semantics,
    env: &Env,
    free: &[FreePlace],
    opts: &mut VerifyOptions,
    started: Instant,
    start: Option<&[u64]>,
) -> Result<Graph, VerifyError> {
    let l = &sem.layout;
    let mut scratch = Scratch::default();
    let guards: Vec<Option<Guard>> = l
        .rules
        .iter()
        .map(|r| {
            p.nets[r.net as usize].transitions[r.transition as usize]
                .guard
                .clone()
        })
        .collect();
    let mut rec = Recorder::with_guards(guards.clone());
    let name_of = |r: u32| {
        let rule = &l.rules[r as usize];
        let net = &p.nets[rule.net as usize];
        format!(
            "{}.{}",
            net.name, net.transitions[rule.transition as usize].name
        )
    };
    let deliveries = deliveries(p, l)?;
    let mut g = Graph {
        states: Vec::new(),
        via: Vec::new(),
        edges: Vec::new(),
        labels: Vec::new(),
        fired_sets: Vec::new(),
        dead: Vec::new(),
        deliveries: Vec::new(),
        unsafe_places: Vec::new(),
        livelocks: Vec::new(),
        conflicts: Vec::new(),
        ever_fired: vec![false; l.rules.len()],
        ever_active: vec![false; p.nets.len()],
        max_tokens_per_marking: 0,
        alone: false,
    };
    // Keyed by delivery, guard outcomes, counter, and whether the delivery went unused.
    let mut label_ids: HashMap<(u32, Vec<bool>, Option<u32>, bool), u32> = HashMap::new();
    let mut fired_ids: HashMap<Vec<u32>, u32> = HashMap::new();
    let mut index: HashMap<State, u32> = HashMap::new();
    let mut unsafe_seen: HashMap<(u32, u32), ()> = HashMap::new();
    let mut conflict_seen: HashMap<(u32, u32), ()> = HashMap::new();
    let mut livelock_seen: HashMap<Vec<u32>, ()> = HashMap::new();

    // What one step showed, with the trace that led to it.
    let mut record = |g: &mut Graph, rec: &Recorder, trace: &dyn Fn(&Graph) -> Trace| {
        for &r in &rec.fired {
            g.ever_fired[r as usize] = true;
        }
        for &(r, place) in &rec.refused {
            if unsafe_seen.insert((r, place), ()).is_none() {
                g.unsafe_places.push(UnsafeFinding {
                    transition: name_of(r),
                    place: l.describe_bit(p, place),
                    trace: trace(g),
                });
            }
        }
        if let Some(cycle) = &rec.livelock {
            let mut key = cycle.clone();
            key.sort_unstable();
            if livelock_seen.insert(key, ()).is_none() {
                g.livelocks.push(LivelockFinding {
                    transitions: cycle.iter().map(|&r| name_of(r)).collect(),
                    trace: trace(g),
                });
            }
        }
    };

    // The initial states: the given one (a reload's), or one per outcome of the guards the
    // start cannot decide.
    if let Some(from) = start {
        let mut t = from.to_vec();
        t.resize(env.words, 0);
        env.saturate(&mut t);
        index.insert(t.clone(), 0);
        g.states.push(t);
        g.via.push(Via::Start);
    }
    let mut prefixes: Vec<Vec<bool>> = if start.is_some() {
        Vec::new()
    } else {
        vec![Vec::new()]
    };
    let mut runs = 0usize;
    while let Some(prefix) = prefixes.pop() {
        runs += 1;
        if runs > MAX_GUARD_RUNS {
            return Err(VerifyError::TooManyUndecidedGuards {
                event: "(start)".into(),
            });
        }
        let initial = run_step(sem, env, &mut rec, &mut scratch, &[], None, &prefix, None);
        record(&mut g, &rec, &|_| Vec::new());
        Oracle::next_prefixes(&prefix, rec.oracle.used, &mut prefixes);
        if !index.contains_key(&initial) {
            index.insert(initial.clone(), g.states.len() as u32);
            g.states.push(initial);
            g.via.push(Via::Start);
        }
    }

    let mut last_progress = Instant::now();
    let mut next = 0usize;
    let mut candidates = Vec::new();
    while next < g.states.len() {
        let i = next as u32;
        next += 1;
        if let Some(cb) = opts.progress.as_mut() {
            if last_progress.elapsed().as_secs_f64() >= 1.0 {
                last_progress = Instant::now();
                let secs = started.elapsed().as_secs_f64();
                cb(
                    g.states.len() as u64,
                    g.states.len() as f64 / secs.max(1e-9),
                );
            }
        }
        let s = g.states[i as usize].clone();
        for (n, seen) in g.ever_active.iter_mut().enumerate() {
            *seen |= l.is_active(&s, n as NetId);
        }
        g.max_tokens_per_marking = g.max_tokens_per_marking.max(l.tokens(&s) as u64);
        let mut successors: Vec<Successor> = Vec::new();
        let mut any_enabled = false;
        if !l.is_over(&s) {
            for (di, d) in deliveries.iter().enumerate() {
                let counters: Vec<Option<u32>> = match env.gate(&s, d.event, d.target) {
                    Gate::Closed => continue,
                    Gate::Free => vec![None],
                    Gate::Counters(list) => list.into_iter().map(Some).collect(),
                };
                sem.candidates(
                    &s,
                    d.event,
                    d.target,
                    &mut MayHold {
                        guards: &guards,
                        params: &d.params,
                    },
                    &mut candidates,
                );
                if candidates.is_empty() {
                    // No transition takes it here. A free event then changes nothing (the
                    // player counts it unused), but a pending answer or emission is consumed
                    // all the same: the player takes it from its queue, finds no candidate
                    // and drops it (docs/semantics.md, "Processing one event", step 5). The
                    // verifier must not let it wait for a consumer that may come later.
                    for counter in counters.into_iter().flatten() {
                        let t = run_step(
                            sem,
                            env,
                            &mut rec,
                            &mut scratch,
                            &s,
                            Some(d),
                            &[],
                            Some(counter),
                        );
                        if t == s {
                            // A counter at "many" stays there: nothing happened.
                            continue;
                        }
                        // The player still has this event to process: not a dead marking.
                        any_enabled = true;
                        let key = (di as u32, vec![], Some(counter), true);
                        let lid = match label_ids.get(&key) {
                            Some(&l) => l,
                            None => {
                                g.labels.push(Label {
                                    text: format!("{} (unused)", d.label),
                                    event: d.event,
                                    delivery: di as u32,
                                    choices: Vec::new(),
                                    counter: Some(counter),
                                });
                                let l = (g.labels.len() - 1) as u32;
                                label_ids.insert(key, l);
                                l
                            }
                        };
                        let fid = match fired_ids.get(&Vec::new()) {
                            Some(&f) => f,
                            None => {
                                g.fired_sets.push(Vec::new());
                                let f = (g.fired_sets.len() - 1) as u32;
                                fired_ids.insert(Vec::new(), f);
                                f
                            }
                        };
                        successors.push((t, Via::Step(i, lid), Some((lid, fid))));
                    }
                    continue;
                }
                any_enabled = true;
                for (a, &ra) in candidates.iter().enumerate() {
                    for &rb in &candidates[a + 1..] {
                        if l.share_input(ra, rb) && conflict_seen.insert((ra, rb), ()).is_none() {
                            let mut trace = g.trace(i);
                            trace.push(d.label.clone());
                            g.conflicts.push(ConflictFinding {
                                event: p.events[d.event as usize].name.clone(),
                                winner: name_of(ra),
                                loser: name_of(rb),
                                trace,
                            });
                        }
                    }
                }
                for counter in counters {
                    // Every outcome of the guards this delivery cannot decide.
                    let mut prefixes: Vec<Vec<bool>> = vec![Vec::new()];
                    let mut runs = 0usize;
                    while let Some(prefix) = prefixes.pop() {
                        runs += 1;
                        if runs > MAX_GUARD_RUNS {
                            return Err(VerifyError::TooManyUndecidedGuards {
                                event: p.events[d.event as usize].name.clone(),
                            });
                        }
                        let t = run_step(
                            sem,
                            env,
                            &mut rec,
                            &mut scratch,
                            &s,
                            Some(d),
                            &prefix,
                            counter,
                        );
                        Oracle::next_prefixes(&prefix, rec.oracle.used, &mut prefixes);
                        let choices: Vec<bool> = (0..rec.oracle.used)
                            .map(|k| prefix.get(k).copied().unwrap_or(false))
                            .collect();
                        let key = (di as u32, choices.clone(), counter, false);
                        let lid = match label_ids.get(&key) {
                            Some(&l) => l,
                            None => {
                                let mut text = d.label.clone();
                                if !choices.is_empty() {
                                    let taken: Vec<&str> = choices
                                        .iter()
                                        .map(|c| if *c { "true" } else { "false" })
                                        .collect();
                                    text = format!(
                                        "{text} (undecided guards taken {})",
                                        taken.join(", ")
                                    );
                                }
                                g.labels.push(Label {
                                    text,
                                    event: d.event,
                                    delivery: di as u32,
                                    choices,
                                    counter,
                                });
                                let l = (g.labels.len() - 1) as u32;
                                label_ids.insert(key, l);
                                l
                            }
                        };
                        let mut fired = rec.fired.clone();
                        fired.sort_unstable();
                        fired.dedup();
                        let fid = match fired_ids.get(&fired) {
                            Some(&f) => f,
                            None => {
                                g.fired_sets.push(fired.clone());
                                let f = (g.fired_sets.len() - 1) as u32;
                                fired_ids.insert(fired, f);
                                f
                            }
                        };
                        let text = g.labels[lid as usize].text.clone();
                        record(&mut g, &rec, &|g| {
                            let mut t = g.trace(i);
                            t.push(text.clone());
                            t
                        });
                        successors.push((t, Via::Step(i, lid), Some((lid, fid))));
                    }
                }
            }
        }
        for (k, f) in free.iter().enumerate() {
            let set = !Layout::bit(&s, f.bit);
            if (set && !f.mark) || (!set && !f.empty) {
                continue;
            }
            // A state the environment can still change is not dead: whether the net can go on
            // from it is the stuck-net check's question.
            any_enabled = true;
            let mut t = s.clone();
            t[(f.bit / 64) as usize] ^= 1 << (f.bit % 64);
            // The environment's change may enable immediate transitions.
            rec.reset();
            rec.params.clear();
            rec.oracle.prefix.clear();
            sem.fixpoint(&mut t, &mut rec, &mut scratch);
            env.apply(&mut t, &rec.requests);
            record(&mut g, &rec, &|g| g.trace(i));
            // An edge like the others, labelled with the environment's move (no event).
            let key = (u32::MAX - k as u32, vec![set], None, false);
            let lid = *label_ids.entry(key).or_insert_with(|| {
                g.labels.push(Label {
                    text: format!(
                        "environment {} {}",
                        if set { "marks" } else { "empties" },
                        f.name
                    ),
                    event: NO_EVENT,
                    delivery: u32::MAX,
                    choices: Vec::new(),
                    counter: None,
                });
                (g.labels.len() - 1) as u32
            });
            let mut fired = rec.fired.clone();
            fired.sort_unstable();
            fired.dedup();
            let fid = *fired_ids.entry(fired.clone()).or_insert_with(|| {
                g.fired_sets.push(fired);
                (g.fired_sets.len() - 1) as u32
            });
            successors.push((t, Via::Env(i, lid), Some((lid, fid))));
        }
        for (t, how, step) in successors {
            let j = match index.get(&t) {
                Some(&j) => j,
                None => {
                    let j = g.states.len() as u32;
                    if let Some(limit) = opts.max_states {
                        if j as u64 >= limit {
                            return Err(VerifyError::TooManyStates { limit });
                        }
                    }
                    index.insert(t.clone(), j);
                    g.states.push(t);
                    g.via.push(how);
                    j
                }
            };
            if let Some((label, fired)) = step {
                g.edges.push(super::explore::Edge {
                    from: i,
                    to: j,
                    label,
                    fired,
                });
            }
        }
        if !any_enabled {
            g.dead.push(i);
        }
    }
    g.deliveries = deliveries;
    Ok(g)
}
