//! A rogue zenoh peer against a vehicle's gateways (tests/tests/gateway.rs): it connects to
//! their endpoints, listens to every key, and for a while puts forged link messages claiming
//! to be computers of the vehicle: an event for the player, a call to a program as the
//! player, a beacon. At the end it prints what it got, as one JSON line: the peers its session
//! reached, the samples it received and their keys, the puts it made.
//!
//! ```text
//! rogue_peer VEHICLE SECONDS --connect ENDPOINT... --claim COMPUTER... [--event NAME]
//!            [--call PROGRAM.FUNCTION] [--keys DIR --as COMPUTER]
//! ```
//!
//! Without `--keys` it speaks plain zenoh (what a stranger on the network has); with them, TLS
//! (for `quic/` endpoints) with that directory's `ca.pem` and the certificate of `--as` (a stranger with a CA of its
//! own, or a computer of the vehicle that claims another).

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use petrel_gateway::link::{key_all, key_of, LinkKind, LinkMsg};
use petrel_ipc::wire::{self, Body};
use zenoh::Wait;

#[derive(Default)]
struct Args {
    vehicle: String,
    seconds: f64,
    connect: Vec<String>,
    claim: Vec<String>,
    event: Option<String>,
    call: Option<(String, String)>,
    keys: Option<(String, String)>,
}

fn args() -> Args {
    let mut it = std::env::args().skip(1);
    let mut a = Args {
        vehicle: it.next().expect("VEHICLE"),
        seconds: it.next().and_then(|s| s.parse().ok()).expect("SECONDS"),
        ..Args::default()
    };
    let mut dir = None;
    while let Some(flag) = it.next() {
        let value = it.next().unwrap_or_else(|| panic!("{flag} needs a value"));
        match flag.as_str() {
            "--connect" => a.connect.push(value),
            "--claim" => a.claim.push(value),
            "--event" => a.event = Some(value),
            "--call" => {
                let (p, f) = value.split_once('.').expect("--call PROGRAM.FUNCTION");
                a.call = Some((p.into(), f.into()));
            }
            "--keys" => dir = Some(value),
            "--as" => a.keys = Some((dir.clone().expect("--keys before --as"), value)),
            _ => panic!("unknown flag {flag}"),
        }
    }
    a
}

fn body<B: Body + ?Sized>(msg: &B) -> Vec<u8> {
    let mut bytes = vec![0u8; wire::encoded_len(msg).expect("encodable")];
    wire::encode_into(msg, &mut bytes).expect("encoded");
    bytes
}

fn config(a: &Args) -> zenoh::Config {
    let mut doc = serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": [] },
        "connect": { "endpoints": a.connect, "retry": { "period_init_ms": 100, "period_max_ms": 500 } },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    });
    if let Some((dir, name)) = &a.keys {
        let keys = petrel_gateway::keys::load(std::path::Path::new(dir), name).expect("keys");
        doc["transport"] = serde_json::json!({
            "link": { "tls": petrel_gateway::session::tls_config(&keys) }
        });
    }
    zenoh::Config::from_json5(&doc.to_string()).expect("zenoh config")
}

/// The forged messages claiming `computer`, numbered from `seq`.
fn forged(a: &Args, computer: &str, incarnation: u64, seq: &mut u64) -> Vec<LinkMsg> {
    let mut kinds: Vec<(&str, LinkKind, Vec<u8>)> = vec![(
        "gateway",
        LinkKind::Beacon {
            alive: vec![],
            follows: vec![],
        },
        vec![],
    )];
    if let Some(e) = &a.event {
        let msg = petrel_ipc::EventMsg::new(e.clone(), vec![]);
        kinds.push(("tool/rogue", LinkKind::Event, body(&msg)));
    }
    if let Some((program, function)) = &a.call {
        let msg = petrel_ipc::CallMsg::new(function.clone(), vec![]);
        let kind = LinkKind::Call {
            program: program.clone(),
        };
        kinds.push(("player", kind, body(&msg)));
    }
    kinds
        .into_iter()
        .map(|(origin, kind, body)| {
            *seq += 1;
            LinkMsg {
                from: computer.to_owned(),
                incarnation,
                link_seq: *seq,
                origin: origin.to_owned(),
                sender: 0,
                seq: *seq,
                kind,
                body,
                sent_us: 0,
                carried: None,
            }
        })
        .collect()
}

fn main() {
    let a = args();
    let session = zenoh::open(config(&a)).wait().expect("a zenoh session");
    let heard: Arc<Mutex<(u64, BTreeSet<String>)>> = Arc::default();
    // Everything, and the link's keys as the gateways subscribe to them (a peer may be let
    // subscribe to these and not to everything).
    let _subs: Vec<_> = ["**".to_owned(), key_all(&a.vehicle)]
        .into_iter()
        .map(|key| {
            let h = heard.clone();
            session
                .declare_subscriber(key)
                // What others put, not its own forgeries coming back.
                .allowed_origin(zenoh::sample::Locality::Remote)
                .callback(move |s| {
                    let mut h = h.lock().expect("lock");
                    h.0 += 1;
                    h.1.insert(s.key_expr().as_str().to_owned());
                })
                .wait()
                .expect("a subscriber")
        })
        .collect();
    let incarnation = 0x0bad_0bad;
    let (mut seq, mut puts, mut put_errors) = (0u64, 0u64, 0u64);
    let mut peers = BTreeSet::new();
    let end = Instant::now() + Duration::from_secs_f64(a.seconds);
    while Instant::now() < end {
        for computer in &a.claim {
            for msg in forged(&a, computer, incarnation, &mut seq) {
                let bytes = msg.encode().expect("encoded");
                match session.put(key_of(&a.vehicle, computer), bytes).wait() {
                    Ok(()) => puts += 1,
                    Err(_) => put_errors += 1,
                }
            }
        }
        peers.extend(session.info().peers_zid().wait().map(|z| z.to_string()));
        std::thread::sleep(Duration::from_millis(50));
    }
    let (received, keys) = heard.lock().expect("lock").clone();
    println!(
        "{}",
        serde_json::json!({
            "peers": peers.len(),
            "received": received,
            "keys": keys,
            "puts": puts,
            "put_errors": put_errors,
        })
    );
}
