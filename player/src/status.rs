//! The player's live status, as JSON (for people and tools: `petrel status`, the monitor, a
//! shadow catching up): carried by every heartbeat. A boundary: its fields are read by other
//! programs and are not renamed.

/// What the status JSON shows: a snapshot of the player, or the largest one its project can
/// have ([`status_bound`]).
pub(crate) struct StatusSnapshot {
    pub(crate) project: String,
    pub(crate) time_s: f64,
    pub(crate) over: bool,
    /// The marked places of each active net (`global` last); `None`: left out (too large).
    pub(crate) marking: Option<Vec<(String, Vec<String>)>>,
    /// The counters of `stats`, in [`STATS_FIELDS`] order.
    pub(crate) stats: [u64; 16],
    /// Each sender: origin, last_seq, received, undecodable, missing, taken, refused, pending,
    /// unrecorded, settled_seq.
    pub(crate) senders: Vec<(String, [u64; 9])>,
    /// The flight recorder: its state, why it fails, and its counters in [`RECORDER_FIELDS`]
    /// order.
    pub(crate) recorder: (&'static str, String, [u64; 4]),
    /// The content hash of the version running, once a reload brought one.
    pub(crate) version: Option<String>,
    /// A reload is being verified.
    pub(crate) reloading: bool,
}

/// The names of the recorder's counters in the status JSON's `recorder`.
const RECORDER_FIELDS: [&str; 4] = [
    "failures",
    "lost_entries",
    "backlog_records",
    "backlog_bytes",
];

/// The names of the counters in the status JSON's `stats`, in [`StatusSnapshot::stats`] order.
const STATS_FIELDS: [&str; 16] = [
    "messages",
    "bad_messages",
    "received",
    "processed",
    "unused",
    "refused",
    "queued",
    "calls_sent",
    "calls_failed",
    "calls_held",
    "journal_records",
    "resumed_steps",
    "heartbeats_sent",
    "heartbeats_refused",
    "reloads",
    "reloads_refused",
];

/// The names of a sender's counters in the status JSON, in [`StatusSnapshot::senders`] order.
const SENDER_FIELDS: [&str; 9] = [
    "last_seq",
    "received",
    "undecodable",
    "missing",
    "taken",
    "refused",
    "pending",
    "unrecorded",
    "settled_seq",
];

/// The live status carried by the heartbeat, for people and tools: JSON with the marking of
/// every active net, the counters, and each sender's account (read by `petrel status`; the
/// acknowledgements senders wait for are the heartbeat's typed [`Heartbeat::acks`]).
pub(crate) fn status_json(s: &StatusSnapshot) -> String {
    let mut doc = serde_json::Map::new();
    doc.insert("project".into(), s.project.clone().into());
    doc.insert("time".into(), s.time_s.into());
    doc.insert("over".into(), s.over.into());
    doc.insert("version".into(), s.version.clone().into());
    doc.insert("reloading".into(), s.reloading.into());
    match &s.marking {
        Some(m) => {
            let marking: serde_json::Map<String, serde_json::Value> = m
                .iter()
                .map(|(n, places)| (n.clone(), places.clone().into()))
                .collect();
            doc.insert("marking".into(), marking.into());
        }
        None => {
            doc.insert("marking".into(), serde_json::Map::new().into());
            doc.insert("marking_omitted".into(), true.into());
        }
    }
    let stats: serde_json::Map<String, serde_json::Value> = STATS_FIELDS
        .iter()
        .zip(&s.stats)
        .map(|(k, v)| (k.to_string(), (*v).into()))
        .collect();
    doc.insert("stats".into(), stats.into());
    let senders: serde_json::Map<String, serde_json::Value> = s
        .senders
        .iter()
        .map(|(origin, counts)| {
            let fields: serde_json::Map<String, serde_json::Value> = SENDER_FIELDS
                .iter()
                .zip(counts)
                .map(|(k, v)| (k.to_string(), (*v).into()))
                .collect();
            (origin.clone(), fields.into())
        })
        .collect();
    doc.insert("senders".into(), senders.into());
    let (state, reason, counts) = &s.recorder;
    let mut recorder = serde_json::Map::new();
    recorder.insert("state".into(), (*state).into());
    recorder.insert("reason".into(), reason.clone().into());
    for (k, v) in RECORDER_FIELDS.iter().zip(counts) {
        recorder.insert(k.to_string(), (*v).into());
    }
    doc.insert("recorder".into(), recorder.into());
    serde_json::Value::Object(doc).to_string()
}
