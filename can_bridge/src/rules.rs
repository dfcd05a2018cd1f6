//! The engine that runs the rules turning signals into player events.
//!
//! The rules are written in the project's `can.toml` (its format is in [`crate::config`] and in
//! the crate's README); [`check_rules`](crate::config::check_rules) reads and checks them
//! against the DBC and the project's events and gives a
//! [`CanConfig`](crate::config::CanConfig). The [`RuleEngine`] is a pure state machine over its
//! rules: decoded frames and the time go in ([`RuleEngine::on_message`],
//! [`RuleEngine::on_time`]), events come out, in a deterministic order, stamped with the time
//! they happened.
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

use std::sync::Arc;

use petrel_nets::compiled::Value;
use petrel_nets::model::Type;

use crate::config::{Condition, Edge, ParamSource, Rule, RuleKind, Target};
use crate::dbc::{Dbc, DecodedMessage, SignalRef};
use crate::event::{EventCause, EventOut};

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

/// Runs the rules of a [`CanConfig`](crate::config::CanConfig) over decoded frames and time.
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
        EventOut::new(time_us, EventCause::Rule(rule), r.event.clone(), params)
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
