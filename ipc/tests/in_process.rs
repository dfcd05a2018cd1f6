//! Ports, accounting and the reactor within one process (two participants of one isolated
//! vehicle). Cross-process behaviour is in `cross_process.rs`.

mod common;

use std::time::{Duration, Instant};

use common::TestVehicle;

use petrel_ipc::port::EVENTS;
use petrel_ipc::{
    CallMsg, EventMsg, Heartbeat, MarkingMsg, Participant, Reactor, RecvError, Role, SendError,
    SetupError, Value, Vehicle, WaitStrategy, EVENT_SENDERS_SPARE, MIN_FIXED_LEN,
    PROGRAM_SENDERS_GONE,
};

fn pair(vehicle: &Vehicle) -> (Participant, Participant) {
    let player = Participant::join(vehicle, Role::Player).unwrap();
    let pln = Participant::join(vehicle, Role::program("PLN").unwrap()).unwrap();
    (player, pln)
}

#[test]
fn event_round_trip_with_origin_and_sequence() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    for i in 0..3 {
        let sent = tx
            .send(&EventMsg::new("depth", vec![Value::Float(i as f64)]))
            .unwrap();
        assert_eq!(sent.seq, i + 1);
        assert_eq!(sent.delivered, 1);
    }
    for i in 0..3u64 {
        let r = rx.try_recv().unwrap().unwrap();
        assert_eq!(r.msg, EventMsg::new("depth", vec![Value::Float(i as f64)]));
        assert_eq!(r.origin.as_str(), "program/PLN");
        assert_eq!(r.seq, i + 1);
        assert_eq!(r.missed, 0);
        assert_eq!(r.sender, tx.sender_id());
    }
    assert!(rx.try_recv().unwrap().is_none());
    assert_eq!(tx.stats().sent, 3);
    assert_eq!(tx.stats().delivered, 3);
    let accounts = rx.senders();
    assert_eq!(accounts.len(), 1);
    assert_eq!(accounts[0].last_seq, 3);
    assert_eq!(accounts[0].received, 3);
}

#[test]
fn a_body_sent_with_its_measured_length_arrives_and_a_wrong_length_sends_nothing() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    let msg = EventMsg::new("depth", vec![Value::Float(12.5), Value::Int(3)]);
    let len = petrel_ipc::wire::encoded_len(&msg).unwrap();
    for wrong in [len - 1, len + 1] {
        let err = tx.send_measured(&msg, wrong).unwrap_err();
        assert!(matches!(err, SendError::Wire { .. }), "{err}");
    }
    assert_eq!(tx.stats().not_sent, 2);
    assert_eq!(tx.stats().sent, 0);
    let sent = tx.send_measured(&msg, len).unwrap();
    // The wrong lengths used no sequence number: no gap at the receiver.
    assert_eq!(sent.seq, 1);
    let r = rx.try_recv().unwrap().unwrap();
    assert_eq!(r.msg, msg);
    assert_eq!(r.missed, 0);
    assert!(rx.try_recv().unwrap().is_none());
}

#[test]
fn no_receiver_is_reported_and_leaves_a_gap() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let tx = pln.event_sender().unwrap();
    let err = tx.send(&EventMsg::new("early", vec![])).unwrap_err();
    assert!(matches!(err, SendError::NoReceiver { seq: 1, .. }), "{err}");
    assert!(err.to_string().contains("is the player running?"), "{err}");
    let rx = player.event_receiver().unwrap();
    tx.send(&EventMsg::new("late", vec![])).unwrap();
    let r = rx.try_recv().unwrap().unwrap();
    assert_eq!((r.seq, r.missed), (2, 1));
    assert_eq!(rx.stats().missing, 1);
    let s = tx.stats();
    assert_eq!((s.sent, s.delivered, s.refused), (2, 1, 1));
}

#[test]
fn a_full_buffer_refuses_and_the_receiver_counts_the_gap() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    let over = 5;
    let total = EVENTS.subscriber_buffer + over;
    let mut refused = 0;
    for i in 0..total {
        match tx.send(&EventMsg::new("tick", vec![Value::Int(i as i64)])) {
            Ok(_) => {}
            Err(SendError::Refused {
                delivered: 0,
                receivers: 1,
                ..
            }) => refused += 1,
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(refused, over);
    // Nothing already buffered was overwritten: the first BUFFER messages are all there.
    let mut seqs = Vec::new();
    rx.drain(|r| seqs.push(r.unwrap().seq)).unwrap();
    assert_eq!(seqs.len(), EVENTS.subscriber_buffer);
    assert!(seqs.iter().enumerate().all(|(i, s)| *s == i as u64 + 1));
    // The next delivered message shows the refused ones as missed.
    tx.send(&EventMsg::new("tick", vec![])).unwrap();
    let r = rx.try_recv().unwrap().unwrap();
    assert_eq!(r.missed, over as u64);
    let s = tx.stats();
    assert_eq!(s.sent, total as u64 + 1);
    assert_eq!(s.sent, rx.stats().received + s.refused);
    assert_eq!(rx.stats().missing, s.refused);
}

#[test]
fn undecodable_bodies_are_typed_errors() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    tx.send_encoded(&[0xFF, 0xFF, 0xFF]).unwrap();
    tx.send(&EventMsg::new("ok", vec![])).unwrap();
    match rx.try_recv() {
        Err(RecvError::Undecodable { seq: 1, origin, .. }) => {
            assert_eq!(origin.as_str(), "program/PLN")
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(rx.try_recv().unwrap().unwrap().msg.name, "ok");
    assert_eq!(rx.stats().undecodable, 1);
}

#[test]
fn events_drained_in_place_are_those_drain_gives_with_the_same_accounts() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    let sent = [
        EventMsg::new(
            "pong_0",
            vec![Value::Int(1), Value::FloatList(vec![0.5; 6])],
        ),
        EventMsg::new(
            "label",
            vec![Value::Text("héllo".into()), Value::Bool(true)],
        ),
        EventMsg::new(
            "pong_0",
            vec![Value::Int(2), Value::FloatList(vec![1.5; 6])],
        ),
    ];
    tx.send(&sent[0]).unwrap();
    tx.send_encoded(&[0xFF, 0xFF, 0xFF]).unwrap();
    tx.send(&sent[1]).unwrap();
    tx.send(&sent[2]).unwrap();
    let mut params = Vec::with_capacity(8);
    let capacity = params.capacity();
    let mut got = Vec::new();
    let mut errors = Vec::new();
    let drained = rx
        .drain_in_place(&mut params, |r, params| match r {
            Ok(r) => got.push((
                EventMsg::new(r.msg, params.clone()),
                r.seq,
                r.missed,
                r.origin.as_str().to_owned(),
            )),
            Err(e) => errors.push(e),
        })
        .unwrap();
    assert_eq!((drained.messages, drained.errors), (3, 1));
    assert_eq!(
        got,
        vec![
            (sent[0].clone(), 1, 0, "program/PLN".to_owned()),
            (sent[1].clone(), 3, 0, "program/PLN".to_owned()),
            (sent[2].clone(), 4, 0, "program/PLN".to_owned()),
        ]
    );
    assert!(
        matches!(&errors[..], [RecvError::Undecodable { seq: 2, .. }]),
        "{errors:?}"
    );
    assert_eq!(params.capacity(), capacity);
    assert_eq!(rx.stats().undecodable, 1);
    assert_eq!(rx.stats().received, 4);
    assert_eq!(rx.senders()[0].undecodable, 1);
}

#[test]
fn a_call_received_into_buffers_is_the_call_and_leaves_them_alone_when_none_waits() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let calls = pln.call_receiver().unwrap();
    let to_pln = player.call_sender("PLN").unwrap();
    let (mut function, mut args) = (String::from("old"), vec![Value::Int(7)]);
    assert!(calls
        .try_recv_into(&mut function, &mut args)
        .unwrap()
        .is_none());
    assert_eq!(
        (function.as_str(), &args[..]),
        ("old", &[Value::Int(7)][..])
    );
    let ping = CallMsg::new("ping", vec![Value::Int(3), Value::FloatList(vec![2.0; 6])]);
    to_pln.send(&ping).unwrap();
    to_pln.send_encoded(&[0x01]).unwrap();
    let r = calls
        .try_recv_into(&mut function, &mut args)
        .unwrap()
        .unwrap();
    assert_eq!((r.seq, r.missed, r.origin.as_str()), (1, 0, "player"));
    assert_eq!(CallMsg::new(function.clone(), args.clone()), ping);
    match calls.try_recv_into(&mut function, &mut args) {
        Err(RecvError::Undecodable { seq: 2, .. }) => {}
        other => panic!("{other:?}"),
    }
    assert_eq!(calls.stats().undecodable, 1);
}

#[test]
fn too_large_is_refused_before_sending() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let _rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    let big = EventMsg::new("big", vec![Value::FloatList(vec![0.5; 10_000])]);
    let err = tx.send(&big).unwrap_err();
    assert!(err.seq().is_none(), "{err}");
    assert!(err.to_string().contains("more than"), "{err}");
    assert_eq!(tx.stats().not_sent, 1);
    assert_eq!(tx.next_seq(), 1);
    // A large message that fits grows the sample memory.
    let grown = EventMsg::new("grown", vec![Value::FloatList(vec![0.25; 4_000])]);
    tx.send(&grown).unwrap();
}

#[test]
fn a_second_event_receiver_is_refused_with_a_hint() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let _rx = player.event_receiver().unwrap();
    let err = pln.event_receiver().unwrap_err();
    assert!(err.to_string().contains("second player"), "{err}");
}

#[test]
fn calls_reach_only_their_program() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    assert!(matches!(
        player.call_receiver(),
        Err(SetupError::NotAProgram { .. })
    ));
    let calls = pln.call_receiver().unwrap();
    let to_pln = player.call_sender("PLN").unwrap();
    let to_gui = player.call_sender("GUI").unwrap();
    to_pln
        .send(&CallMsg::new("climb", vec![Value::Int(300)]))
        .unwrap();
    let err = to_gui.send(&CallMsg::new("show", vec![])).unwrap_err();
    assert!(err.to_string().contains("is the program running?"), "{err}");
    let r = calls.try_recv().unwrap().unwrap();
    assert_eq!(r.msg.function, "climb");
    assert_eq!(r.origin.as_str(), "player");
    assert!(calls.try_recv().unwrap().is_none());
}

#[test]
fn marking_reports_a_lagging_monitor() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let monitor = Participant::join(&vehicle, Role::tool("monitor").unwrap()).unwrap();
    let publisher = player.marking_publisher().unwrap();
    let fast = monitor.marking_subscriber().unwrap();
    let slow = monitor.marking_subscriber().unwrap();
    let buffer = publisher.spec().subscriber_buffer;
    let mut partial = 0;
    for step in 0..buffer as u64 + 2 {
        let delta = MarkingMsg {
            step,
            fired: vec!["mission.t1".into()],
            ..MarkingMsg::default()
        };
        match publisher.send(&delta) {
            Ok(_) => {}
            Err(SendError::Refused {
                delivered: 1,
                receivers: 2,
                ..
            }) => partial += 1,
            Err(e) => panic!("{e}"),
        }
        // The fast monitor keeps up.
        while fast.try_recv().unwrap().is_some() {}
    }
    assert_eq!(partial, 2);
    assert_eq!(fast.stats().received, buffer as u64 + 2);
    let mut n = 0;
    slow.drain(|r| {
        r.unwrap();
        n += 1;
    })
    .unwrap();
    assert_eq!(n, buffer);
}

#[test]
fn heartbeats_keep_the_latest() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let beats = player.heartbeat_publisher().unwrap();
    let beat = |progress| Heartbeat {
        uptime_ms: progress * 100,
        period_ms: 100,
        progress,
        status: "running".into(),
        ..Heartbeat::default()
    };
    assert!(matches!(
        beats.send(&beat(0)),
        Err(SendError::NoReceiver { .. })
    ));
    let monitor = Participant::join(&vehicle, Role::tool("monitor").unwrap()).unwrap();
    let listener = monitor.heartbeat_subscriber().unwrap();
    beats.send(&beat(1)).unwrap();
    assert_eq!(listener.try_recv().unwrap().unwrap().msg, beat(1));
    // Overflow overwrites old heartbeats rather than refusing new ones.
    for progress in 2..30 {
        beats.send(&beat(progress)).unwrap();
    }
    let mut seen = Vec::new();
    listener
        .drain(|r| seen.push(r.unwrap().msg.progress))
        .unwrap();
    assert_eq!(seen.len(), listener.spec().subscriber_buffer);
    assert_eq!(seen.last(), Some(&29));
    assert_eq!(listener.stats().missing, 1 + 28 - seen.len() as u64);
}

#[test]
fn reactor_strategies_wake_on_events_and_time_out() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    assert_eq!(rx.take_wakeups().unwrap().senders_joined, 1);
    for strategy in [
        WaitStrategy::Block,
        WaitStrategy::Spin,
        WaitStrategy::SpinThenBlock(Duration::from_micros(200)),
    ] {
        let reactor = Reactor::without_signal_handling(strategy).unwrap();
        let start = Instant::now();
        let ready = reactor
            .wait(&[&rx], Some(Duration::from_millis(20)))
            .unwrap();
        assert!(ready.timed_out() && !ready.any(), "{strategy}: {ready:?}");
        assert!(start.elapsed() >= Duration::from_millis(20), "{strategy}");
        tx.send(&EventMsg::new("go", vec![])).unwrap();
        let ready = reactor.wait(&[&rx], Some(Duration::from_secs(5))).unwrap();
        assert!(ready.is_ready(0), "{strategy}: {ready:?}");
        let drained = rx.drain(|r| assert!(r.is_ok())).unwrap();
        assert_eq!(drained.messages, 1, "{strategy}");
    }
}

#[test]
fn a_blocking_wait_returns_at_once_for_samples_already_there_without_sleeping() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let events = player.event_receiver().unwrap();
    let reload = player.reload_receiver().unwrap();
    assert!(events.has_doorbell() && reload.has_doorbell());
    let pln = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
    let tx = pln.event_sender().unwrap();
    let reactor = Reactor::without_signal_handling(WaitStrategy::Block).unwrap();
    // The sender's arrival is news: taken by a first wait.
    reactor
        .wait(&[&reload, &events], Some(Duration::from_secs(5)))
        .unwrap();
    events.take_wakeups().unwrap();
    let before = reactor.stats();
    tx.send(&EventMsg::new("go", vec![])).unwrap();
    let ready = reactor
        .wait(&[&reload, &events], Some(Duration::from_secs(5)))
        .unwrap();
    assert!(ready.is_ready(1) && !ready.is_ready(0), "{ready:?}");
    let after = reactor.stats();
    assert_eq!(after.waits, before.waits + 1);
    assert_eq!(after.sleeps, before.sleeps, "{after:?}");
    assert_eq!(after.doorbell_sleeps, before.doorbell_sleeps, "{after:?}");
    assert_eq!(events.drain(|r| assert!(r.is_ok())).unwrap().messages, 1);
}

#[test]
fn reactor_reports_a_sender_joining() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let reactor = Reactor::without_signal_handling(WaitStrategy::Block).unwrap();
    let _tx = pln.event_sender().unwrap();
    let ready = reactor.wait(&[&rx], Some(Duration::from_secs(5))).unwrap();
    assert!(ready.is_ready(0), "{ready:?}");
    let wakeups = rx.take_wakeups().unwrap();
    assert_eq!(wakeups.senders_joined, 1);
    // The wake-up was consumed: the next wait times out.
    let ready = reactor
        .wait(&[&rx], Some(Duration::from_millis(10)))
        .unwrap();
    assert!(ready.timed_out(), "{ready:?}");
}

#[test]
fn fd_sources_wake_the_reactor() {
    use std::io::Write;
    use std::os::fd::AsRawFd;
    use std::os::unix::net::UnixStream;

    let (mut a, b) = UnixStream::pair().unwrap();
    let source = petrel_ipc::FdSource::new(b.as_raw_fd()).unwrap();
    assert!(petrel_ipc::FdSource::new(-1).is_err());
    for strategy in [WaitStrategy::Block, WaitStrategy::Spin] {
        let reactor = Reactor::without_signal_handling(strategy).unwrap();
        let ready = reactor
            .wait(&[&source], Some(Duration::from_millis(5)))
            .unwrap();
        assert!(ready.timed_out(), "{strategy}");
    }
    a.write_all(b"x").unwrap();
    for strategy in [WaitStrategy::Block, WaitStrategy::Spin] {
        let reactor = Reactor::without_signal_handling(strategy).unwrap();
        let ready = reactor
            .wait(&[&source], Some(Duration::from_secs(5)))
            .unwrap();
        assert!(ready.is_ready(0), "{strategy}");
    }
}

/// A program is ready when it receives its calls, not when its node lives (issue 30: a call
/// sent in between found no receiver and was lost).
#[test]
fn program_watch_sees_programs_join_receive_and_go() {
    use petrel_ipc::ProgramStatus::{Absent, Alive, Joining};
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let mut watch = petrel_ipc::ProgramWatch::new(&player, ["PLN"]).unwrap();
    assert!(watch.check().unwrap().is_empty());
    let pln = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
    // Its node lives, its calls have no receiver yet: joining, and a call finds nobody.
    let changes = watch.check().unwrap();
    assert_eq!((changes.len(), changes[0].to), (1, Joining), "{changes:?}");
    assert!(!changes[0].is_lost());
    let calls = player.call_sender("PLN").unwrap();
    assert!(matches!(
        calls.send(&CallMsg::new("plan", vec![])),
        Err(SendError::NoReceiver { .. })
    ));
    assert_eq!(watch.probe("PLN").unwrap(), Some(Joining));
    // Its receiver connected: ready, and a call goes.
    let rx = pln.call_receiver().unwrap();
    assert_eq!(watch.probe("PLN").unwrap(), Some(Alive));
    assert_eq!(
        watch.status("PLN"),
        Some(Joining),
        "a probe changes nothing"
    );
    let changes = watch.check().unwrap();
    assert_eq!((changes[0].from, changes[0].to), (Joining, Alive));
    calls.send(&CallMsg::new("plan", vec![])).unwrap();
    // Its receiver gone first (as a program leaves), then its node: lost only then.
    drop(rx);
    let changes = watch.check().unwrap();
    assert_eq!(changes[0].to, Joining);
    assert!(!changes[0].is_lost(), "{changes:?}");
    drop(pln);
    let changes = watch.check().unwrap();
    assert!(changes[0].is_lost(), "{changes:?}");
    assert_eq!(changes[0].to, Absent);
    assert_eq!(watch.probe("NAV").unwrap(), None, "not watched");
    // Gone and back between two checks (killed and restarted at once): a new process, so the
    // old one went; seen as such, not as no change.
    let pln = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
    let rx = pln.call_receiver().unwrap();
    assert_eq!(watch.check().unwrap()[0].to, Alive);
    drop((rx, pln));
    let pln = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
    let _rx = pln.call_receiver().unwrap();
    let changes = watch.check().unwrap();
    assert_eq!(changes.len(), 2, "{changes:?}");
    assert!(changes[0].is_lost(), "{changes:?}");
    assert_eq!((changes[1].from, changes[1].to), (Absent, Alive));
    assert!(watch.check().unwrap().is_empty());
}

#[test]
fn a_reactor_without_sources_is_a_timer() {
    for strategy in [
        WaitStrategy::Block,
        WaitStrategy::SpinThenBlock(Duration::from_millis(1)),
    ] {
        let reactor = Reactor::without_signal_handling(strategy).unwrap();
        let start = Instant::now();
        let ready = reactor.wait(&[], Some(Duration::from_millis(5))).unwrap();
        assert!(ready.timed_out());
        assert!(start.elapsed() >= Duration::from_millis(5));
        assert!(matches!(
            reactor.wait(&[], None),
            Err(petrel_ipc::ReactorError::NothingToWaitFor)
        ));
    }
}

#[test]
fn a_sized_heartbeat_publisher_carries_what_the_default_refuses() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let small = player.heartbeat_publisher().unwrap();
    let monitor = Participant::join(&vehicle, Role::tool("monitor").unwrap()).unwrap();
    let listener = monitor.heartbeat_subscriber().unwrap();
    let acks: Vec<petrel_ipc::Ack> = (0..petrel_ipc::wire::MAX_ACKS as u64)
        .map(|i| petrel_ipc::Ack {
            sender: i,
            origin: format!("tool/send{i}"),
            last_seq: i,
            settled_seq: i,
            ..petrel_ipc::Ack::default()
        })
        .collect();
    let beat = Heartbeat {
        status: "x".repeat(3000),
        acks,
        ..Heartbeat::default()
    };
    assert!(matches!(small.send(&beat), Err(SendError::Wire { .. })));
    drop(small);
    let max = Heartbeat::max_encoded_len(3000);
    let sized = player.heartbeat_publisher_sized(max).unwrap();
    sized.send(&beat).unwrap();
    let got = listener.try_recv().unwrap().unwrap().msg;
    assert_eq!(got.ack_for(63).map(|a| a.last_seq), Some(63));
    assert_eq!(got, beat);
}

#[test]
fn a_receiver_lists_its_live_senders_and_forgets_departed_ones() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let events = player.event_receiver().unwrap();
    let tool = Participant::join(&vehicle, Role::tool("a").unwrap()).unwrap();
    let a = tool.event_sender().unwrap();
    let b = tool.event_sender().unwrap();
    let mut live = events.live_senders();
    live.sort();
    let mut expected = vec![a.sender_id(), b.sender_id()];
    expected.sort();
    assert_eq!(live, expected);
    a.send(&EventMsg::new("x", vec![])).unwrap();
    b.send(&EventMsg::new("x", vec![])).unwrap();
    events.drain(|_| {}).unwrap();
    assert_eq!(events.senders().len(), 2);
    let gone = a.sender_id();
    drop(a);
    assert_eq!(events.live_senders(), vec![b.sender_id()]);
    events.forget_sender(gone);
    assert_eq!(events.senders().len(), 1);
}

/// Pins the calling thread to `cpu` under `SCHED_FIFO`: threads of one priority on one core
/// then run only when the running one blocks or yields, whatever else the machine does.
/// False when the system refuses (it needs root or `CAP_SYS_NICE`).
fn alone_on_one_core(cpu: usize) -> bool {
    // SAFETY: `set` is a zeroed `cpu_set_t` filled by `CPU_SET` within its size; both calls
    // only read their arguments and act on the calling thread (pid 0).
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
            return false;
        }
        let param = libc::sched_param { sched_priority: 1 };
        libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0
    }
}

/// A spinning side that shares its core with the peer it waits for gives the core away: the
/// peer answers within the spin window. Before, `spin-then-block` held the core for its whole
/// window and every wait ended asleep (one or two spin windows per round trip: the bimodal
/// 250 / 450 µs of docs/benchmarks.md).
#[test]
fn a_spinning_reactor_lets_its_peer_on_the_same_core_answer() {
    const ROUNDS: i64 = 20;
    // A window far longer than an answer: only a peer kept off the core makes it end.
    let strategy = WaitStrategy::SpinThenBlock(Duration::from_millis(20));
    let vehicle = TestVehicle::new("auv");
    // SAFETY: sched_getcpu takes no argument and only reads the calling thread's state.
    let cpu = unsafe { libc::sched_getcpu() }.max(0) as usize;
    let ready = std::sync::Barrier::new(2);
    let (player_side, program_side) = std::thread::scope(|s| {
        let player = s.spawn(|| {
            let fifo = alone_on_one_core(cpu);
            let me = Participant::join(&vehicle, Role::Player).unwrap();
            let events = me.event_receiver().unwrap();
            let calls = me.call_sender("PLN").unwrap();
            let reactor = Reactor::without_signal_handling(strategy).unwrap();
            ready.wait();
            let mut answered = 0;
            while answered < ROUNDS {
                let r = reactor
                    .wait(&[&events], Some(Duration::from_secs(5)))
                    .unwrap();
                assert!(!r.timed_out(), "no event after {answered} rounds");
                events
                    .drain(|r| {
                        let n = r.unwrap().msg.params[0].clone();
                        calls.send(&CallMsg::new("ping", vec![n])).unwrap();
                        answered += 1;
                    })
                    .unwrap();
            }
            (fifo, reactor.stats())
        });
        let program = s.spawn(|| {
            let fifo = alone_on_one_core(cpu);
            let me = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
            let calls = me.call_receiver().unwrap();
            let events = me.event_sender().unwrap();
            let reactor = Reactor::without_signal_handling(strategy).unwrap();
            ready.wait();
            for i in 0..ROUNDS {
                events
                    .send(&EventMsg::new("pong", vec![Value::Int(i)]))
                    .unwrap();
                let call = loop {
                    let r = reactor
                        .wait(&[&calls], Some(Duration::from_secs(5)))
                        .unwrap();
                    assert!(!r.timed_out(), "no call in round {i}");
                    calls.take_wakeups().unwrap();
                    if let Some(call) = calls.try_recv().unwrap() {
                        break call;
                    }
                };
                assert_eq!(call.msg.args, vec![Value::Int(i)]);
            }
            (fifo, reactor.stats())
        });
        (player.join().unwrap(), program.join().unwrap())
    });
    let ((fifo_a, player), (fifo_b, program)) = (player_side, program_side);
    if !(fifo_a && fifo_b) {
        eprintln!("not checked: SCHED_FIFO on one core is refused here (needs CAP_SYS_NICE)");
        return;
    }
    assert!(player.waits >= ROUNDS as u64 && program.waits >= ROUNDS as u64);
    assert_eq!(player.sleeps, 0, "player: {player:?}");
    assert_eq!(program.sleeps, 0, "program: {program:?}");
}

/// A spinning receiver consumes its notifications now and then (`consume_wakeups_every`), not
/// at every message: they wait in the listener meanwhile. When it then sleeps, the waiting
/// notifications neither keep waking it (no sample is pending) nor hide a new one.
#[test]
fn a_lazily_consuming_receiver_neither_misses_a_wakeup_nor_wakes_for_old_ones() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    let tx = pln.event_sender().unwrap();
    // The sender's arrival is news (it wakes a reactor): taken now.
    assert_eq!(rx.take_wakeups().unwrap().senders_joined, 1);
    // A period not yet over: draining takes the samples, not their notifications.
    rx.consume_wakeups_every(Some(Duration::from_secs(3600)));
    for i in 0..5 {
        tx.send(&EventMsg::new("depth", vec![Value::Int(i)]))
            .unwrap();
    }
    let drained = rx.drain(|r| assert!(r.is_ok())).unwrap();
    assert_eq!(drained.messages, 5);
    assert_eq!(
        drained.wakeups.samples, 0,
        "consumed before the period ended"
    );
    // Asleep with only old notifications waiting: it times out rather than returning ready.
    let reactor = Reactor::without_signal_handling(WaitStrategy::Block).unwrap();
    let r = reactor
        .wait(&[&rx], Some(Duration::from_millis(50)))
        .unwrap();
    assert!(
        r.timed_out(),
        "woken by notifications of samples already taken"
    );
    // The reactor consumed them on the receiver's behalf: they are reported, once.
    rx.consume_wakeups_every(None);
    assert!(rx.take_wakeups().unwrap().samples >= 1);
    assert_eq!(rx.take_wakeups().unwrap().samples, 0);
    // A new sample wakes it.
    rx.consume_wakeups_every(Some(Duration::from_secs(3600)));
    let (done, wait_done) = std::sync::mpsc::channel::<()>();
    let vehicle = &vehicle;
    std::thread::scope(|s| {
        s.spawn(move || {
            // iceoryx2's ports stay in their thread: a sender of another program, kept until
            // its sample is taken (its shared memory goes with it).
            let gui = Participant::join(vehicle, Role::program("GUI").unwrap()).unwrap();
            let tx = gui.event_sender().unwrap();
            std::thread::sleep(Duration::from_millis(20));
            tx.send(&EventMsg::new("depth", vec![Value::Int(9)]))
                .unwrap();
            let _ = wait_done.recv_timeout(Duration::from_secs(30));
        });
        // Woken by the new sender's arrival, then by its sample.
        let r = loop {
            let r = reactor.wait(&[&rx], Some(Duration::from_secs(10))).unwrap();
            if r.timed_out() || rx.has_pending() {
                break r;
            }
            rx.take_wakeups().unwrap();
        };
        assert!(
            !r.timed_out(),
            "a new sample did not wake the sleeping receiver"
        );
        let got = rx.try_recv().unwrap().expect("the sample that woke it");
        assert_eq!(got.msg.params, vec![Value::Int(9)]);
        done.send(()).unwrap();
    });
}

#[test]
fn a_sender_made_before_the_player_has_fixed_samples_and_loses_nothing_when_it_leaves() {
    let vehicle = TestVehicle::new("early");
    // The program comes first: it creates the events service, with no bound.
    let gui = Participant::join(&vehicle, Role::program("GUI").unwrap()).unwrap();
    let tx = gui.event_sender_sized().unwrap();
    assert_eq!(tx.fixed_len(), Some(MIN_FIXED_LEN));
    // The player opens it as it is (its bound cannot be recorded any more).
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let events = player.event_receiver_sized(40, 1).unwrap();
    assert_eq!(player.max_event_len().unwrap(), None);
    // A long event goes in pieces.
    let text = EventMsg::new("log", vec![Value::Text("é".repeat(10_000))]);
    tx.send(&text).unwrap();
    assert_eq!(events.try_recv().unwrap().unwrap().msg, text);
    // A later sender of the same process reads no bound either, and its events outlive it:
    // sent, then gone before the player reads (a growing sender's would go with it).
    let late = gui.event_sender_sized().unwrap();
    assert_eq!(late.fixed_len(), Some(MIN_FIXED_LEN));
    assert!(!events.has_pending());
    let last = EventMsg::new("bye", vec![Value::Int(7)]);
    late.send(&last).unwrap();
    late.send(&text).unwrap();
    drop(late);
    drop(tx);
    drop(gui);
    let got: Vec<_> = std::iter::from_fn(|| events.try_recv().unwrap())
        .map(|r| r.msg)
        .collect();
    assert_eq!(got, vec![last, text]);
}

#[test]
fn the_players_events_service_takes_its_programs_and_the_spare_then_refuses_clearly() {
    let vehicle = TestVehicle::new("fullev");
    // A project of two programs: the player makes the service for 2 + the spare senders.
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let events = player.event_receiver_sized(40, 2).unwrap();
    let max = 2 + EVENT_SENDERS_SPARE;
    // Programs open it with their default spec (which asks for more senders than it has),
    // sized or not; every one of the `max` delivers.
    let programs: Vec<_> = (0..max)
        .map(|i| Participant::join(&vehicle, Role::program(&format!("P{i}")).unwrap()).unwrap())
        .collect();
    let mut senders: Vec<_> = programs
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if i % 2 == 0 {
                p.event_sender_sized().unwrap()
            } else {
                p.event_sender().unwrap()
            }
        })
        .collect();
    let ping = EventMsg::new("ping", vec![Value::Int(1)]);
    for tx in &senders {
        tx.send(&ping).unwrap();
    }
    let got: Vec<_> = std::iter::from_fn(|| events.try_recv().unwrap()).collect();
    assert_eq!(got.len(), max);

    // One more is refused, saying how many the service takes and why.
    let late = Participant::join(&vehicle, Role::program("LATE").unwrap()).unwrap();
    let Err(error) = late.event_sender_sized() else {
        panic!("a sender beyond the service's senders is refused");
    };
    assert_eq!(
        error,
        SetupError::SendersFull {
            service: vehicle.events_service(),
            max,
        }
    );
    let text = error.to_string();
    assert!(text.contains(&format!("it takes {max} senders")), "{text}");
    assert!(text.contains("restarted"), "{text}");

    // A sender gone frees its place.
    senders.pop();
    let tx = late.event_sender_sized().unwrap();
    tx.send(&ping).unwrap();
    assert_eq!(events.try_recv().unwrap().unwrap().sender, tx.sender_id());
}

#[test]
fn samples_of_senders_gone_before_they_were_read_all_arrive() {
    // The player keeps the connections of as many senders gone as its events service takes
    // (twice, 32 at least): twenty tools that each emit one event and leave before the player
    // reads lose nothing. (A sender gone before the receiver ever looked was never connected:
    // iceoryx2 delivers nothing of it, whatever the buffer; the SDK's senders wait for the
    // player's acknowledgement.)
    let vehicle = TestVehicle::new("gone");
    let player = Participant::join_player(&vehicle, 1).unwrap();
    let events = player.event_receiver_sized(40, 1).unwrap();
    for round in 0..2 {
        let joined: Vec<_> = (0..10)
            .map(|k| {
                let me = Participant::join(&vehicle, Role::tool(&format!("e{round}_{k}")).unwrap())
                    .unwrap();
                let tx = me.event_sender_sized().unwrap();
                (me, tx)
            })
            .collect();
        // The player looks (and connects to them, reading nothing), then they emit and leave.
        assert_eq!(events.has_pending(), round > 0);
        for (k, (_, tx)) in joined.iter().enumerate() {
            tx.send(&EventMsg::new(
                "ping",
                vec![Value::Int(round * 10 + k as i64)],
            ))
            .unwrap();
        }
        // Gone before the player reads: ten connections kept for their unread events.
        drop(joined);
    }
    let got: Vec<_> = std::iter::from_fn(|| events.try_recv().unwrap())
        .map(|r| r.msg.params[0].clone())
        .collect();
    let mut got: Vec<i64> = got
        .into_iter()
        .map(|v| match v {
            Value::Int(i) => i,
            other => panic!("{other:?}"),
        })
        .collect();
    got.sort_unstable();
    assert_eq!(got, (0..20).collect::<Vec<_>>());

    // A program keeps PROGRAM_SENDERS_GONE: three rounds of four callers (all the calls
    // service takes at once) that call and leave before it reads.
    let pln = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
    let calls = pln.call_receiver().unwrap();
    let mut sent = 0;
    for round in 0..3 {
        let callers: Vec<_> = (0..4)
            .map(|k| {
                let me = Participant::join(&vehicle, Role::tool(&format!("c{round}_{k}")).unwrap())
                    .unwrap();
                // Fixed samples: a growing sender's unread samples go with it (its segments
                // are removed when it leaves, whatever the receiver keeps).
                let tx = me.call_sender_sized("PLN", Some(64)).unwrap();
                (me, tx)
            })
            .collect();
        assert_eq!(calls.has_pending(), round > 0);
        for (_, tx) in &callers {
            tx.send(&CallMsg::new("go", vec![Value::Int(sent)]))
                .unwrap();
            sent += 1;
        }
        drop(callers);
    }
    let got = std::iter::from_fn(|| calls.try_recv().unwrap()).count();
    assert_eq!(got, 12);
    const {
        assert!(
            3 * 4 <= PROGRAM_SENDERS_GONE,
            "the test covers what a program keeps"
        )
    };
}

#[test]
fn a_sized_marking_publisher_sends_a_long_step_in_pieces_every_monitor_joins() {
    let vehicle = TestVehicle::new("pieces");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let publisher = player.marking_publisher_sized(600).unwrap();
    assert_eq!(publisher.fixed_len(), Some(600));
    let monitors: Vec<_> = (0..2)
        .map(|i| {
            let me = Participant::join(&vehicle, Role::tool(&format!("mon{i}")).unwrap()).unwrap();
            let sub = me.marking_subscriber().unwrap();
            (me, sub)
        })
        .collect();
    let short = MarkingMsg {
        step: 1,
        fired: vec!["MISSION.t1".into()],
        ..MarkingMsg::default()
    };
    // A step whose actions take 5,000 bytes: 9 pieces of 600.
    let long = MarkingMsg {
        step: 2,
        actions: vec!["call GUI.say(\"".to_owned() + &"z".repeat(5_000) + "\")"],
        ..MarkingMsg::default()
    };
    let first = publisher.send(&short).unwrap().seq;
    let last = publisher.send(&long).unwrap().seq;
    publisher.send(&short).unwrap();
    assert_eq!(
        last - first,
        9,
        "nine pieces, the last one numbering the step"
    );
    for (_, sub) in &monitors {
        let got: Vec<_> = std::iter::from_fn(|| sub.try_recv().unwrap())
            .map(|r| r.msg)
            .collect();
        assert_eq!(got, vec![short.clone(), long.clone(), short.clone()]);
        assert_eq!(sub.stats().missing, 0);
    }
}

/// A receiver whose connection to a new sender failed once connects again: the sender's data
/// segment was not there when the receiver looked (as when the sender's process, creating it,
/// is not scheduled within iceoryx2's creation timeout on a loaded machine). iceoryx2 retries a
/// connection only when the list of senders changes, so the sender's samples, delivered and
/// counted, were never seen: a blocking receiver slept for ever (issue 38's CI failure).
#[test]
fn a_receiver_whose_connection_to_a_sender_failed_connects_again() {
    let vehicle = TestVehicle::new("auv");
    let (player, pln) = pair(&vehicle);
    let rx = player.event_receiver().unwrap();
    assert!(!rx.has_pending());
    let prefix = vehicle.shm_prefix().unwrap();
    let files = || -> std::collections::BTreeSet<String> {
        std::fs::read_dir("/dev/shm")
            .unwrap()
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(&prefix))
            .collect()
    };
    let before = files();
    let tx = pln.event_sender().unwrap();
    // The sender's data segment (its management part and its first segment).
    let segment: Vec<_> = files()
        .difference(&before)
        .filter(|n| n.ends_with(".data"))
        .map(|n| std::path::Path::new("/dev/shm").join(n))
        .collect();
    assert_eq!(segment.len(), 2, "{segment:?}");
    let hidden = |p: &std::path::Path| p.with_extension("hidden");
    for path in &segment {
        std::fs::rename(path, hidden(path)).unwrap();
    }
    // The receiver looks (its connection to the new sender fails), then the segment is back.
    assert!(!rx.has_pending());
    for path in &segment {
        std::fs::rename(hidden(path), path).unwrap();
    }
    let sent = tx
        .send(&EventMsg::new("depth", vec![Value::Int(7)]))
        .unwrap();
    assert_eq!(sent.delivered, 1, "the sender reached the receiver");
    // A blocking reactor wakes for it (the sender rang, or the retry came due), however many
    // wake-ups it takes.
    let reactor = Reactor::without_signal_handling(WaitStrategy::Block).unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    let got = loop {
        if let Some(got) = rx.try_recv().unwrap() {
            break got;
        }
        let left = deadline.saturating_duration_since(Instant::now());
        assert!(
            !left.is_zero(),
            "the receiver never saw the delivered sample"
        );
        reactor.wait(&[&rx], Some(left)).unwrap();
    };
    assert_eq!(got.msg, EventMsg::new("depth", vec![Value::Int(7)]));
    assert_eq!(got.missed, 0);
    assert!(rx.stats().reconnects >= 1, "{:?}", rx.stats());
}
