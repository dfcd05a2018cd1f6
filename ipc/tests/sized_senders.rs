//! Call senders sized from the project (`Participant::call_sender_sized`): a bounded sender
//! carries calls up to its bound and refuses longer ones, an unbounded one still grows for
//! large parameters, and a bounded one takes less of the process's memory. One test in its
//! own test binary, so that the resident-memory figures are this test's alone.

mod common;

use common::TestVehicle;

use petrel_ipc::port::CALLS;
use petrel_ipc::wire::encoded_len;
use petrel_ipc::{CallMsg, Participant, Role, SendError, Value, WireError};

#[test]
fn sized_call_senders_carry_their_bound_large_calls_grow_and_the_bound_saves_memory() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();

    // A bounded sender: the longest call of a function taking (int, float, bool).
    let worst = CallMsg::new(
        "goto",
        vec![
            Value::Int(i64::MIN),
            Value::Float(f64::MAX),
            Value::Bool(true),
        ],
    );
    let bound = encoded_len(&worst).unwrap();
    let pln = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
    let pln_calls = pln.call_receiver().unwrap();
    let to_pln = player.call_sender_sized("PLN", Some(bound)).unwrap();
    assert_eq!(to_pln.spec().max_body_len, bound);
    to_pln.send(&worst).unwrap();
    let got = pln_calls.try_recv().unwrap().unwrap();
    assert_eq!(got.msg, worst);
    // One byte more than the bound is refused, not cut.
    let longer = CallMsg::new("goto!", worst.args.clone());
    let err = to_pln.send(&longer).unwrap_err();
    assert!(
        matches!(
            err,
            SendError::Wire {
                error: WireError::TooLarge { .. },
                ..
            }
        ),
        "{err}"
    );

    // An unbounded sender (a function taking a list): 6,000 floats (48 KB) go through.
    let gui = Participant::join(&vehicle, Role::program("GUI").unwrap()).unwrap();
    let gui_calls = gui.call_receiver().unwrap();
    let to_gui = player.call_sender_sized("GUI", None).unwrap();
    assert_eq!(to_gui.spec().max_body_len, CALLS.max_body_len);
    let route: Vec<f64> = (0..6_000).map(|i| i as f64 * 0.5).collect();
    let large = CallMsg::new("follow", vec![Value::FloatList(route)]);
    assert!(encoded_len(&large).unwrap() > 48_000);
    to_gui.send(&large).unwrap();
    assert_eq!(gui_calls.try_recv().unwrap().unwrap().msg, large);

    // Memory: 16 programs with bounded senders, then 16 with unbounded ones, each into a
    // service of its own. An unbounded sender keeps about 2 KiB per sample (130 samples).
    const PROGRAMS: usize = 16;
    let before = common::resident_kib();
    let bounded: Vec<_> = (0..PROGRAMS)
        .map(|i| {
            player
                .call_sender_sized(&format!("B{i}"), Some(bound))
                .unwrap()
        })
        .collect();
    let after_bounded = common::resident_kib();
    let unbounded: Vec<_> = (0..PROGRAMS)
        .map(|i| player.call_sender_sized(&format!("U{i}"), None).unwrap())
        .collect();
    let after_unbounded = common::resident_kib();
    let bounded_kib = after_bounded - before;
    let unbounded_kib = after_unbounded - after_bounded;
    eprintln!(
        "{PROGRAMS} call senders: bounded +{bounded_kib} KiB, unbounded +{unbounded_kib} KiB"
    );
    // At least 128 KiB less per sender (the counters alone are 260 KiB).
    assert!(
        bounded_kib + PROGRAMS as u64 * 128 < unbounded_kib,
        "bounded +{bounded_kib} KiB, unbounded +{unbounded_kib} KiB"
    );
    drop((bounded, unbounded));
}
