//! The data server's core, without I/O: frames in, signals, events and frames out.
//!
//! [`BridgeCore`] holds the DBC, the rules, the bus health, the latest value of every signal
//! ([`SignalTable`]) and the counters. The runtime ([`crate::runtime`]) feeds it the frames the
//! bus receives and the time, sends the events it returns to the player, and sends the frames it
//! returns on the bus; replay ([`crate::replay`]) feeds it a log. Everything it does is a
//! function of what it is fed: two cores fed the same frames at the same times return the same
//! events.
//!
//! ```text
//!   bus frames --on_frame--> decode --> SignalTable (latest values, for programs)
//!                              |   \--> RuleEngine ---------> events for the player
//!                              \------> BusHealth (error frames) --^
//!   time --on_time--> staleness, hold times; poll_heartbeat --> heartbeat frame
//!   programs' commands --command--> encode (range checked) --> frame to send (and seen by the rules)
//! ```

use std::sync::Arc;

use petrel_nets::compiled::Value;

use crate::bus_state::BusState;
use crate::config::CanConfig;
use crate::dbc::{Dbc, DecodeOutcome, DecodedMessage, EncodeError, Mux, SignalRef};
use crate::event::EventOut;
use crate::faults::BusHealth;
use crate::frame::Frame;
use crate::rules::RuleEngine;

/// The latest value of one signal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignalSample {
    /// Physical value.
    pub physical: f64,
    /// Raw value (the bits of a float signal).
    pub raw: i128,
    /// When its frame was received (or sent by the bridge).
    pub time_us: u64,
}

/// The latest value of every signal, for the programs: the runtime publishes it on the
/// vehicle's latest-value service `petrel/<vehicle>/signals` whenever it changes.
#[derive(Clone, Debug, Default)]
pub struct SignalTable {
    values: Vec<Vec<Option<SignalSample>>>,
    updates: u64,
}

impl SignalTable {
    /// An empty table for `dbc`.
    pub fn new(dbc: &Dbc) -> Self {
        SignalTable {
            values: dbc
                .messages()
                .iter()
                .map(|m| vec![None; m.signals.len()])
                .collect(),
            updates: 0,
        }
    }

    /// Records the signals of a frame.
    pub fn update(&mut self, time_us: u64, msg: &DecodedMessage) {
        if let Some(row) = self.values.get_mut(msg.message) {
            for s in &msg.signals {
                if let Some(slot) = row.get_mut(s.signal.signal) {
                    *slot = Some(SignalSample {
                        physical: s.physical,
                        raw: s.raw,
                        time_us,
                    });
                }
            }
            self.updates += 1;
        }
    }

    /// The latest value of a signal.
    pub fn get(&self, s: SignalRef) -> Option<SignalSample> {
        *self.values.get(s.message)?.get(s.signal)?
    }

    /// The latest value of `MESSAGE.signal`.
    pub fn get_path(&self, dbc: &Dbc, path: &str) -> Option<SignalSample> {
        self.get(dbc.signal_ref(path)?)
    }

    /// Every signal with a value.
    pub fn iter(&self) -> impl Iterator<Item = (SignalRef, SignalSample)> + '_ {
        self.values.iter().enumerate().flat_map(|(m, row)| {
            row.iter().enumerate().filter_map(move |(s, v)| {
                v.map(|v| {
                    (
                        SignalRef {
                            message: m,
                            signal: s,
                        },
                        v,
                    )
                })
            })
        })
    }

    /// Frames recorded so far (a change counter for publishers).
    pub fn updates(&self) -> u64 {
        self.updates
    }
}

/// What the core counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames received.
    pub frames: u64,
    /// Frames of known messages, decoded.
    pub decoded: u64,
    /// Data frames whose identifier the DBC does not know.
    pub unknown_id: u64,
    /// Frames of known messages with another length than the DBC's.
    pub wrong_length: u64,
    /// Remote frames.
    pub remote: u64,
    /// Error frames.
    pub error_frames: u64,
    /// Decoded signals whose value is not a number (float signals holding NaN or infinity).
    pub decode_errors: u64,
    /// Events produced.
    pub events: u64,
    /// Commands encoded into frames.
    pub commands: u64,
    /// Commands refused (not allowed, unknown, out of range...).
    pub commands_refused: u64,
    /// Heartbeat frames produced.
    pub heartbeats: u64,
    /// Heartbeats due that could not be encoded (not sent; the checker encodes the heartbeat
    /// once, so this stays 0 unless a start value is out of its signal's range).
    pub heartbeats_failed: u64,
}

/// What [`BridgeCore::on_frame`] made of a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameReport {
    /// What the frame was, as the DBC decodes it (count and log the unusual ones).
    pub outcome: DecodeOutcome,
    /// Events, in the order they happened.
    pub events: Vec<EventOut>,
}

/// A command from a program could not become a frame.
#[derive(Clone, Debug, PartialEq)]
pub enum CommandError {
    /// The message is not among `[commands] messages` of can.toml.
    NotAllowed(String),
    /// A value of a type that no signal takes (a list).
    BadValue {
        /// The signal.
        signal: String,
        /// The value's type.
        ty: &'static str,
    },
    /// A text that is not in the signal's value table.
    UnknownLabel {
        /// The signal.
        signal: String,
        /// The text.
        label: String,
    },
    /// A call with another number of arguments than the message's signals.
    Arity {
        /// The message.
        message: String,
        /// Its signals.
        expected: usize,
        /// Arguments given.
        got: usize,
    },
    /// A multiplexed message commanded by a call: its signals depend on the switch, so
    /// name them ([`BridgeCore::command`]).
    Multiplexed(String),
    /// The DBC refused the values (unknown signal, out of range, missing...).
    Encode(EncodeError),
}

impl std::fmt::Display for CommandError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CommandError::NotAllowed(m) => write!(
                f,
                "message `{m}` may not be commanded: list it in [commands] messages of can.toml"
            ),
            CommandError::BadValue { signal, ty } => {
                write!(f, "signal `{signal}` takes a number, a bool or a value name, not {ty}")
            }
            CommandError::UnknownLabel { signal, label } => {
                write!(f, "signal `{signal}` has no value named `{label}`")
            }
            CommandError::Arity {
                message,
                expected,
                got,
            } => write!(
                f,
                "message `{message}` has {expected} signals; the call gives {got} arguments (one per signal, in DBC order)"
            ),
            CommandError::Multiplexed(m) => write!(
                f,
                "message `{m}` is multiplexed: command it with named signals, not by position"
            ),
            CommandError::Encode(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for CommandError {}

#[derive(Clone, Debug)]
struct HeartbeatState {
    next_due: u64,
    counter: f64,
}

/// The data server's core.
#[derive(Clone, Debug)]
pub struct BridgeCore {
    dbc: Arc<Dbc>,
    config: CanConfig,
    rules: RuleEngine,
    health: BusHealth,
    signals: SignalTable,
    counters: Counters,
    heartbeat: Option<HeartbeatState>,
    /// The last commanded physical values, per message and signal.
    commanded: Vec<Vec<Option<f64>>>,
}

impl BridgeCore {
    /// A core for a checked configuration, started at `start_us` (the first heartbeat is due
    /// then; staleness counts from then).
    pub fn new(dbc: Arc<Dbc>, config: CanConfig, start_us: u64) -> Self {
        let rules = RuleEngine::new(dbc.clone(), config.rules.clone(), start_us);
        let health = BusHealth::new(config.bus.clone());
        let signals = SignalTable::new(&dbc);
        let heartbeat = config.heartbeat.as_ref().map(|h| HeartbeatState {
            next_due: start_us,
            counter: h
                .counter
                .and_then(|c| {
                    dbc.signal(SignalRef {
                        message: h.message,
                        signal: c,
                    })
                })
                .map_or(0.0, |s| s.physical_bounds().0.max(s.offset)),
        });
        let commanded = dbc
            .messages()
            .iter()
            .map(|m| vec![None; m.signals.len()])
            .collect();
        BridgeCore {
            dbc,
            config,
            rules,
            health,
            signals,
            counters: Counters::default(),
            heartbeat,
            commanded,
        }
    }

    /// The process loop begins reading the bus at `now_us`. Silence is counted from then for
    /// the messages not seen yet, not from the core's creation: joining the vehicle can take
    /// seconds, and frames that waited meanwhile must not find their sensor already declared
    /// lost. The first heartbeat is due then too.
    pub fn begin(&mut self, now_us: u64) {
        self.rules.restart_silence(now_us);
        if let Some(hb) = &mut self.heartbeat {
            hb.next_due = hb.next_due.max(now_us);
        }
    }

    /// The DBC.
    pub fn dbc(&self) -> &Arc<Dbc> {
        &self.dbc
    }

    /// The configuration.
    pub fn config(&self) -> &CanConfig {
        &self.config
    }

    /// The latest signal values.
    pub fn signals(&self) -> &SignalTable {
        &self.signals
    }

    /// The counters.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// The bus state as last seen.
    pub fn bus_state(&self) -> BusState {
        self.health.state()
    }

    /// The earliest instant at which [`on_time`](Self::on_time) or
    /// [`poll_heartbeat`](Self::poll_heartbeat) has something to do.
    pub fn next_deadline(&self) -> Option<u64> {
        let hb = self.heartbeat.as_ref().map(|h| h.next_due);
        match (self.rules.next_deadline(), hb) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    fn decoded(&mut self, time_us: u64, dm: &DecodedMessage) -> Vec<EventOut> {
        self.signals.update(time_us, dm);
        self.counters.decode_errors += dm
            .signals
            .iter()
            .filter(|s| !s.physical.is_finite())
            .count() as u64;
        self.rules.on_message(time_us, dm)
    }

    /// Takes a frame received at `time_us`.
    pub fn on_frame(&mut self, time_us: u64, frame: &Frame) -> FrameReport {
        self.counters.frames += 1;
        let outcome = self.dbc.decode(frame);
        let events = match &outcome {
            DecodeOutcome::Message(dm) => {
                self.counters.decoded += 1;
                self.decoded(time_us, dm)
            }
            DecodeOutcome::UnknownId(_) => {
                self.counters.unknown_id += 1;
                self.rules.on_time(time_us)
            }
            DecodeOutcome::WrongLength { .. } => {
                self.counters.wrong_length += 1;
                self.rules.on_time(time_us)
            }
            DecodeOutcome::Remote(_) => {
                self.counters.remote += 1;
                self.rules.on_time(time_us)
            }
            DecodeOutcome::Error => {
                self.counters.error_frames += 1;
                let mut events = self.rules.on_time(time_us);
                events.extend(self.health.on_error_frame(time_us, frame));
                events
            }
        };
        self.counters.events += events.len() as u64;
        FrameReport { outcome, events }
    }

    /// Advances the time to `time_us`: staleness and hold times due by then.
    pub fn on_time(&mut self, time_us: u64) -> Vec<EventOut> {
        let events = self.rules.on_time(time_us);
        self.counters.events += events.len() as u64;
        events
    }

    /// Takes the state the interface reports (netlink, or the memory bus).
    pub fn on_bus_state(&mut self, time_us: u64, state: BusState) -> Vec<EventOut> {
        let events = self.health.on_state(time_us, state);
        self.counters.events += events.len() as u64;
        events
    }

    /// The heartbeat frame, when one is due at `time_us`; the next is then due one period
    /// later (or one period after `time_us`, when the caller fell behind by more than a period).
    pub fn poll_heartbeat(&mut self, time_us: u64) -> Option<Frame> {
        let spec = self.config.heartbeat.as_ref()?;
        let st = self.heartbeat.as_mut()?;
        if time_us < st.next_due {
            return None;
        }
        let m = self.dbc.message(spec.message)?;
        let mut values: Vec<(&str, f64)> = spec
            .values
            .iter()
            .filter_map(|(i, v)| Some((m.signals.get(*i)?.name.as_str(), *v)))
            .collect();
        if let Some(c) = spec.counter.and_then(|c| m.signals.get(c)) {
            values.push((c.name.as_str(), st.counter));
            let (lo, hi) = c.physical_bounds();
            let next = st.counter + c.factor.abs();
            st.counter = if next > hi + 1e-9 {
                lo.max(c.offset)
            } else {
                next
            };
        }
        st.next_due = if time_us - st.next_due >= spec.period_us {
            time_us.saturating_add(spec.period_us)
        } else {
            st.next_due.saturating_add(spec.period_us)
        };
        match self.dbc.encode_message(spec.message, &values) {
            Ok(frame) => {
                self.counters.heartbeats += 1;
                Some(frame)
            }
            Err(_) => {
                self.counters.heartbeats_failed += 1;
                None
            }
        }
    }

    /// Encodes a command from a program: physical values by signal name (numbers, bools,
    /// value-table names). Signals not given keep their last commanded value, else the DBC's
    /// start value. Hand the frame to [`on_sent`](Self::on_sent) once the bus took it.
    pub fn command(
        &mut self,
        message: &str,
        values: &[(&str, Value)],
    ) -> Result<Frame, CommandError> {
        let result = self.command_inner(message, values);
        match &result {
            Ok(_) => self.counters.commands += 1,
            Err(_) => self.counters.commands_refused += 1,
        }
        result
    }

    fn command_inner(
        &mut self,
        message: &str,
        values: &[(&str, Value)],
    ) -> Result<Frame, CommandError> {
        let id = self
            .dbc
            .message_by_name(message)
            .filter(|id| self.config.commands.messages.contains(id))
            .ok_or_else(|| CommandError::NotAllowed(message.to_owned()))?;
        let dbc = self.dbc.clone();
        let m = dbc
            .message(id)
            .ok_or_else(|| CommandError::NotAllowed(message.to_owned()))?;
        let mut physical: Vec<(&str, f64)> = Vec::new();
        for (name, v) in values {
            let signal = m.signal_index(name).and_then(|i| m.signals.get(i));
            let x = match v {
                Value::Float(f) => *f,
                Value::Int(i) => *i as f64,
                Value::Bool(b) => f64::from(u8::from(*b)),
                Value::Text(label) => signal.and_then(|s| s.value_of(label)).ok_or_else(|| {
                    CommandError::UnknownLabel {
                        signal: format!("{message}.{name}"),
                        label: label.clone(),
                    }
                })?,
                Value::FloatList(_) => {
                    return Err(CommandError::BadValue {
                        signal: format!("{message}.{name}"),
                        ty: "[float]",
                    })
                }
            };
            physical.push((name, x));
        }
        // Fill in the signals not given: last commanded, else the DBC's start value; for a
        // multiplexed message, only the signals the switch selects.
        let known = |i: usize, physical: &[(&str, f64)]| {
            let name = m.signals[i].name.as_str();
            physical
                .iter()
                .find(|(n, _)| *n == name)
                .map(|(_, v)| *v)
                .or(self.commanded[id][i])
                .or(m.signals[i].start_value)
        };
        let switch_raw = m.multiplexor.and_then(|i| {
            let s = &m.signals[i];
            let v = known(i, &physical)?;
            s.bits_from_physical(v).ok().map(|b| s.raw_from_bits(b))
        });
        let mut filled = Vec::new();
        for (i, s) in m.signals.iter().enumerate() {
            if physical.iter().any(|(n, _)| *n == s.name) {
                continue;
            }
            if let Mux::Multiplexed(v) = s.mux {
                if switch_raw != Some(i128::from(v)) {
                    continue;
                }
            }
            if let Some(v) = known(i, &physical) {
                filled.push((s.name.as_str(), v));
            }
        }
        physical.extend(filled);
        let frame = dbc
            .encode_message(id, &physical)
            .map_err(CommandError::Encode)?;
        for (name, v) in &physical {
            if let Some(i) = m.signal_index(name) {
                self.commanded[id][i] = Some(*v);
            }
        }
        Ok(frame)
    }

    /// Takes a frame the bridge sent at `time_us` (a command, a heartbeat): its signals become
    /// the latest values and the rules see them (a band whose target is a commanded signal),
    /// as replaying a log that recorded it does. It is not counted as received.
    pub fn on_sent(&mut self, time_us: u64, frame: &Frame) -> Vec<EventOut> {
        let events = match self.dbc.decode(frame) {
            DecodeOutcome::Message(dm) => self.decoded(time_us, &dm),
            _ => self.rules.on_time(time_us),
        };
        self.counters.events += events.len() as u64;
        events
    }

    /// Encodes a command received as a call, `function(args)`: the function is the message's
    /// name, the arguments its signals in DBC order (multiplexed messages are refused: name
    /// their signals with [`command`](Self::command)).
    pub fn command_call(&mut self, function: &str, args: &[Value]) -> Result<Frame, CommandError> {
        let dbc = self.dbc.clone();
        let Some(m) = dbc
            .message_by_name(function)
            .filter(|id| self.config.commands.messages.contains(id))
            .and_then(|id| dbc.message(id))
        else {
            self.counters.commands_refused += 1;
            return Err(CommandError::NotAllowed(function.to_owned()));
        };
        if m.multiplexor.is_some() {
            self.counters.commands_refused += 1;
            return Err(CommandError::Multiplexed(m.name.clone()));
        }
        let names: Vec<&str> = m.signals.iter().map(|s| s.name.as_str()).collect();
        if names.len() != args.len() {
            self.counters.commands_refused += 1;
            return Err(CommandError::Arity {
                message: m.name.clone(),
                expected: names.len(),
                got: args.len(),
            });
        }
        let values: Vec<(&str, Value)> = names.into_iter().zip(args.iter().cloned()).collect();
        let name = m.name.clone();
        self.command(&name, &values)
    }
}
