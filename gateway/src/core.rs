//! The gateway's decisions, sans I/O: which local messages go on the link, which link messages
//! are for this computer, the state of each peer computer (heard within the detection bound or
//! lost), which of the peers' nodes this computer mirrors, the carried messages (events and
//! calls: `crate::reliable`'s streams, acknowledged, sent again, or given up and their senders
//! told), and the counters that account for every message. Time is injected (microseconds
//! since the gateway started).

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

use crate::link::{LinkKind, LinkMsg, StreamAck};
use crate::reliable::{Accept, Bounds, Failure, Incoming, Outgoing};

/// Where things live: the vehicle's computers, the player's, and the host of each program.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    /// This computer.
    pub computer: String,
    /// Every other computer of the vehicle.
    pub peers: Vec<String>,
    /// The computer the player runs on.
    pub player_computer: String,
    /// Each program of the vehicle and the computer that hosts it (programs absent from the
    /// map are taken to live with the player).
    pub hosts: BTreeMap<String, String>,
    /// The computer the CAN data server (`petrel bridge`) runs on, whose signals every other
    /// computer mirrors; `None`: the vehicle has no data server, no signals cross.
    pub signals_computer: Option<String>,
    /// A peer silent for this long is lost, microseconds.
    pub detection_us: u64,
    /// A carried message (an event, a call) its destination has not acknowledged within this
    /// long is given up and its sender told, microseconds (longer than `detection_us`).
    pub retention_us: u64,
}

impl Plan {
    /// The computer hosting `program`.
    pub fn host_of(&self, program: &str) -> &str {
        self.hosts
            .get(program)
            .map(String::as_str)
            .unwrap_or(&self.player_computer)
    }

    /// Whether the player runs here.
    pub fn has_player(&self) -> bool {
        self.computer == self.player_computer
    }

    /// Whether the CAN data server runs here (its signals leave this computer).
    pub fn has_signals(&self) -> bool {
        self.signals_computer.as_deref() == Some(self.computer.as_str())
    }

    /// The programs hosted here.
    pub fn local_programs(&self) -> Vec<String> {
        self.hosts
            .iter()
            .filter(|(_, c)| **c == self.computer)
            .map(|(p, _)| p.clone())
            .collect()
    }

    /// The nodes of this computer the others mirror: the player, if it runs here, and the
    /// programs hosted here.
    pub fn exported_nodes(&self) -> Vec<String> {
        let mut nodes = Vec::new();
        if self.has_player() {
            nodes.push("player".to_owned());
        }
        nodes.extend(
            self.local_programs()
                .into_iter()
                .map(|p| format!("program/{p}")),
        );
        nodes
    }

    /// How often a beacon goes out: a quarter of the detection bound, between 10 and 250 ms.
    pub fn beacon_period_us(&self) -> u64 {
        (self.detection_us / 4).clamp(10_000, 250_000)
    }

    /// The computer that delivers a message of `kind`, when it is carried (events go to the
    /// player's computer, calls to the program's); `None` for news (heartbeats, markings,
    /// signals, beacons, acknowledgements), which is not.
    pub fn destination(&self, kind: &LinkKind) -> Option<&str> {
        match kind {
            LinkKind::Event => Some(&self.player_computer),
            LinkKind::Call { program } => Some(self.host_of(program)),
            _ => None,
        }
    }
}

/// Microseconds as people read them: `10 s`, `1.5 s`, `250 ms`.
pub fn seconds(us: u64) -> String {
    if us >= 1_000_000 {
        let s = us as f64 / 1e6;
        format!("{} s", (s * 10.0).round() / 10.0)
    } else {
        format!("{} ms", us / 1000)
    }
}

/// The state of a peer computer as this gateway sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PeerState {
    /// Never heard yet.
    Unknown,
    /// Heard within the detection bound.
    Up,
    /// Silent for longer than the detection bound since it was last heard.
    Lost,
}

/// A change of a peer's state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PeerChange {
    /// First heard.
    Joined(String),
    /// Silent past the detection bound.
    Lost(String),
    /// Heard again after it was lost.
    Restored(String),
}

/// One peer computer.
#[derive(Debug, Clone, Serialize)]
pub struct Peer {
    /// Its state.
    pub state: PeerState,
    /// When it was last heard, microseconds.
    #[serde(skip)]
    pub last_heard_us: Option<u64>,
    /// Its gateway's incarnation (a new one: a restarted gateway).
    pub incarnation: Option<u64>,
    /// The next link sequence number expected from it.
    pub expected_seq: u64,
    /// Link messages of it never received (gaps in its sequence).
    pub missing: u64,
    /// Its nodes alive at its last beacon.
    pub alive: BTreeSet<String>,
    /// Times it was lost.
    pub losses: u64,
    /// Times it came back after a loss.
    pub restorations: u64,
    /// Restarts of its gateway seen (new incarnations after the first).
    pub restarts: u64,
    /// Whether its latest beacon says it follows this gateway for this computer. Until it
    /// does, none of its nodes is mirrored here. (What it carries names the gateway it is for,
    /// [`crate::link::Carried::to_incarnation`]: a copy meant for another gateway of this
    /// computer is not taken here.)
    pub follows_me: bool,
    /// Since when (microseconds) it follows another gateway of this computer, and which.
    #[serde(skip)]
    pub follows_other: Option<(u64, u64)>,
    /// Carried messages for it waiting for its acknowledgement (at the latest tick).
    pub buffered: usize,
}

impl Peer {
    fn new() -> Self {
        Peer {
            state: PeerState::Unknown,
            last_heard_us: None,
            incarnation: None,
            expected_seq: 1,
            missing: 0,
            alive: BTreeSet::new(),
            losses: 0,
            restorations: 0,
            restarts: 0,
            follows_me: false,
            follows_other: None,
            buffered: 0,
        }
    }
}

impl Peer {
    /// Whether a message of incarnation `incarnation` is a second gateway's: the peer's
    /// gateway is another one, heard within the detection bound. (One silent longer is
    /// taken as dead: the new one is its restart.)
    fn claimed_by_another(&self, incarnation: u64, now_us: u64, detection_us: u64) -> bool {
        self.incarnation.is_some_and(|i| i != incarnation)
            && self.state == PeerState::Up
            && now_us.saturating_sub(self.last_heard_us.unwrap_or(0)) <= detection_us
    }

    /// Takes a beacon's `follows`: whether the peer follows `me` (this computer, this
    /// gateway's incarnation), or another gateway of this computer, since when.
    fn heard_follows(&mut self, follows: &[(String, u64)], me: (&str, u64), now_us: u64) {
        let mine = follows.iter().find(|(c, _)| c == me.0).map(|(_, i)| *i);
        self.follows_me = mine == Some(me.1);
        self.follows_other = match mine {
            Some(other) if other != me.1 => {
                Some((self.follows_other.map_or(now_us, |(since, _)| since), other))
            }
            _ => None,
        };
    }
}

/// What became of the messages of one kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// Local messages put on the link.
    pub to_link: u64,
    /// Local messages the link refused (zenoh's put failed, or the message would not encode).
    pub to_link_refused: u64,
    /// Local messages not put on the link because this gateway sent them itself (what came from
    /// the link never goes back).
    pub own: u64,
    /// Link messages received from peers.
    pub from_link: u64,
    /// Link messages delivered to this computer's processes.
    pub delivered: u64,
    /// Link messages for this computer that could not be delivered (no receiver, a full
    /// buffer, a body that does not decode...) or that their computer may not send (an origin
    /// of another computer's, an event or a call not carried); a carried one's reason goes
    /// back to its sender in the acknowledgement.
    pub refused: u64,
    /// Link messages for another computer (each computer hears every peer).
    pub not_mine: u64,
    /// Broadcast news (heartbeats, marking deltas, signals) for this computer that no process
    /// here follows (no status, monitor, shadow or program reading signals): not a loss.
    pub unheard: u64,
    /// Carried messages (events, calls) sent again, unacknowledged.
    pub retransmitted: u64,
    /// Carried messages the destination's gateway acknowledged having taken.
    pub carried: u64,
    /// Carried messages given up (their senders told): unacknowledged within the retention
    /// bound, refused by the destination, for a destination that restarted, or refused at once
    /// by a full buffer.
    pub given_up: u64,
    /// Link messages not taken, and nothing said to their sender: copies of carried messages
    /// already taken, out of order, too late, or for another gateway of this computer (see
    /// `crate::reliable::Discarded`: they come again, or their sender gives them up), and
    /// every message of a second gateway claiming a computer (also in
    /// [`Counters::claims_refused`]).
    pub discarded: u64,
}

/// The gateway's counters, by message kind; `from_link = delivered + refused + not_mine +
/// unheard + discarded` (once the held messages are delivered; a second gateway's messages
/// count in `from_link` and `discarded`), and the carried messages taken here are `carried +
/// given_up` plus those still buffered.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Counters {
    /// By kind (`event`, `call`, `heartbeat`, `marking`, `signals`, `beacon`).
    pub kinds: BTreeMap<&'static str, Counts>,
    /// Link messages that did not decode, or came from a computer the vehicle does not have.
    pub undecodable: u64,
    /// The latest refusals (at most 8), newest last.
    pub refusals: Vec<String>,
    /// Link messages of a second gateway claiming a computer whose first gateway is up
    /// (this one's computer included), refused (and counted `discarded` by kind), by the
    /// computer claimed.
    pub claims_refused: BTreeMap<String, u64>,
}

impl Counters {
    /// The counts of `kind`.
    pub fn of(&mut self, kind: &'static str) -> &mut Counts {
        self.kinds.entry(kind).or_default()
    }

    /// Records a refusal with its reason.
    pub fn refuse(&mut self, kind: &'static str, reason: String) {
        self.of(kind).refused += 1;
        self.remember(reason);
    }

    /// Records a local message the link refused.
    pub fn refuse_to_link(&mut self, kind: &'static str, reason: String) {
        self.of(kind).to_link_refused += 1;
        self.remember(reason);
    }

    /// Keeps `reason` among the latest refusals.
    pub fn remember(&mut self, reason: String) {
        if self.refusals.len() == 8 {
            self.refusals.remove(0);
        }
        self.refusals.push(reason);
    }
}

/// The player's acknowledgements, translated back for senders of other computers: the player
/// acknowledges the gateway's port that sent it an event (by that port's sequence numbers);
/// the sender on the other computer waits for its own id and numbers.
#[derive(Debug, Clone, Default)]
pub struct AckMap {
    /// By the id of the port that sent the events to the player: (its sequence number, the
    /// original sender's id, its sequence number, its origin), in sending order.
    sent: BTreeMap<u64, Vec<(u64, u64, u64, String)>>,
}

/// Entries kept per port at most: past it, the oldest half goes (their senders were long
/// acknowledged).
const ACK_MAP_MAX: usize = 8192;

impl AckMap {
    /// The port `port` sent, as its message `port_seq`, the message `seq` of `sender`.
    pub fn record(&mut self, port: u64, port_seq: u64, sender: u64, seq: u64, origin: &str) {
        let list = self.sent.entry(port).or_default();
        if list.len() >= ACK_MAP_MAX {
            list.drain(..ACK_MAP_MAX / 2);
        }
        list.push((port_seq, sender, seq, origin.to_owned()));
    }

    /// The acknowledgements of the original senders behind the ports among `acks`.
    pub fn translate(&self, acks: &[petrel_ipc::Ack]) -> Vec<petrel_ipc::Ack> {
        let mut out: Vec<petrel_ipc::Ack> = Vec::new();
        for ack in acks {
            let Some(list) = self.sent.get(&ack.sender) else {
                continue;
            };
            let mut by_sender: BTreeMap<u64, petrel_ipc::Ack> = BTreeMap::new();
            for (port_seq, sender, seq, origin) in list {
                let a = by_sender.entry(*sender).or_insert_with(|| petrel_ipc::Ack {
                    sender: *sender,
                    origin: origin.clone(),
                    pending: ack.pending,
                    unrecorded: ack.unrecorded,
                    ..petrel_ipc::Ack::default()
                });
                if *port_seq <= ack.last_seq {
                    a.last_seq = a.last_seq.max(*seq);
                    a.received += 1;
                }
                if *port_seq <= ack.settled_seq {
                    a.settled_seq = a.settled_seq.max(*seq);
                }
                for r in ack.refusals.iter().filter(|r| r.seq == *port_seq) {
                    a.refused += 1;
                    a.refusals.push(petrel_ipc::AckRefusal {
                        seq: *seq,
                        reason: r.reason.clone(),
                    });
                }
            }
            for (_, mut a) in by_sender {
                a.taken = a.received.saturating_sub(a.refused);
                out.push(a);
            }
        }
        out
    }
}

/// What to do with a link message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Route {
    /// This gateway's own message, heard back: dropped.
    Own,
    /// Not a computer of the vehicle (counted `undecodable`), or a message its computer may
    /// not send (counted `refused`): dropped, the reason to log.
    Foreign(String),
    /// A beacon or an acknowledgement: nothing to deliver.
    Beacon,
    /// For another computer.
    NotMine,
    /// To be delivered here (a carried message: then [`Core::taken`]).
    Deliver,
    /// From a second gateway claiming a computer whose first gateway is up: refused (one
    /// gateway per computer). The reason the first time this second gateway is heard (to
    /// log), `None` after.
    Claim(Option<String>),
    /// Carried, for this computer, but its computer came back and the player has not taken the
    /// restored event yet: delivered later, from [`Core::take_released`].
    Held,
    /// A copy of a carried message not taken (counted `discarded`).
    Discarded,
}

/// How long a peer may follow another gateway of this computer before this one gives up,
/// beyond the detection bound. A restarted gateway is refused from the first beacon it hears
/// until its peers lose its killed predecessor: at most the bound after the predecessor's
/// last message, then a beacon period (the peers' tick) and the news' way back; the grace
/// covers those and a loaded machine.
pub const CLAIM_GRACE_US: u64 = 2_000_000;

/// Second gateways remembered (to log each once); past it, they are forgotten.
const CLAIMANTS_MAX: usize = 1024;

/// The gateway's state.
#[derive(Debug, Clone)]
pub struct Core {
    plan: Plan,
    peers: BTreeMap<String, Peer>,
    /// The counters.
    pub counters: Counters,
    incarnation: u64,
    next_seq: u64,
    /// Second gateways already reported: (computer claimed, incarnation).
    claimants: BTreeSet<(String, u64)>,
    outgoing: Outgoing,
    incoming: Incoming,
    /// Whether a returning computer's carried messages wait for the player to take its
    /// restored event (on the player's computer, with link events).
    hold_on_restore: bool,
    failures: Vec<Failure>,
    released: Vec<LinkMsg>,
    /// The clock carried messages age by: the injected one, without the time this gateway
    /// itself stood still (stopped, or starved past two beacon periods), so that it judges
    /// the link only while it listens to it.
    judged_us: u64,
    last_now_us: u64,
}

impl Core {
    /// A gateway for `plan`; `incarnation` should be random (it tells a restarted gateway).
    pub fn new(plan: Plan, incarnation: u64) -> Self {
        let peers = plan
            .peers
            .iter()
            .map(|p| (p.clone(), Peer::new()))
            .collect();
        let bounds = Bounds::new(plan.detection_us, plan.retention_us);
        Core {
            plan,
            peers,
            counters: Counters::default(),
            incarnation,
            next_seq: 1,
            claimants: BTreeSet::new(),
            outgoing: Outgoing::new(bounds),
            incoming: Incoming::new(bounds),
            hold_on_restore: false,
            failures: Vec::new(),
            released: Vec::new(),
            judged_us: 0,
            last_now_us: 0,
        }
    }

    /// A returning computer's carried messages wait until the player took its restored event
    /// ([`link_event_sent`](Self::link_event_sent), [`player_took`](Self::player_took)).
    pub fn set_hold_on_restore(&mut self, on: bool) {
        self.hold_on_restore = on;
    }

    /// Advances the judging clock to the injected `now_us`: a step longer than two beacon
    /// periods counts as two.
    fn judge(&mut self, now_us: u64) -> u64 {
        let step = now_us.saturating_sub(self.last_now_us);
        self.judged_us += step.min(2 * self.plan.beacon_period_us());
        self.last_now_us = self.last_now_us.max(now_us);
        self.judged_us
    }

    /// The plan.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The peers, by name.
    pub fn peers(&self) -> &BTreeMap<String, Peer> {
        &self.peers
    }

    /// A message of this gateway for the link, numbered and stamped at `now_us`; `sender` and
    /// `seq` are the ipc header's of the message it carries (0 for the gateway's own).
    pub fn outgoing(
        &mut self,
        origin: &str,
        header: (u64, u64),
        kind: LinkKind,
        body: Vec<u8>,
        now_us: u64,
    ) -> LinkMsg {
        let mut msg = self.unnumbered(origin, header, kind, body);
        self.number(&mut msg, now_us);
        msg
    }

    fn unnumbered(
        &self,
        origin: &str,
        (sender, seq): (u64, u64),
        kind: LinkKind,
        body: Vec<u8>,
    ) -> LinkMsg {
        LinkMsg {
            from: self.plan.computer.clone(),
            incarnation: self.incarnation,
            link_seq: 0,
            origin: origin.to_owned(),
            sender,
            seq,
            kind,
            body,
            sent_us: 0,
            carried: None,
        }
    }

    fn number(&mut self, msg: &mut LinkMsg, now_us: u64) {
        msg.link_seq = self.next_seq;
        self.next_seq += 1;
        msg.sent_us = now_us;
    }

    /// Takes a local event or call for the link at `now_us`: kept until its destination's
    /// gateway acknowledges it ([`due`](Self::due) sends it). `false`: refused at once (the
    /// buffer for that destination is full, or the kind is not carried): its failure is in
    /// [`take_failures`](Self::take_failures).
    pub fn carry(
        &mut self,
        origin: &str,
        header: (u64, u64),
        kind: LinkKind,
        body: Vec<u8>,
        now_us: u64,
    ) -> bool {
        let Some(to) = self.plan.destination(&kind).map(str::to_owned) else {
            return false;
        };
        let now = self.judge(now_us);
        let msg = self.unnumbered(origin, header, kind, body);
        match self.outgoing.queue(&to, msg, now) {
            Ok(()) => true,
            Err(f) => {
                self.give_up(vec![*f]);
                false
            }
        }
    }

    fn give_up(&mut self, failures: Vec<Failure>) {
        for f in failures {
            self.counters.of(f.msg.kind.name()).given_up += 1;
            self.counters.remember(format!(
                "{} from {} given up: {}",
                f.msg.kind.name(),
                f.msg.origin,
                f.reason
            ));
            self.failures.push(f);
        }
    }

    /// The carried messages given up since the last call: their senders must be told.
    pub fn take_failures(&mut self) -> Vec<Failure> {
        std::mem::take(&mut self.failures)
    }

    /// The held messages released since the last call, in order: to deliver now (then
    /// [`taken`](Self::taken)).
    pub fn take_released(&mut self) -> Vec<LinkMsg> {
        std::mem::take(&mut self.released)
    }

    /// The copies of carried messages to put on the link at `now_us`, numbered and stamped:
    /// the new ones and those unacknowledged for a while, for the peers up; with, for each,
    /// whether it is a retransmission.
    pub fn due(&mut self, now_us: u64) -> Vec<(LinkMsg, bool)> {
        let now = self.judge(now_us);
        let mut out = Vec::new();
        for (name, peer) in &self.peers {
            let (PeerState::Up, Some(inc)) = (peer.state, peer.incarnation) else {
                continue;
            };
            let due = self.outgoing.due(name, inc, now);
            out.extend(due.copies.into_iter().zip(due.again));
        }
        for (msg, _) in out.iter_mut() {
            self.number(msg, now_us);
        }
        out
    }

    /// The acknowledgement of what this gateway took since the last one, if any, to put on the
    /// link at `now_us`.
    pub fn acks_due(&mut self, now_us: u64) -> Option<LinkMsg> {
        let streams = self.incoming.acks_due();
        if streams.is_empty() {
            return None;
        }
        Some(self.outgoing(
            "gateway",
            (0, 0),
            LinkKind::Ack { streams },
            Vec::new(),
            now_us,
        ))
    }

    /// The carried `msg` (from [`on_link`](Self::on_link)'s `Deliver` or
    /// [`take_released`](Self::take_released)) was delivered here, or refused for a reason the
    /// acknowledgement carries back to its sender.
    pub fn taken(&mut self, msg: &LinkMsg, refusal: Option<String>) {
        self.incoming.taken(msg, refusal);
    }

    /// The restored event for `peer` went to the player as this gateway's message `seq`; `None`
    /// when it could not be sent: then nothing waits for it.
    pub fn link_event_sent(&mut self, peer: &str, seq: Option<u64>) {
        match seq {
            Some(seq) => self.incoming.told(peer, seq),
            None => self.release(peer),
        }
    }

    /// The player's heartbeat says it took this gateway's messages up to `seq`.
    pub fn player_took(&mut self, seq: u64) {
        for peer in self.incoming.player_took(seq) {
            self.release(&peer);
        }
    }

    fn release(&mut self, peer: &str) {
        for msg in self.incoming.release(peer) {
            if self.admit(&msg).is_ok() {
                self.released.push(msg);
            }
        }
    }

    /// Messages waiting for `peer`'s acknowledgement.
    pub fn buffered(&self, peer: &str) -> usize {
        self.outgoing.buffered(peer)
    }

    fn on_acks(&mut self, from: &str, incarnation: u64, streams: &[StreamAck]) -> bool {
        let mut mine = false;
        for ack in streams {
            if ack.from != self.plan.computer || ack.from_incarnation != self.incarnation {
                continue;
            }
            mine = true;
            let (taken, failures) = self.outgoing.acknowledged(from, incarnation, ack);
            for m in taken {
                self.counters.of(m.kind.name()).carried += 1;
            }
            self.give_up(failures);
        }
        mine
    }

    /// Whether a local message of `kind` from `origin` goes on the link. `own` says this
    /// gateway sent it itself (it came from the link): never forwarded again.
    pub fn forward_local(&mut self, kind: &LinkKind, origin: &str, own: bool) -> bool {
        if matches!(kind, LinkKind::Heartbeat | LinkKind::Marking) && origin != "player" {
            // Other processes' heartbeats (the gateway's own status among them) stay here.
            return false;
        }
        if matches!(kind, LinkKind::Signals) && origin != "can_bridge" {
            // Only the data server's signals leave (a tool publishing signals is a test's).
            return false;
        }
        if own {
            self.counters.of(kind.name()).own += 1;
            return false;
        }
        match kind {
            // Events go to the player: from every computer but its own.
            LinkKind::Event => !self.plan.has_player(),
            // Calls reach this gateway only through the stand-in of a program hosted elsewhere.
            LinkKind::Call { program } => self.plan.host_of(program) != self.plan.computer,
            // The player's heartbeat and marking, for the other computers (ground stations).
            LinkKind::Heartbeat | LinkKind::Marking => self.plan.has_player() && origin == "player",
            // The data server's signals, for the programs of the other computers.
            LinkKind::Signals => self.plan.has_signals(),
            LinkKind::Beacon { .. } | LinkKind::Ack { .. } => false,
        }
    }

    /// Takes a link message heard at `now_us`: updates the sender's state and sequence, and
    /// says what to do with it. Peer changes it causes are appended to `changes`.
    ///
    /// One rule for a computer's gateways: the first heard is followed; a message of another
    /// incarnation while it is up and heard within the detection bound is a second claim,
    /// refused before anything else ([`Route::Claim`]: no peer state, no stream, no
    /// acknowledgement touched); past the bound, the new incarnation is the first one's
    /// restart, and only then are the messages numbered for its predecessor given up.
    pub fn on_link(&mut self, msg: &LinkMsg, now_us: u64, changes: &mut Vec<PeerChange>) -> Route {
        if msg.from == self.plan.computer {
            if msg.incarnation != self.incarnation {
                // Another gateway claims this computer: refuse it rather than mix their messages.
                return self.refuse_claim(msg);
            }
            return Route::Own;
        }
        let detection_us = self.plan.detection_us;
        if self
            .peers
            .get(&msg.from)
            .is_some_and(|p| p.claimed_by_another(msg.incarnation, now_us, detection_us))
        {
            return self.refuse_claim(msg);
        }
        let me = (self.plan.computer.as_str(), self.incarnation);
        let Some(peer) = self.peers.get_mut(&msg.from) else {
            self.counters.undecodable += 1;
            let why = format!("`{}` is not a computer of the vehicle file", msg.from);
            self.counters.remember(why.clone());
            return Route::Foreign(why);
        };
        let mut restarted = false;
        if peer.incarnation != Some(msg.incarnation) {
            if peer.incarnation.is_some() {
                peer.restarts += 1;
                restarted = true;
            }
            peer.incarnation = Some(msg.incarnation);
            peer.expected_seq = msg.link_seq;
            // A new gateway there: it says whom it follows in its beacons.
            peer.follows_me = false;
            peer.follows_other = None;
        }
        if msg.link_seq > peer.expected_seq {
            peer.missing += msg.link_seq - peer.expected_seq;
        }
        peer.expected_seq = msg.link_seq.max(peer.expected_seq) + 1;
        peer.last_heard_us = Some(now_us);
        let back = peer.state != PeerState::Up;
        match peer.state {
            PeerState::Unknown => changes.push(PeerChange::Joined(msg.from.clone())),
            PeerState::Lost => {
                peer.restorations += 1;
                changes.push(PeerChange::Restored(msg.from.clone()));
                if self.hold_on_restore {
                    // Its messages wait until the player took its restored event.
                    self.incoming.hold(&msg.from, now_us);
                }
            }
            PeerState::Up => {}
        }
        peer.state = PeerState::Up;
        if let LinkKind::Beacon { alive, follows } = &msg.kind {
            peer.alive = alive.iter().cloned().collect();
            peer.heard_follows(follows, me, now_us);
        }
        if restarted {
            // What was numbered for its predecessor may or may not have been delivered.
            let failures = self.outgoing.restarted(&msg.from, msg.incarnation);
            self.give_up(failures);
        }
        if back || restarted {
            self.outgoing.resend(&msg.from);
        }
        self.incoming
            .heard(&msg.from, msg.incarnation, msg.sent_us, now_us);
        let kind = msg.kind.name();
        self.counters.of(kind).from_link += 1;
        let mine = match &msg.kind {
            LinkKind::Beacon { .. } => {
                self.counters.of(kind).delivered += 1;
                return Route::Beacon;
            }
            LinkKind::Ack { streams } => {
                if self.on_acks(&msg.from, msg.incarnation, streams) {
                    self.counters.of(kind).delivered += 1;
                } else {
                    self.counters.of(kind).not_mine += 1;
                }
                return Route::Beacon;
            }
            // Carried: its destination says.
            _ if msg.carried.is_some() => msg
                .carried
                .as_ref()
                .is_some_and(|c| c.to == self.plan.computer),
            LinkKind::Event => self.plan.has_player(),
            LinkKind::Call { program } => self.plan.host_of(program) == self.plan.computer,
            LinkKind::Heartbeat | LinkKind::Marking => !self.plan.has_player(),
            // Every computer but the data server's own: a ground station's too (counted
            // `unheard` when nothing there reads them).
            LinkKind::Signals => {
                self.plan.signals_computer.as_deref() == Some(msg.from.as_str())
                    && !self.plan.has_signals()
            }
        };
        if !mine {
            self.counters.of(kind).not_mine += 1;
            return Route::NotMine;
        }
        match self.incoming.accept(msg, self.incarnation, now_us) {
            Accept::Take => match self.admit(msg) {
                Ok(()) => Route::Deliver,
                Err(why) => Route::Foreign(why),
            },
            Accept::Held => Route::Held,
            Accept::Discard(_) => {
                self.counters.of(kind).discarded += 1;
                Route::Discarded
            }
        }
    }

    /// Whether this computer takes `msg`, a message for it that its stream (if carried) let
    /// through: a computer of the vehicle speaks for its own processes only (the player's
    /// messages come from the player's computer, a program's from its host, the data server's
    /// from its computer, a gateway's, `tool/gw-NAME`, from computer NAME; other tools,
    /// `tool/NAME`, may run anywhere), and an event or a call comes
    /// carried (a gateway always carries them). A refusal is counted `refused` with its reason
    /// and, for a carried message, taken with that reason: the acknowledgement tells its
    /// sender, and the stream goes on.
    fn admit(&mut self, msg: &LinkMsg) -> Result<(), String> {
        let kind = msg.kind.name();
        let home = match msg.origin.as_str() {
            "player" => Some(self.plan.player_computer.as_str()),
            "can_bridge" => self.plan.signals_computer.as_deref(),
            o => match o.strip_prefix("program/") {
                Some(p) => Some(self.plan.host_of(p)),
                // A gateway's node is `tool/gw-COMPUTER` (`petrel_ipc::Role::gateway`).
                None => o.strip_prefix("tool/gw-"),
            },
        };
        let why = match home {
            Some(h) if h != msg.from => format!(
                "{kind} from computer `{}` claims origin `{}`, which is computer `{h}`'s",
                msg.from, msg.origin
            ),
            _ if self.plan.destination(&msg.kind).is_some() && msg.carried.is_none() => {
                format!(
                    "{kind} from computer `{}` not carried on a stream",
                    msg.from
                )
            }
            _ => return Ok(()),
        };
        self.counters.refuse(kind, why.clone());
        self.incoming.taken(msg, Some(why.clone()));
        Err(why)
    }

    /// Refuses a message of a second gateway claiming its computer.
    /// Nothing of it is taken nor acknowledged: counted `discarded` (its kind's `from_link`
    /// too) and in `claims_refused`.
    fn refuse_claim(&mut self, msg: &LinkMsg) -> Route {
        let counts = self.counters.of(msg.kind.name());
        counts.from_link += 1;
        counts.discarded += 1;
        *self
            .counters
            .claims_refused
            .entry(msg.from.clone())
            .or_default() += 1;
        if self.claimants.len() >= CLAIMANTS_MAX {
            self.claimants.clear();
        }
        if !self.claimants.insert((msg.from.clone(), msg.incarnation)) {
            return Route::Claim(None);
        }
        let why = format!(
            "a second gateway claims computer `{}` (incarnation {:x}) while its first is up: refused",
            msg.from, msg.incarnation
        );
        self.counters.remember(why.clone());
        Route::Claim(Some(why))
    }

    /// The gateway this one follows for each computer it has heard, for its beacons.
    pub fn follows(&self) -> Vec<(String, u64)> {
        self.peers
            .iter()
            .filter_map(|(name, p)| p.incarnation.map(|i| (name.clone(), i)))
            .collect()
    }

    /// Why this gateway gives up, if a peer has followed another gateway of this computer for
    /// longer than the detection bound and [`CLAIM_GRACE_US`]: that gateway is alive,
    /// and this one is the second claim.
    pub fn refused(&self, now_us: u64) -> Option<String> {
        let bound = self.plan.detection_us + CLAIM_GRACE_US;
        self.peers.iter().find_map(|(name, p)| {
            let (since, other) = p.follows_other?;
            (now_us.saturating_sub(since) > bound).then(|| {
                format!(
                    "computer `{name}` follows another gateway of computer `{}` (incarnation {other:x}) and refuses this one: a computer has one gateway; stop the other first",
                    self.plan.computer
                )
            })
        })
    }

    /// Peers silent past the detection bound at `now_us` become lost (a held one's messages
    /// are released first: they came before the loss); carried messages unacknowledged within
    /// the retention bound are given up; holds that waited too long for the player end.
    pub fn tick(&mut self, now_us: u64) -> Vec<PeerChange> {
        let now = self.judge(now_us);
        let mut changes = Vec::new();
        for (name, peer) in self.peers.iter_mut() {
            peer.buffered = self.outgoing.buffered(name);
            if peer.state != PeerState::Up {
                continue;
            }
            let heard = peer.last_heard_us.unwrap_or(0);
            if now_us.saturating_sub(heard) > self.plan.detection_us {
                peer.state = PeerState::Lost;
                peer.losses += 1;
                peer.alive.clear();
                changes.push(PeerChange::Lost(name.clone()));
            }
        }
        for change in &changes {
            if let PeerChange::Lost(name) = change {
                if self.incoming.is_held(name) {
                    self.release(name);
                }
            }
        }
        let failures = self.outgoing.expire(now);
        self.give_up(failures);
        // The player acknowledges within a few heartbeats: one that does not (it stopped, or
        // restarted and never heard of the restored event) does not keep the link closed.
        for peer in self
            .incoming
            .overdue(now_us, self.plan.detection_us.max(1_000_000))
        {
            self.counters.remember(format!(
                "the player did not take the restored event of `{peer}` in time: its messages go on"
            ));
            self.release(&peer);
        }
        changes
    }

    /// The nodes of peers this computer stands in for, with the peer hosting each: the player
    /// (when it runs elsewhere) and the programs hosted elsewhere, while their computer is up
    /// and reports them alive.
    pub fn mirrored(&self) -> BTreeMap<String, String> {
        let mut nodes = BTreeMap::new();
        for (name, peer) in &self.peers {
            if peer.state != PeerState::Up || !peer.follows_me {
                continue;
            }
            for node in &peer.alive {
                let belongs = match node.strip_prefix("program/") {
                    Some(program) => self.plan.host_of(program) == name.as_str(),
                    None => node == "player" && self.plan.player_computer == *name,
                };
                if belongs {
                    nodes.insert(node.clone(), name.clone());
                }
            }
        }
        nodes
    }

    /// Whether every peer that was ever heard is up (for status lines).
    pub fn peer_state(&self, name: &str) -> Option<PeerState> {
        self.peers.get(name).map(|p| p.state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(me: &str) -> Plan {
        Plan {
            computer: me.into(),
            peers: ["A", "B", "G"]
                .iter()
                .filter(|c| **c != me)
                .map(|c| c.to_string())
                .collect(),
            player_computer: "A".into(),
            hosts: [("PLN".to_string(), "B".to_string())].into(),
            signals_computer: Some("A".into()),
            detection_us: 1_000_000,
            retention_us: 10_000_000,
        }
    }

    fn msg(from: &str, seq: u64, kind: LinkKind) -> LinkMsg {
        LinkMsg {
            from: from.into(),
            incarnation: 9,
            link_seq: seq,
            origin: "program/PLN".into(),
            sender: 0,
            seq: 0,
            kind,
            body: vec![],
            sent_us: 0,
            carried: None,
        }
    }

    /// `m` carried to computer `to`'s gateway of incarnation `inc`, number `n` on its stream.
    fn carried(m: LinkMsg, to: &str, inc: u64, n: u64) -> LinkMsg {
        LinkMsg {
            carried: Some(crate::link::Carried {
                to: to.into(),
                to_incarnation: inc,
                seq: n,
                floor: 1,
            }),
            ..m
        }
    }

    /// `core` hears a beacon of `from` (incarnation 9) that follows it (and lists `alive`).
    fn followed_by(core: &mut Core, from: &str, seq: u64, alive: &[&str]) {
        let beacon = LinkKind::Beacon {
            alive: alive.iter().map(|s| s.to_string()).collect(),
            follows: vec![(core.plan.computer.clone(), core.incarnation)],
        };
        let mut ch = vec![];
        assert_eq!(
            core.on_link(&msg(from, seq, beacon), 0, &mut ch),
            Route::Beacon
        );
    }

    fn accounted(c: Counts) -> bool {
        c.from_link == c.delivered + c.refused + c.not_mine + c.unheard + c.discarded
    }

    #[test]
    fn events_go_to_the_player_computer_only() {
        let mut b = Core::new(plan("B"), 1);
        assert!(b.forward_local(&LinkKind::Event, "program/PLN", false));
        assert!(!b.forward_local(&LinkKind::Event, "program/PLN", true));
        assert_eq!(b.counters.kinds["event"].own, 1);
        let mut a = Core::new(plan("A"), 2);
        assert!(!a.forward_local(&LinkKind::Event, "program/X", false));
        let mut ch = vec![];
        // A copy meant for another gateway of A (B follows that one) is not taken here.
        let event = |seq| msg("B", seq, LinkKind::Event);
        assert_eq!(
            a.on_link(&carried(event(1), "A", 7, 1), 0, &mut ch),
            Route::Discarded
        );
        assert_eq!(ch, vec![PeerChange::Joined("B".into())]);
        assert_eq!(
            a.on_link(&carried(event(2), "A", 2, 1), 0, &mut ch),
            Route::Deliver
        );
        // An event not carried on a stream: no gateway sends one.
        assert!(matches!(
            a.on_link(&event(3), 0, &mut ch),
            Route::Foreign(w) if w.contains("not carried")
        ));
        let c = a.counters.kinds["event"];
        assert_eq!(
            (c.from_link, c.discarded, c.refused),
            (3, 1, 1),
            "the runtime counts deliveries"
        );
        let mut g = Core::new(plan("G"), 3);
        assert_eq!(
            g.on_link(&carried(event(2), "A", 2, 1), 0, &mut ch),
            Route::NotMine
        );
        assert!(accounted(g.counters.kinds["event"]));
    }

    #[test]
    fn calls_go_to_the_host_and_player_news_to_the_others() {
        let call = LinkKind::Call {
            program: "PLN".into(),
        };
        let mut a = Core::new(plan("A"), 1);
        assert!(a.forward_local(&call, "player", false));
        assert!(a.forward_local(&LinkKind::Heartbeat, "player", false));
        assert!(!a.forward_local(&LinkKind::Heartbeat, "tool/gw-A", false));
        let mut b = Core::new(plan("B"), 2);
        let mut ch = vec![];
        let player = |seq, kind| LinkMsg {
            origin: "player".into(),
            ..msg("A", seq, kind)
        };
        assert_eq!(
            b.on_link(&carried(player(1, call.clone()), "B", 2, 1), 0, &mut ch),
            Route::Deliver
        );
        assert_eq!(
            b.on_link(&player(2, LinkKind::Marking), 0, &mut ch),
            Route::Deliver
        );
        let mut g = Core::new(plan("G"), 3);
        assert_eq!(
            g.on_link(&carried(player(1, call), "B", 2, 1), 0, &mut ch),
            Route::NotMine
        );
        // Its own messages, heard back, are dropped; a second gateway on its computer refused,
        // reported once, counted.
        let mut own = msg("G", 1, LinkKind::Event);
        own.incarnation = 3;
        assert_eq!(g.on_link(&own, 0, &mut ch), Route::Own);
        own.incarnation = 4;
        assert!(matches!(g.on_link(&own, 0, &mut ch), Route::Claim(Some(_))));
        assert_eq!(g.on_link(&own, 0, &mut ch), Route::Claim(None));
        assert_eq!(g.counters.claims_refused["G"], 2);
        let c = g.counters.kinds["event"];
        assert_eq!((c.from_link, c.discarded, c.delivered), (2, 2, 0));
        assert!(matches!(
            g.on_link(&msg("Z", 1, LinkKind::Event), 0, &mut ch),
            Route::Foreign(_)
        ));
        assert_eq!(g.counters.undecodable, 1);
    }

    #[test]
    fn signals_leave_the_data_server_computer_only_and_reach_every_other() {
        let mut a = Core::new(plan("A"), 1);
        assert!(a.forward_local(&LinkKind::Signals, "can_bridge", false));
        // What the gateway published itself (it came from the link) never goes back.
        assert!(!a.forward_local(&LinkKind::Signals, "can_bridge", true));
        assert_eq!(a.counters.kinds["signals"].own, 1);
        assert!(!a.forward_local(&LinkKind::Signals, "tool/fake", false));
        let mut b = Core::new(plan("B"), 2);
        assert!(!b.forward_local(&LinkKind::Signals, "can_bridge", false));
        let mut ch = vec![];
        let mut m = msg("A", 1, LinkKind::Signals);
        m.origin = "can_bridge".into();
        assert_eq!(b.on_link(&m, 0, &mut ch), Route::Deliver);
        let mut g = Core::new(plan("G"), 3);
        assert_eq!(g.on_link(&m, 0, &mut ch), Route::Deliver);
        // Signals claimed by a computer without the data server are not taken.
        assert_eq!(
            g.on_link(&msg("B", 1, LinkKind::Signals), 0, &mut ch),
            Route::NotMine
        );
        let c = g.counters.kinds["signals"];
        assert_eq!((c.from_link, c.not_mine), (2, 1));
        // No data server in the vehicle: nothing leaves.
        let mut none = plan("A");
        none.signals_computer = None;
        let mut a = Core::new(none, 4);
        assert!(!a.forward_local(&LinkKind::Signals, "can_bridge", false));
    }

    #[test]
    fn loss_restoration_gaps_and_restarts() {
        let mut a = Core::new(plan("A"), 1);
        let mut ch = vec![];
        let beacon = |seq, alive: &[&str]| {
            msg(
                "B",
                seq,
                LinkKind::Beacon {
                    alive: alive.iter().map(|s| s.to_string()).collect(),
                    follows: vec![("A".into(), 1)],
                },
            )
        };
        a.on_link(&beacon(1, &["program/PLN", "player"]), 0, &mut ch);
        // B's "player" is not the player's computer's: not mirrored.
        assert_eq!(
            a.mirrored(),
            [("program/PLN".to_string(), "B".to_string())].into()
        );
        assert!(a.tick(1_000_000).is_empty());
        assert_eq!(a.tick(1_000_001), vec![PeerChange::Lost("B".into())]);
        assert!(a.mirrored().is_empty());
        assert!(a.tick(5_000_000).is_empty(), "lost once");
        ch.clear();
        a.on_link(&beacon(4, &["program/PLN"]), 6_000_000, &mut ch);
        assert_eq!(ch, vec![PeerChange::Restored("B".into())]);
        assert_eq!(a.peers()["B"].missing, 2, "2 and 3 never came");
        // A restarted gateway (its predecessor silent past the bound) starts again at 1: not
        // a gap.
        let mut restarted = beacon(1, &[]);
        restarted.incarnation = 10;
        assert_eq!(a.on_link(&restarted, 7_000_001, &mut ch), Route::Beacon);
        assert_eq!(a.peers()["B"].missing, 2);
        assert_eq!(a.peers()["B"].restarts, 1);
        assert_eq!(a.peers()["B"].losses, 1);
        assert_eq!(a.follows(), vec![("B".to_string(), 10)]);
    }

    #[test]
    fn a_computer_speaks_for_its_own_processes_only() {
        let mut b = Core::new(plan("B"), 2);
        let mut ch = vec![];
        let from_g = |seq, origin: &str, kind| LinkMsg {
            origin: origin.into(),
            ..msg("G", seq, kind)
        };
        // G calls PLN (on B) as the player (on A), sends the player's heartbeat: refused.
        let call = LinkKind::Call {
            program: "PLN".into(),
        };
        for m in [
            carried(from_g(1, "player", call.clone()), "B", 2, 1),
            from_g(2, "player", LinkKind::Heartbeat),
        ] {
            assert!(
                matches!(b.on_link(&m, 0, &mut ch), Route::Foreign(w) if w.contains("claims origin"))
            );
        }
        // A tool of G calling PLN is G's to send: the stream went on past the refused call,
        // whose reason goes back to G in the acknowledgement.
        let m = carried(from_g(3, "tool/call1", call), "B", 2, 2);
        assert_eq!(b.on_link(&m, 0, &mut ch), Route::Deliver);
        b.taken(&m, None);
        let c = b.counters.kinds["call"];
        assert_eq!((c.from_link, c.refused), (2, 1));
        let Some(LinkMsg {
            kind: LinkKind::Ack { streams },
            ..
        }) = b.acks_due(0)
        else {
            panic!("an acknowledgement is due")
        };
        assert_eq!((streams[0].from.as_str(), streams[0].taken), ("G", 2));
        assert!(streams[0].refused[0].1.contains("claims origin `player`"));
        // PLN's event sent by G to the player's computer, and a `call_failed` as B's gateway
        // (the player takes `call_failed` from a gateway): refused there. G's gateway's own is
        // G's to send.
        let mut a = Core::new(plan("A"), 1);
        for (n, origin, refused) in [
            (1, "program/PLN", true),
            (2, "tool/gw-B", true),
            (3, "tool/gw-G", false),
        ] {
            let m = carried(from_g(n, origin, LinkKind::Event), "A", 1, n);
            let route = a.on_link(&m, 0, &mut ch);
            assert_eq!(
                matches!(route, Route::Foreign(_)),
                refused,
                "{origin}: {route:?}"
            );
        }
        let e = a.counters.kinds["event"];
        assert_eq!((e.from_link, e.refused), (3, 2));
    }

    #[test]
    fn a_second_gateway_claiming_a_computer_is_refused_and_the_first_undisturbed() {
        let mut a = Core::new(plan("A"), 1);
        followed_by(&mut a, "B", 1, &["program/PLN"]);
        let mut ch = vec![];
        // A call of the player's to PLN, sent to B's first gateway (incarnation 9).
        let call = LinkKind::Call {
            program: "PLN".into(),
        };
        assert!(a.carry("player", (3, 1), call, vec![], 50));
        let due = a.due(50);
        assert_eq!(due[0].0.carried.as_ref().map(|c| c.to_incarnation), Some(9));
        // A second gateway of B (incarnation 77) while the first is heard: refused, whatever
        // it sends, and reported once.
        let mut second = carried(msg("B", 1, LinkKind::Event), "A", 1, 1);
        second.incarnation = 77;
        assert!(
            matches!(a.on_link(&second, 100, &mut ch), Route::Claim(Some(w)) if w.contains("second gateway"))
        );
        second.kind = LinkKind::Beacon {
            alive: vec![],
            follows: vec![("A".into(), 1)],
        };
        second.carried = None;
        assert_eq!(a.on_link(&second, 200, &mut ch), Route::Claim(None));
        // The first goes on: no restart, its nodes still mirrored, its messages delivered, the
        // call sent to it still waiting for its acknowledgement (nothing given up).
        let first = carried(msg("B", 2, LinkKind::Event), "A", 1, 1);
        assert_eq!(a.on_link(&first, 300, &mut ch), Route::Deliver);
        let b = &a.peers()["B"];
        assert_eq!((b.restarts, b.incarnation, b.missing), (0, Some(9), 0));
        assert!(
            ch.iter().all(|c| matches!(c, PeerChange::Joined(_))),
            "{ch:?}"
        );
        assert_eq!(a.mirrored().len(), 1);
        assert_eq!(a.counters.claims_refused["B"], 2);
        assert_eq!(a.follows(), vec![("B".to_string(), 9)]);
        assert!(a.take_failures().is_empty());
        assert_eq!(a.buffered("B"), 1);
        let e = a.counters.kinds["event"];
        assert_eq!(
            (e.from_link, e.discarded),
            (2, 1),
            "and one for the runtime to deliver"
        );
        assert!(accounted(a.counters.kinds["beacon"]));

        // The second's side: A follows the other gateway of B; B2 takes nothing of A's, and
        // gives up once that lasts past the bound and the grace.
        let mut b2 = Core::new(plan("B"), 77);
        let beacon = LinkKind::Beacon {
            alive: vec!["player".into()],
            follows: a.follows(),
        };
        let mut from_a = msg("A", 1, beacon);
        from_a.incarnation = 1;
        assert_eq!(b2.on_link(&from_a, 0, &mut ch), Route::Beacon);
        let mut to_first = due[0].0.clone();
        to_first.incarnation = 1;
        assert_eq!(b2.on_link(&to_first, 10, &mut ch), Route::Discarded);
        assert!(b2.mirrored().is_empty(), "no stand-in of A's player on B2");
        assert_eq!(b2.refused(1_000_000 + CLAIM_GRACE_US), None);
        let why = b2.refused(1_000_001 + CLAIM_GRACE_US).expect("given up");
        assert!(
            why.contains("`A` follows another gateway of computer `B`"),
            "{why}"
        );

        // Once B's first gateway is silent past the bound, a new incarnation is its restart:
        // only then is what was numbered for the first given up.
        second.link_seq = 3;
        assert_eq!(a.on_link(&second, 1_300_001, &mut ch), Route::Beacon);
        assert_eq!(a.peers()["B"].restarts, 1);
        let failures = a.take_failures();
        assert_eq!(failures.len(), 1);
        assert!(failures[0].reason.contains("restarted"), "{failures:?}");
    }

    #[test]
    fn acknowledgements_are_translated_to_the_original_senders() {
        let mut map = AckMap::default();
        // Port 7 sent B's sender 100's messages 1 and 2 as its 1 and 2, then sender 200's 5
        // as its 3.
        map.record(7, 1, 100, 1, "program/PLN");
        map.record(7, 2, 100, 2, "program/PLN");
        map.record(7, 3, 200, 5, "tool/send1");
        let ack = petrel_ipc::Ack {
            sender: 7,
            last_seq: 3,
            settled_seq: 2,
            refusals: vec![petrel_ipc::AckRefusal {
                seq: 3,
                reason: "unknown event".into(),
            }],
            ..Default::default()
        };
        let other = petrel_ipc::Ack {
            sender: 8,
            ..Default::default()
        };
        let t = map.translate(&[ack, other]);
        assert_eq!(t.len(), 2);
        assert_eq!((t[0].sender, t[0].last_seq, t[0].settled_seq), (100, 2, 2));
        assert!(t[0].settles(2));
        assert_eq!((t[1].sender, t[1].last_seq, t[1].settled_seq), (200, 5, 0));
        assert_eq!(t[1].refusals[0].seq, 5);
        assert_eq!((t[1].refused, t[1].taken), (1, 0));
    }

    #[test]
    fn outgoing_messages_are_numbered() {
        let mut b = Core::new(plan("B"), 5);
        let m1 = b.outgoing("program/PLN", (1, 1), LinkKind::Event, vec![1], 0);
        let m2 = b.outgoing("program/PLN", (1, 2), LinkKind::Event, vec![2], 0);
        assert_eq!((m1.link_seq, m2.link_seq, m2.from.as_str()), (1, 2, "B"));
    }
}
