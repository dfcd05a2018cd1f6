//! The resolved project: every name replaced by an index, every literal typed.
//!
//! This is what the verifier explores and the player runs, so both execute the same thing. It is
//! built only by [`crate::check::check`], which guarantees the invariants documented on each
//! type: indices are in range, argument lists match their declarations, nets are safe in their
//! initial marking.

use crate::model::{Category, Type};

/// Index of a net in [`CompiledProject::nets`].
pub type NetId = u32;
/// Index of an event in [`CompiledProject::events`].
pub type EventId = u32;
/// Index of a timer in [`CompiledProject::timers`].
pub type TimerId = u32;
/// Index of a program in [`CompiledProject::programs`].
pub type ProgramId = u32;
/// Index of a function in its program's [`Program::functions`].
pub type FunctionId = u32;

/// A place seen from a transition: one of its own net's places or a global place.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PlaceRef {
    /// Index into the transition's net's [`Net::places`].
    Local(u32),
    /// Index into [`CompiledProject::globals`].
    Global(u32),
}

/// A typed value: an event parameter, a call argument (one type for the whole of Petrel).
pub use petrel_value::Value;

/// Where an argument's value comes from when the transition fires.
#[derive(Clone, Debug, PartialEq)]
pub enum Arg {
    /// A literal written in the net (or a parameter of an instance, fixed when it was made).
    Literal(Value),
    /// Parameter number N of the event that fired the transition.
    EventParam(u32),
    /// Parameter number N of the transition's net, bound when the net was activated.
    NetParam(u32),
}

/// A comparison of a guard.
pub use crate::model::CmpOp;

/// A resolved guard. Parameters fixed by an instance are folded into literals; what remains
/// refers to the triggering event's parameters and the net's activation arguments.
#[derive(Clone, Debug, PartialEq)]
pub enum Guard {
    /// A constant (a guard over fixed parameters only).
    Const(bool),
    /// Negation.
    Not(Box<Guard>),
    /// Every one holds.
    And(Vec<Guard>),
    /// Some one holds.
    Or(Vec<Guard>),
    /// A comparison; the checker proved the operands comparable with this operator.
    Compare(CmpOp, Arg, Arg),
    /// A bool operand standing alone.
    Value(Arg),
}

/// A comparison of two values, as guards compare them (docs/semantics.md): ints and floats as
/// numbers, NaN equal to nothing, other types by equality only.
pub fn compare(op: CmpOp, x: &Value, y: &Value) -> bool {
    use Value as V;
    let num = |v: &V| match v {
        V::Int(i) => Some(*i as f64),
        V::Float(f) => Some(*f),
        _ => None,
    };
    if let (V::Int(a), V::Int(b)) = (x, y) {
        // Exact for every int, where f64 would round above 2^53.
        return match op {
            CmpOp::Eq => a == b,
            CmpOp::Ne => a != b,
            CmpOp::Lt => a < b,
            CmpOp::Le => a <= b,
            CmpOp::Gt => a > b,
            CmpOp::Ge => a >= b,
        };
    }
    if let (Some(a), Some(b)) = (num(x), num(y)) {
        return match op {
            CmpOp::Eq => a == b,
            CmpOp::Ne => a != b,
            CmpOp::Lt => a < b,
            CmpOp::Le => a <= b,
            CmpOp::Gt => a > b,
            CmpOp::Ge => a >= b,
        };
    }
    match op {
        CmpOp::Eq => x == y,
        CmpOp::Ne => x != y,
        _ => false,
    }
}

impl Guard {
    /// Whether the guard holds for an event's parameters and its net's activation arguments
    /// (the checker proved every index in range and every comparison well typed).
    pub fn holds(&self, event: &[Value], net: &[Value]) -> bool {
        // Borrowed, never cloned: the player evaluates guards with no allocation.
        fn value<'a>(a: &'a Arg, event: &'a [Value], net: &'a [Value]) -> Option<&'a Value> {
            match a {
                Arg::Literal(v) => Some(v),
                Arg::EventParam(i) => event.get(*i as usize),
                Arg::NetParam(i) => net.get(*i as usize),
            }
        }
        match self {
            Guard::Const(b) => *b,
            Guard::Not(a) => !a.holds(event, net),
            Guard::And(list) => list.iter().all(|a| a.holds(event, net)),
            Guard::Or(list) => list.iter().any(|a| a.holds(event, net)),
            Guard::Value(a) => matches!(value(a, event, net), Some(Value::Bool(true))),
            Guard::Compare(op, a, b) => match (value(a, event, net), value(b, event, net)) {
                (Some(x), Some(y)) => compare(*op, x, y),
                _ => false,
            },
        }
    }
}

/// A resolved formula over the state: an invariant, or a script's `expect always`.
#[derive(Clone, Debug, PartialEq)]
pub enum StateFormula {
    /// A constant.
    Const(bool),
    /// The place is marked (seen from the net: a global place from any net).
    Marked(NetId, PlaceRef),
    /// The net is active.
    Active(NetId),
    /// Negation.
    Not(Box<StateFormula>),
    /// Conjunction.
    And(Box<StateFormula>, Box<StateFormula>),
    /// Disjunction.
    Or(Box<StateFormula>, Box<StateFormula>),
    /// Implication.
    Implies(Box<StateFormula>, Box<StateFormula>),
}

/// An invariant of the project.
#[derive(Clone, Debug, PartialEq)]
pub struct Invariant {
    /// Its name in the manifest.
    pub name: String,
    /// What must hold in every stable state.
    pub formula: StateFormula,
}

/// How long a started timer runs.
#[derive(Clone, Debug, PartialEq)]
pub enum TimerDuration {
    /// A literal, in milliseconds.
    Millis(u64),
    /// Parameter number N (int or float) of the triggering event, in seconds.
    EventParamSeconds(u32),
    /// Activation argument number N (int or float) of the net, in seconds.
    NetParamSeconds(u32),
}

/// A resolved action.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// Give a net its initial marking (and its activation arguments, one per parameter when
    /// its parameters are bound at activation, else none).
    Activate {
        /// The net.
        net: NetId,
        /// Its arguments.
        args: Vec<Arg>,
    },
    /// Take a net's marking away, and its subtree's (children first).
    Deactivate(NetId),
    /// Mark the parent's completion place of the transition's net, then deactivate the net.
    Finish,
    /// Start (or restart) a timer.
    StartTimer {
        /// The timer.
        timer: TimerId,
        /// For how long.
        after: TimerDuration,
    },
    /// Stop a timer if it runs.
    CancelTimer(TimerId),
    /// Call a program's function.
    Call {
        /// The program.
        program: ProgramId,
        /// The function.
        function: FunctionId,
        /// One argument per declared parameter, types checked.
        args: Vec<Arg>,
    },
    /// Queue an event.
    Emit {
        /// The event.
        event: EventId,
        /// One argument per declared parameter, types checked.
        args: Vec<Arg>,
        /// The one net it is addressed to, if any.
        target: Option<NetId>,
    },
}

/// A resolved transition.
#[derive(Clone, Debug, PartialEq)]
pub struct Transition {
    /// Name within its net.
    pub name: String,
    /// Triggering event; `None` for an immediate transition.
    pub event: Option<EventId>,
    /// The guard; `None`: always true.
    pub guard: Option<Guard>,
    /// Input places, no duplicates.
    pub inputs: Vec<PlaceRef>,
    /// Places that must be empty (emptiness tests), no duplicates, none an input.
    pub empty: Vec<PlaceRef>,
    /// Output places, no duplicates.
    pub outputs: Vec<PlaceRef>,
    /// Actions, in firing order.
    pub actions: Vec<Action>,
}

/// A local place.
#[derive(Clone, Debug, PartialEq)]
pub struct Place {
    /// Name within its net.
    pub name: String,
    /// Marked when the net is activated.
    pub initial: bool,
}

/// A resolved net: a net of the project, or an instance of a template.
#[derive(Clone, Debug, PartialEq)]
pub struct Net {
    /// Its name: the net's, an instance's (`R1`), or a child instance's (`PARENT/CHILD`).
    pub name: String,
    /// The net as written in its file (the template of an instance; else the same as `name`).
    pub template: String,
    /// Parameters bound when the net is activated (`activate NET(args)`); empty when it has
    /// none or an instance fixed them.
    pub params: Vec<(String, Type)>,
    /// Local places, in written order, then one completion place (`CHILD.done`) per child.
    pub places: Vec<Place>,
    /// Transitions, in written order (the order in which they are offered an event).
    pub transitions: Vec<Transition>,
    /// Its children, in declared order.
    pub children: Vec<NetId>,
    /// Its parent, and the index of its completion place among the parent's places.
    pub parent: Option<(NetId, u32)>,
}

/// A global place.
#[derive(Clone, Debug, PartialEq)]
pub struct GlobalPlace {
    /// Name.
    pub name: String,
    /// Marked when the mission starts.
    pub initial: bool,
    /// The nets that may use it; `None`: every net.
    pub nets: Option<Vec<NetId>>,
}

/// A declared event.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// Name.
    pub name: String,
    /// Dispatch category.
    pub category: Category,
    /// Parameter names and types, in order.
    pub params: Vec<(String, Type)>,
    /// Only the nets emit it.
    pub internal: bool,
}

/// A program function.
#[derive(Clone, Debug, PartialEq)]
pub struct Function {
    /// Name.
    pub name: String,
    /// Parameter names and types, in order.
    pub params: Vec<(String, Type)>,
    /// The events the program answers a call with (empty: not declared).
    pub answers: Vec<EventId>,
}

/// A software program.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// Name.
    pub name: String,
    /// Functions.
    pub functions: Vec<Function>,
}

/// A timer.
#[derive(Clone, Debug, PartialEq)]
pub struct Timer {
    /// Name.
    pub name: String,
    /// The parameterless event emitted on expiry.
    pub event: EventId,
}

/// A checked project, ready to verify or to play.
#[derive(Clone, Debug, PartialEq)]
pub struct CompiledProject {
    /// Project name.
    pub name: String,
    /// Nets in dispatch order.
    pub nets: Vec<Net>,
    /// Global places.
    pub globals: Vec<GlobalPlace>,
    /// Events.
    pub events: Vec<Event>,
    /// Programs.
    pub programs: Vec<Program>,
    /// Timers.
    pub timers: Vec<Timer>,
    /// Nets active at start, in manifest order, no duplicates.
    pub start: Vec<NetId>,
    /// Intended final markings: each a set of places (with the net they are seen from; any net
    /// for a global place) that a planned end of the mission holds.
    pub finals: Vec<Vec<(NetId, PlaceRef)>>,
    /// Invariants: what must hold in every stable state.
    pub invariants: Vec<Invariant>,
    /// Markings that count as ends for the progress check (besides `finals`).
    pub goals: Vec<Vec<(NetId, PlaceRef)>>,
    /// Categories whose events the progress check does not count on the way to an end.
    pub progress_excludes: Vec<Category>,
    /// Time bounds to report (`[verify.bounds]`, and `petrel verify --bound`).
    pub bounds: Vec<Bound>,
}

/// One end of a time bound: an event a transition takes, or a marking formula that holds.
#[derive(Clone, Debug, PartialEq)]
pub enum Occurrence {
    /// The event is delivered and some transition takes it.
    Event(EventId),
    /// The formula holds in the stable state reached.
    Marking(StateFormula),
}

/// A time bound: over every occurrence of `from`, the least and greatest time until the next
/// `to` (docs/verification.md, "Time bounds").
#[derive(Clone, Debug, PartialEq)]
pub struct Bound {
    /// Its name (the manifest's key, or the command line's text).
    pub name: String,
    /// Where the observer's clock starts.
    pub from: Occurrence,
    /// What stops it.
    pub to: Occurrence,
    /// `from` as written.
    pub from_text: String,
    /// `to` as written.
    pub to_text: String,
    /// The requirement, in microseconds: a greater (or no) bound is an error (E0607).
    pub within_us: Option<u64>,
    /// The requirement as written (`10min`), for the reports.
    pub within_text: Option<String>,
}

impl CompiledProject {
    /// The net named `name`.
    pub fn net_id(&self, name: &str) -> Option<NetId> {
        self.nets
            .iter()
            .position(|n| n.name == name)
            .map(|i| i as NetId)
    }

    /// The place named `NET.place` or `global.place` (a net's name may hold `/`, a completion
    /// place's name `.`): the net it is seen from (0 for a global place) and the place.
    pub fn place_ref(&self, qualified: &str) -> Option<(NetId, PlaceRef)> {
        if let Some(g) = qualified.strip_prefix("global.") {
            return self
                .globals
                .iter()
                .position(|x| x.name == g)
                .map(|i| (0, PlaceRef::Global(i as u32)));
        }
        // Every split at a `.`: the net's name holds no dot, the place's may (`T.done`).
        for (i, _) in qualified.match_indices('.') {
            let (net, place) = (&qualified[..i], &qualified[i + 1..]);
            if let Some(n) = self.net_id(net) {
                if let Some(p) = self.nets[n as usize]
                    .places
                    .iter()
                    .position(|p| p.name == place)
                {
                    return Some((n, PlaceRef::Local(p as u32)));
                }
            }
        }
        None
    }

    /// The event named `name`.
    pub fn event_id(&self, name: &str) -> Option<EventId> {
        self.events
            .iter()
            .position(|e| e.name == name)
            .map(|i| i as EventId)
    }

    /// A place's name for people: `NET.place` or `global.place`.
    pub fn place_name(&self, net: NetId, place: PlaceRef) -> String {
        match place {
            PlaceRef::Local(p) => {
                let n = &self.nets[net as usize];
                format!("{}.{}", n.name, n.places[p as usize].name)
            }
            PlaceRef::Global(g) => format!("global.{}", self.globals[g as usize].name),
        }
    }
}
