//! What the bridge emits: events for the player, stamped with the bus time they happened and
//! with what produced them.
//!
//! The core's own type, not `petrel_ipc`'s: the core (decoding, rules, faults, replay) runs and
//! is tested without the vehicle's shared memory, and only the process loop
//! ([`crate::runtime`]) turns these into messages.

use petrel_nets::compiled::Value;

use crate::bus_state::BusState;

/// Who produced an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EventCause {
    /// Rule number N of the configuration.
    Rule(usize),
    /// A change of the bus state.
    Bus(BusState),
    /// A command the bridge could not carry out (`call_failed`).
    Command,
}

/// An event for the player, with the time it happened.
#[derive(Clone, Debug, PartialEq)]
pub struct EventOut {
    /// When the condition was met, in the bus clock's microseconds.
    pub time_us: u64,
    /// Who produced it.
    pub cause: EventCause,
    /// The event's name, a declared event of the project.
    pub name: String,
    /// Its parameters, in declaration order and of the declared types.
    pub params: Vec<Value>,
}

impl EventOut {
    /// The event `name(params)` produced by `cause` at `time_us`.
    pub fn new(
        time_us: u64,
        cause: EventCause,
        name: impl Into<String>,
        params: Vec<Value>,
    ) -> Self {
        EventOut {
            time_us,
            cause,
            name: name.into(),
            params,
        }
    }
}
