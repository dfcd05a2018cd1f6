//! Doorbells between real processes (ipc/src/doorbell.rs): several senders and one sleeping
//! receiver, every message must arrive; a receiver that also watches a file descriptor still
//! wakes; a killed receiver leaves no doorbell behind once dead nodes are cleaned up.
//!
//! The receiver runs in a child process whose reactor sleeps without a timeout and with a
//! doorbell slice of an hour, so that a lost wake-up stalls it: the parent is the watchdog, and
//! fails the test when the receiver's report does not come within a generous deadline (the
//! children are killed, the vehicle's files removed).

mod common;

use std::collections::{BTreeSet, HashMap};
use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::net::UnixStream;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{child_role, wait_for_stdin_close, ChildProcess, TestVehicle};
use petrel_ipc::{
    cleanup_dead_nodes, EventMsg, FdSource, Participant, Reactor, Role, Source, Value, Vehicle,
    WaitStrategy,
};

/// Messages per sender.
const PER_SENDER: usize = 1_500;
const SENDERS: usize = 3;
/// The watchdog: far beyond what the exchange takes (a few seconds), far below the receiver's
/// hour-long doorbell slice.
const DEADLINE: Duration = Duration::from_secs(120);

/// A small deterministic generator (seeded per process) for the gaps between messages.
struct Gaps(u64);

impl Gaps {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// Back to back, a short pause the receiver may or may not sleep through, or a pause long
    /// enough for it to fall asleep.
    fn pause(&mut self) {
        match self.next() % 16 {
            0..=7 => {}
            8..=12 => {
                let until = Instant::now() + Duration::from_micros(self.next() % 60);
                while Instant::now() < until {
                    std::thread::yield_now();
                }
            }
            _ => std::thread::sleep(Duration::from_micros(200 + self.next() % 2_000)),
        }
    }
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
        "receiver" => receive(&vehicle, &arg, false),
        "mixed" => receive(&vehicle, &arg, true),
        "sender" => {
            let me = Participant::join(&vehicle, Role::program(&arg).unwrap()).unwrap();
            let tx = me.event_sender().unwrap();
            let mut gaps = Gaps(0x9E37_79B9_7F4A_7C15 ^ u64::from(std::process::id()));
            for i in 0..PER_SENDER {
                gaps.pause();
                tx.send(&EventMsg::new("tick", vec![Value::Int(i as i64)]))
                    .unwrap();
            }
            let stats = tx.stats();
            println!(
                "@@ SENT {} {} {}",
                stats.sent, stats.refused, stats.notified
            );
            wait_for_stdin_close();
        }
        other => panic!("unknown child mode {other}"),
    }
}

/// The receiver: sleeps (strategy `arg`) without a timeout until every message of every
/// sender arrived; with `mixed`, it also watches a socket a thread of its own writes to now
/// and then, and waits for all of those bytes too.
fn receive(vehicle: &Vehicle, arg: &str, mixed: bool) {
    let me = Participant::join(vehicle, Role::Player).unwrap();
    let rx = me.event_receiver().unwrap();
    assert!(rx.has_doorbell());
    let strategy: WaitStrategy = arg.parse().unwrap();
    let mut reactor = Reactor::without_signal_handling(strategy).unwrap();
    reactor.set_doorbell_slice(Duration::from_secs(3_600));
    // One wait before the senders come: the receiver is then awake or asleep on its doorbell,
    // never on its listener, so that no sender has to notify it through iceoryx2.
    reactor.wait(&[&rx], Some(Duration::ZERO)).unwrap();
    const BYTES: usize = 40;
    let (mut writer, reader) = UnixStream::pair().unwrap();
    reader.set_nonblocking(true).unwrap();
    let fd = FdSource::new(reader.as_raw_fd()).unwrap();
    let poker = mixed.then(|| {
        std::thread::spawn(move || {
            let mut gaps = Gaps(0xD1B5_4A32_D192_ED03);
            for _ in 0..BYTES {
                std::thread::sleep(Duration::from_micros(500 + gaps.next() % 20_000));
                writer.write_all(&[1]).unwrap();
            }
        })
    });
    println!("@@ READY");
    let total = SENDERS * PER_SENDER;
    let mut next: HashMap<u64, i64> = HashMap::new();
    let mut got = 0usize;
    let mut bytes = 0usize;
    let mut buf = [0u8; 64];
    while got < total || (mixed && bytes < BYTES) {
        let sources: Vec<&dyn Source> = if mixed { vec![&rx, &fd] } else { vec![&rx] };
        let ready = reactor.wait(&sources, None).unwrap();
        if mixed && ready.is_ready(1) {
            let mut r = &reader;
            while let Ok(n) = r.read(&mut buf) {
                if n == 0 {
                    break;
                }
                bytes += n;
            }
        }
        rx.drain(|r| {
            let r = r.unwrap();
            // Every sender's messages in order, none missed.
            let expected = next.entry(r.sender).or_insert(0);
            assert_eq!(r.msg.params, vec![Value::Int(*expected)]);
            assert_eq!(r.missed, 0);
            *expected += 1;
            got += 1;
        })
        .unwrap();
    }
    if let Some(poker) = poker {
        poker.join().unwrap();
    }
    let stats = reactor.stats();
    println!(
        "@@ GOT {got} {bytes} {} {} {}",
        stats.sleeps, stats.doorbell_sleeps, stats.unrung
    );
    wait_for_stdin_close();
}

// ---------------------------------------------------------------------------------------------
// Parent side

/// The numbers of `child`'s next report, which must start with `word` and come within
/// `within` (a lost wake-up stalls the receiver: the report never comes).
fn expect(child: &ChildProcess, word: &str, within: Duration) -> Vec<u64> {
    child
        .report(word, within)
        .split_whitespace()
        .map(|x| x.parse().unwrap())
        .collect()
}

fn doorbells(vehicle: &Vehicle) -> BTreeSet<String> {
    let prefix = format!("{}db_", vehicle.shm_prefix().unwrap());
    std::fs::read_dir("/dev/shm")
        .map(|dir| {
            dir.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with(&prefix))
                .collect()
        })
        .unwrap_or_default()
}

/// Several senders with random gaps, one receiver asleep between them: every message arrives,
/// in order, and no sender ever notifies through iceoryx2 (the receiver is awake or asleep on
/// its doorbell).
fn stress(strategy: &str) {
    let vehicle = TestVehicle::new("auv");
    let start = Instant::now();
    let receiver = ChildProcess::spawn(&vehicle, "receiver", strategy);
    expect(&receiver, "READY", DEADLINE);
    let senders: Vec<_> = (0..SENDERS)
        .map(|i| ChildProcess::spawn(&vehicle, "sender", &format!("P{i}")))
        .collect();
    let left = DEADLINE.saturating_sub(start.elapsed());
    let got = expect(&receiver, "GOT", left);
    assert_eq!(got[0], (SENDERS * PER_SENDER) as u64);
    assert!(
        got[3] > 0,
        "the receiver never slept on its doorbell: {got:?}"
    );
    for sender in &senders {
        let sent = expect(sender, "SENT", DEADLINE);
        assert_eq!(sent[..2], [PER_SENDER as u64, 0]);
        assert_eq!(sent[2], 0, "a sender notified through iceoryx2");
    }
    for sender in senders {
        sender.finish();
    }
    receiver.finish();
    assert!(doorbells(&vehicle).is_empty(), "{:?}", doorbells(&vehicle));
}

#[test]
fn every_message_of_several_senders_reaches_a_blocking_receiver() {
    stress("block");
}

#[test]
fn every_message_reaches_a_receiver_that_spins_then_blocks() {
    stress("spin-then-block:20");
}

/// A receiver that also watches a socket sleeps on epoll (its senders see it and notify
/// through iceoryx2), and both the messages and the socket wake it.
#[test]
fn a_receiver_watching_a_descriptor_too_still_wakes() {
    let vehicle = TestVehicle::new("auv");
    let start = Instant::now();
    let receiver = ChildProcess::spawn(&vehicle, "mixed", "block");
    expect(&receiver, "READY", DEADLINE);
    let senders: Vec<_> = (0..SENDERS)
        .map(|i| ChildProcess::spawn(&vehicle, "sender", &format!("P{i}")))
        .collect();
    let left = DEADLINE.saturating_sub(start.elapsed());
    let got = expect(&receiver, "GOT", left);
    assert_eq!(got[..2], [(SENDERS * PER_SENDER) as u64, 40]);
    assert_eq!(got[3], 0, "a mixed set sleeps on epoll, not on doorbells");
    assert!(got[2] > 0, "the receiver never slept");
    for sender in senders {
        let sent = expect(&sender, "SENT", DEADLINE);
        assert_eq!(sent[..2], [PER_SENDER as u64, 0]);
        sender.finish();
    }
    receiver.finish();
}

/// A receiver killed without warning leaves its doorbell; the dead-node cleanup removes it,
/// also when iceoryx2 had removed the dead node by itself (another process joined first).
#[test]
fn a_killed_receiver_leaves_no_doorbell_after_cleanup() {
    let vehicle = TestVehicle::new("auv");
    let mut receiver = ChildProcess::spawn(&vehicle, "receiver", "block");
    expect(&receiver, "READY", DEADLINE);
    assert_eq!(doorbells(&vehicle).len(), 1);
    receiver.kill(); // SIGKILL
    assert_eq!(
        doorbells(&vehicle).len(),
        1,
        "a killed process removes nothing"
    );
    // Joining may let iceoryx2 clean the dead node up by itself.
    let tool = Participant::join(&vehicle, Role::tool("probe").unwrap()).unwrap();
    let report = cleanup_dead_nodes(&vehicle, Duration::from_secs(1)).unwrap();
    assert!(report.failed.is_empty(), "{report:?}");
    assert!(doorbells(&vehicle).is_empty(), "{:?}", doorbells(&vehicle));
    drop(tool);
}

/// A receiver whose senders cannot ring it (its doorbell removed, as with a sender of an older
/// Petrel): each sample waits for the end of a doorbell slice, and after `UNRUNG_LIMIT` of them
/// the reactor sleeps on epoll for good, where the senders' notifications wake it. Every
/// message arrives either way.
#[test]
fn a_reactor_whose_senders_do_not_ring_falls_back_to_epoll() {
    let vehicle = TestVehicle::new("auv");
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let rx = player.event_receiver().unwrap();
    for name in doorbells(&vehicle) {
        std::fs::remove_file(std::path::Path::new("/dev/shm").join(name)).unwrap();
    }
    let mut reactor = Reactor::without_signal_handling(WaitStrategy::Block).unwrap();
    reactor.set_doorbell_slice(Duration::from_millis(10));
    let (ack, acked) = mpsc::channel::<()>();
    let (ready, is_ready) = mpsc::channel::<()>();
    const N: i64 = 8;
    std::thread::scope(|s| {
        let vehicle = &vehicle;
        s.spawn(move || {
            let pln = Participant::join(vehicle, Role::program("PLN").unwrap()).unwrap();
            let tx = pln.event_sender().unwrap();
            ready.send(()).unwrap();
            for i in 0..N {
                // Long enough for the receiver to be asleep when the message comes.
                std::thread::sleep(Duration::from_millis(30));
                tx.send(&EventMsg::new("tick", vec![Value::Int(i)]))
                    .unwrap();
                if acked.recv_timeout(DEADLINE).is_err() {
                    return;
                }
            }
            assert!(tx.stats().notified >= N as u64 - 1);
        });
        is_ready.recv_timeout(DEADLINE).unwrap();
        let start = Instant::now();
        let mut got = 0;
        while got < N {
            assert!(start.elapsed() < DEADLINE, "only {got} of {N} arrived");
            reactor.wait(&[&rx], Some(Duration::from_secs(5))).unwrap();
            rx.drain(|r| {
                assert_eq!(r.unwrap().msg.params, vec![Value::Int(got)]);
                got += 1;
                ack.send(()).unwrap();
            })
            .unwrap();
        }
    });
    let stats = reactor.stats();
    assert!(
        stats.unrung >= petrel_ipc::reactor::UNRUNG_LIMIT,
        "{stats:?}"
    );
    assert!(
        !reactor.doorbells(),
        "still sleeping on doorbells: {stats:?}"
    );
}
