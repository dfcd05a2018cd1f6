//! What the player does with each message it takes from the events service, sans I/O (the
//! runtime hands over what its receiver took): an event is submitted to the engine (journaled
//! as it is accepted); a refusal, whoever refuses (the engine: unknown event, parameters, a
//! catastrophic end; the player: a built-in event from another process, a body that does not
//! decode, another wire version), is counted, journaled, acknowledged with its reason and told
//! to the nets (`bad_message`, except after a catastrophic end); a program's
//! [`LEAVE`](petrel_ipc::wire::LEAVE) is noted, for the liveness check to record a stop rather
//! than a loss.
//!
//! Every message is answered (the sender's [`Ack`](petrel_ipc::wire::Ack) says taken or
//! refused, with the reason), and every message but a leave is one submission the engine
//! counts: `received = processed + unused + refused + queued` holds on every path. The tests
//! check both over random mixes of messages.

use crate::ack::Ledger;
use crate::engine::{Engine, Refusal};
use crate::journal::{Entry, Journal};
use petrel_ipc::{Origin, Received, Role};
use petrel_nets::compiled::{EventId, Value};
use std::collections::BTreeSet;
use tracing::{debug, info, warn};

/// Why an event that arrived on the events service names a built-in event it may not: `None`
/// when it may.
///
/// Built-in events (`program_lost`, `call_failed`, `safety_violation`, `livelock`,
/// `bad_message`) tell the nets what the player itself saw, and the player raises them without
/// the events service: one arriving there comes from another process, whatever origin it
/// claims (`player` included), and is refused. The exceptions are `call_failed` from the CAN
/// data server, which reports the CAN commands it could not carry out as the failed calls they
/// are (see `petrel_can_bridge::runtime`), and `call_failed` from a gateway, which reports the
/// calls the link to another computer could not carry (docs/gateway.md).
pub fn builtin_refusal(name: &str, origin: &str) -> Option<String> {
    if !petrel_nets::model::builtin_events()
        .iter()
        .any(|b| b.name.text == name)
    {
        return None;
    }
    if name == "call_failed"
        && (origin == Role::CanBridge.node_name() || Role::is_gateway_node(origin))
    {
        return None;
    }
    Some(format!(
        "`{name}` is a built-in event: only the player raises it (refused from `{origin}`)"
    ))
}

/// Submits an event raised by the player itself, journaled like any input.
pub fn raise(
    engine: &mut Engine,
    journal: &mut Journal,
    event: Option<EventId>,
    params: Vec<Value>,
) {
    let Some(e) = event else { return };
    let record = Entry::Submit {
        time: engine.now(),
        event: engine.project().events[e as usize].name.clone(),
        params: params.clone(),
        origin: "player".into(),
        seq: 0,
    };
    match engine.submit(e, params) {
        Ok(()) => journal.append(&record),
        Err(r) => debug!(refusal = %r, "built-in event refused"),
    }
}

/// The sender of a message, as its header says.
#[derive(Clone, Copy, Debug)]
pub struct Header {
    /// The sending port's id.
    pub sender: u64,
    /// Its origin.
    pub origin: Origin,
    /// The message's sequence number.
    pub seq: u64,
    /// Messages of the sender missed just before this one.
    pub missed: u64,
}

impl<M> From<&Received<M>> for Header {
    fn from(r: &Received<M>) -> Self {
        Header {
            sender: r.sender,
            origin: r.origin,
            seq: r.seq,
            missed: r.missed,
        }
    }
}

/// The player's parts a message touches, borrowed for one drain of the events service.
pub struct Intake<'a, 'p> {
    /// The engine the events go to.
    pub engine: &'a mut Engine<'p>,
    /// The flight recorder.
    pub journal: &'a mut Journal,
    /// The senders' accounts (the heartbeat's acknowledgements).
    pub ledger: &'a mut Ledger,
    /// Messages received (decoded or not): the player's `messages`.
    pub messages: &'a mut u64,
    /// Messages refused as bad (told to the nets) and receiver failures: its `bad_messages`.
    pub bad_messages: &'a mut u64,
    /// The project's `bad_message` event.
    pub bad_message: Option<EventId>,
    /// The programs that said they leave in good order, since they last joined.
    pub leaves: &'a mut BTreeSet<String>,
}

impl Intake<'_, '_> {
    /// An event `name` whose parameters were decoded into `decoded` (moved out of it).
    pub fn event(&mut self, from: Header, name: &str, decoded: &mut Vec<Value>) {
        *self.messages += 1;
        let origin = from.origin.as_str();
        if name == petrel_ipc::wire::LEAVE {
            return self.leave(from, decoded);
        }
        if let Some(reason) = builtin_refusal(name, origin) {
            decoded.clear();
            self.engine.count_refused();
            return self.refuse(Some(from), origin, name, reason, false, true);
        }
        let time = self.engine.now();
        let mut params = self.engine.param_buffer();
        params.append(decoded);
        let journal = &mut *self.journal;
        // Journaled from the parameters the engine keeps, before it queues the event: no copy
        // of the event on the way to its call.
        let submitted = self.engine.submit_named_with(name, params, |params| {
            journal.append_submit(time, name, params, origin, from.seq);
        });
        match submitted {
            Ok(()) => self
                .ledger
                .taken(from.sender, from.origin, from.seq, from.missed),
            Err(refusal) => {
                // After a catastrophic end nothing is wrong with the message: no bad_message.
                let bad = !matches!(refusal, Refusal::AfterCatastrophic(_));
                self.refuse(Some(from), origin, name, refusal.to_string(), false, bad);
            }
        }
    }

    /// A program's leave: noted if it comes from a program of the project as itself, refused
    /// otherwise (as any message that means nothing to the player).
    fn leave(&mut self, from: Header, decoded: &mut Vec<Value>) {
        let origin = from.origin.as_str();
        let project = self.engine.project();
        let program = origin
            .strip_prefix("program/")
            .filter(|p| project.programs.iter().any(|q| q.name == *p));
        match program {
            Some(program) if decoded.is_empty() => {
                info!(program, "program says it leaves in good order");
                self.leaves.insert(program.to_string());
                self.ledger
                    .taken(from.sender, from.origin, from.seq, from.missed);
            }
            _ => {
                decoded.clear();
                self.engine.count_refused();
                let reason = format!(
                    "`{}` from `{origin}`: only a program of the project says it leaves, as itself (`program/NAME`), without parameters",
                    petrel_ipc::wire::LEAVE
                );
                self.refuse(
                    Some(from),
                    origin,
                    petrel_ipc::wire::LEAVE,
                    reason,
                    false,
                    true,
                );
            }
        }
    }

    /// A message whose body did not decode (`from.sender` known).
    pub fn undecodable(&mut self, from: Header, error: &str) {
        *self.messages += 1;
        self.engine.count_refused();
        let reason = format!("undecodable: {error}");
        let origin = from.origin.as_str().to_string();
        self.refuse(Some(from), &origin, "(undecodable)", reason, true, true);
    }

    /// A message of another wire version or kind, whose sender the player cannot acknowledge
    /// (a process of another Petrel: it cannot read the acknowledgement either).
    pub fn foreign(&mut self, origin: &str, reason: &str) {
        *self.messages += 1;
        self.engine.count_refused();
        self.refuse(None, origin, "(foreign)", reason.to_string(), false, true);
    }

    /// The receiver failed (not a message): logged and counted in `bad_messages`.
    pub fn failed(&mut self, error: &dyn std::fmt::Display) {
        *self.bad_messages += 1;
        warn!(error = %error, "events could not be received");
    }

    /// A refused message: acknowledged with the reason (when its sender is known), journaled,
    /// logged and, if `bad`, counted as a bad message and told to the nets.
    fn refuse(
        &mut self,
        from: Option<Header>,
        origin: &str,
        what: &str,
        reason: String,
        undecodable: bool,
        bad: bool,
    ) {
        if let Some(f) = from {
            self.ledger
                .refused(f.sender, f.origin, f.seq, f.missed, &reason, undecodable);
        }
        self.journal.append(&Entry::Refused {
            time: self.engine.now(),
            what: what.to_owned(),
            reason: reason.clone(),
            origin: origin.to_string(),
        });
        let seq = from.map(|f| f.seq);
        if !bad {
            info!(from = %origin, ?seq, %reason, "event refused");
            return;
        }
        *self.bad_messages += 1;
        warn!(from = %origin, ?seq, %reason, "event refused");
        let params = vec![Value::Text(origin.to_string()), Value::Text(reason)];
        raise(self.engine, self.journal, self.bad_message, params);
    }
}

#[cfg(test)]
mod tests;
