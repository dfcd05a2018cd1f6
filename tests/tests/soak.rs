//! The counters under a flood (issue 30, item 5): two senders flood the player with a mix of
//! events it processes, leaves unused and refuses (unknown, wrong parameters, built-in,
//! undecodable; after a catastrophic event, everything), while `petrel status` reads the
//! player again and again; `received = processed + unused + refused + queued` must hold at
//! every read, and every message each sender sent must be accounted for at the end (taken,
//! refused, or missing: refused by a full buffer).
//!
//! `PETREL_SOAK_SECS` sets how long the flood lasts (10 s by default, what the suite runs;
//! docs/testing.md gives the figures of a 5-minute run):
//! `PETREL_SOAK_SECS=300 cargo test -p petrel-tests --test soak -- --nocapture`.

use petrel_ipc::{EventMsg, Participant, Role, SendError, Value, Vehicle};
use petrel_tests::{unique_vehicle, Player, TempProject};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const MANIFEST: &str = r#"[project]
name = "soak"
files = ["soak.pn"]
start = ["SOAK"]

[events]
tick = { category = "nominal", params = ["n: int"] }
noise = { category = "nominal" }
doom = { category = "catastrophic" }

[verify]
final = [["SOAK.over"]]
"#;

const NET: &str = r#"net SOAK {
    place up = 1
    place over
    transition t on tick(n): up -> up
    transition d on doom: up -> over
}
"#;

/// What one flooding sender did.
#[derive(Debug, Default)]
struct Flood {
    origin: String,
    /// Sequence numbers used (messages handed to the transport).
    sent: u64,
    /// Of them, refused by the transport (the player's buffer full).
    refused: u64,
    /// Messages by kind: tick, noise, unknown, arity, type, built-in, undecodable.
    kinds: [u64; 7],
    /// The player's account of the sender once it acknowledged the last message.
    ack: petrel_ipc::Ack,
}

/// Messages each sender sends between two pauses of a millisecond (about 20,000 a second in
/// all, not so many that a debug build's journal grows by gigabytes), except in the window of
/// the flood given to `flood`, at full speed: more than the player takes, so that its buffer
/// fills and the transport refuses messages (the full queue).
const BURST: i64 = 10;

/// Floods the player until `stop`; sender 0 sends `doom` at `doom_at`. Ends with one message
/// sent until it is delivered, so that every refused one before it shows as a gap.
fn flood(
    vehicle: &str,
    who: usize,
    stop: &AtomicBool,
    full_speed: std::ops::Range<Instant>,
    doom_at: Instant,
) -> Flood {
    let v = Vehicle::new(vehicle).unwrap();
    let me = Participant::join(&v, Role::tool(&format!("soak{who}")).unwrap()).unwrap();
    let tx = me.event_sender_sized().unwrap();
    let mut f = Flood {
        origin: tx.origin().to_string(),
        ..Flood::default()
    };
    let mut doomed = who != 0;
    let mut n: i64 = 0;
    while !stop.load(Ordering::Relaxed) {
        n += 1;
        if n % BURST == 0 && !full_speed.contains(&Instant::now()) {
            std::thread::sleep(Duration::from_millis(1));
        }
        let kind = (n % 16) as usize;
        let sent = if !doomed && Instant::now() >= doom_at {
            let sent = tx.send(&EventMsg::new("doom", vec![]));
            // Refused by a full buffer, it goes again.
            doomed = sent.is_ok();
            sent
        } else {
            let (k, result) = match kind {
                0 => (2, tx.send(&EventMsg::new("no_such_event", vec![]))),
                1 => (3, tx.send(&EventMsg::new("tick", vec![]))),
                2 => (
                    4,
                    tx.send(&EventMsg::new("tick", vec![Value::Text("one".into())])),
                ),
                3 => (
                    5,
                    tx.send(&EventMsg::new(
                        "program_lost",
                        vec![Value::Text("X".into())],
                    )),
                ),
                4 => (6, tx.send_encoded(&[0xff, 0xfe, 0xfd, 0x00, 0x13])),
                5..=8 => (1, tx.send(&EventMsg::new("noise", vec![]))),
                _ => (0, tx.send(&EventMsg::new("tick", vec![Value::Int(n)]))),
            };
            f.kinds[k] += 1;
            result
        };
        match sent {
            Ok(_) => {}
            Err(e) if e.is_refusal() => {
                f.refused += 1;
                // The player's buffer is full: let it read.
                std::thread::sleep(Duration::from_micros(200));
            }
            Err(e) => panic!("{} cannot send: {e}", f.origin),
        }
    }
    // The last one, until delivered.
    loop {
        match tx.send(&EventMsg::new("noise", vec![])) {
            Ok(_) => break,
            Err(SendError::Refused { .. }) => {
                f.refused += 1;
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(e) => panic!("{} cannot send: {e}", f.origin),
        }
    }
    f.kinds[1] += 1;
    f.sent = tx.stats().sent;
    // The sender stays until the player took everything (shared memory goes with it).
    let beats = me.heartbeat_subscriber().unwrap();
    let heard = petrel_ipc::wait_acknowledged(
        &beats,
        tx.sender_id(),
        tx.next_seq() - 1,
        Duration::from_secs(60),
    );
    assert!(heard.settled(tx.next_seq() - 1), "{}: {heard:?}", f.origin);
    f.ack = heard.ack.expect("the player's account of the sender");
    f
}

fn stat(s: &serde_json::Value, key: &str) -> u64 {
    s["stats"][key]
        .as_u64()
        .unwrap_or_else(|| panic!("no stats.{key} in {s}"))
}

fn balances(s: &serde_json::Value) -> bool {
    stat(s, "received")
        == stat(s, "processed") + stat(s, "unused") + stat(s, "refused") + stat(s, "queued")
}

#[test]
fn the_counters_balance_at_every_status_read_during_a_flood() {
    let secs: f64 = std::env::var("PETREL_SOAK_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    let project = TempProject::new(&[("petrel.toml", MANIFEST), ("soak.pn", NET)]);
    let vehicle = unique_vehicle("soak");
    let player = Player::start(project.path(), &vehicle);
    let stop = Arc::new(AtomicBool::new(false));
    let started = Instant::now();
    // Full speed from 40 % to 60 % of the flood; the catastrophic event at 80 %: from then
    // on, every event is refused.
    let at = |part: f64| started + Duration::from_secs_f64(secs * part);
    let doom_at = at(0.8);
    let floods: Vec<_> = (0..2)
        .map(|who| {
            let (vehicle, stop, full_speed) = (vehicle.clone(), stop.clone(), at(0.4)..at(0.6));
            std::thread::spawn(move || flood(&vehicle, who, &stop, full_speed, doom_at))
        })
        .collect();
    // The status reader: the identity at every read.
    let mut reads = 0u64;
    let mut last = serde_json::Value::Null;
    while started.elapsed() < Duration::from_secs_f64(secs) {
        if let Some(s) = player.status() {
            reads += 1;
            assert!(
                balances(&s),
                "read {reads}: the counters do not balance: {s}"
            );
            last = s;
        }
    }
    stop.store(true, Ordering::Relaxed);
    let floods: Vec<Flood> = floods
        .into_iter()
        .map(|f| f.join().expect("a flood"))
        .collect();
    let s = player.wait_for(30.0, |s| s["stats"]["queued"] == 0);
    assert!(balances(&s), "{s}");
    assert_eq!(
        s["over"], true,
        "the catastrophic event ended the mission: {s}"
    );
    for f in &floods {
        let a = &f.ack;
        // Every message sent is accounted for: received by the player (taken or refused) or
        // missing (refused by its full buffer, seen as a gap).
        assert_eq!(f.sent, a.received + a.missing, "{}: {f:?}", f.origin);
        assert_eq!(a.missing, f.refused, "{}: {f:?}", f.origin);
        assert_eq!(a.received, a.taken + a.refused, "{}: {f:?}", f.origin);
    }
    let sent: u64 = floods.iter().map(|f| f.sent).sum();
    let kinds: Vec<u64> = (0..7)
        .map(|k| floods.iter().map(|f| f.kinds[k]).sum())
        .collect();
    eprintln!(
        "soak of {secs} s: {sent} messages sent by 2 senders (ticks {}, unused {}, unknown {}, arity {}, type {}, built-in {}, undecodable {}), {} refused by the full buffer; {reads} status reads, the identity held at each; at the end: received {} = processed {} + unused {} + refused {} + queued {}; messages {}, bad_messages {}",
        kinds[0],
        kinds[1],
        kinds[2],
        kinds[3],
        kinds[4],
        kinds[5],
        kinds[6],
        floods.iter().map(|f| f.refused).sum::<u64>(),
        stat(&s, "received"),
        stat(&s, "processed"),
        stat(&s, "unused"),
        stat(&s, "refused"),
        stat(&s, "queued"),
        stat(&s, "messages"),
        stat(&s, "bad_messages"),
    );
    assert!(reads > 0 && !last.is_null(), "no status was read");
    assert!(player.stop().success());
}
