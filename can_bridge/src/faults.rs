//! Bus faults as events: [`BusHealth`] follows the state of the controller (from error frames
//! and from the interface; see [`crate::bus_state`]) and turns each change into the events
//! `can.toml` names ([`crate::config::BusEvents`]).

use petrel_nets::compiled::Value;

use crate::bus_state::{state_from_error_frame, BusState};
use crate::config::BusEvents;
use crate::event::{EventCause, EventOut};
use crate::frame::Frame;

/// The events `events` names for entering `state` at `time_us`: the state event with the
/// state's name, then the state's own event, if configured.
pub fn events_for_state(events: &BusEvents, time_us: u64, state: BusState) -> Vec<EventOut> {
    let mut out = Vec::new();
    if let Some(name) = &events.state_event {
        out.push(EventOut::new(
            time_us,
            EventCause::Bus(state),
            name.clone(),
            vec![Value::Text(state.name().to_owned())],
        ));
    }
    for (s, name) in &events.on_state {
        if *s == state {
            out.push(EventOut::new(
                time_us,
                EventCause::Bus(state),
                name.clone(),
                Vec::new(),
            ));
        }
    }
    out
}

/// Follows the bus state and reports its changes as events.
#[derive(Clone, Debug)]
pub struct BusHealth {
    events: BusEvents,
    state: BusState,
    error_frames: u64,
    changes: u64,
}

impl BusHealth {
    /// Starts error-active.
    pub fn new(events: BusEvents) -> Self {
        BusHealth {
            events,
            state: BusState::ErrorActive,
            error_frames: 0,
            changes: 0,
        }
    }

    /// The configured events.
    pub fn events(&self) -> &BusEvents {
        &self.events
    }

    /// The current state.
    pub fn state(&self) -> BusState {
        self.state
    }

    /// Error frames seen.
    pub fn error_frames(&self) -> u64 {
        self.error_frames
    }

    /// Changes of state seen.
    pub fn changes(&self) -> u64 {
        self.changes
    }

    /// Takes an error frame: counts it, and reports the change of state it tells, if any.
    pub fn on_error_frame(&mut self, time_us: u64, frame: &Frame) -> Vec<EventOut> {
        if !frame.is_error() {
            return Vec::new();
        }
        self.error_frames += 1;
        match state_from_error_frame(frame) {
            Some(s) => self.on_state(time_us, s),
            None => Vec::new(),
        }
    }

    /// Takes the state the interface reports: events if it changed.
    pub fn on_state(&mut self, time_us: u64, state: BusState) -> Vec<EventOut> {
        if state == self.state {
            return Vec::new();
        }
        self.state = state;
        self.changes += 1;
        events_for_state(&self.events, time_us, state)
    }
}
