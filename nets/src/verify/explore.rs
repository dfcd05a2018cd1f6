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
use super::store::StateStore;
use super::timed::{TimerOps, Timing};
use super::{ConflictFinding, LivelockFinding, Trace, UnsafeFinding, VerifyError, VerifyOptions};
use crate::compiled::{
    Arg, CompiledProject, EventId, FunctionId, Guard, NetId, ProgramId, TimerDuration, TimerId,
};
use crate::model::Category;
use crate::semantics::{Effects, Layout, Scratch, Semantics, State};
use petrel_value::Value;
use std::collections::{HashMap, HashSet};
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
    pub states: StateStore,
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
    /// States expanded with one component's deliveries only (partial-order reduction): when
    /// there are any, the graph holds only some of the reachable states.
    pub reduced: u64,
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
    /// The timers the step started (with their duration) or cancelled, in order.
    pub timer_ops: TimerOps,
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
    fn start_timer(&mut self, timer: TimerId, after: &TimerDuration) {
        self.timer_ops.push((timer, Some(after.clone())));
    }
    fn cancel_timer(&mut self, timer: TimerId) {
        self.timer_ops.push((timer, None));
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
        self.timer_ops.clear();
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

/// A delivery the environment can make in a state: which one, the counters it may consume
/// (`None`: a free event), and whether no transition takes it (a pending event, dropped).
struct Move {
    delivery: usize,
    counters: Vec<Option<u32>>,
    dropped: bool,
}

/// What the exploration keeps besides the graph: the firing code, the environment, and what
/// was already reported or labelled.
struct Ctx<'a> {
    p: &'a CompiledProject,
    sem: &'a Semantics<'a>,
    env: &'a Env,
    deliveries: Vec<Delivery>,
    guards: Vec<Option<Guard>>,
    rec: Recorder,
    scratch: Scratch,
    candidates: Vec<u32>,
    /// Keyed by delivery, guard outcomes, counter, and whether the delivery went unused.
    label_ids: HashMap<(u32, Vec<bool>, Option<u32>, bool), u32>,
    fired_ids: HashMap<Vec<u32>, u32>,
    unsafe_seen: HashSet<(u32, u32)>,
    conflict_seen: HashSet<(u32, u32)>,
    livelock_seen: HashSet<Vec<u32>>,
    /// Timed exploration: the zone beside each state, and each delivery's timer (the one
    /// whose expiry it is, when its event is a timer's and comes from nowhere else).
    timing: Option<Timing>,
    timer_of: Vec<Option<usize>>,
}

impl Ctx<'_> {
    fn name_of(&self, r: u32) -> String {
        let l = &self.sem.layout;
        let rule = &l.rules[r as usize];
        let net = &self.p.nets[rule.net as usize];
        format!(
            "{}.{}",
            net.name, net.transitions[rule.transition as usize].name
        )
    }

    /// What the last step showed, with the trace that led to it.
    fn record(&mut self, g: &mut Graph, trace: &dyn Fn(&Graph) -> Trace) {
        for &r in &self.rec.fired {
            g.ever_fired[r as usize] = true;
        }
        for k in 0..self.rec.refused.len() {
            let (r, place) = self.rec.refused[k];
            if self.unsafe_seen.insert((r, place)) {
                g.unsafe_places.push(UnsafeFinding {
                    transition: self.name_of(r),
                    place: self.sem.layout.describe_bit(self.p, place),
                    trace: trace(g),
                });
            }
        }
        if let Some(cycle) = self.rec.livelock.clone() {
            let mut key = cycle.clone();
            key.sort_unstable();
            if self.livelock_seen.insert(key) {
                g.livelocks.push(LivelockFinding {
                    transitions: cycle.iter().map(|&r| self.name_of(r)).collect(),
                    trace: trace(g),
                });
            }
        }
    }

    fn label(
        &mut self,
        g: &mut Graph,
        key: (u32, Vec<bool>, Option<u32>, bool),
        make: impl FnOnce() -> Label,
    ) -> u32 {
        *self.label_ids.entry(key).or_insert_with(|| {
            g.labels.push(make());
            (g.labels.len() - 1) as u32
        })
    }

    /// The set of transitions the last step fired, as an index into `g.fired_sets`.
    fn fired_set(&mut self, g: &mut Graph) -> u32 {
        let mut fired = self.rec.fired.clone();
        fired.sort_unstable();
        fired.dedup();
        *self.fired_ids.entry(fired).or_insert_with_key(|f| {
            g.fired_sets.push(f.clone());
            (g.fired_sets.len() - 1) as u32
        })
    }

    /// The deliveries the environment can make in state `i` (`s`), and the conflicts they
    /// show.
    fn moves(&mut self, g: &mut Graph, i: u32, s: &[u64], out: &mut Vec<Move>) {
        out.clear();
        for di in 0..self.deliveries.len() {
            let d = &self.deliveries[di];
            let gate = self.env.gate(s, d.event, d.target);
            // Timed: a timer's event comes when its clock reaches its duration, and only then.
            let timer = match (&self.timing, &gate) {
                (Some(tm), Gate::Free) => match self.timer_of[di] {
                    Some(k) if d.target.is_none() => {
                        if !tm.may_expire(&self.sem.layout, s, k) {
                            continue;
                        }
                        Some(k)
                    }
                    Some(_) => continue,
                    None => None,
                },
                _ => None,
            };
            let counters: Vec<Option<u32>> = match gate {
                Gate::Closed => continue,
                Gate::Free => vec![None],
                Gate::Counters(list) => list.into_iter().map(Some).collect(),
            };
            self.sem.candidates(
                s,
                d.event,
                d.target,
                &mut MayHold {
                    guards: &self.guards,
                    params: &d.params,
                },
                &mut self.candidates,
            );
            if self.candidates.is_empty() {
                // No transition takes it here. A free event then changes nothing (the player
                // counts it unused), but a pending answer or emission is consumed all the
                // same: the player takes it from its queue, finds no candidate and drops it
                // (docs/semantics.md, "Processing one event", step 5). The verifier must not
                // let it wait for a consumer that may come later. A counter at "many" stays
                // there: that drop changes nothing.
                // Timed, an expiry nobody takes still stops its timer: time could not pass
                // its deadline otherwise.
                let once: Vec<Option<u32>> = counters
                    .into_iter()
                    .filter(|c| timer.is_some() || c.is_some_and(|c| self.env.is_once(s, c)))
                    .collect();
                if !once.is_empty() {
                    out.push(Move {
                        delivery: di,
                        counters: once,
                        dropped: true,
                    });
                }
                continue;
            }
            for a in 0..self.candidates.len() {
                let ra = self.candidates[a];
                for b in a + 1..self.candidates.len() {
                    let rb = self.candidates[b];
                    if self.sem.layout.share_input(ra, rb) && self.conflict_seen.insert((ra, rb)) {
                        let mut trace = g.trace(i);
                        trace.push(self.deliveries[di].label.clone());
                        g.conflicts.push(ConflictFinding {
                            event: self.p.events[self.deliveries[di].event as usize]
                                .name
                                .clone(),
                            winner: self.name_of(ra),
                            loser: self.name_of(rb),
                            trace,
                        });
                    }
                }
            }
            out.push(Move {
                delivery: di,
                counters,
                dropped: false,
            });
        }
    }

    /// Runs move `m` from state `i` (`s`): one step per counter and per outcome of the guards
    /// it cannot decide.
    fn run(
        &mut self,
        g: &mut Graph,
        i: u32,
        s: &[u64],
        m: &Move,
        out: &mut Vec<Successor>,
    ) -> Result<(), VerifyError> {
        let di = m.delivery;
        for &counter in &m.counters {
            if m.dropped {
                let d = &self.deliveries[di];
                let mut t = run_step(
                    self.sem,
                    self.env,
                    &mut self.rec,
                    &mut self.scratch,
                    s,
                    Some(d),
                    &[],
                    counter,
                );
                if let Some(tm) = &self.timing {
                    let k = if counter.is_none() {
                        self.timer_of[di]
                    } else {
                        None
                    };
                    tm.step(&self.sem.layout, &mut t, k, &self.rec.timer_ops);
                }
                let (label, event) = (format!("{} (unused)", d.label), d.event);
                let lid = self.label(g, (di as u32, Vec::new(), counter, true), || Label {
                    text: label,
                    event,
                    delivery: di as u32,
                    choices: Vec::new(),
                    counter,
                });
                let fid = self.fired_set(g);
                out.push((t, Via::Step(i, lid), Some((lid, fid))));
                continue;
            }
            // Every outcome of the guards this delivery cannot decide.
            let mut prefixes: Vec<Vec<bool>> = vec![Vec::new()];
            let mut runs = 0usize;
            while let Some(prefix) = prefixes.pop() {
                runs += 1;
                let d = &self.deliveries[di];
                if runs > MAX_GUARD_RUNS {
                    return Err(VerifyError::TooManyUndecidedGuards {
                        event: self.p.events[d.event as usize].name.clone(),
                    });
                }
                let mut t = run_step(
                    self.sem,
                    self.env,
                    &mut self.rec,
                    &mut self.scratch,
                    s,
                    Some(d),
                    &prefix,
                    counter,
                );
                if let Some(tm) = &self.timing {
                    let k = if counter.is_none() {
                        self.timer_of[di]
                    } else {
                        None
                    };
                    tm.step(&self.sem.layout, &mut t, k, &self.rec.timer_ops);
                }
                Oracle::next_prefixes(&prefix, self.rec.oracle.used, &mut prefixes);
                let choices: Vec<bool> = (0..self.rec.oracle.used)
                    .map(|k| prefix.get(k).copied().unwrap_or(false))
                    .collect();
                let (base, event) = (d.label.clone(), d.event);
                let lid = self.label(g, (di as u32, choices.clone(), counter, false), || {
                    let mut text = base;
                    if !choices.is_empty() {
                        let taken: Vec<&str> = choices
                            .iter()
                            .map(|c| if *c { "true" } else { "false" })
                            .collect();
                        text = format!("{text} (undecided guards taken {})", taken.join(", "));
                    }
                    Label {
                        text,
                        event,
                        delivery: di as u32,
                        choices,
                        counter,
                    }
                });
                let fid = self.fired_set(g);
                let text = g.labels[lid as usize].text.clone();
                self.record(g, &|g| {
                    let mut t = g.trace(i);
                    t.push(text.clone());
                    t
                });
                out.push((t, Via::Step(i, lid), Some((lid, fid))));
            }
        }
        Ok(())
    }
}

/// Explores every stable state of `p` (with `reduce`, a subset that keeps what
/// [`super::reduction`] says).
#[allow(clippy::too_many_arguments)]
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
    let guards: Vec<Option<Guard>> = l
        .rules
        .iter()
        .map(|r| {
            p.nets[r.net as usize].transitions[r.transition as usize]
                .guard
                .clone()
        })
        .collect();
    let deliveries = deliveries(p, l)?;
    let timing = opts.timed.then(|| Timing::new(p, env.words));
    let timer_of: Vec<Option<usize>> = deliveries
        .iter()
        .map(|d| Timing::timer_of(p, d.event))
        .collect();
    let words = timing.as_ref().map_or(env.words, Timing::words);
    let mut ctx = Ctx {
        p,
        sem,
        env,
        deliveries,
        timing,
        timer_of,
        rec: Recorder::with_guards(guards.clone()),
        guards,
        scratch: Scratch::default(),
        candidates: Vec::new(),
        label_ids: HashMap::new(),
        fired_ids: HashMap::new(),
        unsafe_seen: HashSet::new(),
        conflict_seen: HashSet::new(),
        livelock_seen: HashSet::new(),
    };
    let mut g = Graph {
        states: StateStore::new(words),
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
        reduced: 0,
    };
    // Breadth-first depth of each state, and whether it was (or must be) expanded in full:
    // the cycle proviso of the reduction.
    let mut depth: Vec<u32> = Vec::new();
    let mut full: Vec<bool> = Vec::new();
    let mut must_full: Vec<bool> = Vec::new();

    // The initial states: the given one (a reload's), or one per outcome of the guards the
    // start cannot decide.
    if let Some(from) = start {
        let mut t = from.to_vec();
        t.resize(env.words, 0);
        env.saturate(&mut t);
        if let Some(tm) = &ctx.timing {
            tm.init(l, &mut t);
            tm.step(l, &mut t, None, &TimerOps::new());
        }
        g.states.push(&t);
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
        let mut initial = run_step(
            sem,
            env,
            &mut ctx.rec,
            &mut ctx.scratch,
            &[],
            None,
            &prefix,
            None,
        );
        if let Some(tm) = &ctx.timing {
            tm.init(l, &mut initial);
            tm.step(l, &mut initial, None, &ctx.rec.timer_ops);
        }
        ctx.record(&mut g, &|_| Vec::new());
        Oracle::next_prefixes(&prefix, ctx.rec.oracle.used, &mut prefixes);
        if g.states.find(&initial).is_none() {
            g.states.push(&initial);
            g.via.push(Via::Start);
        }
    }
    depth.resize(g.states.len(), 0);
    full.resize(g.states.len(), false);
    // The initial states are expanded in full: the loops of each component come back to them.
    must_full.resize(g.states.len(), true);

    // The reduction: the component of each delivery (`None`: every component).
    // With catastrophic events counted on the way to an end, any component that can reach
    // one ends the mission: an end would no longer be one component's question.
    let ends_local = (p.finals.is_empty() && p.goals.is_empty())
        || p.progress_excludes.contains(&Category::Catastrophic);
    let counted = |di: usize, deliveries: &[Delivery]| {
        !p.progress_excludes
            .contains(&p.events[deliveries[di].event as usize].category)
    };
    // Timed, a delivery also depends on the clocks of every running timer: no reduction.
    let components = (!opts.no_reduction && !opts.timed && free.is_empty() && ends_local)
        .then(|| super::reduction::Components::new(p, l))
        .filter(|c| c.count > 1);
    let delivery_component: Vec<Option<u32>> = match &components {
        Some(c) => ctx
            .deliveries
            .iter()
            .map(|d| c.of_delivery(p, l, d))
            .collect(),
        None => Vec::new(),
    };

    let mut last_progress = Instant::now();
    let mut next = 0usize;
    let mut moves: Vec<Move> = Vec::new();
    let mut tried: Vec<Successor> = Vec::new();
    let mut order: Vec<u32> = Vec::new();
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
        let s = g.states[i as usize].to_vec();
        for (n, seen) in g.ever_active.iter_mut().enumerate() {
            *seen |= l.is_active(&s, n as NetId);
        }
        g.max_tokens_per_marking = g.max_tokens_per_marking.max(l.tokens(&s) as u64);
        let mut successors: Vec<Successor> = Vec::new();
        if l.is_over(&s) {
            moves.clear();
        } else {
            ctx.moves(&mut g, i, &s, &mut moves);
        }
        // A drop counts: the player still has that event to process.
        let mut any_enabled = !moves.is_empty();

        // One component's deliveries, when they make a persistent set (no catastrophic event
        // enabled: it touches everything) and pass the cycle proviso; else every delivery.
        let mut reduced = false;
        if components.is_some() && !must_full[i as usize] {
            order.clear();
            let mut global = false;
            for m in &moves {
                match delivery_component[m.delivery] {
                    None => global = true,
                    Some(c) => {
                        if !order.contains(&c) {
                            order.push(c);
                        }
                    }
                }
            }
            if !global && order.len() > 1 {
                // The component that moved last first: it tends to go round its own loop
                // back to a state expanded in full.
                let last = match g.via[i as usize] {
                    Via::Step(_, lid) => {
                        let dl = g.labels[lid as usize].delivery as usize;
                        delivery_component.get(dl).copied().flatten()
                    }
                    _ => None,
                };
                order.sort_unstable_by_key(|&c| (Some(c) != last, c));
                // A component whose deliveries all belong to categories progress does not count
                // on is no choice while others offer counted ones: the states it leads to would
                // hide the counted ways to an end.
                let any_counted = moves.iter().any(|m| counted(m.delivery, &ctx.deliveries));
                for &c in &order {
                    if any_counted
                        && !moves.iter().any(|m| {
                            delivery_component[m.delivery] == Some(c)
                                && counted(m.delivery, &ctx.deliveries)
                        })
                    {
                        continue;
                    }
                    tried.clear();
                    for m in moves
                        .iter()
                        .filter(|m| delivery_component[m.delivery] == Some(c))
                    {
                        ctx.run(&mut g, i, &s, m, &mut tried)?;
                    }
                    // The cycle proviso: every edge that does not go one level deeper ends
                    // in a state expanded in full (or that will be), so every loop of the
                    // reduced graph holds a state expanded in full and no component is
                    // ignored forever.
                    let ok = tried.iter().all(|(t, _, _)| match g.states.find(t) {
                        None => true,
                        Some(j) => {
                            depth[j as usize] > depth[i as usize]
                                || (j != i && (j > i || full[j as usize]))
                        }
                    });
                    if ok {
                        for (t, _, _) in &tried {
                            if let Some(j) = g.states.find(t) {
                                if j > i && depth[j as usize] <= depth[i as usize] {
                                    must_full[j as usize] = true;
                                }
                            }
                        }
                        successors.append(&mut tried);
                        reduced = true;
                        break;
                    }
                }
            }
        }
        if !reduced {
            for m in &moves {
                ctx.run(&mut g, i, &s, m, &mut successors)?;
            }
        } else {
            g.reduced += 1;
        }
        if components.is_some() && !ctx.livelock_seen.is_empty() {
            // A loop of immediate transitions leaves a state that is not stable: every later
            // step's fixpoint runs into it again, whatever component the step is of, and the
            // components are no longer independent. Explore again, in full.
            opts.no_reduction = true;
            let full = explore(p, sem, env, free, opts, started, start);
            opts.no_reduction = false;
            return full;
        }
        full[i as usize] = !reduced;

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
            ctx.rec.reset();
            ctx.rec.params.clear();
            ctx.rec.oracle.prefix.clear();
            sem.fixpoint(&mut t, &mut ctx.rec, &mut ctx.scratch);
            env.apply(&mut t, &ctx.rec.requests);
            if let Some(tm) = &ctx.timing {
                tm.step(l, &mut t, None, &ctx.rec.timer_ops);
            }
            ctx.record(&mut g, &|g| g.trace(i));
            // An edge like the others, labelled with the environment's move (no event).
            let name = f.name.clone();
            let lid = ctx.label(
                &mut g,
                (u32::MAX - k as u32, vec![set], None, false),
                || Label {
                    text: format!(
                        "environment {} {name}",
                        if set { "marks" } else { "empties" }
                    ),
                    event: NO_EVENT,
                    delivery: u32::MAX,
                    choices: Vec::new(),
                    counter: None,
                },
            );
            let fid = ctx.fired_set(&mut g);
            successors.push((t, Via::Env(i, lid), Some((lid, fid))));
        }
        for (t, how, step) in successors {
            let j = match g.states.find(&t) {
                Some(j) => j,
                None => {
                    let j = g.states.len() as u32;
                    if let Some(limit) = opts.max_states {
                        if j as u64 >= limit {
                            return Err(VerifyError::TooManyStates { limit });
                        }
                    }
                    g.states.push(&t);
                    g.via.push(how);
                    depth.push(depth[i as usize] + 1);
                    full.push(false);
                    must_full.push(false);
                    j
                }
            };
            if let Some((label, fired)) = step {
                g.edges.push(Edge {
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
    g.deliveries = ctx.deliveries;
    Ok(g)
}
