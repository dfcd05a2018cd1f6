//! Event senders sized from the project (`Participant::event_receiver_sized` records the
//! longest event in the events service, `Participant::event_sender_sized` reads it): a sized
//! sender carries its bound, sends a longer event in pieces that the receiver joins, in order
//! with the others, takes less of the process's memory than the default (a sender made before the player
//! created the service: `in_process.rs`). One test in its own test binary, so that the
//! resident-memory figures are this test's alone.

mod common;

use common::TestVehicle;

use petrel_ipc::wire::encoded_len;
use petrel_ipc::{EventMsg, Participant, Role, Value};

#[test]
fn sized_event_senders_carry_their_bound_send_longer_events_in_pieces_and_save_memory() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    // The longest event of a project whose events take (int, float, bool, text): its text
    // counts for 1,000 bytes.
    let worst = EventMsg::new(
        "arrived",
        vec![
            Value::Int(i64::MIN),
            Value::Float(f64::MAX),
            Value::Bool(true),
            Value::Text("w".repeat(1_000)),
        ],
    );
    let bound = encoded_len(&worst).unwrap();
    let events = player.event_receiver_sized(bound, 1).unwrap();

    let pln = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
    assert_eq!(pln.max_event_len().unwrap(), Some(bound));
    let tx = pln.event_sender_sized().unwrap();
    assert_eq!(tx.fixed_len(), Some(bound));

    // Four events before the player reads: one at the bound, one far beyond it (a 48 KB list:
    // 49 pieces), one just beyond it (2 pieces), one at the bound again. All arrive whole, in
    // order, numbered by their last piece.
    let route: Vec<f64> = (0..6_000).map(|i| i as f64 * 0.5).collect();
    let large = EventMsg::new("route", vec![Value::FloatList(route)]);
    let large_len = encoded_len(&large).unwrap();
    assert!(large_len > 48_000);
    let just_over = EventMsg::new("arrived!", worst.params.clone());
    let sent: Vec<u64> = [&worst, &large, &just_over, &worst]
        .iter()
        .map(|m| tx.send(m).unwrap().seq)
        .collect();
    let large_pieces = large_len.div_ceil(bound) as u64;
    assert_eq!(
        sent,
        vec![1, 1 + large_pieces, 3 + large_pieces, 4 + large_pieces]
    );
    let got: Vec<_> = std::iter::from_fn(|| events.try_recv().unwrap()).collect();
    assert_eq!(
        got.iter().map(|r| &r.msg).collect::<Vec<_>>(),
        vec![&worst, &large, &just_over, &worst]
    );
    assert_eq!(got.iter().map(|r| r.seq).collect::<Vec<_>>(), sent);
    assert!(got
        .iter()
        .all(|r| r.missed == 0 && r.sender == tx.sender_id()));
    let stats = events.stats();
    assert_eq!((stats.missing, stats.undecodable), (0, 0));
    assert_eq!(stats.received, large_pieces + 4, "every piece is a sample");

    // A body whose pieces stop short (a piece refused, its sender gone) is dropped, and the
    // next event comes through: the receiver's buffer for PLN holds 2,048 samples, a burst of
    // large events fills it.
    let mut refused_at = None;
    for i in 0..100 {
        if let Err(e) = tx.send(&large) {
            assert!(e.is_refusal(), "{e}");
            refused_at = Some(i);
            break;
        }
    }
    let refused_at = refused_at.expect("the buffer fills");
    let got: Vec<_> = std::iter::from_fn(|| events.try_recv().unwrap()).collect();
    assert_eq!(got.len(), refused_at, "the whole ones, not the cut one");
    assert!(got.iter().all(|r| r.msg == large));
    tx.send(&worst).unwrap();
    let next = events.try_recv().unwrap().unwrap();
    assert_eq!(next.msg, worst);
    assert_eq!(next.missed, 1, "the refused piece");

    // Memory: 8 sized senders, then 8 default ones, on the same service.
    const SENDERS: usize = 8;
    let before = common::resident_kib();
    let sized: Vec<_> = (0..SENDERS)
        .map(|_| pln.event_sender_sized().unwrap())
        .collect();
    let after_sized = common::resident_kib();
    let default: Vec<_> = (0..SENDERS).map(|_| pln.event_sender().unwrap()).collect();
    let after_default = common::resident_kib();
    assert!(sized.iter().all(|s| s.fixed_len() == Some(bound)));
    assert!(default.iter().all(|s| s.fixed_len().is_none()));
    let (sized_kib, default_kib) = (after_sized - before, after_default - after_sized);
    eprintln!("{SENDERS} event senders: sized +{sized_kib} KiB, default +{default_kib} KiB");
    // At least 2 MiB less per sender (a default sender's counters alone are about 4 MiB).
    assert!(
        sized_kib + SENDERS as u64 * 2048 < default_kib,
        "sized +{sized_kib} KiB, default +{default_kib} KiB"
    );
    drop((sized, default));
}
