//! Sending and receiving ports: a [`Sender`] and a [`Receiver`] per message kind, each a
//! publish-subscribe port on `[u8]` paired with an event port that wakes the receiving side.
//!
//! Every service of a vehicle is set up from one [`ServiceSpec`] (see [`EVENTS`], [`CALLS`],
//! [`MARKING`], [`HEARTBEAT`]) so that every process opens it with the same settings.
//!
//! **Nothing is lost unseen.** Except for heartbeats, services do not overwrite: iceoryx2's
//! `safe_overflow` is off and publishers discard a sample for a receiver whose buffer is full.
//! [`Sender::send`] compares the delivery count iceoryx2 returns with the number of connected
//! receivers and reports the difference as [`SendError::NoReceiver`] or
//! [`SendError::Refused`]. The refused message keeps its sequence number, so the receiver sees
//! the gap ([`Received::missed`], [`ReceiverStats::missing`]): for every sender, messages
//! sent = received + refused.
//!
//! **Waking the receiver.** After a delivery a sender rings the receivers' doorbells
//! ([`crate::doorbell`]): one asleep on its futex word is woken, an awake one is left alone,
//! and one asleep on its listener (or without a doorbell) is notified through the paired event
//! service ([`SenderStats::notified`]). A sender keeps the doorbells it found and lists
//! iceoryx2's subscribers again only when the receivers may have changed (see
//! [`crate::doorbell`], "Knowing the receivers").
//!
//! Ports of `ipc::Service` are single-threaded (not `Send`): create them on the thread that uses
//! them. Their methods take `&self`, so a [`Reactor`](crate::reactor::Reactor) can watch
//! receivers while the caller drains them.

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::fmt;
use std::marker::PhantomData;
use std::mem::ManuallyDrop;
use std::sync::Arc;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::{LoanError, ReceiveError};
use iceoryx2::prelude::{ipc, EventId, PortFactory};
use iceoryx2::service::port_factory::publish_subscribe;

use crate::access::Session;
use crate::doorbell::{self, Bells, Changes, Doorbell, Joined};
use crate::mending::Mending;
use crate::wire::{self, Message, MsgHeader, MsgKind, Origin, WireError, WIRE_VERSION};

/// Event id a sender notifies after delivering a sample.
pub const WAKE_SAMPLE: usize = 1;
/// Event id iceoryx2 emits when a sender (its notifier) joins the service.
pub const WAKE_SENDER_JOINED: usize = 2;
/// Event id iceoryx2 emits when a sender leaves the service in good order.
pub const WAKE_SENDER_LEFT: usize = 3;
/// Event id iceoryx2 emits when the node of a sender was found dead and cleaned up.
pub const WAKE_SENDER_DIED: usize = 4;
/// Largest event id of the paired event services.
pub const WAKE_MAX: usize = 7;

/// How often a spinning receiver consumes its notifications
/// ([`Receiver::consume_wakeups_every`]): news of a sender comes at most this late.
pub const SPIN_WAKEUP_PERIOD: Duration = Duration::from_millis(1);

/// How one kind of service is set up. Every process opens a service with the same spec.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceSpec {
    /// The body the service carries.
    pub kind: MsgKind,
    /// Samples one receiver holds for one sender before further ones are refused
    /// (or, with `safe_overflow`, overwritten).
    pub subscriber_buffer: usize,
    /// Samples a sender keeps for receivers that connect later.
    pub history: usize,
    /// Senders at most.
    pub max_publishers: usize,
    /// Receivers at most.
    pub max_subscribers: usize,
    /// Processes (nodes) that may open the service at most.
    pub max_nodes: usize,
    /// Slice length every sample starts with; larger bodies grow the sender's memory by powers
    /// of two, up to `max_body_len`.
    pub initial_slice_len: usize,
    /// Largest encoded body accepted by [`Sender::send`].
    pub max_body_len: usize,
    /// Overwrite the oldest sample when a receiver's buffer is full (latest-value semantics)
    /// instead of refusing the new one.
    pub safe_overflow: bool,
}

/// Events into the player: a burst of 2,048 events from one sender fits in the player's
/// buffer (200 ms of a 10 kHz stream while the player does not read); one player receives (a
/// second one is refused).
///
/// **What a buffer costs.** A sender holds `max_subscribers x (subscriber_buffer + 2) + 2`
/// samples, and iceoryx2 0.10 keeps, in the sender's own memory, a reference counter per
/// sample for each of the 255 segments a power-of-two publisher may grow to: about 2 KiB of
/// resident memory per sample, whatever the body's size. 16,384 events cost every program
/// 33 MB; 2,048 cost it 4 MB (docs/benchmarks.md, "Footprint"). A sender of one fixed
/// segment keeps 8 bytes per sample: what
/// [`Participant::event_sender_sized`](crate::Participant::event_sender_sized) gives a program
/// once the player recorded its project's longest event.
pub const EVENTS: ServiceSpec = ServiceSpec {
    kind: MsgKind::Event,
    subscriber_buffer: 2_048,
    history: 0,
    // For a service a process makes before the player (which makes it for its project's
    // programs: `Participant::event_receiver_sized`): 50 programs, the data server and
    // operator tools at once. A slot costs the service a few bytes, but a receiver's every look
    // walks them all.
    max_publishers: 128,
    max_subscribers: 1,
    max_nodes: 160,
    initial_slice_len: 512,
    max_body_len: 64 * 1024,
    safe_overflow: false,
};

/// Calls from the player to one program (one service per program): a program may fall 128
/// calls behind before the player's calls to it are refused (each refusal becomes
/// `call_failed`). The player pays about 0.3 MB per program for it (see [`EVENTS`]; at 4,096
/// the five programs of Redermor cost it about 40 MB). No history: a restarted program never
/// receives stale calls.
pub const CALLS: ServiceSpec = ServiceSpec {
    kind: MsgKind::Call,
    subscriber_buffer: 128,
    history: 0,
    max_publishers: 4,
    max_subscribers: 1,
    max_nodes: 16,
    initial_slice_len: 512,
    max_body_len: 64 * 1024,
    safe_overflow: false,
};

/// Marking deltas to monitors. A monitor that falls 128 steps behind is refused further
/// deltas (counted by the player, seen as a gap by the monitor) until it catches up, and must
/// wait for a snapshot. Eight monitors of 128 deltas cost a growing publisher about 2 MB (see
/// [`EVENTS`]); the player's is one fixed segment sized from its project
/// ([`Participant::marking_publisher_sized`](crate::Participant::marking_publisher_sized)), a
/// few KB.
pub const MARKING: ServiceSpec = ServiceSpec {
    kind: MsgKind::Marking,
    subscriber_buffer: 128,
    history: 0,
    max_publishers: 2,
    max_subscribers: 8,
    max_nodes: 16,
    initial_slice_len: 1_024,
    max_body_len: wire::MAX_BODY_LEN,
    safe_overflow: false,
};

/// Heartbeats: latest-value semantics (a slow listener loses old heartbeats, never new ones).
///
/// No history: iceoryx2 hands its history to a new subscriber only when the publisher next
/// sends (or updates its connections), and by then the next heartbeat is there anyway.
pub const HEARTBEAT: ServiceSpec = ServiceSpec {
    kind: MsgKind::Heartbeat,
    subscriber_buffer: 4,
    history: 0,
    max_publishers: 64,
    max_subscribers: 16,
    max_nodes: 80,
    initial_slice_len: 64,
    max_body_len: 1_024,
    safe_overflow: true,
};

/// CAN signals: latest-value semantics, like heartbeats (a program wants the newest depth, not
/// every one it missed).
pub const SIGNALS: ServiceSpec = ServiceSpec {
    kind: MsgKind::Signals,
    subscriber_buffer: 4,
    history: 0,
    max_publishers: 4,
    max_subscribers: 32,
    max_nodes: 64,
    initial_slice_len: 4_096,
    max_body_len: wire::MAX_BODY_LEN,
    safe_overflow: true,
};

/// Reload requests into the player (`petrel reload`): a few at a time, from a few tools.
pub const RELOAD: ServiceSpec = ServiceSpec {
    kind: MsgKind::ReloadRequest,
    subscriber_buffer: 8,
    history: 0,
    max_publishers: 8,
    max_subscribers: 1,
    max_nodes: 16,
    initial_slice_len: 1_024,
    max_body_len: 128 * 1024,
    safe_overflow: false,
};

/// The player's answers to reload requests, to the requesters and shadows listening.
pub const RELOAD_ANSWER: ServiceSpec = ServiceSpec {
    kind: MsgKind::ReloadAnswer,
    subscriber_buffer: 8,
    history: 0,
    max_publishers: 2,
    max_subscribers: 16,
    max_nodes: 32,
    initial_slice_len: 4_096,
    max_body_len: wire::MAX_BODY_LEN,
    safe_overflow: true,
};

/// What a successful [`Sender::send`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sent {
    /// The message's sequence number.
    pub seq: u64,
    /// Receivers that got it.
    pub delivered: usize,
}

/// Counters of a sender. `sent = delivered + refused`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SenderStats {
    /// Messages handed to the transport (sequence numbers used).
    pub sent: u64,
    /// Messages delivered to every connected receiver.
    pub delivered: u64,
    /// Messages some receiver did not get: nobody listened, a buffer was full, or the
    /// transport failed.
    pub refused: u64,
    /// Messages never handed to the transport (too large, no shared memory left); they used no
    /// sequence number.
    pub not_sent: u64,
    /// Deliveries whose wake-up notification failed (the receiver finds the sample at its next
    /// wake-up).
    pub wake_failures: u64,
    /// Deliveries that notified the receivers through iceoryx2 (a receiver asleep on its
    /// listener, or without a doorbell). The others rang a doorbell or found every receiver
    /// awake: see [`crate::doorbell`].
    pub notified: u64,
}

/// A message could not be sent, or not to everyone.
#[derive(Debug)]
pub enum SendError {
    /// The body could not be encoded or is too large; nothing was sent.
    Wire {
        /// The service.
        service: String,
        /// Why.
        error: WireError,
    },
    /// No shared memory could be loaned for the sample; nothing was sent.
    Loan {
        /// The service.
        service: String,
        /// iceoryx2's reason.
        error: LoanError,
    },
    /// Nobody receives on the service: the message was dropped.
    NoReceiver {
        /// The service.
        service: String,
        /// Kind of the message.
        kind: MsgKind,
        /// The dropped message's sequence number.
        seq: u64,
    },
    /// Some receiver's buffer was full: it did not get the message.
    Refused {
        /// The service.
        service: String,
        /// The message's sequence number.
        seq: u64,
        /// Receivers that got it.
        delivered: usize,
        /// Receivers connected.
        receivers: usize,
    },
    /// iceoryx2 failed while delivering.
    Transport {
        /// The service.
        service: String,
        /// The message's sequence number.
        seq: u64,
        /// iceoryx2's reason.
        error: iceoryx2::port::SendError,
    },
}

impl SendError {
    /// The sequence number the message used, if it was handed to the transport.
    pub fn seq(&self) -> Option<u64> {
        match self {
            SendError::Wire { .. } | SendError::Loan { .. } => None,
            SendError::NoReceiver { seq, .. }
            | SendError::Refused { seq, .. }
            | SendError::Transport { seq, .. } => Some(*seq),
        }
    }

    /// True when the message was handed over but not delivered to every receiver; such a
    /// message shows as a gap at the receivers that missed it.
    pub fn is_refusal(&self) -> bool {
        self.seq().is_some()
    }
}

impl fmt::Display for SendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SendError::Wire { service, error } => {
                write!(f, "cannot send on `{service}`: {error}")
            }
            SendError::Loan { service, error } => write!(
                f,
                "cannot send on `{service}`: no shared memory for the sample ({error:?}); \
                 the receivers may hold too many samples"
            ),
            SendError::NoReceiver { service, kind, seq } => {
                let hint = match kind {
                    MsgKind::Event => "is the player running?",
                    MsgKind::Call => "is the program running?",
                    MsgKind::ReloadRequest => "is the player running?",
                    MsgKind::Marking
                    | MsgKind::Heartbeat
                    | MsgKind::Signals
                    | MsgKind::ReloadAnswer => "no monitor is connected",
                };
                write!(
                    f,
                    "message {seq} on `{service}` was dropped: nobody receives ({hint})"
                )
            }
            SendError::Refused {
                service,
                seq,
                delivered,
                receivers,
            } => write!(
                f,
                "message {seq} on `{service}` reached {delivered} of {receivers} receivers: \
                 a receiver's buffer is full (it does not keep up)"
            ),
            SendError::Transport {
                service,
                seq,
                error,
            } => write!(
                f,
                "message {seq} on `{service}` could not be delivered: {error}"
            ),
        }
    }
}

impl std::error::Error for SendError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            SendError::Wire { error, .. } => Some(error),
            SendError::Loan { error, .. } => Some(error),
            SendError::Transport { error, .. } => Some(error),
            _ => None,
        }
    }
}

/// The sending side of one service: encodes bodies straight into loaned shared memory, numbers
/// them, and wakes the receivers.
pub struct Sender<M: Message> {
    service: String,
    spec: ServiceSpec,
    origin: Origin,
    sender_id: u64,
    // Dropped by hand, publisher then notifier, before the receivers' doorbells ring the news
    // (see `Drop`).
    publisher: ManuallyDrop<Publisher<ipc::Service, [u8], MsgHeader>>,
    /// `Some`: the port's samples are one fixed segment of this many bytes, and a longer body
    /// (up to `spec.max_body_len`) goes in pieces of this size ([`wire::FRAGMENT`]).
    fixed_len: Option<usize>,
    notifier: ManuallyDrop<Notifier<ipc::Service>>,
    factory: publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
    /// The doorbells of the service's receivers.
    bells: RefCell<Bells>,
    next_seq: Cell<u64>,
    stats: Cell<SenderStats>,
    _kind: PhantomData<fn(&M)>,
    /// The process's membership of the vehicle, kept while the port lives.
    _session: Arc<Session>,
}

/// Sends events to the player (programs, CAN bridge, tools).
pub type EventSender = Sender<wire::EventMsg>;
/// Sends calls to one program (the player).
pub type CallSender = Sender<wire::CallMsg>;
/// Publishes marking deltas (the player).
pub type MarkingPublisher = Sender<wire::MarkingMsg>;
/// Publishes heartbeats.
pub type HeartbeatPublisher = Sender<wire::Heartbeat>;
/// Publishes the latest CAN signal values (the CAN data server).
pub type SignalsPublisher = Sender<wire::SignalsMsg>;
/// Sends reload requests to the player.
pub type ReloadRequester = Sender<wire::ReloadRequest>;
/// The player's sender of reload answers.
pub type ReloadAnswerPublisher = Sender<wire::ReloadAnswer>;

impl<M: Message> fmt::Debug for Sender<M> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Sender")
            .field("service", &self.service)
            .field("origin", &self.origin)
            .field("sender_id", &self.sender_id)
            .field("fixed_len", &self.fixed_len)
            .field("stats", &self.stats.get())
            .finish()
    }
}

/// The node id of subscriber `subscriber` of the service.
fn own_node_id(
    factory: &publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
    subscriber: u128,
) -> Option<u128> {
    let mut node = None;
    factory.dynamic_config().list_subscribers(|d| {
        if d.subscriber_id.value() == subscriber {
            node = Some(d.node_id.value());
            iceoryx2::prelude::CallbackProgression::Stop
        } else {
            iceoryx2::prelude::CallbackProgression::Continue
        }
    });
    node
}

/// The change counter of the service's receivers ([`Changes`]), made for the session's group
/// when it is shared, or `None` when it cannot be opened: senders then list the receivers at
/// every send.
fn changes(
    factory: &publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
    session: &Session,
) -> Option<Changes> {
    Changes::open(
        session.shm_prefix(),
        factory.service_hash().as_str(),
        session.group(),
    )
    .ok()
}

fn fold_id(id: u128) -> u64 {
    (id as u64) ^ ((id >> 64) as u64)
}

impl<M: Message> Sender<M> {
    #[allow(clippy::too_many_arguments)] // one per part of a port, all owned by it
    pub(crate) fn new(
        service: String,
        spec: ServiceSpec,
        origin: Origin,
        publisher: Publisher<ipc::Service, [u8], MsgHeader>,
        fixed_len: Option<usize>,
        notifier: Notifier<ipc::Service>,
        factory: publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
        session: Arc<Session>,
    ) -> Self {
        let sender_id = fold_id(publisher.id().value());
        let bells = Bells::new(changes(&factory, &session));
        let sender = Sender {
            service,
            spec,
            origin,
            sender_id,
            publisher: ManuallyDrop::new(publisher),
            fixed_len,
            notifier: ManuallyDrop::new(notifier),
            factory,
            bells: RefCell::new(bells),
            next_seq: Cell::new(1),
            stats: Cell::new(SenderStats::default()),
            _kind: PhantomData,
            _session: session,
        };
        // iceoryx2 told the receivers' listeners that this sender joined (its notifier was
        // created): a receiver asleep on its doorbell must look.
        sender.ring_bells(true, 0);
        sender
    }

    /// Rings the doorbells of the service's receivers (the news, or a delivery to `delivered`
    /// of them); returns whether some receiver must be notified through iceoryx2.
    fn ring_bells(&self, news: bool, delivered: usize) -> bool {
        let config = self.factory.dynamic_config();
        self.bells
            .borrow_mut()
            .ring(self._session.shm_prefix(), news, delivered, |f| {
                config.list_subscribers(|d| {
                    f(d.node_id.value(), d.subscriber_id.value());
                    iceoryx2::prelude::CallbackProgression::Continue
                })
            })
    }

    /// The service this sender publishes on.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The spec the service was opened with.
    pub fn spec(&self) -> &ServiceSpec {
        &self.spec
    }

    /// This sender's id, as receivers see it in [`Received::sender`].
    pub fn sender_id(&self) -> u64 {
        self.sender_id
    }

    /// The length of this sender's fixed samples (`None`: its samples grow by powers of two up
    /// to the spec's `max_body_len`). A longer body goes in pieces of this length.
    pub fn fixed_len(&self) -> Option<usize> {
        self.fixed_len
    }

    /// This sender's origin (its participant's node name).
    pub fn origin(&self) -> Origin {
        self.origin
    }

    /// The sequence number the next message will use.
    pub fn next_seq(&self) -> u64 {
        self.next_seq.get()
    }

    /// The counters of this sender.
    pub fn stats(&self) -> SenderStats {
        self.stats.get()
    }

    /// Sets how often at least this sender lists the service's receivers again when their
    /// change counter did not move ([`DOORBELL_SLICE`](crate::reactor::DOORBELL_SLICE) by
    /// default): the safety net for a receiver that does not bump the counter (of another
    /// build; see [`crate::doorbell`]). A test that must see the counter at work sets an hour.
    pub fn set_listing_period(&self, period: Duration) {
        self.bells.borrow_mut().set_period(period);
    }

    /// Receivers connected to the service now.
    pub fn receivers(&self) -> usize {
        self.factory.dynamic_config().number_of_subscribers()
    }

    /// Encodes `msg` into loaned shared memory, sends it and wakes the receivers.
    ///
    /// Returns an error when the message was not delivered to every connected receiver, so the
    /// caller can count refusals; [`SendError::seq`] tells whether it used a sequence number.
    pub fn send(&self, msg: &M) -> Result<Sent, SendError> {
        self.send_body(msg)
    }

    /// [`send`](Self::send) of a body borrowed from the caller's data ([`wire::CallRef`]),
    /// whose bytes are those of the message it stands for: nothing is built on the way.
    pub fn send_body<B: wire::Body<Msg = M>>(&self, msg: &B) -> Result<Sent, SendError> {
        match wire::encoded_len(msg) {
            Ok(len) => self.send_measured(msg, len),
            Err(error) => Err(self.not_sent_wire(error)),
        }
    }

    /// [`send_body`](Self::send_body) of a body whose encoded length the caller measured
    /// already ([`wire::encoded_len`]), so that it is not measured twice. A `len` that is not
    /// the body's is refused as [`WireError`] (nothing is sent): the encoding must fill
    /// exactly `len` bytes.
    pub fn send_measured<B: wire::Body<Msg = M>>(
        &self,
        msg: &B,
        len: usize,
    ) -> Result<Sent, SendError> {
        if len > self.spec.max_body_len {
            return Err(self.not_sent_wire(WireError::TooLarge {
                len,
                max: self.spec.max_body_len,
            }));
        }
        if let Some(fixed) = self.fixed_len.filter(|&f| len > f) {
            // Longer than the fixed samples: encoded apart, then sent in pieces (rare: the
            // fixed length is the longest body the project foresees).
            let mut body = vec![0u8; len];
            return match wire::encode_into(msg, &mut body) {
                Ok(written) if written == len => self.send_pieces(&body, fixed),
                Ok(written) => Err(self.not_sent_wire(WireError::LengthMismatch {
                    measured: len,
                    written,
                })),
                Err(error) => Err(self.not_sent_wire(error)),
            };
        }
        let sample = match self.publisher.loan_slice_uninit(len) {
            Ok(sample) => sample,
            Err(error) => return Err(self.not_sent_loan(error)),
        };
        // Zero the loaned bytes (a memset of `len` bytes) so that encoding writes into an
        // initialised `&mut [u8]` without `unsafe`; no intermediate buffer is built.
        let mut sample = sample.write_from_fn(|_| 0u8);
        match wire::encode_into(msg, sample.payload_mut()) {
            Ok(written) if written == len => {}
            Ok(written) => {
                return Err(self.not_sent_wire(WireError::LengthMismatch {
                    measured: len,
                    written,
                }))
            }
            Err(error) => return Err(self.not_sent_wire(error)),
        }
        let seq = self.take_seq();
        *sample.user_header_mut() = self.header(seq);
        let result = sample.send();
        self.account(seq, result)
    }

    /// Sends a body that is already encoded (for relays that forward messages without decoding
    /// them). The body is not checked: receivers report what does not decode.
    pub fn send_encoded(&self, body: &[u8]) -> Result<Sent, SendError> {
        if body.len() > self.spec.max_body_len {
            return Err(self.not_sent_wire(WireError::TooLarge {
                len: body.len(),
                max: self.spec.max_body_len,
            }));
        }
        if let Some(fixed) = self.fixed_len.filter(|&f| body.len() > f) {
            return self.send_pieces(body, fixed);
        }
        let sample = match self.publisher.loan_slice_uninit(body.len()) {
            Ok(sample) => sample,
            Err(error) => return Err(self.not_sent_loan(error)),
        };
        let mut sample = sample.write_from_slice(body);
        let seq = self.take_seq();
        *sample.user_header_mut() = self.header(seq);
        let result = sample.send();
        self.account(seq, result)
    }

    /// Sends `body` in pieces of `piece` bytes, each a sample numbered like a message
    /// ([`wire::FRAGMENT`]): the receiver joins them. A piece that is not delivered ends the
    /// body there (the receiver drops what it had of it: a gap in the sequence) and is
    /// returned as the body's error; the caller may send the body again.
    fn send_pieces(&self, body: &[u8], piece: usize) -> Result<Sent, SendError> {
        let pieces = body.len().div_ceil(piece);
        let mut sent = None;
        for (i, chunk) in body.chunks(piece).enumerate() {
            let mut flags = wire::FRAGMENT;
            if i == 0 {
                flags |= wire::FRAGMENT_FIRST;
            }
            if i + 1 == pieces {
                flags |= wire::FRAGMENT_LAST;
            }
            let sample = match self.publisher.loan_slice_uninit(chunk.len()) {
                Ok(sample) => sample,
                Err(error) => return Err(self.not_sent_loan(error)),
            };
            let mut sample = sample.write_from_slice(chunk);
            let seq = self.take_seq();
            *sample.user_header_mut() = MsgHeader {
                fragment: flags,
                ..self.header(seq)
            };
            let result = sample.send();
            sent = Some(self.account(seq, result)?);
        }
        // A body is never empty (its encoding has a length or a tag at least).
        sent.ok_or_else(|| {
            self.not_sent_wire(WireError::LengthMismatch {
                measured: body.len(),
                written: 0,
            })
        })
    }

    fn header(&self, seq: u64) -> MsgHeader {
        MsgHeader {
            sender: self.sender_id,
            seq,
            version: WIRE_VERSION,
            kind: M::KIND as u16,
            fragment: 0,
            origin: self.origin.bytes(),
        }
    }

    fn take_seq(&self) -> u64 {
        let seq = self.next_seq.get();
        self.next_seq.set(seq + 1);
        seq
    }

    fn update(&self, f: impl FnOnce(&mut SenderStats)) {
        let mut stats = self.stats.get();
        f(&mut stats);
        self.stats.set(stats);
    }

    fn not_sent_wire(&self, error: WireError) -> SendError {
        self.update(|s| s.not_sent += 1);
        SendError::Wire {
            service: self.service.clone(),
            error,
        }
    }

    fn not_sent_loan(&self, error: LoanError) -> SendError {
        self.update(|s| s.not_sent += 1);
        SendError::Loan {
            service: self.service.clone(),
            error,
        }
    }

    fn account(
        &self,
        seq: u64,
        result: Result<usize, iceoryx2::port::SendError>,
    ) -> Result<Sent, SendError> {
        let delivered = match result {
            Ok(delivered) => delivered,
            Err(error) => {
                self.update(|s| {
                    s.sent += 1;
                    s.refused += 1;
                });
                return Err(SendError::Transport {
                    service: self.service.clone(),
                    seq,
                    error,
                });
            }
        };
        if delivered > 0 {
            // Every receiver that sleeps on its doorbell is rung; the awake ones are left
            // alone; those asleep on their listener (or without a doorbell) are notified.
            doorbell::delivered();
            if self.ring_bells(false, delivered) {
                self.update(|s| s.notified += 1);
                let woke = self
                    .notifier
                    .notify_with_custom_event_id(EventId::new(WAKE_SAMPLE));
                if woke.is_err() {
                    self.update(|s| s.wake_failures += 1);
                }
            }
        }
        // The receivers the last listing found, refreshed by `ring_bells` when they changed:
        // enough to tell that everyone got the sample. Fewer deliveries are checked against
        // iceoryx2's count, so that a stale listing never makes a refusal.
        let receivers = match self.bells.borrow().listed() {
            Some(listed) if delivered > 0 && delivered >= listed => delivered,
            _ => self.receivers(),
        };
        if delivered >= receivers && delivered > 0 {
            self.update(|s| {
                s.sent += 1;
                s.delivered += 1;
            });
            return Ok(Sent { seq, delivered });
        }
        self.update(|s| {
            s.sent += 1;
            s.refused += 1;
        });
        if receivers == 0 {
            Err(SendError::NoReceiver {
                service: self.service.clone(),
                kind: M::KIND,
                seq,
            })
        } else {
            Err(SendError::Refused {
                service: self.service.clone(),
                seq,
                delivered,
                receivers,
            })
        }
    }
}

impl<M: Message> Drop for Sender<M> {
    fn drop(&mut self) {
        // SAFETY: both fields are dropped once, here, and not used afterwards (the struct is
        // being dropped).
        unsafe {
            ManuallyDrop::drop(&mut self.publisher);
            ManuallyDrop::drop(&mut self.notifier);
        }
        // The notifier's drop told the listeners this sender left, the publisher being gone
        // already (as a receiver that looks at the live senders expects): now the receivers
        // asleep on their doorbell must look.
        self.ring_bells(true, 0);
    }
}

/// A message taken from a receiver.
#[derive(Debug, Clone, PartialEq)]
pub struct Received<M> {
    /// The message.
    pub msg: M,
    /// Who sent it.
    pub origin: Origin,
    /// The sending port's id.
    pub sender: u64,
    /// Its sequence number at the sender.
    pub seq: u64,
    /// Messages of this sender missed just before this one (refused by this receiver's full
    /// buffer, or sent while it was not connected).
    pub missed: u64,
}

impl Received<()> {
    /// What the header said, with the message decoded from the body.
    fn with<T>(self, msg: T) -> Received<T> {
        Received {
            msg,
            origin: self.origin,
            sender: self.sender,
            seq: self.seq,
            missed: self.missed,
        }
    }
}

/// Counters of a receiver, all senders together.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReceiverStats {
    /// Samples taken from the buffer, decodable or not.
    pub received: u64,
    /// Samples whose body did not decode, or of another wire version or kind.
    pub undecodable: u64,
    /// Sequence numbers skipped by senders: messages this receiver never got.
    pub missing: u64,
    /// Samples whose sequence number went backwards (should never happen).
    pub out_of_order: u64,
    /// Connections to senders iceoryx2 could not make, tried again ([`crate::mending`]).
    pub reconnects: u64,
}

/// What a receiver knows of one sender.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SenderAccount {
    /// The sending port's id.
    pub sender: u64,
    /// Its origin.
    pub origin: Origin,
    /// The last sequence number seen.
    pub last_seq: u64,
    /// Samples taken, decodable or not.
    pub received: u64,
    /// Samples that did not decode.
    pub undecodable: u64,
    /// Sequence numbers skipped.
    pub missing: u64,
}

/// Notifications consumed from a receiver's paired event service.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Wakeups {
    /// Sample notifications (coalesced: one may stand for many samples).
    pub samples: u64,
    /// Senders that joined.
    pub senders_joined: u64,
    /// Senders that left in good order.
    pub senders_left: u64,
    /// Senders whose process died and whose resources were cleaned up: time to check which
    /// programs are alive.
    pub senders_died: u64,
}

impl Wakeups {
    fn add(&mut self, other: Wakeups) {
        self.samples += other.samples;
        self.senders_joined += other.senders_joined;
        self.senders_left += other.senders_left;
        self.senders_died += other.senders_died;
    }
}

/// A sample could not be received or decoded. The receiver carries on with the next one.
#[derive(Debug)]
pub enum RecvError {
    /// The body did not decode.
    Undecodable {
        /// The service.
        service: String,
        /// Who sent it.
        origin: Origin,
        /// The sending port's id.
        sender: u64,
        /// Its sequence number.
        seq: u64,
        /// Messages of this sender missed just before this one (as [`Received::missed`]).
        missed: u64,
        /// Why it did not decode.
        error: WireError,
    },
    /// The header names another wire version or another kind of body.
    Foreign {
        /// The service.
        service: String,
        /// Who sent it.
        origin: Origin,
        /// Its sequence number.
        seq: u64,
        /// The wire version in the header.
        version: u16,
        /// The kind in the header.
        kind: u16,
    },
    /// iceoryx2 failed to receive.
    Transport {
        /// The service.
        service: String,
        /// iceoryx2's reason.
        error: ReceiveError,
    },
    /// Consuming the wake-up notifications failed.
    Wakeup {
        /// The service.
        service: String,
        /// iceoryx2's reason.
        error: ListenerWaitError,
    },
}

impl fmt::Display for RecvError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RecvError::Undecodable {
                service,
                origin,
                seq,
                error,
                ..
            } => write!(
                f,
                "message {seq} from `{origin}` on `{service}` is refused: {error}"
            ),
            RecvError::Foreign {
                service,
                origin,
                seq,
                version,
                kind,
            } => write!(
                f,
                "message {seq} from `{origin}` on `{service}` is refused: wire version {version}, \
                 kind {kind} (expected version {WIRE_VERSION}); build every process of the vehicle \
                 from the same Petrel"
            ),
            RecvError::Transport { service, error } => {
                write!(f, "cannot receive on `{service}`: {error}")
            }
            RecvError::Wakeup { service, error } => {
                write!(f, "cannot consume wake-ups on `{service}`: {error:?}")
            }
        }
    }
}

impl std::error::Error for RecvError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            RecvError::Undecodable { error, .. } => Some(error),
            RecvError::Transport { error, .. } => Some(error),
            _ => None,
        }
    }
}

/// What [`Receiver::drain`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Drained {
    /// Messages handed over.
    pub messages: usize,
    /// Errors handed over.
    pub errors: usize,
    /// Notifications consumed.
    pub wakeups: Wakeups,
}

/// A receiver's accounts of its senders, found by the sender's id.
///
/// A list and the index of the last account used rather than a hash map: a receiver hears
/// from a few senders (128 at most, the events service's slots), the sender of one sample is
/// most often that of the one before, and a look-up is then one comparison instead of a hash.
#[derive(Debug, Default)]
struct Accounts {
    list: Vec<SenderAccount>,
    last: usize,
}

impl Accounts {
    fn position(&self, sender: u64) -> Option<usize> {
        if self.list.get(self.last).is_some_and(|a| a.sender == sender) {
            return Some(self.last);
        }
        self.list.iter().position(|a| a.sender == sender)
    }

    /// The account of `sender`, opened (from `origin`, nothing seen yet) if it has none.
    fn entry(&mut self, sender: u64, origin: Origin) -> &mut SenderAccount {
        let index = match self.position(sender) {
            Some(index) => index,
            None => {
                self.list.push(SenderAccount {
                    sender,
                    origin,
                    last_seq: 0,
                    received: 0,
                    undecodable: 0,
                    missing: 0,
                });
                self.list.len() - 1
            }
        };
        self.last = index;
        &mut self.list[index]
    }

    fn get_mut(&mut self, sender: u64) -> Option<&mut SenderAccount> {
        let index = self.position(sender)?;
        Some(&mut self.list[index])
    }

    fn remove(&mut self, sender: u64) {
        if let Some(index) = self.position(sender) {
            self.list.swap_remove(index);
        }
    }
}

/// The receiving side of one service: takes samples, checks their headers, accounts for every
/// sender's sequence, and decodes bodies.
pub struct Receiver<M: Message> {
    service: String,
    spec: ServiceSpec,
    subscriber: Subscriber<ipc::Service, [u8], MsgHeader>,
    listener: Listener<ipc::Service>,
    factory: publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
    stats: Cell<ReceiverStats>,
    senders: RefCell<Accounts>,
    /// The pieces taken so far of each sender's body in pieces ([`wire::FRAGMENT`]): the
    /// number of messages missed before its first piece, and its bytes.
    pieces: RefCell<HashMap<u64, (u64, Vec<u8>)>>,
    pending_wakeups: Cell<Wakeups>,
    /// Set: [`take_wakeups`](Self::take_wakeups) consumes notifications at most once per this
    /// period (see [`consume_wakeups_every`](Self::consume_wakeups_every)).
    wakeup_period: Cell<Option<Duration>>,
    last_consumed: Cell<Instant>,
    /// Tells this receiver from every other source of a reactor.
    key: crate::reactor::SourceKey,
    /// How this receiver sleeps, for its senders (`None`: it could not be created; senders
    /// notify through iceoryx2).
    doorbell: Option<Doorbell>,
    /// Set once the listener was handed out: someone may wait on it outside a reactor, so
    /// senders must always notify.
    doorbell_off: Cell<bool>,
    /// Bumps the service's change counter once more when dropped, after the subscriber and
    /// the doorbell (fields drop in order): senders forget this receiver.
    _joined: Option<Joined>,
    _kind: PhantomData<fn() -> M>,
    /// Connections to senders that iceoryx2 could not make, to make again.
    mending: Mending,
    /// The process's membership of the vehicle, kept while the port lives.
    _session: Arc<Session>,
}

/// Receives the events of the vehicle (the player).
pub type EventReceiver = Receiver<wire::EventMsg>;
/// Receives the calls of one program (the program).
pub type CallReceiver = Receiver<wire::CallMsg>;
/// Receives marking deltas (monitors).
pub type MarkingSubscriber = Receiver<wire::MarkingMsg>;
/// Receives heartbeats.
pub type HeartbeatSubscriber = Receiver<wire::Heartbeat>;
/// Reads the latest CAN signal values (programs).
pub type SignalsSubscriber = Receiver<wire::SignalsMsg>;
/// The player's receiver of reload requests.
pub type ReloadReceiver = Receiver<wire::ReloadRequest>;
/// Receives the player's reload answers.
pub type ReloadAnswerSubscriber = Receiver<wire::ReloadAnswer>;

impl<M: Message> fmt::Debug for Receiver<M> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Receiver")
            .field("service", &self.service)
            .field("stats", &self.stats.get())
            .finish()
    }
}

impl<M: Message> Receiver<M> {
    pub(crate) fn new(
        service: String,
        spec: ServiceSpec,
        subscriber: Subscriber<ipc::Service, [u8], MsgHeader>,
        listener: Listener<ipc::Service>,
        factory: publish_subscribe::PortFactory<ipc::Service, [u8], MsgHeader>,
        mending: Mending,
        session: Arc<Session>,
    ) -> Self {
        let doorbell = own_node_id(&factory, subscriber.id().value()).and_then(|node| {
            Doorbell::create(session.shm_prefix(), node, subscriber.id().value()).ok()
        });
        // Now that the subscriber is listed and its doorbell made: senders list again.
        let joined = changes(&factory, &session).map(Joined::new);
        Receiver {
            doorbell,
            _joined: joined,
            doorbell_off: Cell::new(false),
            service,
            spec,
            subscriber,
            listener,
            factory,
            stats: Cell::new(ReceiverStats::default()),
            senders: RefCell::new(Accounts::default()),
            pieces: RefCell::new(HashMap::new()),
            pending_wakeups: Cell::new(Wakeups::default()),
            wakeup_period: Cell::new(None),
            last_consumed: Cell::new(Instant::now()),
            key: crate::reactor::SourceKey::new(),
            _kind: PhantomData,
            mending,
            _session: session,
        }
    }

    /// The service this receiver takes from.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The spec the service was opened with.
    pub fn spec(&self) -> &ServiceSpec {
        &self.spec
    }

    /// The listener of the paired event service, to attach to an iceoryx2 `WaitSet` (it is
    /// file-descriptor based). After it wakes a `WaitSet`, call [`take_wakeups`](Self::take_wakeups)
    /// or [`drain`](Self::drain), otherwise the `WaitSet` wakes again at once.
    ///
    /// Its senders then notify it through iceoryx2 at every sample, as without a
    /// doorbell ([`crate::doorbell`]), since nothing tells them when it sleeps.
    pub fn listener(&self) -> &Listener<ipc::Service> {
        if let Some(bell) = &self.doorbell {
            self.doorbell_off.set(true);
            bell.announce(doorbell::EPOLL);
        }
        &self.listener
    }

    /// The listener, for a reactor (which keeps the doorbell told how it sleeps).
    pub(crate) fn listener_fd(&self) -> &Listener<ipc::Service> {
        &self.listener
    }

    /// The doorbell a reactor announces this receiver's sleeps in, if its senders can ring it.
    pub(crate) fn doorbell(&self) -> Option<&Doorbell> {
        if self.doorbell_off.get() {
            return None;
        }
        self.doorbell.as_ref()
    }

    /// Whether senders can wake this receiver through its doorbell (see [`crate::doorbell`]).
    pub fn has_doorbell(&self) -> bool {
        self.doorbell().is_some()
    }

    pub(crate) fn source_key(&self) -> crate::reactor::SourceKey {
        self.key
    }

    /// The counters of this receiver.
    pub fn stats(&self) -> ReceiverStats {
        ReceiverStats {
            reconnects: self.mending.retries(),
            ..self.stats.get()
        }
    }

    /// What this receiver knows of each sender it heard from.
    pub fn senders(&self) -> Vec<SenderAccount> {
        let mut v = self.senders.borrow().list.clone();
        v.sort_by_key(|a| (a.origin.bytes(), a.sender));
        v
    }

    /// The ids of the senders connected to the service now ([`Sender::sender_id`]), in no
    /// particular order. A sender whose process died stays listed until its node is cleaned up.
    pub fn live_senders(&self) -> Vec<u64> {
        let mut ids = Vec::new();
        self.factory.dynamic_config().list_publishers(|p| {
            ids.push(fold_id(p.publisher_id.value()));
            iceoryx2::prelude::CallbackProgression::Continue
        });
        ids
    }

    /// Forgets what this receiver knows of sender `sender` (a sender that left): its account
    /// no longer shows in [`senders`](Self::senders). Should it send again, its sequence
    /// numbers are accounted from scratch.
    pub fn forget_sender(&self, sender: u64) {
        self.senders.borrow_mut().remove(sender);
        self.pieces.borrow_mut().remove(&sender);
    }

    /// True when a sample waits in the buffer (a shared-memory read, no system call).
    pub fn has_pending(&self) -> bool {
        self.mending.before_look(|| self.change_senders());
        // A connection failure still lets the caller try to receive and see the error.
        let pending = self.subscriber.has_samples().unwrap_or(true);
        self.mending.after_look();
        pending
    }

    /// Makes the service's list of senders change, so that this receiver's next look connects
    /// again to the senders iceoryx2 could not connect it to ([`crate::mending`]): a publisher
    /// of its own, made and dropped (no notifier: no one hears of it).
    /// Returns whether the list changed (the publisher could be made).
    fn change_senders(&self) -> bool {
        self.factory
            .publisher_builder()
            .initial_max_slice_len(1)
            .max_loaned_samples(1)
            .create()
            .is_ok()
    }

    /// When this receiver must look again to mend a connection iceoryx2 could not make.
    pub(crate) fn mend_by(&self) -> Option<Instant> {
        self.mending.due()
    }

    /// Consumes the notifications of the paired event service and returns them, with those a
    /// [`Reactor`](crate::reactor::Reactor) already consumed on this receiver's behalf.
    ///
    /// A receiver that has a doorbell and was neither asleep on its listener nor told of news
    /// since its listener was last read skips the read (a system call), unless the last read
    /// is [`DOORBELL_SLICE`](crate::reactor::DOORBELL_SLICE) old: news iceoryx2 gives without
    /// a ring (a dead node it cleaned up by itself) then come at most that late.
    pub fn take_wakeups(&self) -> Result<Wakeups, RecvError> {
        let due = match self.wakeup_period.get() {
            None => match self.doorbell() {
                None => true,
                Some(bell) => {
                    bell.listener_may_hold()
                        || self.last_consumed.get().elapsed() >= crate::reactor::DOORBELL_SLICE
                }
            },
            Some(period) => self.last_consumed.get().elapsed() >= period,
        };
        if due {
            self.consume_notifications()?;
        }
        Ok(self.pending_wakeups.replace(Wakeups::default()))
    }

    /// For a receiver that spins: [`take_wakeups`](Self::take_wakeups) and
    /// [`drain`](Self::drain) consume the notifications (a system call, or two) at most once per
    /// `period` instead of at every call (`None`: at every call, the default).
    ///
    /// A spinning receiver sees its samples in shared memory and needs no notification; they
    /// wait in the listener meanwhile. News of senders (joined, left, died) then comes up to
    /// `period` late. A [`Reactor`](crate::reactor::Reactor) about to sleep still consumes
    /// everything first (the waiting notifications wake it at once), so that nothing is missed.
    pub fn consume_wakeups_every(&self, period: Option<Duration>) {
        self.wakeup_period.set(period);
    }

    pub(crate) fn consume_notifications(&self) -> Result<(), RecvError> {
        if let Some(bell) = self.doorbell() {
            bell.reading_listener();
            self.last_consumed.set(Instant::now());
        } else if self.wakeup_period.get().is_some() {
            self.last_consumed.set(Instant::now());
        }
        let mut fresh = Wakeups::default();
        self.listener
            .try_wait(|activation| match activation.id.as_value() {
                WAKE_SAMPLE => fresh.samples += activation.count,
                WAKE_SENDER_JOINED => fresh.senders_joined += activation.count,
                WAKE_SENDER_LEFT => fresh.senders_left += activation.count,
                WAKE_SENDER_DIED => fresh.senders_died += activation.count,
                _ => {}
            })
            .map_err(|error| RecvError::Wakeup {
                service: self.service.clone(),
                error,
            })?;
        let mut pending = self.pending_wakeups.get();
        pending.add(fresh);
        self.pending_wakeups.set(pending);
        Ok(())
    }

    /// Whether consumed notifications report a sender that joined, left or died, not yet taken
    /// with [`take_wakeups`](Self::take_wakeups).
    pub fn has_sender_news(&self) -> bool {
        let w = self.pending_wakeups.get();
        w.senders_joined + w.senders_left + w.senders_died > 0
    }

    /// Takes the next sample, if any, without waiting and without a system call.
    ///
    /// `Ok(None)` when the buffer is empty. A sample whose body does not decode is taken, counted
    /// and reported as [`RecvError::Undecodable`]; the next call goes on with the next sample.
    pub fn try_recv(&self) -> Result<Option<Received<M>>, RecvError> {
        self.take_with(|taken, body| wire::decode::<M>(body).map(|msg| taken.with(msg)))
    }

    /// Takes the next sample as [`try_recv`](Self::try_recv) does (headers checked, every
    /// sender accounted for, pieces joined) and hands its body, with what its header says, to
    /// `on_body`, whose [`WireError`] makes it an undecodable sample. The receivers that decode
    /// in place ([`Receiver::try_recv_into`], [`Receiver::drain_in_place`]) read the body
    /// where it lies, in the sample.
    fn take_with<T>(
        &self,
        on_body: impl FnOnce(Received<()>, &[u8]) -> Result<T, WireError>,
    ) -> Result<Option<T>, RecvError> {
        self.mending.before_look(|| self.change_senders());
        loop {
            let sample = match self.subscriber.receive() {
                Ok(Some(sample)) => sample,
                Ok(None) => {
                    self.mending.after_look();
                    return Ok(None);
                }
                Err(error) => {
                    return Err(RecvError::Transport {
                        service: self.service.clone(),
                        error,
                    })
                }
            };
            let header = *sample.user_header();
            let origin = Origin::from_bytes(header.origin);
            let missed = self.account(&header, origin);
            if header.version != WIRE_VERSION || header.kind != M::KIND as u16 {
                self.count_undecodable(header.sender);
                return Err(RecvError::Foreign {
                    service: self.service.clone(),
                    origin,
                    seq: header.seq,
                    version: header.version,
                    kind: header.kind,
                });
            }
            let undecodable = |error| {
                self.count_undecodable(header.sender);
                RecvError::Undecodable {
                    service: self.service.clone(),
                    origin,
                    sender: header.sender,
                    seq: header.seq,
                    missed,
                    error,
                }
            };
            let taken = |missed| Received {
                msg: (),
                origin,
                sender: header.sender,
                seq: header.seq,
                missed,
            };
            if header.fragment == 0 {
                self.drop_pieces(header.sender);
                return on_body(taken(missed), sample.payload())
                    .map(Some)
                    .map_err(undecodable);
            }
            let Some(joined) = self.join_piece(&header, missed, sample.payload()) else {
                // More pieces to come (or a piece whose body this receiver cannot have).
                continue;
            };
            let (missed, body) = joined.map_err(&undecodable)?;
            return on_body(taken(missed), &body).map(Some).map_err(undecodable);
        }
    }

    /// Drops what this receiver holds of a body in pieces of `sender`: a whole message came
    /// after them, so that body was given up.
    fn drop_pieces(&self, sender: u64) {
        let mut pieces = self.pieces.borrow_mut();
        if !pieces.is_empty() {
            pieces.remove(&sender);
        }
    }

    /// Takes one piece of a body ([`wire::FRAGMENT`]). Returns the whole body, with the
    /// messages missed before its first piece, once its last piece is there; `None` while
    /// pieces are missing, or for a piece whose first piece this receiver did not get or after
    /// a gap (the body is dropped: its lost pieces are counted missing, and its sender was
    /// told that the piece was refused).
    fn join_piece(
        &self,
        header: &MsgHeader,
        missed: u64,
        payload: &[u8],
    ) -> Option<Result<(u64, Vec<u8>), WireError>> {
        let mut pieces = self.pieces.borrow_mut();
        if header.fragment & wire::FRAGMENT_FIRST != 0 {
            pieces.insert(header.sender, (missed, payload.to_vec()));
        } else {
            match pieces.get_mut(&header.sender) {
                Some((_, bytes)) if missed == 0 => bytes.extend_from_slice(payload),
                _ => {
                    pieces.remove(&header.sender);
                    return None;
                }
            }
        }
        let len = pieces.get(&header.sender).map_or(0, |(_, b)| b.len());
        if len > wire::MAX_BODY_LEN {
            pieces.remove(&header.sender);
            return Some(Err(WireError::TooLarge {
                len,
                max: wire::MAX_BODY_LEN,
            }));
        }
        if header.fragment & wire::FRAGMENT_LAST == 0 {
            return None;
        }
        pieces.remove(&header.sender).map(Ok)
    }

    /// Consumes the wake-ups, then hands every waiting sample to `f`, in order, until the
    /// buffer is empty. Undecodable samples are handed over as errors and draining goes on; a
    /// transport error is handed over and ends this drain.
    pub fn drain(
        &self,
        mut f: impl FnMut(Result<Received<M>, RecvError>),
    ) -> Result<Drained, RecvError> {
        self.drain_by(|| match self.try_recv() {
            Ok(Some(received)) => {
                f(Ok(received));
                Took::Message
            }
            Ok(None) => Took::Empty,
            Err(error) => {
                let took = Took::error(&error);
                f(Err(error));
                took
            }
        })
    }

    /// The loop of a drain: consumes the wake-ups, then calls `take` until the buffer is empty
    /// or a transport error ended it, counting what it handed over.
    fn drain_by(&self, mut take: impl FnMut() -> Took) -> Result<Drained, RecvError> {
        let wakeups = self.take_wakeups()?;
        let mut drained = Drained {
            wakeups,
            ..Drained::default()
        };
        loop {
            match take() {
                Took::Message => drained.messages += 1,
                Took::Empty => break,
                Took::Error => drained.errors += 1,
                Took::Ended => {
                    drained.errors += 1;
                    break;
                }
            }
        }
        Ok(drained)
    }

    fn account(&self, header: &MsgHeader, origin: Origin) -> u64 {
        let mut stats = self.stats.get();
        stats.received += 1;
        let mut senders = self.senders.borrow_mut();
        let account = senders.entry(header.sender, origin);
        account.received += 1;
        let missed = if header.seq > account.last_seq {
            let missed = header.seq - account.last_seq - 1;
            account.last_seq = header.seq;
            missed
        } else {
            stats.out_of_order += 1;
            0
        };
        account.missing += missed;
        stats.missing += missed;
        self.stats.set(stats);
        missed
    }

    fn count_undecodable(&self, sender: u64) {
        let mut stats = self.stats.get();
        stats.undecodable += 1;
        self.stats.set(stats);
        if let Some(account) = self.senders.borrow_mut().get_mut(sender) {
            account.undecodable += 1;
        }
    }
}

/// What one step of a drain handed over.
enum Took {
    /// A message.
    Message,
    /// Nothing: the buffer is empty.
    Empty,
    /// An error; draining goes on.
    Error,
    /// A transport error, which ends the drain.
    Ended,
}

impl Took {
    fn error(error: &RecvError) -> Took {
        if matches!(error, RecvError::Transport { .. }) {
            Took::Ended
        } else {
            Took::Error
        }
    }
}

impl Receiver<wire::CallMsg> {
    /// [`try_recv`](Self::try_recv) without building a [`CallMsg`](wire::CallMsg): the call's
    /// function goes into `function` and its arguments into `args`, reusing their buffers (a
    /// text or a list of floats in the same position of `args` reuses its own; see
    /// [`wire::decode_call_into`]). Returns what the header says (`msg` is `()`).
    ///
    /// Takes, accounts for and refuses exactly the samples `try_recv` does, with the same
    /// errors. `function` and `args` are left as they were by `Ok(None)` and by an error before
    /// the body (a transport error, a foreign sample); after [`RecvError::Undecodable`] they hold
    /// valid values but not a call.
    pub fn try_recv_into(
        &self,
        function: &mut String,
        args: &mut Vec<wire::Value>,
    ) -> Result<Option<Received<()>>, RecvError> {
        self.take_with(|taken, body| wire::decode_call_into(body, function, args).map(|()| taken))
    }
}

impl Receiver<wire::EventMsg> {
    /// [`drain`](Self::drain) without building an [`EventMsg`](wire::EventMsg) per event: `f`
    /// gets each event's name borrowed from its sample (as `msg`) and its parameters in
    /// `params`, where they were decoded (see [`wire::decode_event_in_place`]); it may take
    /// them out (`params.drain(..)`) or leave them, and `params` keeps its capacity from one
    /// event to the next. Errors are handed over as `drain` hands them (with `params` as it
    /// is: not an event's).
    pub fn drain_in_place(
        &self,
        params: &mut Vec<wire::Value>,
        mut f: impl FnMut(Result<Received<&str>, RecvError>, &mut Vec<wire::Value>),
    ) -> Result<Drained, RecvError> {
        self.drain_by(|| {
            let taken = self.take_with(|taken, body| {
                let name = wire::decode_event_in_place(body, params)?;
                f(Ok(taken.with(name)), params);
                Ok(())
            });
            match taken {
                Ok(Some(())) => Took::Message,
                Ok(None) => Took::Empty,
                Err(error) => {
                    let took = Took::error(&error);
                    f(Err(error), params);
                    took
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn origin() -> Origin {
        Origin::from_bytes([0; crate::wire::ORIGIN_LEN])
    }

    #[test]
    fn accounts_are_found_by_sender_whatever_the_order_and_after_a_removal() {
        let mut accounts = Accounts::default();
        for (sender, seq) in [(7, 1), (9, 1), (7, 2), (7, 3), (11, 1), (9, 2)] {
            accounts.entry(sender, origin()).last_seq = seq;
        }
        let seqs = |a: &Accounts| {
            let mut v: Vec<_> = a.list.iter().map(|a| (a.sender, a.last_seq)).collect();
            v.sort();
            v
        };
        assert_eq!(seqs(&accounts), vec![(7, 3), (9, 2), (11, 1)]);
        // Removing the first moves the last into its place: the others stay found.
        accounts.remove(7);
        assert!(accounts.get_mut(7).is_none());
        assert_eq!(accounts.get_mut(11).map(|a| a.last_seq), Some(1));
        assert_eq!(accounts.entry(9, origin()).last_seq, 2);
        // A removed sender that comes back starts afresh.
        assert_eq!(accounts.entry(7, origin()).last_seq, 0);
        assert_eq!(seqs(&accounts), vec![(7, 0), (9, 2), (11, 1)]);
    }
}
