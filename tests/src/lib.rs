//! Helpers for Petrel's cross-crate and cross-process tests.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The build's own artifacts: `target/<profile>/` for the test executable running now.
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>
    exe.parent()
        .and_then(Path::parent)
        .expect("test binary lives in target/<profile>/deps")
        .to_path_buf()
}

/// An artifact that the test command builds (`cargo test --workspace` builds every package's
/// binaries and examples before running a test); a clear failure if this run did not.
fn artifact(path: PathBuf, what: &str) -> PathBuf {
    assert!(
        path.exists(),
        "{what} is not built ({}): run the tests with `cargo test --workspace` (as scripts/test.sh does), or build it first with `cargo build --workspace --bins --examples`",
        path.display()
    );
    path
}

/// The `petrel` binary of this build.
pub fn petrel_bin() -> PathBuf {
    artifact(profile_dir().join("petrel"), "the `petrel` binary")
}

/// A vehicle name no other test run uses (iceoryx2 resources are per vehicle).
pub fn unique_vehicle(tag: &str) -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "{tag}{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// A directory for one test's files (journals, logs), removed, pass or fail, when its last
/// holder is dropped.
#[derive(Clone)]
pub struct Workdir(std::sync::Arc<tempfile::TempDir>);

impl Workdir {
    /// A new, empty directory.
    pub fn new() -> Self {
        Workdir(std::sync::Arc::new(
            tempfile::Builder::new()
                .prefix("petrel-test-")
                .tempdir()
                .expect("a temporary directory"),
        ))
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        self.0.path()
    }
}

impl Default for Workdir {
    fn default() -> Self {
        Self::new()
    }
}

/// A `petrel play` process, stopped (SIGTERM, then SIGKILL) when dropped.
pub struct Player {
    /// The process.
    pub child: std::process::Child,
    /// Its vehicle.
    pub vehicle: String,
    /// Its project directory.
    pub dir: PathBuf,
    /// Its journal directory (in its work directory).
    pub journal: PathBuf,
    /// Its log (standard error).
    pub log: PathBuf,
    /// The directory holding its journal and logs.
    pub work: Workdir,
}

impl Player {
    /// Starts `petrel play DIR --vehicle VEHICLE` and waits until it answers `petrel status`.
    pub fn start(dir: &Path, vehicle: &str) -> Player {
        Self::start_with(dir, vehicle, &[])
    }

    /// The same, with more arguments for `petrel play` (`--shadow`...).
    pub fn start_with(dir: &Path, vehicle: &str, extra: &[&str]) -> Player {
        Self::start_in(&Workdir::new(), dir, vehicle, extra)
    }

    /// The same, with its journal and log in `work` (another player's, for `--resume`).
    pub fn start_in(work: &Workdir, dir: &Path, vehicle: &str, extra: &[&str]) -> Player {
        use std::sync::atomic::{AtomicU32, Ordering};
        static N: AtomicU32 = AtomicU32::new(0);
        let log = work
            .path()
            .join(format!("play-{}.log", N.fetch_add(1, Ordering::Relaxed)));
        let journal = work.path().join("journal");
        let child = Command::new(petrel_bin())
            .arg("play")
            .arg(dir)
            .args(["--vehicle", vehicle])
            .arg("--journal")
            .arg(&journal)
            .args(extra)
            .stderr(std::fs::File::create(&log).expect("log file"))
            .spawn()
            .expect("petrel play starts");
        let player = Player {
            child,
            vehicle: vehicle.to_string(),
            dir: dir.to_path_buf(),
            journal,
            log: log.clone(),
            work: work.clone(),
        };
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while std::time::Instant::now() < deadline {
            if player.status().is_some() {
                return player;
            }
        }
        panic!("the player did not start; log in {}", log.display());
    }

    /// The player's live status (`petrel status --json`), if it answers.
    pub fn status(&self) -> Option<serde_json::Value> {
        let o = Command::new(petrel_bin())
            .arg("status")
            .arg(&self.dir)
            .args(["--vehicle", &self.vehicle, "--json"])
            .output()
            .ok()?;
        if !o.status.success() {
            return None;
        }
        serde_json::from_slice(&o.stdout).ok()
    }

    /// Waits (up to `secs`) until `pred` holds on the status; returns the last status.
    pub fn wait_for(
        &self,
        secs: f64,
        pred: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs_f64(secs);
        loop {
            let s = self.status().unwrap_or_default();
            if pred(&s) || std::time::Instant::now() >= deadline {
                return s;
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }

    /// `petrel send` to this player.
    pub fn send(&self, event: &str, count: u64) -> std::process::Output {
        Command::new(petrel_bin())
            .arg("send")
            .arg(&self.dir)
            .arg(event)
            .args(["--vehicle", &self.vehicle, "--count", &count.to_string()])
            .output()
            .expect("petrel send runs")
    }

    /// What the player has written to its log so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Stops the player with SIGTERM and returns its exit status.
    pub fn stop(mut self) -> std::process::ExitStatus {
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        self.child.wait().expect("player exits")
    }
}

impl Drop for Player {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        // The vehicle was this test's alone: leave nothing in /dev/shm.
        if let Ok(v) = petrel_ipc::Vehicle::new(&self.vehicle) {
            let _ = petrel_ipc::cleanup_dead_nodes(&v, std::time::Duration::from_millis(200));
            let _ = petrel_ipc::remove_vehicle_files(&v);
        }
    }
}

/// An example program of `petrel-programs` (`uav_gui`, `uav_dec`, `auv_gui`, `echo`).
pub fn example_bin(name: &str) -> PathBuf {
    artifact(
        profile_dir().join("examples").join(name),
        &format!("the example program `{name}`"),
    )
}

/// Child processes stopped with SIGTERM (so that they leave the vehicle cleanly), then SIGKILL
/// after 5 s, when dropped or by [`stop`](Self::stop).
pub struct Processes(pub Vec<std::process::Child>);

impl Processes {
    /// Stops them all; their exit codes, in order (`None`: killed, or ended by a signal).
    pub fn stop(mut self) -> Vec<Option<i32>> {
        let codes = stop_all(&mut self.0);
        self.0.clear();
        codes
    }
}

fn stop_all(children: &mut [std::process::Child]) -> Vec<Option<i32>> {
    for c in children.iter() {
        let _ = Command::new("kill")
            .args(["-TERM", &c.id().to_string()])
            .status();
    }
    children
        .iter_mut()
        .map(|c| {
            let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
            while matches!(c.try_wait(), Ok(None)) && std::time::Instant::now() < deadline {
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            match c.try_wait() {
                Ok(Some(s)) => s.code(),
                _ => {
                    let _ = c.kill();
                    let _ = c.wait();
                    None
                }
            }
        })
        .collect()
}

impl Drop for Processes {
    fn drop(&mut self) {
        stop_all(&mut self.0);
    }
}
