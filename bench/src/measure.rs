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

use crate::alternate::{alternate, prepare, Plan, Side};
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
    /// Blocks the transport part's set-ups take turns in (see `alternate`).
    pub blocks: usize,
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

    /// Writes a line to its standard input.
    pub fn tell(&mut self, line: &str) -> Res<()> {
        let name = &self.name;
        let stdin = self
            .stdin
            .as_mut()
            .ok_or_else(|| format!("{name}: no input"))?;
        writeln!(stdin, "{line}")
            .and_then(|()| stdin.flush())
            .map_err(|e| format!("{name}: {e}"))
    }

    /// Reads its lines until `want` (fails at the end of its output).
    pub fn expect(&mut self, want: &str) -> Res<()> {
        loop {
            let line = self.line()?;
            if line.is_empty() {
                return Err(format!("{} ended before saying {want}", self.name));
            }
            if line.trim() == want {
                return Ok(());
            }
        }
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
    paused: bool,
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
            paused: false,
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

    /// Stops the player (SIGSTOP) until [`resume`](Self::resume): it runs `petrel play`'s loop,
    /// which has no pause of its own, and a spinning player would take a CPU from what is
    /// measured meanwhile (a sleeping one would still wake for its heartbeats).
    pub fn pause(&mut self) -> Res<()> {
        if let Some(pid) = self.player_pid() {
            signal(pid, "STOP")?;
            self.paused = true;
            await_stopped(pid, true)?;
        }
        Ok(())
    }

    /// Lets the player go on (SIGCONT).
    pub fn resume(&mut self) -> Res<()> {
        if let Some(pid) = self.player_pid() {
            signal(pid, "CONT")?;
            self.paused = false;
            await_stopped(pid, false)?;
        }
        Ok(())
    }

    /// Stops everything; returns what the background processes said.
    pub fn stop(mut self) -> Res<Vec<String>> {
        if self.paused {
            // A stopped player would not see its SIGTERM.
            let _ = self.resume();
        }
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

/// Sends signal `sig` (a name: STOP, CONT, TERM) to process `pid`.
fn signal(pid: u32, sig: &str) -> Res<()> {
    let status = Command::new("kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .status()
        .map_err(|e| format!("kill -{sig} {pid}: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("kill -{sig} {pid}: {status}"))
    }
}

/// The state letter of process `pid` (`/proc/PID/stat`'s third field: `T` when stopped).
fn process_state(pid: u32) -> Res<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map_err(|e| format!("process {pid}: {e}"))?;
    // The second field (the command) is in parentheses and may hold spaces: the state follows
    // the last closing one.
    stat.rsplit_once(')')
        .and_then(|(_, rest)| rest.trim_start().chars().next())
        .ok_or_else(|| format!("process {pid}: unexpected /proc/{pid}/stat"))
}

/// Waits until process `pid` is stopped (`stopped`) or runs again (a signal is delivered when
/// the process is next scheduled, not when `kill` returns).
fn await_stopped(pid: u32, stopped: bool) -> Res<()> {
    let until = Instant::now() + Duration::from_secs(5);
    loop {
        if (process_state(pid)? == 'T') == stopped {
            return Ok(());
        }
        if Instant::now() > until {
            let what = if stopped { "stop" } else { "go on" };
            return Err(format!("process {pid} did not {what} within 5 s"));
        }
        std::thread::sleep(Duration::from_micros(100));
    }
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

/// Petrel's round trip as a set-up measured in blocks: a player with `wait` on a vehicle of its
/// own, and a program in this process.
pub struct PetrelSide {
    pinger: Option<roles::Pinger>,
    run: Option<PlayerRun>,
}

impl PetrelSide {
    /// Starts the player and connects the program.
    pub fn start(wait: WaitStrategy) -> Res<Box<dyn Side>> {
        let run = PlayerRun::start(1, wait, Load::Idle)?;
        let pinger = roles::Pinger::connect(&roles::RoundTrips {
            vehicle: run.vehicle.clone(),
            program: crate::project::program_name(0),
            event: "pong_0".to_owned(),
            wait,
            warmup: 0,
            rounds: 0,
            max: Duration::ZERO,
            gate: None,
        });
        match pinger {
            Ok(p) => Ok(Box::new(PetrelSide {
                pinger: Some(p),
                run: Some(run),
            })),
            Err(e) => {
                let _ = run.stop();
                Err(e)
            }
        }
    }
}

/// Runs up to `n` rounds of `round` (which returns one round trip's time), recording each
/// into `into` when given, and stops before a round that would start after `until`; returns
/// the rounds done (every [`Side::rounds`] of this module).
fn timed_rounds(
    n: usize,
    mut into: Option<&mut Latencies>,
    until: Option<Instant>,
    mut round: impl FnMut() -> Res<Duration>,
) -> Res<usize> {
    for done in 0..n {
        if until.is_some_and(|u| Instant::now() > u) {
            return Ok(done);
        }
        let d = round()?;
        if let Some(l) = into.as_deref_mut() {
            l.record(d);
        }
    }
    Ok(n)
}

impl Side for PetrelSide {
    fn rounds(
        &mut self,
        n: usize,
        into: Option<&mut Latencies>,
        until: Option<Instant>,
    ) -> Res<usize> {
        let pinger = self.pinger.as_mut().ok_or("finished")?;
        timed_rounds(n, into, until, || pinger.round())
    }

    fn pause(&mut self) -> Res<()> {
        // The program is this process, idle between blocks: only the player runs.
        self.run.as_mut().map_or(Ok(()), PlayerRun::pause)
    }

    fn resume(&mut self) -> Res<()> {
        self.run.as_mut().map_or(Ok(()), PlayerRun::resume)
    }

    fn finish(mut self: Box<Self>) -> Res<()> {
        // No close(): it waits for the player's acknowledgement of the last events, which the
        // measurement does not need.
        drop(self.pinger.take());
        match self.run.take() {
            Some(run) => run.stop().map(|_| ()),
            None => Ok(()),
        }
    }
}

/// Raw iceoryx2 publish-subscribe ping-pong, busy polling or sleeping in a WaitSet, with the
/// Petrel event's size, as a set-up measured in blocks; its answering process pauses on its
/// gate between blocks.
pub struct IoxPingPong {
    // Declared in the order they are dropped: ports, then the node, then the vehicle's files.
    side: Option<roles::IoxSide>,
    ws: Option<WaitSet<ipc::Service>>,
    me: Option<Participant>,
    vehicle: Vehicle,
    pong: Option<Kid>,
    buf: Vec<u8>,
    next: u64,
}

impl IoxPingPong {
    /// Opens the ports and starts the answering process.
    pub fn start(waitset: bool) -> Res<Box<dyn Side>> {
        let len = payload_len();
        let vehicle = Vehicle::isolated("ioxrt").map_err(|e| e.to_string())?;
        let mut me = IoxPingPong {
            side: None,
            ws: None,
            me: None,
            vehicle,
            pong: None,
            buf: vec![0u8; len],
            next: 0,
        };
        match me.open(waitset, len) {
            Ok(()) => Ok(Box::new(me)),
            Err(e) => {
                let _ = Box::new(me).finish();
                Err(e)
            }
        }
    }

    fn open(&mut self, waitset: bool, len: usize) -> Res<()> {
        let me = Participant::join(
            &self.vehicle,
            Role::tool("ioxping").map_err(|e| e.to_string())?,
        )
        .map_err(|e| e.to_string())?;
        self.side = Some(roles::iox_side(me.node(), "bench/ping", "bench/pong", len)?);
        self.me = Some(me);
        if waitset {
            self.ws = Some(
                WaitSetBuilder::new()
                    .create::<ipc::Service>()
                    .map_err(err("waitset"))?,
            );
        }
        let mut pong = Kid::role(&[
            "iox-pong",
            "--name",
            self.vehicle.name(),
            "--prefix",
            self.vehicle.prefix(),
            "--mode",
            if waitset { "waitset" } else { "busy" },
            "--len",
            &len.to_string(),
        ])?;
        let ready = pong.ready();
        self.pong = Some(pong);
        ready
    }

    fn pong(&mut self) -> Res<&mut Kid> {
        self.pong
            .as_mut()
            .ok_or_else(|| "iox-pong: not started".to_owned())
    }
}

impl Side for IoxPingPong {
    fn rounds(
        &mut self,
        n: usize,
        into: Option<&mut Latencies>,
        until: Option<Instant>,
    ) -> Res<usize> {
        let side = self.side.as_ref().ok_or("finished")?;
        // Attached for the block only (a guard borrows the WaitSet), outside the timed rounds.
        let _guard = match &self.ws {
            Some(ws) => Some(
                ws.attach_notification(&side.listener)
                    .map_err(err("attach"))?,
            ),
            None => None,
        };
        timed_rounds(n, into, until, || {
            let i = self.next;
            self.next += 1;
            self.buf[..8].copy_from_slice(&i.to_le_bytes());
            let t = Instant::now();
            roles::iox_send(&side.publisher, &self.buf)?;
            if self.ws.is_some() {
                side.notifier.notify().map_err(err("notify"))?;
            }
            roles::iox_recv(side, self.ws.as_ref(), i, t + Duration::from_secs(10))?;
            Ok(t.elapsed())
        })
    }

    fn pause(&mut self) -> Res<()> {
        let pong = self.pong()?;
        pong.tell("pause")?;
        pong.expect("PAUSED")
    }

    fn resume(&mut self) -> Res<()> {
        let pong = self.pong()?;
        pong.tell("go")?;
        pong.expect("GOING")
    }

    fn finish(mut self: Box<Self>) -> Res<()> {
        // The end of its input stops the answering process, paused or not.
        let stopped = self.pong.take().map_or(Ok(()), |p| p.finish().map(|_| ()));
        drop(self.side.take());
        drop(self.ws.take());
        drop(self.me.take());
        let _ = petrel_ipc::remove_vehicle_files(&self.vehicle);
        stopped
    }
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

/// A socket ping-pong (blocking reads, the Petrel event's size) as a set-up measured in
/// blocks. Between blocks nothing of it runs: the answering process sleeps in its read.
pub struct SocketSide<S: Read + Write> {
    stream: Option<S>,
    pong: Option<Kid>,
    buf: Vec<u8>,
    next: u64,
    // The Unix socket's directory, removed at the end.
    _dir: Option<tempfile::TempDir>,
}

impl<S: Read + Write + 'static> SocketSide<S> {
    fn started(stream: S, mut pong: Kid, dir: Option<tempfile::TempDir>) -> Res<Box<dyn Side>> {
        let ready = pong.ready();
        let side = Box::new(SocketSide {
            stream: Some(stream),
            pong: Some(pong),
            buf: vec![0u8; payload_len()],
            next: 0,
            _dir: dir,
        });
        match ready {
            Ok(()) => Ok(side),
            Err(e) => {
                let _ = side.finish();
                Err(e)
            }
        }
    }
}

impl<S: Read + Write> Side for SocketSide<S> {
    fn rounds(
        &mut self,
        n: usize,
        into: Option<&mut Latencies>,
        until: Option<Instant>,
    ) -> Res<usize> {
        let stream = self.stream.as_mut().ok_or("finished")?;
        timed_rounds(n, into, until, || {
            self.buf[..8].copy_from_slice(&self.next.to_le_bytes());
            self.next += 1;
            let t = Instant::now();
            stream.write_all(&self.buf).map_err(err("socket write"))?;
            stream
                .read_exact(&mut self.buf)
                .map_err(err("socket read"))?;
            Ok(t.elapsed())
        })
    }

    fn pause(&mut self) -> Res<()> {
        Ok(())
    }

    fn resume(&mut self) -> Res<()> {
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> Res<()> {
        drop(self.stream.take());
        self.pong.take().map_or(Ok(()), |p| p.finish().map(|_| ()))
    }
}

/// Starts a Unix-domain stream socket ping-pong.
pub fn uds_side() -> Res<Box<dyn Side>> {
    let dir = tempfile::tempdir().map_err(|e| format!("tempdir: {e}"))?;
    let path = dir.path().join("pp.sock");
    let listener = UnixListener::bind(&path).map_err(err("bind"))?;
    let pong = Kid::role(&[
        "sock-pong",
        "--uds",
        &path.display().to_string(),
        "--len",
        &payload_len().to_string(),
    ])?;
    let (stream, _) = listener.accept().map_err(err("accept"))?;
    SocketSide::started(stream, pong, Some(dir))
}

/// Starts a TCP loopback ping-pong (`TCP_NODELAY`): what ProCoSA used.
pub fn tcp_side() -> Res<Box<dyn Side>> {
    let listener = TcpListener::bind("127.0.0.1:0").map_err(err("bind"))?;
    let addr = listener.local_addr().map_err(err("addr"))?;
    let pong = Kid::role(&[
        "sock-pong",
        "--tcp",
        &addr.to_string(),
        "--len",
        &payload_len().to_string(),
    ])?;
    let (stream, _): (TcpStream, _) = listener.accept().map_err(err("accept"))?;
    stream.set_nodelay(true).map_err(err("nodelay"))?;
    SocketSide::started(stream, pong, None)
}

/// One set-up measured alone: warm-up, then all its rounds in one block.
pub fn alone(s: &Settings, side: Res<Box<dyn Side>>) -> Res<Latencies> {
    let plan = Plan {
        rounds: s.rounds,
        blocks: 1,
        block_warmup: 0,
        max: s.max,
    };
    let mut r = alternate(vec![prepare(side, s.warmup)], &plan);
    r.pop()
        .unwrap_or_else(|| Err("nothing measured".to_owned()))
        .map(|a| a.latencies)
}

/// Unix-domain stream socket ping-pong (blocking reads), the Petrel event's size, alone, under
/// `load`.
pub fn uds_rt(s: &Settings, load: Load) -> Res<Latencies> {
    let loaders = start_load(load)?;
    let r = alone(s, uds_side());
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
