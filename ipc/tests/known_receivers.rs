//! A sender rings the doorbells of the receivers it listed last time, and lists iceoryx2's
//! subscribers again only when the service's change counter moved (ipc/src/doorbell.rs,
//! `Bells`): a receiver that joins, or replaces one that left, in this process or another,
//! must still be woken from its doorbell sleep by the next send; a receiver killed without
//! warning must neither fail nor stall the sends; refusals are counted as before.
//!
//! Receivers sleep without a timeout and with a doorbell slice of an hour, so that a lost
//! wake-up stalls them: the test is the watchdog, and fails when a message does not arrive
//! within a generous deadline. The sender's safety-net listing is put an hour apart, so that
//! only the change counter (or more deliveries than known receivers) makes it list again.
//! Marking deltas are the service: it has several receivers.

mod common;

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{child_role, wait_for_stdin_close, ChildProcess, TestVehicle};
use petrel_ipc::{
    cleanup_dead_nodes, MarkingMsg, MarkingPublisher, Participant, Reactor, Role, SendError,
    Vehicle, WaitStrategy,
};

/// The watchdog: far beyond what a delivery takes, far below the receivers' hour-long slice.
const DEADLINE: Duration = Duration::from_secs(60);

fn delta(step: u64) -> MarkingMsg {
    MarkingMsg {
        step,
        fired: vec!["mission.t1".into()],
        ..MarkingMsg::default()
    }
}

/// The names of the vehicle's doorbells in /dev/shm.
fn doorbells(vehicle: &Vehicle) -> BTreeSet<PathBuf> {
    let prefix = format!("{}db_", vehicle.shm_prefix().unwrap());
    std::fs::read_dir("/dev/shm")
        .map(|dir| {
            dir.filter_map(Result::ok)
                .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
                .map(|e| e.path())
                .collect()
        })
        .unwrap_or_default()
}

/// Waits until the receiver of the doorbell at `path` sleeps on it: its mode (the page's
/// second 32-bit word, ipc/src/doorbell.rs) says `FUTEX` (2). A send made afterwards can only
/// reach the receiver by ringing its doorbell.
fn wait_until_asleep(path: &PathBuf) {
    let start = Instant::now();
    loop {
        let page = std::fs::read(path).unwrap();
        if page.get(4..8) == Some(&2u32.to_ne_bytes()[..]) {
            return;
        }
        assert!(
            start.elapsed() < DEADLINE,
            "the receiver never slept on its doorbell"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// The one doorbell in `after` that is not in `before`.
fn new_doorbell(before: &BTreeSet<PathBuf>, after: &BTreeSet<PathBuf>) -> PathBuf {
    let new: Vec<_> = after.difference(before).collect();
    assert_eq!(new.len(), 1, "{before:?} -> {after:?}");
    new[0].clone()
}

/// A monitor: subscribes, says it is ready (its doorbell made), then sleeps on its doorbell
/// without a timeout and hands over the steps of `n` deltas.
fn monitor(vehicle: &Vehicle, n: usize, ready: mpsc::Sender<()>, steps: mpsc::Sender<u64>) {
    let me = Participant::join(vehicle, Role::tool("monitor").unwrap()).unwrap();
    let rx = me.marking_subscriber().unwrap();
    assert!(rx.has_doorbell());
    let mut reactor = Reactor::without_signal_handling(WaitStrategy::Block).unwrap();
    reactor.set_doorbell_slice(Duration::from_secs(3_600));
    // One look first: the listener is read, the receiver then sleeps on its doorbell.
    reactor.wait(&[&rx], Some(Duration::ZERO)).unwrap();
    ready.send(()).unwrap();
    let mut got = 0;
    while got < n {
        reactor.wait(&[&rx], None).unwrap();
        rx.drain(|r| {
            let _ = steps.send(r.unwrap().msg.step);
            got += 1;
        })
        .unwrap();
    }
}

/// Starts `monitor` on a thread of its own (ports are not `Send`) and waits until it sleeps
/// on its doorbell; returns the steps it gets, and its doorbell.
fn sleeping_monitor(vehicle: &Vehicle, n: usize) -> (mpsc::Receiver<u64>, PathBuf) {
    let before = doorbells(vehicle);
    let (ready, is_ready) = mpsc::channel();
    let (steps, got) = mpsc::channel();
    let own = vehicle.clone();
    // Detached: should a wake-up be lost, the test fails at its deadline instead of hanging.
    std::thread::spawn(move || monitor(&own, n, ready, steps));
    is_ready.recv_timeout(DEADLINE).unwrap();
    let doorbell = new_doorbell(&before, &doorbells(vehicle));
    wait_until_asleep(&doorbell);
    (got, doorbell)
}

fn expect_step(got: &mpsc::Receiver<u64>, step: u64) {
    assert_eq!(got.recv_timeout(DEADLINE), Ok(step), "delta {step} lost");
}

// ---------------------------------------------------------------------------------------------
// Child side

/// Runs as a child process when `PETREL_IPC_CHILD` is set; otherwise does nothing.
#[test]
fn child() {
    let Some((mode, vehicle, arg)) = child_role() else {
        return;
    };
    match mode.as_str() {
        "monitor" => {
            let n: usize = arg.parse().unwrap();
            let (ready, is_ready) = mpsc::channel();
            let (steps, got) = mpsc::channel();
            let vehicle2 = vehicle.clone();
            let thread = std::thread::spawn(move || monitor(&vehicle2, n, ready, steps));
            is_ready.recv().unwrap();
            println!("@@ READY");
            for step in got {
                println!("@@ GOT {step}");
            }
            thread.join().unwrap();
            wait_for_stdin_close();
        }
        other => panic!("unknown child mode {other}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Parent side

/// Each of `steps` sent to the one monitor `monitor` listens as, delivered to it, then the
/// monitor (which takes that many) leaves.
fn deliver_then_gone(
    publisher: &MarkingPublisher,
    monitor: &mpsc::Receiver<u64>,
    steps: impl IntoIterator<Item = u64>,
) {
    for step in steps {
        let sent = publisher.send(&delta(step)).unwrap();
        assert_eq!(sent.delivered, 1);
        expect_step(monitor, step);
    }
    assert_eq!(
        monitor.recv_timeout(DEADLINE),
        Err(mpsc::RecvTimeoutError::Disconnected)
    );
}

/// The player's marking publisher, which lists the monitors again only when the change
/// counter tells it to (its safety-net period an hour).
fn counting_publisher(vehicle: &Vehicle) -> (Participant, MarkingPublisher) {
    let player = Participant::join(vehicle, Role::Player).unwrap();
    let publisher = player.marking_publisher().unwrap();
    publisher.set_listing_period(Duration::from_secs(3_600));
    (player, publisher)
}

/// The publisher of the player, and a first monitor it has delivered to (and so listed).
fn publisher_with_a_listed_monitor(
    vehicle: &Vehicle,
) -> (Participant, MarkingPublisher, mpsc::Receiver<u64>) {
    let (player, publisher) = counting_publisher(vehicle);
    let (first, _) = sleeping_monitor(vehicle, 1);
    publisher.send(&delta(0)).unwrap();
    expect_step(&first, 0);
    (player, publisher, first)
}

#[test]
fn a_monitor_that_joins_after_a_send_is_woken_by_the_next_one() {
    let vehicle = TestVehicle::new("auv");
    let (_player, publisher) = counting_publisher(&vehicle);
    // Sent to nobody, then to one monitor: the sender has listed the receivers.
    assert!(matches!(
        publisher.send(&delta(0)),
        Err(SendError::NoReceiver { .. })
    ));
    let (first, first_doorbell) = sleeping_monitor(&vehicle, 2);
    publisher.send(&delta(1)).unwrap();
    expect_step(&first, 1);
    let (second, _) = sleeping_monitor(&vehicle, 1);
    wait_until_asleep(&first_doorbell);
    let sent = publisher.send(&delta(2)).unwrap();
    assert_eq!(sent.delivered, 2);
    expect_step(&second, 2);
    expect_step(&first, 2);
    // Both took their last delta and left.
    for got in [first, second] {
        assert_eq!(
            got.recv_timeout(DEADLINE),
            Err(mpsc::RecvTimeoutError::Disconnected)
        );
    }
    let stats = publisher.stats();
    assert_eq!((stats.sent, stats.delivered, stats.refused), (3, 2, 1));
    assert_eq!(
        stats.notified, 0,
        "a doorbell sleeper was notified through iceoryx2"
    );
}

/// The case only the change counter tells: as many receivers as before, one of them new.
#[test]
fn a_monitor_dropped_and_replaced_in_this_process_is_rung() {
    let vehicle = TestVehicle::new("auv");
    let (_player, publisher, first) = publisher_with_a_listed_monitor(&vehicle);
    // The first monitor took its one delta and is gone (its thread ended, its doorbell too).
    assert_eq!(
        first.recv_timeout(DEADLINE),
        Err(mpsc::RecvTimeoutError::Disconnected)
    );
    let start = Instant::now();
    while !doorbells(&vehicle).is_empty() {
        assert!(start.elapsed() < DEADLINE, "the first monitor never left");
        std::thread::sleep(Duration::from_millis(1));
    }
    for step in 1..4 {
        let (next, _) = sleeping_monitor(&vehicle, 1);
        deliver_then_gone(&publisher, &next, [step]);
    }
    assert_eq!(publisher.stats().notified, 0);
}

#[test]
fn a_monitor_replaced_by_one_of_another_process_is_rung() {
    let vehicle = TestVehicle::new("auv");
    let (_player, publisher) = counting_publisher(&vehicle);
    for step in 0..3 {
        let before = doorbells(&vehicle);
        let child = ChildProcess::spawn(&vehicle, "monitor", "1");
        assert_eq!(child.report("READY", DEADLINE), "");
        wait_until_asleep(&new_doorbell(&before, &doorbells(&vehicle)));
        let sent = publisher.send(&delta(step)).unwrap();
        assert_eq!(sent.delivered, 1);
        assert_eq!(child.report("GOT", DEADLINE), step.to_string());
        child.finish();
    }
    let stats = publisher.stats();
    assert_eq!((stats.sent, stats.delivered, stats.notified), (3, 3, 0));
}

#[test]
fn a_killed_monitor_neither_fails_nor_stalls_the_sends() {
    let vehicle = TestVehicle::new("auv");
    let (_player, publisher) = counting_publisher(&vehicle);
    let before = doorbells(&vehicle);
    let mut child = ChildProcess::spawn(&vehicle, "monitor", "1000000");
    assert_eq!(child.report("READY", DEADLINE), "");
    wait_until_asleep(&new_doorbell(&before, &doorbells(&vehicle)));
    publisher.send(&delta(0)).unwrap();
    assert_eq!(child.report("GOT", DEADLINE), "0");
    child.kill(); // SIGKILL: no drop, its doorbell and subscriber stay
                  // Past the dead monitor's buffer: delivered while it has room, refused after.
    let buffer = publisher.spec().subscriber_buffer as u64;
    let mut refused = 0;
    for step in 1..=buffer + 10 {
        match publisher.send(&delta(step)) {
            Ok(_) => {}
            Err(SendError::Refused { .. } | SendError::NoReceiver { .. }) => refused += 1,
            Err(e) => panic!("{e}"),
        }
    }
    assert!(refused >= 10, "{refused}");
    let stats = publisher.stats();
    assert_eq!(stats.sent, buffer + 11);
    assert_eq!(stats.sent, stats.delivered + stats.refused);
    let report = cleanup_dead_nodes(&vehicle, Duration::from_secs(1)).unwrap();
    assert!(report.failed.is_empty(), "{report:?}");
    // The dead monitor is forgotten: a new one gets everything, and nothing is refused.
    let (next, _) = sleeping_monitor(&vehicle, 2);
    deliver_then_gone(&publisher, &next, [500, 501]);
}

/// A monitor whose buffer is full is refused, counted, and the others still get everything,
/// also after the set of monitors changed.
#[test]
fn refusals_are_counted_when_a_listed_monitor_is_full() {
    let vehicle = TestVehicle::new("auv");
    let (_player, publisher) = counting_publisher(&vehicle);
    let monitor = Participant::join(&vehicle, Role::tool("monitor").unwrap()).unwrap();
    let fast = monitor.marking_subscriber().unwrap();
    let slow = monitor.marking_subscriber().unwrap();
    let buffer = publisher.spec().subscriber_buffer as u64;
    let mut partial = 0;
    let mut send = |step| match publisher.send(&delta(step)) {
        Ok(sent) => sent.delivered,
        Err(SendError::Refused {
            delivered,
            receivers,
            ..
        }) => {
            partial += 1;
            assert!(delivered < receivers);
            delivered
        }
        Err(e) => panic!("{e}"),
    };
    for step in 0..buffer + 3 {
        send(step);
        while fast.try_recv().unwrap().is_some() {}
    }
    // A third monitor joins: the full one is still refused, the two others get the deltas.
    let late = monitor.marking_subscriber().unwrap();
    for step in buffer + 3..buffer + 6 {
        assert_eq!(send(step), 2);
        while fast.try_recv().unwrap().is_some() {}
    }
    drop(late);
    assert_eq!(send(buffer + 6), 1);
    while fast.try_recv().unwrap().is_some() {}
    assert_eq!(partial, 7);
    let stats = publisher.stats();
    assert_eq!(
        (stats.sent, stats.delivered, stats.refused),
        (buffer + 7, buffer, 7)
    );
    assert_eq!(fast.stats().received, buffer + 7);
    let mut n = 0;
    slow.drain(|r| {
        r.unwrap();
        n += 1;
    })
    .unwrap();
    assert_eq!(n, buffer);
}
