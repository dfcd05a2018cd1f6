//! The processes a benchmark starts: this binary run again with `role ...`.
//!
//! Each prints `READY` on its standard output once set up, and stops in good order when its
//! standard input closes (the orchestrator drops it), except the player, which stops on
//! SIGTERM like `petrel play`.

use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use petrel_ipc::iceoryx2::prelude::*;
use petrel_ipc::{Participant, Reactor, Role, Value, Vehicle, WaitStrategy};
use petrel_programs::{Call, PlayerCheck, Program, ProgramConfig};

use crate::stats::Latencies;

/// An error as text, with what was being done.
pub type Res<T> = Result<T, String>;

/// Maps any debug-printable error to text naming `what` failed.
pub fn err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> String {
    move |e| format!("{what}: {e:?}")
}

/// Says READY to the orchestrator.
pub fn ready() {
    say("READY");
}

/// A flag set once standard input reaches its end (the orchestrator let go of us).
pub fn stop_on_stdin_eof() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    std::thread::spawn(move || {
        let mut buf = [0u8; 64];
        let mut stdin = std::io::stdin();
        while matches!(stdin.read(&mut buf), Ok(n) if n > 0) {}
        flag.store(true, Ordering::Relaxed);
    });
    stop
}

/// A pause switch worked from standard input, for a process that must not run while another
/// set-up is measured (a busy-polling peer would take a CPU from it): a `pause` line pauses
/// it, a `go` line lets it go on, the end of the input stops it.
#[derive(Clone)]
pub struct Gate {
    paused: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    // The paused process sleeps on it, and the switch changes under its lock: a `go` is
    // never missed.
    wake: Arc<(Mutex<()>, Condvar)>,
}

impl Gate {
    /// Reads the orchestrator's lines on a thread of its own.
    pub fn on_stdin() -> Gate {
        let gate = Gate {
            paused: Arc::new(AtomicBool::new(false)),
            stop: Arc::new(AtomicBool::new(false)),
            wake: Arc::new((Mutex::new(()), Condvar::new())),
        };
        let g = gate.clone();
        std::thread::spawn(move || {
            let mut line = String::new();
            let mut stdin = std::io::stdin().lock();
            loop {
                line.clear();
                match stdin.read_line(&mut line) {
                    Ok(n) if n > 0 => match line.trim() {
                        "pause" => g.set(|| g.paused.store(true, Ordering::SeqCst)),
                        "go" => g.set(|| g.paused.store(false, Ordering::SeqCst)),
                        _ => {}
                    },
                    _ => break,
                }
            }
            g.set(|| g.stop.store(true, Ordering::SeqCst));
        });
        gate
    }

    fn set(&self, change: impl FnOnce()) {
        let (lock, cv) = &*self.wake;
        let _held = lock.lock().unwrap_or_else(|p| p.into_inner());
        change();
        cv.notify_all();
    }

    /// Whether the input has ended.
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// When paused: says `PAUSED`, sleeps until `go` (then says `GOING`) or the end of the
    /// input. A relaxed load when not paused, so that a busy loop may call it every turn.
    pub fn hold(&self) {
        if !self.paused.load(Ordering::Relaxed) {
            return;
        }
        say("PAUSED");
        let (lock, cv) = &*self.wake;
        let mut held = lock.lock().unwrap_or_else(|p| p.into_inner());
        while self.paused.load(Ordering::SeqCst) && !self.stop.load(Ordering::SeqCst) {
            held = cv.wait(held).unwrap_or_else(|p| p.into_inner());
        }
        drop(held);
        say("GOING");
    }
}

/// Says a line to the orchestrator at once.
fn say(line: &str) {
    println!("{line}");
    let _ = std::io::stdout().flush();
}

/// Loads and checks a project (what `petrel play` starts with).
pub fn compiled(dir: &Path) -> Res<petrel_nets::compiled::CompiledProject> {
    let (_, compiled, diags) = petrel_nets::project::load_and_check(dir)
        .map_err(|e| format!("{}: {e:?}", dir.display()))?;
    compiled.ok_or_else(|| format!("{}: the project has errors: {diags:?}", dir.display()))
}

/// The player, as `petrel play` runs it (same `PlayerLoop`), until SIGTERM.
pub fn player(dir: &Path, vehicle: &str, wait: WaitStrategy, journal: Option<PathBuf>) -> Res<()> {
    let c = compiled(dir)?;
    let mut opts = petrel_player::runtime::PlayOptions::new(vehicle);
    opts.wait = wait;
    opts.journal = journal;
    opts.project_dir = dir.display().to_string();
    petrel_player::runtime::play(&c, &opts).map_err(|e| e.to_string())?;
    Ok(())
}

/// The parameters of a round-trip event or call: a counter and six floats, as in
/// `ipc/examples/latency.rs`.
pub fn round_payload(i: usize) -> Vec<Value> {
    vec![Value::Int(i as i64), Value::FloatList(vec![0.5; 6])]
}

/// How a measuring program runs.
#[derive(Clone, Debug)]
pub struct RoundTrips {
    /// The vehicle.
    pub vehicle: String,
    /// The program's name.
    pub program: String,
    /// The event it emits (the player answers with the call `ping`).
    pub event: String,
    /// Its wait strategy.
    pub wait: WaitStrategy,
    /// Rounds before the measurement.
    pub warmup: usize,
    /// Rounds measured at most.
    pub rounds: usize,
    /// Time the measurement takes at most.
    pub max: Duration,
    /// With several programs: say READY after the warm-up and measure only once this file
    /// exists, so that all measure at once.
    pub gate: Option<PathBuf>,
}

/// What a measuring program measured.
pub struct Measured {
    /// The round trips.
    pub latencies: Latencies,
}

/// The measuring side of a Petrel round trip: a program that emits an event and waits for
/// the call the player's transition makes, one round at a time.
pub struct Pinger {
    program: Program,
    name: String,
    event: String,
    next: usize,
    /// The call each round receives into: after the first, a round's call allocates nothing.
    call: Call,
}

impl Pinger {
    /// Connects the program `cfg.program` to the vehicle's player (with `cfg.wait`).
    pub fn connect(cfg: &RoundTrips) -> Res<Pinger> {
        let vehicle = Vehicle::new(&cfg.vehicle).map_err(|e| e.to_string())?;
        let config = ProgramConfig {
            wait: cfg.wait,
            handle_signals: false,
            // The default checks that the player lives before every send (~0.2 ms): a program
            // that talks to the player thousands of times a second trusts a check for a second.
            player_check: PlayerCheck::Every(Duration::from_secs(1)),
            ..ProgramConfig::default()
        };
        let program = Program::connect_with(&vehicle, &[cfg.program.as_str()], config)
            .map_err(|e| e.to_string())?;
        Ok(Pinger {
            program,
            name: cfg.program.clone(),
            event: cfg.event.clone(),
            next: 0,
            call: Call::default(),
        })
    }

    /// One round trip: from the emit to the arrival of its call.
    pub fn round(&mut self) -> Res<Duration> {
        let i = self.next;
        self.next += 1;
        let start = Instant::now();
        self.program
            .emit(self.event.clone(), round_payload(i))
            .map_err(|e| format!("{}: emit: {e}", self.name))?;
        loop {
            let call = &mut self.call;
            match self.program.recv_into(call, Some(Duration::from_secs(20))) {
                Ok(true) => {
                    if call.function == "ping" && call.args.first() == Some(&Value::Int(i as i64)) {
                        return Ok(start.elapsed());
                    }
                }
                Ok(false) => return Err(format!("{}: no call for round {i}", self.name)),
                Err(e) => return Err(format!("{}: {e}", self.name)),
            }
        }
    }
}

/// A program that measures the round trip program -> player -> program: it emits an event
/// and waits for the call the player's transition makes, again and again.
pub fn petrel_round_trips(cfg: &RoundTrips) -> Res<Measured> {
    let mut pinger = Pinger::connect(cfg)?;
    for _ in 0..cfg.warmup {
        pinger.round()?;
    }
    if let Some(gate) = &cfg.gate {
        ready();
        let waited = Instant::now();
        while !gate.exists() {
            if waited.elapsed() > Duration::from_secs(120) {
                return Err("the start gate never opened".to_owned());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let mut latencies = Latencies::new();
    let start = Instant::now();
    let mut done = 0;
    for _ in 0..cfg.rounds {
        if start.elapsed() > cfg.max {
            break;
        }
        latencies.record(pinger.round()?);
        done += 1;
    }
    latencies.cut_short = (cfg.rounds - done) as u64;
    // No close(): it waits for the player's acknowledgement of the last events, which the
    // measurement does not need; the player is stopped next.
    drop(pinger);
    Ok(Measured { latencies })
}

/// Sends `len` bytes on a raw iceoryx2 publisher.
pub fn iox_send(
    publisher: &petrel_ipc::iceoryx2::port::publisher::Publisher<ipc::Service, [u8], ()>,
    buf: &[u8],
) -> Res<()> {
    let sample = publisher
        .loan_slice_uninit(buf.len())
        .map_err(err("loan"))?;
    let sample = sample.write_from_slice(buf);
    sample.send().map_err(err("send"))?;
    Ok(())
}

/// Raw iceoryx2 ports of one side of a ping-pong: publisher on `out`, subscriber on `inp`, and
/// for the WaitSet mode a notifier and a listener on event services of the same names.
pub struct IoxSide {
    /// Sends.
    pub publisher: petrel_ipc::iceoryx2::port::publisher::Publisher<ipc::Service, [u8], ()>,
    /// Receives.
    pub subscriber: petrel_ipc::iceoryx2::port::subscriber::Subscriber<ipc::Service, [u8], ()>,
    /// Wakes the other side.
    pub notifier: petrel_ipc::iceoryx2::port::notifier::Notifier<ipc::Service>,
    /// Woken by the other side.
    pub listener: petrel_ipc::iceoryx2::port::listener::Listener<ipc::Service>,
}

/// Opens one side's raw ports on `node`.
pub fn iox_side(node: &Node<ipc::Service>, out: &str, inp: &str, len: usize) -> Res<IoxSide> {
    let pubsub = |name: &str| {
        let name = ServiceName::new(name).map_err(err("service name"))?;
        node.service_builder(&name)
            .publish_subscribe::<[u8]>()
            .max_publishers(1)
            .max_subscribers(1)
            .subscriber_max_buffer_size(4)
            .history_size(0)
            .open_or_create()
            .map_err(err("publish-subscribe service"))
    };
    let event = |name: &str| {
        let name = ServiceName::new(&format!("{name}/wake")).map_err(err("service name"))?;
        node.service_builder(&name)
            .event()
            .open_or_create()
            .map_err(err("event service"))
    };
    let out_s = pubsub(out)?;
    let in_s = pubsub(inp)?;
    let publisher = out_s
        .publisher_builder()
        .initial_max_slice_len(len)
        .create()
        .map_err(err("publisher"))?;
    let subscriber = in_s
        .subscriber_builder()
        .create()
        .map_err(err("subscriber"))?;
    let notifier = event(out)?
        .notifier_builder()
        .create()
        .map_err(err("notifier"))?;
    let listener = event(inp)?
        .listener_builder()
        .create()
        .map_err(err("listener"))?;
    Ok(IoxSide {
        publisher,
        subscriber,
        notifier,
        listener,
    })
}

/// Receives the answer to `round` (a sample whose first 8 bytes are the round), busy polling
/// (`waitset` None) or sleeping in the WaitSet (the listener attached by the caller), until
/// `deadline`.
pub fn iox_recv(
    side: &IoxSide,
    waitset: Option<&WaitSet<ipc::Service>>,
    round: u64,
    deadline: Instant,
) -> Res<()> {
    loop {
        while let Some(sample) = side.subscriber.receive().map_err(err("receive"))? {
            let p = sample.payload();
            if p.len() >= 8 && p[..8] == round.to_le_bytes() {
                return Ok(());
            }
        }
        if Instant::now() > deadline {
            return Err(format!("raw iceoryx2: no answer to round {round}"));
        }
        match waitset {
            Some(ws) => {
                ws.wait_and_process_once_with_timeout(
                    |_| CallbackProgression::Continue,
                    Duration::from_millis(100),
                )
                .map_err(err("wait"))?;
                side.listener.try_wait(|_| {}).map_err(err("listener"))?;
            }
            None => std::hint::spin_loop(),
        }
    }
}

/// The answering side of the raw iceoryx2 ping-pong. It pauses on its [`Gate`] (`pause` and
/// `go` lines): the busy-polling one would otherwise take a CPU from the set-up measured
/// beside it.
pub fn iox_pong(name: &str, prefix: &str, waitset: bool, len: usize) -> Res<()> {
    let gate = Gate::on_stdin();
    let vehicle = Vehicle::with_prefix(name, prefix).map_err(|e| e.to_string())?;
    let me = Participant::join(&vehicle, Role::tool("ioxpong").map_err(|e| e.to_string())?)
        .map_err(|e| e.to_string())?;
    let side = iox_side(me.node(), "bench/pong", "bench/ping", len)?;
    let ws = if waitset {
        Some(
            WaitSetBuilder::new()
                .create::<ipc::Service>()
                .map_err(err("waitset"))?,
        )
    } else {
        None
    };
    let guard = match &ws {
        Some(ws) => Some(
            ws.attach_notification(&side.listener)
                .map_err(err("attach"))?,
        ),
        None => None,
    };
    ready();
    let mut buf = vec![0u8; len];
    let mut idle = 0u32;
    while !gate.stopped() {
        gate.hold();
        let mut got = false;
        while let Some(sample) = side.subscriber.receive().map_err(err("receive"))? {
            let n = sample.payload().len().min(len);
            buf[..n].copy_from_slice(&sample.payload()[..n]);
            drop(sample);
            iox_send(&side.publisher, &buf)?;
            if ws.is_some() {
                side.notifier.notify().map_err(err("notify"))?;
            }
            got = true;
        }
        if got {
            idle = 0;
            continue;
        }
        match &ws {
            Some(ws) => {
                ws.wait_and_process_once_with_timeout(
                    |_| CallbackProgression::Continue,
                    Duration::from_millis(50),
                )
                .map_err(err("wait"))?;
                side.listener.try_wait(|_| {}).map_err(err("listener"))?;
            }
            None => {
                idle = idle.wrapping_add(1);
                std::hint::spin_loop();
            }
        }
    }
    drop(guard);
    Ok(())
}

/// The answering side of a socket ping-pong: echoes `len`-byte messages until EOF.
pub fn sock_pong(mut stream: impl Read + Write, len: usize) -> Res<()> {
    let mut buf = vec![0u8; len];
    ready();
    loop {
        match stream.read_exact(&mut buf) {
            Ok(()) => stream.write_all(&buf).map_err(err("write"))?,
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
            Err(e) => return Err(format!("read: {e}")),
        }
    }
}

/// A program emitting `tick(n)` at `rate` events a second until standard input closes.
pub fn emitter(vehicle: &str, rate: f64) -> Res<()> {
    let stop = stop_on_stdin_eof();
    let vehicle = Vehicle::new(vehicle).map_err(|e| e.to_string())?;
    let config = ProgramConfig {
        handle_signals: false,
        player_check: PlayerCheck::Every(Duration::from_secs(1)),
        outbox_capacity: 65_536,
        ..ProgramConfig::default()
    };
    let mut program =
        Program::connect_with(&vehicle, &["LOADGEN"], config).map_err(|e| e.to_string())?;
    ready();
    let start = Instant::now();
    let mut sent = 0u64;
    let mut errors = 0u64;
    while !stop.load(Ordering::Relaxed) {
        // Catch up with the schedule, then sleep a tenth of a millisecond: the average rate
        // is kept even though a sleep overshoots.
        let due = (start.elapsed().as_secs_f64() * rate) as u64;
        while sent < due {
            if program.emit("tick", vec![Value::Int(sent as i64)]).is_err() {
                errors += 1;
            }
            sent += 1;
        }
        std::thread::sleep(Duration::from_micros(100));
    }
    let _ = program.flush();
    println!(
        "SENT {sent} SECS {:.3} ERRORS {errors}",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A monitor: follows the player's heartbeats (its status JSON) and marking deltas, as
/// `petrel status` does, until standard input closes.
pub fn status_reader(vehicle: &str) -> Res<()> {
    let stop = stop_on_stdin_eof();
    let vehicle = Vehicle::new(vehicle).map_err(|e| e.to_string())?;
    let me = Participant::join(
        &vehicle,
        Role::tool("benchstatus").map_err(|e| e.to_string())?,
    )
    .map_err(|e| e.to_string())?;
    let beats = me.heartbeat_subscriber().map_err(|e| e.to_string())?;
    let marking = me.marking_subscriber().map_err(|e| e.to_string())?;
    let reactor =
        Reactor::without_signal_handling(WaitStrategy::Block).map_err(|e| e.to_string())?;
    ready();
    let (mut n_beats, mut n_deltas) = (0u64, 0u64);
    while !stop.load(Ordering::Relaxed) {
        reactor
            .wait(&[&beats, &marking], Some(Duration::from_millis(50)))
            .map_err(|e| e.to_string())?;
        while let Some(b) = beats.try_recv().map_err(|e| e.to_string())? {
            // Read the status as a monitor would.
            let _ = serde_json::from_str::<serde_json::Value>(&b.msg.status);
            n_beats += 1;
        }
        while marking.try_recv().map_err(|e| e.to_string())?.is_some() {
            n_deltas += 1;
        }
    }
    println!("READ {n_beats} HEARTBEATS {n_deltas} DELTAS");
    Ok(())
}

/// Burns a CPU until standard input closes.
pub fn busy() -> Res<()> {
    let stop = stop_on_stdin_eof();
    ready();
    let mut x = 0u64;
    while !stop.load(Ordering::Relaxed) {
        for _ in 0..100_000 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
    }
    std::hint::black_box(x);
    Ok(())
}

/// A process that does nothing but wait (the footprint's baseline), optionally with a raw
/// iceoryx2 node and one publish-subscribe service of iceoryx2's default settings.
pub fn idle(with_iox: bool) -> Res<()> {
    let stop = stop_on_stdin_eof();
    let keep = if with_iox {
        let vehicle = Vehicle::isolated("ioxidle").map_err(|e| e.to_string())?;
        let me = Participant::join(&vehicle, Role::tool("ioxidle").map_err(|e| e.to_string())?)
            .map_err(|e| e.to_string())?;
        let side = iox_side(me.node(), "bench/a", "bench/a", 64)?;
        iox_send(&side.publisher, &[0u8; 64])?;
        Some((side, me, vehicle))
    } else {
        None
    };
    ready();
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(20));
    }
    if let Some((side, me, vehicle)) = keep {
        drop(side);
        drop(me);
        let _ = petrel_ipc::remove_vehicle_files(&vehicle);
    }
    Ok(())
}

/// Reads a child's lines until `READY` (or fails with what it said).
pub fn await_ready(out: &mut impl BufRead, who: &str) -> Res<()> {
    let mut line = String::new();
    loop {
        line.clear();
        let n = out
            .read_line(&mut line)
            .map_err(|e| format!("{who}: {e}"))?;
        if n == 0 {
            return Err(format!("{who} ended before it was ready"));
        }
        if line.trim() == "READY" {
            return Ok(());
        }
    }
}

/// Opens a player's ports one by one on a fresh vehicle and prints the resident memory after
/// each (`STEP what kB`): where a Petrel process's memory goes.
pub fn ports() -> Res<()> {
    let rss = || crate::footprint::status_kb(std::process::id(), "VmRSS").unwrap_or(0);
    let step = |what: &str| println!("STEP {what}\t{}", rss());
    step("process started");
    let vehicle = Vehicle::isolated("ports").map_err(|e| e.to_string())?;
    let s = |e: petrel_ipc::SetupError| e.to_string();
    {
        let player = Participant::join(&vehicle, Role::Player).map_err(s)?;
        step("joined the vehicle (iceoryx2 node)");
        // The bound a project of fixed-size events records (64 B); senders take 512 B at least.
        // Three programs (the three call senders below).
        let events = player.event_receiver_sized(64, 3).map_err(s)?;
        step("events receiver (the player's, recording its project's longest event)");
        let calls = player.call_sender("P0").map_err(s)?;
        step("a call sender, a program taking text or lists (grows to 64 KiB calls)");
        let sized = player.call_sender_sized("P2", Some(64)).map_err(s)?;
        step("a call sender sized from the project (fixed-size parameters: 64 B calls)");
        let marking = player.marking_publisher().map_err(s)?;
        step("marking publisher, default (grows to 1 MiB)");
        let marking_sized = player.marking_publisher_sized(4 * 1024).map_err(s)?;
        step("marking publisher sized from the project (4 KiB snapshots)");
        let beat = player.heartbeat_publisher_sized(64 * 1024).map_err(s)?;
        step("heartbeat publisher (64 KiB)");
        let program = Participant::join(&vehicle, Role::program("P1").map_err(|e| e.to_string())?)
            .map_err(s)?;
        let sender_default = program.event_sender().map_err(s)?;
        step("an events sender, default (grows to 64 KiB events)");
        let sender = program.event_sender_sized().map_err(s)?;
        step("an events sender sized from the project (a program's: 512 B samples)");
        let receiver = program.call_receiver().map_err(s)?;
        step("a calls receiver (a program's)");
        let beats = program.heartbeat_subscriber().map_err(s)?;
        step("a heartbeat subscriber");
        let signals = program.signals_subscriber().map_err(s)?;
        step("a signals subscriber");
        drop((
            events,
            calls,
            sized,
            marking,
            marking_sized,
            beat,
            sender_default,
            sender,
            receiver,
            beats,
            signals,
            program,
            player,
        ));
    }
    let _ = petrel_ipc::remove_vehicle_files(&vehicle);
    Ok(())
}
