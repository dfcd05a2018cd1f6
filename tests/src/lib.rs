//! Helpers for Petrel's cross-crate and cross-process tests.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The `petrel` binary of this build, built first if a test run did not build it
/// (`cargo test -p petrel-tests` alone builds no binary of another package).
pub fn petrel_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>/petrel
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("test binary lives in target/<profile>/deps");
    let bin = profile_dir.join("petrel");
    if !bin.exists() {
        let release = profile_dir.file_name().is_some_and(|n| n == "release");
        let mut cmd = Command::new(env!("CARGO"));
        cmd.args(["build", "-p", "petrel-player", "--bin", "petrel"]);
        if release {
            cmd.arg("--release");
        }
        let status = cmd.current_dir(repo()).status().expect("cargo runs");
        assert!(status.success(), "building petrel failed");
    }
    bin
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

/// A `petrel play` process, stopped (SIGTERM, then SIGKILL) when dropped.
pub struct Player {
    /// The process.
    pub child: std::process::Child,
    /// Its vehicle.
    pub vehicle: String,
    /// Its project directory.
    pub dir: PathBuf,
    /// Its journal directory (in the system's temporary directory).
    pub journal: PathBuf,
}

/// The journal directory the tests give the player of `vehicle`.
pub fn journal_dir(vehicle: &str) -> PathBuf {
    std::env::temp_dir().join(format!("petrel-journal-{vehicle}"))
}

impl Player {
    /// Starts `petrel play DIR --vehicle VEHICLE` and waits until it answers `petrel status`.
    pub fn start(dir: &Path, vehicle: &str) -> Player {
        Self::start_with(dir, vehicle, &[])
    }

    /// The same, with more arguments for `petrel play` (`--resume`, `--shadow`...).
    pub fn start_with(dir: &Path, vehicle: &str, extra: &[&str]) -> Player {
        let log = std::env::temp_dir().join(format!("petrel-play-{vehicle}.log"));
        let journal = journal_dir(vehicle);
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

/// An example program of `petrel-programs` (`uav_gui`, `uav_dec`, `echo`), built first if this
/// test run did not build it.
pub fn example_bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("test binary lives in target/<profile>/deps");
    let bin = profile_dir.join("examples").join(name);
    if !bin.exists() {
        let release = profile_dir.file_name().is_some_and(|n| n == "release");
        let mut cmd = Command::new(env!("CARGO"));
        cmd.args(["build", "-p", "petrel-programs", "--example", name]);
        if release {
            cmd.arg("--release");
        }
        let status = cmd.current_dir(repo()).status().expect("cargo runs");
        assert!(status.success(), "building example {name} failed");
    }
    bin
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
