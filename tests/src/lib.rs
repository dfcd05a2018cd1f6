//! Helpers for Petrel's cross-crate and cross-process tests.

pub mod programs;
pub mod web;

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

// Other users: the tests that switch users run as root, with `setpriv`.

/// The effective user of this process.
pub fn euid() -> u32 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Uid:"))
                .and_then(|r| r.split_whitespace().nth(1)?.parse().ok())
        })
        .expect("the effective user in /proc/self/status")
}

/// True when the tests may switch users; otherwise says why the test is skipped.
pub fn can_switch_users(test: &str) -> bool {
    let root = euid() == 0;
    let setpriv = Path::new("/usr/bin/setpriv").exists() || Path::new("/bin/setpriv").exists();
    if !(root && setpriv) {
        eprintln!(
            "SKIPPED {test}: it runs commands as other users with setpriv, which needs root (running as uid {}, setpriv {})",
            euid(),
            if setpriv { "present" } else { "absent" }
        );
    }
    root && setpriv
}

/// `setpriv` as `uid` (its group `uid`, and `groups` besides), running `program`.
pub fn as_user(uid: u32, groups: &[u32], program: &Path) -> std::process::Command {
    let mut c = std::process::Command::new("setpriv");
    c.arg(format!("--reuid={uid}"))
        .arg(format!("--regid={uid}"));
    if groups.is_empty() {
        c.arg("--clear-groups");
    } else {
        let list: Vec<String> = groups.iter().map(u32::to_string).collect();
        c.arg(format!("--groups={}", list.join(",")));
    }
    // No home directory to read, no runtime directory of root's to inherit.
    c.arg(program)
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove(petrel_ipc::RUNTIME_DIR_ENV)
        .env_remove(petrel_ipc::GROUP_ENV)
        .current_dir("/");
    c
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
        Self::start_journaled(work, dir, vehicle, &work.path().join("journal"), extra)
    }

    /// The same, with its journal in `journal` (a directory anywhere: a small tmpfs...) and its
    /// log in `work`.
    pub fn start_journaled(
        work: &Workdir,
        dir: &Path,
        vehicle: &str,
        journal: &Path,
        extra: &[&str],
    ) -> Player {
        use std::sync::atomic::{AtomicU32, Ordering};
        static N: AtomicU32 = AtomicU32::new(0);
        let log = work
            .path()
            .join(format!("play-{}.log", N.fetch_add(1, Ordering::Relaxed)));
        let journal = journal.to_path_buf();
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

    /// `petrel send` to this player with more arguments (`--timeout`...).
    pub fn send_with(&self, event: &str, extra: &[&str]) -> std::process::Output {
        Command::new(petrel_bin())
            .arg("send")
            .arg(&self.dir)
            .arg(event)
            .args(["--vehicle", &self.vehicle])
            .args(extra)
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

/// An example of this build: the SDK's demos (`echo` of `petrel-programs`), the tests' own.
pub fn example_bin(name: &str) -> PathBuf {
    artifact(
        profile_dir().join("examples").join(name),
        &format!("the example program `{name}`"),
    )
}

/// A vehicle's program of this build, a binary of a crate of vehicles/ (`uav-gui`, `uav-dec`,
/// `ugv`, `auv-gui`, `auv-bridge`, `redermor-program`, `redermor-bridge`...).
pub fn vehicle_bin(name: &str) -> PathBuf {
    artifact(
        profile_dir().join(name),
        &format!("the vehicle's program `{name}`"),
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

/// Runs `petrel ARGS` to completion.
pub fn petrel(args: &[&str]) -> std::process::Output {
    Command::new(petrel_bin())
        .args(args)
        .output()
        .expect("petrel runs")
}

/// True when a process ended by itself with an exit code (not a panic's 101, not an abort or
/// any other signal): what "refused cleanly" means for a command given bad input.
pub fn ended_cleanly(o: &std::process::Output) -> bool {
    matches!(o.status.code(), Some(0..=2))
}

/// A project written into a temporary directory (removed when dropped): the files of `from`
/// (a project directory of the repository), each edited by `edit(file name, text)`, plus
/// `extra` files.
pub struct TempProject(tempfile::TempDir);

impl TempProject {
    /// Copies the project `from`, passing each file through `edit`.
    pub fn copy(from: &Path, edit: impl Fn(&str, String) -> String) -> Self {
        let dir = tempfile::Builder::new()
            .prefix("petrel-project-")
            .tempdir()
            .expect("a temporary directory");
        for entry in std::fs::read_dir(from).expect("the project directory") {
            let path = entry.expect("a directory entry").path();
            if path.is_file() {
                let name = path
                    .file_name()
                    .and_then(|n| n.to_str())
                    .unwrap_or_default();
                let text = std::fs::read_to_string(&path).expect("a project file");
                std::fs::write(dir.path().join(name), edit(name, text)).expect("written");
            }
        }
        TempProject(dir)
    }

    /// A project of the given files (name, text).
    pub fn new(files: &[(&str, &str)]) -> Self {
        let dir = tempfile::Builder::new()
            .prefix("petrel-project-")
            .tempdir()
            .expect("a temporary directory");
        for (name, text) in files {
            std::fs::write(dir.path().join(name), text).expect("written");
        }
        TempProject(dir)
    }

    /// Its directory.
    pub fn path(&self) -> &Path {
        self.0.path()
    }
}

/// A small tmpfs mounted for one test (a full disk on demand), unmounted when dropped, pass or
/// fail. Mounting needs root: [`Tmpfs::mount`] returns `None` (and says so) where it is not.
pub struct Tmpfs {
    path: PathBuf,
}

impl Tmpfs {
    /// Mounts a tmpfs of `kib` KiB at `path` (created if needed).
    pub fn mount(path: &Path, kib: u64) -> Option<Tmpfs> {
        std::fs::create_dir_all(path).expect("mount point");
        let ok = Command::new("mount")
            .args([
                "-t",
                "tmpfs",
                "-o",
                &format!("size={kib}k,mode=0700"),
                "tmpfs",
            ])
            .arg(path)
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            eprintln!(
                "cannot mount a tmpfs at {} (this test needs root): skipped",
                path.display()
            );
            return None;
        }
        Some(Tmpfs {
            path: path.to_path_buf(),
        })
    }

    /// Gives the tmpfs `kib` KiB (the disk is no longer full).
    pub fn resize(&self, kib: u64) {
        let ok = Command::new("mount")
            .args(["-o", &format!("remount,size={kib}k"), "tmpfs"])
            .arg(&self.path)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "cannot resize the tmpfs at {}", self.path.display());
    }

    /// The mount point.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let unmounted = Command::new("umount")
            .arg(&self.path)
            .status()
            .is_ok_and(|s| s.success());
        if !unmounted {
            // A process still holds a file there: detach it now, it goes when they close.
            let _ = Command::new("umount").arg("-l").arg(&self.path).status();
        }
    }
}

/// A journal record as the flight recorder writes it: little-endian length, CRC-32 of the
/// body, the body. For tests that craft records (valid checksums around hostile bodies).
pub fn journal_record(body: &[u8]) -> Vec<u8> {
    let mut crc = !0u32;
    for &b in body {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    let mut out = (body.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&(!crc).to_le_bytes());
    out.extend_from_slice(body);
    out
}

/// The segment files of a journal directory, in order.
pub fn journal_segments(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "pj"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// `petrel journal show DIR --format json`, one document per entry (and the exit status).
pub fn journal_json(dir: &Path) -> (Vec<serde_json::Value>, std::process::Output) {
    let o = petrel(&[
        "journal",
        "show",
        &dir.display().to_string(),
        "--format",
        "json",
    ]);
    let docs = String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    (docs, o)
}

/// Removes what a vehicle left in shared memory (dead nodes, then its files): for a test whose
/// processes of that vehicle were started by hand and have ended.
pub fn forget_vehicle(vehicle: &str) {
    if let Ok(v) = petrel_ipc::Vehicle::new(vehicle) {
        let _ = petrel_ipc::cleanup_dead_nodes(&v, std::time::Duration::from_millis(200));
        let _ = petrel_ipc::remove_vehicle_files(&v);
    }
}
