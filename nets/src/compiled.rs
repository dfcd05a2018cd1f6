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
    /// A literal written in the net.
    Literal(Value),
    /// Parameter number N of the event that fired the transition.
    EventParam(u32),
}

/// How long a started timer runs.
#[derive(Clone, Debug, PartialEq)]
pub enum TimerDuration {
    /// A literal, in milliseconds.
    Millis(u64),
    /// Parameter number N (int or float) of the triggering event, in seconds.
    EventParamSeconds(u32),
}

/// A resolved action.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// Give a net its initial marking.
    Activate(NetId),
    /// Take a net's marking away.
    Deactivate(NetId),
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
    },
}

/// A resolved transition.
#[derive(Clone, Debug, PartialEq)]
pub struct Transition {
    /// Name within its net.
    pub name: String,
    /// Triggering event; `None` for an immediate transition.
    pub event: Option<EventId>,
    /// Input places, no duplicates.
    pub inputs: Vec<PlaceRef>,
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

/// A resolved net.
#[derive(Clone, Debug, PartialEq)]
pub struct Net {
    /// Net name.
    pub name: String,
    /// Local places, in written order.
    pub places: Vec<Place>,
    /// Transitions, in written order (the order in which they are offered an event).
    pub transitions: Vec<Transition>,
}

/// A global place.
#[derive(Clone, Debug, PartialEq)]
pub struct GlobalPlace {
    /// Name.
    pub name: String,
    /// Marked when the mission starts.
    pub initial: bool,
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
}

/// A program function.
#[derive(Clone, Debug, PartialEq)]
pub struct Function {
    /// Name.
    pub name: String,
    /// Parameter names and types, in order.
    pub params: Vec<(String, Type)>,
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
}

impl CompiledProject {
    /// The net named `name`.
    pub fn net_id(&self, name: &str) -> Option<NetId> {
        self.nets
            .iter()
            .position(|n| n.name == name)
            .map(|i| i as NetId)
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
