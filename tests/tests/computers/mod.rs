//! The simulated computers of the gateway tests (tests/tests/gateway.rs): each its own
//! iceoryx2 root and state directory, in a network namespace of its own where a test gives one;
//! the cable between two namespaces, a gateway stopped and continued, the vehicle's keys given
//! out one per computer, and the rogue zenoh peer (`examples/rogue_peer`).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use petrel_tests::{example_bin, petrel_bin, Workdir};

/// One simulated computer: its own iceoryx2 root.
pub struct Computer {
    pub name: &'static str,
    pub root: PathBuf,
    pub work: PathBuf,
    /// The network namespace its processes run in, if any.
    pub netns: Option<String>,
    /// Its user's state directory (`PETREL_STATE_DIR`: the vehicle's keys).
    pub state: PathBuf,
    /// The root, removed pass or fail; short, in /tmp: iceoryx2's Unix sockets live in it.
    _root: tempfile::TempDir,
}

impl Computer {
    pub fn new(work: &Workdir, name: &'static str) -> Computer {
        let root = tempfile::Builder::new()
            .prefix("pg")
            .tempdir_in("/tmp")
            .expect("a runtime root");
        Computer {
            name,
            root: root.path().to_path_buf(),
            work: work.path().to_path_buf(),
            netns: None,
            state: work.path().join("state"),
            _root: root,
        }
    }

    pub fn command(&self, program: &Path) -> Command {
        let mut c = match &self.netns {
            Some(ns) => {
                let mut c = Command::new("ip");
                c.args(["netns", "exec", ns]).arg(program);
                c
            }
            None => Command::new(program),
        };
        c.env("PETREL_RUNTIME_DIR", &self.root)
            .env(petrel_gateway::keys::STATE_DIR_ENV, &self.state);
        c
    }

    pub fn spawn(&self, program: &Path, args: &[&str], log: &str) -> Child {
        self.command(program)
            .args(args)
            .stdout(std::fs::File::create(self.work.join(format!("{log}.out"))).expect("log"))
            .stderr(std::fs::File::create(self.work.join(format!("{log}.log"))).expect("log"))
            .spawn()
            .expect("the process starts")
    }

    pub fn gateway(&self, project: &Path, vehicle: &str, log: &str) -> Child {
        self.spawn(
            &petrel_bin(),
            &[
                "gateway",
                &project.display().to_string(),
                "--vehicle",
                vehicle,
                "--computer",
                self.name,
            ],
            log,
        )
    }

    /// `petrel status --json` on this computer.
    pub fn status(&self, project: &Path, vehicle: &str) -> Option<serde_json::Value> {
        let o = self
            .command(&petrel_bin())
            .arg("status")
            .arg(project)
            .args(["--vehicle", vehicle, "--json"])
            .stderr(Stdio::null())
            .output()
            .ok()?;
        o.status
            .success()
            .then(|| serde_json::from_slice(&o.stdout).ok())
            .flatten()
    }

    /// Waits (up to a minute: the machine is shared) until `pred` holds on this computer's
    /// status; returns it, or panics with the last one and the logs.
    pub fn wait_for(
        &self,
        project: &Path,
        vehicle: &str,
        what: &str,
        pred: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut last = serde_json::Value::Null;
        while Instant::now() < deadline {
            if let Some(s) = self.status(project, vehicle) {
                if pred(&s) {
                    return s;
                }
                last = s;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        panic!(
            "on computer {}: never {what}; last status {last}\nlogs: {}",
            self.name,
            logs(&self.work)
        );
    }

    pub fn send(&self, project: &Path, vehicle: &str, event: &str) -> String {
        let o = self
            .command(&petrel_bin())
            .arg("send")
            .arg(project)
            .arg(event)
            .args(["--vehicle", vehicle])
            .output()
            .expect("petrel send runs");
        let out = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(
            o.status.success(),
            "petrel send {event}: {out}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        out
    }

    /// `petrel send` started now, waiting up to 40 s for its verdict (an outage is longer
    /// than the default 10 s); its output is read by [`verdict`].
    pub fn send_waiting(&self, project: &Path, vehicle: &str, event: &str) -> Child {
        self.command(&petrel_bin())
            .arg("send")
            .arg(project)
            .arg(event)
            .args(["--vehicle", vehicle, "--timeout", "40"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("petrel send starts")
    }
}

/// The logs (`*.log`, `*.out`) of a test's work directory, for a failure's message.
pub fn logs(dir: &Path) -> String {
    let mut text = String::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.extension().is_some_and(|x| x == "log" || x == "out") {
            text.push_str(&format!(
                "\n--- {}\n{}",
                p.display(),
                std::fs::read_to_string(&p).unwrap_or_default()
            ));
        }
    }
    text
}

/// A TCP port of loopback free now.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// `examples/rogue_peer` on `at` (its network namespace), for `seconds`: a zenoh peer that
/// connects to `connect`, listens to everything and forges link messages (`args`).
pub fn rogue(
    at: &Computer,
    vehicle: &str,
    seconds: &str,
    connect: &[String],
    args: &[&str],
    log: &str,
) -> Child {
    let mut all: Vec<&str> = vec![vehicle, seconds];
    for e in connect {
        all.extend(["--connect", e]);
    }
    all.extend(args);
    at.spawn(&example_bin("rogue_peer"), &all, log)
}

/// What a rogue peer got (its last line).
pub fn rogue_report(work: &Workdir, rogue: Child, log: &str) -> serde_json::Value {
    let out = rogue.wait_with_output().expect("the rogue ends");
    assert!(out.status.success(), "{}", logs(work.path()));
    last_json(&work.path().join(format!("{log}.out")))
}

/// Two network namespaces joined by a veth pair (a cable between two computers), removed when
/// dropped; `None` where they cannot be made (not root, no `ip`).
pub struct Cable {
    pub ns: [String; 2],
    ends: [String; 2],
    pub addrs: [String; 2],
}

impl Cable {
    pub fn new() -> Option<Cable> {
        let id = std::process::id() % 100_000;
        let ns = [format!("pg{id}a"), format!("pg{id}b")];
        let ends = [format!("pgv{id}a"), format!("pgv{id}b")];
        let net = format!("10.{}.{}", 200 + id % 50, id % 250);
        let addrs = [format!("{net}.1"), format!("{net}.2")];
        let cable = Cable { ns, ends, addrs };
        let ip = |args: &[&str]| {
            Command::new("ip")
                .args(args)
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        let made = ip(&["netns", "add", &cable.ns[0]])
            && ip(&["netns", "add", &cable.ns[1]])
            && ip(&[
                "link",
                "add",
                &cable.ends[0],
                "type",
                "veth",
                "peer",
                "name",
                &cable.ends[1],
            ])
            && (0..2).all(|i| {
                ip(&["link", "set", &cable.ends[i], "netns", &cable.ns[i]])
                    && ip(&[
                        "-n",
                        &cable.ns[i],
                        "addr",
                        "add",
                        &format!("{}/24", cable.addrs[i]),
                        "dev",
                        &cable.ends[i],
                    ])
                    && ip(&["-n", &cable.ns[i], "link", "set", &cable.ends[i], "up"])
                    && ip(&["-n", &cable.ns[i], "link", "set", "lo", "up"])
            });
        if !made {
            eprintln!("cannot make network namespaces and a veth pair (this test needs root and `ip`): skipped");
            return None;
        }
        Some(cable)
    }

    /// Unplugs (or plugs back) the cable at the first computer's end.
    pub fn set(&self, up: bool) {
        let ok = Command::new("ip")
            .args([
                "-n",
                &self.ns[0],
                "link",
                "set",
                &self.ends[0],
                if up { "up" } else { "down" },
            ])
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "ip link set {}", self.ends[0]);
    }
}

impl Drop for Cable {
    fn drop(&mut self) {
        // Deleting a namespace deletes its end of the pair, and so the pair.
        for ns in &self.ns {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// The vehicle's keys made by `petrel keys` (in the work directory, as on an operator's
/// computer), and each computer given its own in a state directory of its own: ca.pem,
/// NAME.pem and NAME.key, owner-only, as docs/gateway.md says.
pub fn distribute_keys<const N: usize>(
    work: &Workdir,
    dir: &Path,
    vehicle: &str,
    computers: [&mut Computer; N],
) {
    use std::os::unix::fs::PermissionsExt;
    let made = work.path().join("made-keys");
    let o = petrel_tests::petrel(&[
        "keys",
        &dir.display().to_string(),
        "--vehicle",
        vehicle,
        "--out",
        &made.display().to_string(),
    ]);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && said.contains("ca.key"),
        "{said}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for c in computers {
        c.state = work.path().join(format!("state-{}", c.name));
        let to = c.state.join("keys").join(vehicle);
        std::fs::create_dir_all(&to).expect("a keys directory");
        std::fs::set_permissions(&to, std::fs::Permissions::from_mode(0o700)).expect("0700");
        for f in [
            "ca.pem".to_string(),
            format!("{}.pem", c.name),
            format!("{}.key", c.name),
        ] {
            std::fs::copy(made.join(&f), to.join(&f)).expect("copied");
            std::fs::set_permissions(to.join(&f), std::fs::Permissions::from_mode(0o600))
                .expect("0600");
        }
    }
}

/// A gateway stopped (SIGSTOP) for as long as it lives, continued (SIGCONT) when dropped.
pub struct Stopped(u32);

impl Stopped {
    pub fn new(pid: u32) -> Stopped {
        signal("-STOP", pid);
        Stopped(pid)
    }
}

impl Drop for Stopped {
    fn drop(&mut self) {
        signal("-CONT", self.0);
    }
}

pub fn signal(which: &str, pid: u32) {
    let ok = Command::new("kill")
        .args([which, &pid.to_string()])
        .status()
        .is_ok_and(|s| s.success());
    assert!(ok, "kill {which} {pid}");
}

/// A waiting `petrel send`'s exit code and output.
pub fn verdict(send: Child) -> (Option<i32>, String) {
    let o = send.wait_with_output().expect("petrel send ends");
    (
        o.status.code(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        ),
    )
}

/// The last line of `path` that is a JSON object (a gateway prints its final counters).
pub fn last_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .rev()
        .find_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v.is_object())
        .unwrap_or_else(|| panic!("no final counters in {}:\n{text}", path.display()))
}
