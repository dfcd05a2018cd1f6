//! What became of the events this computer's senders sent to a player on another computer,
//! sans I/O: the gateway carried them (and the player's acknowledgement, translated back by the
//! player's computer, says the rest), or gave them up (the link was out past its bound, the
//! buffer was full, the player's computer refused them). A sender waits for its verdict in the
//! heartbeats (`petrel_ipc::wait_acknowledged`); the player cannot give the verdict on events
//! it never got, so the gateway gives it, in its own heartbeat: the player's acknowledgement
//! with the gateway's refusals merged in.

use std::collections::BTreeMap;

use petrel_ipc::wire::{cut_text, Ack, AckRefusal, MAX_ACKS, MAX_REASON_LEN, MAX_REFUSALS};

/// Senders kept at most (the least recently active go first).
const MAX_SENDERS: usize = 256;

/// Open messages kept per sender at most (the oldest go first).
const MAX_OPEN: usize = 4096;

/// How long a sender with nothing open stays after its last message, microseconds: longer
/// than any sender waits for its verdict.
pub const LINGER_US: u64 = 120_000_000;

#[derive(Debug, Clone, Default)]
struct Account {
    origin: String,
    /// Messages carried or waiting, by sequence number: `None` while the player has not
    /// settled it, the reason when the gateway gave it up.
    open: BTreeMap<u64, Option<String>>,
    /// The player's latest acknowledgement of the sender, as heard here.
    player: Option<Ack>,
    /// Messages given up, and the latest reasons.
    given_up: u64,
    refusals: Vec<AckRefusal>,
    /// Every message up to this one is settled (the open ones before it are forgotten).
    settled: u64,
    last_active_us: u64,
}

/// The accounts of this computer's senders whose events crossed the link.
#[derive(Debug, Clone, Default)]
pub struct Senders {
    accounts: BTreeMap<u64, Account>,
}

impl Senders {
    fn account(&mut self, sender: u64, origin: &str, now_us: u64) -> &mut Account {
        if !self.accounts.contains_key(&sender) && self.accounts.len() >= MAX_SENDERS {
            if let Some(oldest) = self
                .accounts
                .iter()
                .min_by_key(|(_, a)| a.last_active_us)
                .map(|(id, _)| *id)
            {
                self.accounts.remove(&oldest);
            }
        }
        let a = self.accounts.entry(sender).or_default();
        a.origin = origin.to_owned();
        a.last_active_us = now_us;
        a
    }

    /// Message `seq` of `sender` was taken for the link.
    pub fn carried(&mut self, sender: u64, seq: u64, origin: &str, now_us: u64) {
        let a = self.account(sender, origin, now_us);
        if a.open.len() >= MAX_OPEN {
            a.open.pop_first();
        }
        a.open.insert(seq, None);
    }

    /// Message `seq` of `sender` was given up, for `reason`.
    pub fn given_up(&mut self, sender: u64, seq: u64, origin: &str, reason: &str, now_us: u64) {
        let a = self.account(sender, origin, now_us);
        let mut reason = reason.to_owned();
        cut_text(&mut reason, MAX_REASON_LEN);
        a.open.insert(seq, Some(reason.clone()));
        a.given_up += 1;
        if a.refusals.len() == MAX_REFUSALS {
            a.refusals.remove(0);
        }
        a.refusals.push(AckRefusal { seq, reason });
    }

    /// The player's acknowledgements, as a heartbeat heard here carries them.
    pub fn player_acks(&mut self, acks: &[Ack]) {
        for ack in acks {
            if let Some(a) = self.accounts.get_mut(&ack.sender) {
                a.player = Some(ack.clone());
            }
        }
    }

    /// Forgets the senders idle for [`LINGER_US`] at `now_us`.
    pub fn prune(&mut self, now_us: u64) {
        self.accounts
            .retain(|_, a| now_us.saturating_sub(a.last_active_us) < LINGER_US);
    }

    /// The acknowledgements of the senders with messages given up (the others wait for the
    /// player's alone), the most recently active first, at most [`MAX_ACKS`].
    pub fn acks(&mut self) -> Vec<Ack> {
        let mut with: Vec<(u64, Ack)> = Vec::new();
        for (id, a) in self.accounts.iter_mut() {
            if a.given_up == 0 {
                continue;
            }
            let ack = merged(*id, a);
            // What is settled needs no keeping (the refusals are kept apart).
            a.settled = ack.settled_seq;
            a.open = a.open.split_off(&(ack.settled_seq + 1));
            with.push((a.last_active_us, ack));
        }
        with.sort_by_key(|(t, _)| std::cmp::Reverse(*t));
        with.into_iter().take(MAX_ACKS).map(|(_, a)| a).collect()
    }
}

/// The player's acknowledgement of `a`'s sender with the gateway's refusals merged in: a
/// message is settled when the player settled it or the gateway gave it up.
fn merged(sender: u64, a: &Account) -> Ack {
    let p = a.player.clone().unwrap_or_default();
    let mut settled = p.settled_seq.max(a.settled);
    for (seq, state) in &a.open {
        if *seq <= settled {
            continue;
        }
        match state {
            Some(_) => settled = *seq,
            None => break,
        }
    }
    let last_given_up = a.refusals.iter().map(|r| r.seq).max().unwrap_or(0);
    let mut refusals: Vec<AckRefusal> = p.refusals.iter().chain(&a.refusals).cloned().collect();
    refusals.sort_by_key(|r| r.seq);
    let cut = refusals.len().saturating_sub(MAX_REFUSALS);
    refusals.drain(..cut);
    Ack {
        sender,
        origin: a.origin.clone(),
        last_seq: p.last_seq.max(last_given_up),
        settled_seq: settled,
        received: p.received + a.given_up,
        taken: p.taken,
        refused: p.refused + a.given_up,
        pending: p.pending,
        unrecorded: p.unrecorded,
        missing: p.missing,
        refusals,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn given_up_messages_settle_with_the_players_verdict_on_the_others() {
        let mut s = Senders::default();
        for seq in 1..=4 {
            s.carried(7, seq, "tool/send1", 0);
        }
        // Nothing given up: the player's acknowledgement alone is the verdict.
        assert!(s.acks().is_empty());
        // 1 and 2 given up; 3 and 4 still on their way.
        s.given_up(7, 1, "tool/send1", "the link was out", 10);
        s.given_up(7, 2, "tool/send1", "the link was out", 10);
        let a = &s.acks()[0];
        assert_eq!((a.settled_seq, a.refused, a.taken), (2, 2, 0));
        assert!(!a.settles(3));
        // The player settles 3 and 4 (its acknowledgement as translated for this sender).
        s.player_acks(&[Ack {
            sender: 7,
            last_seq: 4,
            settled_seq: 4,
            received: 2,
            taken: 2,
            ..Ack::default()
        }]);
        let a = &s.acks()[0];
        assert!(a.settles(4));
        assert!(
            s.acks()[0].settles(4),
            "the settlement stays once the open ones are forgotten"
        );
        assert_eq!((a.taken, a.refused, a.received), (2, 2, 4));
        assert_eq!(a.refusals.len(), MAX_REFUSALS);
        assert_eq!(a.refusals[0].reason, "the link was out");
    }

    #[test]
    fn a_message_carried_but_unsettled_holds_the_settlement_back() {
        let mut s = Senders::default();
        s.carried(3, 1, "program/PLN", 0);
        s.carried(3, 2, "program/PLN", 0);
        // 2 given up, 1 delivered but not settled by the player yet.
        s.given_up(3, 2, "program/PLN", "refused on computer `A`: no player", 5);
        let a = &s.acks()[0];
        assert_eq!(a.settled_seq, 0);
        s.player_acks(&[Ack {
            sender: 3,
            last_seq: 1,
            settled_seq: 1,
            received: 1,
            taken: 1,
            ..Ack::default()
        }]);
        let a = &s.acks()[0];
        assert_eq!((a.settled_seq, a.last_seq), (2, 2));
        // Idle senders go.
        s.prune(LINGER_US + 5);
        assert!(s.acks().is_empty());
    }
}
