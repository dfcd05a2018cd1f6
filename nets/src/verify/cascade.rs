//! Zero-time cascades (docs/semantics.md, "Zero-time cascades"; docs/verification.md): what the
//! player does at one instant after an event, followed as the player does it.
//!
//! A step's produced events (the nets' `emit`s, and the reports the player raises about the
//! step: `safety_violation`, `invariant_violated`) are queued and taken at the same instant, in
//! the player's queue order. From each reachable stable state and each event the environment
//! may deliver there, the search follows that **configuration** (a state and the queue of
//! produced events) step by step with the firing code ([`crate::semantics`]), every way the
//! guards it cannot decide may go. A cascade that comes back to a configuration it was in
//! never ends: a strongly connected component of the configurations (Tarjan's algorithm, over
//! the configurations met from every start) with an edge inside is a loop. A cascade that takes
//! [`crate::semantics::Semantics::cascade_bound`] steps with produced events still queued is
//! one the player stops. Both are E0608.
//!
//! Only what can go on for ever is searched: an event is followed when a cycle of "a step on
//! this event may produce that one" can be reached from it (read from the nets' text); a
//! project without such a cycle has no cascade that never ends, and costs nothing here. A
//! cascade's queue of more than [`MEMO_QUEUE`] events is followed along one path, without
//! memory, to its end or the bound.

use super::env::{cascade_deliveries, Gate};
use super::explore::{Graph, Recorder};
use super::store::FxMap;
use super::{CascadeFinding, Trace};
use crate::compiled::{Action, Arg, CompiledProject, EventId, Guard, NetId};
use crate::semantics::{queue_index, Effects, Scratch, Semantics, State};
use petrel_value::Value;
use std::collections::VecDeque;

/// Queues longer than this are not remembered: followed along one path to their end.
pub(super) const MEMO_QUEUE: usize = 256;

/// Configurations remembered at most (or the exploration's `--max-states`, when lower);
/// beyond, the search stops and says so.
pub(super) const BUDGET: u64 = 1_000_000;

/// Steps of the paths followed without memory, at most, over the whole search: this many per
/// configuration of the budget, and at least enough for a few paths to the bound.
const LINEAR_PER_CONFIGURATION: u64 = 50;

/// What the search found: the loops and the cascades that reach the bound, and whether it went
/// through every configuration.
pub(super) struct Cascades {
    pub findings: Vec<CascadeFinding>,
    pub complete: bool,
    pub configurations: u64,
}

/// One produced event in the queue.
#[derive(Clone, Debug)]
struct Item {
    event: EventId,
    target: Option<NetId>,
    params: Vec<Value>,
    /// Whether each parameter's value is known (not a net's parameter bound at activation).
    known: Vec<bool>,
}

/// A state and the produced events queued, by category (catastrophic first).
#[derive(Clone, Debug)]
struct Config {
    state: State,
    queue: [VecDeque<Item>; 5],
}

impl Config {
    fn len(&self) -> usize {
        self.queue.iter().map(VecDeque::len).sum()
    }

    /// The bytes that tell configurations apart.
    fn key(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.state.len() * 8 + 16 * self.len());
        for w in &self.state {
            out.extend_from_slice(&w.to_le_bytes());
        }
        for q in &self.queue {
            out.extend_from_slice(&(q.len() as u32).to_le_bytes());
            for item in q {
                out.extend_from_slice(&item.event.to_le_bytes());
                out.extend_from_slice(&item.target.map_or(u32::MAX, |n| n).to_le_bytes());
                for (v, &k) in item.params.iter().zip(&item.known) {
                    if k {
                        push_value(&mut out, v);
                    } else {
                        out.push(9);
                    }
                }
            }
        }
        out
    }
}

fn push_value(out: &mut Vec<u8>, v: &Value) {
    match v {
        Value::Int(i) => {
            out.push(0);
            out.extend_from_slice(&i.to_le_bytes());
        }
        Value::Float(f) => {
            out.push(1);
            out.extend_from_slice(&f.to_bits().to_le_bytes());
        }
        Value::Bool(b) => out.extend_from_slice(&[2, u8::from(*b)]),
        Value::Text(t) => {
            out.push(3);
            out.extend_from_slice(&(t.len() as u64).to_le_bytes());
            out.extend_from_slice(t.as_bytes());
        }
        Value::FloatList(l) => {
            out.push(4);
            out.extend_from_slice(&(l.len() as u64).to_le_bytes());
            for f in l {
                out.extend_from_slice(&f.to_bits().to_le_bytes());
            }
        }
    }
}

/// True when `g` reads a parameter of the event for which `unknown` holds.
fn reads(g: &Guard, unknown: &dyn Fn(u32) -> bool) -> bool {
    let arg = |a: &Arg| matches!(a, Arg::EventParam(i) if unknown(*i));
    match g {
        Guard::Const(_) => false,
        Guard::Not(a) => reads(a, unknown),
        Guard::And(list) | Guard::Or(list) => list.iter().any(|a| reads(a, unknown)),
        Guard::Value(a) => arg(a),
        Guard::Compare(_, a, b) => arg(a) || arg(b),
    }
}

/// The firing code's effects during one step of a cascade: the exploration's [`Recorder`]
/// (guards, undecided outcomes, loops of immediate transitions, refusals), and the events the
/// step emits, with their values.
struct Watch<'a> {
    rec: &'a mut Recorder,
    p: &'a CompiledProject,
    known: &'a [bool],
    emits: Vec<Item>,
}

impl Effects for Watch<'_> {
    fn fired(&mut self, rule: u32) {
        self.rec.fired(rule);
    }
    fn refused(&mut self, rule: u32, place: u32) {
        self.rec.refused(rule, place);
    }
    fn emit(&mut self, event: EventId, args: &[Arg], target: Option<NetId>) {
        let decl = &self.p.events[event as usize];
        let mut item = Item {
            event,
            target,
            params: Vec::with_capacity(args.len()),
            known: Vec::with_capacity(args.len()),
        };
        for (a, (_, ty)) in args.iter().zip(&decl.params) {
            let (v, k) = match a {
                Arg::Literal(v) => (v.clone(), true),
                Arg::EventParam(i) => (
                    self.rec.params[*i as usize].clone(),
                    self.known.get(*i as usize).copied().unwrap_or(false),
                ),
                // Bound at activation: the verifier does not track it.
                Arg::NetParam(_) => (ty.neutral(), false),
            };
            item.params.push(v);
            item.known.push(k);
        }
        self.emits.push(item);
    }
    fn guard(&mut self, rule: u32) -> bool {
        let unknown = |i: u32| !self.known.get(i as usize).copied().unwrap_or(true);
        match self.rec.guards.get(rule as usize) {
            Some(Some(g)) if reads(g, &unknown) => self.rec.oracle.choose(),
            _ => self.rec.guard(rule),
        }
    }
    fn immediate_step(&mut self, state: &[u64]) -> bool {
        self.rec.immediate_step(state)
    }
    fn livelock(&mut self) {
        self.rec.livelock();
    }
}

/// One step's outcome: the configuration after it, and what it took and fired.
struct Next {
    config: Config,
    step: u32,
}

/// A step of a cascade, for the findings: the event taken (`event`, `event(args)`,
/// `event to NET`) and the rules fired.
struct StepInfo {
    label: String,
    fired: Vec<u32>,
}

/// A configuration of the search (Tarjan's bookkeeping).
struct Node {
    index: u32,
    low: u32,
    on_stack: bool,
    succ: Vec<(u32, u32)>,
}

const UNVISITED: u32 = u32::MAX;

struct Search<'a> {
    p: &'a CompiledProject,
    g: &'a Graph,
    sem: &'a Semantics<'a>,
    rec: Recorder,
    scratch: Scratch,
    /// Per event, whether a step on it may lead to a step on an event of a cycle.
    leads: Vec<bool>,
    raised: [Option<EventId>; 2],
    ids: FxMap<Vec<u8>, u32>,
    nodes: Vec<Node>,
    /// Each node's configuration until it is expanded.
    pending: Vec<Option<Config>>,
    steps: Vec<StepInfo>,
    step_ids: FxMap<(String, Vec<u32>), u32>,
    stack: Vec<u32>,
    counter: u32,
    linear_steps: u64,
    /// The budgets: configurations, and steps followed without memory.
    budget: u64,
    linear_budget: u64,
    complete: bool,
    findings: Vec<(Vec<u32>, Vec<String>, CascadeFinding)>,
    /// The current start: the graph state and the label of the event delivered there (`None`:
    /// the project's start), for the trace of a finding.
    start: Option<(u32, String)>,
}

/// Per event, whether it lies on a cycle of "a step on it may produce that one", and whether a
/// step on it may lead to one. A step on `e` may produce what its transitions emit, what any
/// immediate transition emits (its fixpoint may fire one), `safety_violation` when a firing may
/// be refused and `invariant_violated` when the manifest has invariants.
fn produce_graph(p: &CompiledProject, sem: &Semantics) -> Vec<bool> {
    let n = p.events.len();
    let l = &sem.layout;
    let mut next: Vec<Vec<EventId>> = vec![Vec::new(); n];
    let mut always: Vec<EventId> = Vec::new();
    if let Some(e) = p.event_id("safety_violation") {
        always.push(e);
    }
    if let (Some(e), false) = (p.event_id("invariant_violated"), p.invariants.is_empty()) {
        always.push(e);
    }
    for rule in &l.rules {
        let t = &p.nets[rule.net as usize].transitions[rule.transition as usize];
        for a in &t.actions {
            if let Action::Emit { event, .. } = a {
                match t.event {
                    Some(e) => next[e as usize].push(*event),
                    None => always.push(*event),
                }
            }
        }
    }
    for (e, list) in next.iter_mut().enumerate() {
        // A step on an event no transition waits for changes nothing and produces nothing.
        if l.by_event[e].is_empty() {
            list.clear();
            continue;
        }
        list.extend_from_slice(&always);
        list.sort_unstable();
        list.dedup();
    }
    // Events on a cycle: those that reach themselves. The graph is small (events).
    let reach_from = |e: usize| -> Vec<bool> {
        let mut seen = vec![false; n];
        let mut todo: Vec<usize> = next[e].iter().map(|&x| x as usize).collect();
        while let Some(x) = todo.pop() {
            if !std::mem::replace(&mut seen[x], true) {
                todo.extend(next[x].iter().map(|&y| y as usize));
            }
        }
        seen
    };
    let reach: Vec<Vec<bool>> = (0..n).map(reach_from).collect();
    let cyclic: Vec<bool> = (0..n).map(|e| reach[e][e]).collect();
    (0..n)
        .map(|e| cyclic[e] || (0..n).any(|x| cyclic[x] && reach[e][x]))
        .collect()
}

/// The zero-time cascades of the explored graph `g`: from each of its states, each delivery
/// the environment may make there; and from the start's own produced events (`initial`: the
/// graph starts with the project's start, not a reload's state), within `budget`
/// configurations.
pub(super) fn cascades(
    p: &CompiledProject,
    sem: &Semantics,
    env: &super::env::Env,
    g: &Graph,
    guards: Vec<Option<Guard>>,
    initial: bool,
    budget: u64,
) -> Cascades {
    let leads = produce_graph(p, sem);
    let mut search = Search {
        p,
        g,
        sem,
        rec: Recorder::with_guards(guards),
        scratch: Scratch::default(),
        raised: [
            p.event_id("safety_violation"),
            p.event_id("invariant_violated"),
        ],
        leads,
        ids: FxMap::default(),
        nodes: Vec::new(),
        pending: Vec::new(),
        steps: Vec::new(),
        step_ids: FxMap::default(),
        stack: Vec::new(),
        counter: 0,
        linear_steps: 0,
        budget,
        linear_budget: (budget * LINEAR_PER_CONFIGURATION).max(4 * u64::from(sem.cascade_bound)),
        complete: true,
        findings: Vec::new(),
        start: None,
    };
    if search.leads.iter().any(|&x| x) {
        search.run(env, initial);
    }
    Cascades {
        configurations: search.nodes.len() as u64,
        complete: search.complete,
        findings: search.findings.into_iter().map(|(_, _, f)| f).collect(),
    }
}

impl Search<'_> {
    fn run(&mut self, env: &super::env::Env, initial: bool) {
        let g = self.g;
        let l = &self.sem.layout;
        let deliveries = cascade_deliveries(self.p, l, &self.leads);
        if initial {
            // The start's produced events: every outcome of the guards it cannot decide.
            let mut prefixes = vec![Vec::new()];
            while let Some(prefix) = prefixes.pop() {
                let next = self.step(None, &prefix);
                // The questions this step asked (the search below asks its own).
                let used = self.rec.oracle.used;
                if let Some(next) = next {
                    self.start = None;
                    self.explore_from(next.config);
                }
                super::env::Oracle::next_prefixes(&prefix, used, &mut prefixes);
                if prefixes.len() > super::env::MAX_GUARD_RUNS {
                    break;
                }
            }
        }
        // Each state's words of the project, and the deliveries started from them (a bit
        // each): states that differ only in the environment's counters share their starts.
        let mut started: FxMap<State, Vec<u64>> = FxMap::default();
        for i in 0..g.states.len() as u32 {
            if !self.complete {
                return;
            }
            let s = &g.states[i as usize];
            let words = s[..l.words].to_vec();
            let done = started
                .entry(words.clone())
                .or_insert_with(|| vec![0; deliveries.len().div_ceil(64)]);
            let todo: Vec<usize> = (0..deliveries.len())
                .filter(|&k| {
                    let d = &deliveries[k];
                    done[k / 64] & (1 << (k % 64)) == 0
                        && !matches!(env.gate(s, d.event, d.target), Gate::Closed)
                })
                .collect();
            for &k in &todo {
                done[k / 64] |= 1 << (k % 64);
            }
            for k in todo {
                let d = &deliveries[k];
                let mut prefixes = vec![Vec::new()];
                let mut runs = 0;
                while let Some(prefix) = prefixes.pop() {
                    runs += 1;
                    let first = Config {
                        state: words.clone(),
                        queue: Default::default(),
                    };
                    let item = Item {
                        event: d.event,
                        target: d.target,
                        params: d.params.clone(),
                        known: vec![true; d.params.len()],
                    };
                    let next = self.first_step(first, item, &prefix);
                    let used = self.rec.oracle.used;
                    if let Some(next) = next {
                        self.start = Some((i, d.label.clone()));
                        self.explore_from(next.config);
                    }
                    super::env::Oracle::next_prefixes(&prefix, used, &mut prefixes);
                    if runs >= super::env::MAX_GUARD_RUNS || !self.complete {
                        break;
                    }
                }
            }
        }
    }

    /// The step of an outside event `item` in `config` (a timer's event: that timer expires),
    /// with the undecided guards' outcomes of `prefix`: the configuration it leads to, if a
    /// produced event it queues may go on for ever.
    fn first_step(&mut self, mut config: Config, item: Item, prefix: &[bool]) -> Option<Next> {
        for (k, timer) in self.p.timers.iter().enumerate() {
            if timer.event == item.event {
                self.sem.timer_expired(&mut config.state, k as u32);
            }
        }
        // Nothing else is queued: it is the first event taken.
        config.queue[0].push_front(item);
        self.step(Some(config), prefix)
            .filter(|next| self.goes_on(&next.config))
    }

    /// Whether a configuration's queue holds an event that may lead to a cascade without end.
    fn goes_on(&self, c: &Config) -> bool {
        c.queue
            .iter()
            .flatten()
            .any(|item| self.leads[item.event as usize])
    }

    /// One step from `config` (`None`: the start), taking the first event of its queue, with
    /// the undecided guards' outcomes of `prefix`. `None` when the step's immediate transitions
    /// loop (E0603 says so) or nothing is queued.
    fn step(&mut self, config: Option<Config>, prefix: &[bool]) -> Option<Next> {
        self.rec.reset();
        self.rec.oracle.prefix.clear();
        self.rec.oracle.prefix.extend_from_slice(prefix);
        let (mut config, item) = match config {
            None => {
                self.rec.params.clear();
                let mut watch = Watch {
                    rec: &mut self.rec,
                    p: self.p,
                    known: &[],
                    emits: Vec::new(),
                };
                let state = self.sem.initial(&mut watch, &mut self.scratch);
                let emits = std::mem::take(&mut watch.emits);
                let mut c = Config {
                    state,
                    queue: Default::default(),
                };
                self.queue_produced(&mut c, None, emits);
                let step = self.step_id(String::from("(start)"));
                return (self.rec.livelock.is_none() && self.goes_on(&c))
                    .then_some(Next { config: c, step });
            }
            Some(mut c) => {
                let q = c.queue.iter_mut().find(|q| !q.is_empty())?;
                let item = q.pop_front()?;
                (c, item)
            }
        };
        let before = config.state.clone();
        self.rec.params.clone_from(&item.params);
        let mut watch = Watch {
            rec: &mut self.rec,
            p: self.p,
            known: &item.known,
            emits: Vec::new(),
        };
        self.sem.process_event(
            &mut config.state,
            item.event,
            item.target,
            &mut watch,
            &mut self.scratch,
        );
        let emits = std::mem::take(&mut watch.emits);
        if self.rec.livelock.is_some() {
            return None;
        }
        self.queue_produced(&mut config, Some(&before), emits);
        let step = self.step_id(label(self.p, &item));
        Some(Next { config, step })
    }

    /// Queues what a step produced, in the player's order: the emitted events, the invariants
    /// the step broke, the firings it refused.
    fn queue_produced(&mut self, c: &mut Config, before: Option<&[u64]>, emits: Vec<Item>) {
        let l = &self.sem.layout;
        let push = |c: &mut Config, item: Item| {
            let cat = queue_index(self.p.events[item.event as usize].category);
            c.queue[cat].push_back(item);
        };
        for item in emits {
            push(c, item);
        }
        if let (Some(before), Some(e)) = (before, self.raised[1]) {
            for inv in &self.p.invariants {
                if l.holds(&inv.formula, before) && !l.holds(&inv.formula, &c.state) {
                    let item = Item {
                        event: e,
                        target: None,
                        params: vec![Value::Text(inv.name.clone())],
                        known: vec![true],
                    };
                    push(c, item);
                }
            }
        }
        if let Some(e) = self.raised[0] {
            for &(r, place) in &self.rec.refused {
                let rule = &l.rules[r as usize];
                let net = &self.p.nets[rule.net as usize];
                let item = Item {
                    event: e,
                    target: None,
                    params: vec![
                        Value::Text(net.name.clone()),
                        Value::Text(net.transitions[rule.transition as usize].name.clone()),
                        Value::Text(l.describe_bit(self.p, place)),
                    ],
                    known: vec![true; 3],
                };
                push(c, item);
            }
        }
    }

    /// The step kind of the step just run (`label`, and the rules it fired).
    fn step_id(&mut self, label: String) -> u32 {
        let key = (label, self.rec.fired.clone());
        if let Some(&k) = self.step_ids.get(&key) {
            return k;
        }
        let k = self.steps.len() as u32;
        self.steps.push(StepInfo {
            label: key.0.clone(),
            fired: key.1.clone(),
        });
        self.step_ids.insert(key, k);
        k
    }

    /// Every way the step from `config` may go (one per outcome of the undecided guards).
    fn successors(&mut self, config: &Config) -> Vec<Next> {
        let mut out = Vec::new();
        let mut prefixes = vec![Vec::new()];
        let mut runs = 0;
        while let Some(prefix) = prefixes.pop() {
            runs += 1;
            if let Some(next) = self.step(Some(config.clone()), &prefix) {
                out.push(next);
            }
            super::env::Oracle::next_prefixes(&prefix, self.rec.oracle.used, &mut prefixes);
            if runs >= super::env::MAX_GUARD_RUNS {
                break;
            }
        }
        out
    }

    /// The node of `config`, made (unvisited) if it is new.
    fn node(&mut self, config: Config) -> u32 {
        let key = config.key();
        if let Some(&k) = self.ids.get(&key) {
            return k;
        }
        let k = self.nodes.len() as u32;
        self.ids.insert(key, k);
        self.nodes.push(Node {
            index: UNVISITED,
            low: UNVISITED,
            on_stack: false,
            succ: Vec::new(),
        });
        self.pending.push(Some(config));
        if self.nodes.len() as u64 > self.budget {
            self.complete = false;
        }
        k
    }

    /// Tarjan's search from `config` (the configuration after a start's first step); each
    /// strongly connected component with an edge inside is a loop; a path that takes as many
    /// steps as the bound with events still queued is a cascade the player stops.
    fn explore_from(&mut self, config: Config) {
        if config.len() > MEMO_QUEUE {
            self.follow(config, &[]);
            return;
        }
        let root = self.node(config);
        if self.nodes[root as usize].index != UNVISITED {
            return;
        }
        // (node, next successor); the path's steps are the edges taken.
        let mut frames: Vec<(u32, usize)> = Vec::new();
        self.visit(root, &mut frames);
        while let Some(&mut (v, ref mut k)) = frames.last_mut() {
            let vi = v as usize;
            if *k < self.nodes[vi].succ.len() {
                let (w, _) = self.nodes[vi].succ[*k];
                *k += 1;
                let wi = w as usize;
                if self.nodes[wi].index == UNVISITED {
                    if !self.complete {
                        continue;
                    }
                    self.visit(w, &mut frames);
                } else if self.nodes[wi].on_stack {
                    self.nodes[vi].low = self.nodes[vi].low.min(self.nodes[wi].index);
                }
                continue;
            }
            frames.pop();
            if let Some(&(u, _)) = frames.last() {
                let low = self.nodes[vi].low;
                let ul = &mut self.nodes[u as usize].low;
                *ul = (*ul).min(low);
            }
            if self.nodes[vi].low == self.nodes[vi].index {
                let mut members = Vec::new();
                while let Some(x) = self.stack.pop() {
                    self.nodes[x as usize].on_stack = false;
                    members.push(x);
                    if x == v {
                        break;
                    }
                }
                let looped = members.len() > 1 || self.nodes[vi].succ.iter().any(|&(w, _)| w == v);
                if looped {
                    self.report_loop(v, &members);
                }
            }
        }
    }

    /// Numbers node `v`, expands it, and pushes it on the path.
    fn visit(&mut self, v: u32, frames: &mut Vec<(u32, usize)>) {
        let vi = v as usize;
        self.nodes[vi].index = self.counter;
        self.nodes[vi].low = self.counter;
        self.counter += 1;
        self.nodes[vi].on_stack = true;
        self.stack.push(v);
        let config = self.pending[vi].take().expect("a node is expanded once");
        // Steps taken on produced events from the start to here.
        let depth = frames.len() as u32;
        frames.push((v, 0));
        if depth >= self.sem.cascade_bound {
            let path = self.path(frames);
            self.report_bound(&path);
            return;
        }
        let mut succ = Vec::new();
        for next in self.successors(&config) {
            if next.config.len() == 0 || !self.goes_on(&next.config) {
                continue;
            }
            if next.config.len() > MEMO_QUEUE {
                let mut path = self.path(frames);
                path.push(next.step);
                self.follow(next.config, &path);
                continue;
            }
            let w = self.node(next.config);
            succ.push((w, next.step));
        }
        self.nodes[vi].succ = succ;
    }

    /// The steps of the path from the root to the top of `frames`.
    fn path(&self, frames: &[(u32, usize)]) -> Vec<u32> {
        frames
            .windows(2)
            .map(|w| {
                let (v, k) = w[0];
                self.nodes[v as usize].succ[k - 1].1
            })
            .collect()
    }

    /// Follows a configuration too long to remember along one path (the undecided guards
    /// taken false), to its end or to the bound; `path` is the steps that led to it.
    fn follow(&mut self, mut config: Config, path: &[u32]) {
        let mut steps: Vec<u32> = path.to_vec();
        let mut depth = path.len() as u32;
        while config.len() > 0 && self.goes_on(&config) {
            if depth >= self.sem.cascade_bound {
                self.report_bound(&steps);
                return;
            }
            self.linear_steps += 1;
            if self.linear_steps > self.linear_budget {
                self.complete = false;
                return;
            }
            let Some(next) = self.step(Some(config), &[]) else {
                return;
            };
            if steps.last() != Some(&next.step) {
                steps.push(next.step);
            }
            config = next.config;
            depth += 1;
        }
    }

    /// The events that lead to the current start.
    fn trace(&self) -> Trace {
        match &self.start {
            None => Vec::new(),
            Some((i, label)) => {
                let mut t = self.g.trace(*i);
                t.push(label.clone());
                t
            }
        }
    }

    fn names(&self, rules: &[u32]) -> Vec<String> {
        let l = &self.sem.layout;
        rules
            .iter()
            .map(|&r| {
                let rule = &l.rules[r as usize];
                let net = &self.p.nets[rule.net as usize];
                format!(
                    "{}.{}",
                    net.name, net.transitions[rule.transition as usize].name
                )
            })
            .collect()
    }

    fn add(&mut self, mut rules: Vec<u32>, events: Vec<String>, endless: bool) {
        rules.sort_unstable();
        rules.dedup();
        let mut key_events = events.clone();
        key_events.sort();
        key_events.dedup();
        if self
            .findings
            .iter()
            .any(|(r, e, f)| *r == rules && *e == key_events && f.endless == endless)
        {
            return;
        }
        let finding = CascadeFinding {
            events,
            transitions: self.names(&rules),
            endless,
            trace: self.trace(),
        };
        self.findings.push((rules, key_events, finding));
    }

    /// A cascade that took as many steps as the bound along `path`.
    fn report_bound(&mut self, path: &[u32]) {
        let mut rules = Vec::new();
        let mut events: Vec<String> = Vec::new();
        for &s in path {
            let info = &self.steps[s as usize];
            rules.extend_from_slice(&info.fired);
            if !events.contains(&info.label) {
                events.push(info.label.clone());
            }
        }
        self.add(rules, events, false);
    }

    /// A loop: the strongly connected component `members` of root `v`. Its transitions are
    /// those fired inside it; its events, those of one shortest turn through `v`.
    fn report_loop(&mut self, v: u32, members: &[u32]) {
        let inside = |x: u32| members.contains(&x);
        let mut rules = Vec::new();
        for &u in members {
            for &(w, s) in &self.nodes[u as usize].succ {
                if inside(w) {
                    rules.extend_from_slice(&self.steps[s as usize].fired);
                }
            }
        }
        // One shortest turn: breadth first from v inside the component, back to v.
        let mut parent: FxMap<u32, (u32, u32)> = FxMap::default();
        let mut todo = VecDeque::from([v]);
        let mut last = None;
        'bfs: while let Some(u) = todo.pop_front() {
            for &(w, s) in &self.nodes[u as usize].succ {
                if w == v {
                    last = Some((u, s));
                    break 'bfs;
                }
                if inside(w) && !parent.contains_key(&w) {
                    parent.insert(w, (u, s));
                    todo.push_back(w);
                }
            }
        }
        let mut turn: Vec<u32> = Vec::new();
        if let Some((mut u, s)) = last {
            turn.push(s);
            while u != v {
                let (p, s) = parent[&u];
                turn.push(s);
                u = p;
            }
        }
        turn.reverse();
        // Read the same whichever configuration the search entered the loop by: from its
        // step with the first rule in dispatch order.
        if let Some(first) = (0..turn.len()).min_by_key(|&k| {
            let info = &self.steps[turn[k] as usize];
            (
                info.fired.first().copied().unwrap_or(u32::MAX),
                info.label.clone(),
            )
        }) {
            turn.rotate_left(first);
        }
        let events = turn
            .iter()
            .map(|&s| self.steps[s as usize].label.clone())
            .collect();
        self.add(rules, events, true);
    }
}

/// An event as a cascade's step takes it: `event`, `event(args)` (an unknown value as `_`),
/// `event to NET`.
fn label(p: &CompiledProject, item: &Item) -> String {
    let mut out = p.events[item.event as usize].name.clone();
    if !item.params.is_empty() {
        let args: Vec<String> = item
            .params
            .iter()
            .zip(&item.known)
            .map(|(v, &k)| if k { v.literal() } else { "_".into() })
            .collect();
        out = format!("{out}({})", args.join(", "));
    }
    if let Some(n) = item.target {
        out = format!("{out} to {}", p.nets[n as usize].name);
    }
    out
}
