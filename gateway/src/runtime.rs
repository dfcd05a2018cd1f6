//! The gateway process: one thread joining this computer's iceoryx2 services of the vehicle to a
//! zenoh session, with [`Core`] deciding.
//!
//! Stand-ins ("mirrors") make a remote process look local: for each program hosted on another
//! computer that reports it alive, a node `program/NAME` here, whose call receiver takes the
//! calls for it; for a player on another computer, a node `player` here, which republishes its
//! heartbeat and marking and sends its calls. A mirror lives while its computer is heard
//! within the detection bound, so the player's own liveness check turns a lost computer's
//! programs into `program_lost`, and programs whose player is out of reach keep their events in
//! their outbox, exactly as when the player is not running.
//!
//! Events and calls are carried ([`crate::reliable`]): each loop puts on the link the copies
//! due and the acknowledgements of what it took, tells the senders of what was given up (a
//! call's `call_failed` to the player, an event's refusal in this gateway's heartbeat, where its
//! sender waits for it: [`crate::ledger`]), and delivers the held messages the player's
//! acknowledgement of a restored event released.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use petrel_ipc::wire::{self, Message};
use petrel_ipc::{
    CallReceiver, CallSender, EventMsg, EventReceiver, EventSender, FdSource, Heartbeat,
    HeartbeatPublisher, HeartbeatSubscriber, MarkingPublisher, MarkingSubscriber, Participant,
    Reactor, Received, Role, SignalsPublisher, SignalsSubscriber, Source, Value, Vehicle,
    WaitStrategy,
};
use zenoh::Wait;

use crate::core::{AckMap, Core, PeerChange, Plan, Route};
use crate::ledger::Senders;
use crate::link::{key_all, key_of, LinkKind, LinkMsg};
use crate::reliable::Failure;
use crate::session::{zenoh_config, Security, INSECURE_WARNING};

/// The events the player's computer raises when a peer computer is lost or comes back, each
/// with one parameter, the computer's name (`computer: text`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkEvents {
    /// Raised when a peer is silent past the detection bound.
    pub lost: String,
    /// Raised when a lost peer is heard again.
    pub restored: String,
}

/// zenoh's user/password authentication.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Credentials {
    /// This gateway's user.
    pub user: String,
    /// Its password.
    pub password: String,
    /// The file of `user:password` lines the gateway accepts from its peers.
    pub dictionary: PathBuf,
}

/// Everything a gateway needs.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The vehicle, as this computer's processes join it.
    pub vehicle: Vehicle,
    /// Where things live.
    pub plan: Plan,
    /// zenoh endpoints to listen on (`tcp/0.0.0.0:7447`).
    pub listen: Vec<String>,
    /// zenoh endpoints of the peers to connect to.
    pub connect: Vec<String>,
    /// How the link is secured (mutual TLS with the vehicle's keys, unless a lab bench opts
    /// out).
    pub security: Security,
    /// zenoh's user/password authentication of the peers too, if the vehicle file asks for it.
    pub credentials: Option<Credentials>,
    /// The link's events, if the vehicle file names them.
    pub link_events: Option<LinkEvents>,
    /// How often the gateway publishes its own heartbeat (its counters) here.
    pub status_period: Duration,
}

/// A gateway that could not start or stopped on an error.
#[derive(Debug)]
pub struct GatewayError(pub String);

impl std::fmt::Display for GatewayError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GatewayError {}

fn err(what: &str, e: impl std::fmt::Display) -> GatewayError {
    GatewayError(format!("{what}: {e}"))
}

/// Removes the resources of the vehicle's dead nodes on this computer, saying what it did.
fn clean_dead(vehicle: &Vehicle) {
    match petrel_ipc::cleanup_dead_nodes(vehicle, Duration::from_millis(500)) {
        Ok(r) => {
            if !r.cleaned.is_empty() {
                tracing::info!(
                    "cleaned up {} dead node(s) of the vehicle: {}",
                    r.cleaned.len(),
                    r.cleaned
                        .iter()
                        .map(|n| n.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
            for (n, e) in &r.failed {
                tracing::warn!("cannot clean up dead node `{}`: {e:?}", n.name);
            }
        }
        Err(e) => tracing::warn!("cannot clean up the vehicle's dead nodes: {e}"),
    }
}

/// The encoded body of an ipc message.
fn body_of<M: Message>(msg: &M) -> Result<Vec<u8>, String> {
    let len = wire::encoded_len(msg).map_err(|e| e.to_string())?;
    let mut bytes = vec![0u8; len];
    wire::encode_into(msg, &mut bytes).map_err(|e| e.to_string())?;
    Ok(bytes)
}

/// A stand-in for a process of another computer. Ports are declared before the participant:
/// they are dropped first.
struct Mirror {
    calls_in: Option<CallReceiver>,
    events: Option<EventSender>,
    heartbeat: Option<HeartbeatPublisher>,
    /// The largest heartbeat body `heartbeat` may send.
    heartbeat_capacity: usize,
    marking: Option<MarkingPublisher>,
    calls_out: BTreeMap<String, CallSender>,
    participant: Participant,
}

/// The gateway's own ports on this computer.
struct Own {
    status: HeartbeatPublisher,
    events_out: EventSender,
    calls_out: BTreeMap<String, CallSender>,
    events_in: Option<EventReceiver>,
    beats_in: Option<HeartbeatSubscriber>,
    marking_in: Option<MarkingSubscriber>,
    /// The data server's signals, on its computer.
    signals_in: Option<SignalsSubscriber>,
    /// The data server's signals republished, on the other computers (made at the first).
    signals_out: Option<SignalsPublisher>,
    participant: Participant,
}

/// What [`Gateway::deliver`] says of news nobody here follows.
const UNHEARD: &str = "no receiver here";

/// Sender ids of every port this gateway sends with: what they send came from the link.
#[derive(Default)]
struct OwnIds(BTreeSet<u64>);

/// Runs the gateway until SIGINT or SIGTERM. Returns its final counters as JSON.
pub fn run(settings: Settings) -> Result<serde_json::Value, GatewayError> {
    let Settings {
        vehicle,
        plan,
        status_period,
        link_events,
        ..
    } = settings.clone();
    let me = plan.computer.clone();
    let role = Role::gateway(&me).map_err(|e| err("the gateway's node name", e))?;
    let participant =
        Participant::join(&vehicle, role).map_err(|e| err("cannot join the vehicle", e))?;
    // A gateway killed before this one left its stand-ins' nodes dead: a dead `player` would
    // keep this computer's programs waiting (they wait for a dead player to be cleaned up), a
    // dead program would look crashed. Clean them as a restarted player does (and again at
    // each beacon that finds one).
    clean_dead(&vehicle);
    let mut ids = OwnIds::default();
    let status = participant
        .heartbeat_publisher_sized(64 * 1024)
        .map_err(|e| err("the status heartbeat", e))?;
    let events_out = participant
        .event_sender()
        .map_err(|e| err("the event sender", e))?;
    // Its status beats are its own news, not something that came from the link: they are not
    // among the ids whose messages never leave.
    ids.0.insert(events_out.sender_id());
    let has_player = plan.has_player();
    let own = Own {
        status,
        events_out,
        calls_out: BTreeMap::new(),
        // Events leave every computer but the player's; there, a second receiver would only
        // share the programs' buffers.
        events_in: if has_player {
            None
        } else {
            Some(
                participant
                    .event_receiver()
                    .map_err(|e| err("the event receiver", e))?,
            )
        },
        beats_in: if has_player {
            Some(
                participant
                    .heartbeat_subscriber()
                    .map_err(|e| err("the heartbeat subscriber", e))?,
            )
        } else {
            None
        },
        marking_in: if has_player {
            Some(
                participant
                    .marking_subscriber()
                    .map_err(|e| err("the marking subscriber", e))?,
            )
        } else {
            None
        },
        signals_in: if plan.has_signals() {
            Some(
                participant
                    .signals_subscriber()
                    .map_err(|e| err("the signals subscriber", e))?,
            )
        } else {
            None
        },
        signals_out: None,
        participant,
    };

    match &settings.security {
        Security::Tls(_) => tracing::info!("the link: {}", settings.security.describe()),
        Security::None => tracing::warn!("WARNING: {INSECURE_WARNING}"),
    }
    let session = zenoh::open(zenoh_config(&settings)?)
        .wait()
        .map_err(|e| err("cannot open the zenoh session", e))?;
    let publisher = session
        .declare_publisher(key_of(vehicle.name(), &me))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .map_err(|e| err("cannot declare the link publisher", e))?;
    // Each message with the computer of the key it came on: the access control lets a peer
    // put on its own computer's key only, and a message must say it is from that computer.
    let (tx, rx) = mpsc::channel::<(String, Vec<u8>)>();
    let (wake_r, wake_w) = UnixStream::pair().map_err(|e| err("the wake-up socket", e))?;
    wake_r
        .set_nonblocking(true)
        .and_then(|_| wake_w.set_nonblocking(true))
        .map_err(|e| err("the wake-up socket", e))?;
    let _subscriber = session
        .declare_subscriber(key_all(vehicle.name()))
        .callback(move |sample| {
            let computer = sample.key_expr().as_str().rsplit('/').next().unwrap_or("");
            let _ = tx.send((
                computer.to_owned(),
                sample.payload().to_bytes().into_owned(),
            ));
            // A full socket already holds a wake-up: nothing is lost.
            let _ = (&wake_w).write(&[1]);
        })
        .wait()
        .map_err(|e| err("cannot declare the link subscriber", e))?;
    let wake_source = FdSource::new(wake_r.as_raw_fd()).map_err(|e| err("the wake-up fd", e))?;
    let reactor = Reactor::new(WaitStrategy::Block).map_err(|e| err("the reactor", e))?;

    let incarnation = {
        let t = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0);
        t ^ (u64::from(std::process::id()) << 32)
    };
    let mut core = Core::new(plan, incarnation);
    // The nets must see a returning computer come back before they see its messages.
    core.set_hold_on_restore(has_player && link_events.is_some());
    let mut gw = Gateway {
        core,
        vehicle,
        own,
        ids,
        mirrors: BTreeMap::new(),
        acks: AckMap::default(),
        senders: Senders::default(),
        link_events,
        publisher,
        start: Instant::now(),
        status_period,
        security: settings.security.describe(),
    };
    tracing::info!(
        "gateway of computer `{me}` up, link key {}",
        key_of(gw.vehicle.name(), &me)
    );
    let beacon_period = Duration::from_micros(gw.core.plan().beacon_period_us());
    let mut next_beacon = Instant::now();
    let mut next_status = Instant::now();
    let mut buf = [0u8; 256];
    loop {
        let now = Instant::now();
        if now >= next_beacon {
            gw.beacon();
            let now_us = gw.now_us();
            let changes = gw.core.tick(now_us);
            gw.senders.prune(now_us);
            // A lost computer's held messages came before its loss: delivered first.
            gw.flush();
            gw.on_changes(changes);
            if let Some(why) = gw.core.refused(gw.now_us()) {
                return Err(GatewayError(format!("refused: {why}")));
            }
            next_beacon = now + beacon_period;
        }
        if now >= next_status {
            gw.publish_status();
            next_status = now + gw.status_period;
        }
        let timeout = next_beacon.min(next_status).saturating_duration_since(now);
        let ready = {
            let mut sources: Vec<&dyn Source> = vec![&wake_source];
            if let Some(r) = &gw.own.events_in {
                sources.push(r);
            }
            if let Some(r) = &gw.own.beats_in {
                sources.push(r);
            }
            if let Some(r) = &gw.own.marking_in {
                sources.push(r);
            }
            if let Some(r) = &gw.own.signals_in {
                sources.push(r);
            }
            for m in gw.mirrors.values() {
                if let Some(r) = &m.calls_in {
                    sources.push(r);
                }
            }
            reactor
                .wait(&sources, Some(timeout.max(Duration::from_millis(1))))
                .map_err(|e| err("waiting", e))?
        };
        if ready.termination_requested() {
            break;
        }
        while matches!((&wake_r).read(&mut buf), Ok(n) if n > 0) {}
        let mut changes = Vec::new();
        while let Ok((computer, bytes)) = rx.try_recv() {
            gw.take_link(&computer, &bytes, &mut changes);
        }
        gw.on_changes(changes);
        gw.take_local();
        gw.flush();
    }
    gw.publish_status();
    let status = gw.status_json();
    drop(gw);
    drop(_subscriber);
    leave(session);
    Ok(status)
}

/// Closes the zenoh session without waiting on peers that are gone: zenoh closes each QUIC
/// link gracefully and waits (up to 10 s) for an answer a stopped peer never gives. The live
/// peers are told at once; the gateway waits half a second at most, then leaves (its peers
/// would see its silence within the detection bound anyway).
fn leave(session: zenoh::Session) {
    let closing = std::thread::spawn(move || {
        let _ = session.close().wait();
    });
    let deadline = Instant::now() + Duration::from_millis(500);
    while !closing.is_finished() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Local messages for the link: origin, ipc header, kind, body.
type Out = Vec<(String, (u64, u64), LinkKind, Vec<u8>)>;

/// Local messages that could not be taken: kind, why.
type Failed = Vec<(&'static str, String)>;

/// The calls waiting in the receiver of stand-in `node`, for the link.
fn take_calls(
    node: &str,
    m: &Mirror,
    core: &mut Core,
    ids: &OwnIds,
    out: &mut Out,
    failed: &mut Failed,
) {
    if let (Some(r), Some(program)) = (&m.calls_in, node.strip_prefix("program/")) {
        let kind = LinkKind::Call {
            program: program.to_owned(),
        };
        take(r, &kind, core, ids, out, failed, &|_| {});
    }
}

/// Drains `r`: the messages of `kind` that leave this computer go to `out` (after `edit`),
/// those that cannot be read or encoded to `failed`.
fn take<M: Message>(
    r: &petrel_ipc::Receiver<M>,
    kind: &LinkKind,
    core: &mut Core,
    ids: &OwnIds,
    out: &mut Out,
    failed: &mut Failed,
    edit: &dyn Fn(&mut M),
) {
    let drained = r.drain(|r: Result<Received<M>, petrel_ipc::RecvError>| match r {
        Ok(mut rcv) => {
            let origin = rcv.origin.as_str().to_owned();
            let own = ids.0.contains(&rcv.sender);
            if core.forward_local(kind, &origin, own) {
                edit(&mut rcv.msg);
                match body_of(&rcv.msg) {
                    Ok(body) => out.push((origin, (rcv.sender, rcv.seq), kind.clone(), body)),
                    Err(e) => failed.push((kind.name(), e)),
                }
            }
        }
        Err(e) => failed.push((kind.name(), format!("local {}: {e}", kind.name()))),
    });
    if let Err(e) = drained {
        failed.push((kind.name(), format!("local {}: {e}", kind.name())));
    }
}

struct Gateway {
    core: Core,
    vehicle: Vehicle,
    own: Own,
    ids: OwnIds,
    mirrors: BTreeMap<String, Mirror>,
    acks: AckMap,
    /// This computer's senders whose events the link gave up: their verdicts.
    senders: Senders,
    link_events: Option<LinkEvents>,
    publisher: zenoh::pubsub::Publisher<'static>,
    start: Instant,
    status_period: Duration,
    /// How the link is secured, for the status.
    security: String,
}

impl Gateway {
    fn now_us(&self) -> u64 {
        self.start.elapsed().as_micros() as u64
    }

    /// Puts news (not carried) on the link.
    fn put(&mut self, origin: &str, header: (u64, u64), kind: LinkKind, body: Vec<u8>) {
        let msg = self
            .core
            .outgoing(origin, header, kind, body, self.now_us());
        self.put_msg(&msg, false);
    }

    /// Puts `msg` on the link; `again`: a carried message sent before.
    fn put_msg(&mut self, msg: &LinkMsg, again: bool) {
        let (name, origin) = (msg.kind.name(), &msg.origin);
        let bytes = match msg.encode() {
            Ok(b) => b,
            Err(e) => {
                self.core
                    .counters
                    .refuse_to_link(name, format!("{name} from {origin} not encoded: {e}"));
                return;
            }
        };
        match self.publisher.put(bytes).wait() {
            Ok(()) if again => self.core.counters.of(name).retransmitted += 1,
            Ok(()) => self.core.counters.of(name).to_link += 1,
            // A carried message stays in its buffer: it is sent again.
            Err(e) => self
                .core
                .counters
                .refuse_to_link(name, format!("{name} from {origin}: zenoh: {e}")),
        }
    }

    /// Takes a local message for the link: carried (an event, a call) or put at once (news).
    fn forward(&mut self, origin: &str, header: (u64, u64), kind: LinkKind, body: Vec<u8>) {
        if self.core.plan().destination(&kind).is_none() {
            self.put(origin, header, kind, body);
            return;
        }
        let now = self.now_us();
        if matches!(kind, LinkKind::Event) && header.0 != 0 {
            self.senders.carried(header.0, header.1, origin, now);
        }
        // Refused at once (a full buffer): its failure is told at the next flush.
        self.core.carry(origin, header, kind, body, now);
    }

    /// After each step of the loop: tells the senders of what was given up, delivers what was
    /// released, puts the copies due and the acknowledgements on the link.
    fn flush(&mut self) {
        let failures = self.core.take_failures();
        for f in failures {
            self.tell(f);
        }
        for msg in self.core.take_released() {
            self.deliver_counted(&msg);
        }
        let now = self.now_us();
        for (msg, again) in self.core.due(now) {
            self.put_msg(&msg, again);
        }
        if let Some(ack) = self.core.acks_due(now) {
            self.put_msg(&ack, false);
        }
    }

    /// Tells the sender of a carried message that the link gave it up: a call's caller gets
    /// `call_failed(program, function)` (through the player: sent here on its computer, carried
    /// to it from the others); an event's sender its refusal, in this gateway's heartbeat.
    fn tell(&mut self, f: Failure) {
        let Failure { to, msg, reason } = f;
        tracing::warn!(
            "{} from {} for computer `{to}` given up: {reason}",
            msg.kind.name(),
            msg.origin
        );
        match &msg.kind {
            LinkKind::Call { program } => {
                let function = wire::decode::<petrel_ipc::CallMsg>(&msg.body)
                    .map(|c| c.function)
                    .unwrap_or_default();
                let event = EventMsg::new(
                    "call_failed",
                    vec![Value::Text(program.clone()), Value::Text(function)],
                );
                if self.core.plan().has_player() {
                    if let Err(e) = self.own.events_out.send(&event) {
                        self.core
                            .counters
                            .refuse("call_failed", format!("call_failed({program}): {e}"));
                    } else {
                        self.core.counters.of("call_failed").delivered += 1;
                    }
                } else {
                    match body_of(&event) {
                        Ok(body) => {
                            let origin = self.own.participant.role().node_name();
                            self.forward(&origin, (0, 0), LinkKind::Event, body);
                        }
                        Err(e) => self
                            .core
                            .counters
                            .refuse("call_failed", format!("call_failed({program}): {e}")),
                    }
                }
            }
            LinkKind::Event if msg.sender != 0 => {
                let now = self.now_us();
                self.senders
                    .given_up(msg.sender, msg.seq, &msg.origin, &reason, now);
            }
            _ => {}
        }
    }

    /// Sends a beacon: this gateway lives, and which of its computer's nodes do.
    fn beacon(&mut self) {
        let exported = self.core.plan().exported_nodes();
        let alive: Vec<String> = match petrel_ipc::list_nodes(&self.vehicle) {
            Ok(nodes) => {
                // A dead node with a stand-in's name (a killed gateway's, or a crashed
                // process's) would keep programs waiting: clean it up now.
                let stale = nodes.iter().any(|n| {
                    n.status == petrel_ipc::NodeStatus::Dead
                        && (n.name == "player" || n.name.starts_with("program/"))
                });
                if stale {
                    clean_dead(&self.vehicle);
                }
                exported
                    .into_iter()
                    .filter(|e| {
                        nodes
                            .iter()
                            .any(|n| &n.name == e && n.status == petrel_ipc::NodeStatus::Alive)
                    })
                    .collect()
            }
            Err(e) => {
                tracing::warn!("cannot list the vehicle's nodes: {e}");
                Vec::new()
            }
        };
        let follows = self.core.follows();
        self.put(
            "gateway",
            (0, 0),
            LinkKind::Beacon { alive, follows },
            Vec::new(),
        );
    }

    /// Counts what could not be taken, and forwards what was.
    fn forward_all(&mut self, out: Out, failed: Failed) {
        for (kind, why) in failed {
            self.core.counters.refuse_to_link(kind, why);
        }
        for (origin, header, kind, body) in out {
            self.forward(&origin, header, kind, body);
        }
    }

    fn take_local(&mut self) {
        let mut out: Out = Vec::new();
        let mut failed: Failed = Vec::new();
        if let Some(r) = &self.own.events_in {
            take(
                r,
                &LinkKind::Event,
                &mut self.core,
                &self.ids,
                &mut out,
                &mut failed,
                &|_| {},
            );
        }
        // The player's account of this gateway's own messages (its link events).
        let own_taken = std::cell::Cell::new(None::<u64>);
        if let Some(r) = &self.own.beats_in {
            let acks = &self.acks;
            let own_sender = self.own.events_out.sender_id();
            // The other computers' senders wait for their own ids: theirs first, since a
            // heartbeat carries at most 64 acknowledgements.
            let translate = |beat: &mut Heartbeat| {
                if let Some(a) = beat.ack_for(own_sender) {
                    own_taken.set(Some(a.last_seq));
                }
                let mut translated = acks.translate(&beat.acks);
                if !translated.is_empty() {
                    translated.append(&mut beat.acks);
                    beat.acks = translated;
                    beat.bound();
                }
            };
            take(
                r,
                &LinkKind::Heartbeat,
                &mut self.core,
                &self.ids,
                &mut out,
                &mut failed,
                &translate,
            );
        }
        if let Some(r) = &self.own.marking_in {
            take(
                r,
                &LinkKind::Marking,
                &mut self.core,
                &self.ids,
                &mut out,
                &mut failed,
                &|_| {},
            );
        }
        if let Some(r) = &self.own.signals_in {
            take(
                r,
                &LinkKind::Signals,
                &mut self.core,
                &self.ids,
                &mut out,
                &mut failed,
                &|_| {},
            );
        }
        for (node, m) in &self.mirrors {
            take_calls(node, m, &mut self.core, &self.ids, &mut out, &mut failed);
        }
        if let Some(seq) = own_taken.get() {
            self.core.player_took(seq);
        }
        self.forward_all(out, failed);
    }

    fn take_link(&mut self, key_computer: &str, bytes: &[u8], changes: &mut Vec<PeerChange>) {
        let msg = match LinkMsg::decode(bytes) {
            Ok(m) if m.from == key_computer => m,
            Ok(m) => {
                let why = format!(
                    "a message claiming computer `{}` on computer `{key_computer}`'s key",
                    m.from
                );
                tracing::warn!("link message refused: {why}");
                self.core.counters.undecodable += 1;
                self.core.counters.remember(why);
                return;
            }
            Err(e) => {
                self.core.counters.undecodable += 1;
                tracing::warn!("a link message does not decode: {e}");
                return;
            }
        };
        let now = self.now_us();
        match self.core.on_link(&msg, now, changes) {
            Route::Own | Route::NotMine | Route::Beacon | Route::Held | Route::Discarded => {}
            Route::Claim(None) => {}
            Route::Claim(Some(why)) => tracing::warn!("{why}"),
            Route::Foreign(why) => tracing::warn!("link message refused: {why}"),
            Route::Deliver => self.deliver_counted(&msg),
        }
    }

    /// Delivers a link message for this computer, counts what became of it, and, for a
    /// carried one, tells the link (its acknowledgement carries a refusal back to the sender).
    fn deliver_counted(&mut self, msg: &LinkMsg) {
        // A stand-in may be needed before the message is delivered (a beacon that listed it
        // came just before): make them match only when it is missing.
        let needed = match msg.kind {
            LinkKind::Heartbeat | LinkKind::Marking => Some("player"),
            // The gateway republishes signals itself, under no stand-in.
            LinkKind::Signals => None,
            _ => Some(msg.origin.as_str()),
        };
        if needed.is_some_and(|n| !self.mirrors.contains_key(n)) {
            self.sync_mirrors();
        }
        let name = msg.kind.name();
        let refusal = match self.deliver(msg) {
            Ok(()) => {
                self.core.counters.of(name).delivered += 1;
                None
            }
            Err(why) if why == UNHEARD => {
                self.core.counters.of(name).unheard += 1;
                None
            }
            Err(why) => {
                self.core.counters.refuse(
                    name,
                    format!("{name} from {} ({}): {why}", msg.from, msg.origin),
                );
                Some(why)
            }
        };
        if msg.carried.is_some() {
            self.core.taken(msg, refusal);
        }
    }

    fn deliver(&mut self, msg: &LinkMsg) -> Result<(), String> {
        let mirror = self.mirrors.get_mut(&msg.origin);
        let sent = match &msg.kind {
            LinkKind::Event => {
                let sender: Option<&EventSender> = match mirror {
                    Some(m) => {
                        if m.events.is_none() {
                            let s = m.participant.event_sender().map_err(|e| e.to_string())?;
                            self.ids.0.insert(s.sender_id());
                            m.events = Some(s);
                        }
                        m.events.as_ref()
                    }
                    None => Some(&self.own.events_out),
                };
                let sent = sender.map(|s| (s.sender_id(), s.send_encoded(&msg.body)));
                // The player acknowledges the port that sent it: remember whose message it
                // was, for the heartbeat that goes back (see `AckMap`).
                if let Some((port, Ok(s))) = &sent {
                    self.acks
                        .record(*port, s.seq, msg.sender, msg.seq, &msg.origin);
                }
                if let Some((port, Err(e))) = &sent {
                    if let Some(seq) = e.seq() {
                        self.acks
                            .record(*port, seq, msg.sender, msg.seq, &msg.origin);
                    }
                }
                sent.map(|(_, r)| r)
            }
            LinkKind::Call { program } => {
                let (participant, calls) = match mirror {
                    Some(m) => (&m.participant, &mut m.calls_out),
                    None => (&self.own.participant, &mut self.own.calls_out),
                };
                if !calls.contains_key(program) {
                    let s = participant
                        .call_sender(program)
                        .map_err(|e| e.to_string())?;
                    self.ids.0.insert(s.sender_id());
                    calls.insert(program.clone(), s);
                }
                calls.get(program).map(|s| s.send_encoded(&msg.body))
            }
            LinkKind::Heartbeat | LinkKind::Marking => {
                let Some(m) = self.mirrors.get_mut("player") else {
                    return Err("the player is not mirrored here (its computer is not up)".into());
                };
                if matches!(msg.kind, LinkKind::Heartbeat) {
                    // The player's verdicts on this computer's senders, for those whose events
                    // the link gave up (their verdict merges both).
                    if let Ok(beat) = wire::decode::<Heartbeat>(&msg.body) {
                        self.senders.player_acks(&beat.acks);
                    }
                    // Sized from the player's heartbeats as they come (twice the largest seen),
                    // as the player sizes its own from the project: a publisher sized for the
                    // largest body possible takes long to set up and holds memory for nothing.
                    if m.heartbeat.is_none() || msg.body.len() > m.heartbeat_capacity {
                        m.heartbeat = None;
                        let capacity = (msg.body.len() * 2).clamp(64 * 1024, wire::MAX_BODY_LEN);
                        let s = m
                            .participant
                            .heartbeat_publisher_sized(capacity)
                            .map_err(|e| e.to_string())?;
                        self.ids.0.insert(s.sender_id());
                        m.heartbeat = Some(s);
                        m.heartbeat_capacity = capacity;
                    }
                    m.heartbeat.as_ref().map(|s| s.send_encoded(&msg.body))
                } else {
                    if m.marking.is_none() {
                        let s = m
                            .participant
                            .marking_publisher()
                            .map_err(|e| e.to_string())?;
                        self.ids.0.insert(s.sender_id());
                        m.marking = Some(s);
                    }
                    m.marking.as_ref().map(|s| s.send_encoded(&msg.body))
                }
            }
            LinkKind::Signals => {
                // Published by the gateway's own node (`tool/gw-NAME`): the programs read the
                // latest signals whoever publishes them.
                if self.own.signals_out.is_none() {
                    let s = self
                        .own
                        .participant
                        .signals_publisher()
                        .map_err(|e| e.to_string())?;
                    self.ids.0.insert(s.sender_id());
                    self.own.signals_out = Some(s);
                }
                self.own
                    .signals_out
                    .as_ref()
                    .map(|s| s.send_encoded(&msg.body))
            }
            LinkKind::Beacon { .. } | LinkKind::Ack { .. } => return Ok(()),
        };
        match sent {
            Some(Ok(_)) => Ok(()),
            // A heartbeat, marking delta or signals nobody here follows (no status, monitor,
            // shadow or program reading signals running): broadcast news, not a loss.
            Some(Err(petrel_ipc::SendError::NoReceiver { .. }))
                if matches!(
                    msg.kind,
                    LinkKind::Heartbeat | LinkKind::Marking | LinkKind::Signals
                ) =>
            {
                Err(UNHEARD.into())
            }
            Some(Err(e)) => Err(e.to_string()),
            None => Err("no port".into()),
        }
    }

    fn on_changes(&mut self, changes: Vec<PeerChange>) {
        // A computer heard (again): say at once whom this gateway follows, so that it takes
        // what this one sends it without waiting for the next beacon.
        let heard = changes
            .iter()
            .any(|c| matches!(c, PeerChange::Joined(_) | PeerChange::Restored(_)));
        for change in changes {
            let (event, computer) = match &change {
                PeerChange::Joined(c) => {
                    tracing::info!("computer `{c}` joined");
                    continue;
                }
                PeerChange::Lost(c) => {
                    tracing::warn!("computer `{c}` lost (silent for longer than the bound)");
                    (self.link_events.as_ref().map(|e| e.lost.clone()), c)
                }
                PeerChange::Restored(c) => {
                    tracing::info!("computer `{c}` back");
                    (self.link_events.as_ref().map(|e| e.restored.clone()), c)
                }
            };
            // The player's computer tells the nets; the others have no player to tell.
            if let (Some(event), true) = (event, self.core.plan().has_player()) {
                let msg = EventMsg::new(event.clone(), vec![Value::Text(computer.clone())]);
                let sent = match self.own.events_out.send(&msg) {
                    Err(e) => {
                        tracing::warn!(
                            "the link event `{event}({computer})` was not delivered: {e}"
                        );
                        self.core
                            .counters
                            .refuse("link_event", format!("{event}({computer}): {e}"));
                        None
                    }
                    Ok(sent) => {
                        self.core.counters.of("link_event").delivered += 1;
                        Some(sent.seq)
                    }
                };
                if matches!(change, PeerChange::Restored(_)) {
                    // The computer's held messages go once the player took this one.
                    self.core.link_event_sent(computer, sent);
                }
            }
        }
        if heard {
            self.beacon();
        }
        self.sync_mirrors();
    }

    /// Makes the mirrors match the peers' nodes alive.
    fn sync_mirrors(&mut self) {
        let wanted = self.core.mirrored();
        let gone: Vec<String> = self
            .mirrors
            .keys()
            .filter(|n| !wanted.contains_key(*n))
            .cloned()
            .collect();
        for node in gone {
            tracing::info!("stand-in `{node}` leaves");
            if let Some(m) = self.mirrors.remove(&node) {
                // Calls the player sent it before it left are carried like the others (their
                // destination tells, or the link gives them up): none dropped with the port.
                let (mut out, mut failed) = (Vec::new(), Vec::new());
                take_calls(&node, &m, &mut self.core, &self.ids, &mut out, &mut failed);
                self.forward_all(out, failed);
            }
        }
        for node in wanted.keys() {
            if self.mirrors.contains_key(node) {
                continue;
            }
            let role = match node.strip_prefix("program/") {
                Some(p) => Role::program(p),
                None => Ok(Role::Player),
            };
            let participant = match role.map(|r| Participant::join(&self.vehicle, r)) {
                Ok(Ok(p)) => p,
                Ok(Err(e)) => {
                    tracing::warn!("cannot stand in for `{node}`: {e}");
                    continue;
                }
                Err(e) => {
                    tracing::warn!("cannot stand in for `{node}`: {e}");
                    continue;
                }
            };
            let calls_in = if node.starts_with("program/") {
                match participant.call_receiver() {
                    Ok(r) => Some(r),
                    Err(e) => {
                        tracing::warn!("no call receiver for `{node}`: {e}");
                        None
                    }
                }
            } else {
                None
            };
            tracing::info!("stand-in `{node}` joins");
            self.mirrors.insert(
                node.clone(),
                Mirror {
                    calls_in,
                    events: None,
                    heartbeat: None,
                    heartbeat_capacity: 0,
                    marking: None,
                    calls_out: BTreeMap::new(),
                    participant,
                },
            );
        }
    }

    fn status_json(&self) -> serde_json::Value {
        serde_json::json!({
            "computer": self.core.plan().computer,
            "player_computer": self.core.plan().player_computer,
            "peers": self.core.peers(),
            "mirrors": self.mirrors.keys().collect::<Vec<_>>(),
            "counters": self.core.counters,
            "security": self.security,
        })
    }

    fn publish_status(&mut self) {
        let status = self.status_json().to_string();
        let progress = self
            .core
            .counters
            .kinds
            .values()
            .map(|c| c.to_link + c.from_link)
            .sum();
        let mut beat = Heartbeat {
            uptime_ms: self.start.elapsed().as_millis() as u64,
            period_ms: self.status_period.as_millis() as u32,
            progress,
            status,
            // The verdicts of this computer's senders whose events the link gave up
            // (`petrel_ipc::wait_acknowledged` reads them with the player's).
            acks: self.senders.acks(),
            ..Heartbeat::default()
        };
        beat.bound();
        if let Err(e) = self.own.status.send(&beat) {
            // Nobody listens (no `petrel status` running): the usual case.
            tracing::trace!("status heartbeat: {e}");
        }
    }
}
