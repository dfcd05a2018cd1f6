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
            buffered: 0,
        }
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
    /// buffer, a body that does not decode...).
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
    /// Copies of carried messages for this computer not taken: already taken, out of order,
    /// too late, or for an earlier gateway of this computer (see `crate::reliable::Discarded`).
    pub discarded: u64,
}

/// The gateway's counters, by message kind; `from_link = delivered + refused + not_mine +
/// unheard + discarded` (once the held messages are delivered), and the carried messages taken
/// here are `carried + given_up` plus those still buffered.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Counters {
    /// By kind (`event`, `call`, `heartbeat`, `marking`, `signals`, `beacon`).
    pub kinds: BTreeMap<&'static str, Counts>,
    /// Link messages that did not decode, or came from a computer the vehicle does not have.
    pub undecodable: u64,
    /// The latest refusals (at most 8), newest last.
    pub refusals: Vec<String>,
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

    fn remember(&mut self, reason: String) {
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
    /// Not a computer of the vehicle, or damaged: counted, dropped.
    Foreign(String),
    /// A beacon or an acknowledgement: nothing to deliver.
    Beacon,
    /// For another computer.
    NotMine,
    /// To be delivered here (a carried message: then [`Core::taken`]).
    Deliver,
    /// Carried, for this computer, but its computer came back and the player has not taken the
    /// restored event yet: delivered later, from [`Core::take_released`].
    Held,
    /// A copy of a carried message not taken (counted `discarded`).
    Discarded,
}

/// The gateway's state.
#[derive(Debug, Clone)]
pub struct Core {
    plan: Plan,
    peers: BTreeMap<String, Peer>,
    /// The counters.
    pub counters: Counters,
    incarnation: u64,
    next_seq: u64,
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
        let msgs = self.incoming.release(peer);
        self.released.extend(msgs);
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
    pub fn on_link(&mut self, msg: &LinkMsg, now_us: u64, changes: &mut Vec<PeerChange>) -> Route {
        if msg.from == self.plan.computer {
            if msg.incarnation != self.incarnation {
                // Another gateway claims this computer: refuse it rather than mix their messages.
                self.counters.undecodable += 1;
                self.counters
                    .remember(format!("a second gateway claims computer `{}`", msg.from));
                return Route::Foreign(format!("a second gateway claims `{}`", msg.from));
            }
            return Route::Own;
        }
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
        if let LinkKind::Beacon { alive } = &msg.kind {
            peer.alive = alive.iter().cloned().collect();
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
            Accept::Take => Route::Deliver,
            Accept::Held => Route::Held,
            Accept::Discard(_) => {
                self.counters.of(kind).discarded += 1;
                Route::Discarded
            }
        }
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
            if peer.state != PeerState::Up {
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

    #[test]
    fn events_go_to_the_player_computer_only() {
        let mut b = Core::new(plan("B"), 1);
        assert!(b.forward_local(&LinkKind::Event, "program/PLN", false));
        assert!(!b.forward_local(&LinkKind::Event, "program/PLN", true));
        assert_eq!(b.counters.kinds["event"].own, 1);
        let mut a = Core::new(plan("A"), 2);
        assert!(!a.forward_local(&LinkKind::Event, "program/X", false));
        let mut ch = vec![];
        assert_eq!(
            a.on_link(&msg("B", 1, LinkKind::Event), 0, &mut ch),
            Route::Deliver
        );
        assert_eq!(ch, vec![PeerChange::Joined("B".into())]);
        let mut g = Core::new(plan("G"), 3);
        assert_eq!(
            g.on_link(&msg("B", 1, LinkKind::Event), 0, &mut ch),
            Route::NotMine
        );
        let c = g.counters.kinds["event"];
        assert_eq!(
            c.from_link,
            c.delivered + c.refused + c.not_mine + c.unheard
        );
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
        assert_eq!(
            b.on_link(&msg("A", 1, call.clone()), 0, &mut ch),
            Route::Deliver
        );
        assert_eq!(
            b.on_link(&msg("A", 2, LinkKind::Marking), 0, &mut ch),
            Route::Deliver
        );
        let mut g = Core::new(plan("G"), 3);
        assert_eq!(g.on_link(&msg("A", 1, call), 0, &mut ch), Route::NotMine);
        // Its own messages, heard back, are dropped; a second gateway on its computer refused.
        let mut own = msg("G", 1, LinkKind::Event);
        own.incarnation = 3;
        assert_eq!(g.on_link(&own, 0, &mut ch), Route::Own);
        own.incarnation = 4;
        assert!(matches!(g.on_link(&own, 0, &mut ch), Route::Foreign(_)));
        assert!(matches!(
            g.on_link(&msg("Z", 1, LinkKind::Event), 0, &mut ch),
            Route::Foreign(_)
        ));
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
        // A restarted gateway starts again at 1: not a gap.
        let mut restarted = beacon(1, &[]);
        restarted.incarnation = 10;
        a.on_link(&restarted, 6_100_000, &mut ch);
        assert_eq!(a.peers()["B"].missing, 2);
        assert_eq!(a.peers()["B"].restarts, 1);
        assert_eq!(a.peers()["B"].losses, 1);
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
