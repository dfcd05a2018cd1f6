//! Real iceoryx2 between real processes: the test binary runs itself again as a child
//! (test `child`, with `PETREL_IPC_CHILD` naming what to do), on the same isolated vehicle.
//!
//! The child reports on its standard output with lines starting `@@ `, and exits when its
//! standard input closes (or is killed).

mod common;

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use common::{child_role, wait_for_stdin_close, ChildProcess, TestVehicle};
use petrel_ipc::{
    cleanup_dead_nodes, dead_nodes, list_nodes, program_status, EventMsg, NodeStatus, Participant,
    ProgramStatus, ProgramWatch, Reactor, RecvError, Role, SendError, Value, WaitStrategy,
};

/// A burst as large as the player's event buffer (2,048: ipc/src/port.rs sizes it for the
/// memory it costs every program).
const BURST: usize = petrel_ipc::port::EVENTS.subscriber_buffer;
const TIMEOUT: Duration = Duration::from_secs(60);

/// One event per kind of value, and all of them together.
fn value_events() -> Vec<EventMsg> {
    let values = vec![
        Value::Int(-7),
        Value::Int(i64::MIN),
        Value::Float(2.5),
        Value::Float(-0.0),
        Value::Bool(true),
        Value::Bool(false),
        Value::Text("surface".into()),
        Value::Text("ünïcødé ✓".into()),
        Value::FloatList(vec![43.1, 5.9, -120.0]),
        Value::FloatList(vec![]),
    ];
    let mut events: Vec<EventMsg> = values
        .iter()
        .map(|v| EventMsg::new(format!("got_{}", v.type_name()), vec![v.clone()]))
        .collect();
    events.push(EventMsg::new("all", values));
    events.push(EventMsg::new("none", vec![]));
    events
}

// ---------------------------------------------------------------------------------------------
// Child side

/// Runs as a child process when `PETREL_IPC_CHILD` is set; otherwise does nothing.
#[test]
fn child() {
    let Some((mode, vehicle, _)) = child_role() else {
        return;
    };
    match mode.as_str() {
        "values" => {
            let me = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
            let tx = me.event_sender().unwrap();
            for event in value_events() {
                tx.send(&event).unwrap();
            }
            report_and_wait(&tx.stats());
        }
        "burst" => {
            let me = Participant::join(&vehicle, Role::CanBridge).unwrap();
            let tx = me.event_sender().unwrap();
            for i in 0..BURST {
                let event = EventMsg::new("ping", vec![Value::Int(i as i64)]);
                // Refusals are counted in the stats and reported.
                let _ = tx.send(&event);
            }
            report_and_wait(&tx.stats());
        }
        "garbage" => {
            let me = Participant::join(&vehicle, Role::program("GUI").unwrap()).unwrap();
            let tx = me.event_sender().unwrap();
            tx.send(&EventMsg::new("before", vec![])).unwrap();
            tx.send_encoded(&[0xFB, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x7F])
                .unwrap();
            tx.send_encoded(b"").unwrap();
            tx.send(&EventMsg::new("after", vec![Value::Bool(true)]))
                .unwrap();
            report_and_wait(&tx.stats());
        }
        "sleeper" => {
            let me = Participant::join(&vehicle, Role::program("GDD").unwrap()).unwrap();
            let tx = me.event_sender().unwrap();
            let _calls = me.call_receiver().unwrap();
            tx.send(&EventMsg::new("gdd_ready", vec![])).unwrap();
            println!("@@ READY");
            wait_for_stdin_close();
        }
        "other_vehicle" => {
            let me = Participant::join(&vehicle, Role::program("PLN").unwrap()).unwrap();
            let tx = me.event_sender().unwrap();
            let outcome = match tx.send(&EventMsg::new("hello", vec![])) {
                Err(SendError::NoReceiver { .. }) => "no_receiver",
                Ok(_) => "delivered",
                Err(_) => "other_error",
            };
            let names: Vec<String> = list_nodes(&vehicle)
                .unwrap()
                .into_iter()
                .map(|n| n.name)
                .collect();
            println!("@@ OUTCOME {outcome}");
            println!("@@ NODES {}", names.join(","));
            wait_for_stdin_close();
        }
        other => panic!("unknown child mode {other}"),
    }
}

fn report_and_wait(stats: &petrel_ipc::SenderStats) {
    println!(
        "@@ SENT {} {} {}",
        stats.sent, stats.refused, stats.not_sent
    );
    wait_for_stdin_close();
}

// ---------------------------------------------------------------------------------------------
// Parent side

/// The next report starting with `word`, without it.
fn expect(child: &ChildProcess, word: &str) -> String {
    child.report(word, TIMEOUT)
}

/// Reads "SENT sent refused not_sent".
fn sent(child: &ChildProcess) -> (u64, u64, u64) {
    let report = expect(child, "SENT");
    let n: Vec<u64> = report.split(' ').map(|x| x.parse().unwrap()).collect();
    (n[0], n[1], n[2])
}

/// Drains `rx` with a blocking reactor until `n` messages and errors arrived.
fn collect_events(
    rx: &petrel_ipc::EventReceiver,
    n: usize,
) -> Vec<Result<petrel_ipc::Received<EventMsg>, RecvError>> {
    let reactor = Reactor::without_signal_handling(WaitStrategy::Block).unwrap();
    let start = Instant::now();
    let mut out = Vec::new();
    while out.len() < n {
        assert!(
            start.elapsed() < TIMEOUT,
            "only {} of {n} arrived",
            out.len()
        );
        let ready = reactor
            .wait(&[rx], Some(Duration::from_millis(200)))
            .unwrap();
        if ready.is_ready(0) {
            rx.drain(|r| out.push(r)).unwrap();
        }
    }
    out
}

fn shm_files(prefix: &str) -> BTreeSet<String> {
    std::fs::read_dir("/dev/shm")
        .map(|dir| {
            dir.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with(prefix))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn every_value_type_crosses_processes() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let rx = player.event_receiver().unwrap();
    let child = ChildProcess::spawn(&vehicle, "values", "");
    let expected = value_events();
    let got = collect_events(&rx, expected.len());
    for (i, (r, want)) in got.into_iter().zip(&expected).enumerate() {
        let r = r.unwrap();
        assert_eq!(&r.msg, want);
        assert_eq!(r.seq, i as u64 + 1);
        assert_eq!(r.missed, 0);
        assert_eq!(r.origin.as_str(), "program/PLN");
    }
    let (sent, refused, not_sent) = sent(&child);
    assert_eq!((sent, refused, not_sent), (expected.len() as u64, 0, 0));
    assert_eq!(rx.stats().received, sent);
    child.finish();
}

#[test]
fn a_burst_the_size_of_the_buffer_is_fully_received() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let rx = player.event_receiver().unwrap();
    let child = ChildProcess::spawn(&vehicle, "burst", "");
    // The player reads nothing until the whole burst is sent: the buffer must hold it.
    let (sent, refused, not_sent) = sent(&child);
    assert_eq!((sent, refused, not_sent), (BURST as u64, 0, 0));
    let mut next = 0i64;
    let drained = rx
        .drain(|r| {
            let r = r.unwrap();
            assert_eq!(r.msg.params, vec![Value::Int(next)]);
            assert_eq!(r.seq, next as u64 + 1);
            assert_eq!(r.missed, 0);
            next += 1;
        })
        .unwrap();
    assert_eq!(drained.messages, BURST);
    let stats = rx.stats();
    assert_eq!(sent, stats.received + refused);
    assert_eq!((stats.missing, stats.undecodable), (0, 0));
    let accounts = rx.senders();
    assert_eq!(accounts.len(), 1);
    assert_eq!(accounts[0].origin.as_str(), "can_bridge");
    assert_eq!(accounts[0].last_seq, BURST as u64);
    child.finish();
}

#[test]
fn an_undecodable_body_is_a_typed_error_and_the_receiver_carries_on() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let rx = player.event_receiver().unwrap();
    let child = ChildProcess::spawn(&vehicle, "garbage", "");
    let got = collect_events(&rx, 4);
    assert_eq!(got[0].as_ref().unwrap().msg.name, "before");
    for (r, seq) in got[1..3].iter().zip([2, 3]) {
        match r {
            Err(e @ RecvError::Undecodable { seq: s, origin, .. }) => {
                assert_eq!(*s, seq);
                assert_eq!(origin.as_str(), "program/GUI");
                assert!(e.to_string().contains("program/GUI"), "{e}");
            }
            other => panic!("expected an undecodable body, got {other:?}"),
        }
    }
    let last = got[3].as_ref().unwrap();
    assert_eq!(last.msg, EventMsg::new("after", vec![Value::Bool(true)]));
    assert_eq!((last.seq, last.missed), (4, 0));
    let stats = rx.stats();
    assert_eq!(
        (stats.received, stats.undecodable, stats.missing),
        (4, 2, 0)
    );
    let (sent, refused, _) = sent(&child);
    assert_eq!(sent, stats.received + refused);
    child.finish();
}

#[test]
fn a_sigkilled_program_is_reported_dead_and_cleaned() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let rx = player.event_receiver().unwrap();
    let mut watch = ProgramWatch::new(&player, ["GDD", "PLN"]).unwrap();
    assert!(watch.check().unwrap().is_empty());
    let before = shm_files(&vehicle.shm_prefix().unwrap());
    let mut child = ChildProcess::spawn(&vehicle, "sleeper", "");
    expect(&child, "READY");
    let changes = watch.check().unwrap();
    assert_eq!(changes.len(), 1);
    assert_eq!(
        (changes[0].program.as_str(), changes[0].to),
        ("GDD", ProgramStatus::Alive)
    );
    assert_eq!(
        program_status(&vehicle, "GDD").unwrap(),
        ProgramStatus::Alive
    );
    let pid = child.id() as i32;
    let nodes = list_nodes(&vehicle).unwrap();
    let gdd = nodes.iter().find(|n| n.name == "program/GDD").unwrap();
    assert_eq!((gdd.status, gdd.pid), (NodeStatus::Alive, Some(pid)));
    let with_child = shm_files(&vehicle.shm_prefix().unwrap());
    // A service's change counter of receivers (`rx_`) is the vehicle's, not the node's: it
    // stays while the vehicle lives, whoever created it (ipc/src/doorbell.rs, `Changes`).
    let child_files: Vec<_> = with_child
        .difference(&before)
        .filter(|f| !f.contains("_rx_"))
        .cloned()
        .collect();
    assert!(!child_files.is_empty());
    assert_eq!(
        collect_events(&rx, 1)[0].as_ref().unwrap().msg.name,
        "gdd_ready"
    );
    assert!(rx.take_wakeups().unwrap().senders_died == 0);

    child.kill(); // SIGKILL: no chance to clean up

    assert_eq!(
        program_status(&vehicle, "GDD").unwrap(),
        ProgramStatus::Dead
    );
    let lost = watch.check().unwrap();
    assert!(lost.len() == 1 && lost[0].is_lost(), "{lost:?}");
    assert_eq!(lost[0].to, ProgramStatus::Dead);
    let dead = dead_nodes(&vehicle).unwrap();
    assert_eq!(dead.len(), 1);
    assert_eq!(
        (dead[0].name.as_str(), dead[0].pid),
        ("program/GDD", Some(pid))
    );
    let left = shm_files(&vehicle.shm_prefix().unwrap());
    assert!(
        child_files.iter().any(|f| left.contains(f)),
        "the killed child left nothing behind?"
    );

    let report = cleanup_dead_nodes(&vehicle, Duration::from_secs(1)).unwrap();
    assert_eq!(report.cleaned.len(), 1, "{report:?}");
    assert!(report.failed.is_empty(), "{report:?}");
    assert_eq!(
        program_status(&vehicle, "GDD").unwrap(),
        ProgramStatus::Absent
    );
    // The connection between the dead sender and the player goes when the player's side next
    // updates its connections (any receive does).
    assert!(rx.try_recv().unwrap().is_none());
    let after = shm_files(&vehicle.shm_prefix().unwrap());
    let remaining: Vec<_> = child_files.iter().filter(|f| after.contains(*f)).collect();
    assert!(remaining.is_empty(), "not cleaned: {remaining:?}");
    // The player hears of the death through its event service.
    assert!(rx.take_wakeups().unwrap().senders_died >= 1);
    // The program can come back: its call service accepts a receiver again.
    let again = Participant::join(&vehicle, Role::program("GDD").unwrap()).unwrap();
    again.call_receiver().unwrap();
}

#[test]
fn two_vehicles_with_different_prefixes_do_not_meet() {
    let ours = TestVehicle::new("auv");
    let theirs = TestVehicle::new("auv");
    assert_eq!(ours.events_service(), theirs.events_service());
    let player = Participant::join(&ours, Role::Player).unwrap();
    let rx = player.event_receiver().unwrap();
    let child = ChildProcess::spawn(&theirs, "other_vehicle", "");
    assert_eq!(expect(&child, "OUTCOME"), "no_receiver");
    assert_eq!(expect(&child, "NODES"), "program/PLN");
    let our_nodes: Vec<String> = list_nodes(&ours)
        .unwrap()
        .into_iter()
        .map(|n| n.name)
        .collect();
    assert_eq!(our_nodes, ["player"]);
    assert_eq!(
        program_status(&theirs, "PLN").unwrap(),
        ProgramStatus::Alive
    );
    assert_eq!(program_status(&ours, "PLN").unwrap(), ProgramStatus::Absent);
    std::thread::sleep(Duration::from_millis(20));
    assert!(rx.try_recv().unwrap().is_none());
    assert_eq!(rx.take_wakeups().unwrap(), petrel_ipc::Wakeups::default());
    child.finish();
}
