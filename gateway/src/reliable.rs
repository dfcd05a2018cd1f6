//! Carried messages, sans I/O: the events and calls that cross the link go on a numbered
//! stream from this gateway to the one gateway that delivers them, stay in a bounded buffer
//! until that gateway acknowledges them, are sent again when it does not, and are given up past
//! a bound, their senders told. docs/gateway.md ("Nothing lost unsaid") is the protocol for
//! people; this is its two ends.
//!
//! - [`Outgoing`], the sending end: per destination computer, the buffer ([`MAX_BUFFERED`]
//!   messages, [`MAX_BUFFERED_BYTES`] bytes), numbering on the stream to the destination's
//!   current incarnation, what is due to be sent (new, or unacknowledged for [`Bounds::resend_us`]),
//!   what is given up: unacknowledged at `retention`, numbered for an incarnation of the
//!   destination that has gone, refused by the destination, or refused at once (a full buffer).
//! - [`Incoming`], the receiving end: per sending computer and incarnation, the next number
//!   expected, copies discarded (already taken, out of order, too late, for an earlier
//!   incarnation of this gateway), what it took and refused, to acknowledge; and the hold
//!   that keeps a returning computer's messages back until the player has taken its
//!   `link_restored`.
//!
//! Time is the caller's: microseconds since the gateway started. A copy is sent only while it
//! is younger than `retention - detection`, and a receiver takes a copy only when it crossed in
//! less than half the detection bound (by the sender's clock as the receiver estimates it): so
//! a copy that waited in a buffer of a stopped process or a dead connection is never delivered
//! after its sender was told it failed.

use std::collections::{BTreeMap, VecDeque};

use crate::link::{Carried, LinkMsg, StreamAck, MAX_STREAM_REFUSALS};

/// Carried messages buffered at most per destination computer.
pub const MAX_BUFFERED: usize = 1024;

/// Bytes of carried messages (their bodies) buffered at most per destination computer.
pub const MAX_BUFFERED_BYTES: usize = 16 << 20;

/// Incarnations of one peer whose streams a receiver remembers (a peer that restarts starts a
/// new stream; an old one's late copies must still be told from new messages).
const INCARNATIONS_KEPT: usize = 4;

/// The bounds of the protocol, from the plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bounds {
    /// A carried message unacknowledged this long is given up, microseconds.
    pub retention_us: u64,
    /// The detection bound: no copy is sent in the last `detection` before `retention`, and a
    /// receiver takes no copy that crossed in half of it or more.
    pub detection_us: u64,
    /// An unacknowledged copy is sent again after this long while its destination is up.
    pub resend_us: u64,
}

impl Bounds {
    /// The bounds for a detection bound and a retention bound (microseconds).
    pub fn new(detection_us: u64, retention_us: u64) -> Self {
        Bounds {
            retention_us,
            detection_us,
            resend_us: (detection_us / 2).max(100_000),
        }
    }

    /// The age past which a message is no longer sent (it waits to be given up).
    fn last_send_us(&self) -> u64 {
        self.retention_us.saturating_sub(self.detection_us)
    }
}

/// A carried message given up: its sender must be told.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Failure {
    /// The computer it was for.
    pub to: String,
    /// The message (origin, ipc sender and sequence number, kind, body).
    pub msg: LinkMsg,
    /// Why, for the sender and the counters.
    pub reason: String,
}

#[derive(Debug, Clone)]
struct Entry {
    msg: LinkMsg,
    /// When the gateway took it (the judging clock).
    taken_us: u64,
    /// When a copy was last sent (the judging clock); `None`: due now.
    sent_us: Option<u64>,
    /// Whether a copy was ever sent (the next ones are retransmissions).
    sent_before: bool,
    /// Its number, on the stream to the incarnation `.0` of the destination.
    number: Option<(u64, u64)>,
}

/// The sending end of the stream to one destination computer.
#[derive(Debug, Clone, Default)]
struct Outbound {
    entries: VecDeque<Entry>,
    bytes: usize,
    /// The destination's incarnation the stream goes to, and the next number on it.
    stream: Option<(u64, u64)>,
}

/// What [`Outgoing::due`] hands over: copies to put on the link, and whether each is a first.
#[derive(Debug, Default)]
pub struct Due {
    /// The copies, each with its [`Carried`] set (the caller numbers and stamps them).
    pub copies: Vec<LinkMsg>,
    /// How many of them were sent before (retransmissions).
    pub again: Vec<bool>,
}

/// The sending end of every stream of this gateway.
#[derive(Debug, Clone)]
pub struct Outgoing {
    bounds: Bounds,
    to: BTreeMap<String, Outbound>,
}

impl Outgoing {
    /// No stream yet.
    pub fn new(bounds: Bounds) -> Self {
        Outgoing {
            bounds,
            to: BTreeMap::new(),
        }
    }

    /// Messages waiting for the acknowledgement of `to`'s gateway.
    pub fn buffered(&self, to: &str) -> usize {
        self.to.get(to).map_or(0, |o| o.entries.len())
    }

    /// Takes `msg` for computer `to` at `now_us`; a full buffer refuses it (returned as the
    /// failure, never numbered: the stream goes on without it).
    pub fn queue(&mut self, to: &str, msg: LinkMsg, now_us: u64) -> Result<(), Box<Failure>> {
        let out = self.to.entry(to.to_owned()).or_default();
        if out.entries.len() >= MAX_BUFFERED || out.bytes + msg.body.len() > MAX_BUFFERED_BYTES {
            return Err(Box::new(Failure {
                to: to.to_owned(),
                reason: format!(
                    "the link to computer `{to}` holds {} unacknowledged messages ({} bytes): the buffer is full",
                    out.entries.len(),
                    out.bytes
                ),
                msg,
            }));
        }
        out.bytes += msg.body.len();
        out.entries.push_back(Entry {
            msg,
            taken_us: now_us,
            sent_us: None,
            sent_before: false,
            number: None,
        });
        Ok(())
    }

    /// Copies due for `to`, whose gateway is up with incarnation `incarnation`: the new ones
    /// (numbered now), and those unacknowledged since [`Bounds::resend_us`]; none older than
    /// `retention - detection`.
    pub fn due(&mut self, to: &str, incarnation: u64, now_us: u64) -> Due {
        let mut due = Due::default();
        let bounds = self.bounds;
        let Some(out) = self.to.get_mut(to) else {
            return due;
        };
        if out.stream.is_none_or(|(inc, _)| inc != incarnation) {
            // A first stream, or the destination restarted (its numbered messages were given up
            // by `restarted`): number from 1 again.
            out.stream = Some((incarnation, 1));
        }
        let floor = out
            .entries
            .iter()
            .find_map(|e| {
                e.number
                    .filter(|(inc, _)| *inc == incarnation)
                    .map(|(_, n)| n)
            })
            .unwrap_or_else(|| out.stream.map_or(1, |(_, next)| next));
        for e in out.entries.iter_mut() {
            if now_us.saturating_sub(e.taken_us) >= bounds.last_send_us() {
                // Too old to be sent: it will be given up; a receiver taking it now might do so
                // after its sender was told it failed.
                continue;
            }
            if e.sent_us
                .is_some_and(|s| now_us.saturating_sub(s) < bounds.resend_us)
            {
                continue;
            }
            let n = match e.number {
                Some((inc, n)) if inc == incarnation => n,
                // Numbered for an incarnation gone (`restarted` gives those up first).
                Some(_) => continue,
                None => {
                    let (inc, next) = out.stream.as_mut().expect("set above");
                    e.number = Some((*inc, *next));
                    *next += 1;
                    *next - 1
                }
            };
            let mut copy = e.msg.clone();
            copy.carried = Some(Carried {
                to: to.to_owned(),
                to_incarnation: incarnation,
                seq: n,
                floor,
            });
            due.again.push(e.sent_before);
            due.copies.push(copy);
            e.sent_us = Some(now_us);
            e.sent_before = true;
        }
        due
    }

    /// Every unacknowledged message for `to` is due now (its gateway was heard again).
    pub fn resend(&mut self, to: &str) {
        if let Some(out) = self.to.get_mut(to) {
            for e in out.entries.iter_mut() {
                e.sent_us = None;
            }
        }
    }

    /// `to`'s gateway has a new incarnation: what was numbered for another one is given up (it
    /// may or may not have been delivered before that gateway stopped); the rest waits for the
    /// new stream.
    pub fn restarted(&mut self, to: &str, incarnation: u64) -> Vec<Failure> {
        let Some(out) = self.to.get_mut(to) else {
            return Vec::new();
        };
        let mut failures = Vec::new();
        let mut kept = VecDeque::new();
        for e in out.entries.drain(..) {
            match e.number {
                Some((inc, _)) if inc != incarnation => {
                    out.bytes -= e.msg.body.len();
                    failures.push(Failure {
                        to: to.to_owned(),
                        msg: e.msg,
                        reason: format!(
                            "the gateway of computer `{to}` restarted before acknowledging it (it may have been delivered)"
                        ),
                    });
                }
                _ => kept.push_back(e),
            }
        }
        out.entries = kept;
        out.stream = None;
        failures
    }

    /// `to`'s gateway (incarnation `incarnation`) took the stream up to `ack.taken`: those
    /// leave the buffer (wherever they are in it: one too old to be sent again may wait before
    /// them to be given up). Returns the ones it took (acknowledged) and those it refused
    /// (failed, with its reason).
    pub fn acknowledged(
        &mut self,
        to: &str,
        incarnation: u64,
        ack: &StreamAck,
    ) -> (Vec<LinkMsg>, Vec<Failure>) {
        let (mut taken, mut failures) = (Vec::new(), Vec::new());
        let Some(out) = self.to.get_mut(to) else {
            return (taken, failures);
        };
        let mut kept = VecDeque::with_capacity(out.entries.len());
        for e in out.entries.drain(..) {
            let n = match e.number {
                Some((inc, n)) if inc == incarnation && n <= ack.taken => n,
                _ => {
                    kept.push_back(e);
                    continue;
                }
            };
            out.bytes -= e.msg.body.len();
            match ack.refused.iter().find(|(seq, _)| *seq == n) {
                Some((_, why)) => failures.push(Failure {
                    to: to.to_owned(),
                    msg: e.msg,
                    reason: format!("refused on computer `{to}`: {why}"),
                }),
                None => taken.push(e.msg),
            }
        }
        out.entries = kept;
        (taken, failures)
    }

    /// The messages unacknowledged at `retention` are given up (the oldest first).
    pub fn expire(&mut self, now_us: u64) -> Vec<Failure> {
        let mut failures = Vec::new();
        for (to, out) in self.to.iter_mut() {
            while out
                .entries
                .front()
                .is_some_and(|e| now_us.saturating_sub(e.taken_us) >= self.bounds.retention_us)
            {
                let e = out.entries.pop_front().expect("front");
                out.bytes -= e.msg.body.len();
                failures.push(Failure {
                    to: to.clone(),
                    msg: e.msg,
                    reason: format!(
                        "not acknowledged by the gateway of computer `{to}` within {} (the link was out)",
                        crate::core::seconds(self.bounds.retention_us)
                    ),
                });
            }
        }
        failures
    }
}

/// What the receiving end makes of a copy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accept {
    /// Next on its stream: deliver it (then [`Incoming::taken`]).
    Take,
    /// Next on its stream, but its computer is held (it came back and the player has not taken
    /// `link_restored` yet): kept for [`Incoming::release`].
    Held,
    /// Not taken: already taken, out of order (an earlier one will come again), too late, or
    /// for an earlier incarnation of this gateway.
    Discard(Discarded),
}

/// Why a copy was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Discarded {
    /// Taken before (its acknowledgement did not reach the sender in time).
    Duplicate,
    /// An earlier message of its stream is missing: it will come again after it.
    OutOfOrder,
    /// It crossed in half the detection bound or more: its sender may have given it up.
    Late,
    /// For another incarnation of this gateway (one that ran before).
    NotThisGateway,
    /// Its computer is held and the hold is full: it will come again.
    HoldFull,
}

#[derive(Debug, Clone, Default)]
struct Stream {
    /// Every number up to this one was received (taken or held).
    received: u64,
    /// Every number up to this one was taken (delivered or refused here).
    taken: u64,
    refused: VecDeque<(u64, String)>,
    /// Something to acknowledge.
    ack_due: bool,
}

/// A computer held back after it came back.
#[derive(Debug, Clone)]
struct Hold {
    since_us: u64,
    /// The number the player's acknowledgement of this gateway must reach: the sequence number
    /// of `link_restored`, once sent.
    told: Option<u64>,
    queue: VecDeque<LinkMsg>,
}

/// The receiving end of every stream sent to this gateway.
#[derive(Debug, Clone)]
pub struct Incoming {
    bounds: Bounds,
    /// By sending computer and incarnation, in the order first heard.
    streams: Vec<((String, u64), Stream)>,
    /// By sending computer and incarnation: the least (arrival - sending) time seen, the
    /// difference of the two clocks plus the quickest crossing.
    offsets: BTreeMap<(String, u64), i128>,
    holds: BTreeMap<String, Hold>,
}

impl Incoming {
    /// No stream yet.
    pub fn new(bounds: Bounds) -> Self {
        Incoming {
            bounds,
            streams: Vec::new(),
            offsets: BTreeMap::new(),
            holds: BTreeMap::new(),
        }
    }

    /// A message of `from`'s incarnation `incarnation` arrived at `now_us`: the clocks'
    /// difference is at most what it shows.
    pub fn heard(&mut self, from: &str, incarnation: u64, sent_us: u64, now_us: u64) {
        let d = i128::from(now_us) - i128::from(sent_us);
        let key = (from.to_owned(), incarnation);
        if !self.offsets.contains_key(&key) {
            // Forget the incarnations beyond the ones kept (the oldest first heard).
            let same: Vec<_> = self
                .offsets
                .keys()
                .filter(|(f, _)| f == from)
                .cloned()
                .collect();
            if same.len() >= INCARNATIONS_KEPT {
                if let Some(old) = same.first() {
                    self.offsets.remove(old);
                }
            }
        }
        let o = self.offsets.entry(key).or_insert(d);
        *o = (*o).min(d);
    }

    fn stream(&mut self, from: &str, incarnation: u64) -> &mut Stream {
        let i = match self
            .streams
            .iter()
            .position(|((f, inc), _)| f == from && *inc == incarnation)
        {
            Some(i) => i,
            None => {
                let same = self.streams.iter().filter(|((f, _), _)| f == from).count();
                if same >= INCARNATIONS_KEPT {
                    if let Some(i) = self.streams.iter().position(|((f, _), _)| f == from) {
                        self.streams.remove(i);
                    }
                }
                self.streams
                    .push(((from.to_owned(), incarnation), Stream::default()));
                self.streams.len() - 1
            }
        };
        &mut self.streams[i].1
    }

    /// What to make of `msg` (carried, for this gateway of incarnation `me`), at `now_us`.
    pub fn accept(&mut self, msg: &LinkMsg, me: u64, now_us: u64) -> Accept {
        let Some(c) = &msg.carried else {
            return Accept::Take;
        };
        if c.to_incarnation != me {
            return Accept::Discard(Discarded::NotThisGateway);
        }
        let offset = self
            .offsets
            .get(&(msg.from.clone(), msg.incarnation))
            .copied()
            .unwrap_or(i128::from(now_us) - i128::from(msg.sent_us));
        let crossed = i128::from(now_us) - i128::from(msg.sent_us) - offset;
        let late = crossed >= i128::from(self.bounds.detection_us / 2);
        let held = self.holds.contains_key(&msg.from);
        let hold_full = self
            .holds
            .get(&msg.from)
            .is_some_and(|h| h.queue.len() >= MAX_BUFFERED);
        let s = self.stream(&msg.from, msg.incarnation);
        if c.floor > s.received + 1 {
            // The sender gave up (or saw acknowledged) everything before `floor`.
            s.received = c.floor - 1;
            s.taken = s.taken.max(c.floor - 1);
            let floor = c.floor;
            if let Some(h) = self.holds.get_mut(&msg.from) {
                h.queue.retain(|m| {
                    m.incarnation != msg.incarnation
                        || m.carried.as_ref().is_none_or(|c| c.seq >= floor)
                });
            }
        }
        let s = self.stream(&msg.from, msg.incarnation);
        if c.seq <= s.received {
            s.ack_due = true;
            return Accept::Discard(Discarded::Duplicate);
        }
        if late {
            return Accept::Discard(Discarded::Late);
        }
        if c.seq > s.received + 1 {
            s.ack_due = true;
            return Accept::Discard(Discarded::OutOfOrder);
        }
        if hold_full {
            return Accept::Discard(Discarded::HoldFull);
        }
        s.received = c.seq;
        if held {
            if let Some(h) = self.holds.get_mut(&msg.from) {
                h.queue.push_back(msg.clone());
            }
            Accept::Held
        } else {
            Accept::Take
        }
    }

    /// The carried `msg` was delivered here (`refusal`: `None`) or refused (the reason).
    pub fn taken(&mut self, msg: &LinkMsg, refusal: Option<String>) {
        let Some(c) = &msg.carried else {
            return;
        };
        let s = self.stream(&msg.from, msg.incarnation);
        s.taken = s.taken.max(c.seq);
        s.ack_due = true;
        if let Some(why) = refusal {
            if s.refused.len() == MAX_STREAM_REFUSALS {
                s.refused.pop_front();
            }
            s.refused.push_back((c.seq, why));
        }
    }

    /// The acknowledgements to send: every stream with something new, or that was sent a copy
    /// it had already taken.
    pub fn acks_due(&mut self) -> Vec<StreamAck> {
        let mut acks = Vec::new();
        for ((from, inc), s) in self.streams.iter_mut() {
            if s.ack_due {
                s.ack_due = false;
                acks.push(StreamAck {
                    from: from.clone(),
                    from_incarnation: *inc,
                    taken: s.taken,
                    refused: s.refused.iter().cloned().collect(),
                });
            }
        }
        acks
    }

    /// `from` came back at `now_us`: its messages wait until [`release`](Self::release).
    pub fn hold(&mut self, from: &str, now_us: u64) {
        self.holds.entry(from.to_owned()).or_insert(Hold {
            since_us: now_us,
            told: None,
            queue: VecDeque::new(),
        });
    }

    /// `link_restored(from)` was sent to the player as this gateway's message `seq`.
    pub fn told(&mut self, from: &str, seq: u64) {
        if let Some(h) = self.holds.get_mut(from) {
            h.told = Some(seq);
        }
    }

    /// Whether `from` is held.
    pub fn is_held(&self, from: &str) -> bool {
        self.holds.contains_key(from)
    }

    /// Ends the hold of `from`: its messages, in order, to deliver now.
    pub fn release(&mut self, from: &str) -> Vec<LinkMsg> {
        self.holds
            .remove(from)
            .map(|h| h.queue.into())
            .unwrap_or_default()
    }

    /// The player took (or refused) this gateway's messages up to `seq`: the holds waiting for
    /// one of them end. Returns the computers released.
    pub fn player_took(&mut self, seq: u64) -> Vec<String> {
        self.holds
            .iter()
            .filter(|(_, h)| h.told.is_some_and(|t| t <= seq))
            .map(|(c, _)| c.clone())
            .collect()
    }

    /// The holds older than `max_us` at `now_us` (a player that does not answer, or restarted
    /// and never heard of this gateway's message): the computers to release anyway.
    pub fn overdue(&self, now_us: u64, max_us: u64) -> Vec<String> {
        self.holds
            .iter()
            .filter(|(_, h)| now_us.saturating_sub(h.since_us) > max_us)
            .map(|(c, _)| c.clone())
            .collect()
    }
}
