//! The player process: the engine wired to iceoryx2 (`petrel play`).
//!
//! [`play`] builds a [`PlayerLoop`] and runs it. One reactor thread waits, with the chosen
//! strategy, on the events service, the next timer deadline, the heartbeat and the liveness
//! check. On each wake-up it moves time forward, drains incoming events into the engine
//! (refusing malformed ones with a `bad_message` event), turns dead programs into
//! `program_lost`, processes the queue, sends calls (an absent program gives `call_failed`),
//! journals every input and step, and publishes marking deltas and a heartbeat carrying the
//! live status. The heartbeat is the acknowledgement senders wait for, and it goes out only
//! after the journal is flushed: an acknowledged event is on record.

use crate::engine::{Args, Engine, Micros, Refusal, Sink, Stats};
use crate::journal::{Entry, FlushPolicy, Journal, JournalWriter};
use crate::record::{marked_places, outcome_name, StepRecord};
use petrel_ipc::{
    CallMsg, CallSender, EventReceiver, HeartbeatPublisher, MarkingMsg, MarkingPublisher,
    Participant, ProgramWatch, Reactor, RecvError, Role, SendError, Vehicle, WaitStrategy,
};
use petrel_nets::compiled::{
    CompiledProject, EventId, FunctionId, NetId, ProgramId, TimerId, Value,
};
use petrel_nets::semantics::Notice;
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

/// Runs the player until SIGINT/SIGTERM (or `run_for`).
pub fn play(project: &CompiledProject, opts: &PlayOptions) -> Result<PlayReport, PlayError> {
    PlayerLoop::new(project, opts)?.run()
}

/// Sends what the engine asks for, during one step, and keeps its record.
struct RuntimeSink<'a, 'p> {
    record: &'a mut StepRecord<'p>,
    calls: &'a [CallSender],
    /// Calls that could not be delivered in this step: each becomes `call_failed`.
    failed: &'a mut Vec<(ProgramId, FunctionId)>,
    sent: &'a mut u64,
}

impl Sink for RuntimeSink<'_, '_> {
    fn taken(&mut self, event: EventId, params: &[Value]) {
        self.record.taken(event, params);
    }

    fn fired(&mut self, net: NetId, transition: u32) {
        let n = &self.record.project.nets[net as usize];
        debug!(net = %n.name, transition = %n.transitions[transition as usize].name, "fired");
        self.record.fired(net, transition);
    }

    fn activated(&mut self, net: NetId) {
        self.record.activated(net);
    }

    fn deactivated(&mut self, net: NetId) {
        self.record.deactivated(net);
    }

    fn call(&mut self, program: ProgramId, function: FunctionId, args: Args<'_>) {
        self.record.call(program, function, args);
        let prog = &self.record.project.programs[program as usize];
        let fname = &prog.functions[function as usize].name;
        let msg = CallMsg::new(fname.clone(), args.iter().map(|a| a.to_value()).collect());
        match self.calls[program as usize].send(&msg) {
            Ok(_) => {
                *self.sent += 1;
                debug!(program = %prog.name, function = %fname, "call sent");
            }
            Err(e) => {
                warn!(program = %prog.name, function = %fname, error = %e, "call not delivered: raising call_failed");
                self.failed.push((program, function));
            }
        }
    }

    fn emitted(&mut self, event: EventId, params: &[Value]) {
        self.record.emitted(event, params);
    }

    fn timer_started(&mut self, timer: TimerId, deadline: Micros) {
        self.record.timer_started(timer, deadline);
    }

    fn timer_cancelled(&mut self, timer: TimerId) {
        self.record.timer_cancelled(timer);
    }

    fn safety_violation(&mut self, net: NetId, transition: u32, place: &str) {
        let n = &self.record.project.nets[net as usize];
        warn!(net = %n.name, transition = %n.transitions[transition as usize].name, place, "firing refused: a second token; raising safety_violation");
        self.record.safety_violation(net, transition, place);
    }

    fn conflict(&mut self, net: NetId, transition: u32) {
        self.record.conflict(net, transition);
    }

    fn notice(&mut self, notice: Notice) {
        info!(?notice, "notice");
        self.record.notice(notice);
    }

    fn livelock(&mut self) {
        warn!("immediate transitions did not settle: fixpoint stopped, raising livelock");
        self.record.livelock();
    }

    fn invariant_violated(&mut self, name: &str) {
        error!(
            invariant = name,
            "an invariant of the manifest stopped holding: raising invariant_violated"
        );
        self.record.invariant_violated(name);
    }
}

/// The ports of the player on the vehicle's services.
struct Ports {
    events: EventReceiver,
    calls: Vec<CallSender>,
    marking: MarkingPublisher,
    heartbeat: HeartbeatPublisher,
    /// The node: dropped last, after its ports.
    _me: Participant,
}

/// The built-in events the player raises itself.
struct Builtins {
    program_lost: Option<EventId>,
    call_failed: Option<EventId>,
    bad_message: Option<EventId>,
}

fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// Rebuilds the engine from the journal (`--resume`): the mission time it reached, and the
/// number of steps restored.
fn resume<'p>(
    project: &'p CompiledProject,
    opts: &PlayOptions,
) -> Result<(Engine<'p>, Micros, u64), PlayError> {
    let dir = opts.journal.as_ref().ok_or_else(|| {
        PlayError::Journal("--resume needs the journal (do not pass --no-journal)".into())
    })?;
    let read = crate::journal::read_journal(dir).map_err(|e| PlayError::Journal(e.to_string()))?;
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
    let restored = engine.marking();
    info!(steps = r.steps, time_s = r.last_time as f64 / 1e6, queued = engine.queued(), ?restored, timers = ?engine.deadlines(), "resumed from the journal");
    Ok((engine, r.last_time, r.steps))
}

/// Submits an event raised by the player itself, journaled like any input.
fn raise(engine: &mut Engine, journal: &mut Journal, event: Option<EventId>, params: Vec<Value>) {
    let Some(e) = event else { return };
    let record = Entry::Submit {
        time: engine.now(),
        event: engine.project().events[e as usize].name.clone(),
        params: params.clone(),
        origin: "player".into(),
        seq: 0,
    };
    match engine.submit(e, params) {
        Ok(()) => journal.append(&record),
        Err(r) => debug!(refusal = %r, "built-in event refused"),
    }
}

/// The player: the engine, its ports, its journal, and the clocks of its loop.
pub struct PlayerLoop<'p> {
    project: &'p CompiledProject,
    opts: PlayOptions,
    engine: Engine<'p>,
    record: StepRecord<'p>,
    /// Calls of the current step that could not be delivered.
    failed: Vec<(ProgramId, FunctionId)>,
    journal: Journal,
    ports: Ports,
    watch: ProgramWatch,
    reactor: Reactor,
    builtins: Builtins,
    report: PlayReport,
    /// When the loop started, and the mission time it started at (after a resume).
    t0: Instant,
    base: Micros,
    /// The state published last, to compute the next marking delta.
    previous: Vec<u64>,
    step_no: u64,
    next_heartbeat: Instant,
    next_liveness: Instant,
}

impl<'p> PlayerLoop<'p> {
    /// Sets the player up: removes what dead processes left, restores the journal for
    /// `--resume`, joins the vehicle, opens the journal and starts the mission (or carries on
    /// the restored one).
    pub fn new(project: &'p CompiledProject, opts: &PlayOptions) -> Result<Self, PlayError> {
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
        let resumed = if opts.resume {
            Some(resume(project, opts)?)
        } else {
            None
        };

        let setup = |e: petrel_ipc::SetupError| PlayError::Setup(e.to_string());
        let me = Participant::join(&vehicle, Role::Player).map_err(setup)?;
        let ports = Ports {
            events: me.event_receiver().map_err(setup)?,
            calls: project
                .programs
                .iter()
                .map(|p| me.call_sender(&p.name))
                .collect::<Result<_, _>>()
                .map_err(setup)?,
            marking: me.marking_publisher().map_err(setup)?,
            heartbeat: me.heartbeat_publisher().map_err(setup)?,
            _me: me,
        };
        let watch = ProgramWatch::new(&vehicle, project.programs.iter().map(|p| p.name.clone()));
        let reactor = Reactor::new(opts.wait).map_err(|e| PlayError::Setup(e.to_string()))?;

        let writer = match &opts.journal {
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
        };
        let mut journal = Journal::new(writer);
        let mut record = StepRecord::new(project);
        let mut failed = Vec::new();
        let mut report = PlayReport::default();
        let (engine, base) = match resumed {
            Some((engine, time, steps)) => {
                report.resumed_steps = steps;
                journal.append(&Entry::Resume { time });
                (engine, time)
            }
            None => {
                let mut engine = Engine::new(project);
                engine.start(
                    0,
                    &mut RuntimeSink {
                        record: &mut record,
                        calls: &ports.calls,
                        failed: &mut failed,
                        sent: &mut report.calls_sent,
                    },
                );
                // The start's actions are the start's, not the first event's.
                record.clear();
                journal.append(&Entry::Start {
                    time: 0,
                    state: engine.state().to_vec(),
                });
                (engine, 0)
            }
        };
        let words = engine.state().len();
        Ok(PlayerLoop {
            project,
            opts: opts.clone(),
            engine,
            record,
            failed,
            journal,
            ports,
            watch,
            reactor,
            builtins: Builtins {
                program_lost: project.event_id("program_lost"),
                call_failed: project.event_id("call_failed"),
                bad_message: project.event_id("bad_message"),
            },
            report,
            t0: Instant::now(),
            base,
            previous: vec![0u64; words],
            step_no: 0,
            next_heartbeat: Instant::now(),
            next_liveness: Instant::now() + opts.liveness,
        })
    }

    /// Mission time now: it goes on from where the journal left it.
    fn now(&self) -> Micros {
        self.base + self.t0.elapsed().as_micros().min(u64::MAX as u128) as u64
    }

    /// Runs until SIGINT/SIGTERM (or `run_for`) and reports what was done.
    pub fn run(mut self) -> Result<PlayReport, PlayError> {
        info!(project = %self.project.name, vehicle = %self.opts.vehicle, wait = ?self.opts.wait, "player started");
        // The programs already there are known from now on; one that dies later is lost. An
        // error here shows again at the next check, which reports it.
        if let Err(e) = self.watch.check() {
            warn!(error = %e, "liveness check failed");
        }
        loop {
            self.process_queue();
            self.heartbeat_if_due();
            if let Some(limit) = self.opts.run_for {
                if self.t0.elapsed() >= limit {
                    info!("run time over");
                    break;
                }
            }
            let mut timeout = self
                .next_heartbeat
                .min(self.next_liveness)
                .saturating_duration_since(Instant::now());
            if let Some(d) = self.engine.next_deadline() {
                timeout = timeout.min(Duration::from_micros(d.saturating_sub(self.now())));
            }
            let ready = match self.reactor.wait(&[&self.ports.events], Some(timeout)) {
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
            self.engine.advance_to(self.now());
            let someone_died = self.take_events();
            if someone_died || Instant::now() >= self.next_liveness {
                self.check_liveness();
            }
        }
        self.journal.flush();
        if let Some((records, busy)) = self.journal.written() {
            self.report.journal_records = records;
            self.report.journal_busy = busy;
        }
        if self.journal.failures > 0 {
            error!(
                failures = self.journal.failures,
                "the journal missed entries"
            );
        }
        self.report.stats = self.engine.stats();
        info!(report = ?self.report, "player stopped");
        Ok(self.report)
    }

    /// Submits an event raised by the player itself, journaled like any input.
    fn raise(&mut self, event: Option<EventId>, params: Vec<Value>) {
        raise(&mut self.engine, &mut self.journal, event, params);
    }

    /// Processes everything queued (by the start, a timer, an event), journals and publishes
    /// each step, and raises `call_failed` for the calls that could not be delivered.
    fn process_queue(&mut self) {
        loop {
            let mut sink = RuntimeSink {
                record: &mut self.record,
                calls: &self.ports.calls,
                failed: &mut self.failed,
                sent: &mut self.report.calls_sent,
            };
            let Some(step) = self.engine.step(&mut sink) else {
                if self.step_no == 0 {
                    self.publish_delta();
                    self.step_no += 1;
                }
                break;
            };
            let (event, params) = self.record.taken.clone().unwrap_or_default();
            self.journal.append(&Entry::Step {
                time: self.engine.now(),
                event,
                params,
                outcome: outcome_name(step.outcome).into(),
                fired: self.record.fired_names(),
                actions: self.record.actions.clone(),
                state: self.engine.state().to_vec(),
                deadlines: self.engine.deadlines().to_vec(),
            });
            self.publish_delta();
            self.step_no += 1;
            self.record.clear();
            for (p, f) in std::mem::take(&mut self.failed) {
                self.report.calls_failed += 1;
                let prog = &self.project.programs[p as usize];
                let params = vec![
                    Value::Text(prog.name.clone()),
                    Value::Text(prog.functions[f as usize].name.clone()),
                ];
                self.raise(self.builtins.call_failed, params);
            }
        }
    }

    /// Publishes the heartbeat, with the live status, when its period is over. The heartbeat
    /// acknowledges what the player took: the journal is flushed first.
    fn heartbeat_if_due(&mut self) {
        let instant = Instant::now();
        if instant < self.next_heartbeat {
            return;
        }
        self.journal.flush();
        if let Some((records, busy)) = self.journal.written() {
            self.report.journal_records = records;
            self.report.journal_busy = busy;
        }
        let status = status_json(&self.engine, &self.report, &self.ports.events);
        let hb = petrel_ipc::Heartbeat {
            uptime_ms: self.t0.elapsed().as_millis() as u64,
            period_ms: self.opts.heartbeat.as_millis() as u32,
            progress: self.step_no,
            status,
        };
        // Latest-value service: a heartbeat nobody reads is not an error.
        let _ = self.ports.heartbeat.send(&hb);
        self.next_heartbeat = instant + self.opts.heartbeat;
    }

    /// Drains the events service into the engine; true when iceoryx2 saw a sender die.
    fn take_events(&mut self) -> bool {
        let engine = &mut self.engine;
        let journal = &mut self.journal;
        let report = &mut self.report;
        let bad_message = self.builtins.bad_message;
        let drained = self.ports.events.drain(|r| {
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
                    params.extend(rcv.msg.params);
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
                                let params =
                                    vec![Value::Text(origin), Value::Text(refusal.to_string())];
                                raise(engine, journal, bad_message, params);
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
                    raise(engine, journal, bad_message, params);
                }
                Err(e) => {
                    report.bad_messages += 1;
                    warn!(error = %e, "event could not be received");
                }
            }
        });
        match drained {
            Ok(d) => d.wakeups.senders_died > 0,
            Err(e) => {
                warn!(error = %e, "draining events failed");
                false
            }
        }
    }

    /// Lists the vehicle's nodes: a program that died becomes `program_lost`.
    fn check_liveness(&mut self) {
        self.next_liveness = Instant::now() + self.opts.liveness;
        match self.watch.check() {
            Ok(changes) => {
                for c in changes {
                    if c.is_lost() {
                        warn!(program = %c.program, "program lost");
                        let params = vec![Value::Text(c.program.clone())];
                        self.raise(self.builtins.program_lost, params);
                    } else {
                        info!(program = %c.program, status = ?c.to, "program status");
                    }
                }
            }
            Err(e) => warn!(error = %e, "liveness check failed"),
        }
    }

    /// Publishes what the last step changed (the first message of a run is a full snapshot).
    fn publish_delta(&mut self) {
        let project = self.project;
        let layout = self.engine.layout();
        let now = self.engine.state();
        let before = marked_places(project, layout, &self.previous);
        let after = marked_places(project, layout, now);
        let snapshot = self.step_no == 0;
        let record = &mut self.record;
        let net_names = |ids: &mut Vec<NetId>| -> Vec<String> {
            ids.drain(..)
                .map(|n| project.nets[n as usize].name.clone())
                .collect()
        };
        // A snapshot lists the whole state: every active net.
        let active: Vec<String> = (0..project.nets.len() as NetId)
            .filter(|&n| self.engine.is_active(n))
            .map(|n| project.nets[n as usize].name.clone())
            .collect();
        let msg = MarkingMsg {
            step: self.step_no,
            event: record.taken.take().map(|t| t.0),
            fired: record.fired_names(),
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
            activated: if snapshot {
                record.activated.clear();
                active
            } else {
                net_names(&mut record.activated)
            },
            deactivated: net_names(&mut record.deactivated),
            snapshot,
        };
        self.previous.clear();
        self.previous.extend_from_slice(now);
        match self.ports.marking.send(&msg) {
            Ok(_) | Err(SendError::NoReceiver { .. }) => {}
            Err(e) => warn!(error = %e, "marking delta not delivered to every monitor"),
        }
    }
}

/// The live status carried by the heartbeat: JSON with the marking of every active net, the
/// counters, and the last sequence number taken from each sender (read by `petrel status`, and
/// by `petrel send` as its acknowledgement).
fn status_json(engine: &Engine, report: &PlayReport, events: &EventReceiver) -> String {
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
