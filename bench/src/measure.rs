//! The measurements: each starts its processes, measures, stops them and removes what they left.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::os::unix::net::UnixListener;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use petrel_ipc::iceoryx2::prelude::*;
use petrel_ipc::{Participant, Role, Vehicle, WaitStrategy};

use crate::roles::{self, err, Res};
use crate::stats::Latencies;

/// How much to measure.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Rounds measured per figure.
    pub rounds: usize,
    /// Rounds before each measurement, not recorded.
    pub warmup: usize,
    /// Longest time one measurement takes (rounds past it are not done, and said so).
    pub max: Duration,
    /// Seconds each scale measurement runs.
    pub scale_secs: f64,
    /// Program counts of the scale measurement.
    pub scale: Vec<usize>,
    /// The `petrel` binary, for the footprint of the real commands (else this binary's roles).
    pub petrel: Option<PathBuf>,
    /// The `echo` example of the programs SDK, for a program's footprint.
    pub echo: Option<PathBuf>,
    /// The repository (its missions).
    pub repo: PathBuf,
}

/// The strategies every round trip is measured with.
pub fn strategies() -> Vec<WaitStrategy> {
    vec![
        WaitStrategy::Spin,
        WaitStrategy::SpinThenBlock(Duration::from_micros(200)),
        WaitStrategy::Block,
    ]
}

static VEHICLES: AtomicU32 = AtomicU32::new(0);

/// A vehicle name unique to this run.
pub fn vehicle_name(what: &str) -> String {
    let n = VEHICLES.fetch_add(1, Ordering::Relaxed);
    format!("b{what}{}x{n}", std::process::id())
}

/// Removes what a vehicle's processes left (dead nodes, files).
pub fn clear_vehicle(name: &str) {
    if let Ok(v) = Vehicle::new(name) {
        let _ = petrel_ipc::cleanup_dead_nodes(&v, Duration::from_millis(500));
        let _ = petrel_ipc::remove_vehicle_files(&v);
    }
}

/// A child process: this binary in a role, or another program.
pub struct Kid {
    name: String,
    child: Child,
    stdin: Option<ChildStdin>,
    out: Option<BufReader<ChildStdout>>,
}

impl Kid {
    /// Starts this binary with `role ARGS`.
    pub fn role(args: &[&str]) -> Res<Kid> {
        let exe = std::env::current_exe().map_err(|e| format!("current exe: {e}"))?;
        let mut all = vec!["role"];
        all.extend_from_slice(args);
        Kid::spawn(&exe, &all, args.first().copied().unwrap_or("role"))
    }

    /// Starts `exe ARGS`.
    pub fn spawn(exe: &Path, args: &[&str], name: &str) -> Res<Kid> {
        let mut child = Command::new(exe)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
        let stdin = child.stdin.take();
        let out = child.stdout.take().map(BufReader::new);
        Ok(Kid {
            name: name.to_owned(),
            child,
            stdin,
            out,
        })
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Waits for its `READY` line.
    pub fn ready(&mut self) -> Res<()> {
        let name = self.name.clone();
        let out = self
            .out
            .as_mut()
            .ok_or_else(|| format!("{name}: no output"))?;
        roles::await_ready(out, &name)
    }

    /// Waits for a line of its output.
    pub fn line(&mut self) -> Res<String> {
        let mut line = String::new();
        if let Some(out) = self.out.as_mut() {
            out.read_line(&mut line)
                .map_err(|e| format!("{}: {e}", self.name))?;
        }
        Ok(line)
    }

    /// Closes its standard input (it stops), and returns the rest of its output.
    pub fn finish(mut self) -> Res<String> {
        drop(self.stdin.take());
        let mut rest = String::new();
        if let Some(mut out) = self.out.take() {
            let _ = out.read_to_string(&mut rest);
        }
        self.wait(Duration::from_secs(10))?;
        Ok(rest)
    }

    /// Sends SIGTERM and waits for the end (SIGKILL after `grace`).
    pub fn terminate(mut self, grace: Duration) -> Res<()> {
        // This binary's roles stop at the end of their standard input and remove their
        // files; a signal first would end them before that (their shared-memory files were
        // left behind). Other programs get SIGTERM after a moment.
        drop(self.stdin.take());
        let until = Instant::now() + Duration::from_millis(500);
        while Instant::now() < until {
            if let Ok(Some(_)) = self.child.try_wait() {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        self.wait(grace)
    }

    fn wait(&mut self, grace: Duration) -> Res<()> {
        let until = Instant::now() + grace;
        loop {
            match self.child.try_wait() {
                Ok(Some(_)) => return Ok(()),
                Ok(None) if Instant::now() < until => std::thread::sleep(Duration::from_millis(5)),
                _ => {
                    let _ = self.child.kill();
                    let _ = self.child.wait();
                    return Err(format!("{} did not stop in time: killed", self.name));
                }
            }
        }
    }
}

impl Drop for Kid {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The bytes the round trip moves each way: a Petrel event's header and body.
pub fn payload_len() -> usize {
    let body = petrel_ipc::wire::encoded_len(&petrel_ipc::EventMsg::new(
        "pong_0",
        roles::round_payload(0),
    ))
    .unwrap_or(64);
    body + std::mem::size_of::<petrel_ipc::wire::MsgHeader>()
}

/// Background work during a measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Load {
    /// None.
    Idle,
    /// A 10 kHz stream of events into the player and a status reader.
    Events,
    /// One busy process per CPU.
    Cpu,
}

/// A player on a fresh vehicle with the round-trip project, and what runs beside it.
pub struct PlayerRun {
    /// The vehicle.
    pub vehicle: String,
    dir: tempfile::TempDir,
    player: Option<Kid>,
    load: Vec<Kid>,
}

impl PlayerRun {
    /// Starts the player for `programs` programs, with `wait`, and the background `load`.
    pub fn start(programs: usize, wait: WaitStrategy, load: Load) -> Res<PlayerRun> {
        let dir = tempfile::tempdir().map_err(|e| format!("tempdir: {e}"))?;
        let project = dir.path().join("project");
        crate::project::write_round_trip(&project, programs).map_err(|e| e.to_string())?;
        let vehicle = vehicle_name("rt");
        let journal = dir.path().join("journal");
        let wait_s = wait.to_string();
        let player = Kid::role(&[
            "player",
            "--dir",
            &project.display().to_string(),
            "--vehicle",
            &vehicle,
            "--wait",
            &wait_s,
            "--journal",
            &journal.display().to_string(),
        ])?;
        let mut run = PlayerRun {
            vehicle,
            dir,
            player: Some(player),
            load: Vec::new(),
        };
        match load {
            Load::Idle => {}
            Load::Events => {
                let mut e = Kid::role(&["emitter", "--vehicle", &run.vehicle, "--rate", "10000"])?;
                e.ready()?;
                run.load.push(e);
                let mut s = Kid::role(&["status-reader", "--vehicle", &run.vehicle])?;
                s.ready()?;
                run.load.push(s);
            }
            Load::Cpu => {
                for _ in 0..cpus() {
                    let mut b = Kid::role(&["busy"])?;
                    b.ready()?;
                    run.load.push(b);
                }
            }
        }
        Ok(run)
    }

    /// The player's process id.
    pub fn player_pid(&self) -> Option<u32> {
        self.player.as_ref().map(Kid::pid)
    }

    /// The temporary directory of this run.
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// Stops everything; returns what the background processes said.
    pub fn stop(mut self) -> Res<Vec<String>> {
        let mut said = Vec::new();
        for k in self.load.drain(..) {
            said.push(k.finish()?.trim().to_owned());
        }
        if let Some(p) = self.player.take() {
            let _ = p.terminate(Duration::from_secs(5));
        }
        clear_vehicle(&self.vehicle);
        Ok(said)
    }
}

/// CPUs of this machine.
pub fn cpus() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Round trips program -> player -> program, measured by a program in this process.
pub fn petrel_rt(s: &Settings, wait: WaitStrategy, load: Load) -> Res<(Latencies, Vec<String>)> {
    let run = PlayerRun::start(1, wait, load)?;
    let measured = roles::petrel_round_trips(&roles::RoundTrips {
        vehicle: run.vehicle.clone(),
        program: crate::project::program_name(0),
        event: "pong_0".to_owned(),
        wait,
        warmup: s.warmup,
        rounds: s.rounds,
        max: s.max,
        gate: None,
    });
    let said = run.stop()?;
    Ok((measured?.latencies, said))
}

/// Raw iceoryx2 publish-subscribe ping-pong, busy polling or sleeping in a WaitSet, with the
/// Petrel event's size.
pub fn iox_rt(s: &Settings, waitset: bool, load: Load) -> Res<Latencies> {
    let len = payload_len();
    let vehicle = Vehicle::isolated("ioxrt").map_err(|e| e.to_string())?;
    let result = {
        let me = Participant::join(&vehicle, Role::tool("ioxping").map_err(|e| e.to_string())?)
            .map_err(|e| e.to_string())?;
        let side = roles::iox_side(me.node(), "bench/ping", "bench/pong", len)?;
        let ws = WaitSetBuilder::new()
            .create::<ipc::Service>()
            .map_err(err("waitset"))?;
        let _guard = if waitset {
            Some(
                ws.attach_notification(&side.listener)
                    .map_err(err("attach"))?,
            )
        } else {
            None
        };
        let loaders = start_load(load)?;
        let mut pong = Kid::role(&[
            "iox-pong",
            "--name",
            vehicle.name(),
            "--prefix",
            vehicle.prefix(),
            "--mode",
            if waitset { "waitset" } else { "busy" },
            "--len",
            &len.to_string(),
        ])?;
        pong.ready()?;
        let mut buf = vec![0u8; len];
        let mut lat = Latencies::new();
        let start = Instant::now();
        let mut done = 0usize;
        let mut result = Ok(());
        for i in 0..(s.warmup + s.rounds) as u64 {
            if i as usize >= s.warmup && start.elapsed() > s.max {
                break;
            }
            buf[..8].copy_from_slice(&i.to_le_bytes());
            let t = Instant::now();
            let sent = roles::iox_send(&side.publisher, &buf).and_then(|()| {
                if waitset {
                    side.notifier.notify().map(|_| ()).map_err(err("notify"))
                } else {
                    Ok(())
                }
            });
            if let Err(e) = sent.and_then(|()| {
                roles::iox_recv(
                    &side,
                    waitset.then_some(&ws),
                    i,
                    t + Duration::from_secs(10),
                )
            }) {
                result = Err(e);
                break;
            }
            if i as usize >= s.warmup {
                lat.record(t.elapsed());
                done += 1;
            }
        }
        lat.cut_short = (s.rounds - done.min(s.rounds)) as u64;
        let _ = pong.finish();
        stop_load(loaders)?;
        result.map(|()| lat)
    };
    let _ = petrel_ipc::remove_vehicle_files(&vehicle);
    result
}

fn start_load(load: Load) -> Res<Vec<Kid>> {
    let mut kids = Vec::new();
    if load == Load::Cpu {
        for _ in 0..cpus() {
            let mut b = Kid::role(&["busy"])?;
            b.ready()?;
            kids.push(b);
        }
    }
    Ok(kids)
}

fn stop_load(kids: Vec<Kid>) -> Res<()> {
    for k in kids {
        k.finish()?;
    }
    Ok(())
}

fn socket_rt(s: &Settings, mut stream: impl Read + Write, mut pong: Kid) -> Res<Latencies> {
    let len = payload_len();
    pong.ready()?;
    let mut buf = vec![0u8; len];
    let mut lat = Latencies::new();
    let start = Instant::now();
    let mut done = 0;
    for i in 0..s.warmup + s.rounds {
        if i >= s.warmup && start.elapsed() > s.max {
            break;
        }
        buf[..8].copy_from_slice(&(i as u64).to_le_bytes());
        let t = Instant::now();
        stream.write_all(&buf).map_err(err("socket write"))?;
        stream.read_exact(&mut buf).map_err(err("socket read"))?;
        if i >= s.warmup {
            lat.record(t.elapsed());
            done += 1;
        }
    }
    lat.cut_short = (s.rounds - done) as u64;
    drop(stream);
    pong.finish()?;
    Ok(lat)
}

/// Unix-domain stream socket ping-pong (blocking reads), the Petrel event's size.
pub fn uds_rt(s: &Settings, load: Load) -> Res<Latencies> {
    let dir = tempfile::tempdir().map_err(|e| format!("tempdir: {e}"))?;
    let path = dir.path().join("pp.sock");
    let listener = UnixListener::bind(&path).map_err(err("bind"))?;
    let loaders = start_load(load)?;
    let pong = Kid::role(&[
        "sock-pong",
        "--uds",
        &path.display().to_string(),
        "--len",
        &payload_len().to_string(),
    ])?;
    let (stream, _) = listener.accept().map_err(err("accept"))?;
    let r = socket_rt(s, stream, pong);
    stop_load(loaders)?;
    r
}

/// TCP loopback ping-pong (TCP_NODELAY, blocking reads), the Petrel event's size: what
/// ProCoSA used.
pub fn tcp_rt(s: &Settings, load: Load) -> Res<Latencies> {
    let listener = TcpListener::bind("127.0.0.1:0").map_err(err("bind"))?;
    let addr = listener.local_addr().map_err(err("addr"))?;
    let loaders = start_load(load)?;
    let pong = Kid::role(&[
        "sock-pong",
        "--tcp",
        &addr.to_string(),
        "--len",
        &payload_len().to_string(),
    ])?;
    let (stream, _): (TcpStream, _) = listener.accept().map_err(err("accept"))?;
    stream.set_nodelay(true).map_err(err("nodelay"))?;
    let r = socket_rt(s, stream, pong);
    stop_load(loaders)?;
    r
}

/// One scale measurement: `n` programs, each in its own process, all doing round trips at
/// once with the player for the same time.
pub struct ScaleResult {
    /// Programs.
    pub programs: usize,
    /// Every program's round trips, merged.
    pub latencies: Latencies,
    /// Round trips per second, all programs together (each one event in, one call out).
    pub events_per_s: f64,
    /// The player's resident memory at the end (kB).
    pub player_rss_kb: u64,
}

/// Round trips with `n` programs attached, all busy, with `wait`.
pub fn scale(s: &Settings, n: usize, wait: WaitStrategy) -> Res<ScaleResult> {
    let run = PlayerRun::start(n, wait, Load::Idle)?;
    let gate = run.dir().join("gate");
    let out_dir = run.dir().to_path_buf();
    let wait_s = wait.to_string();
    let secs = s.scale_secs.to_string();
    let mut kids = Vec::new();
    let mut result = Ok(());
    for k in 0..n {
        let out = out_dir.join(format!("p{k}.txt"));
        match Kid::role(&[
            "program",
            "--vehicle",
            &run.vehicle,
            "--name",
            &crate::project::program_name(k),
            "--event",
            &format!("pong_{k}"),
            "--wait",
            &wait_s,
            "--warmup",
            // Every program warms up before the gate opens, one after another on a shared
            // player: 50 rounds each in the full mode, 5 in the short one (the test's time).
            &(s.warmup / 10).clamp(5, 50).to_string(),
            "--rounds",
            "100000000",
            "--max-secs",
            &secs,
            "--gate",
            &gate.display().to_string(),
            "--out",
            &out.display().to_string(),
        ]) {
            Ok(k) => kids.push(k),
            Err(e) => {
                result = Err(e);
                break;
            }
        }
    }
    if result.is_ok() {
        for k in &mut kids {
            if let Err(e) = k.ready() {
                result = Err(e);
                break;
            }
        }
    }
    let mut merged = Latencies::new();
    let mut rounds = 0u64;
    let mut player_rss_kb = 0;
    let mut wall = s.scale_secs;
    if result.is_ok() {
        std::fs::write(&gate, b"go").map_err(err("gate"))?;
        let opened = Instant::now();
        for (k, kid) in kids.drain(..).enumerate() {
            kid.finish()?;
            let text = std::fs::read_to_string(out_dir.join(format!("p{k}.txt")))
                .map_err(|e| format!("program {k}: no result ({e})"))?;
            let l = Latencies::from_text(&text)?;
            rounds += l.len();
            merged.merge(&l);
        }
        // From the gate to the last program's end: a program stops at its first round after
        // the time given, and that round may be long when the player is shared by 50.
        wall = opened.elapsed().as_secs_f64().max(s.scale_secs);
        player_rss_kb = run
            .player_pid()
            .and_then(|p| crate::footprint::status_kb(p, "VmRSS"))
            .unwrap_or(0);
    }
    drop(kids);
    run.stop()?;
    result?;
    Ok(ScaleResult {
        programs: n,
        latencies: merged,
        events_per_s: rounds as f64 / wall,
        player_rss_kb,
    })
}
