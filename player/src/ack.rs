//! The player's ledger of its senders: what it took from each, what it refused and why, and
//! what is settled on the flight record. Its [`Ack`]s go out in every heartbeat, where senders
//! wait for them before they leave (their shared memory goes with their process).
//!
//! The ledger is bounded: a sender that left (no longer connected to the events service) is
//! forgotten [`LINGER`] after its last message, and a heartbeat carries at most
//! [`MAX_ACKS`] senders, the most recently active first.

use petrel_ipc::wire::{cut_text, Ack, AckRefusal, MAX_ACKS, MAX_REASON_LEN, MAX_REFUSALS};
use petrel_ipc::Origin;
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// How long a sender that left stays in the ledger after its last message: long enough for
/// its last acknowledgement to be read by whoever waits for it.
pub const LINGER: Duration = Duration::from_secs(5);

/// What the ledger knows of one sender.
#[derive(Debug, Clone)]
pub struct Account {
    /// The acknowledgement sent for it.
    pub ack: Ack,
    /// Messages from it that did not decode (for people: `petrel status`).
    pub undecodable: u64,
    /// When it last sent something.
    pub last_active: Instant,
    /// Order of activity (larger: more recent), to list the most recently active first.
    pub order: u64,
    /// Taken events not yet settled on the record.
    unsettled: u64,
}

/// The ledger of every sender the player heard from.
#[derive(Debug, Default)]
pub struct Ledger {
    accounts: HashMap<u64, Account>,
    tick: u64,
    /// When the messages being accounted arrived ([`set_clock`](Self::set_clock)); `None`:
    /// the clock is read for each.
    clock: Option<Instant>,
}

impl Ledger {
    /// An empty ledger.
    pub fn new() -> Self {
        Ledger::default()
    }

    /// The messages accounted from now on arrived at `now` (the player reads the clock once
    /// when its wait ends, not once per message).
    pub fn set_clock(&mut self, now: Instant) {
        self.clock = Some(now);
    }

    fn account(&mut self, sender: u64, origin: Origin, seq: u64, missed: u64) -> &mut Account {
        self.tick += 1;
        let order = self.tick;
        let now = self.clock.unwrap_or_else(Instant::now);
        let a = self.accounts.entry(sender).or_insert_with(|| Account {
            ack: Ack {
                sender,
                origin: origin.as_str().to_string(),
                ..Ack::default()
            },
            undecodable: 0,
            last_active: now,
            order,
            unsettled: 0,
        });
        a.last_active = now;
        a.order = order;
        a.ack.received += 1;
        a.ack.missing += missed;
        if seq > a.ack.last_seq {
            // Refusals and events settle together with what came before them: a message
            // older than the last settled one cannot exist (sequence numbers only grow).
            a.ack.last_seq = seq;
        }
        a
    }

    /// Message `seq` of `sender` was taken into the engine's queue (and appended to the
    /// journal). It is settled at the next [`settle`](Self::settle).
    pub fn taken(&mut self, sender: u64, origin: Origin, seq: u64, missed: u64) {
        let a = self.account(sender, origin, seq, missed);
        a.ack.taken += 1;
        a.ack.pending += 1;
        a.unsettled += 1;
    }

    /// Message `seq` of `sender` was refused, for `reason`. `undecodable`: its body did not
    /// decode.
    pub fn refused(
        &mut self,
        sender: u64,
        origin: Origin,
        seq: u64,
        missed: u64,
        reason: &str,
        undecodable: bool,
    ) {
        let a = self.account(sender, origin, seq, missed);
        a.ack.refused += 1;
        if undecodable {
            a.undecodable += 1;
        }
        let mut reason = reason.to_string();
        cut_text(&mut reason, MAX_REASON_LEN);
        if a.ack.refusals.len() == MAX_REFUSALS {
            a.ack.refusals.remove(0);
        }
        a.ack.refusals.push(AckRefusal { seq, reason });
    }

    /// Everything taken so far is on the flight record (the journal was flushed, or there is
    /// none): every sender's messages up to its last one are settled.
    pub fn settle(&mut self) {
        for a in self.accounts.values_mut() {
            a.ack.pending = a.ack.pending.saturating_sub(a.unsettled);
            a.unsettled = 0;
            a.ack.settled_seq = a.ack.last_seq;
        }
    }

    /// The flight recorder dropped everything not yet on record: those events are settled as
    /// unrecorded (processed, but lost from the record).
    pub fn lose_unsettled(&mut self) {
        for a in self.accounts.values_mut() {
            a.ack.pending = a.ack.pending.saturating_sub(a.unsettled);
            a.ack.unrecorded += a.unsettled;
            a.unsettled = 0;
            a.ack.settled_seq = a.ack.last_seq;
        }
    }

    /// Forgets the senders that are not in `live` (the events service's senders now) and sent
    /// nothing for [`LINGER`]; returns their ids, for the receiver to forget them too.
    pub fn prune(&mut self, live: &[u64]) -> Vec<u64> {
        let now = Instant::now();
        let gone: Vec<u64> = self
            .accounts
            .iter()
            .filter(|(id, a)| {
                !live.contains(id)
                    && now.duration_since(a.last_active) >= LINGER
                    && a.unsettled == 0
            })
            .map(|(id, _)| *id)
            .collect();
        for id in &gone {
            self.accounts.remove(id);
        }
        gone
    }

    /// The accounts, the most recently active first, at most [`MAX_ACKS`].
    pub fn recent(&self) -> Vec<&Account> {
        let mut v: Vec<&Account> = self.accounts.values().collect();
        v.sort_by_key(|a| std::cmp::Reverse(a.order));
        v.truncate(MAX_ACKS);
        v
    }

    /// The acknowledgements a heartbeat carries: the most recently active senders first, at
    /// most [`MAX_ACKS`].
    pub fn acks(&self) -> Vec<Ack> {
        self.recent().into_iter().map(|a| a.ack.clone()).collect()
    }

    /// Senders in the ledger.
    pub fn len(&self) -> usize {
        self.accounts.len()
    }

    /// True when no sender is in the ledger.
    pub fn is_empty(&self) -> bool {
        self.accounts.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taken_events_settle_or_are_lost() {
        let mut l = Ledger::new();
        let o = Origin::new("tool/send1");
        l.taken(1, o, 1, 0);
        l.taken(1, o, 2, 0);
        let a = &l.acks()[0];
        assert_eq!((a.last_seq, a.settled_seq, a.pending), (2, 0, 2));
        l.settle();
        let a = &l.acks()[0];
        assert_eq!((a.settled_seq, a.pending, a.unrecorded), (2, 0, 0));
        l.taken(1, o, 3, 0);
        l.refused(1, o, 4, 0, "unknown event `x`", false);
        l.lose_unsettled();
        let a = &l.acks()[0];
        assert_eq!(
            (a.settled_seq, a.pending, a.unrecorded, a.refused),
            (4, 0, 1, 1)
        );
        assert_eq!(a.refusals[0].seq, 4);
    }

    #[test]
    fn the_ledger_is_bounded() {
        let mut l = Ledger::new();
        for s in 0..200u64 {
            l.taken(s, Origin::new("tool/x"), 1, 0);
            for i in 0..5 {
                l.refused(s, Origin::new("tool/x"), 2 + i, 0, &"r".repeat(1000), true);
            }
        }
        let acks = l.acks();
        assert_eq!(acks.len(), MAX_ACKS);
        assert_eq!(acks[0].sender, 199, "the most recently active first");
        assert!(acks.iter().all(|a| a.refusals.len() == MAX_REFUSALS
            && a.refusals.iter().all(|r| r.reason.len() <= MAX_REASON_LEN)));
        // Nobody is connected, but they all just sent: they linger.
        l.settle();
        assert!(l.prune(&[]).is_empty());
        assert_eq!(l.len(), 200);
    }
}
