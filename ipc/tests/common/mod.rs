//! Helpers shared by the integration tests.

use std::io::{BufRead, BufReader, Read};
use std::ops::Deref;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use petrel_ipc::Vehicle;

/// An isolated vehicle whose leftover files (iceoryx2 keeps a small global segment per prefix)
/// are removed when the test ends. Declare it before the participants, so it drops after them.
pub struct TestVehicle(pub Vehicle);

impl TestVehicle {
    pub fn new(name: &str) -> Self {
        TestVehicle(Vehicle::isolated(name).expect("valid name"))
    }
}

impl Deref for TestVehicle {
    type Target = Vehicle;
    fn deref(&self) -> &Vehicle {
        &self.0
    }
}

impl Drop for TestVehicle {
    fn drop(&mut self) {
        if let Err(e) = petrel_ipc::remove_vehicle_files(&self.0) {
            eprintln!("leftover files of {}: {e}", self.0.prefix());
        }
    }
}

// The tests between processes run their own binary again as a child (test `child`, with
// `PETREL_IPC_CHILD` naming its role). The child reports on its standard output with lines
// starting `@@ `, and exits when its standard input closes (or is killed).

/// The child's role (`PETREL_IPC_CHILD`).
pub const CHILD_ENV: &str = "PETREL_IPC_CHILD";
const VEHICLE_ENV: &str = "PETREL_IPC_VEHICLE";
const PREFIX_ENV: &str = "PETREL_IPC_PREFIX";
const ARG_ENV: &str = "PETREL_IPC_ARG";

/// In a child: its role, its parent's vehicle and its argument; `None` in the parent.
#[allow(dead_code)] // each test binary uses its part of this module
pub fn child_role() -> Option<(String, Vehicle, String)> {
    let mode = std::env::var(CHILD_ENV).ok()?;
    let name = std::env::var(VEHICLE_ENV).expect("vehicle name");
    let prefix = std::env::var(PREFIX_ENV).expect("vehicle prefix");
    let arg = std::env::var(ARG_ENV).unwrap_or_default();
    let vehicle = Vehicle::with_prefix(&name, &prefix).expect("vehicle");
    Some((mode, vehicle, arg))
}

/// In a child: waits until the parent closes its standard input.
#[allow(dead_code)]
pub fn wait_for_stdin_close() {
    let mut sink = Vec::new();
    let _ = std::io::stdin().read_to_end(&mut sink);
}

/// A child process of the test binary, on the parent's vehicle.
#[allow(dead_code)]
pub struct ChildProcess {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: mpsc::Receiver<String>,
}

#[allow(dead_code)]
impl ChildProcess {
    /// Starts the child in role `mode` with argument `arg`.
    pub fn spawn(vehicle: &Vehicle, mode: &str, arg: &str) -> Self {
        let exe = std::env::current_exe().expect("test binary");
        let mut child = Command::new(exe)
            .args(["--exact", "child", "--nocapture", "--test-threads=1", "-q"])
            .env(CHILD_ENV, mode)
            .env(VEHICLE_ENV, vehicle.name())
            .env(PREFIX_ENV, vehicle.prefix())
            .env(ARG_ENV, arg)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("spawn the child");
        let stdin = child.stdin.take();
        let stdout = child.stdout.take().expect("child stdout");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Some(report) = line.strip_prefix("@@ ") {
                    if tx.send(report.to_owned()).is_err() {
                        break;
                    }
                }
            }
        });
        ChildProcess {
            child,
            stdin,
            lines,
        }
    }

    /// The next report, which must start with `word` and come within `within`: the rest of it.
    pub fn report(&self, word: &str, within: Duration) -> String {
        let line = self
            .lines
            .recv_timeout(within)
            .unwrap_or_else(|e| panic!("no `{word}` from the child within {within:?}: {e}"));
        line.strip_prefix(word)
            .unwrap_or_else(|| panic!("expected `{word}`, got `{line}`"))
            .trim()
            .to_owned()
    }

    /// The child's process id.
    pub fn id(&self) -> u32 {
        self.child.id()
    }

    /// Kills the child (SIGKILL) and reaps it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Closes the child's standard input and waits for it to exit successfully.
    pub fn finish(mut self) {
        drop(self.stdin.take());
        let status = self.child.wait().expect("wait for the child");
        assert!(status.success(), "child failed: {status}");
    }
}

impl Drop for ChildProcess {
    fn drop(&mut self) {
        // On a failed assertion, do not leave the child behind.
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// This process's resident memory, in KiB (`VmRSS` of /proc/self/status).
#[allow(dead_code)] // Not every test binary that shares this module measures memory.
pub fn resident_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .expect("VmRSS in /proc/self/status");
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}
