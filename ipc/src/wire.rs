//! The wire format: what travels in the shared-memory samples.
//!
//! Every sample is a byte slice (`publish_subscribe::<[u8]>()`) holding one message body encoded
//! with bincode 2 (standard configuration: little endian, variable-length integers), preceded by
//! a fixed [`MsgHeader`] in iceoryx2's user-header slot. The header says who sent the message
//! ([`Origin`], sender id) and its per-sender sequence number, so a receiver accounts for every
//! message: for each sender, messages sent = received + refused, and a refused message shows as a
//! gap in the sequence.
//!
//! Bodies:
//!
//! | service   | body          | direction                              |
//! |-----------|---------------|----------------------------------------|
//! | events    | [`EventMsg`]  | programs, CAN bridge, tools to player  |
//! | calls     | [`CallMsg`]   | player to one program                  |
//! | marking   | [`MarkingMsg`]| player to monitors                     |
//! | heartbeat | [`Heartbeat`] | anyone to anyone who listens; the player's carries its acknowledgements ([`Ack`]) |
//! | signals   | [`SignalsMsg`]| CAN bridge to programs (latest values) |
//! | reload    | [`ReloadRequest`] | `petrel reload` to player          |
//! | reload/answer | [`ReloadAnswer`] | player to `petrel reload` and shadows |
//!
//! Events travel by **name**: programs do not know the player's event indices.
//!
//! **Acknowledgements.** A sender's shared memory goes with its process, so a sender waits for
//! the player to say it has taken its events before it leaves. The player says so in its
//! heartbeat, typed ([`Heartbeat::acks`], one [`Ack`] per sender: the last sequence number
//! taken, the last one settled on the flight record, the counts of what was taken, refused and
//! not recorded, the latest refusals with the player's reasons) and bounded ([`MAX_ACKS`]
//! senders, the most recently active first; [`MAX_REFUSALS`] refusals of at most
//! [`MAX_REASON_LEN`] bytes each), beside the flight recorder's state ([`Recorder`]). The JSON
//! `status` is for people and tools only; nothing parses an acknowledgement out of it.
//!
//! Encoding never builds an intermediate buffer: [`encoded_len`] measures the body (bincode's
//! size writer), the sender loans a slice of exactly that length and [`encode_into`] writes it
//! in place. [`decode`] reads a body from the received slice; a body that does not decode is a
//! [`WireError`], never a panic, and decoding never allocates more than [`MAX_BODY_LEN`] bytes
//! whatever the lengths a corrupt body claims. The two bodies of every round trip also decode
//! in place ([`in_place`]): [`decode_event_in_place`] lends an event's name from the received
//! bytes and writes its parameters into the caller's vector, [`decode_call_into`] writes a call
//! into the caller's buffers; they accept and refuse exactly what [`decode`] does.

use std::fmt;

use bincode::config::{Configuration, Limit, LittleEndian, Varint};
use bincode::enc::write::SizeWriter;
use bincode::enc::EncoderImpl;
use bincode::{Decode, Encode};
use iceoryx2::prelude::ZeroCopySend;

pub mod in_place;
pub use in_place::{decode_call_into, decode_event_in_place};

/// Version of the wire format. It is written in every header, and it is part of the header's
/// iceoryx2 type name, so a process built with another wire version cannot even open the
/// services. Version 2: the heartbeat carries typed acknowledgements and the recorder's state.
/// Version 3: a marking delta carries its step's mission time, the event's parameters and the
/// step's actions as text, so that a monitor shows the whole step. Version 4: a body longer
/// than its sender's fixed samples travels in fragments ([`MsgHeader::fragment`]). Version 5: a
/// program says it leaves in good order ([`LEAVE`] on the events service).
pub const WIRE_VERSION: u16 = 5;

/// The name of the one message on the events service that is not an event: a program says
/// that it leaves the vehicle in good order (`Program::close`, a `Program` dropped, the CAN
/// data server's commands program at its stop), before its node goes. The player then
/// records a stop, not a loss (`program_lost` stays for programs that die). It goes with no
/// parameters, from the program's own sender (origin `program/NAME`: that is the program it
/// speaks for), numbered and acknowledged like an event, and crosses computers like one.
/// No event of a project has this name: it is not an identifier.
pub const LEAVE: &str = "petrel:leave";

/// [`MsgHeader::fragment`]: this sample carries a piece of a body longer than its sender's
/// samples; the receiver joins the pieces of one sender, in sequence, into the body.
pub const FRAGMENT: u32 = 1;
/// [`MsgHeader::fragment`]: the first piece of a body (with [`FRAGMENT`]).
pub const FRAGMENT_FIRST: u32 = 2;
/// [`MsgHeader::fragment`]: the last piece of a body (with [`FRAGMENT`]): the body is whole.
pub const FRAGMENT_LAST: u32 = 4;

/// Most senders one heartbeat acknowledges (the most recently active first). The events
/// service takes 32 senders at once; the rest is room for senders that just left.
pub const MAX_ACKS: usize = 64;

/// Most refusals one [`Ack`] lists (the latest).
pub const MAX_REFUSALS: usize = 2;

/// Longest reason (of a refusal, of the recorder's state) a heartbeat carries, in bytes; a
/// longer one is cut on a character boundary.
pub const MAX_REASON_LEN: usize = 160;

/// Length of the origin field of a header, in bytes.
pub const ORIGIN_LEN: usize = 32;

/// The largest body any service carries (marking snapshots); decoding refuses to read more.
pub const MAX_BODY_LEN: usize = 1 << 20;

type WireConfig = Configuration<LittleEndian, Varint, Limit<MAX_BODY_LEN>>;

const CONFIG: WireConfig = bincode::config::standard()
    .with_little_endian()
    .with_variable_int_encoding()
    .with_limit::<MAX_BODY_LEN>();

/// A parameter of an event or an argument of a call: the one value type of Petrel, encoded
/// with bincode on the wire.
pub use petrel_value::Value;

/// An event for the player, by name, with its parameters in declaration order.
#[derive(Debug, Clone, PartialEq, Encode, Decode)]
pub struct EventMsg {
    /// The event's name as the manifest declares it.
    pub name: String,
    /// The parameters, by position.
    pub params: Vec<Value>,
}

impl EventMsg {
    /// An event with its parameters.
    pub fn new(name: impl Into<String>, params: Vec<Value>) -> Self {
        EventMsg {
            name: name.into(),
            params,
        }
    }

    /// The message by which a program says it leaves in good order ([`LEAVE`]).
    pub fn leave() -> Self {
        EventMsg::new(LEAVE, Vec::new())
    }

    /// Whether this is a program's [`LEAVE`] rather than an event.
    pub fn is_leave(&self) -> bool {
        self.name == LEAVE
    }
}

/// A call from the player to one program: a function and its arguments. The program answers,
/// if it has to, with events.
#[derive(Debug, Clone, PartialEq, Encode, Decode)]
pub struct CallMsg {
    /// The function's name as the manifest declares it.
    pub function: String,
    /// The arguments, by position.
    pub args: Vec<Value>,
}

impl CallMsg {
    /// A call with its arguments.
    pub fn new(function: impl Into<String>, args: Vec<Value>) -> Self {
        CallMsg {
            function: function.into(),
            args,
        }
    }
}

/// A [`CallMsg`] borrowed: the function's name and the arguments as they are, each encoded as
/// the [`Value`] it stands for (the player's arguments are borrowed from the net and the
/// event). Its bytes are [`CallMsg`]'s (bincode writes a `&str` as a `String` and a sequence
/// as its length then its items, as it writes a `Vec`), so that the player sends a call
/// without building one: no copy of the name nor of the arguments. A test decodes it.
#[derive(Debug, Clone, Copy)]
pub struct CallRef<'a, A> {
    /// The function's name as the manifest declares it.
    pub function: &'a str,
    /// The arguments, by position: each item encodes as a [`Value`] does.
    pub args: A,
}

impl<A> Encode for CallRef<'_, A>
where
    A: Clone + ExactSizeIterator,
    A::Item: Encode,
{
    fn encode<E: bincode::enc::Encoder>(
        &self,
        encoder: &mut E,
    ) -> Result<(), bincode::error::EncodeError> {
        self.function.encode(encoder)?;
        (self.args.len() as u64).encode(encoder)?;
        for arg in self.args.clone() {
            arg.encode(encoder)?;
        }
        Ok(())
    }
}

/// What one step of the player changed in the marking, for monitors. Names are text
/// (`NET.transition`, `NET.place`, global places by their own name) so that a monitor needs
/// nothing but the project to follow along.
#[derive(Debug, Clone, PartialEq, Default, Encode, Decode)]
pub struct MarkingMsg {
    /// The player's step number (one per processed event, 0 for the initial state).
    pub step: u64,
    /// The event processed in this step, if any.
    pub event: Option<String>,
    /// Transitions fired, in firing order, as `NET.transition`.
    pub fired: Vec<String>,
    /// Places that received a token.
    pub marked: Vec<String>,
    /// Places that lost their token.
    pub unmarked: Vec<String>,
    /// Nets activated in this step.
    pub activated: Vec<String>,
    /// Nets deactivated in this step.
    pub deactivated: Vec<String>,
    /// True when `marked` and `activated` list the whole state rather than a change (sent at
    /// start, and whenever a monitor may have lost track).
    pub snapshot: bool,
    /// Mission time of the step, microseconds.
    pub time_us: u64,
    /// The parameters of the event processed, in declaration order.
    pub params: Vec<Value>,
    /// Every action and notice of the step as text (`call GUI.climb(300.0)`, `start
    /// dec_answer (expires at 12.5)`), as the journal records them.
    pub actions: Vec<String>,
}

/// A sign of life, with what the sender promises and what it has done.
#[derive(Debug, Clone, PartialEq, Default, Encode, Decode)]
pub struct Heartbeat {
    /// Milliseconds since the sender started.
    pub uptime_ms: u64,
    /// The period the sender promises between two heartbeats, in milliseconds; a listener may
    /// declare the sender stale after a few periods of silence.
    pub period_ms: u32,
    /// A counter of work done (events processed, frames read...), to tell a stuck process from
    /// an idle one.
    pub progress: u64,
    /// The sender's live status as JSON, for people and tools (`petrel status`).
    pub status: String,
    /// The player's acknowledgement of each sender of events (empty in other heartbeats): at
    /// most [`MAX_ACKS`], the most recently active first.
    pub acks: Vec<Ack>,
    /// The state of the player's flight recorder ([`RecorderState::None`] in other heartbeats).
    pub recorder: Recorder,
}

impl Heartbeat {
    /// The acknowledgement of sender `sender` ([`Sender::sender_id`](crate::Sender::sender_id)).
    pub fn ack_for(&self, sender: u64) -> Option<&Ack> {
        self.acks.iter().find(|a| a.sender == sender)
    }

    /// Cuts what the heartbeat carries to its bounds ([`MAX_ACKS`], [`MAX_REFUSALS`],
    /// [`MAX_REASON_LEN`], [`ORIGIN_LEN`]), so that its encoded length never exceeds
    /// [`Heartbeat::max_encoded_len`] of its status's length.
    pub fn bound(&mut self) {
        self.acks.truncate(MAX_ACKS);
        for a in &mut self.acks {
            cut_text(&mut a.origin, ORIGIN_LEN);
            let extra = a.refusals.len().saturating_sub(MAX_REFUSALS);
            a.refusals.drain(..extra);
            for r in &mut a.refusals {
                cut_text(&mut r.reason, MAX_REASON_LEN);
            }
        }
        cut_text(&mut self.recorder.reason, MAX_REASON_LEN);
    }

    /// The largest encoded length of a bounded heartbeat (see [`Heartbeat::bound`]) whose status
    /// is `status_len` bytes long: what a publisher must be able to send.
    pub fn max_encoded_len(status_len: usize) -> usize {
        // bincode writes a string as its length and its bytes: only the length matters.
        let text = |n: usize| "x".repeat(n);
        let worst = Heartbeat {
            uptime_ms: u64::MAX,
            period_ms: u32::MAX,
            progress: u64::MAX,
            status: String::new(),
            acks: vec![
                Ack {
                    sender: u64::MAX,
                    origin: text(ORIGIN_LEN),
                    last_seq: u64::MAX,
                    settled_seq: u64::MAX,
                    received: u64::MAX,
                    taken: u64::MAX,
                    refused: u64::MAX,
                    pending: u64::MAX,
                    unrecorded: u64::MAX,
                    missing: u64::MAX,
                    refusals: vec![
                        AckRefusal {
                            seq: u64::MAX,
                            reason: text(MAX_REASON_LEN),
                        };
                        MAX_REFUSALS
                    ],
                };
                MAX_ACKS
            ],
            recorder: Recorder {
                state: RecorderState::Failing,
                reason: text(MAX_REASON_LEN),
            },
        };
        // The status's length prefix is a varint of at most 9 bytes.
        encoded_len(&worst).unwrap_or(MAX_BODY_LEN) + status_len + 9
    }
}

/// Cuts `text` to at most `max` bytes, on a character boundary.
pub fn cut_text(text: &mut String, max: usize) {
    if text.len() > max {
        let mut end = max;
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        text.truncate(end);
    }
}

/// The player's account of the events of one sender: what it took, refused and recorded.
///
/// For a sender, every message it delivered is, once the player has read it, either taken
/// (queued in the engine) or refused (with a reason); a taken event is then settled on the
/// flight record, or pending (not yet written: the recorder is failing), or unrecorded (the
/// recorder had to drop it). An event is safe, surviving a crash of the player, once it is
/// settled and was not unrecorded.
#[derive(Debug, Clone, PartialEq, Eq, Default, Encode, Decode)]
pub struct Ack {
    /// The sending port's id ([`MsgHeader::sender`]).
    pub sender: u64,
    /// Its origin (at most [`ORIGIN_LEN`] bytes).
    pub origin: String,
    /// The newest sequence number the player took (taken or refused).
    pub last_seq: u64,
    /// Every message up to this sequence number is settled: refused, or taken and on the flight
    /// record (flushed to the operating system), or counted in `unrecorded`. Without a journal
    /// taking is settling.
    pub settled_seq: u64,
    /// Messages taken from the events buffer (taken + refused).
    pub received: u64,
    /// Events accepted into the engine's queue.
    pub taken: u64,
    /// Messages refused before the engine (unknown event, parameters, undecodable, after a
    /// catastrophic event).
    pub refused: u64,
    /// Taken events not yet on the flight record (the recorder is failing and retries).
    pub pending: u64,
    /// Taken events the flight recorder could not keep: processed, but lost from the record.
    pub unrecorded: u64,
    /// Sequence numbers the player never received (refused by the transport: its buffer was
    /// full).
    pub missing: u64,
    /// The latest refusals (at most [`MAX_REFUSALS`]), oldest first.
    pub refusals: Vec<AckRefusal>,
}

impl Ack {
    /// True when every message up to `seq` is settled (see [`Ack::settled_seq`]).
    pub fn settles(&self, seq: u64) -> bool {
        self.settled_seq >= seq
    }
}

/// One message the player refused, and why (its refusal text).
#[derive(Debug, Clone, PartialEq, Eq, Default, Encode, Decode)]
pub struct AckRefusal {
    /// The message's sequence number.
    pub seq: u64,
    /// The player's reason, at most [`MAX_REASON_LEN`] bytes.
    pub reason: String,
}

/// The state of the player's flight recorder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Encode, Decode)]
pub enum RecorderState {
    /// Not a player's heartbeat, or a player without a journal (`--no-journal`).
    #[default]
    None,
    /// Every record written.
    Ok,
    /// Records cannot be written (a full disk...): they are kept in memory, not acknowledged,
    /// and written once the recorder can again.
    Failing,
    /// The recorder could not keep what it could not write: records are dropped (unrecorded)
    /// until it can write again, when it starts over from a checkpoint of the state.
    Dropping,
}

impl RecorderState {
    /// The state as a word (`none`, `ok`, `failing`, `dropping`), as `petrel status` shows it.
    pub fn as_str(self) -> &'static str {
        match self {
            RecorderState::None => "none",
            RecorderState::Ok => "ok",
            RecorderState::Failing => "failing",
            RecorderState::Dropping => "dropping",
        }
    }
}

/// The flight recorder's state, and why it fails (empty when it does not).
#[derive(Debug, Clone, PartialEq, Eq, Default, Encode, Decode)]
pub struct Recorder {
    /// The state.
    pub state: RecorderState,
    /// The last error, at most [`MAX_REASON_LEN`] bytes.
    pub reason: String,
}

/// The latest decoded values of the vehicle's CAN signals (`MESSAGE.signal`), published by the
/// CAN data server after each batch of frames for the programs that read them.
#[derive(Debug, Clone, PartialEq, Default, Encode, Decode)]
pub struct SignalsMsg {
    /// When the newest of these values was received, microseconds on the bridge's clock.
    pub time_us: u64,
    /// `(MESSAGE.signal, physical value, microseconds when received)` for every signal seen.
    pub values: Vec<(String, f64, u64)>,
}

impl SignalsMsg {
    /// The latest value of `path` (`MESSAGE.signal`), if it was seen.
    pub fn get(&self, path: &str) -> Option<f64> {
        self.values
            .iter()
            .find(|(p, _, _)| p == path)
            .map(|(_, v, _)| *v)
    }
}

/// A request to reload the player's project (`petrel reload`): the new version is named by its
/// directory and the content hash of its files, which the player reads and hashes itself (it
/// runs on the same computer): a project may be larger than a message carries.
#[derive(Debug, Clone, PartialEq, Default, Encode, Decode)]
pub struct ReloadRequest {
    /// The new version's project directory, absolute.
    pub dir: String,
    /// The content hash of its files as the requester read them (16 hex digits).
    pub source_hash: String,
    /// The mapping file's text (empty: no mapping file).
    pub mapping: String,
    /// Say what would happen, swap nothing.
    pub dry_run: bool,
}

/// The player's answer to a [`ReloadRequest`], to every listener (the requester finds its own
/// by its sender id and sequence number; a shadow follows accepted reloads).
#[derive(Debug, Clone, PartialEq, Default, Encode, Decode)]
pub struct ReloadAnswer {
    /// The requesting port's sender id.
    pub request_sender: u64,
    /// The request's sequence number.
    pub request_seq: u64,
    /// The reload is (or, for a dry run, would be) accepted.
    pub accepted: bool,
    /// It was a dry run: nothing was swapped.
    pub dry_run: bool,
    /// The new version's directory and content hash, as requested.
    pub dir: String,
    /// The content hash.
    pub source_hash: String,
    /// The player's step number after which the new version runs (accepted, not a dry run).
    pub step: u64,
    /// What the mapping did, one line each.
    pub summary: Vec<String>,
    /// Why it is refused, one line each (the mapping's reasons, or the verification's finding).
    pub reasons: Vec<String>,
    /// The shortest sequence of events from the mapped state to the finding, if any.
    pub trace: Vec<String>,
    /// Stable states the verification explored from the mapped state.
    pub states: u64,
    /// Milliseconds from the request to the answer.
    pub millis: u64,
}

impl ReloadAnswer {
    /// Cuts the answer to fit the service ([`MAX_BODY_LEN`]): long lists lose their tail.
    pub fn bound(&mut self) {
        for list in [&mut self.summary, &mut self.reasons, &mut self.trace] {
            list.truncate(1000);
            for line in list.iter_mut() {
                cut_text(line, 512);
            }
        }
    }
}

/// The kinds of message bodies, as written in the header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u16)]
pub enum MsgKind {
    /// [`EventMsg`].
    Event = 1,
    /// [`CallMsg`].
    Call = 2,
    /// [`MarkingMsg`].
    Marking = 3,
    /// [`Heartbeat`].
    Heartbeat = 4,
    /// [`SignalsMsg`].
    Signals = 5,
    /// [`ReloadRequest`].
    ReloadRequest = 6,
    /// [`ReloadAnswer`].
    ReloadAnswer = 7,
}

impl MsgKind {
    /// The kind written as `value` in a header, if any.
    pub fn from_u16(value: u16) -> Option<Self> {
        match value {
            1 => Some(MsgKind::Event),
            2 => Some(MsgKind::Call),
            3 => Some(MsgKind::Marking),
            4 => Some(MsgKind::Heartbeat),
            5 => Some(MsgKind::Signals),
            6 => Some(MsgKind::ReloadRequest),
            7 => Some(MsgKind::ReloadAnswer),
            _ => None,
        }
    }
}

impl fmt::Display for MsgKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            MsgKind::Event => "event",
            MsgKind::Call => "call",
            MsgKind::Marking => "marking",
            MsgKind::Heartbeat => "heartbeat",
            MsgKind::Signals => "signals",
            MsgKind::ReloadRequest => "reload request",
            MsgKind::ReloadAnswer => "reload answer",
        })
    }
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for super::EventMsg {}
    impl Sealed for super::CallMsg {}
    impl Sealed for super::MarkingMsg {}
    impl Sealed for super::Heartbeat {}
    impl Sealed for super::SignalsMsg {}
    impl Sealed for super::ReloadRequest {}
    impl Sealed for super::ReloadAnswer {}

    pub trait SealedBody {}
    impl<M: super::Message> SealedBody for M {}
    impl<A> SealedBody for super::CallRef<'_, A> {}
}

/// What a [`Sender`](crate::Sender) of [`Msg`](Self::Msg) can send: the message itself, or
/// a borrowed body whose bytes are the message's ([`CallRef`] for [`CallMsg`]). Sealed, like
/// [`Message`].
pub trait Body: Encode + sealed::SealedBody {
    /// The message the body's bytes are.
    type Msg: Message;
}

impl<M: Message> Body for M {
    type Msg = M;
}
impl<A> Body for CallRef<'_, A>
where
    A: Clone + ExactSizeIterator,
    A::Item: Encode,
{
    type Msg = CallMsg;
}

/// A message body of this crate. Sealed: only the four bodies above travel on Petrel's
/// services, so that every process agrees on what each service carries.
pub trait Message: Encode + Decode<()> + fmt::Debug + sealed::Sealed {
    /// The kind written in the header.
    const KIND: MsgKind;
}

impl Message for EventMsg {
    const KIND: MsgKind = MsgKind::Event;
}
impl Message for CallMsg {
    const KIND: MsgKind = MsgKind::Call;
}
impl Message for MarkingMsg {
    const KIND: MsgKind = MsgKind::Marking;
}
impl Message for Heartbeat {
    const KIND: MsgKind = MsgKind::Heartbeat;
}
impl Message for SignalsMsg {
    const KIND: MsgKind = MsgKind::Signals;
}
impl Message for ReloadRequest {
    const KIND: MsgKind = MsgKind::ReloadRequest;
}
impl Message for ReloadAnswer {
    const KIND: MsgKind = MsgKind::ReloadAnswer;
}

/// The fixed header of every sample, in iceoryx2's user-header slot.
///
/// `#[repr(C)]` and [`ZeroCopySend`] with an explicit type name, so that its identity does not
/// depend on the module path and changes with [`WIRE_VERSION`].
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("petrel::MsgHeader/v5")]
pub struct MsgHeader {
    /// The sending port's id, unique among the vehicle's live ports.
    pub sender: u64,
    /// Per-sender sequence number: 1 for the sender's first message, then one more for every
    /// message it offered to the transport, delivered or not.
    pub seq: u64,
    /// [`WIRE_VERSION`] of the sender.
    pub version: u16,
    /// [`MsgKind`] of the body, as a number.
    pub kind: u16,
    /// Zero for a whole body; for a piece of a longer one, [`FRAGMENT`] with [`FRAGMENT_FIRST`]
    /// or [`FRAGMENT_LAST`] as the case may be (a piece numbered like any message: a body in
    /// `n` pieces takes `n` sequence numbers, the last one its own).
    pub fragment: u32,
    /// The sender's role (its node name, such as `program/PLN`), NUL-padded UTF-8.
    pub origin: [u8; ORIGIN_LEN],
}

/// The role of a message's sender (`player`, `program/PLN`, `can_bridge`, `tool/NAME`).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Origin([u8; ORIGIN_LEN]);

impl Origin {
    /// The origin for `name`, cut at [`ORIGIN_LEN`] bytes (on a character boundary).
    pub fn new(name: &str) -> Self {
        let mut bytes = [0u8; ORIGIN_LEN];
        let mut end = name.len().min(ORIGIN_LEN);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        bytes[..end].copy_from_slice(&name.as_bytes()[..end]);
        Origin(bytes)
    }

    /// The origin as found in a header.
    pub fn from_bytes(bytes: [u8; ORIGIN_LEN]) -> Self {
        Origin(bytes)
    }

    /// The raw bytes, NUL-padded.
    pub fn bytes(&self) -> [u8; ORIGIN_LEN] {
        self.0
    }

    /// The origin as text; the valid UTF-8 prefix if a foreign sender wrote anything else.
    pub fn as_str(&self) -> &str {
        let end = self.0.iter().position(|b| *b == 0).unwrap_or(ORIGIN_LEN);
        match std::str::from_utf8(&self.0[..end]) {
            Ok(s) => s,
            Err(e) => std::str::from_utf8(&self.0[..e.valid_up_to()]).unwrap_or_default(),
        }
    }
}

impl fmt::Debug for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Origin({:?})", self.as_str())
    }
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A body could not be encoded or decoded.
#[derive(Debug)]
pub enum WireError {
    /// bincode refused to encode the body.
    Encode(bincode::error::EncodeError),
    /// The bytes are not a valid body of the expected kind.
    Decode(bincode::error::DecodeError),
    /// A body decoded from the start of the slice but bytes were left over.
    TrailingBytes {
        /// Bytes the body used.
        used: usize,
        /// Bytes in the slice.
        len: usize,
    },
    /// The body is larger than the service carries.
    TooLarge {
        /// The body's length in bytes.
        len: usize,
        /// The largest body accepted.
        max: usize,
    },
    /// The encoder wrote another length than it measured (a bug in a body's encoding).
    LengthMismatch {
        /// Length measured first.
        measured: usize,
        /// Length written.
        written: usize,
    },
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WireError::Encode(e) => write!(f, "cannot encode the message: {e}"),
            WireError::Decode(e) => write!(f, "the body does not decode: {e}"),
            WireError::TrailingBytes { used, len } => write!(
                f,
                "the body holds {len} bytes but the message used only {used}; sender and receiver disagree on the format"
            ),
            WireError::TooLarge { len, max } => write!(
                f,
                "the encoded message is {len} bytes, more than the {max} bytes this service carries; send less data per message"
            ),
            WireError::LengthMismatch { measured, written } => write!(
                f,
                "encoding measured {measured} bytes but wrote {written}: this is a bug in petrel-ipc"
            ),
        }
    }
}

impl std::error::Error for WireError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            WireError::Encode(e) => Some(e),
            WireError::Decode(e) => Some(e),
            _ => None,
        }
    }
}

/// The exact number of bytes [`encode_into`] will write for `msg`, measured without allocating.
pub fn encoded_len<B: Body + ?Sized>(msg: &B) -> Result<usize, WireError> {
    let mut encoder = EncoderImpl::new(SizeWriter::default(), CONFIG);
    msg.encode(&mut encoder).map_err(WireError::Encode)?;
    Ok(encoder.into_writer().bytes_written)
}

/// Encodes `msg` at the start of `dst` and returns the number of bytes written.
pub fn encode_into<B: Body + ?Sized>(msg: &B, dst: &mut [u8]) -> Result<usize, WireError> {
    bincode::encode_into_slice(msg, dst, CONFIG).map_err(WireError::Encode)
}

/// Decodes a whole body: every byte of `bytes` must belong to the message.
pub fn decode<M: Message>(bytes: &[u8]) -> Result<M, WireError> {
    if bytes.len() > MAX_BODY_LEN {
        return Err(WireError::TooLarge {
            len: bytes.len(),
            max: MAX_BODY_LEN,
        });
    }
    let (msg, used) =
        bincode::decode_from_slice::<M, _>(bytes, CONFIG).map_err(WireError::Decode)?;
    if used != bytes.len() {
        return Err(WireError::TrailingBytes {
            used,
            len: bytes.len(),
        });
    }
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn every_value() -> Vec<Value> {
        vec![
            Value::Int(-42),
            Value::Int(i64::MAX),
            Value::Float(3.25),
            Value::Float(f64::NEG_INFINITY),
            Value::Bool(true),
            Value::Text("héllo".into()),
            Value::Text(String::new()),
            Value::FloatList(vec![1.0, -2.5, 1e300]),
            Value::FloatList(vec![]),
        ]
    }

    fn round_trip<M: Message + PartialEq + Clone>(msg: M) {
        let len = encoded_len(&msg).unwrap();
        let mut buf = vec![0u8; len];
        assert_eq!(encode_into(&msg, &mut buf).unwrap(), len);
        let back: M = decode(&buf).unwrap();
        assert_eq!(back, msg);
    }

    #[test]
    fn a_borrowed_call_is_the_call_s_bytes_and_decodes_to_it() {
        for args in [
            every_value(),
            vec![],
            vec![Value::FloatList(vec![0.5; 300])],
        ] {
            let call = CallMsg::new("climb_to", args.clone());
            let borrowed = CallRef {
                function: "climb_to",
                args: args.iter(),
            };
            let len = encoded_len(&borrowed).unwrap();
            assert_eq!(len, encoded_len(&call).unwrap());
            let (mut a, mut b) = (vec![0u8; len], vec![0u8; len]);
            assert_eq!(encode_into(&borrowed, &mut a).unwrap(), len);
            encode_into(&call, &mut b).unwrap();
            assert_eq!(a, b);
            assert_eq!(decode::<CallMsg>(&a).unwrap(), call);
        }
    }

    #[test]
    fn bodies_round_trip() {
        round_trip(EventMsg::new("waypoint", every_value()));
        round_trip(CallMsg::new("climb", vec![Value::Int(300)]));
        round_trip(MarkingMsg {
            step: 7,
            event: Some("go".into()),
            fired: vec!["mission.t1".into()],
            marked: vec!["mission.p2".into()],
            unmarked: vec!["mission.p1".into()],
            activated: vec![],
            deactivated: vec!["nav".into()],
            snapshot: false,
            time_us: 12_500_000,
            params: every_value(),
            actions: vec!["call GUI.climb(300.0)".into()],
        });
        round_trip(Heartbeat {
            uptime_ms: 1,
            period_ms: 100,
            progress: 3,
            status: "running".into(),
            acks: vec![Ack {
                sender: 9,
                origin: "tool/send1".into(),
                last_seq: 4,
                settled_seq: 3,
                received: 4,
                taken: 3,
                refused: 1,
                pending: 1,
                unrecorded: 0,
                missing: 0,
                refusals: vec![AckRefusal {
                    seq: 2,
                    reason: "unknown event `x`".into(),
                }],
            }],
            recorder: Recorder {
                state: RecorderState::Failing,
                reason: "No space left on device".into(),
            },
        });
        let signals = SignalsMsg {
            time_us: 7,
            values: vec![
                ("Depth.depth".into(), 30.25, 7),
                ("Leak.leak".into(), 0.0, 5),
            ],
        };
        assert_eq!(signals.get("Depth.depth"), Some(30.25));
        assert_eq!(signals.get("Depth.nope"), None);
        round_trip(signals);
    }

    #[test]
    fn nan_survives() {
        let msg = EventMsg::new("x", vec![Value::Float(f64::NAN)]);
        let len = encoded_len(&msg).unwrap();
        let mut buf = vec![0u8; len];
        encode_into(&msg, &mut buf).unwrap();
        let back: EventMsg = decode(&buf).unwrap();
        assert!(matches!(back.params[0], Value::Float(f) if f.is_nan()));
    }

    #[test]
    fn short_destination_is_an_error() {
        let msg = EventMsg::new("waypoint", every_value());
        let mut buf = vec![0u8; 3];
        assert!(matches!(
            encode_into(&msg, &mut buf),
            Err(WireError::Encode(_))
        ));
    }

    #[test]
    fn trailing_bytes_are_refused() {
        let msg = EventMsg::new("go", vec![]);
        let len = encoded_len(&msg).unwrap();
        let mut buf = vec![0u8; len + 2];
        encode_into(&msg, &mut buf).unwrap();
        assert!(matches!(
            decode::<EventMsg>(&buf),
            Err(WireError::TrailingBytes { used, len: l }) if used == len && l == len + 2
        ));
    }

    #[test]
    fn huge_claimed_lengths_are_refused_without_allocating() {
        // name length claims u64::MAX bytes.
        let bytes = [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x01];
        let mut varint = vec![253u8];
        varint.extend_from_slice(&u64::MAX.to_le_bytes());
        assert!(decode::<EventMsg>(&varint).is_err());
        assert!(decode::<EventMsg>(&bytes).is_err());
    }

    #[test]
    fn garbage_never_panics() {
        // xorshift: deterministic pseudo-random bodies, and mutations of a valid one.
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let valid = {
            let msg = EventMsg::new("waypoint", every_value());
            let mut buf = vec![0u8; encoded_len(&msg).unwrap()];
            encode_into(&msg, &mut buf).unwrap();
            buf
        };
        for i in 0..20_000 {
            let bytes: Vec<u8> = if i % 2 == 0 {
                let len = (next() % 64) as usize;
                (0..len).map(|_| next() as u8).collect()
            } else {
                let mut b = valid.clone();
                let at = (next() as usize) % b.len();
                b[at] = next() as u8;
                b.truncate(b.len() - (next() as usize % 3).min(b.len()));
                b
            };
            let _ = decode::<EventMsg>(&bytes);
            let _ = decode::<CallMsg>(&bytes);
            let _ = decode::<MarkingMsg>(&bytes);
            let _ = decode::<Heartbeat>(&bytes);
        }
    }

    #[test]
    fn origin_text() {
        assert_eq!(Origin::new("program/PLN").as_str(), "program/PLN");
        let long = "é".repeat(40);
        let o = Origin::new(&long);
        assert_eq!(o.as_str().len(), 32);
        let mut raw = [0u8; ORIGIN_LEN];
        raw[0] = b'a';
        raw[1] = 0xFF;
        assert_eq!(Origin::from_bytes(raw).as_str(), "a");
    }

    #[test]
    fn a_bounded_heartbeat_never_exceeds_its_maximum() {
        let long = "é".repeat(500);
        let mut hb = Heartbeat {
            status: "s".repeat(300),
            acks: (0..200)
                .map(|i| Ack {
                    sender: u64::MAX - i,
                    origin: long.clone(),
                    last_seq: u64::MAX,
                    settled_seq: u64::MAX,
                    refusals: (0..10)
                        .map(|_| AckRefusal {
                            seq: u64::MAX,
                            reason: long.clone(),
                        })
                        .collect(),
                    ..Ack::default()
                })
                .collect(),
            recorder: Recorder {
                state: RecorderState::Dropping,
                reason: long.clone(),
            },
            ..Heartbeat::default()
        };
        hb.bound();
        assert_eq!(hb.acks.len(), MAX_ACKS);
        assert!(hb.acks.iter().all(|a| a.refusals.len() == MAX_REFUSALS));
        let len = encoded_len(&hb).unwrap();
        assert!(len <= Heartbeat::max_encoded_len(300), "{len}");
        let back: Heartbeat = {
            let mut buf = vec![0u8; len];
            encode_into(&hb, &mut buf).unwrap();
            decode(&buf).unwrap()
        };
        assert_eq!(back.ack_for(u64::MAX).map(|a| a.origin.len()), Some(32));
    }

    #[test]
    fn header_layout_is_stable() {
        assert_eq!(std::mem::size_of::<MsgHeader>(), 56);
        assert_eq!(std::mem::align_of::<MsgHeader>(), 8);
    }
}
