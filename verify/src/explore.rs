//! The exploration: breadth first over the stable states, with the firing code the player
//! runs, every delivery the environment may make ([`super::env`]) from every state.
//!
//! It builds the graph the analyses read ([`Graph`]: the states with a parent pointer each, for
//! the shortest traces, and every edge with what fired on it) and collects on the way what a
//! single step shows: firings refused for safety, loops of immediate transitions, conflicts,
//! invariants broken.

use super::cache::Cache;
use super::env::{
    deliveries, Delivery, Env, Gate, MayHold, Oracle, Requests, Truth, MAX_GUARD_RUNS,
};
use super::store::{FxMap, Packed, StateStore};
use super::timed::{TimerOps, Timing};
use super::{VerifyError, VerifyOptions};
use crate::report::{ConflictFinding, LivelockFinding, Trace, UnsafeFinding};
use petrel_nets::compiled::{
    Arg, CompiledProject, EventId, FunctionId, Guard, NetId, ProgramId, TimerDuration, TimerId,
};
use petrel_nets::model::Category;
use petrel_nets::semantics::{Effects, Layout, Scratch, Semantics, State};
use petrel_value::Value;
use std::collections::HashSet;
use std::ops::Range;
use std::time::Instant;

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

/// The step kind of a successor whose kind is not looked up yet.
const NO_KIND: u32 = u32::MAX;

/// Successors the transition cache may hold whatever the number of states.
const CACHE_ROOM: usize = 4096;

/// An edge of the graph from a given state: a step to another stable state (or the same),
/// and its step kind (an index in [`Graph::steps`]: its label and fired set).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Edge {
    pub to: u32,
    pub kind: u32,
}

/// Everything the exploration found.
///
/// The graph is kept compact (docs/benchmarks.md, "What the full exploration costs per
/// state"): the states packed in a [`StateStore`]; one parent pointer per state (the state it
/// was first reached from and the label of that step), in [`Packed`] numbers; the edges grouped
/// by source state in state order (breadth first expands the states in order, so the source
/// is implicit), each a target and a step kind (a distinct label and fired set) in as few
/// bytes as their largest values need.
pub(super) struct Graph {
    pub states: StateStore,
    /// The state each state was first reached from, itself for an initial state.
    parent: Packed,
    /// The label of that step.
    parent_label: Packed,
    /// Where the edges of each state start in `edge_to` and `edge_step` (one more at the end),
    /// while they are kept ([`Graph::edges_kept`]).
    edge_start: Packed,
    edge_to: Packed,
    edge_step: Packed,
    /// Whether the edges are in memory; when not, an analysis that walks them recomputes each
    /// state's with [`Replay`].
    edges_kept: bool,
    /// How many edges (kept or not).
    edges: u64,
    /// The step kinds: (label, fired set) pairs the edges name.
    steps: Vec<(u32, u32)>,
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
    /// Components' moves the exploration took from the transition cache ([`super::cache`]).
    pub cache_hits: u64,
}

impl Graph {
    /// An empty graph of states of `words` words, for `rules` rules and `nets` nets.
    fn new(words: usize, rules: usize, nets: usize) -> Graph {
        Graph {
            states: StateStore::new(words),
            parent: Packed::new(),
            parent_label: Packed::new(),
            edge_start: Packed::new(),
            edge_to: Packed::new(),
            edge_step: Packed::new(),
            edges_kept: true,
            edges: 0,
            steps: Vec::new(),
            labels: Vec::new(),
            fired_sets: Vec::new(),
            dead: Vec::new(),
            deliveries: Vec::new(),
            unsafe_places: Vec::new(),
            livelocks: Vec::new(),
            conflicts: Vec::new(),
            ever_fired: vec![false; rules],
            ever_active: vec![false; nets],
            max_tokens_per_marking: 0,
            alone: false,
            reduced: 0,
            cache_hits: 0,
        }
    }

    /// The state `s` was first reached from and the label of that step; `None` for an initial
    /// state.
    pub fn parent(&self, s: u32) -> Option<(u32, u32)> {
        let p = self.parent.get(s as usize) as u32;
        (p != s).then(|| (p, self.parent_label.get(s as usize) as u32))
    }

    /// How many edges.
    pub fn edge_count(&self) -> usize {
        self.edges as usize
    }

    /// Whether the edges are kept in memory (else [`Edges`] replays them).
    pub fn edges_kept(&self) -> bool {
        self.edges_kept
    }

    /// The kept edges of state `i` (target, step kind), in the order the exploration found
    /// them, appended to `out`.
    pub fn kept_edges(&self, i: u32, out: &mut Vec<Edge>) {
        debug_assert!(self.edges_kept);
        let range =
            self.edge_start.get(i as usize) as usize..self.edge_start.get(i as usize + 1) as usize;
        out.extend(range.map(|k| Edge {
            to: self.edge_to.get(k) as u32,
            kind: self.edge_step.get(k) as u32,
        }));
    }

    /// Forgets the edges kept so far and keeps none from now on: the analyses will replay
    /// them.
    fn drop_edges(&mut self) {
        self.edges_kept = false;
        self.edge_start = Packed::new();
        self.edge_to = Packed::new();
        self.edge_step = Packed::new();
    }

    /// The step kinds, (label, fired set), that edges name ([`Edge::kind`]).
    pub fn steps(&self) -> &[(u32, u32)] {
        &self.steps
    }

    /// The label of step kind `kind`.
    #[inline]
    pub fn label_of(&self, kind: u32) -> u32 {
        self.steps[kind as usize].0
    }

    /// The bytes the states, parent pointers and edges hold (docs/benchmarks.md).
    pub fn heap_bytes(&self) -> usize {
        self.states.heap_bytes()
            + self.parent.heap_bytes()
            + self.parent_label.heap_bytes()
            + self.edge_start.heap_bytes()
            + self.edge_to.heap_bytes()
            + self.edge_step.heap_bytes()
    }

    /// The shortest trace to state `s`.
    pub fn trace(&self, s: u32) -> Trace {
        // Its length first, so that the trace is allocated once: Redermor reports thousands
        // of dead markings, each with its trace (docs/benchmarks.md).
        let mut len = 0;
        let mut x = s;
        while let Some((prev, _)) = self.parent(x) {
            len += 1;
            x = prev;
        }
        let mut out = vec![String::new(); len];
        let mut x = s;
        while let Some((prev, l)) = self.parent(x) {
            len -= 1;
            out[len].clone_from(&self.labels[l as usize].text);
            x = prev;
        }
        out
    }

    /// The steps (labels) of the shortest trace to `s`, `None` where the environment changed a
    /// global place.
    pub fn trace_steps(&self, mut s: u32) -> Vec<Option<u32>> {
        let mut out = Vec::new();
        while let Some((prev, l)) = self.parent(s) {
            out.push((self.labels[l as usize].event != NO_EVENT).then_some(l));
            s = prev;
        }
        out.reverse();
        out
    }

    /// The initial state the shortest trace to `s` starts from.
    pub fn root(&self, mut s: u32) -> u32 {
        while let Some((prev, _)) = self.parent(s) {
            s = prev;
        }
        s
    }

    fn push_state(&mut self, t: &[u64], parent: Option<(u32, u32)>) -> u32 {
        let j = self.states.push(t);
        let (p, l) = parent.unwrap_or((j, 0));
        self.parent.push(u64::from(p));
        self.parent_label.push(u64::from(l));
        j
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
    /// each), to find cycles of immediate transitions: the first few one after the other in
    /// `fixpoint_seen` (a fixpoint fires a few immediate transitions, and a `Vec` per state
    /// was an allocation per immediate firing), the others in `fixpoint_states`.
    fixpoint_seen: Vec<u64>,
    fixpoint_at: Vec<usize>,
    fixpoint_states: FxMap<State, usize>,
    fixpoint_rules: Vec<u32>,
    pub livelock: Option<Vec<u32>>,
    /// The timers the step started (with their duration) or cancelled, in order.
    pub timer_ops: TimerOps,
}

/// States of a fixpoint compared one by one before they go to a hash map.
const FIXPOINT_LISTED: usize = 16;

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
        let w = state.len().max(1);
        let seen = self
            .fixpoint_seen
            .chunks_exact(w)
            .position(|x| x == state)
            .map(|k| self.fixpoint_at[k])
            .or_else(|| {
                (!self.fixpoint_states.is_empty())
                    .then(|| self.fixpoint_states.get(state).copied())
                    .flatten()
            });
        if let Some(at) = seen {
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
        if self.fixpoint_at.len() < FIXPOINT_LISTED {
            self.fixpoint_seen.extend_from_slice(state);
            self.fixpoint_at.push(self.fixpoint_rules.len());
        } else {
            self.fixpoint_states
                .insert(state.to_vec(), self.fixpoint_rules.len());
        }
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
        self.fixpoint_seen.clear();
        self.fixpoint_at.clear();
        // Clearing a map that held states once writes its whole table again: only when needed.
        if !self.fixpoint_states.is_empty() {
            self.fixpoint_states.clear();
        }
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
    let mut t = State::new();
    run_step_into(sem, env, rec, scratch, state, d, choices, counter, &mut t);
    t
}

/// [`run_step`] into `t` (whatever it held), which keeps its allocation: the exploration runs
/// one step per edge.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_step_into(
    sem: &Semantics,
    env: &Env,
    rec: &mut Recorder,
    scratch: &mut Scratch,
    state: &[u64],
    d: Option<&Delivery>,
    choices: &[bool],
    counter: Option<u32>,
    t: &mut State,
) {
    rec.reset();
    rec.oracle.prefix.clear();
    rec.oracle.prefix.extend_from_slice(choices);
    match d {
        None => {
            rec.params.clear();
            *t = sem.initial(rec, scratch);
            t.resize(env.words, 0);
        }
        Some(d) => {
            t.clear();
            t.extend_from_slice(state);
            // A timer's event arriving is that timer expiring: it no longer runs.
            for (k, timer) in sem.project.timers.iter().enumerate() {
                if timer.event == d.event {
                    sem.timer_expired(t, k as u32);
                }
            }
            if let Some(c) = counter {
                env.down(t, c);
            }
            rec.params.clone_from(&d.params);
            sem.process_event(t, d.event, d.target, rec, scratch);
        }
    }
    env.apply(t, &rec.requests);
}

/// The states reached from the one being expanded, one after the other in one vector, each
/// with its edge's label and fired set: no vector per successor (an allocation per edge cost a
/// tenth of the exploration, docs/benchmarks.md).
pub(super) struct Successors {
    words: usize,
    data: Vec<u64>,
    /// Label, fired set and step kind of each (the kind `NO_KIND` until it is known).
    meta: Vec<(u32, u32, u32)>,
}

impl Successors {
    fn new(words: usize) -> Successors {
        Successors {
            words: words.max(1),
            data: Vec::new(),
            meta: Vec::new(),
        }
    }

    fn clear(&mut self) {
        self.data.clear();
        self.meta.clear();
    }

    fn push(&mut self, t: &[u64], label: u32, fired: u32) {
        debug_assert_eq!(t.len(), self.words);
        self.data.extend_from_slice(t);
        self.meta.push((label, fired, NO_KIND));
    }

    fn states(&self) -> std::slice::ChunksExact<'_, u64> {
        self.data.chunks_exact(self.words)
    }

    /// How many.
    fn len(&self) -> usize {
        self.meta.len()
    }

    /// Successor `k`.
    fn state(&self, k: usize) -> &[u64] {
        &self.data[k * self.words..(k + 1) * self.words]
    }

    /// Adds `s` with the bits of `mask` taken from `local`: a successor from the cache.
    #[inline]
    fn push_masked(&mut self, s: &[u64], mask: &[u64], local: &[u64], meta: (u32, u32, u32)) {
        self.data.extend(
            s.iter()
                .zip(mask)
                .zip(local)
                .map(|((&a, &m), &b)| (a & !m) | b),
        );
        self.meta.push(meta);
    }

    fn append(&mut self, other: &mut Successors) {
        self.data.append(&mut other.data);
        self.meta.append(&mut other.meta);
    }
}

/// A delivery the environment can make in a state: which one, the counters it may consume
/// (`None`: a free event; a range of [`Moves::counters`]), and whether no transition takes it
/// (a pending event, dropped).
struct Move {
    delivery: usize,
    counters: Range<usize>,
    dropped: bool,
}

/// The moves of a state, their counters in one vector. (The candidates of each delivery,
/// computed here to list the moves, are computed again by its step: keeping them for the step
/// made the exploration slower, docs/benchmarks.md.)
#[derive(Default)]
struct Moves {
    list: Vec<Move>,
    counters: Vec<Option<u32>>,
}

/// What [`Ctx::expand`] reuses from one state to the next.
#[derive(Default)]
pub(super) struct Expansion {
    moves: Moves,
    /// Per component, its cache entry in this state; per delivery, whether a cache entry gives
    /// its moves; per component, the next cached successor to take, whether its moves here
    /// must not be stored, and the successors computed here (component, number in the
    /// successors, delivery).
    hit: Vec<Option<u32>>,
    skip: Vec<bool>,
    cursor: Vec<u32>,
    unstorable: Vec<bool>,
    computed: Vec<(u32, u32, u32)>,
}

/// The graph a state's expansion works on: the exploration's, which it adds labels, fired sets
/// and findings to, or a finished one whose edges are replayed (all of those known already).
enum At<'g> {
    Explore(&'g mut Graph),
    Replay(&'g Graph),
}

impl At<'_> {
    fn graph(&self) -> &Graph {
        match self {
            At::Explore(g) => g,
            At::Replay(g) => g,
        }
    }

    fn exploring(&mut self) -> Option<&mut Graph> {
        match self {
            At::Explore(g) => Some(g),
            At::Replay(_) => None,
        }
    }
}

/// What the exploration keeps besides the graph: the firing code, the environment, and what
/// was already reported or labelled. After the exploration, what replays a state's edges.
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
    label_ids: FxMap<(u32, Vec<bool>, Option<u32>, bool), u32>,
    fired_ids: FxMap<Vec<u32>, u32>,
    step_ids: FxMap<(u32, u32), u32>,
    /// The labels of keys with no undecided guard, looked up without comparing vectors: by
    /// delivery for a free event taken, else by the rest of the key.
    free_labels: Vec<u32>,
    plain_labels: FxMap<(u32, Option<u32>, bool), u32>,
    /// The fired sets of one rule (by rule) and of none, likewise.
    single_fired: Vec<u32>,
    no_fired: Option<u32>,
    /// The step kinds of a label with the fired set of no rule or of one rule, likewise
    /// (`u32::MAX` where none yet): by label, then by rule + 1.
    plain_steps: Vec<Vec<u32>>,
    /// The last step's fired set, sorted (reused).
    fired_buf: Vec<u32>,
    /// The state after the step being run, and the prefixes of undecided guards still to run
    /// (reused).
    next: State,
    prefixes: Vec<Vec<bool>>,
    unsafe_seen: HashSet<(u32, u32)>,
    conflict_seen: HashSet<(u32, u32)>,
    livelock_seen: HashSet<Vec<u32>>,
    /// Timed exploration: the zone beside each state, and each delivery's timer (the one
    /// whose expiry it is, when its event is a timer's and comes from nowhere else).
    timing: Option<Timing>,
    timer_of: Vec<Option<usize>>,
    /// The transition cache of the full exploration (none when timed, reducing, `--net`, or
    /// the nets make one component).
    cache: Option<Cache>,
    /// Whether a step since it was last cleared recorded something or asked the oracle (its
    /// component's moves are then not cached), and the deliveries whose conflicts the last
    /// [`Ctx::moves`] recorded.
    flagged: bool,
    conflicted: Vec<usize>,
}

/// The label, fired set or step kind a replay did not find: the exploration made them all, so
/// this is a replay that does not follow the exploration (a bug the cross-check test catches).
const NOT_REPLAYED: &str = "a replayed step is one the exploration made";

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

    /// The label of `key`, if there is one yet.
    fn known_label(&self, key: &(u32, Vec<bool>, Option<u32>, bool)) -> Option<u32> {
        if key.1.is_empty() && key.2.is_none() && !key.3 {
            self.free_labels
                .get(key.0 as usize)
                .copied()
                .filter(|&l| l != u32::MAX)
        } else if key.1.is_empty() {
            self.plain_labels.get(&(key.0, key.2, key.3)).copied()
        } else {
            self.label_ids.get(key).copied()
        }
    }

    /// The label of `key`, made by `make` the first time (looked up before the key is
    /// cloned: once per edge).
    fn label(
        &mut self,
        at: &mut At,
        key: (u32, Vec<bool>, Option<u32>, bool),
        make: impl FnOnce() -> Label,
    ) -> u32 {
        if let Some(l) = self.known_label(&key) {
            return l;
        }
        let g = at.exploring().expect(NOT_REPLAYED);
        g.labels.push(make());
        let l = (g.labels.len() - 1) as u32;
        if key.1.is_empty() && key.2.is_none() && !key.3 {
            if self.free_labels.len() <= key.0 as usize {
                self.free_labels.resize(key.0 as usize + 1, u32::MAX);
            }
            self.free_labels[key.0 as usize] = l;
        } else if key.1.is_empty() {
            self.plain_labels.insert((key.0, key.2, key.3), l);
        }
        self.label_ids.insert(key, l);
        l
    }

    /// The set of transitions the last step fired, as an index into `g.fired_sets`.
    fn fired_set(&mut self, at: &mut At) -> u32 {
        // Most steps fire one rule or none: looked up by index, not by a hashed vector.
        let fast = match self.rec.fired.as_slice() {
            [] => self.no_fired,
            &[r] => self
                .single_fired
                .get(r as usize)
                .copied()
                .filter(|&f| f != u32::MAX),
            _ => None,
        };
        if let Some(f) = fast {
            return f;
        }
        self.fired_buf.clear();
        self.fired_buf.extend_from_slice(&self.rec.fired);
        self.fired_buf.sort_unstable();
        self.fired_buf.dedup();
        let f = match self.fired_ids.get(self.fired_buf.as_slice()) {
            Some(&f) => f,
            None => {
                let g = at.exploring().expect(NOT_REPLAYED);
                g.fired_sets.push(self.fired_buf.clone());
                let f = (g.fired_sets.len() - 1) as u32;
                self.fired_ids.insert(self.fired_buf.clone(), f);
                f
            }
        };
        match self.rec.fired.as_slice() {
            [] => self.no_fired = Some(f),
            &[r] => {
                if self.single_fired.len() <= r as usize {
                    self.single_fired.resize(r as usize + 1, u32::MAX);
                }
                self.single_fired[r as usize] = f;
            }
            _ => {}
        }
        f
    }

    /// The step kind of an edge labelled `label` that fired set `fired`.
    fn step(&mut self, at: &mut At, label: u32, fired: u32) -> u32 {
        // By index when the fired set is none or one rule's (most edges), else hashed.
        let slot = match at.graph().fired_sets[fired as usize].as_slice() {
            [] => Some(0),
            &[r] => Some(r as usize + 1),
            _ => None,
        };
        if let Some(k) = slot {
            if let Some(&st) = self
                .plain_steps
                .get(label as usize)
                .and_then(|v| v.get(k))
                .filter(|&&st| st != u32::MAX)
            {
                return st;
            }
        }
        let st = match self.step_ids.get(&(label, fired)) {
            Some(&st) => st,
            None => {
                let g = at.exploring().expect(NOT_REPLAYED);
                g.steps.push((label, fired));
                let st = (g.steps.len() - 1) as u32;
                self.step_ids.insert((label, fired), st);
                st
            }
        };
        if let Some(k) = slot {
            if self.plain_steps.len() <= label as usize {
                self.plain_steps.resize(label as usize + 1, Vec::new());
            }
            let v = &mut self.plain_steps[label as usize];
            if v.len() <= k {
                v.resize(k + 1, u32::MAX);
            }
            v[k] = st;
        }
        st
    }

    /// The deliveries the environment can make in state `i` (`s`), but those `skip` says
    /// (none when it is empty), and the conflicts they show (while exploring).
    fn moves(&mut self, at: &mut At, i: u32, s: &[u64], skip: &[bool], out: &mut Moves) {
        out.list.clear();
        out.counters.clear();
        self.conflicted.clear();
        for di in 0..self.deliveries.len() {
            if skip.get(di).copied().unwrap_or(false) {
                continue;
            }
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
            let from = out.counters.len();
            match gate {
                Gate::Closed => continue,
                Gate::Free => out.counters.push(None),
                Gate::Counters(list) => out.counters.extend(list.into_iter().map(Some)),
            }
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
                let env = self.env;
                let mut kept = from;
                for k in from..out.counters.len() {
                    let c = out.counters[k];
                    if timer.is_some() || c.is_some_and(|c| env.is_once(s, c)) {
                        out.counters[kept] = c;
                        kept += 1;
                    }
                }
                out.counters.truncate(kept);
                if kept > from {
                    out.list.push(Move {
                        delivery: di,
                        counters: from..kept,
                        dropped: true,
                    });
                }
                continue;
            }
            if let Some(g) = at.exploring() {
                for a in 0..self.candidates.len() {
                    let ra = self.candidates[a];
                    for b in a + 1..self.candidates.len() {
                        let rb = self.candidates[b];
                        if self.sem.layout.share_input(ra, rb)
                            && self.conflict_seen.insert((ra, rb))
                        {
                            self.conflicted.push(di);
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
            }
            out.list.push(Move {
                delivery: di,
                counters: from..out.counters.len(),
                dropped: false,
            });
        }
    }

    /// Runs delivery `di` from `s` with the guards' choices `prefix` into `t`, then (timed
    /// exploration) advances the zone by the step's timer operations and, for a timer's expiry,
    /// by that timer: every successor of a move is made here.
    fn run_delivery(
        &mut self,
        s: &[u64],
        di: usize,
        prefix: &[bool],
        counter: Option<u32>,
        t: &mut State,
    ) {
        run_step_into(
            self.sem,
            self.env,
            &mut self.rec,
            &mut self.scratch,
            s,
            Some(&self.deliveries[di]),
            prefix,
            counter,
            t,
        );
        if let Some(tm) = &self.timing {
            let k = if counter.is_none() {
                self.timer_of[di]
            } else {
                None
            };
            tm.step(&self.sem.layout, t, k, &self.rec.timer_ops);
        }
    }

    /// Runs move `m` from state `i` (`s`): one step per counter (from `counters`) and per
    /// outcome of the guards it cannot decide.
    #[allow(clippy::too_many_arguments)]
    fn run(
        &mut self,
        at: &mut At,
        i: u32,
        s: &[u64],
        m: &Move,
        counters: &[Option<u32>],
        out: &mut Successors,
    ) -> Result<(), VerifyError> {
        let di = m.delivery;
        let mut t = std::mem::take(&mut self.next);
        let mut prefixes = std::mem::take(&mut self.prefixes);
        for &counter in &counters[m.counters.clone()] {
            if m.dropped {
                self.run_delivery(s, di, &[], counter, &mut t);
                let d = &self.deliveries[di];
                self.flagged |= !self.rec.refused.is_empty() || self.rec.livelock.is_some();
                let key = (di as u32, Vec::new(), counter, true);
                let lid = match self.known_label(&key) {
                    Some(l) => l,
                    None => {
                        let (label, event) = (format!("{} (unused)", d.label), d.event);
                        self.label(at, key, || Label {
                            text: label,
                            event,
                            delivery: di as u32,
                            choices: Vec::new(),
                            counter,
                        })
                    }
                };
                let fid = self.fired_set(at);
                out.push(&t, lid, fid);
                continue;
            }
            // Every outcome of the guards this delivery cannot decide.
            prefixes.clear();
            prefixes.push(Vec::new());
            let mut runs = 0usize;
            while let Some(prefix) = prefixes.pop() {
                runs += 1;
                let d = &self.deliveries[di];
                if runs > MAX_GUARD_RUNS {
                    self.next = t;
                    return Err(VerifyError::TooManyUndecidedGuards {
                        event: self.p.events[d.event as usize].name.clone(),
                    });
                }
                self.run_delivery(s, di, &prefix, counter, &mut t);
                let d = &self.deliveries[di];
                Oracle::next_prefixes(&prefix, self.rec.oracle.used, &mut prefixes);
                self.flagged |= self.rec.oracle.used > 0
                    || !self.rec.refused.is_empty()
                    || self.rec.livelock.is_some();
                let choices: Vec<bool> = (0..self.rec.oracle.used)
                    .map(|k| prefix.get(k).copied().unwrap_or(false))
                    .collect();
                let key = (di as u32, choices, counter, false);
                let lid = match self.known_label(&key) {
                    Some(l) => l,
                    None => {
                        let (base, event) = (d.label.clone(), d.event);
                        let choices = key.1.clone();
                        self.label(at, key, || {
                            let mut text = base;
                            if !choices.is_empty() {
                                let taken: Vec<&str> = choices
                                    .iter()
                                    .map(|c| if *c { "true" } else { "false" })
                                    .collect();
                                text =
                                    format!("{text} (undecided guards taken {})", taken.join(", "));
                            }
                            Label {
                                text,
                                event,
                                delivery: di as u32,
                                choices,
                                counter,
                            }
                        })
                    }
                };
                let fid = self.fired_set(at);
                if let Some(g) = at.exploring() {
                    if self.rec.refused.is_empty() && self.rec.livelock.is_none() {
                        // Nothing to report: only the rules that fired.
                        for &r in &self.rec.fired {
                            g.ever_fired[r as usize] = true;
                        }
                    } else {
                        self.record(g, &|g| {
                            let mut t = g.trace(i);
                            t.push(g.labels[lid as usize].text.clone());
                            t
                        });
                    }
                }
                out.push(&t, lid, fid);
            }
        }
        self.next = t;
        self.prefixes = prefixes;
        Ok(())
    }

    /// Every move of state `i` (`s`, not over) run, its successors appended to `out` in
    /// delivery order; whether there was any move. With the transition cache, a component
    /// whose bits of `s` were met before in a state like this one takes its moves from the
    /// cache (the same successors, labels and fired sets, in the same order: the graph is the
    /// same, docs/verification.md), and one whose were not has them computed and stored.
    fn expand(
        &mut self,
        at: &mut At,
        i: u32,
        s: &[u64],
        w: &mut Expansion,
        out: &mut Successors,
    ) -> Result<bool, VerifyError> {
        let from = out.len();
        let l = &self.sem.layout;
        // An enabled immediate transition (refused, or its guard undecided) is tried again by
        // every step's fixpoint, whatever its component; after a loop of immediate
        // transitions, states are not stable. No cache then.
        let usable = self.cache.is_some()
            && self.livelock_seen.is_empty()
            && !l.immediate.iter().any(|&r| l.enabled(s, r));
        let cache = if usable { self.cache.take() } else { None };
        let Some(mut cache) = cache else {
            self.moves(at, i, s, &[], &mut w.moves);
            for m in &w.moves.list {
                self.run(at, i, s, m, &w.moves.counters, out)?;
            }
            return Ok(out.len() > from);
        };
        let done = self.expand_cached(&mut cache, at, i, s, w, out);
        self.cache = Some(cache);
        done?;
        Ok(out.len() > from)
    }

    /// [`Ctx::expand`] with the cache.
    fn expand_cached(
        &mut self,
        cache: &mut Cache,
        at: &mut At,
        i: u32,
        s: &[u64],
        w: &mut Expansion,
        out: &mut Successors,
    ) -> Result<(), VerifyError> {
        let n = cache.components();
        w.hit.clear();
        for c in 0..n {
            w.hit.push(cache.lookup(c, s));
        }
        w.skip.clear();
        w.skip.extend(
            cache
                .of_delivery
                .iter()
                .map(|c| c.is_some_and(|c| w.hit[c as usize].is_some())),
        );
        self.moves(at, i, s, &w.skip, &mut w.moves);
        w.unstorable.clear();
        w.unstorable.resize(n, false);
        for &di in &self.conflicted {
            if let Some(c) = cache.of_delivery[di] {
                w.unstorable[c as usize] = true;
            }
        }
        w.cursor.clear();
        w.cursor
            .extend(w.hit.iter().map(|h| h.map_or(0, |e| cache.entry(e).start)));
        w.computed.clear();
        // In delivery order, as without the cache: the cached successors of the components
        // met before, the computed ones of the others.
        let mut next_move = 0;
        for di in 0..self.deliveries.len() {
            match cache.of_delivery[di] {
                Some(c) if w.hit[c as usize].is_some() => {
                    let c = c as usize;
                    let end = w.hit[c].map_or(0, |e| cache.entry(e).end);
                    let mask = cache.mask(c);
                    while w.cursor[c] < end {
                        let (d, local, meta) = cache.successor(w.cursor[c]);
                        if d as usize != di {
                            break;
                        }
                        out.push_masked(s, mask, local, meta);
                        w.cursor[c] += 1;
                    }
                }
                comp => {
                    let Some(m) = w.moves.list.get(next_move).filter(|m| m.delivery == di) else {
                        continue;
                    };
                    next_move += 1;
                    let first = out.len();
                    self.flagged = false;
                    self.run(at, i, s, m, &w.moves.counters, out)?;
                    // The step kinds now, in successor order as they would be made after:
                    // the cache keeps them too.
                    for k in first..out.len() {
                        let (label, fired, _) = out.meta[k];
                        out.meta[k].2 = self.step(at, label, fired);
                    }
                    if let Some(c) = comp {
                        w.unstorable[c as usize] |= self.flagged;
                        w.computed
                            .extend((first..out.len()).map(|k| (c, k as u32, di as u32)));
                    }
                }
            }
        }
        // A bounded cache: a quarter of a successor per state explored, and a few thousand.
        let room = at.graph().states.len() / 4 + CACHE_ROOM;
        for c in 0..n {
            if w.hit[c].is_some()
                || w.unstorable[c]
                || !cache.cacheable(c)
                || cache.successors() >= room
            {
                continue;
            }
            let list = w
                .computed
                .iter()
                .filter(|&&(k, _, _)| k as usize == c)
                .map(|&(_, k, d)| (d, out.state(k as usize), out.meta[k as usize]));
            cache.store(c, s, list);
        }
        Ok(())
    }

    /// The edges of state `i` of the finished graph `g`, recomputed: the same moves, steps and
    /// order as when the exploration expanded it in full, each target looked up in the store.
    fn replay(&mut self, g: &Graph, i: u32, w: &mut ReplayBuffers, out: &mut Vec<Edge>) {
        let at = &mut At::Replay(g);
        w.s.clear();
        w.s.extend_from_slice(&g.states[i as usize]);
        let s = std::mem::take(&mut w.s);
        w.succ.clear();
        if !self.sem.layout.is_over(&s) {
            self.expand(at, i, &s, &mut w.exp, &mut w.succ)
                .expect(NOT_REPLAYED);
        }
        w.s = s;
        g.states
            .find_all(w.succ.states(), &mut w.slots, &mut w.found);
        for (&(label, fired, kind), known) in w.succ.meta.iter().zip(&w.found) {
            let to = known.expect(NOT_REPLAYED);
            out.push(Edge {
                to,
                kind: match kind {
                    NO_KIND => self.step(at, label, fired),
                    k => k,
                },
            });
        }
    }
}

/// What a replay reuses from one state to the next.
struct ReplayBuffers {
    s: State,
    exp: Expansion,
    succ: Successors,
    slots: Vec<(usize, u32)>,
    found: Vec<Option<u32>>,
}

/// Recomputes the edges of a finished graph whose edges were not kept: the exploration's own
/// expansion of a state ([`Ctx::moves`], [`Ctx::run`]: the same firing code, the same order),
/// every label, fired set and step kind looked up, none made.
pub(super) struct Replay<'a> {
    ctx: Ctx<'a>,
    w: ReplayBuffers,
}

impl Replay<'_> {
    /// The edges of state `i`, appended to `out`.
    pub fn edges(&mut self, g: &Graph, i: u32, out: &mut Vec<Edge>) {
        self.ctx.replay(g, i, &mut self.w, out);
    }
}

/// The edges of a finished graph, kept or replayed: what the analyses walk.
pub(super) struct Edges<'g, 'a> {
    g: &'g Graph,
    replay: Option<std::cell::RefCell<Replay<'a>>>,
}

impl<'g, 'a> Edges<'g, 'a> {
    /// The edges of `g`; `replay`, what explored it, recomputes them when `g` did not keep
    /// them (it must be given then).
    pub fn new(g: &'g Graph, replay: Option<Replay<'a>>) -> Self {
        debug_assert!(g.edges_kept || replay.is_some());
        Edges {
            g,
            replay: if g.edges_kept {
                None
            } else {
                replay.map(std::cell::RefCell::new)
            },
        }
    }

    /// The edges of state `i` (what `out` held is cleared), in the order the exploration found
    /// them.
    pub fn of(&self, i: u32, out: &mut Vec<Edge>) {
        out.clear();
        match &self.replay {
            None => self.g.kept_edges(i, out),
            Some(r) => r.borrow_mut().edges(self.g, i, out),
        }
    }
}

/// Explores every stable state of `p` (with `reduce`, a subset that keeps what
/// [`super::reduction`] says).
#[allow(clippy::too_many_arguments)]
/// The guard of each rule's transition, in the layout's rule order (what [`Recorder`] checks).
pub(super) fn rule_guards(p: &CompiledProject, sem: &Semantics) -> Vec<Option<Guard>> {
    sem.layout
        .rules
        .iter()
        .map(|r| {
            p.nets[r.net as usize].transitions[r.transition as usize]
                .guard
                .clone()
        })
        .collect()
}

pub(super) fn explore<'a>(
    p: &'a CompiledProject,
    sem: &'a Semantics<'a>,
    env: &'a Env,
    free: &[FreePlace],
    opts: &mut VerifyOptions,
    started: Instant,
    start: Option<&[u64]>,
) -> Result<(Graph, Replay<'a>), VerifyError> {
    let l = &sem.layout;
    let guards = rule_guards(p, sem);
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
        label_ids: FxMap::default(),
        fired_ids: FxMap::default(),
        step_ids: FxMap::default(),
        free_labels: Vec::new(),
        plain_labels: FxMap::default(),
        single_fired: Vec::new(),
        no_fired: None,
        plain_steps: Vec::new(),
        fired_buf: Vec::new(),
        next: State::new(),
        prefixes: Vec::new(),
        unsafe_seen: HashSet::new(),
        conflict_seen: HashSet::new(),
        livelock_seen: HashSet::new(),
        cache: None,
        flagged: false,
        conflicted: Vec::new(),
    };
    let mut g = Graph::new(words, l.rules.len(), p.nets.len());
    // Breadth-first depth of each state, and whether it was (or must be) expanded in full:
    // the cycle proviso of the reduction (kept only when reducing).
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
        g.push_state(&t, None);
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
            g.push_state(&initial, None);
        }
    }

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
    let reducing = components.is_some();
    // The transition cache: in the full exploration, untimed, of the whole project.
    if !reducing && !opts.no_cache && !opts.timed && free.is_empty() {
        let comps = super::reduction::Components::new(p, l);
        ctx.cache = Cache::new(p, l, env, &ctx.deliveries, &comps);
    }
    if reducing {
        depth.resize(g.states.len(), 0);
        full.resize(g.states.len(), false);
        // The initial states are expanded in full: the loops of each component come back to
        // them.
        must_full.resize(g.states.len(), true);
    }

    let mut last_progress = Instant::now();
    let mut next = 0usize;
    let mut moves = Moves::default();
    let mut expansion = Expansion::default();
    let mut tried = Successors::new(words);
    let mut successors = Successors::new(words);
    let mut s = State::new();
    // The edges are kept while they are few (or when asked to), else dropped and replayed by
    // the analyses. Not when reducing (which states were expanded in full is not kept) nor
    // with places the environment changes (`--net`: those moves are not replayed): those
    // graphs keep theirs.
    let replayable = !reducing && free.is_empty();
    let keep_limit = match opts.edges {
        _ if !replayable => u64::MAX,
        super::EdgeMemory::Auto => KEEP_EDGES,
        super::EdgeMemory::Keep => u64::MAX,
        super::EdgeMemory::Replay => 0,
    };
    let mut order: Vec<u32> = Vec::new();
    let (mut slots, mut found) = (Vec::new(), Vec::new());
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
        s.clear();
        s.extend_from_slice(&g.states[i as usize]);
        if g.edges_kept && g.edges > keep_limit {
            g.drop_edges();
        }
        if g.edges_kept {
            g.edge_start.push(g.edge_to.len() as u64);
        }
        for (n, seen) in g.ever_active.iter_mut().enumerate() {
            *seen |= l.is_active(&s, n as NetId);
        }
        g.max_tokens_per_marking = g.max_tokens_per_marking.max(l.tokens(&s) as u64);
        successors.clear();
        if l.is_over(&s) || !reducing {
            moves.list.clear();
        } else {
            ctx.moves(&mut At::Explore(&mut g), i, &s, &[], &mut moves);
        }
        // A drop counts: the player still has that event to process.
        let mut any_enabled = !moves.list.is_empty();
        if !reducing && !l.is_over(&s) {
            any_enabled = ctx.expand(
                &mut At::Explore(&mut g),
                i,
                &s,
                &mut expansion,
                &mut successors,
            )?;
        }

        // One component's deliveries, when they make a persistent set (no catastrophic event
        // enabled: it touches everything) and pass the cycle proviso; else every delivery.
        let mut reduced = false;
        if components.is_some() && !must_full[i as usize] {
            order.clear();
            let mut global = false;
            for m in &moves.list {
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
                let last = g.parent(i).and_then(|(_, lid)| {
                    let dl = g.labels[lid as usize].delivery as usize;
                    delivery_component.get(dl).copied().flatten()
                });
                order.sort_unstable_by_key(|&c| (Some(c) != last, c));
                // A component whose deliveries all belong to categories progress does not count
                // on is no choice while others offer counted ones: the states it leads to would
                // hide the counted ways to an end.
                let any_counted = moves
                    .list
                    .iter()
                    .any(|m| counted(m.delivery, &ctx.deliveries));
                for &c in &order {
                    if any_counted
                        && !moves.list.iter().any(|m| {
                            delivery_component[m.delivery] == Some(c)
                                && counted(m.delivery, &ctx.deliveries)
                        })
                    {
                        continue;
                    }
                    tried.clear();
                    for m in moves
                        .list
                        .iter()
                        .filter(|m| delivery_component[m.delivery] == Some(c))
                    {
                        ctx.run(
                            &mut At::Explore(&mut g),
                            i,
                            &s,
                            m,
                            &moves.counters,
                            &mut tried,
                        )?;
                    }
                    // The cycle proviso: every edge that does not go one level deeper ends
                    // in a state expanded in full (or that will be), so every loop of the
                    // reduced graph holds a state expanded in full and no component is
                    // ignored forever.
                    let ok = tried.states().all(|t| match g.states.find(t) {
                        None => true,
                        Some(j) => {
                            depth[j as usize] > depth[i as usize]
                                || (j != i && (j > i || full[j as usize]))
                        }
                    });
                    if ok {
                        for t in tried.states() {
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
            for m in &moves.list {
                ctx.run(
                    &mut At::Explore(&mut g),
                    i,
                    &s,
                    m,
                    &moves.counters,
                    &mut successors,
                )?;
            }
        } else {
            g.reduced += 1;
        }
        // An immediate transition left enabled in a stable state (refused for safety, or its
        // guard undecided and taken false) is tried again by every later step's fixpoint,
        // whatever component the step is of: a delivery of one component may then fire another
        // component's transition, and the components are no longer independent (the
        // transition cache declines such states for the same reason).
        let coupled = reducing && l.immediate.iter().any(|&r| l.enabled(&s, r));
        if components.is_some() && (!ctx.livelock_seen.is_empty() || coupled) {
            // A loop of immediate transitions leaves a state that is not stable: every later
            // step's fixpoint runs into it again, whatever component the step is of, and the
            // components are no longer independent. Explore again, in full.
            opts.no_reduction = true;
            let full = explore(p, sem, env, free, opts, started, start);
            opts.no_reduction = false;
            return full;
        }
        if reducing {
            full[i as usize] = !reduced;
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
                &mut At::Explore(&mut g),
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
            let fid = ctx.fired_set(&mut At::Explore(&mut g));
            successors.push(&t, lid, fid);
        }
        g.states
            .find_all(successors.states(), &mut slots, &mut found);
        for ((t, &(label, fired, kind)), known) in successors
            .states()
            .zip(successors.meta.iter())
            .zip(found.iter())
        {
            // A state not found may have been added by an earlier successor of this one.
            let j = match known.or_else(|| g.states.find(t)) {
                Some(j) => j,
                None => {
                    let j = g.states.len() as u32;
                    if let Some(limit) = opts.max_states {
                        if j as u64 >= limit {
                            return Err(VerifyError::TooManyStates { limit });
                        }
                    }
                    g.push_state(t, Some((i, label)));
                    if reducing {
                        depth.push(depth[i as usize] + 1);
                        full.push(false);
                        must_full.push(false);
                    }
                    j
                }
            };
            let step = match kind {
                NO_KIND => ctx.step(&mut At::Explore(&mut g), label, fired),
                k => k,
            };
            g.edges += 1;
            if g.edges_kept {
                g.edge_to.push(u64::from(j));
                g.edge_step.push(u64::from(step));
            }
        }
        if !any_enabled {
            g.dead.push(i);
        }
    }
    if g.edges_kept {
        g.edge_start.push(g.edge_to.len() as u64);
    }
    g.deliveries = ctx.deliveries.clone();
    if let Some(c) = &ctx.cache {
        g.cache_hits = c.hits;
    }
    // What expanded the states replays them: the same labels, fired sets and step kinds.
    let replay = Replay {
        ctx,
        w: ReplayBuffers {
            s: State::new(),
            exp: Expansion::default(),
            succ: Successors::new(words),
            slots: Vec::new(),
            found: Vec::new(),
        },
    };
    Ok((g, replay))
}

/// Edges kept in memory at most, unless asked otherwise ([`super::EdgeMemory`]): about 4 MB;
/// beyond, the analyses replay them (docs/benchmarks.md, "What the full exploration costs per
/// state").
const KEEP_EDGES: u64 = 1 << 20;

/// A graph with the edges `adj` (state `i`'s targets), of 70 step kinds (edge `k` of state `i`
/// of kind `(7i + k) % 70`, two words of kinds), for the analyses' unit tests.
#[cfg(test)]
pub(super) fn tests_graph(adj: &[Vec<u32>]) -> Graph {
    let mut g = Graph::new(1, 0, 0);
    for i in 0..adj.len() {
        g.push_state(&[i as u64], None);
    }
    g.labels.push(Label {
        text: "e".into(),
        event: 0,
        delivery: 0,
        choices: Vec::new(),
        counter: None,
    });
    g.fired_sets.push(Vec::new());
    g.steps.extend((0..70).map(|_| (0, 0)));
    for (i, succ) in adj.iter().enumerate() {
        g.edge_start.push(g.edge_to.len() as u64);
        for (k, &j) in succ.iter().enumerate() {
            g.edge_to.push(u64::from(j));
            g.edge_step.push(((7 * i + k) % 70) as u64);
            g.edges += 1;
        }
    }
    g.edge_start.push(g.edge_to.len() as u64);
    g
}
