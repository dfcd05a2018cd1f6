//! Verification of a mission project (section 2.4 of the ProCoSA paper): explore every stable
//! state the project can reach, with the firing code the player runs ([`crate::semantics`]),
//! and report unsafe places, dead markings, loops, transitions that never fire, nets never
//! activated, unused events and conflicts, each with the shortest sequence of events that shows
//! it.
//!
//! The environment is free: in every stable state, any event some transition waits for may
//! arrive (events emitted by nets and timer expiries included, at any later point). That
//! over-approximates what the vehicle can do, so a property proved here holds in flight.

use crate::compiled::{Arg, CompiledProject, EventId, Guard, NetId, PlaceRef, Value};
use crate::semantics::{Effects, Layout, Scratch, Semantics, State};
use petrel_value::Type;
use std::collections::HashMap;
use std::time::Instant;

/// Most runs of one event delivery in one state, over the outcomes of the guards the verifier
/// cannot decide (see [`Oracle`]): beyond it the verification stops with an error.
const MAX_GUARD_RUNS: usize = 4096;

/// What to explore and how far.
#[derive(Default)]
pub struct VerifyOptions {
    /// Stop with [`VerifyError::TooManyStates`] beyond this many states.
    pub max_states: Option<u64>,
    /// Verify one net alone: its global places and events are free choices of the
    /// environment, and the other nets are not modelled.
    pub only_net: Option<String>,
    /// Called about once a second with (states so far, states per second).
    pub progress: Option<Box<dyn FnMut(u64, f64)>>,
    /// Keep every reachable stable state in [`Report::reachable`] (for cross-checks).
    pub keep_states: bool,
}

/// Why a verification could not finish.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VerifyError {
    /// The state space is larger than `--max-states`.
    TooManyStates {
        /// The limit.
        limit: u64,
    },
    /// `--net` named no net.
    UnknownNet(String),
    /// Too many guards that the verifier cannot decide in one step (each doubles the runs).
    TooManyUndecidedGuards {
        /// The event delivered.
        event: String,
    },
}

impl std::fmt::Display for VerifyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VerifyError::TooManyStates { limit } => write!(
                f,
                "stopped after {limit} states (--max-states): the project has more reachable states; raise the limit, or verify one net with --net"
            ),
            VerifyError::UnknownNet(n) => write!(f, "no net named `{n}` in the project"),
            VerifyError::TooManyUndecidedGuards { event } => write!(
                f,
                "event `{event}` meets more than {MAX_GUARD_RUNS} combinations of guards the verifier cannot decide (comparisons of two parameters, or of parameters bound at activation): compare parameters with constants or with fixed instance parameters"
            ),
        }
    }
}

impl std::error::Error for VerifyError {}

/// One step of a trace: the event delivered by the environment, or a global place the
/// environment changed (single-net verification).
pub type Trace = Vec<String>;

/// A place that can receive a second token.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct UnsafeFinding {
    /// `NET.transition` whose firing would put the second token.
    pub transition: String,
    /// `NET.place` or `global.place`.
    pub place: String,
    /// The shortest sequence of events that gets there (the last one triggers the firing).
    pub trace: Trace,
}

/// A stable state from which nothing can fire any more.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DeadFinding {
    /// Active nets with their marked places, global places, running timers.
    pub marking: Vec<String>,
    /// It holds one of the manifest's intended final markings.
    pub intended: bool,
    /// A catastrophic event ended the mission there.
    pub after_catastrophic: bool,
    /// The shortest sequence of events that gets there.
    pub trace: Trace,
}

/// A cycle of immediate transitions: the player would spin.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LivelockFinding {
    /// `NET.transition`s fired in the cycle, in order.
    pub transitions: Vec<String>,
    /// The events that lead to it (the last one starts the cycle; empty: at start).
    pub trace: Trace,
}

/// Two transitions enabled by the same event in the same state, taking a common token.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ConflictFinding {
    /// The event.
    pub event: String,
    /// `NET.transition` that fires (first in dispatch order).
    pub winner: String,
    /// `NET.transition` that does not.
    pub loser: String,
    /// The shortest sequence of events reaching the state where the event shows the conflict.
    pub trace: Trace,
}

/// A reachable stable state that breaks an invariant of the manifest.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InvariantFinding {
    /// The invariant's name.
    pub invariant: String,
    /// The state: active nets with their marked places, global places, running timers.
    pub marking: Vec<String>,
    /// The shortest sequence of events that gets there.
    pub trace: Trace,
}

/// A loop of stable states that needs outside events to go round (the waypoint loop, say).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LoopFinding {
    /// Every event that moves the mission around inside the loop.
    pub events: Vec<String>,
    /// The events of one shortest turn.
    pub turn: Vec<String>,
    /// Stable states in the strongly connected components that show this loop.
    pub states: u64,
    /// How many strongly connected components show this same loop.
    pub components: u64,
}

/// Everything verification found.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Report {
    /// Stable states reached.
    pub states: u64,
    /// Event deliveries that change the state (self-loops included).
    pub edges: u64,
    /// Most tokens in one place over all reachable states (1 unless a place is unsafe, where
    /// Petrel refuses the second token: then 2 is what the net asked for).
    pub max_tokens_in_place: u64,
    /// Most marked places in one reachable state.
    pub max_tokens_per_marking: u64,
    /// No firing ever asks for a second token in a place.
    pub safe: bool,
    /// Some reachable stable state has no way out and is not an intended final marking.
    pub deadlock: bool,
    /// Places that can receive a second token.
    pub unsafe_places: Vec<UnsafeFinding>,
    /// Dead markings, intended or not.
    pub dead_markings: Vec<DeadFinding>,
    /// Cycles of immediate transitions.
    pub livelocks: Vec<LivelockFinding>,
    /// Invariants checked in every reachable stable state.
    pub invariants: Vec<String>,
    /// Invariants broken, each with the shortest trace to a state that breaks it.
    pub invariant_violations: Vec<InvariantFinding>,
    /// Loops that need outside events (information).
    pub event_loops: Vec<LoopFinding>,
    /// Conflicts between transitions enabled by one event.
    pub conflicts: Vec<ConflictFinding>,
    /// `NET.transition`s that never fire.
    pub never_fired: Vec<String>,
    /// Nets never active.
    pub never_activated: Vec<String>,
    /// Declared events that no transition waits for.
    pub unused_events: Vec<String>,
    /// Seconds spent.
    pub seconds: f64,
    /// Each net's template (its declaration in the net files), for locating findings.
    #[serde(skip)]
    pub templates: HashMap<String, String>,
    /// Every reachable stable state, when [`VerifyOptions::keep_states`] asked for them.
    #[serde(skip)]
    pub reachable: Vec<State>,
}

impl Report {
    /// True when nothing needs fixing: safe, no unintended dead marking, no livelock, every
    /// invariant holding.
    pub fn is_clean(&self) -> bool {
        self.safe
            && !self.deadlock
            && self.livelocks.is_empty()
            && self.invariant_violations.is_empty()
    }
}

/// A truth value of a guard the verifier evaluates on representative parameters: known, or
/// not decidable without data it does not track.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Truth {
    True,
    False,
    Unknown,
}

impl Truth {
    fn of(b: bool) -> Truth {
        if b {
            Truth::True
        } else {
            Truth::False
        }
    }
    fn not(self) -> Truth {
        match self {
            Truth::True => Truth::False,
            Truth::False => Truth::True,
            Truth::Unknown => Truth::Unknown,
        }
    }
}

/// The outcomes of undecidable guards for one run of a delivery: the first ones replayed from
/// `prefix`, the rest taken false (and counted, so that the caller explores them true too).
#[derive(Default)]
struct Oracle {
    prefix: Vec<bool>,
    used: usize,
}

impl Oracle {
    fn choose(&mut self) -> bool {
        let c = self.prefix.get(self.used).copied().unwrap_or(false);
        self.used += 1;
        c
    }
}

/// Evaluates a guard on the event's representative parameters. Comparisons of a parameter with
/// a constant are decided; what involves data the verifier does not track (two parameters of
/// the event, a parameter bound at activation) is unknown.
fn truth(g: &Guard, params: &[Value]) -> Truth {
    match g {
        Guard::Const(b) => Truth::of(*b),
        Guard::Not(a) => truth(a, params).not(),
        Guard::And(list) => {
            let mut out = Truth::True;
            for a in list {
                match truth(a, params) {
                    Truth::False => return Truth::False,
                    Truth::Unknown => out = Truth::Unknown,
                    Truth::True => {}
                }
            }
            out
        }
        Guard::Or(list) => {
            let mut out = Truth::False;
            for a in list {
                match truth(a, params) {
                    Truth::True => return Truth::True,
                    Truth::Unknown => out = Truth::Unknown,
                    Truth::False => {}
                }
            }
            out
        }
        Guard::Value(a) => match a {
            Arg::Literal(Value::Bool(b)) => Truth::of(*b),
            Arg::EventParam(i) => match params.get(*i as usize) {
                Some(Value::Bool(b)) => Truth::of(*b),
                _ => Truth::Unknown,
            },
            _ => Truth::Unknown,
        },
        Guard::Compare(op, a, b) => {
            let known = |x: &Arg| -> Option<(Value, bool)> {
                match x {
                    Arg::Literal(v) => Some((v.clone(), false)),
                    Arg::EventParam(i) => params.get(*i as usize).map(|v| (v.clone(), true)),
                    Arg::NetParam(_) => None,
                }
            };
            match (known(a), known(b)) {
                // Two parameters of the event: representatives do not cover their relations.
                (Some((_, true)), Some((_, true))) => Truth::Unknown,
                (Some((x, _)), Some((y, _))) => Truth::of(crate::compiled::compare(*op, &x, &y)),
                _ => Truth::Unknown,
            }
        }
    }
}

/// Collects what one event step did, for the exploration.
#[derive(Default)]
struct Recorder {
    /// The guards of the rules, and the parameters of the event being delivered.
    guards: Vec<Option<Guard>>,
    params: Vec<Value>,
    oracle: Oracle,
    fired: Vec<u32>,
    refused: Vec<(u32, u32)>,
    /// States seen during the current fixpoint (with the number of immediate firings before
    /// each), to find cycles of immediate transitions.
    fixpoint_states: HashMap<State, usize>,
    fixpoint_rules: Vec<u32>,
    livelock: Option<Vec<u32>>,
}

impl Effects for Recorder {
    fn fired(&mut self, rule: u32) {
        self.fired.push(rule);
        self.fixpoint_rules.push(rule);
    }
    fn refused(&mut self, rule: u32, place: u32) {
        self.refused.push((rule, place));
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
        match truth(g, &self.params) {
            Truth::True => true,
            Truth::False => false,
            Truth::Unknown => self.oracle.choose(),
        }
    }
}

impl Recorder {
    fn reset(&mut self) {
        self.oracle.used = 0;
        self.fired.clear();
        self.refused.clear();
        self.fixpoint_states.clear();
        self.fixpoint_rules.clear();
        self.livelock = None;
    }
}

/// How a stable state was first reached.
#[derive(Clone, Copy)]
enum Via {
    Start,
    /// By a delivery, named by its label (an index in the labels of the run).
    Event(u32, u32),
    /// Single-net mode: the environment set (true) or cleared a global place.
    Global(u32, u32, bool),
}

/// One way the environment can deliver an event: to every net or to one, with representative
/// parameters (docs/semantics.md, "What the verifier explores").
struct Delivery {
    event: EventId,
    target: Option<NetId>,
    params: Vec<Value>,
    /// `event`, `event(args)`, `event to NET`, for traces.
    label: String,
}

/// The values a guard can tell apart for one parameter: each constant it is compared with,
/// the intervals between them for numbers (and NaN for floats), and one other value.
fn domain(ty: Type, comparands: &[Value], used: bool) -> Vec<Value> {
    if !used && comparands.is_empty() {
        return vec![ty.neutral()];
    }
    match ty {
        Type::Bool => vec![Value::Bool(false), Value::Bool(true)],
        Type::Text => {
            let mut out: Vec<Value> = Vec::new();
            for c in comparands {
                if let Value::Text(_) = c {
                    if !out.contains(c) {
                        out.push(c.clone());
                    }
                }
            }
            let mut other = String::from("other");
            while out.contains(&Value::Text(other.clone())) {
                other.push('_');
            }
            out.push(Value::Text(other));
            out
        }
        Type::FloatList => {
            let mut out: Vec<Value> = Vec::new();
            for c in comparands {
                if let Value::FloatList(_) = c {
                    if !out.contains(c) {
                        out.push(c.clone());
                    }
                }
            }
            let mut other = Vec::new();
            while out.contains(&Value::FloatList(other.clone())) {
                other.push(0.5);
            }
            out.push(Value::FloatList(other));
            out
        }
        Type::Int | Type::Float => {
            let mut t: Vec<f64> = comparands
                .iter()
                .filter_map(|c| match c {
                    Value::Int(i) => Some(*i as f64),
                    Value::Float(f) if f.is_finite() => Some(*f),
                    _ => None,
                })
                .collect();
            t.sort_by(f64::total_cmp);
            t.dedup();
            if ty == Type::Float {
                let mut out = Vec::new();
                match (t.first(), t.last()) {
                    (Some(&lo), Some(&hi)) => {
                        out.push(lo - 1.0);
                        for (k, &x) in t.iter().enumerate() {
                            out.push(x);
                            if let Some(&y) = t.get(k + 1) {
                                out.push(x + (y - x) / 2.0);
                            }
                        }
                        out.push(hi + 1.0);
                    }
                    _ => out.push(0.0),
                }
                let mut out: Vec<Value> = out.into_iter().map(Value::Float).collect();
                out.push(Value::Float(f64::NAN));
                out
            } else {
                let mut out: Vec<i64> = Vec::new();
                match (t.first(), t.last()) {
                    (Some(&lo), Some(&hi)) => {
                        out.push((lo.ceil() as i64).saturating_sub(1));
                        for (k, &x) in t.iter().enumerate() {
                            if x.fract() == 0.0 {
                                out.push(x as i64);
                            }
                            if let Some(&y) = t.get(k + 1) {
                                let between = (x.floor() as i64).saturating_add(1);
                                if (between as f64) < y && (between as f64) > x {
                                    out.push(between);
                                }
                            }
                        }
                        out.push((hi.floor() as i64).saturating_add(1));
                    }
                    _ => out.push(0),
                }
                out.sort_unstable();
                out.dedup();
                out.into_iter().map(Value::Int).collect()
            }
        }
    }
}

/// What the guards of an event's transitions compare each of its parameters with.
fn comparands(g: &Guard, out: &mut [(Vec<Value>, bool)]) {
    match g {
        Guard::Const(_) => {}
        Guard::Not(a) => comparands(a, out),
        Guard::And(list) | Guard::Or(list) => list.iter().for_each(|a| comparands(a, out)),
        Guard::Value(Arg::EventParam(i)) => {
            if let Some(slot) = out.get_mut(*i as usize) {
                slot.1 = true;
            }
        }
        Guard::Value(_) => {}
        Guard::Compare(_, a, b) => {
            for (x, y) in [(a, b), (b, a)] {
                if let Arg::EventParam(i) = x {
                    if let Some(slot) = out.get_mut(*i as usize) {
                        slot.1 = true;
                        if let Arg::Literal(v) = y {
                            slot.0.push(v.clone());
                        }
                    }
                }
            }
        }
    }
}

/// Every delivery the environment may make: each awaited event, to every net and to each net
/// some `emit ... to` addresses it to, with each combination of its parameters' classes.
fn deliveries(p: &CompiledProject, l: &Layout) -> Result<Vec<Delivery>, VerifyError> {
    use crate::compiled::Action;
    let mut out = Vec::new();
    for e in 0..p.events.len() as EventId {
        if l.by_event[e as usize].is_empty() {
            continue;
        }
        let decl = &p.events[e as usize];
        let mut targets: Vec<Option<NetId>> = vec![None];
        for net in &p.nets {
            for t in &net.transitions {
                for a in &t.actions {
                    if let Action::Emit {
                        event,
                        target: Some(n),
                        ..
                    } = a
                    {
                        if *event == e && !targets.contains(&Some(*n)) {
                            targets.push(Some(*n));
                        }
                    }
                }
            }
        }
        let mut slots: Vec<(Vec<Value>, bool)> = vec![(Vec::new(), false); decl.params.len()];
        for &r in &l.by_event[e as usize] {
            let rule = &l.rules[r as usize];
            if let Some(g) = &p.nets[rule.net as usize].transitions[rule.transition as usize].guard
            {
                comparands(g, &mut slots);
            }
        }
        let domains: Vec<Vec<Value>> = decl
            .params
            .iter()
            .zip(&slots)
            .map(|((_, ty), (c, used))| domain(*ty, c, *used))
            .collect();
        let combinations: usize = domains.iter().map(Vec::len).product();
        if combinations > MAX_GUARD_RUNS {
            return Err(VerifyError::TooManyUndecidedGuards {
                event: decl.name.clone(),
            });
        }
        let shown = domains.iter().any(|d| d.len() > 1);
        let mut tuple = vec![0usize; domains.len()];
        loop {
            let params: Vec<Value> = tuple
                .iter()
                .zip(&domains)
                .map(|(&k, d)| d[k].clone())
                .collect();
            for &target in &targets {
                let mut label = decl.name.clone();
                if shown {
                    label = format!(
                        "{label}({})",
                        params
                            .iter()
                            .map(Value::literal)
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                }
                if let Some(n) = target {
                    label = format!("{label} to {}", p.nets[n as usize].name);
                }
                out.push(Delivery {
                    event: e,
                    target,
                    params: params.clone(),
                    label,
                });
            }
            // The next combination, odometer-wise.
            let mut k = 0;
            loop {
                if k == tuple.len() {
                    break;
                }
                tuple[k] += 1;
                if tuple[k] < domains[k].len() {
                    break;
                }
                tuple[k] = 0;
                k += 1;
            }
            if k == tuple.len() {
                break;
            }
        }
    }
    Ok(out)
}

/// Answers "may this guard hold?" for the conflict check: true unless it is decided false.
struct MayHold<'a> {
    guards: &'a [Option<Guard>],
    params: &'a [Value],
}

impl Effects for MayHold<'_> {
    fn guard(&mut self, rule: u32) -> bool {
        match self.guards.get(rule as usize) {
            Some(Some(g)) => truth(g, self.params) != Truth::False,
            _ => true,
        }
    }
}

/// Verifies a compiled project.
pub fn verify(project: &CompiledProject, mut opts: VerifyOptions) -> Result<Report, VerifyError> {
    let restricted;
    let (p, free_globals) = match &opts.only_net {
        None => (project, false),
        Some(name) => {
            let id = project
                .net_id(name)
                .ok_or_else(|| VerifyError::UnknownNet(name.clone()))?;
            restricted = only_net(project, id);
            (&restricted, true)
        }
    };
    let started = Instant::now();
    let sem = Semantics::new(p);
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
    let mut rec = Recorder {
        guards: guards.clone(),
        ..Recorder::default()
    };
    let mut report = Report {
        safe: true,
        invariants: p.invariants.iter().map(|i| i.name.clone()).collect(),
        ..Report::default()
    };
    let name_of = |r: u32| {
        let rule = &l.rules[r as usize];
        let net = &p.nets[rule.net as usize];
        format!(
            "{}.{}",
            net.name, net.transitions[rule.transition as usize].name
        )
    };
    let deliveries = deliveries(p, l)?;
    let mut labels: Vec<String> = Vec::new();
    let mut label_ids: HashMap<String, u32> = HashMap::new();
    let label_of = |labels: &mut Vec<String>, text: String| -> u32 {
        *label_ids.entry(text.clone()).or_insert_with(|| {
            labels.push(text);
            (labels.len() - 1) as u32
        })
    };
    let mut label_of = label_of;

    let mut ever_fired = vec![false; l.rules.len()];
    let mut ever_active = vec![false; p.nets.len()];
    let mut states: Vec<State> = Vec::new();
    let mut via: Vec<Via> = Vec::new();
    let mut index: HashMap<State, u32> = HashMap::new();
    let mut edges: Vec<(u32, u32, EventId)> = Vec::new();
    let mut unsafe_seen: HashMap<(u32, u32), ()> = HashMap::new();
    let mut conflict_seen: HashMap<(u32, u32), ()> = HashMap::new();
    let mut livelock_seen: HashMap<Vec<u32>, ()> = HashMap::new();
    let mut invariant_seen = vec![false; p.invariants.len()];
    let mut record_step = |rec: &Recorder,
                           from: Option<(u32, u32)>,
                           report: &mut Report,
                           ever_fired: &mut Vec<bool>,
                           via: &[Via],
                           trace_of: &dyn Fn(&[Via], u32) -> Trace,
                           label: &dyn Fn(u32) -> String| {
        for &r in &rec.fired {
            ever_fired[r as usize] = true;
        }
        let trace = || match from {
            None => Vec::new(),
            Some((s, d)) => {
                let mut t = trace_of(via, s);
                t.push(label(d));
                t
            }
        };
        for &(r, place) in &rec.refused {
            if unsafe_seen.insert((r, place), ()).is_none() {
                report.safe = false;
                report.unsafe_places.push(UnsafeFinding {
                    transition: name_of(r),
                    place: l.describe_bit(p, place),
                    trace: trace(),
                });
            }
        }
        if let Some(cycle) = &rec.livelock {
            let mut key = cycle.clone();
            key.sort_unstable();
            if livelock_seen.insert(key, ()).is_none() {
                report.livelocks.push(LivelockFinding {
                    transitions: cycle.iter().map(|&r| name_of(r)).collect(),
                    trace: trace(),
                });
            }
        }
    };

    // The initial states: one per outcome of the guards the start cannot decide.
    let mut prefixes: Vec<Vec<bool>> = vec![Vec::new()];
    let mut runs = 0usize;
    while let Some(prefix) = prefixes.pop() {
        runs += 1;
        if runs > MAX_GUARD_RUNS {
            return Err(VerifyError::TooManyUndecidedGuards {
                event: "(start)".into(),
            });
        }
        rec.reset();
        rec.params.clear();
        rec.oracle.prefix = prefix.clone();
        let initial = sem.initial(&mut rec, &mut scratch);
        let labels_now = labels.clone();
        record_step(
            &rec,
            None,
            &mut report,
            &mut ever_fired,
            &via,
            &|_, _| Vec::new(),
            &|d| labels_now[d as usize].clone(),
        );
        for k in prefix.len()..rec.oracle.used {
            let mut next = prefix.clone();
            next.resize(k, false);
            next.push(true);
            prefixes.push(next);
        }
        if !index.contains_key(&initial) {
            index.insert(initial.clone(), states.len() as u32);
            states.push(initial);
            via.push(Via::Start);
        }
    }

    let trace_of = |via: &[Via], mut s: u32, labels: &[String]| -> Trace {
        let mut out = Vec::new();
        loop {
            match via[s as usize] {
                Via::Start => break,
                Via::Event(prev, d) => {
                    out.push(labels[d as usize].clone());
                    s = prev;
                }
                Via::Global(prev, g, set) => {
                    let verb = if set {
                        "environment marks"
                    } else {
                        "environment empties"
                    };
                    out.push(format!("{verb} global.{}", p.globals[g as usize].name));
                    s = prev;
                }
            }
        }
        out.reverse();
        out
    };

    let mut last_progress = Instant::now();
    let mut next = 0usize;
    let mut candidates = Vec::new();
    while next < states.len() {
        let i = next as u32;
        next += 1;
        if let Some(cb) = opts.progress.as_mut() {
            if last_progress.elapsed().as_secs_f64() >= 1.0 {
                last_progress = Instant::now();
                let secs = started.elapsed().as_secs_f64();
                cb(states.len() as u64, states.len() as f64 / secs.max(1e-9));
            }
        }
        let s = states[next - 1].clone();
        for (n, seen) in ever_active.iter_mut().enumerate() {
            *seen |= l.is_active(&s, n as NetId);
        }
        report.max_tokens_per_marking = report.max_tokens_per_marking.max(l.tokens(&s) as u64);
        for (k, inv) in p.invariants.iter().enumerate() {
            if !invariant_seen[k] && !l.holds(&inv.formula, &s) {
                invariant_seen[k] = true;
                report.invariant_violations.push(InvariantFinding {
                    invariant: inv.name.clone(),
                    marking: l.describe_state(p, &s),
                    trace: trace_of(&via, i, &labels),
                });
            }
        }
        let mut successors: Vec<(State, Via, Option<EventId>)> = Vec::new();
        let mut any_enabled = false;
        if !l.is_over(&s) {
            for d in &deliveries {
                let e = d.event;
                sem.candidates(
                    &s,
                    e,
                    d.target,
                    &mut MayHold {
                        guards: &guards,
                        params: &d.params,
                    },
                    &mut candidates,
                );
                if candidates.is_empty() {
                    continue;
                }
                any_enabled = true;
                for (a, &ra) in candidates.iter().enumerate() {
                    for &rb in &candidates[a + 1..] {
                        if l.share_input(ra, rb) && conflict_seen.insert((ra, rb), ()).is_none() {
                            let mut trace = trace_of(&via, i, &labels);
                            trace.push(d.label.clone());
                            report.conflicts.push(ConflictFinding {
                                event: p.events[e as usize].name.clone(),
                                winner: name_of(ra),
                                loser: name_of(rb),
                                trace,
                            });
                        }
                    }
                }
                // Every outcome of the guards this delivery cannot decide.
                let mut prefixes: Vec<Vec<bool>> = vec![Vec::new()];
                let mut runs = 0usize;
                while let Some(prefix) = prefixes.pop() {
                    runs += 1;
                    if runs > MAX_GUARD_RUNS {
                        return Err(VerifyError::TooManyUndecidedGuards {
                            event: p.events[e as usize].name.clone(),
                        });
                    }
                    let mut t = s.clone();
                    // A timer's event arriving is that timer expiring: it no longer runs.
                    for (k, timer) in p.timers.iter().enumerate() {
                        if timer.event == e {
                            sem.timer_expired(&mut t, k as u32);
                        }
                    }
                    rec.reset();
                    rec.params.clone_from(&d.params);
                    rec.oracle.prefix = prefix.clone();
                    sem.process_event(&mut t, e, d.target, &mut rec, &mut scratch);
                    let decided = rec.oracle.used == 0;
                    for k in prefix.len()..rec.oracle.used {
                        let mut next = prefix.clone();
                        next.resize(k, false);
                        next.push(true);
                        prefixes.push(next);
                    }
                    let text = if decided {
                        d.label.clone()
                    } else {
                        let taken: Vec<&str> = (0..rec.oracle.used)
                            .map(|k| {
                                if prefix.get(k).copied().unwrap_or(false) {
                                    "true"
                                } else {
                                    "false"
                                }
                            })
                            .collect();
                        format!("{} (undecided guards taken {})", d.label, taken.join(", "))
                    };
                    let lid = label_of(&mut labels, text);
                    let labels_now = &labels;
                    record_step(
                        &rec,
                        Some((i, lid)),
                        &mut report,
                        &mut ever_fired,
                        &via,
                        &|v, s| trace_of(v, s, labels_now),
                        &|x| labels_now[x as usize].clone(),
                    );
                    successors.push((t, Via::Event(i, lid), Some(e)));
                }
            }
        }
        if free_globals {
            for g in 0..p.globals.len() as u32 {
                let mut t = s.clone();
                let bit = l.global_base + g;
                let set = !Layout::bit(&t, bit);
                t[(bit / 64) as usize] ^= 1 << (bit % 64);
                // The environment's change may enable immediate transitions.
                rec.reset();
                rec.params.clear();
                rec.oracle.prefix.clear();
                sem.fixpoint(&mut t, &mut rec, &mut scratch);
                let labels_now = &labels;
                record_step(
                    &rec,
                    None,
                    &mut report,
                    &mut ever_fired,
                    &via,
                    &|v, s| trace_of(v, s, labels_now),
                    &|x| labels_now[x as usize].clone(),
                );
                successors.push((t, Via::Global(i, g, set), None));
            }
        }
        for (t, how, event) in successors {
            let j = match index.get(&t) {
                Some(&j) => j,
                None => {
                    let j = states.len() as u32;
                    if let Some(limit) = opts.max_states {
                        if j as u64 >= limit {
                            return Err(VerifyError::TooManyStates { limit });
                        }
                    }
                    index.insert(t.clone(), j);
                    states.push(t);
                    via.push(how);
                    j
                }
            };
            if let Some(e) = event {
                edges.push((i, j, e));
            }
        }
        if !any_enabled {
            let marking = l.describe_state(p, &s);
            let after_catastrophic = l.is_over(&s);
            let intended = after_catastrophic
                || p.finals.iter().any(|f| {
                    f.iter()
                        .all(|&(n, r)| l.is_active(&s, n) || matches!(r, PlaceRef::Global(_)))
                        && f.iter().all(|&(n, r)| l.is_marked(&s, n, r))
                });
            if !intended {
                report.deadlock = true;
            }
            report.dead_markings.push(DeadFinding {
                marking,
                intended,
                after_catastrophic,
                trace: trace_of(&via, i, &labels),
            });
        }
    }

    report.states = states.len() as u64;
    report.edges = edges.len() as u64;
    report.max_tokens_in_place = if report.safe { 1 } else { 2 };
    report.event_loops = event_loops(p, states.len(), &edges);
    report.never_fired = (0..l.rules.len() as u32)
        .filter(|&r| !ever_fired[r as usize])
        .map(name_of)
        .collect();
    report.never_activated = p
        .nets
        .iter()
        .enumerate()
        .filter(|(n, _)| {
            !ever_active[*n]
                && !l
                    .rules
                    .iter()
                    .enumerate()
                    .any(|(r, rule)| rule.net as usize == *n && ever_fired[r])
        })
        .map(|(_, n)| n.name.clone())
        .collect();
    let builtin = |name: &str| {
        crate::model::builtin_events()
            .iter()
            .any(|b| b.name.text == name)
    };
    report.unused_events = (0..p.events.len())
        .filter(|&e| l.by_event[e].is_empty() && !builtin(&p.events[e].name))
        .map(|e| p.events[e].name.clone())
        .collect();
    if opts.keep_states {
        report.reachable = states;
    }
    report.templates = p
        .nets
        .iter()
        .map(|n| (n.name.clone(), n.template.clone()))
        .collect();
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The project reduced to one net, active at start; actions on other nets are dropped.
fn only_net(p: &CompiledProject, id: NetId) -> CompiledProject {
    use crate::compiled::Action;
    let mut net = p.nets[id as usize].clone();
    // Alone: no parent, no children (its completion places stay, never marked).
    net.parent = None;
    net.children.clear();
    for t in &mut net.transitions {
        t.actions.retain(|a| match a {
            Action::Activate { net, .. } | Action::Deactivate(net) => *net == id,
            _ => true,
        });
        for a in &mut t.actions {
            match a {
                Action::Activate { net, .. } | Action::Deactivate(net) => *net = 0,
                Action::Emit { target, .. } => {
                    *target = target.filter(|&n| n == id).map(|_| 0);
                }
                _ => {}
            }
        }
    }
    CompiledProject {
        name: format!("{} (net {} alone)", p.name, net.name),
        nets: vec![net],
        globals: p.globals.clone(),
        events: p.events.clone(),
        programs: p.programs.clone(),
        timers: p.timers.clone(),
        start: vec![0],
        finals: p
            .finals
            .iter()
            .filter(|f| {
                f.iter()
                    .all(|&(n, r)| n == id || matches!(r, PlaceRef::Global(_)))
            })
            .map(|f| f.iter().map(|&(_, r)| (0, r)).collect())
            .collect(),
        // The invariants speak of the whole project.
        invariants: Vec::new(),
    }
}

/// Loops of stable states, one finding per non-trivial strongly connected component, with the
/// events of one turn.
fn event_loops(p: &CompiledProject, n: usize, edges: &[(u32, u32, EventId)]) -> Vec<LoopFinding> {
    let mut adj: Vec<Vec<(u32, EventId)>> = vec![Vec::new(); n];
    for &(a, b, e) in edges {
        adj[a as usize].push((b, e));
    }
    let comp = tarjan(n, &adj);
    let mut size = HashMap::new();
    for &c in &comp {
        *size.entry(c).or_insert(0u64) += 1;
    }
    let mut out = Vec::new();
    let mut done = std::collections::HashSet::new();
    for (a, succ) in adj.iter().enumerate() {
        let c = comp[a];
        if done.contains(&c) {
            continue;
        }
        let cyclic = size[&c] > 1 || succ.iter().any(|&(b, _)| b as usize == a);
        if !cyclic {
            continue;
        }
        done.insert(c);
        // One turn: a shortest path inside the component from `a` back to `a`.
        let turn: Vec<String> = shortest_cycle(a as u32, &adj, &comp)
            .into_iter()
            .map(|e| p.events[e as usize].name.clone())
            .collect();
        let mut inside: Vec<EventId> = Vec::new();
        for (x, succ) in adj.iter().enumerate() {
            if comp[x] != c {
                continue;
            }
            for &(y, e) in succ {
                if comp[y as usize] == c && !inside.contains(&e) {
                    inside.push(e);
                }
            }
        }
        inside.sort_unstable();
        let events: Vec<String> = inside
            .into_iter()
            .map(|e| p.events[e as usize].name.clone())
            .collect();
        // The same loop in many components (a reaction possible in many states) is one finding.
        match out
            .iter_mut()
            .find(|l: &&mut LoopFinding| l.events == events)
        {
            Some(l) => {
                l.states += size[&c];
                l.components += 1;
            }
            None => out.push(LoopFinding {
                events,
                turn,
                states: size[&c],
                components: 1,
            }),
        }
    }
    out
}

fn shortest_cycle(start: u32, adj: &[Vec<(u32, EventId)>], comp: &[u32]) -> Vec<EventId> {
    let c = comp[start as usize];
    let mut prev: HashMap<u32, (u32, EventId)> = HashMap::new();
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(a) = queue.pop_front() {
        for &(b, e) in &adj[a as usize] {
            if comp[b as usize] != c {
                continue;
            }
            if b == start {
                let mut events = vec![e];
                let mut cur = a;
                while cur != start {
                    let (p, ev) = prev[&cur];
                    events.push(ev);
                    cur = p;
                }
                events.reverse();
                return events;
            }
            if let std::collections::hash_map::Entry::Vacant(v) = prev.entry(b) {
                v.insert((a, e));
                queue.push_back(b);
            }
        }
    }
    Vec::new()
}

/// Strongly connected components (iterative Tarjan); returns each node's component id.
fn tarjan(n: usize, adj: &[Vec<(u32, EventId)>]) -> Vec<u32> {
    const UNSEEN: u32 = u32::MAX;
    let mut index = vec![UNSEEN; n];
    let mut low = vec![0u32; n];
    let mut on_stack = vec![false; n];
    let mut comp = vec![UNSEEN; n];
    let mut stack = Vec::new();
    let mut next_index = 0u32;
    let mut next_comp = 0u32;
    for root in 0..n {
        if index[root] != UNSEEN {
            continue;
        }
        let mut call: Vec<(usize, usize)> = vec![(root, 0)];
        index[root] = next_index;
        low[root] = next_index;
        next_index += 1;
        stack.push(root);
        on_stack[root] = true;
        while let Some(&mut (v, ref mut k)) = call.last_mut() {
            if *k < adj[v].len() {
                let w = adj[v][*k].0 as usize;
                *k += 1;
                if index[w] == UNSEEN {
                    index[w] = next_index;
                    low[w] = next_index;
                    next_index += 1;
                    stack.push(w);
                    on_stack[w] = true;
                    call.push((w, 0));
                } else if on_stack[w] {
                    low[v] = low[v].min(index[w]);
                }
            } else {
                call.pop();
                if let Some(&(u, _)) = call.last() {
                    low[u] = low[u].min(low[v]);
                }
                if low[v] == index[v] {
                    while let Some(w) = stack.pop() {
                        on_stack[w] = false;
                        comp[w] = next_comp;
                        if w == v {
                            break;
                        }
                    }
                    next_comp += 1;
                }
            }
        }
    }
    comp
}

fn trace_text(t: &Trace) -> String {
    if t.is_empty() {
        "at start".to_string()
    } else {
        format!("after {}", t.join(" → "))
    }
}

/// The report for people.
pub fn render_human(project_name: &str, r: &Report) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "verified `{project_name}`: {} stable states, {} event deliveries, {:.3} s",
        r.states, r.edges, r.seconds
    );
    let _ = writeln!(
        o,
        "max tokens in a place: {}, max tokens in a marking: {}",
        r.max_tokens_in_place, r.max_tokens_per_marking
    );
    if r.safe {
        let _ = writeln!(o, "safe: yes, no place can receive a second token");
    } else {
        let _ = writeln!(o, "safe: NO, {} unsafe firing(s):", r.unsafe_places.len());
        for u in &r.unsafe_places {
            let _ = writeln!(
                o,
                "  error: {} would put a second token in {}, {}",
                u.transition,
                u.place,
                trace_text(&u.trace)
            );
        }
    }
    let unintended = r.dead_markings.iter().filter(|d| !d.intended).count();
    let _ = writeln!(
        o,
        "dead markings: {} ({} intended, {} not)",
        r.dead_markings.len(),
        r.dead_markings.len() - unintended,
        unintended
    );
    for d in &r.dead_markings {
        let kind = if d.after_catastrophic {
            "end after a catastrophic event"
        } else if d.intended {
            "intended final marking"
        } else {
            "error: dead marking"
        };
        let _ = writeln!(
            o,
            "  {kind}: {}, {}",
            if d.marking.is_empty() {
                "nothing marked".to_string()
            } else {
                d.marking.join(" ")
            },
            trace_text(&d.trace)
        );
    }
    let _ = writeln!(o, "loops of immediate transitions: {}", r.livelocks.len());
    for l in &r.livelocks {
        let _ = writeln!(
            o,
            "  error: immediate transitions loop forever: {}, {}",
            l.transitions.join(" → "),
            trace_text(&l.trace)
        );
    }
    if !r.invariants.is_empty() {
        let _ = writeln!(
            o,
            "invariants: {} checked, {} broken",
            r.invariants.len(),
            r.invariant_violations.len()
        );
        for v in &r.invariant_violations {
            let _ = writeln!(
                o,
                "  error: invariant `{}` is broken in {}, {}",
                v.invariant,
                if v.marking.is_empty() {
                    "a state with nothing marked".to_string()
                } else {
                    v.marking.join(" ")
                },
                trace_text(&v.trace)
            );
        }
    }
    let _ = writeln!(
        o,
        "loops that need outside events (expected): {}",
        r.event_loops.len()
    );
    for l in &r.event_loops {
        let _ = writeln!(
            o,
            "  info: a loop on {{{}}}, {} states in {} component(s); one turn: {}",
            l.events.join(", "),
            l.states,
            l.components,
            l.turn.join(" → ")
        );
    }
    let _ = writeln!(o, "conflicts: {}", r.conflicts.len());
    for c in &r.conflicts {
        let _ = writeln!(
            o,
            "  warning: on {}, {} fires and {} does not (written order), {}",
            c.event,
            c.winner,
            c.loser,
            trace_text(&c.trace)
        );
    }
    let list = |o: &mut String, what: &str, v: &[String]| {
        if v.is_empty() {
            let _ = writeln!(o, "{what}: none");
        } else {
            let _ = writeln!(o, "{what}: {}", v.join(", "));
        }
    };
    list(&mut o, "transitions that never fire", &r.never_fired);
    list(&mut o, "nets never activated", &r.never_activated);
    list(&mut o, "events no transition waits for", &r.unused_events);
    let errors =
        r.unsafe_places.len() + unintended + r.livelocks.len() + r.invariant_violations.len();
    if errors == 0 {
        let _ = writeln!(o, "result: verified, no error");
    } else {
        let _ = writeln!(o, "result: {errors} error(s)");
    }
    o
}

/// The report for tools.
pub fn to_json(r: &Report) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

/// The findings as diagnostics on the project's text, for `petrel check`: errors for unsafe
/// places, unintended dead markings and livelocks; warnings for conflicts, transitions that
/// never fire, nets never activated and events nobody waits for.
pub fn diagnostics(project: &crate::model::Project, r: &Report) -> crate::diag::Diagnostics {
    use crate::diag::{Diagnostic, Diagnostics};
    let mut d = Diagnostics::new();
    let at = |span: Option<crate::source::Span>, diag: Diagnostic| Diagnostic { span, ..diag };
    // An instance's findings point at its template's text.
    let decl_of = |net: &str| {
        let template = r.templates.get(net).map(String::as_str).unwrap_or(net);
        project.nets().find(|n| n.name.text == template)
    };
    let transition_span = |qualified: &str| {
        let (net, t) = qualified.rsplit_once('.')?;
        decl_of(net)?
            .transitions()
            .find(|x| x.name.text == t)
            .map(|x| x.name.span)
    };
    let net_span = |net: &str| decl_of(net).map(|n| n.name.span);
    for v in &r.invariant_violations {
        let span = project
            .manifest
            .invariants
            .iter()
            .find(|i| i.name.text == v.invariant)
            .map(|i| i.name.span);
        d.push(at(
            span,
            Diagnostic::error(
                "E0604",
                Default::default(),
                format!("invariant `{}` is broken: {}", v.invariant, v.marking.join(" ")),
            )
            .label(format!("broken {}", trace_text(&v.trace)))
            .help("the nets can reach a stable state where the formula is false: follow the trace, and fix the nets (or the invariant)"),
        ));
    }
    for u in &r.unsafe_places {
        d.push(at(
            transition_span(&u.transition),
            Diagnostic::error(
                "E0601",
                Default::default(),
                format!("{} can put a second token in {}", u.transition, u.place),
            )
            .label(format!("unsafe firing {}", trace_text(&u.trace)))
            .help("the player refuses such a firing: make sure the place is empty when this transition fires (an extra input, or an empty-place guard)"),
        ));
    }
    for x in r.dead_markings.iter().filter(|x| !x.intended) {
        d.push(
            Diagnostic::global(
                "E0602",
                format!("dead marking {}: {}", trace_text(&x.trace), x.marking.join(" ")),
            )
            .help("no event can move the mission on from there: add a transition out of it, or declare it a planned end in the manifest's [verify] final"),
        );
    }
    for l in &r.livelocks {
        d.push(at(
            l.transitions.first().and_then(|t| transition_span(t)),
            Diagnostic::error(
                "E0603",
                Default::default(),
                format!(
                    "immediate transitions loop forever: {}",
                    l.transitions.join(" → ")
                ),
            )
            .label(format!("the player would spin {}", trace_text(&l.trace)))
            .help("give one transition of the loop a triggering event"),
        ));
    }
    for c in &r.conflicts {
        d.push(at(
            transition_span(&c.loser),
            Diagnostic::warning(
                "W0601",
                Default::default(),
                format!("{} and {} conflict on {}", c.winner, c.loser, c.event),
            )
            .label(format!("does not fire when both are enabled ({})", trace_text(&c.trace)))
            .help("written order decides; if that is intended, no change is needed, otherwise make their input places exclusive"),
        ));
    }
    for t in &r.never_fired {
        let immediate = t.rsplit_once('.').and_then(|(net, name)| {
            decl_of(net)?
                .transitions()
                .find(|x| x.name.text == name)
                .map(|x| x.trigger.is_none())
        });
        let (label, help) = if immediate == Some(true) {
            (
                "never enabled",
                "check its input places (and its guard); remove it if it is dead code, or say it is intended with @allow(W0602, \"why\")",
            )
        } else {
            (
                "never enabled (guard included) when its event comes",
                "check its input places, its guard and its event; remove it if it is dead code, or say it is intended with @allow(W0602, \"why\")",
            )
        };
        d.push(at(
            transition_span(t),
            Diagnostic::warning("W0602", Default::default(), format!("{t} can never fire"))
                .label(label)
                .help(help),
        ));
    }
    for n in &r.never_activated {
        d.push(at(
            net_span(n),
            Diagnostic::warning(
                "W0603",
                Default::default(),
                format!("net `{n}` is never activated"),
            )
            .label("never active")
            .help("list it in `start`, or activate it from a transition"),
        ));
    }
    for e in &r.unused_events {
        let span = project
            .manifest
            .events
            .iter()
            .find(|x| &x.name.text == e)
            .map(|x| x.name.span);
        d.push(at(
            span,
            Diagnostic::warning("W0604", Default::default(), format!("no transition waits for event `{e}`"))
                .label("never used")
                .help("the player will count it as unused each time it comes; remove it, or add a transition `on` it"),
        ));
    }
    d
}
