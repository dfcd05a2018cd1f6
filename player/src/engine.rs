//! The engine: a compiled project and its state, turning events into firings and actions.
//!
//! Sans-I/O and deterministic: the caller gives it events and the time, and receives what to do
//! through a [`Sink`]. The firing itself is [`petrel_nets::semantics`], the code the verifier
//! explores, so what was verified is what runs. Events are dispatched by category (catastrophic
//! first, oldest first within a category); after a catastrophic event nothing more is
//! processed. Processing an event allocates nothing in the steady state: queues and buffers are
//! reused (a test counts allocations).
//!
//! Every event is accounted for: `received = processed + unused + refused + queued` holds
//! after every call ([`Stats`]). A cascade of events produced at one instant is bounded
//! (docs/semantics.md, "Zero-time cascades"): each queued event knows whether a step produced
//! it, and at the bound the produced events still queued are dropped, counted as refused, and
//! `livelock` is raised once ([`Sink::cascade_stopped`]).

use petrel_nets::compiled::{
    Arg, CompiledProject, EventId, FunctionId, NetId, PlaceRef, ProgramId, TimerDuration, TimerId,
    Value,
};
use petrel_nets::model::{Category, Type};
use petrel_nets::semantics::{Effects, Notice, Scratch, Semantics, State, StepOutcome};
use std::collections::VecDeque;

/// Time in microseconds since the mission started (injected: the engine has no clock).
pub type Micros = u64;

/// An argument of a call, borrowed from the net's literal or the triggering event.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ArgValue<'a> {
    /// An int.
    Int(i64),
    /// A float.
    Float(f64),
    /// A bool.
    Bool(bool),
    /// A text.
    Text(&'a str),
    /// A list of floats.
    FloatList(&'a [f64]),
}

impl<'a> ArgValue<'a> {
    /// The value `v`, borrowed.
    pub fn of(v: &'a Value) -> Self {
        match v {
            Value::Int(i) => ArgValue::Int(*i),
            Value::Float(f) => ArgValue::Float(*f),
            Value::Bool(b) => ArgValue::Bool(*b),
            Value::Text(s) => ArgValue::Text(s),
            Value::FloatList(l) => ArgValue::FloatList(l),
        }
    }

    /// Appends the value as the language writes it ([`Value::literal`]) to `out`.
    pub fn write_literal(self, out: &mut String) {
        match self {
            ArgValue::Int(i) => Value::Int(i).write_literal(out),
            ArgValue::Float(f) => petrel_value::write_float(out, f),
            ArgValue::Bool(b) => Value::Bool(b).write_literal(out),
            ArgValue::Text(s) => petrel_value::write_quoted(out, s),
            ArgValue::FloatList(l) => petrel_value::write_float_list(out, l),
        }
    }

    /// An owned copy.
    pub fn to_value(self) -> Value {
        match self {
            ArgValue::Int(i) => Value::Int(i),
            ArgValue::Float(f) => Value::Float(f),
            ArgValue::Bool(b) => Value::Bool(b),
            ArgValue::Text(s) => Value::Text(s.to_string()),
            ArgValue::FloatList(l) => Value::FloatList(l.to_vec()),
        }
    }
}

/// Encodes as the [`Value`] it borrows from (bincode's derive for `Value`: the variant's index,
/// then its field), so that a call goes on the wire without copying its arguments
/// ([`petrel_ipc::CallRef`]). A test compares the bytes.
impl bincode::Encode for ArgValue<'_> {
    fn encode<E: bincode::enc::Encoder>(
        &self,
        encoder: &mut E,
    ) -> Result<(), bincode::error::EncodeError> {
        match *self {
            ArgValue::Int(i) => {
                0u32.encode(encoder)?;
                i.encode(encoder)
            }
            ArgValue::Float(f) => {
                1u32.encode(encoder)?;
                f.encode(encoder)
            }
            ArgValue::Bool(b) => {
                2u32.encode(encoder)?;
                b.encode(encoder)
            }
            ArgValue::Text(s) => {
                3u32.encode(encoder)?;
                s.encode(encoder)
            }
            ArgValue::FloatList(l) => {
                4u32.encode(encoder)?;
                l.encode(encoder)
            }
        }
    }
}

/// The arguments of a call or an emission, resolved lazily (no allocation).
#[derive(Clone, Copy)]
pub struct Args<'a> {
    args: &'a [Arg],
    params: &'a [Value],
    /// The activation arguments of the net whose transition fired.
    net_params: &'a [Value],
}

impl<'a> Args<'a> {
    /// Number of arguments.
    pub fn len(&self) -> usize {
        self.args.len()
    }

    /// True when there is none.
    pub fn is_empty(&self) -> bool {
        self.args.is_empty()
    }

    /// Argument `i`.
    pub fn get(&self, i: usize) -> ArgValue<'a> {
        match &self.args[i] {
            Arg::Literal(v) => ArgValue::of(v),
            // The checker proved the index is in range for the triggering event.
            Arg::EventParam(p) => ArgValue::of(&self.params[*p as usize]),
            // ... and for the net's parameters bound at activation.
            Arg::NetParam(p) => ArgValue::of(&self.net_params[*p as usize]),
        }
    }

    /// Every argument, in order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = ArgValue<'a>> + Clone + 'a {
        let this = *self;
        (0..self.args.len()).map(move |i| this.get(i))
    }
}

/// What the engine asks of the world, and tells it. Every method has a default that ignores it.
pub trait Sink {
    /// The engine took `event` from the queue and is about to process it.
    fn taken(&mut self, _event: EventId, _params: &[Value]) {}
    /// A transition fired.
    fn fired(&mut self, _net: NetId, _transition: u32) {}
    /// `call PROGRAM.FUNCTION(args)`: deliver it (the engine does not wait for an answer).
    fn call(&mut self, _program: ProgramId, _function: FunctionId, _args: Args<'_>) {}
    /// An event was emitted by a net, with its arguments (it is queued by the engine).
    fn emitted(&mut self, _event: EventId, _params: &[Value]) {}
    /// A timer was started; it expires at `deadline`.
    fn timer_started(&mut self, _timer: TimerId, _deadline: Micros) {}
    /// A timer was cancelled.
    fn timer_cancelled(&mut self, _timer: TimerId) {}
    /// A firing was refused: it would have put a second token in `place` (a description such
    /// as `NET.place`). A `safety_violation` event is queued too.
    fn safety_violation(&mut self, _net: NetId, _transition: u32, _place: &str) {}
    /// A transition lost a conflict on the current event.
    fn conflict(&mut self, _net: NetId, _transition: u32) {}
    /// `activate` of an active net, `deactivate` of an inactive one.
    fn notice(&mut self, _notice: Notice) {}
    /// A net was activated.
    fn activated(&mut self, _net: NetId) {}
    /// A net was deactivated.
    fn deactivated(&mut self, _net: NetId) {}
    /// The immediate fixpoint did not settle and was stopped; a `livelock` event is queued.
    fn livelock(&mut self) {}
    /// A zero-time cascade reached the bound (docs/semantics.md, "Zero-time cascades"): after
    /// `steps` steps on produced events, the `dropped` produced events still queued were
    /// dropped (counted as refused); a `livelock` event is queued the first time in a cascade.
    fn cascade_stopped(&mut self, _steps: u32, _dropped: u64) {}
    /// Invariant `name` of the manifest stopped holding after the step; an
    /// `invariant_violated` event is queued.
    fn invariant_violated(&mut self, _name: &str) {}
    /// The engine raised a built-in event about a step (`safety_violation`, `livelock`,
    /// `invariant_violated`), with its parameters; it is queued like an emitted event.
    fn raised(&mut self, _event: EventId, _params: &[Value]) {}
}

/// A sink that ignores everything.
pub struct NullSink;
impl Sink for NullSink {}

/// Why an event was not accepted.
#[derive(Clone, Debug, PartialEq)]
pub enum Refusal {
    /// No event of this name is declared.
    UnknownEvent(String),
    /// Wrong number of parameters.
    Arity {
        /// The event.
        event: String,
        /// Declared count.
        expected: usize,
        /// Given count.
        found: usize,
    },
    /// A parameter of the wrong type.
    ParamType {
        /// The event.
        event: String,
        /// The parameter's name.
        param: String,
        /// Declared type.
        expected: Type,
        /// Given type.
        found: Type,
    },
    /// A catastrophic event was processed: the mission is over.
    AfterCatastrophic(String),
    /// The event was queued when the project was reloaded, and the new version cannot take it
    /// (it no longer declares it, or with other parameters, or its target net is gone).
    Reloaded(String),
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::UnknownEvent(e) => write!(f, "unknown event `{e}`: the project declares no such event"),
            Refusal::Arity {
                event,
                expected,
                found,
            } => write!(f, "event `{event}` takes {expected} parameter(s), {found} given"),
            Refusal::ParamType {
                event,
                param,
                expected,
                found,
            } => write!(f, "parameter `{param}` of event `{event}` is {expected}, {found} given"),
            Refusal::AfterCatastrophic(e) => write!(
                f,
                "event `{e}` refused: a catastrophic event ended the mission, no further event is processed"
            ),
            Refusal::Reloaded(why) => write!(f, "refused at the reload: {why}"),
        }
    }
}

/// Counters that account for every event: `received == processed + unused + refused + queued`,
/// on every path: an event refused at its submission (unknown, wrong parameters, after a
/// catastrophic event) is received and refused at once, one refused when taken (after a
/// catastrophic event) was received when it was queued, and a message the player refuses
/// before it could be submitted (undecodable, a built-in event from another process) is
/// counted with [`Engine::count_refused`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Events submitted (from outside, from nets, from timers, built-ins), accepted into the
    /// queue or refused.
    pub received: u64,
    /// Events that fired or offered at least one transition.
    pub processed: u64,
    /// Events no transition waited for in the state they found.
    pub unused: u64,
    /// Events refused (at submission or, after a catastrophic event, when taken).
    pub refused: u64,
}

/// Where a queued event comes from: outside, or produced by a step (docs/semantics.md,
/// "Zero-time cascades").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Origin {
    /// Submitted (a program, the operator, a timer, a report of the player's loop).
    Outside,
    /// Emitted by this transition of this net.
    Emitted(NetId, u32),
    /// Raised by the engine about a step: `safety_violation`, `livelock`, `invariant_violated`.
    Raised,
}

/// One event waiting in the queue.
#[derive(Debug)]
struct Queued {
    event: EventId,
    params: Vec<Value>,
    /// The one net it is addressed to, if any.
    target: Option<NetId>,
    origin: Origin,
}

/// The zero-time cascade under way: steps taken on produced events while some stay queued.
#[derive(Clone, Copy, Debug, Default)]
struct Cascade {
    /// Produced events in the queue.
    queued: u64,
    /// Steps taken on produced events since none was queued.
    steps: u32,
    /// The bound was reached in this cascade (its `livelock` raised).
    stopped: bool,
    /// The transition that emitted the last emitted event the cascade took.
    emitter: Option<(NetId, u32)>,
}

/// What one step did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Step {
    /// The event taken from the queue.
    pub event: EventId,
    /// What became of it.
    pub outcome: StepOutcome,
}

/// The engine.
pub struct Engine<'p> {
    sem: Semantics<'p>,
    state: State,
    scratch: Scratch,
    queues: [VecDeque<Queued>; 5],
    deadlines: Vec<Option<Micros>>,
    now: Micros,
    stats: Stats,
    /// Parameter vectors given back after processing, reused for later events.
    pool: Vec<Vec<Value>>,
    /// Events emitted during the current step, queued once it is over.
    emitted: Vec<Queued>,
    started: bool,
    /// Ids of the built-in events the engine raises itself.
    safety_violation: Option<EventId>,
    livelock: Option<EventId>,
    invariant_violated: Option<EventId>,
    /// Each net's activation arguments (empty for nets whose parameters are not bound at
    /// activation), kept while it is active.
    net_args: Vec<Vec<Value>>,
    /// Each invariant held after the previous step: a violation is raised once, when it stops
    /// holding.
    invariant_held: Vec<bool>,
    cascade: Cascade,
}

fn category_index(c: Category) -> usize {
    petrel_nets::semantics::queue_index(c)
}

impl<'p> Engine<'p> {
    /// An engine for `project`, not started yet (see [`Engine::start`]).
    pub fn new(project: &'p CompiledProject) -> Self {
        let sem = Semantics::new(project);
        let words = sem.layout.words;
        Engine {
            state: vec![0; words],
            sem,
            scratch: Scratch::default(),
            queues: Default::default(),
            deadlines: vec![None; project.timers.len()],
            now: 0,
            stats: Stats::default(),
            pool: Vec::new(),
            emitted: Vec::new(),
            started: false,
            safety_violation: project.event_id("safety_violation"),
            livelock: project.event_id("livelock"),
            invariant_violated: project.event_id("invariant_violated"),
            net_args: project
                .nets
                .iter()
                .map(|n| Vec::with_capacity(n.params.len()))
                .collect(),
            invariant_held: vec![true; project.invariants.len()],
            cascade: Cascade::default(),
        }
    }

    /// Sets the most immediate firings one fixpoint may do before it is a livelock.
    pub fn set_fixpoint_bound(&mut self, bound: u32) {
        self.sem.fixpoint_bound = bound;
    }

    /// Sets the most steps a zero-time cascade may take before it is stopped
    /// ([`petrel_nets::semantics::CASCADE_BOUND`] by default).
    pub fn set_cascade_bound(&mut self, bound: u32) {
        self.sem.cascade_bound = bound;
    }

    /// Steps the zero-time cascade under way has taken (0 when no produced event is queued).
    pub fn cascade_steps(&self) -> u32 {
        self.cascade.steps
    }

    /// The project.
    pub fn project(&self) -> &'p CompiledProject {
        self.sem.project
    }

    /// Starts the mission at time `now`: global places marked, start nets activated, immediate
    /// transitions run. Their actions go to `sink`.
    pub fn start(&mut self, now: Micros, sink: &mut impl Sink) {
        self.now = now;
        let mut fx = Adapter {
            sink,
            sem: &self.sem,
            params: &[],
            deadlines: &mut self.deadlines,
            now,
            emitted: &mut self.emitted,
            pool: &mut self.pool,
            net_args: &mut self.net_args,
            violations: Vec::new(),
            livelock: None,
            last_fired: None,
        };
        self.state = self.sem.initial(&mut fx, &mut self.scratch);
        let violations = std::mem::take(&mut fx.violations);
        let livelock = fx.livelock;
        self.after_step(violations, livelock, sink);
        self.started = true;
    }

    /// The current time.
    pub fn now(&self) -> Micros {
        self.now
    }

    /// The counters.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Events waiting.
    pub fn queued(&self) -> usize {
        self.queues.iter().map(VecDeque::len).sum()
    }

    /// True once a catastrophic event has been processed.
    pub fn is_over(&self) -> bool {
        self.sem.layout.is_over(&self.state)
    }

    /// Where each part of the project lives in [`Engine::state`].
    pub fn layout(&self) -> &petrel_nets::semantics::Layout {
        &self.sem.layout
    }

    /// The state, as bits (see [`petrel_nets::semantics::Layout`]).
    pub fn state(&self) -> &[u64] {
        &self.state
    }

    /// True if net `n` is active.
    pub fn is_active(&self, n: NetId) -> bool {
        self.sem.layout.is_active(&self.state, n)
    }

    /// True if place `r` of net `n` is marked.
    pub fn is_marked(&self, n: NetId, r: PlaceRef) -> bool {
        self.sem.layout.is_marked(&self.state, n, r)
    }

    /// The marked places of each active net, then the marked global places (key `global`).
    pub fn marking(&self) -> Vec<(String, Vec<String>)> {
        let p = self.sem.project;
        let mut out = Vec::new();
        for (n, net) in p.nets.iter().enumerate() {
            if !self.is_active(n as NetId) {
                continue;
            }
            let marked = net
                .places
                .iter()
                .enumerate()
                .filter(|(i, _)| self.is_marked(n as NetId, PlaceRef::Local(*i as u32)))
                .map(|(_, pl)| pl.name.clone())
                .collect();
            out.push((net.name.clone(), marked));
        }
        let globals = p
            .globals
            .iter()
            .enumerate()
            .filter(|(g, _)| self.is_marked(0, PlaceRef::Global(*g as u32)))
            .map(|(_, gp)| gp.name.clone())
            .collect();
        out.push(("global".to_string(), globals));
        out
    }

    /// A parameter vector to fill for [`Engine::submit`], reused from processed events.
    pub fn param_buffer(&mut self) -> Vec<Value> {
        self.pool.pop().unwrap_or_default()
    }

    /// Queues an event after checking its parameters against the declaration.
    pub fn submit(&mut self, event: EventId, params: Vec<Value>) -> Result<(), Refusal> {
        self.submit_with(event, params, |_| {})
    }

    /// [`submit`](Self::submit), calling `accepted` with the parameters once they are checked
    /// and before the event is queued (the player journals the event there, from the
    /// parameters the engine keeps, without a copy). Not called for a refused event.
    pub fn submit_with(
        &mut self,
        event: EventId,
        params: Vec<Value>,
        accepted: impl FnOnce(&[Value]),
    ) -> Result<(), Refusal> {
        let p = self.sem.project;
        // Every submission is received: the refusals below count as refused besides.
        self.stats.received += 1;
        let Some(decl) = p.events.get(event as usize) else {
            self.stats.refused += 1;
            return Err(Refusal::UnknownEvent(format!("#{event}")));
        };
        if self.is_over() {
            self.stats.refused += 1;
            self.recycle(params);
            return Err(Refusal::AfterCatastrophic(decl.name.clone()));
        }
        if decl.params.len() != params.len() {
            self.stats.refused += 1;
            let found = params.len();
            self.recycle(params);
            return Err(Refusal::Arity {
                event: decl.name.clone(),
                expected: decl.params.len(),
                found,
            });
        }
        for ((name, ty), v) in decl.params.iter().zip(&params) {
            if v.ty() != *ty {
                self.stats.refused += 1;
                let r = Refusal::ParamType {
                    event: decl.name.clone(),
                    param: name.clone(),
                    expected: *ty,
                    found: v.ty(),
                };
                self.recycle(params);
                return Err(r);
            }
        }
        accepted(&params);
        self.queues[category_index(decl.category)].push_back(Queued {
            event,
            params,
            target: None,
            origin: Origin::Outside,
        });
        Ok(())
    }

    /// Queues an event addressed to one net (`target`), as `emit EVENT to NET` does; `None`
    /// queues it for every net, as [`Engine::submit`] does.
    pub fn submit_to(
        &mut self,
        event: EventId,
        params: Vec<Value>,
        target: Option<NetId>,
    ) -> Result<(), Refusal> {
        self.submit(event, params)?;
        if target.is_some() {
            let cat = category_index(self.sem.project.events[event as usize].category);
            if let Some(last) = self.queues[cat].back_mut() {
                last.target = target;
            }
        }
        Ok(())
    }

    /// Drops every queued event (counted as refused, so the accounting still balances), and
    /// returns how many there were: for analyses that deliver events one at a time.
    pub fn discard_queued(&mut self) -> usize {
        let mut n = 0;
        for q in &mut self.queues {
            n += q.len();
            q.clear();
        }
        self.stats.refused += n as u64;
        self.cascade = Cascade::default();
        n
    }

    /// Queues an event by name.
    pub fn submit_named(&mut self, name: &str, params: Vec<Value>) -> Result<(), Refusal> {
        self.submit_named_with(name, params, |_| {})
    }

    /// [`submit_named`](Self::submit_named) with [`submit_with`](Self::submit_with)'s
    /// `accepted`.
    pub fn submit_named_with(
        &mut self,
        name: &str,
        params: Vec<Value>,
        accepted: impl FnOnce(&[Value]),
    ) -> Result<(), Refusal> {
        match self.sem.project.event_id(name) {
            Some(e) => self.submit_with(e, params, accepted),
            None => {
                self.count_refused();
                self.recycle(params);
                Err(Refusal::UnknownEvent(name.to_string()))
            }
        }
    }

    /// Counts a message refused before it could be submitted (one that did not decode, a
    /// built-in event another process sent): received and refused, so that `received =
    /// processed + unused + refused + queued` accounts for every message the player took.
    pub fn count_refused(&mut self) {
        self.stats.received += 1;
        self.stats.refused += 1;
    }

    fn recycle(&mut self, mut params: Vec<Value>) {
        params.clear();
        if self.pool.len() < 1024 {
            self.pool.push(params);
        }
    }

    /// Replaces the state (active nets, markings, timers' running flags) with `state`, of
    /// [`Layout::words`](petrel_nets::semantics::Layout) words: for a shadow re-synchronising on
    /// its vehicle. Queued events are kept; timers' deadlines are not changed.
    pub fn set_state(&mut self, state: &[u64]) {
        if state.len() == self.state.len() {
            self.state.copy_from_slice(state);
        }
    }

    /// Puts the engine in a recorded state between two steps (a journal's checkpoint): time
    /// `now`, `state` of [`Layout::words`](petrel_nets::semantics::Layout) words, the timers'
    /// `deadlines`; the queue is emptied and the engine counts as started. False (and nothing
    /// changed) when the state or the deadlines are not of this project's size.
    pub fn restore(&mut self, now: Micros, state: &[u64], deadlines: &[Option<Micros>]) -> bool {
        if state.len() != self.state.len() || deadlines.len() != self.deadlines.len() {
            return false;
        }
        for i in 0..self.queues.len() {
            while let Some(Queued { params, .. }) = self.queues[i].pop_front() {
                self.recycle(params);
            }
        }
        self.cascade = Cascade::default();
        self.now = now;
        self.state.copy_from_slice(state);
        self.deadlines.copy_from_slice(deadlines);
        self.started = true;
        true
    }

    /// Processes `event` at once, as a step the vehicle took: whatever is queued is dropped
    /// first (the vehicle reports the steps of its own emitted and timer events), parameters
    /// are neutral values of the declared types (they steer no firing), and what the step
    /// queues is dropped after it. For a shadow, which must follow, not decide.
    pub fn follow(&mut self, event: EventId, sink: &mut impl Sink) -> Option<Step> {
        for q in &mut self.queues {
            q.clear();
        }
        let decl = self.sem.project.events.get(event as usize)?;
        let params = decl
            .params
            .iter()
            .map(|(_, t)| match t {
                Type::Int => Value::Int(0),
                Type::Float => Value::Float(0.0),
                Type::Bool => Value::Bool(false),
                Type::Text => Value::Text(String::new()),
                Type::FloatList => Value::FloatList(Vec::new()),
            })
            .collect();
        self.submit(event, params).ok()?;
        let step = self.step(sink);
        for q in &mut self.queues {
            q.clear();
        }
        self.cascade = Cascade::default();
        step
    }

    /// Every net's activation arguments, by net.
    pub fn all_net_args(&self) -> &[Vec<Value>] {
        &self.net_args
    }

    /// The queue as [`Engine::take_queue`] would give it, without emptying it.
    pub fn queued_names(&self) -> Vec<(String, Vec<Value>, Option<String>)> {
        let p = self.sem.project;
        self.queues
            .iter()
            .flatten()
            .map(|q| {
                (
                    p.events[q.event as usize].name.clone(),
                    q.params.clone(),
                    q.target.map(|n| p.nets[n as usize].name.clone()),
                )
            })
            .collect()
    }

    /// Empties the queue, for a reload: each event by name, with its parameters and the name
    /// of the net it is addressed to, highest category first, oldest first within one. The
    /// counters still count them as received: [`Engine::adopt`] settles them.
    pub fn take_queue(&mut self) -> Vec<(String, Vec<Value>, Option<String>)> {
        let p = self.sem.project;
        let mut out = Vec::new();
        for q in &mut self.queues {
            for Queued {
                event,
                params,
                target,
                ..
            } in q.drain(..)
            {
                out.push((
                    p.events[event as usize].name.clone(),
                    params,
                    target.map(|n| p.nets[n as usize].name.clone()),
                ));
            }
        }
        // What a new version takes over comes to it from outside (`Engine::adopt`).
        self.cascade = Cascade::default();
        out
    }

    /// Takes over from the engine of the version a reload replaces (docs/semantics.md): time
    /// `now`, the mapped `state`, `deadlines` and activation arguments, the old engine's
    /// counters, and its queued events ([`Engine::take_queue`]) in order, each by name
    /// (addressed nets renamed by `renamed_nets`). An event the new version cannot take is
    /// refused and counted so, and returned with the reason: `received = processed + unused +
    /// refused + queued` still holds. False (and nothing changed) when the sizes are not this
    /// project's.
    #[allow(clippy::too_many_arguments)]
    pub fn adopt(
        &mut self,
        now: Micros,
        state: &[u64],
        deadlines: &[Option<Micros>],
        net_args: Vec<Vec<Value>>,
        stats: Stats,
        queued: Vec<(String, Vec<Value>, Option<String>)>,
        renamed_nets: &std::collections::BTreeMap<String, String>,
    ) -> Option<Vec<(String, Refusal)>> {
        if !self.restore(now, state, deadlines) || net_args.len() != self.net_args.len() {
            return None;
        }
        self.net_args = net_args;
        self.stats = stats;
        for (k, inv) in self.sem.project.invariants.iter().enumerate() {
            self.invariant_held[k] = self.sem.layout.holds(&inv.formula, &self.state);
        }
        let mut refused = Vec::new();
        for (name, params, target) in queued {
            let p = self.sem.project;
            let target_id = match &target {
                None => Ok(None),
                Some(t) => {
                    let t = renamed_nets.get(t).unwrap_or(t);
                    p.net_id(t).map(Some).ok_or_else(|| {
                        Refusal::Reloaded(format!(
                            "event `{name}` is addressed to net `{t}`, which the new version does not have"
                        ))
                    })
                }
            };
            let result = match (target_id, p.event_id(&name)) {
                (Err(r), _) => {
                    self.stats.refused += 1;
                    Err(r)
                }
                (Ok(_), None) => {
                    self.stats.refused += 1;
                    Err(Refusal::Reloaded(format!(
                        "the new version does not declare event `{name}`"
                    )))
                }
                (Ok(t), Some(e)) => {
                    // Counted as received once already, when it first arrived: submitted
                    // again, it is received again (and refused, if it is).
                    self.stats.received -= 1;
                    self.submit_to(e, params, t)
                }
            };
            if let Err(r) = result {
                refused.push((name, r));
            }
        }
        Some(refused)
    }

    /// Each timer's deadline, if it runs.
    pub fn deadlines(&self) -> &[Option<Micros>] {
        &self.deadlines
    }

    /// The earliest running timer's deadline.
    pub fn next_deadline(&self) -> Option<Micros> {
        self.deadlines.iter().flatten().min().copied()
    }

    /// Moves time to `now`: every timer whose deadline has passed stops, and its event is
    /// queued (earliest deadline first, then timer order).
    pub fn advance_to(&mut self, now: Micros) {
        self.now = self.now.max(now);
        while let Some((t, _)) = self
            .deadlines
            .iter()
            .enumerate()
            .filter_map(|(t, d)| d.filter(|&d| d <= self.now).map(|d| (t, d)))
            .min_by_key(|&(t, d)| (d, t))
        {
            self.deadlines[t] = None;
            self.sem.timer_expired(&mut self.state, t as TimerId);
            let event = self.sem.project.timers[t].event;
            let params = self.param_buffer();
            // A timer's event has no parameters; refusal happens only after a catastrophic
            // event, and is counted.
            let _ = self.submit(event, params);
        }
    }

    /// Takes the next event (highest category, oldest first) and processes it. `None` when the
    /// queue is empty.
    pub fn step(&mut self, sink: &mut impl Sink) -> Option<Step> {
        let q = self.queues.iter_mut().find(|q| !q.is_empty())?;
        let Queued {
            event,
            params,
            target,
            origin,
        } = q.pop_front()?;
        if origin != Origin::Outside {
            self.cascade.queued = self.cascade.queued.saturating_sub(1);
            self.cascade.steps += 1;
            if let Origin::Emitted(net, t) = origin {
                self.cascade.emitter = Some((net, t));
            }
        }
        sink.taken(event, &params);
        if self.is_over() {
            self.stats.refused += 1;
            self.recycle(params);
            self.bound_cascade(sink);
            return Some(Step {
                event,
                outcome: StepOutcome::RefusedAfterCatastrophic,
            });
        }
        let mut fx = Adapter {
            sink,
            sem: &self.sem,
            params: &params,
            deadlines: &mut self.deadlines,
            now: self.now,
            emitted: &mut self.emitted,
            pool: &mut self.pool,
            net_args: &mut self.net_args,
            violations: Vec::new(),
            livelock: None,
            last_fired: None,
        };
        let outcome =
            self.sem
                .process_event(&mut self.state, event, target, &mut fx, &mut self.scratch);
        let violations = std::mem::take(&mut fx.violations);
        let livelock = fx.livelock;
        match outcome {
            StepOutcome::Processed => self.stats.processed += 1,
            StepOutcome::Unused => self.stats.unused += 1,
            StepOutcome::RefusedAfterCatastrophic => self.stats.refused += 1,
        }
        self.recycle(params);
        self.after_step(violations, livelock, sink);
        self.bound_cascade(sink);
        Some(Step { event, outcome })
    }

    /// Queues what a step produced (emitted by a net, or raised by the engine about it): part
    /// of the zero-time cascade (docs/semantics.md, "Zero-time cascades").
    fn queue_produced(
        &mut self,
        event: EventId,
        params: Vec<Value>,
        target: Option<NetId>,
        origin: Origin,
    ) {
        // Types were checked statically; only a catastrophic end can refuse (counted).
        if self.submit_to(event, params, target).is_ok() {
            let cat = category_index(self.sem.project.events[event as usize].category);
            if let Some(last) = self.queues[cat].back_mut() {
                last.origin = origin;
            }
            self.cascade.queued += 1;
        }
    }

    /// Queues a built-in event the engine raises about a step, telling the sink first.
    fn raise(&mut self, event: EventId, params: Vec<Value>, sink: &mut impl Sink) {
        sink.raised(event, &params);
        self.queue_produced(event, params, None, Origin::Raised);
    }

    /// After a step: the cascade ends when no produced event is left; at the bound, the
    /// produced events still queued are dropped (counted as refused) and `livelock` is raised,
    /// once per cascade (docs/semantics.md, "Zero-time cascades").
    fn bound_cascade(&mut self, sink: &mut impl Sink) {
        if self.cascade.queued > 0 && self.cascade.steps >= self.sem.cascade_bound {
            let mut dropped = 0u64;
            for k in 0..self.queues.len() {
                let before = self.queues[k].len();
                let mut kept = VecDeque::with_capacity(before);
                while let Some(q) = self.queues[k].pop_front() {
                    if q.origin == Origin::Outside {
                        kept.push_back(q);
                    } else {
                        self.recycle(q.params);
                    }
                }
                dropped += (before - kept.len()) as u64;
                self.queues[k] = kept;
            }
            self.stats.refused += dropped;
            self.cascade.queued = 0;
            sink.cascade_stopped(self.cascade.steps, dropped);
            if !std::mem::replace(&mut self.cascade.stopped, true) {
                if let Some(e) = self.livelock {
                    let p = self.sem.project;
                    let (net, transition) = match self.cascade.emitter {
                        Some((n, t)) => {
                            let n = &p.nets[n as usize];
                            (n.name.clone(), n.transitions[t as usize].name.clone())
                        }
                        None => (String::new(), String::new()),
                    };
                    let params = vec![Value::Text(net), Value::Text(transition)];
                    self.raise(e, params, sink);
                }
            }
        }
        if self.cascade.queued == 0 {
            self.cascade = Cascade::default();
        }
    }

    /// Queues what the step produced: emitted events, then built-in reports; then checks the
    /// invariants on the stable state the step reached.
    fn after_step(
        &mut self,
        violations: Vec<(NetId, u32, String)>,
        livelock: Option<(NetId, u32)>,
        sink: &mut impl Sink,
    ) {
        let mut emitted = std::mem::take(&mut self.emitted);
        for q in emitted.drain(..) {
            self.queue_produced(q.event, q.params, q.target, q.origin);
        }
        // The buffer goes back for the next step: no allocation in the steady state.
        self.emitted = emitted;
        let p = self.sem.project;
        for (k, inv) in p.invariants.iter().enumerate() {
            let holds = self.sem.layout.holds(&inv.formula, &self.state);
            if !holds && self.invariant_held[k] {
                sink.invariant_violated(&inv.name);
                if let Some(e) = self.invariant_violated {
                    let mut params = self.param_buffer();
                    params.push(Value::Text(inv.name.clone()));
                    self.raise(e, params, sink);
                }
            }
            self.invariant_held[k] = holds;
        }
        let p = self.sem.project;
        for (net, t, place) in violations {
            if let Some(e) = self.safety_violation {
                let n = &p.nets[net as usize];
                let params = vec![
                    Value::Text(n.name.clone()),
                    Value::Text(n.transitions[t as usize].name.clone()),
                    Value::Text(place),
                ];
                self.raise(e, params, sink);
            }
        }
        if let (Some((net, t)), Some(e)) = (livelock, self.livelock) {
            let n = &p.nets[net as usize];
            let params = vec![
                Value::Text(n.name.clone()),
                Value::Text(n.transitions[t as usize].name.clone()),
            ];
            self.raise(e, params, sink);
        }
    }

    /// Whether each invariant of the manifest holds in the current state.
    pub fn invariants_holding(&self) -> &[bool] {
        &self.invariant_held
    }

    /// The activation arguments of net `n` (empty unless its parameters are bound at
    /// activation and it was activated).
    pub fn net_args(&self, n: NetId) -> &[Value] {
        &self.net_args[n as usize]
    }

    /// Processes events until the queue is empty; returns how many were taken.
    pub fn run_until_idle(&mut self, sink: &mut impl Sink) -> u64 {
        let mut n = 0;
        while self.step(sink).is_some() {
            n += 1;
        }
        n
    }
}

/// Turns the firing code's effects into sink calls and engine bookkeeping.
struct Adapter<'a, 'p, S: Sink> {
    sink: &'a mut S,
    sem: &'a Semantics<'p>,
    params: &'a [Value],
    deadlines: &'a mut Vec<Option<Micros>>,
    now: Micros,
    emitted: &'a mut Vec<Queued>,
    pool: &'a mut Vec<Vec<Value>>,
    net_args: &'a mut Vec<Vec<Value>>,
    violations: Vec<(NetId, u32, String)>,
    /// The last transition fired when the fixpoint was stopped.
    livelock: Option<(NetId, u32)>,
    last_fired: Option<(NetId, u32)>,
}

impl<S: Sink> Effects for Adapter<'_, '_, S> {
    fn fired(&mut self, rule: u32) {
        let r = &self.sem.layout.rules[rule as usize];
        self.last_fired = Some((r.net, r.transition));
        self.sink.fired(r.net, r.transition);
    }

    fn refused(&mut self, rule: u32, place: u32) {
        let r = &self.sem.layout.rules[rule as usize];
        let name = self.sem.layout.describe_bit(self.sem.project, place);
        self.sink.safety_violation(r.net, r.transition, &name);
        self.violations.push((r.net, r.transition, name));
    }

    fn conflict(&mut self, rule: u32) {
        let r = &self.sem.layout.rules[rule as usize];
        self.sink.conflict(r.net, r.transition);
    }

    fn call(&mut self, program: ProgramId, function: FunctionId, args: &[Arg]) {
        let net = self.last_fired.map_or(0, |(n, _)| n) as usize;
        self.sink.call(
            program,
            function,
            Args {
                args,
                params: self.params,
                net_params: &self.net_args[net],
            },
        );
    }

    fn emit(&mut self, event: EventId, args: &[Arg], target: Option<NetId>) {
        let mut params = self.pool.pop().unwrap_or_default();
        let net = self.last_fired.map_or(0, |(n, _)| n) as usize;
        let a = Args {
            args,
            params: self.params,
            net_params: &self.net_args[net],
        };
        params.extend(a.iter().map(ArgValue::to_value));
        self.sink.emitted(event, &params);
        let (net, transition) = self.last_fired.unwrap_or((0, 0));
        self.emitted.push(Queued {
            event,
            params,
            target,
            origin: Origin::Emitted(net, transition),
        });
    }

    fn guard(&mut self, rule: u32) -> bool {
        let r = &self.sem.layout.rules[rule as usize];
        let t = &self.sem.project.nets[r.net as usize].transitions[r.transition as usize];
        match &t.guard {
            Some(g) => g.holds(self.params, &self.net_args[r.net as usize]),
            None => true,
        }
    }

    fn start_timer(&mut self, timer: TimerId, after: &TimerDuration) {
        let net = self.last_fired.map_or(0, |(n, _)| n) as usize;
        let micros = match after {
            TimerDuration::Millis(ms) => ms.saturating_mul(1000),
            TimerDuration::EventParamSeconds(_) | TimerDuration::NetParamSeconds(_) => {
                let value = match after {
                    TimerDuration::EventParamSeconds(i) => self.params.get(*i as usize),
                    TimerDuration::NetParamSeconds(i) => self.net_args[net].get(*i as usize),
                    TimerDuration::Millis(_) => None,
                };
                let secs = match value {
                    Some(Value::Int(v)) => *v as f64,
                    Some(Value::Float(v)) => *v,
                    _ => 0.0,
                };
                // Negative or not-a-number durations count as zero (docs/semantics.md).
                if secs.is_finite() && secs > 0.0 {
                    (secs * 1e6).min(u64::MAX as f64) as u64
                } else {
                    0
                }
            }
        };
        let deadline = self.now.saturating_add(micros);
        self.deadlines[timer as usize] = Some(deadline);
        self.sink.timer_started(timer, deadline);
    }

    fn cancel_timer(&mut self, timer: TimerId) {
        self.deadlines[timer as usize] = None;
        self.sink.timer_cancelled(timer);
    }

    fn notice(&mut self, notice: Notice) {
        self.sink.notice(notice);
    }

    fn activated(&mut self, net: NetId, args: &[Arg]) {
        if !args.is_empty() {
            // The arguments are read in the firing net's context, then kept for `net`; the
            // vector is reused, so a steady mission allocates only for text arguments.
            let from = self.last_fired.map_or(0, |(n, _)| n) as usize;
            let mut values = std::mem::take(&mut self.net_args[net as usize]);
            values.clear();
            {
                let a = Args {
                    args,
                    params: self.params,
                    net_params: &self.net_args[from],
                };
                values.extend(a.iter().map(ArgValue::to_value));
            }
            self.net_args[net as usize] = values;
        }
        self.sink.activated(net);
    }

    fn deactivated(&mut self, net: NetId) {
        self.sink.deactivated(net);
    }

    fn livelock(&mut self) {
        self.livelock = self.last_fired.or(Some((0, 0)));
        self.sink.livelock();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes<T: bincode::Encode>(v: &T) -> Vec<u8> {
        bincode::encode_to_vec(v, bincode::config::standard()).unwrap()
    }

    #[test]
    fn a_borrowed_argument_encodes_as_its_value() {
        let values = [
            Value::Int(-7),
            Value::Int(i64::MAX),
            Value::Float(-0.0),
            Value::Float(1.5e300),
            Value::Bool(true),
            Value::Bool(false),
            Value::Text(String::new()),
            Value::Text("héllo \"x\"".into()),
            Value::FloatList(vec![]),
            Value::FloatList(vec![1.0, f64::NAN, -2.5]),
        ];
        for v in &values {
            assert_eq!(bytes(&ArgValue::of(v)), bytes(v), "{v:?}");
            let mut text = String::new();
            ArgValue::of(v).write_literal(&mut text);
            assert_eq!(text, v.literal());
        }
        // And as a call on the wire: the bytes of the call with owned arguments.
        let call = petrel_ipc::CallMsg::new("f", values.to_vec());
        let borrowed = petrel_ipc::CallRef {
            function: "f",
            args: values.iter().map(ArgValue::of),
        };
        let len = petrel_ipc::wire::encoded_len(&borrowed).unwrap();
        let mut body = vec![0u8; len];
        petrel_ipc::wire::encode_into(&borrowed, &mut body).unwrap();
        assert_eq!(body, bytes(&call));
        let back = petrel_ipc::wire::decode::<petrel_ipc::CallMsg>(&body).unwrap();
        // NaN is not equal to itself: the texts say the values are the same.
        assert_eq!(format!("{back:?}"), format!("{call:?}"));
    }
}
