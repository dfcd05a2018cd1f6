//! What crosses the link: one zenoh key per computer and vehicle, one message type.
//!
//! Every message a gateway puts on the link goes on `petrel/<vehicle>/link/<computer>` (its
//! own computer), numbered by a per-process sequence, so that a receiver sees each peer's
//! messages in order, tells a gap (a message lost) from a restart (a new incarnation), and
//! recognises its own messages coming back (zenoh delivers a session's puts to its own matching
//! subscribers): nothing crosses twice.
//!
//! Events and calls are also *carried* ([`Carried`]): numbered again on a stream from this
//! gateway to the one destination gateway that delivers them, kept until that gateway
//! acknowledges them ([`LinkKind::Ack`]) and sent again when it does not (`crate::reliable`).

use bincode::{Decode, Encode};

/// Longest body carried (the ipc crate's own bound on a message body).
pub const MAX_LINK_BODY: usize = petrel_ipc::wire::MAX_BODY_LEN;

/// What a link message carries.
#[derive(Debug, Clone, PartialEq, Eq, Encode, Decode)]
pub enum LinkKind {
    /// An event for the player (body: an ipc `EventMsg`).
    Event,
    /// A call to program `program` (body: an ipc `CallMsg`).
    Call {
        /// The program called.
        program: String,
    },
    /// The player's heartbeat (body: an ipc `Heartbeat`).
    Heartbeat,
    /// The player's marking delta (body: an ipc `MarkingMsg`).
    Marking,
    /// The CAN data server's latest signals (body: an ipc `SignalsMsg`).
    Signals,
    /// The sending gateway is alive; `alive` lists the vehicle's nodes alive on its computer
    /// (`player`, `program/NAME`) that the other computers mirror. No body.
    Beacon {
        /// Node names alive on the sender's computer.
        alive: Vec<String>,
        /// The gateway (incarnation) the sender follows for each computer it has heard: one
        /// per computer, so a second gateway claiming a computer learns it is refused, and
        /// nothing the sender meant for the first is taken by the second.
        follows: Vec<(String, u64)>,
    },
    /// The sending gateway has taken the carried messages of other gateways' streams up to a
    /// point (delivered here, or refused here for the reasons listed). No body.
    Ack {
        /// One per stream, by the gateway that sent it.
        streams: Vec<StreamAck>,
    },
}

/// A carried message's place on its stream: from the sending gateway's incarnation to one
/// incarnation of the destination's gateway, numbered from 1.
#[derive(Debug, Clone, PartialEq, Eq, Encode, Decode)]
pub struct Carried {
    /// The computer whose gateway delivers it.
    pub to: String,
    /// The incarnation of that gateway the stream goes to: a copy for another one (a gateway
    /// that restarted since) is not taken.
    pub to_incarnation: u64,
    /// Its number on the stream.
    pub seq: u64,
    /// The oldest number the sender still holds: the ones before it were acknowledged or given
    /// up (and their senders told), so the receiver waits for none of them.
    pub floor: u64,
}

/// What a gateway took of one stream sent to it.
#[derive(Debug, Clone, PartialEq, Eq, Encode, Decode)]
pub struct StreamAck {
    /// The computer whose gateway sent the stream.
    pub from: String,
    /// That gateway's incarnation.
    pub from_incarnation: u64,
    /// Every message of the stream up to this number was taken (delivered or refused here).
    pub taken: u64,
    /// The latest refusals among them (at most [`MAX_STREAM_REFUSALS`]): number and reason.
    pub refused: Vec<(u64, String)>,
}

/// Refusals a [`StreamAck`] repeats at most (the latest).
pub const MAX_STREAM_REFUSALS: usize = 16;

impl LinkKind {
    /// The kind as counters name it.
    pub fn name(&self) -> &'static str {
        match self {
            LinkKind::Event => "event",
            LinkKind::Call { .. } => "call",
            LinkKind::Heartbeat => "heartbeat",
            LinkKind::Marking => "marking",
            LinkKind::Signals => "signals",
            LinkKind::Beacon { .. } => "beacon",
            LinkKind::Ack { .. } => "ack",
        }
    }
}

/// One message on the link.
#[derive(Debug, Clone, PartialEq, Eq, Encode, Decode)]
pub struct LinkMsg {
    /// The computer whose gateway put it on the link.
    pub from: String,
    /// A random number drawn when that gateway started: a new one means a new process, whose
    /// sequence starts again at 1.
    pub incarnation: u64,
    /// 1 for the gateway's first message, one more for each message it put on the link.
    pub link_seq: u64,
    /// The iceoryx2 origin of the message on its first computer (`player`, `program/PLN`,
    /// `tool/send123`), so the receiving side can send it under the same role.
    pub origin: String,
    /// The ipc sender id of the message on its first computer (0 for the gateway's own).
    pub sender: u64,
    /// Its ipc sequence number there, so that the player's acknowledgement can be translated
    /// back to the sender.
    pub seq: u64,
    /// What it is.
    pub kind: LinkKind,
    /// The ipc body, exactly as the ipc crate encodes it.
    pub body: Vec<u8>,
    /// When it was put on the link, microseconds on the sending gateway's clock (its start is
    /// 0): the receiver tells a copy that waited long in a buffer (see `crate::reliable`).
    pub sent_us: u64,
    /// For an event or a call: its place on the stream to its destination.
    pub carried: Option<Carried>,
}

type LinkConfig = bincode::config::Configuration<
    bincode::config::LittleEndian,
    bincode::config::Varint,
    bincode::config::Limit<{ MAX_LINK_BODY + 4096 }>,
>;

const CONFIG: LinkConfig = bincode::config::standard()
    .with_little_endian()
    .with_variable_int_encoding()
    .with_limit::<{ MAX_LINK_BODY + 4096 }>();

impl LinkMsg {
    /// The bytes put on the link.
    pub fn encode(&self) -> Result<Vec<u8>, String> {
        bincode::encode_to_vec(self, CONFIG).map_err(|e| e.to_string())
    }

    /// A message read from the link; an error says why it does not decode (a foreign or
    /// damaged sender: counted as refused, never a panic).
    pub fn decode(bytes: &[u8]) -> Result<LinkMsg, String> {
        let (msg, used): (LinkMsg, usize) =
            bincode::decode_from_slice(bytes, CONFIG).map_err(|e| e.to_string())?;
        if used != bytes.len() {
            return Err(format!("{} bytes after the message", bytes.len() - used));
        }
        Ok(msg)
    }
}

/// The key a computer's gateway puts everything on.
pub fn key_of(vehicle: &str, computer: &str) -> String {
    format!("petrel/{vehicle}/link/{computer}")
}

/// The key expression a gateway listens to: every computer of the vehicle.
pub fn key_all(vehicle: &str) -> String {
    format!("petrel/{vehicle}/link/*")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_damage() {
        let m = LinkMsg {
            from: "ground".into(),
            incarnation: 7,
            link_seq: 3,
            origin: "program/PLN".into(),
            sender: 11,
            seq: 2,
            kind: LinkKind::Call {
                program: "GUI".into(),
            },
            body: vec![1, 2, 3],
            sent_us: 12,
            carried: Some(Carried {
                to: "A".into(),
                to_incarnation: 5,
                seq: 4,
                floor: 2,
            }),
        };
        let bytes = m.encode().unwrap();
        assert_eq!(LinkMsg::decode(&bytes).unwrap(), m);
        assert!(LinkMsg::decode(&bytes[..bytes.len() - 1]).is_err());
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(LinkMsg::decode(&longer).unwrap_err().contains("after"));
        assert!(LinkMsg::decode(&[0xff; 16]).is_err());
    }
}
