//! The player process: the engine wired to iceoryx2 (`petrel play`).
//!
//! One reactor thread waits, with the chosen strategy, on the events service, the next timer
//! deadline, the heartbeat and the liveness check. On each wake-up it moves time forward,
//! drains incoming events into the engine (refusing malformed ones with a `bad_message` event),
//! turns dead programs into `program_lost`, processes the queue, sends calls (an absent program
//! gives `call_failed`), journals every input and step, and publishes marking deltas and a
//! heartbeat carrying the live status. The heartbeat is the acknowledgement senders wait for,
//! and it goes out only after the journal is flushed: an acknowledged event is on record.

use crate::engine::{ArgValue, Args, Engine, Micros, Refusal, Sink, Stats};
use crate::journal::{Entry, FlushPolicy, JournalWriter};
use crate::script::Recorder;
use petrel_ipc::{
    CallMsg, CallSender, HeartbeatPublisher, MarkingMsg, MarkingPublisher, Participant,
    ProgramWatch, Reactor, RecvError, Role, SendError, Vehicle, WaitStrategy,
};
use petrel_nets::compiled::{CompiledProject, EventId, FunctionId, NetId, ProgramId, Value};
use petrel_nets::semantics::{Layout, Notice};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tracing::{debug, error, info, warn};

/// How to run the player.
#[derive(Clone, Debug)]
pub struct PlayOptions {
    /// The vehicle: its services are `petrel/<vehicle>/...`.
    pub vehicle: String,
    /// How the reactor waits.
    pub wait: WaitStrategy,
    /// Period of the heartbeat (which carries the live status).
    pub heartbeat: Duration,
    /// Period of the check for dead programs (also run whenever a sender is seen dying).
    pub liveness: Duration,
    /// Stop after this long (tests and demos); `None` runs until SIGINT or SIGTERM.
    pub run_for: Option<Duration>,
    /// The journal directory; `None`: no journal.
    pub journal: Option<PathBuf>,
    /// When journal records reach the disk.
    pub flush: FlushPolicy,
    /// Start a new journal segment past this size.
    pub rotate_bytes: u64,
    /// Restore the mission from the journal and carry on.
    pub resume: bool,
    /// The project directory, recorded in the journal header.
    pub project_dir: String,
}

impl PlayOptions {
    /// Defaults for `vehicle`: block, heartbeat every 100 ms, liveness every 50 ms, no journal.
    pub fn new(vehicle: &str) -> Self {
        PlayOptions {
            vehicle: vehicle.to_string(),
            wait: WaitStrategy::Block,
            heartbeat: Duration::from_millis(100),
            liveness: Duration::from_millis(50),
            run_for: None,
            journal: None,
            flush: FlushPolicy::EveryRecord,
            rotate_bytes: 64 << 20,
            resume: false,
            project_dir: String::new(),
        }
    }
}

/// Why the player could not run.
#[derive(Debug)]
pub enum PlayError {
    /// The vehicle name is not usable.
    Vehicle(String),
    /// iceoryx2 could not be set up (another player on the vehicle, say).
    Setup(String),
    /// The journal could not be written or, for `--resume`, read.
    Journal(String),
}

impl std::fmt::Display for PlayError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlayError::Vehicle(e) => write!(f, "bad vehicle name: {e}"),
            PlayError::Setup(e) => write!(f, "cannot set up the player: {e}"),
            PlayError::Journal(e) => write!(f, "journal: {e}"),
        }
    }
}

impl std::error::Error for PlayError {}

/// What a run of the player did.
#[derive(Clone, Debug, Default)]
pub struct PlayReport {
    /// The engine's counters.
    pub stats: Stats,
    /// Events received from iceoryx2 (decoded or not).
    pub messages: u64,
    /// Messages refused before the engine: undecodable, unknown event, wrong parameters.
    pub bad_messages: u64,
    /// Calls delivered to programs.
    pub calls_sent: u64,
    /// Calls to absent programs (each became `call_failed`).
    pub calls_failed: u64,
    /// Journal records written.
    pub journal_records: u64,
    /// Time the reactor thread spent writing the journal.
    pub journal_busy: Duration,
    /// Steps restored from the journal by `--resume`.
    pub resumed_steps: u64,
}

/// Sends what the engine asks for, during one step, and keeps its record.
struct RuntimeSink<'a> {
    log: Recorder<'a>,
    calls: &'a [CallSender],
    failed: Vec<(ProgramId, FunctionId)>,
    activated: Vec<String>,
    deactivated: Vec<String>,
    sent: u64,
}

fn to_wire(v: ArgValue<'_>) -> petrel_ipc::Value {
    match v {
        ArgValue::Int(i) => petrel_ipc::Value::Int(i),
        ArgValue::Float(f) => petrel_ipc::Value::Float(f),
        ArgValue::Bool(b) => petrel_ipc::Value::Bool(b),
        ArgValue::Text(s) => petrel_ipc::Value::Text(s.to_string()),
        ArgValue::FloatList(l) => petrel_ipc::Value::FloatList(l.to_vec()),
    }
}

/// A checked value as it travels on the wire.
pub fn value_to_wire(v: &Value) -> petrel_ipc::Value {
    to_wire(ArgValue::of(v))
}

fn from_wire(v: petrel_ipc::Value) -> Value {
    match v {
        petrel_ipc::Value::Int(i) => Value::Int(i),
        petrel_ipc::Value::Float(f) => Value::Float(f),
        petrel_ipc::Value::Bool(b) => Value::Bool(b),
        petrel_ipc::Value::Text(s) => Value::Text(s),
        petrel_ipc::Value::FloatList(l) => Value::FloatList(l),
    }
}

impl Sink for RuntimeSink<'_> {
    fn taken(&mut self, event: EventId, params: &[Value]) {
        self.log.taken(event, params);
    }

    fn fired(&mut self, net: NetId, transition: u32) {
        let n = &self.log.p.nets[net as usize];
        debug!(net = %n.name, transition = %n.transitions[transition as usize].name, "fired");
        self.log.fired(net, transition);
    }

    fn activated(&mut self, net: NetId) {
        self.activated
            .push(self.log.p.nets[net as usize].name.clone());
        self.log.activated(net);
    }

    fn deactivated(&mut self, net: NetId) {
        self.deactivated
            .push(self.log.p.nets[net as usize].name.clone());
        self.log.deactivated(net);
    }

    fn call(&mut self, program: ProgramId, function: FunctionId, args: Args<'_>) {
        self.log.call(program, function, args);
        let prog = &self.log.p.programs[program as usize];
        let fname = &prog.functions[function as usize].name;
        let msg = CallMsg::new(fname.clone(), args.iter().map(to_wire).collect());
        match self.calls[program as usize].send(&msg) {
            Ok(_) => {
                self.sent += 1;
                debug!(program = %prog.name, function = %fname, "call sent");
            }
            Err(e) => {
                warn!(program = %prog.name, function = %fname, error = %e, "call not delivered: raising call_failed");
                self.failed.push((program, function));
            }
        }
    }

    fn emitted(&mut self, event: EventId) {
        self.log.emitted(event);
    }

    fn timer_started(&mut self, timer: petrel_nets::compiled::TimerId, deadline: Micros) {
        self.log.timer_started(timer, deadline);
    }

    fn timer_cancelled(&mut self, timer: petrel_nets::compiled::TimerId) {
        self.log.timer_cancelled(timer);
    }

    fn safety_violation(&mut self, net: NetId, transition: u32, place: &str) {
        let n = &self.log.p.nets[net as usize];
        warn!(net = %n.name, transition = %n.transitions[transition as usize].name, place, "firing refused: a second token; raising safety_violation");
        self.log.safety_violation(net, transition, place);
    }

    fn conflict(&mut self, net: NetId, transition: u32) {
        self.log.conflict(net, transition);
    }

    fn notice(&mut self, notice: Notice) {
        info!(?notice, "notice");
        self.log.notice(notice);
    }

    fn livelock(&mut self) {
        warn!("immediate transitions did not settle: fixpoint stopped, raising livelock");
        self.log.livelock();
    }
}

/// The marking as `NET.place` and `global.place`, for marking messages.
fn marked_places(project: &CompiledProject, layout: &Layout, state: &[u64]) -> Vec<String> {
    let mut out = Vec::new();
    for (n, net) in project.nets.iter().enumerate() {
        for (i, p) in net.places.iter().enumerate() {
            if Layout::bit(state, layout.net_base[n] + i as u32) {
                out.push(format!("{}.{}", net.name, p.name));
            }
        }
    }
    for (g, gp) in project.globals.iter().enumerate() {
        if Layout::bit(state, layout.global_base + g as u32) {
            out.push(format!("global.{}", gp.name));
        }
    }
    out
}

/// The live status carried by the heartbeat: JSON with the marking of every active net, the
/// counters, and the last sequence number taken from each sender (read by `petrel status`, and
/// by `petrel send` as its acknowledgement).
fn status_json(engine: &Engine, report: &PlayReport, events: &petrel_ipc::EventReceiver) -> String {
    let senders: serde_json::Map<String, serde_json::Value> = events
        .senders()
        .into_iter()
        .map(|a| {
            (
                a.origin.to_string(),
                serde_json::json!({"last_seq": a.last_seq, "received": a.received, "undecodable": a.undecodable, "missing": a.missing}),
            )
        })
        .collect();
    let marking: serde_json::Map<String, serde_json::Value> = engine
        .marking()
        .into_iter()
        .map(|(n, places)| (n, places.into()))
        .collect();
    let s = engine.stats();
    serde_json::json!({
        "project": engine.project().name,
        "time": engine.now() as f64 / 1e6,
        "over": engine.is_over(),
        "marking": marking,
        "stats": {
            "messages": report.messages,
            "bad_messages": report.bad_messages,
            "received": s.received,
            "processed": s.processed,
            "unused": s.unused,
            "refused": s.refused,
            "queued": engine.queued(),
            "calls_sent": report.calls_sent,
            "calls_failed": report.calls_failed,
            "journal_records": report.journal_records,
            "resumed_steps": report.resumed_steps,
        },
        "senders": senders,
    })
    .to_string()
}

/// The journal, if any: every failure to write it is logged loudly but never stops the player
/// (a vehicle must keep flying), and is counted.
struct Recorder2 {
    writer: Option<JournalWriter>,
    failures: u64,
}

impl Recorder2 {
    fn append(&mut self, entry: &Entry) {
        if let Some(w) = self.writer.as_mut() {
            if let Err(e) = w.append(entry) {
                self.failures += 1;
                error!(error = %e, "journal write failed: the flight recorder is missing this entry");
            }
        }
    }

    fn flush(&mut self) {
        if let Some(w) = self.writer.as_mut() {
            if let Err(e) = w.flush() {
                self.failures += 1;
                error!(error = %e, "journal flush failed");
            }
        }
    }
}

fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// Runs the player until SIGINT/SIGTERM (or `run_for`).
pub fn play(project: &CompiledProject, opts: &PlayOptions) -> Result<PlayReport, PlayError> {
    let vehicle = Vehicle::new(&opts.vehicle).map_err(|e| PlayError::Vehicle(e.to_string()))?;
    match petrel_ipc::cleanup_dead_nodes(&vehicle, Duration::from_millis(500)) {
        Ok(r) if !r.cleaned.is_empty() => {
            info!(
                cleaned = r.cleaned.len(),
                "removed the resources of dead processes"
            )
        }
        Ok(_) => {}
        Err(e) => warn!(error = %e, "could not look for dead processes"),
    }

    // Recovery first: the engine is rebuilt from the journal before anything else happens.
    let mut report = PlayReport::default();
    let mut resumed: Option<(Engine, Micros)> = None;
    if opts.resume {
        let dir = opts.journal.as_ref().ok_or_else(|| {
            PlayError::Journal("--resume needs the journal (do not pass --no-journal)".into())
        })?;
        let read =
            crate::journal::read_journal(dir).map_err(|e| PlayError::Journal(e.to_string()))?;
        if let Some(c) = &read.corrupt {
            return Err(PlayError::Journal(format!(
                "{} is damaged at record {} (byte {}): {}; refusing to resume from a damaged journal",
                c.segment.display(),
                c.record,
                c.offset,
                c.what
            )));
        }
        if let Some(t) = &read.torn {
            warn!(segment = %t.segment.display(), offset = t.offset, what = %t.what, "the last journal record was torn by the crash: dropped");
        }
        let digest = crate::journal::project_digest(project);
        if let Some(Entry::Header { digest: d, .. }) = read.entries.first() {
            if *d != digest {
                return Err(PlayError::Journal(
                    "the journal was recorded with another version of the project".into(),
                ));
            }
        }
        let (engine, r) = crate::replay::replay(project, &read.entries, None);
        if let Some(d) = r.divergence {
            return Err(PlayError::Journal(format!(
                "the journal does not replay (entry {}, {}): refusing to resume",
                d.entry, d.what
            )));
        }
        report.resumed_steps = r.steps;
        let restored = engine.marking();
        info!(steps = r.steps, time_s = r.last_time as f64 / 1e6, queued = engine.queued(), ?restored, timers = ?engine.deadlines(), "resumed from the journal");
        resumed = Some((engine, r.last_time));
    }

    let setup = |e: petrel_ipc::SetupError| PlayError::Setup(e.to_string());
    let me = Participant::join(&vehicle, Role::Player).map_err(setup)?;
    let events = me.event_receiver().map_err(setup)?;
    let calls: Vec<CallSender> = project
        .programs
        .iter()
        .map(|p| me.call_sender(&p.name))
        .collect::<Result<_, _>>()
        .map_err(setup)?;
    let marking_out: MarkingPublisher = me.marking_publisher().map_err(setup)?;
    let heartbeat: HeartbeatPublisher = me.heartbeat_publisher().map_err(setup)?;
    let mut watch = ProgramWatch::new(&vehicle, project.programs.iter().map(|p| p.name.clone()));
    let reactor = Reactor::new(opts.wait).map_err(|e| PlayError::Setup(e.to_string()))?;
    let program_lost = project.event_id("program_lost");
    let call_failed = project.event_id("call_failed");
    let bad_message = project.event_id("bad_message");

    let mut journal = Recorder2 {
        writer: match &opts.journal {
            None => None,
            Some(dir) => {
                let header = Entry::Header {
                    version: 1,
                    project: project.name.clone(),
                    project_dir: opts.project_dir.clone(),
                    digest: crate::journal::project_digest(project),
                    vehicle: opts.vehicle.clone(),
                    started_unix_ms: unix_ms(),
                };
                let w = JournalWriter::open(dir, header, opts.flush, opts.rotate_bytes).map_err(
                    |e| PlayError::Journal(format!("cannot write {}: {e}", dir.display())),
                )?;
                info!(dir = %dir.display(), flush = ?opts.flush, "journal open");
                Some(w)
            }
        },
        failures: 0,
    };

    let t0 = Instant::now();
    let mut sink = RuntimeSink {
        log: Recorder::new(project),
        calls: &calls,
        failed: Vec::new(),
        activated: Vec::new(),
        deactivated: Vec::new(),
        sent: 0,
    };
    let (mut engine, base) = match resumed {
        Some((engine, time)) => {
            journal.append(&Entry::Resume { time });
            (engine, time)
        }
        None => {
            let mut engine = Engine::new(project);
            engine.start(0, &mut sink);
            // The start's actions are the start's, not the first event's.
            sink.log.clear();
            journal.append(&Entry::Start {
                time: 0,
                state: engine.state().to_vec(),
            });
            (engine, 0)
        }
    };
    // Mission time goes on from where the journal left it.
    let now = move || base + t0.elapsed().as_micros().min(u64::MAX as u128) as u64;
    let mut previous = vec![0u64; engine.state().len()];
    let mut step_no = 0u64;
    info!(project = %project.name, vehicle = %opts.vehicle, wait = ?opts.wait, "player started");
    // The programs already there are known from now on; one that dies later is lost. An error
    // here shows again at the next check, which reports it.
    if let Err(e) = watch.check() {
        warn!(error = %e, "liveness check failed");
    }

    let mut next_heartbeat = Instant::now();
    let mut next_liveness = Instant::now() + opts.liveness;
    // Submits an event raised by the player itself, journaled like any input.
    let raise = |engine: &mut Engine,
                 journal: &mut Recorder2,
                 event: Option<EventId>,
                 params: Vec<Value>| {
        let Some(e) = event else { return };
        let record = Entry::Submit {
            time: engine.now(),
            event: project.events[e as usize].name.clone(),
            params: params.iter().map(value_to_wire).collect(),
            origin: "player".into(),
            seq: 0,
        };
        match engine.submit(e, params) {
            Ok(()) => journal.append(&record),
            Err(r) => debug!(refusal = %r, "built-in event refused"),
        }
    };
    loop {
        // Everything queued (by the start, a timer, an event) is processed, then published.
        loop {
            let Some(step) = engine.step(&mut sink) else {
                if step_no == 0 {
                    publish_delta(&engine, &mut sink, &mut previous, step_no, &marking_out);
                    step_no += 1;
                }
                break;
            };
            let (event, params) = sink.log.taken.take().unwrap_or_default();
            journal.append(&Entry::Step {
                time: engine.now(),
                event: event.clone(),
                params: params.iter().map(value_to_wire).collect(),
                outcome: match step.outcome {
                    petrel_nets::semantics::StepOutcome::Processed => "processed",
                    petrel_nets::semantics::StepOutcome::Unused => "unused",
                    petrel_nets::semantics::StepOutcome::RefusedAfterCatastrophic => "refused",
                }
                .into(),
                fired: sink.log.fired_names(),
                actions: sink.log.actions.clone(),
                state: engine.state().to_vec(),
                deadlines: engine.deadlines().to_vec(),
            });
            sink.log.taken = Some((event, Vec::new()));
            publish_delta(&engine, &mut sink, &mut previous, step_no, &marking_out);
            step_no += 1;
            sink.log.clear();
            let failed = std::mem::take(&mut sink.failed);
            for (p, f) in failed {
                report.calls_failed += 1;
                let prog = &project.programs[p as usize];
                let params = vec![
                    Value::Text(prog.name.clone()),
                    Value::Text(prog.functions[f as usize].name.clone()),
                ];
                raise(&mut engine, &mut journal, call_failed, params);
            }
        }
        report.calls_sent = sink.sent;

        let instant = Instant::now();
        if instant >= next_heartbeat {
            // The heartbeat acknowledges what the player took: it must be on record first.
            journal.flush();
            if let Some(w) = &journal.writer {
                report.journal_records = w.records;
                report.journal_busy = w.busy;
            }
            let status = status_json(&engine, &report, &events);
            let hb = petrel_ipc::Heartbeat {
                uptime_ms: t0.elapsed().as_millis() as u64,
                period_ms: opts.heartbeat.as_millis() as u32,
                progress: step_no,
                status,
            };
            // Latest-value service: a heartbeat nobody reads is not an error.
            let _ = heartbeat.send(&hb);
            next_heartbeat = instant + opts.heartbeat;
        }
        if let Some(limit) = opts.run_for {
            if t0.elapsed() >= limit {
                info!("run time over");
                break;
            }
        }
        let mut timeout = next_heartbeat
            .min(next_liveness)
            .saturating_duration_since(Instant::now());
        if let Some(d) = engine.next_deadline() {
            timeout = timeout.min(Duration::from_micros(d.saturating_sub(now())));
        }
        let ready = match reactor.wait(&[&events], Some(timeout)) {
            Ok(r) => r,
            Err(e) => {
                warn!(error = %e, "waiting failed; retrying");
                std::thread::sleep(Duration::from_millis(1));
                continue;
            }
        };
        if ready.termination_requested() {
            info!("termination requested: stopping");
            break;
        }
        engine.advance_to(now());
        let mut someone_died = false;
        let drained = events.drain(|r| {
            report.messages += 1;
            match r {
                Ok(rcv) => {
                    let origin = rcv.origin.to_string();
                    let time = engine.now();
                    let record = Entry::Submit {
                        time,
                        event: rcv.msg.name.clone(),
                        params: rcv.msg.params.clone(),
                        origin: origin.clone(),
                        seq: rcv.seq,
                    };
                    let mut params = engine.param_buffer();
                    params.extend(rcv.msg.params.into_iter().map(from_wire));
                    match engine.submit_named(&rcv.msg.name, params) {
                        Ok(()) => journal.append(&record),
                        Err(refusal) => {
                            journal.append(&Entry::Refused {
                                time,
                                what: rcv.msg.name.clone(),
                                reason: refusal.to_string(),
                                origin: origin.clone(),
                            });
                            if matches!(refusal, Refusal::AfterCatastrophic(_)) {
                                info!(from = %origin, reason = %refusal, "event refused");
                            } else {
                                report.bad_messages += 1;
                                warn!(from = %origin, seq = rcv.seq, reason = %refusal, "event refused");
                                let params = vec![Value::Text(origin), Value::Text(refusal.to_string())];
                                raise(&mut engine, &mut journal, bad_message, params);
                            }
                        }
                    }
                }
                Err(RecvError::Undecodable {
                    origin, seq, error, ..
                }) => {
                    report.bad_messages += 1;
                    warn!(from = %origin, seq, error = %error, "undecodable event refused");
                    journal.append(&Entry::Refused {
                        time: engine.now(),
                        what: "(undecodable)".into(),
                        reason: error.to_string(),
                        origin: origin.to_string(),
                    });
                    let params = vec![
                        Value::Text(origin.to_string()),
                        Value::Text(format!("undecodable: {error}")),
                    ];
                    raise(&mut engine, &mut journal, bad_message, params);
                }
                Err(e) => {
                    report.bad_messages += 1;
                    warn!(error = %e, "event could not be received");
                }
            }
        });
        match drained {
            Ok(d) => someone_died = d.wakeups.senders_died > 0,
            Err(e) => warn!(error = %e, "draining events failed"),
        }
        if someone_died || Instant::now() >= next_liveness {
            next_liveness = Instant::now() + opts.liveness;
            match watch.check() {
                Ok(changes) => {
                    for c in changes {
                        if c.is_lost() {
                            warn!(program = %c.program, "program lost");
                            let params = vec![Value::Text(c.program.clone())];
                            raise(&mut engine, &mut journal, program_lost, params);
                        } else {
                            info!(program = %c.program, status = ?c.to, "program status");
                        }
                    }
                }
                Err(e) => warn!(error = %e, "liveness check failed"),
            }
        }
    }
    journal.flush();
    if let Some(w) = &journal.writer {
        report.journal_records = w.records;
        report.journal_busy = w.busy;
    }
    if journal.failures > 0 {
        error!(failures = journal.failures, "the journal missed entries");
    }
    report.stats = engine.stats();
    report.calls_sent = sink.sent;
    info!(?report, "player stopped");
    Ok(report)
}

/// Publishes what the last step changed (the first message of a run is a full snapshot).
fn publish_delta(
    engine: &Engine,
    sink: &mut RuntimeSink,
    previous: &mut Vec<u64>,
    step: u64,
    out: &MarkingPublisher,
) {
    let project = engine.project();
    let layout = engine.layout();
    let now = engine.state();
    let before = marked_places(project, layout, previous);
    let after = marked_places(project, layout, now);
    let snapshot = step == 0;
    let msg = MarkingMsg {
        step,
        event: sink.log.taken.take().map(|t| t.0),
        fired: sink.log.fired_names(),
        marked: if snapshot {
            after.clone()
        } else {
            after
                .iter()
                .filter(|p| !before.contains(p))
                .cloned()
                .collect()
        },
        unmarked: before
            .iter()
            .filter(|p| !after.contains(p))
            .cloned()
            .collect(),
        activated: std::mem::take(&mut sink.activated),
        deactivated: std::mem::take(&mut sink.deactivated),
        snapshot,
    };
    previous.clear();
    previous.extend_from_slice(now);
    match out.send(&msg) {
        Ok(_) | Err(SendError::NoReceiver { .. }) => {}
        Err(e) => warn!(error = %e, "marking delta not delivered to every monitor"),
    }
}
