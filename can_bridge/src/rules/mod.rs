//! Rules that turn signals into player events, and the engine that runs them.
//!
//! The rules are written in the project's `can.toml` (its format is in [`check`] and in the
//! crate's README); [`check_rules`] reads and checks them against the DBC and the project's
//! events and gives a [`CanConfig`]. The [`RuleEngine`] is a pure state machine over it:
//! decoded frames and the time go in ([`RuleEngine::on_message`], [`RuleEngine::on_time`]),
//! events come out, in a deterministic order, stamped with the time they happened.
//!
//! **Conditions** are evaluated on each new value of their signal (and of a band's target
//! signal), with hysteresis (a Schmitt trigger: the condition becomes true at the threshold and
//! false only beyond it by `hysteresis`). A condition starts false, so a first value that
//! satisfies it is a rising edge. With a hold time (`for`), a change of the condition counts
//! only once it has lasted that long without interruption, and the event is stamped with the
//! instant the hold ended. **Staleness** fires once when a message has not arrived for its
//! timeout (counted from the engine's start for a message never seen), and re-arms when the
//! message arrives again.
//!
//! Deadlines due at or before a frame's time are handled before the frame: a frame arriving
//! exactly at a staleness deadline comes too late.

pub mod check;

pub use check::{check_rules, load_project_can, CAN_TOML};

use std::sync::Arc;

use petrel_ipc::{EventMsg, Value};
use petrel_nets::model::Type;

use crate::dbc::{Dbc, DecodedMessage, MessageId, SignalRef};
use crate::faults::BusState;

/// Which changes of a condition fire the event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edge {
    /// The condition becomes true.
    Rising,
    /// The condition becomes false.
    Falling,
    /// Either.
    Both,
}

/// The target of a band: a fixed value or the latest value of another signal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// A fixed value.
    Value(f64),
    /// The latest value of a signal (received, or sent by the bridge itself).
    Signal(SignalRef),
}

/// A condition on one signal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Condition {
    /// True from `value >= threshold`; false again below `threshold - hysteresis`.
    Above {
        /// The signal.
        signal: SignalRef,
        /// The threshold (physical).
        threshold: f64,
        /// The hysteresis, at least 0.
        hysteresis: f64,
    },
    /// True from `value <= threshold`; false again above `threshold + hysteresis`.
    Below {
        /// The signal.
        signal: SignalRef,
        /// The threshold (physical).
        threshold: f64,
        /// The hysteresis, at least 0.
        hysteresis: f64,
    },
    /// True from `|value - target| <= within`; false again beyond `within + hysteresis`.
    Band {
        /// The signal.
        signal: SignalRef,
        /// The target.
        target: Target,
        /// Half-width of the band, above 0.
        within: f64,
        /// The hysteresis, at least 0.
        hysteresis: f64,
    },
    /// True when the raw value equals `raw` (a bit, a value-table entry).
    Equals {
        /// The signal.
        signal: SignalRef,
        /// The raw value.
        raw: i64,
    },
}

impl Condition {
    /// The signal the condition watches.
    pub fn signal(&self) -> SignalRef {
        match *self {
            Condition::Above { signal, .. }
            | Condition::Below { signal, .. }
            | Condition::Band { signal, .. }
            | Condition::Equals { signal, .. } => signal,
        }
    }

    /// The target signal of a band, if it has one.
    pub fn target_signal(&self) -> Option<SignalRef> {
        match *self {
            Condition::Band {
                target: Target::Signal(s),
                ..
            } => Some(s),
            _ => None,
        }
    }
}

/// What a rule watches.
#[derive(Clone, Debug, PartialEq)]
pub enum RuleKind {
    /// A condition on a signal (kinds `threshold`, `band`, `debounce`, `edge`).
    Condition {
        /// The condition.
        condition: Condition,
        /// Which changes fire.
        edge: Edge,
        /// How long a change must last to count, in microseconds (0: at once).
        hold_us: u64,
    },
    /// A message that stops arriving (kind `stale`).
    Stale {
        /// The message.
        message: MessageId,
        /// Silence after which the event fires, in microseconds.
        timeout_us: u64,
    },
}

/// Where an event parameter comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamSource {
    /// The latest value of a signal, as the declared type: `float` the physical value, `int`
    /// the physical value of an integral signal, `bool` whether it is not zero, `text` its
    /// value-table name (or the number when the value has no name).
    ///
    /// A signal never received gives NaN, 0, false or the empty text.
    Signal {
        /// The signal.
        signal: SignalRef,
        /// The declared type of the parameter.
        ty: Type,
    },
    /// A literal written in the rule.
    Literal(Value),
}

/// A checked rule.
#[derive(Clone, Debug, PartialEq)]
pub struct Rule {
    /// The rule's name (its `name`, else its event's).
    pub name: String,
    /// The event it sends, by name.
    pub event: String,
    /// What it watches.
    pub kind: RuleKind,
    /// The event's parameters, in declaration order.
    pub params: Vec<ParamSource>,
}

/// Events for changes of the bus state (`[bus]` of `can.toml`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BusEvents {
    /// An event with one `text` parameter, sent on every change of state with the state's
    /// name (`error_active`, `error_warning`, `error_passive`, `bus_off`, `stopped`,
    /// `sleeping`).
    pub state_event: Option<String>,
    /// Events without parameters, one per state entered.
    pub on_state: Vec<(BusState, String)>,
    /// Ask the interface to restart after a bus-off (SocketCAN; needs the privilege, and
    /// is refused by interfaces that restart by themselves).
    pub restart_after_bus_off: bool,
}

/// The supervisor heartbeat the thrusters expect (`[heartbeat]`).
#[derive(Clone, Debug, PartialEq)]
pub struct HeartbeatSpec {
    /// The message sent.
    pub message: MessageId,
    /// Its period, in microseconds.
    pub period_us: u64,
    /// A signal of the message incremented at each frame, wrapping within its range.
    pub counter: Option<usize>,
    /// Physical values of the other signals, by index in the message.
    pub values: Vec<(usize, f64)>,
}

/// What programs may command (`[commands]`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CommandSpec {
    /// Messages programs may have the bridge send.
    pub messages: Vec<MessageId>,
    /// The program name under which the bridge receives commands as calls (a function per
    /// message, the signals as arguments in DBC order), if any.
    pub program: Option<String>,
}

/// A checked `can.toml`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CanConfig {
    /// The DBC file, as written (relative to the project directory).
    pub dbc_path: Option<String>,
    /// The interface to open when none is given on the command line.
    pub interface: Option<String>,
    /// Open the interface for CAN FD frames.
    pub fd: bool,
    /// `[bus] receive = "dbc"`: the socket's identifier filters pass only the DBC's messages
    /// (and error frames), so that a busy bus costs the bridge only what it decodes.
    pub receive_only_dbc: bool,
    /// The rules, in written order (the order their simultaneous events come out).
    pub rules: Vec<Rule>,
    /// Bus fault events.
    pub bus: BusEvents,
    /// The heartbeat, if any.
    pub heartbeat: Option<HeartbeatSpec>,
    /// Commands.
    pub commands: CommandSpec,
}

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
    /// The event, ready to send.
    pub msg: EventMsg,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Latest {
    physical: f64,
    raw: i128,
}

#[derive(Clone, Debug, PartialEq)]
enum State {
    Condition {
        /// The condition now (after hysteresis).
        now: bool,
        /// The condition as it last counted (after the hold).
        stable: bool,
        /// When a change of `now` away from `stable` will count.
        pending: Option<u64>,
    },
    Stale {
        deadline: u64,
        fired: bool,
    },
}

/// Runs the rules of a [`CanConfig`] over decoded frames and time.
#[derive(Clone, Debug)]
pub struct RuleEngine {
    dbc: Arc<Dbc>,
    rules: Vec<Rule>,
    states: Vec<State>,
    latest: Vec<Vec<Option<Latest>>>,
    /// For each message, the rules to evaluate when it arrives.
    watchers: Vec<Vec<usize>>,
}

impl RuleEngine {
    /// An engine for `rules` (checked against `dbc`), started at `start_us`: a message never
    /// seen is stale at `start_us` plus its timeout.
    pub fn new(dbc: Arc<Dbc>, rules: Vec<Rule>, start_us: u64) -> Self {
        let n = dbc.messages().len();
        let latest = dbc
            .messages()
            .iter()
            .map(|m| vec![None; m.signals.len()])
            .collect();
        let mut watchers = vec![Vec::new(); n];
        let mut states = Vec::with_capacity(rules.len());
        for (i, r) in rules.iter().enumerate() {
            match &r.kind {
                RuleKind::Condition { condition, .. } => {
                    let mut msgs = vec![condition.signal().message];
                    if let Some(t) = condition.target_signal() {
                        msgs.push(t.message);
                    }
                    msgs.dedup();
                    for m in msgs {
                        if let Some(w) = watchers.get_mut(m) {
                            w.push(i);
                        }
                    }
                    states.push(State::Condition {
                        now: false,
                        stable: false,
                        pending: None,
                    });
                }
                RuleKind::Stale {
                    message,
                    timeout_us,
                } => {
                    if let Some(w) = watchers.get_mut(*message) {
                        w.push(i);
                    }
                    states.push(State::Stale {
                        deadline: start_us.saturating_add(*timeout_us),
                        fired: false,
                    });
                }
            }
        }
        RuleEngine {
            dbc,
            rules,
            states,
            latest,
            watchers,
        }
    }

    /// Counts the silence of every message not seen yet from `start_us` rather than from the
    /// engine's creation (see [`BridgeCore::begin`](crate::bridge::BridgeCore::begin)). A
    /// deadline already later stays.
    pub fn restart_silence(&mut self, start_us: u64) {
        for (rule, state) in self.rules.iter().zip(&mut self.states) {
            if let (
                RuleKind::Stale { timeout_us, .. },
                State::Stale {
                    deadline,
                    fired: false,
                },
            ) = (&rule.kind, state)
            {
                *deadline = (*deadline).max(start_us.saturating_add(*timeout_us));
            }
        }
    }

    /// The rules.
    pub fn rules(&self) -> &[Rule] {
        &self.rules
    }

    /// The DBC.
    pub fn dbc(&self) -> &Arc<Dbc> {
        &self.dbc
    }

    /// The latest physical value of a signal, if one arrived.
    pub fn latest(&self, s: SignalRef) -> Option<f64> {
        self.latest_of(s).map(|l| l.physical)
    }

    fn latest_of(&self, s: SignalRef) -> Option<Latest> {
        *self.latest.get(s.message)?.get(s.signal)?
    }

    /// The earliest instant at which [`on_time`](Self::on_time) has something to do.
    pub fn next_deadline(&self) -> Option<u64> {
        self.states
            .iter()
            .filter_map(|s| match s {
                State::Condition { pending, .. } => *pending,
                State::Stale { deadline, fired } => (!fired).then_some(*deadline),
            })
            .min()
    }

    /// Handles every deadline at or before `time_us`, in time order (rule order among equal
    /// times), and returns the events, each stamped with its deadline.
    pub fn on_time(&mut self, time_us: u64) -> Vec<EventOut> {
        let mut out = Vec::new();
        self.expire(time_us, &mut out);
        out
    }

    fn expire(&mut self, time_us: u64, out: &mut Vec<EventOut>) {
        loop {
            // The earliest due deadline, first rule among equals.
            let due = self
                .states
                .iter()
                .enumerate()
                .filter_map(|(i, s)| match s {
                    State::Condition {
                        pending: Some(d), ..
                    } => Some((*d, i)),
                    State::Stale {
                        deadline,
                        fired: false,
                    } => Some((*deadline, i)),
                    _ => None,
                })
                .filter(|(d, _)| *d <= time_us)
                .min();
            let Some((at, i)) = due else { return };
            let fire = match &mut self.states[i] {
                State::Condition {
                    now,
                    stable,
                    pending,
                } => {
                    *pending = None;
                    *stable = *now;
                    let became = *now;
                    self.edge_fires(i, became)
                }
                State::Stale { fired, .. } => {
                    *fired = true;
                    true
                }
            };
            if fire {
                out.push(self.event(i, at));
            }
        }
    }

    fn edge_fires(&self, rule: usize, became: bool) -> bool {
        match &self.rules[rule].kind {
            RuleKind::Condition { edge, .. } => match edge {
                Edge::Rising => became,
                Edge::Falling => !became,
                Edge::Both => true,
            },
            RuleKind::Stale { .. } => false,
        }
    }

    /// Takes a decoded frame received (or sent) at `time_us`: first the deadlines due by then,
    /// then the frame's new values. Returns the events in the order they happened.
    pub fn on_message(&mut self, time_us: u64, msg: &DecodedMessage) -> Vec<EventOut> {
        let mut out = Vec::new();
        self.expire(time_us, &mut out);
        let Some(latest) = self.latest.get_mut(msg.message) else {
            return out;
        };
        for s in &msg.signals {
            if let Some(slot) = latest.get_mut(s.signal.signal) {
                *slot = Some(Latest {
                    physical: s.physical,
                    raw: s.raw,
                });
            }
        }
        let watchers = self.watchers.get(msg.message).cloned().unwrap_or_default();
        for i in watchers {
            match self.rules[i].kind.clone() {
                RuleKind::Stale { timeout_us, .. } => {
                    self.states[i] = State::Stale {
                        deadline: time_us.saturating_add(timeout_us),
                        fired: false,
                    };
                }
                RuleKind::Condition {
                    condition, hold_us, ..
                } => {
                    let State::Condition { now, stable, .. } = self.states[i] else {
                        continue;
                    };
                    let Some(new) = self.evaluate(&condition, now) else {
                        continue;
                    };
                    let State::Condition {
                        now,
                        stable: _,
                        pending,
                    } = &mut self.states[i]
                    else {
                        continue;
                    };
                    *now = new;
                    if new == stable {
                        *pending = None;
                    } else if hold_us == 0 {
                        *pending = None;
                        self.states[i] = State::Condition {
                            now: new,
                            stable: new,
                            pending: None,
                        };
                        if self.edge_fires(i, new) {
                            out.push(self.event(i, time_us));
                        }
                    } else if pending.is_none() {
                        *pending = Some(time_us.saturating_add(hold_us));
                    }
                }
            }
        }
        out
    }

    /// The condition's value given the latest values and its previous value (hysteresis);
    /// `None` when a value it needs is unknown or not a number.
    fn evaluate(&self, c: &Condition, was: bool) -> Option<bool> {
        let value = self.latest_of(c.signal())?;
        let v = value.physical;
        if v.is_nan() {
            return None;
        }
        Some(match *c {
            Condition::Above {
                threshold,
                hysteresis,
                ..
            } => {
                if was {
                    v >= threshold - hysteresis
                } else {
                    v >= threshold
                }
            }
            Condition::Below {
                threshold,
                hysteresis,
                ..
            } => {
                if was {
                    v <= threshold + hysteresis
                } else {
                    v <= threshold
                }
            }
            Condition::Band {
                target,
                within,
                hysteresis,
                ..
            } => {
                let t = match target {
                    Target::Value(t) => t,
                    Target::Signal(s) => self.latest_of(s)?.physical,
                };
                if t.is_nan() {
                    return None;
                }
                let d = (v - t).abs();
                if was {
                    d <= within + hysteresis
                } else {
                    d <= within
                }
            }
            Condition::Equals { raw, .. } => value.raw == i128::from(raw),
        })
    }

    fn event(&self, rule: usize, time_us: u64) -> EventOut {
        let r = &self.rules[rule];
        let params = r
            .params
            .iter()
            .map(|p| match p {
                ParamSource::Literal(v) => v.clone(),
                ParamSource::Signal { signal, ty } => self.param(*signal, *ty),
            })
            .collect();
        EventOut {
            time_us,
            cause: EventCause::Rule(rule),
            msg: EventMsg::new(r.event.clone(), params),
        }
    }

    fn param(&self, s: SignalRef, ty: Type) -> Value {
        let latest = self.latest_of(s);
        match ty {
            Type::Float => Value::Float(latest.map_or(f64::NAN, |l| l.physical)),
            Type::Int => Value::Int(latest.map_or(0, |l| l.physical.round() as i64)),
            Type::Bool => Value::Bool(latest.is_some_and(|l| l.physical != 0.0)),
            Type::Text => Value::Text(match latest {
                None => String::new(),
                Some(l) => self
                    .dbc
                    .signal(s)
                    .and_then(|sig| sig.label(l.raw))
                    .map_or_else(|| format_number(l.physical), str::to_owned),
            }),
            Type::FloatList => {
                Value::FloatList(latest.map(|l| vec![l.physical]).unwrap_or_default())
            }
        }
    }
}

/// A number as text: integers without a decimal point.
fn format_number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v}")
    }
}
