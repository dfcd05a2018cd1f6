//! Helpers of the programs' tests (the SDK's, and the vehicles' programs'): a throw-away
//! vehicle, programs as child processes, and a fake player (a plain ipc participant with
//! `Role::Player`).

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use petrel_ipc::{
    cleanup_dead_nodes, CallMsg, CallSender, EventMsg, EventReceiver, Participant, Reactor,
    Received, Role, Value, Vehicle, WaitStrategy,
};

/// How long a test waits for anything before failing.
pub const TIMEOUT: Duration = Duration::from_secs(10);

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// A vehicle with a name unique to this test (process id, counter, clock), so that parallel
/// tests and earlier runs never meet. Its files are removed when it drops: declare it first in
/// a test, so that it drops after the processes and participants using it.
pub struct TestVehicle {
    pub vehicle: Vehicle,
}

impl TestVehicle {
    pub fn new() -> Self {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let name = format!("pp{}n{n}t{nanos:x}", std::process::id());
        TestVehicle {
            vehicle: Vehicle::new(&name).expect("valid vehicle name"),
        }
    }

    pub fn name(&self) -> &str {
        self.vehicle.name()
    }
}

impl Default for TestVehicle {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for TestVehicle {
    fn drop(&mut self) {
        let _ = cleanup_dead_nodes(&self.vehicle, Duration::from_secs(1));
        if let Err(e) = petrel_ipc::remove_vehicle_files(&self.vehicle) {
            eprintln!("leftover files of vehicle {}: {e}", self.vehicle.name());
        }
    }
}

/// Which output of a child a line came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    Out,
    Err,
}

/// A program running as a child process, its output collected line by line.
pub struct Proc {
    pub name: String,
    pub child: Child,
    lines: mpsc::Receiver<(Stream, String)>,
    /// Every line read so far.
    pub seen: Vec<(Stream, String)>,
}

impl Proc {
    /// Starts `program` (a binary of this build: `env!("CARGO_BIN_EXE_name")` in its own
    /// package's tests, [`crate::vehicle_bin`], [`crate::example_bin`]) with `args`.
    pub fn spawn(program: impl AsRef<Path>, args: &[&str]) -> Self {
        let program = program.as_ref();
        let name = program.file_name().map_or_else(
            || program.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        let mut child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", program.display()));
        let (tx, lines) = mpsc::channel();
        let out = child.stdout.take().expect("stdout");
        let err = child.stderr.take().expect("stderr");
        let tx2 = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                let _ = tx.send((Stream::Out, line));
            }
        });
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                let _ = tx2.send((Stream::Err, line));
            }
        });
        Proc {
            name,
            child,
            lines,
            seen: Vec::new(),
        }
    }

    fn transcript(&self) -> String {
        self.seen
            .iter()
            .map(|(s, l)| format!("{}{l}", if *s == Stream::Err { "! " } else { "  " }))
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// Waits for a line of `stream` containing `needle`, and returns it.
    pub fn wait_for(&mut self, stream: Stream, needle: &str) -> String {
        if let Some((_, line)) = self
            .seen
            .iter()
            .find(|(s, l)| *s == stream && l.contains(needle))
        {
            return line.clone();
        }
        let deadline = Instant::now() + TIMEOUT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok((s, line)) => {
                    self.seen.push((s, line.clone()));
                    if s == stream && line.contains(needle) {
                        return line;
                    }
                }
                Err(_) => panic!(
                    "{} printed no line containing `{needle}`; its output:\n{}",
                    self.name,
                    self.transcript()
                ),
            }
        }
    }

    /// Reads the lines printed so far.
    pub fn collect(&mut self) {
        while let Ok(item) = self.lines.try_recv() {
            self.seen.push(item);
        }
    }

    /// Sends SIGTERM.
    pub fn terminate(&self) {
        self.signal("TERM");
    }

    /// Sends signal `name` (`INT`, `TERM`...).
    pub fn signal(&self, name: &str) {
        let status = Command::new("kill")
            .args([&format!("-{name}"), &self.child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(status.success());
    }

    /// Waits for the process to exit, and returns its status.
    pub fn wait_exit(&mut self) -> ExitStatus {
        let deadline = Instant::now() + TIMEOUT;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                // The output threads end with the process: read what is left.
                std::thread::sleep(Duration::from_millis(20));
                self.collect();
                return status;
            }
            if Instant::now() >= deadline {
                self.collect();
                panic!(
                    "{} did not exit; its output:\n{}",
                    self.name,
                    self.transcript()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// A stand-in for `petrel play`: cleans up dead nodes as the player does at start, then
/// receives events and sends calls. Fields drop in order: ports before the node.
pub struct FakePlayer {
    events: EventReceiver,
    calls: HashMap<String, CallSender>,
    reactor: Reactor,
    pub participant: Participant,
}

impl FakePlayer {
    pub fn join(vehicle: &Vehicle) -> Self {
        cleanup_dead_nodes(vehicle, Duration::from_secs(1)).expect("cleanup");
        let participant = Participant::join(vehicle, Role::Player).expect("join as the player");
        let events = participant.event_receiver().expect("event receiver");
        FakePlayer {
            events,
            calls: HashMap::new(),
            reactor: Reactor::without_signal_handling(WaitStrategy::Block).expect("reactor"),
            participant,
        }
    }

    /// The call sender to `program`, once the program receives calls.
    pub fn sender(&mut self, program: &str) -> &CallSender {
        if !self.calls.contains_key(program) {
            let sender = self.participant.call_sender(program).expect("call sender");
            self.calls.insert(program.to_owned(), sender);
        }
        let sender = &self.calls[program];
        let deadline = Instant::now() + TIMEOUT;
        while sender.receivers() == 0 {
            assert!(
                Instant::now() < deadline,
                "program {program} never opened its call receiver"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        sender
    }

    /// Calls `program.function(args)`, waiting for the program to be there first.
    pub fn call(&mut self, program: &str, function: &str, args: Vec<Value>) {
        self.sender(program)
            .send(&CallMsg::new(function, args))
            .unwrap_or_else(|e| panic!("call {program}.{function}: {e}"));
    }

    /// The next event, if one comes within `timeout`.
    pub fn next_within(&self, timeout: Duration) -> Option<Received<EventMsg>> {
        let deadline = Instant::now() + timeout;
        loop {
            match self.events.try_recv() {
                Ok(Some(event)) => return Some(event),
                Ok(None) => {}
                Err(e) => panic!("the player refused an event: {e}"),
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            self.reactor
                .wait(&[&self.events], Some(left))
                .expect("wait");
            let _ = self.events.take_wakeups();
        }
    }

    /// The next event, which must come within [`TIMEOUT`].
    pub fn next(&self) -> Received<EventMsg> {
        self.next_within(TIMEOUT)
            .unwrap_or_else(|| panic!("no event within {TIMEOUT:?}"))
    }

    /// The next event, which must be `name`; returns its parameters.
    pub fn expect(&self, name: &str) -> Vec<Value> {
        let event = self.next();
        assert_eq!(
            event.msg.name, name,
            "expected `{name}`, got {:?}",
            event.msg
        );
        event.msg.params
    }

    /// Checks that no event comes within `quiet`.
    pub fn expect_silence(&self, quiet: Duration) {
        if let Some(event) = self.next_within(quiet) {
            panic!("unexpected event {:?}", event.msg);
        }
    }
}
