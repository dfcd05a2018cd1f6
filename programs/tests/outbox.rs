//! The outbox, and the SDK's own errors, with a program and a fake player in this process
//! (real iceoryx2, one process).

use std::time::Duration;

use petrel_ipc::{Role, Value};
use petrel_programs::{Call, PlayerCheck, Program, ProgramConfig, ProgramError};
use petrel_tests::programs::{FakePlayer, TestVehicle};

fn config(capacity: usize) -> ProgramConfig {
    ProgramConfig {
        outbox_capacity: capacity,
        handle_signals: false,
        ..ProgramConfig::default()
    }
}

#[test]
fn the_outbox_keeps_the_newest_events_and_reports_the_dropped_ones() {
    let v = TestVehicle::new();
    let mut program = Program::connect_with(&v.vehicle, &["GUI", "PLD"], config(3)).unwrap();
    assert!(!program.player_present().unwrap());
    for i in 0..5 {
        let result = program.emit("tick", vec![Value::Int(i)]);
        match (i, result) {
            (0..=2, Ok(())) => {}
            (
                3 | 4,
                Err(ProgramError::EventsDropped {
                    events,
                    total,
                    capacity,
                }),
            ) => {
                assert_eq!(
                    (events, total as i64, capacity),
                    (vec!["tick".to_owned()], i - 2, 3)
                );
            }
            (i, other) => panic!("emit {i}: {other:?}"),
        }
    }
    let e = program.emit("tock", vec![]).unwrap_err();
    assert!(!e.is_fatal());
    let text = e.to_string();
    assert!(
        text.contains("the oldest, tick, was dropped (3 dropped since the start)"),
        "{text}"
    );
    let stats = program.stats();
    assert_eq!(
        (stats.emitted, stats.dropped, stats.queued, stats.delivered),
        (6, 3, 3, 0)
    );

    let mut player = FakePlayer::join(&v.vehicle);
    assert!(program.player_present().unwrap());
    assert_eq!(program.flush().unwrap(), 3);
    for (want, seq) in [(Some(3), 1), (Some(4), 2), (None, 3)] {
        let event = player.next();
        assert_eq!((event.seq, event.missed), (seq, 0));
        match want {
            Some(i) => assert_eq!(event.msg.params, [Value::Int(i)]),
            None => assert_eq!(event.msg.name, "tock"),
        }
    }
    // With the player there, events go straight through, as the program they are emitted as.
    program
        .emit_as("PLD", "payload_failure", vec![Value::Text("camera".into())])
        .unwrap();
    let event = player.next();
    assert_eq!(event.origin.as_str(), "program/PLD");
    let stats = program.stats();
    assert_eq!(
        (
            stats.emitted,
            stats.delivered,
            stats.delivered_late,
            stats.dropped,
            stats.queued
        ),
        (7, 4, 3, 3, 0)
    );
    // Calls come tagged with the program they were addressed to.
    player.call("PLD", "use_payload", vec![Value::Text("lidar".into())]);
    player.call("GUI", "climb", vec![Value::Float(300.0)]);
    let mut calls = Vec::new();
    while calls.len() < 2 {
        if let Some(call) = program.recv(Some(Duration::from_secs(5))).unwrap() {
            calls.push(call.to_string());
        }
    }
    calls.sort();
    assert_eq!(calls, ["GUI.climb(300.0)", "PLD.use_payload(\"lidar\")"]);
    assert_eq!(program.recv(Some(Duration::from_millis(10))).unwrap(), None);
}

#[test]
fn calls_received_into_one_call_are_recv_s_calls_and_reuse_its_buffers() {
    let v = TestVehicle::new();
    let mut program = Program::connect_with(&v.vehicle, &["GUI", "PLD"], config(4)).unwrap();
    let mut player = FakePlayer::join(&v.vehicle);
    let mut call = Call::default();
    // Nothing waits: the call is left as it was.
    assert!(!program
        .recv_into(&mut call, Some(Duration::from_millis(10)))
        .unwrap());
    assert_eq!(call, Call::default());
    let track = |i: i64| vec![Value::Int(i), Value::FloatList(vec![i as f64; 6])];
    player.call("GUI", "track", track(1));
    assert!(program
        .recv_into(&mut call, Some(Duration::from_secs(5)))
        .unwrap());
    assert_eq!(call, Call::new("GUI", "track", track(1)));
    let list = call.floats(1).unwrap().as_ptr();
    // The next call of the same shape lands in the same buffers; another program's is tagged
    // with its name.
    player.call("PLD", "track", track(2));
    assert!(program
        .recv_into(&mut call, Some(Duration::from_secs(5)))
        .unwrap());
    assert_eq!(call, Call::new("PLD", "track", track(2)));
    assert_eq!(call.floats(1).unwrap().as_ptr(), list);
    // An undecodable call is recv's error, counted alike.
    player.sender("GUI").send_encoded(&[0x01]).unwrap();
    match program.recv_into(&mut call, Some(Duration::from_secs(5))) {
        Err(ProgramError::BadCall { program, .. }) => assert_eq!(program, "GUI"),
        other => panic!("{other:?}"),
    }
    assert_eq!((program.stats().calls, program.stats().bad_calls), (2, 1));
    player.call("GUI", "climb", vec![Value::Float(300.0)]);
    assert!(program
        .recv_into(&mut call, Some(Duration::from_secs(5)))
        .unwrap());
    assert_eq!(call.to_string(), "GUI.climb(300.0)");
}

#[test]
fn a_player_leaving_and_coming_back_gets_the_events_in_between_in_order() {
    let v = TestVehicle::new();
    let mut program = Program::connect_with(&v.vehicle, &["DEC"], config(16)).unwrap();
    let player = FakePlayer::join(&v.vehicle);
    program.emit("a", vec![]).unwrap();
    assert_eq!(player.next().msg.name, "a");
    drop(player);
    for name in ["b", "c", "d"] {
        program.emit(name, vec![]).unwrap();
    }
    assert_eq!(program.queued(), 3);
    assert_eq!(program.stats().player_losses, 1);
    let player = FakePlayer::join(&v.vehicle);
    // recv delivers the queued events while it waits for calls.
    assert_eq!(
        program.recv(Some(Duration::from_millis(100))).unwrap(),
        None
    );
    assert_eq!(program.queued(), 0);
    program.emit("e", vec![]).unwrap();
    for (name, seq) in [("b", 1), ("c", 2), ("d", 3), ("e", 4)] {
        let event = player.next();
        assert_eq!(
            (event.msg.name.as_str(), event.seq, event.missed),
            (name, seq, 0)
        );
    }
    let stats = program.close(Duration::from_millis(10)).unwrap();
    assert_eq!((stats.emitted, stats.delivered, stats.queued), (5, 5, 0));
    // The fake player sends no heartbeat: nothing says it took the last event.
    assert!(stats.unacknowledged);
}

#[test]
fn connect_errors_are_typed_and_clear() {
    let v = TestVehicle::new();
    assert!(matches!(
        Program::connect_with(&v.vehicle, &[], config(1)),
        Err(ProgramError::NoProgram)
    ));
    let e = Program::connect_with(&v.vehicle, &["GUI", "GUI"], config(1)).unwrap_err();
    assert!(
        matches!(&e, ProgramError::DuplicateProgram(p) if p == "GUI"),
        "{e}"
    );
    let e = Program::connect_with(&v.vehicle, &["G U I"], config(1)).unwrap_err();
    assert!(e.is_fatal());
    assert!(e.to_string().contains("contains ' '"), "{e}");
    // A second instance of a program is refused: its call service takes one receiver.
    let _first = Program::connect_with(&v.vehicle, &["DEC"], config(1)).unwrap();
    let e = Program::connect_with(&v.vehicle, &["DEC"], config(1)).unwrap_err();
    assert!(
        matches!(&e, ProgramError::Setup { program, .. } if program == "DEC"),
        "{e}"
    );
    assert!(
        e.to_string().starts_with("cannot connect program `DEC`"),
        "{e}"
    );
    let mut program = Program::connect_with(&v.vehicle, &["GUI"], config(1)).unwrap();
    let e = program.emit_as("PLD", "x", vec![]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "this process does not host program `PLD` (it hosts GUI); emit as one of them"
    );
    let huge = Value::FloatList(vec![0.5; 10_000]);
    let e = program.emit("big", vec![huge]).unwrap_err();
    assert!(
        matches!(&e, ProgramError::Unsendable { event, .. } if event == "big"),
        "{e}"
    );
    assert_eq!(program.stats().emitted, 0);
    // Only a program has a call receiver; a player is not one.
    assert_eq!(Role::Player.node_name(), "player");
}

#[test]
fn the_player_check_can_be_relaxed() {
    let v = TestVehicle::new();
    for check in [
        PlayerCheck::Every(Duration::from_secs(3600)),
        PlayerCheck::Never,
    ] {
        let config = ProgramConfig {
            player_check: check,
            ..config(8)
        };
        let mut program = Program::connect_with(&v.vehicle, &["GUI"], config).unwrap();
        let player = FakePlayer::join(&v.vehicle);
        program.emit("a", vec![]).unwrap();
        program.emit("b", vec![]).unwrap();
        assert_eq!(player.next().msg.name, "a");
        assert_eq!(player.next().msg.name, "b");
        // A player that leaves in good order is seen at once, whatever the check.
        drop(player);
        program.emit("c", vec![]).unwrap();
        assert_eq!(program.queued(), 1, "{check:?}");
        let player = FakePlayer::join(&v.vehicle);
        assert_eq!(program.flush().unwrap(), 1);
        assert_eq!(player.next().msg.name, "c");
    }
}
