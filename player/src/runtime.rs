//! The player process: the engine wired to iceoryx2 (`petrel play`).
//!
//! [`play`] builds a [`PlayerLoop`] and runs it. One reactor thread waits, with the chosen
//! strategy, on the events service, the next timer deadline, the heartbeat and the liveness
//! check. On each wake-up it moves time forward, drains incoming events into the engine
//! (refusing malformed ones, and built-in events that other processes send, with a
//! `bad_message` event), turns dead programs into
//! `program_lost`, processes the queue, sends calls (an absent program gives `call_failed`),
//! journals every input and step, and publishes marking deltas and a heartbeat carrying the
//! live status (JSON, for people and tools) and, typed, the acknowledgement of each sender
//! ([`crate::ack`]). The heartbeat is the acknowledgement senders wait for, and an event is
//! acknowledged as settled only after the journal holding it is flushed: an acknowledged event
//! is on record. The heartbeat's publisher is sized from the project, so that the status of
//! the largest marking and the fullest ledger always fit; a heartbeat that cannot be sent
//! anyway is logged and counted (`heartbeats_refused` in the status).

use crate::ack::Ledger;
use crate::engine::{Args, Engine, Micros, Sink, Stats};
use crate::held::{HeldCalls, Undelivered, HOLD_POLL};
use crate::intake::{Header, Intake};
use crate::journal::{
    Entry, FlushPolicy, Journal, JournalLock, JournalWriter, RecorderChange, Settlement, StepParts,
    BATCH_DELAY,
};
use crate::record::{marked_places, outcome_name, place_changes, StepRecord};
use petrel_ipc::{
    CallMsg, CallRef, CallSender, EventMsg, EventReceiver, Heartbeat, HeartbeatPublisher,
    MarkingMsg, MarkingPublisher, Participant, ProgramWatch, Reactor, RecvError, ReloadAnswer,
    ReloadAnswerPublisher, ReloadReceiver, ReloadRequest, SendError, Vehicle, WaitStrategy,
};
use petrel_nets::compiled::{
    CompiledProject, EventId, FunctionId, NetId, Program, ProgramId, TimerId, Value,
};
use petrel_nets::model::Type;
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
    /// Bytes of journal records kept in memory while the journal cannot be written (a full
    /// disk); past it the recorder drops records and starts over from a checkpoint.
    pub journal_backlog: usize,
    /// Restore the mission from the journal and carry on.
    pub resume: bool,
    /// The project directory, recorded in the journal header.
    pub project_dir: String,
    /// The Unix group (name or number) given the vehicle's files, for operator accounts
    /// (`petrel play --group`); `None`: the user's alone (or `PETREL_GROUP`'s).
    pub group: Option<String>,
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
            journal_backlog: crate::journal::DEFAULT_BACKLOG,
            resume: false,
            project_dir: String::new(),
            group: None,
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
    /// Calls that could not be delivered (each became `call_failed`): to a program with no
    /// live process, held past [`CALL_HOLD`](crate::held::CALL_HOLD), to a program that went while they were held.
    pub calls_failed: u64,
    /// Calls held because their program's process lived but did not receive them yet
    /// (delivered since, or counted in `calls_failed`).
    pub calls_held: u64,
    /// Journal records written.
    pub journal_records: u64,
    /// Attempts to write the journal that failed (a full disk...).
    pub journal_failures: u64,
    /// Journal entries the recorder had to drop.
    pub journal_lost: u64,
    /// Time the reactor thread spent writing the journal.
    pub journal_busy: Duration,
    /// Steps restored from the journal by `--resume`.
    pub resumed_steps: u64,
    /// Heartbeats published.
    pub heartbeats_sent: u64,
    /// Heartbeats that could not be published at all (no shared memory, a bug in their size):
    /// each is logged (the first, then one in a hundred) and counted here.
    pub heartbeats_refused: u64,
    /// Reloads of the project accepted (and swapped).
    pub reloads: u64,
    /// Reload requests refused (or dry runs answered).
    pub reloads_refused: u64,
}

/// Runs the player until SIGINT/SIGTERM (or `run_for`).
pub fn play(project: &CompiledProject, opts: &PlayOptions) -> Result<PlayReport, PlayError> {
    PlayerLoop::new(project, opts)?.run()
}

/// Sends what the engine asks for, during one step, and keeps its record.
struct RuntimeSink<'a, 'p> {
    record: &'a mut StepRecord<'p>,
    calls: &'a [CallSender],
    /// By program: calls to it are held ([`HeldCalls`]); a new one goes behind them.
    holding: &'a [bool],
    /// Calls that could not be delivered in this step: each is held, or becomes `call_failed`.
    undelivered: &'a mut Vec<Undelivered>,
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
        let project = self.record.project;
        let prog = &project.programs[program as usize];
        let fname = &prog.functions[function as usize].name;
        let body = CallRef {
            function: fname,
            args: args.iter(),
        };
        // Behind calls to the same program held, or not yet settled, in order.
        let behind = self.holding.get(program as usize) == Some(&true)
            || self
                .undelivered
                .iter()
                .any(|u| u.program == program && u.body.is_some());
        // Encoded from the borrowed arguments straight into the loaned sample.
        let sent = match behind {
            false => self.calls[program as usize].send_body(&body).map_err(Some),
            true => Err(None),
        };
        match sent {
            Ok(_) => {
                *self.sent += 1;
                debug!(program = %prog.name, function = %fname, "call sent");
            }
            Err(e) => {
                // A call that found no receiver may be held (the program may be joining):
                // encoded apart, for later.
                let holdable = e
                    .as_ref()
                    .is_none_or(|e| matches!(e, SendError::NoReceiver { .. }));
                let body = holdable
                    .then(|| {
                        let mut bytes = vec![0; petrel_ipc::wire::encoded_len(&body).ok()?];
                        petrel_ipc::wire::encode_into(&body, &mut bytes).ok()?;
                        Some(bytes)
                    })
                    .flatten();
                let error = e.map_or_else(
                    || "calls to this program are held".to_string(),
                    |e| e.to_string(),
                );
                self.undelivered.push(Undelivered {
                    program,
                    function,
                    body,
                    error,
                });
            }
        }
        // The call's text for the journal and the monitors once the call is out.
        self.record.call(program, function, args);
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

    fn cascade_stopped(&mut self, steps: u32, dropped: u64) {
        warn!(
            steps,
            dropped,
            "events produced at one instant did not settle: cascade stopped, produced events dropped, raising livelock"
        );
        self.record.cascade_stopped(steps, dropped);
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
    reload: ReloadReceiver,
    reload_answers: ReloadAnswerPublisher,
    /// The node: dropped last, after its ports.
    _me: Participant,
}

/// The built-in events the player raises itself.
struct Builtins {
    program_lost: Option<EventId>,
    call_failed: Option<EventId>,
    bad_message: Option<EventId>,
    recorder_failed: Option<EventId>,
    recorder_restored: Option<EventId>,
}

fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// Locks the journal directory for this player and checks that it may write there: a new
/// mission needs a directory without a journal, a resumed one its own vehicle's journal.
/// Returns the lock and the mission's start (wall clock, milliseconds since the Unix epoch):
/// now for a new mission, the journal's for a resumed one.
fn take_journal(
    dir: &std::path::Path,
    opts: &PlayOptions,
    now_ms: u64,
) -> Result<(JournalLock, u64), PlayError> {
    let mut lock = JournalLock::acquire(dir).map_err(|e| PlayError::Journal(e.to_string()))?;
    let has_segments = crate::journal::segments(dir)
        .map(|s| !s.is_empty())
        .map_err(|e| PlayError::Journal(format!("cannot read {}: {e}", dir.display())))?;
    let header = crate::journal::first_header(dir);
    let start = match (&header, opts.resume) {
        (
            Some(Entry::Header {
                vehicle,
                started_unix_ms,
                ..
            }),
            true,
        ) => {
            if *vehicle != opts.vehicle {
                return Err(PlayError::Journal(format!(
                    "{} holds the journal of vehicle `{vehicle}`, not `{}`: refusing to resume another vehicle's mission",
                    dir.display(),
                    opts.vehicle
                )));
            }
            *started_unix_ms
        }
        // An unreadable first header is said by the replay, with the record it is.
        (_, true) => now_ms,
        (_, false) if has_segments => {
            let whose = match &header {
                Some(Entry::Header { vehicle, .. }) => format!("vehicle `{vehicle}`"),
                _ => "an unknown vehicle".to_string(),
            };
            return Err(PlayError::Journal(format!(
                "{} already holds the journal of a mission of {whose}: carry that mission on with --resume, or record this one elsewhere (--journal DIR)",
                dir.display()
            )));
        }
        (_, false) => now_ms,
    };
    if let Some(owner) = lock.stale_owner() {
        warn!(lock = %lock.path().display(), vehicle = %owner.vehicle, pid = owner.pid, "took over the stale lock of a player that died without releasing it");
    }
    lock.claim(&opts.vehicle)
        .map_err(|e| PlayError::Journal(format!("cannot write {}: {e}", lock.path().display())))?;
    Ok((lock, start))
}

/// Rebuilds the engine from the journal (`--resume`): the mission time it reached, and the
/// number of steps restored.
fn resume<'p>(
    project: &'p CompiledProject,
    opts: &PlayOptions,
) -> Result<(Engine<'p>, Micros, u64, Option<String>), PlayError> {
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
        if read.unwritten {
            info!(segment = %t.segment.display(), offset = t.offset, what = %t.what, "the journal ends in zeros (space the stopped player had reserved and not written, or a power loss before the data reached the disk): cut off, every record before them kept");
        } else {
            warn!(segment = %t.segment.display(), offset = t.offset, what = %t.what, "the end of the journal was torn by the crash: dropped, and cut off so that the journal goes on from its last good record");
        }
        crate::journal::cut_torn_tail(t).map_err(|e| {
            PlayError::Journal(format!(
                "cannot cut the torn tail off {}: {e}",
                t.segment.display()
            ))
        })?;
    }
    let digest = crate::journal::project_digest(project);
    let reloaded = crate::replay::last_reload(&read.entries).is_some();
    if let Some(Entry::Header { digest: d, .. }) = read.entries.first() {
        // After a reload the mission resumes on the version the journal keeps, whatever the
        // project directory holds now (an operator may have edited it in place).
        if *d != digest && !reloaded {
            return Err(PlayError::Journal(
                "the journal was recorded with another version of the project".into(),
            ));
        }
    }
    let (engine, r) =
        crate::replay::replay_in(project, &read.entries, None, Some(dir.as_path()), reloaded);
    let version = reloaded.then(|| engine_version(&read.entries));
    if let Some(hash) = &version {
        info!(%hash, "resuming on the version of the journal's last reload");
    }
    if let Some(d) = r.divergence {
        return Err(PlayError::Journal(format!(
            "the journal does not replay (entry {}, {}): refusing to resume",
            d.entry, d.what
        )));
    }
    let restored = engine.marking();
    info!(steps = r.steps, time_s = r.last_time as f64 / 1e6, queued = engine.queued(), ?restored, timers = ?engine.deadlines(), "resumed from the journal");
    Ok((engine, r.last_time, r.steps, version))
}

/// The content hash of the version the journal's last reload brought ("" without a reload).
fn engine_version(entries: &[Entry]) -> String {
    match crate::replay::last_reload(entries).map(|k| &entries[k]) {
        Some(Entry::Reload { source_hash, .. }) => source_hash.clone(),
        _ => String::new(),
    }
}

/// The player: the engine, its ports, its journal, and the clocks of its loop.
pub struct PlayerLoop<'p> {
    project: &'p CompiledProject,
    opts: PlayOptions,
    engine: Engine<'p>,
    record: StepRecord<'p>,
    /// Calls of the current step that could not be delivered: held or failed after the step.
    undelivered: Vec<Undelivered>,
    /// Calls held for programs whose process lives but does not receive them yet.
    held: HeldCalls,
    journal: Journal,
    ports: Ports,
    watch: ProgramWatch,
    reactor: Reactor,
    builtins: Builtins,
    report: PlayReport,
    /// What was taken from each sender, refused and settled: the heartbeat's acknowledgements.
    ledger: Ledger,
    /// Where each event's parameters are decoded, before they move into an engine's buffer.
    decoded: Vec<Value>,
    /// The programs that said they leave in good order (since they last joined): their going
    /// is a stop, not a loss.
    leaves: std::collections::BTreeSet<String>,
    /// When the loop started, and the mission time it started at (after a resume).
    t0: Instant,
    base: Micros,
    /// The state published last, to compute the next marking delta.
    previous: Vec<u64>,
    step_no: u64,
    next_heartbeat: Instant,
    next_liveness: Instant,
    /// The next marking message is a snapshot (after a reload, or steps no monitor saw).
    snapshot_next: bool,
    /// The reload under verification, if any.
    pending: Option<PendingReload>,
    /// The content hash of the version running, once a reload brought one.
    version: Option<String>,
    /// The hold on the journal directory: released last, after the journal is closed.
    _lock: Option<JournalLock>,
}

/// A reload whose new version is being verified from the mapped state, in a thread of its
/// own, while the loop goes on taking events (and, for a dry run, processing them).
struct PendingReload {
    request: ReloadRequest,
    sender: u64,
    seq: u64,
    received: Instant,
    candidate: crate::reload::Candidate,
    summary: Vec<String>,
    verdict: std::thread::JoinHandle<Result<u64, petrel_nets::reload::Finding>>,
}

/// The most stable states a reload's verification explores before it refuses the reload.
const RELOAD_MAX_STATES: u64 = 2_000_000;

impl<'p> PlayerLoop<'p> {
    /// Sets the player up: removes what dead processes left, restores the journal for
    /// `--resume`, joins the vehicle, opens the journal and starts the mission (or carries on
    /// the restored one).
    pub fn new(project: &'p CompiledProject, opts: &PlayOptions) -> Result<Self, PlayError> {
        let mut vehicle =
            Vehicle::new(&opts.vehicle).map_err(|e| PlayError::Vehicle(e.to_string()))?;
        if let Some(group) = &opts.group {
            let group =
                petrel_ipc::Group::lookup(group).map_err(|e| PlayError::Setup(e.to_string()))?;
            vehicle = vehicle.with_group(group);
        }
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
        // Mission time is wall-clock time since the mission started; a new mission starts now.
        let (mut t0, now_ms) = (Instant::now(), unix_ms());
        // The journal directory is this player's alone, and this vehicle's.
        let (lock, mission_start_ms) = match &opts.journal {
            Some(dir) => {
                let (lock, start) = take_journal(dir, opts, now_ms)?;
                (Some(lock), start)
            }
            None => (None, now_ms),
        };
        // Recovery first: the engine is rebuilt from the journal before anything else happens.
        let resumed = if opts.resume {
            Some(resume(project, opts)?)
        } else {
            None
        };
        // A resume after a reload runs the reloaded version.
        let project: &'p CompiledProject = match &resumed {
            Some((engine, ..)) => engine.project(),
            None => project,
        };
        let version = resumed.as_ref().and_then(|r| r.3.clone());

        let setup = |e: petrel_ipc::SetupError| PlayError::Setup(e.to_string());
        let me = Participant::join_player(&vehicle, project.programs.len()).map_err(setup)?;
        // The largest status this project can have, and the fullest ledger, always fit.
        let heartbeat_max = Heartbeat::max_encoded_len(status_bound(project));
        if heartbeat_max > petrel_ipc::wire::MAX_BODY_LEN {
            warn!(
                bytes = heartbeat_max,
                "the status of this project may exceed what a heartbeat carries: it will leave out the marking when it does"
            );
        }
        let ports = Ports {
            events: me
                .event_receiver_sized(event_bound(project), project.programs.len())
                .map_err(setup)?,
            calls: project
                .programs
                .iter()
                .map(|p| me.call_sender_sized(&p.name, call_bound(p)))
                .collect::<Result<_, _>>()
                .map_err(setup)?,
            marking: me
                .marking_publisher_sized(marking_bound(project))
                .map_err(setup)?,
            heartbeat: me.heartbeat_publisher_sized(heartbeat_max).map_err(setup)?,
            reload: me.reload_receiver().map_err(setup)?,
            reload_answers: me.reload_answer_publisher().map_err(setup)?,
            _me: me,
        };
        if opts.wait != WaitStrategy::Block {
            // Spinning, the player sees events in shared memory: their notifications are
            // consumed now and then, not at every event (two system calls fewer each).
            ports
                .events
                .consume_wakeups_every(Some(petrel_ipc::SPIN_WAKEUP_PERIOD));
        }
        let watch = ProgramWatch::new(&ports._me, project.programs.iter().map(|p| p.name.clone()))
            .map_err(setup)?;
        let reactor = Reactor::new(opts.wait).map_err(|e| PlayError::Setup(e.to_string()))?;

        let writer = match &opts.journal {
            None => None,
            Some(dir) => {
                let header = Entry::Header {
                    version: crate::journal::FORMAT_VERSION,
                    project: project.name.clone(),
                    project_dir: opts.project_dir.clone(),
                    // A mission's segments all name its first version (a resume after a
                    // reload runs a later one: the reload entries say which).
                    digest: match (opts.resume, crate::journal::first_header(dir)) {
                        (true, Some(Entry::Header { digest, .. })) => digest,
                        _ => crate::journal::project_digest(project),
                    },
                    vehicle: opts.vehicle.clone(),
                    // Every segment of a mission names its start: replay checks they agree.
                    started_unix_ms: mission_start_ms,
                };
                let w = JournalWriter::open(dir, header, opts.flush, opts.rotate_bytes).map_err(
                    |e| PlayError::Journal(format!("cannot write {}: {e}", dir.display())),
                )?;
                info!(dir = %dir.display(), flush = ?opts.flush, "journal open");
                Some(w)
            }
        };
        let mut journal = Journal::with_backlog(writer, opts.journal_backlog);
        journal.batch_records();
        let mut record = StepRecord::new(project).without_calls();
        let mut undelivered = Vec::new();
        let mut report = PlayReport::default();
        let held = HeldCalls::new(project.programs.len());
        let (engine, base) = match resumed {
            Some((mut engine, last, steps, _)) => {
                report.resumed_steps = steps;
                // Mission time went on while the player was down: timers keep their wall-clock
                // deadlines, and those that passed expire now, in deadline order. The resume
                // entry says when, so that replay expires them at the same time.
                t0 = Instant::now();
                let wall = unix_ms()
                    .saturating_sub(mission_start_ms)
                    .saturating_mul(1000);
                if wall < last {
                    warn!(
                        wall_s = wall as f64 / 1e6,
                        journal_s = last as f64 / 1e6,
                        "the wall clock is behind the journal's last entry: mission time goes on from the journal's"
                    );
                }
                let time = wall.max(last);
                let overdue = engine
                    .deadlines()
                    .iter()
                    .flatten()
                    .filter(|&&d| d <= time)
                    .count();
                journal.append(&Entry::Resume { time });
                engine.advance_to(time);
                info!(
                    down_s = (time - last) as f64 / 1e6,
                    overdue, "resumed at the mission's wall-clock time; overdue timers expire now"
                );
                (engine, time)
            }
            None => {
                let mut engine = Engine::new(project);
                engine.start(
                    0,
                    &mut RuntimeSink {
                        record: &mut record,
                        calls: &ports.calls,
                        holding: held.holding(),
                        undelivered: &mut undelivered,
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
            undelivered,
            held,
            journal,
            ports,
            watch,
            reactor,
            builtins: Builtins {
                program_lost: project.event_id("program_lost"),
                call_failed: project.event_id("call_failed"),
                bad_message: project.event_id("bad_message"),
                recorder_failed: project.event_id("recorder_failed"),
                recorder_restored: project.event_id("recorder_restored"),
            },
            report,
            ledger: Ledger::new(),
            decoded: Vec::new(),
            leaves: Default::default(),
            t0,
            base,
            previous: vec![0u64; words],
            step_no: 0,
            next_heartbeat: Instant::now(),
            next_liveness: Instant::now() + opts.liveness,
            snapshot_next: false,
            pending: None,
            version,
            _lock: lock,
        })
    }

    /// Mission time at `instant`: wall-clock time since the mission started, read from the
    /// monotonic clock within a run (so it never goes backwards), from the wall clock across a
    /// resume.
    fn mission_time(&self, instant: Instant) -> Micros {
        let since = instant.saturating_duration_since(self.t0);
        self.base + since.as_micros().min(u64::MAX as u128) as u64
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
            // The clock is read twice a round: here, for what is due before the wait (the
            // heartbeat, the journal's hold, the wait's timeout), and when the wait ends.
            let now = Instant::now();
            self.heartbeat_if_due(now);
            // Everything journaled reaches the operating system before the player sleeps.
            // A spinning player holds a round's records while the next event may come (at
            // most BATCH_DELAY), so that their write is not on that event's path.
            let hold = match self.reactor.strategy() {
                WaitStrategy::Block => None,
                WaitStrategy::Spin => Some(None),
                WaitStrategy::SpinThenBlock(window) => Some(Some(window)),
            }
            .and_then(|window| {
                let since = self.journal.batch_since()?;
                let left = BATCH_DELAY.saturating_sub(now.saturating_duration_since(since));
                (!left.is_zero()).then(|| window.map_or(left, |w| w.min(left)))
            });
            if hold.is_none() {
                self.journal.write_batch();
            }
            if self.journal.has_changes() {
                // The heartbeat's flush changed the recorder's state: tell the nets now.
                continue;
            }
            if let Some(limit) = self.opts.run_for {
                if now.saturating_duration_since(self.t0) >= limit {
                    info!("run time over");
                    break;
                }
            }
            let mut timeout = self
                .next_heartbeat
                .min(self.next_liveness)
                .saturating_duration_since(now);
            if let Some(d) = self.engine.next_deadline() {
                timeout = timeout.min(Duration::from_micros(
                    d.saturating_sub(self.mission_time(now)),
                ));
            }
            if self.pending.is_some() {
                // The verifier's thread says nothing when it is done: look again soon.
                timeout = timeout.min(Duration::from_millis(2));
            }
            if !self.held.is_empty() {
                // Nothing says when a receiver connects: look for the held calls' programs.
                timeout = timeout.min(HOLD_POLL);
            }
            if let Some(hold) = hold {
                // Within a spin window, so that the wait ends before it could sleep.
                timeout = timeout.min(hold);
            }
            let ready = match self
                .reactor
                .wait(&[&self.ports.events, &self.ports.reload], Some(timeout))
            {
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
            let woke = Instant::now();
            self.engine.advance_to(self.mission_time(woke));
            self.ledger.set_clock(woke);
            let someone_died = self.take_events();
            if someone_died || woke >= self.next_liveness {
                self.check_liveness();
            }
            self.take_reload_requests();
            self.finish_reload();
        }
        // A last look at the programs: one gone since the last check (the programs of a
        // vehicle stop before its player) is journaled, a stop, or a loss as an input that a
        // resumed player takes.
        self.check_liveness();
        if self.journal.flush() != Settlement::Recorded {
            error!(
                state = self.journal.state().as_str(),
                reason = self.journal.reason(),
                backlog = ?self.journal.backlog(),
                lost = self.journal.lost,
                "the player stops with journal records not written: the journal ends at its last good record"
            );
        }
        self.count_journal();
        self.report.stats = self.engine.stats();
        info!(report = ?self.report, "player stopped");
        Ok(self.report)
    }

    /// Submits an event raised by the player itself, journaled like any input.
    fn raise(&mut self, event: Option<EventId>, params: Vec<Value>) {
        crate::intake::raise(&mut self.engine, &mut self.journal, event, params);
    }

    /// Processes everything queued (by the start, a timer, an event), journals and publishes
    /// each step, and raises `call_failed` for the calls that could not be delivered.
    fn process_queue(&mut self) {
        // The recorder's changes are raised (queued) even while a reload holds the steps, so
        // that the loop does not come back here for them before it waits.
        self.raise_recorder_changes();
        // A reload under way holds the steps: the new version starts from the state it maps.
        if self.pending.as_ref().is_some_and(|p| !p.request.dry_run) {
            return;
        }
        // The start's calls not delivered, then the held calls whose program now receives.
        self.settle_undelivered();
        self.deliver_held();
        loop {
            let mut sink = RuntimeSink {
                record: &mut self.record,
                calls: &self.ports.calls,
                holding: self.held.holding(),
                undelivered: &mut self.undelivered,
                sent: &mut self.report.calls_sent,
            };
            let Some(step) = self.engine.step(&mut sink) else {
                if self.step_no == 0 {
                    self.publish_delta();
                    self.step_no += 1;
                }
                // Journaling these steps may have changed the recorder's state.
                if self.raise_recorder_changes() {
                    continue;
                }
                break;
            };
            let (event, params) = match &self.record.taken {
                Some((event, params)) => (event.as_str(), params.as_slice()),
                None => ("", &[][..]),
            };
            // Encoded from the record and the engine as they are: no copy of the step.
            self.journal.append_step(&StepParts {
                time: self.engine.now(),
                event,
                params,
                outcome: outcome_name(step.outcome),
                fired: self.record.fired_encoded(),
                actions: &self.record.actions,
                state: self.engine.state(),
                deadlines: self.engine.deadlines(),
            });
            self.publish_delta();
            self.step_no += 1;
            self.record.clear();
            self.settle_undelivered();
        }
    }

    /// Holds each call of the last step that could not be delivered, if its program's process
    /// lives (it may be joining: [`HeldCalls`]) or calls to it are held already; raises
    /// `call_failed` for the others.
    fn settle_undelivered(&mut self) {
        for u in std::mem::take(&mut self.undelivered) {
            let prog = &self.project.programs[u.program as usize];
            let function = &prog.functions[u.function as usize].name;
            let hold = match &u.body {
                None => false,
                Some(_) if self.held.holding().get(u.program as usize) == Some(&true) => true,
                Some(_) => match self.watch.probe(&prog.name) {
                    Ok(status) => status.is_some_and(|s| s.is_running()),
                    Err(e) => {
                        warn!(error = %e, "liveness check failed");
                        false
                    }
                },
            };
            match u.body {
                Some(body) if hold => {
                    self.report.calls_held += 1;
                    self.held
                        .hold(u.program, &prog.name, function, body, Instant::now());
                }
                _ => {
                    let (program, function) = (prog.name.clone(), function.clone());
                    self.call_failed(program, function, &u.error);
                }
            }
        }
    }

    /// Sends the held calls whose program receives now; raises `call_failed` for those held
    /// too long.
    fn deliver_held(&mut self) {
        if self.held.is_empty() {
            return;
        }
        let (sent, failed) = self
            .held
            .deliver(self.project, &self.ports.calls, Instant::now());
        self.report.calls_sent += sent;
        for (program, function, why) in failed {
            self.call_failed(program, function, &why);
        }
    }

    /// A call that could not be delivered, `why`: logged, counted, and raised as
    /// `call_failed(program, function)`.
    fn call_failed(&mut self, program: String, function: String, why: &str) {
        warn!(%program, %function, reason = why, "call not delivered: raising call_failed");
        self.report.calls_failed += 1;
        let params = vec![Value::Text(program), Value::Text(function)];
        self.raise(self.builtins.call_failed, params);
    }

    /// Raises `recorder_failed` and `recorder_restored` for the recorder's changes of state;
    /// true when it raised any.
    fn raise_recorder_changes(&mut self) -> bool {
        let changes = self.journal.take_changes();
        for change in &changes {
            match change {
                RecorderChange::Failed(reason) => {
                    let mut reason = reason.clone();
                    petrel_ipc::wire::cut_text(&mut reason, petrel_ipc::wire::MAX_REASON_LEN);
                    self.raise(self.builtins.recorder_failed, vec![Value::Text(reason)]);
                }
                RecorderChange::Restored => self.raise(self.builtins.recorder_restored, vec![]),
            }
        }
        !changes.is_empty()
    }

    fn count_journal(&mut self) {
        if let Some((records, busy)) = self.journal.written() {
            self.report.journal_records = records;
            self.report.journal_busy = busy;
        }
        self.report.journal_failures = self.journal.failures;
        self.report.journal_lost = self.journal.lost;
    }

    /// Publishes the heartbeat, with the live status and the acknowledgements, when its period
    /// is over. The journal is flushed first: what it holds is then settled, what it still
    /// keeps in memory stays pending, what it dropped is unrecorded.
    fn heartbeat_if_due(&mut self, instant: Instant) {
        if instant < self.next_heartbeat {
            return;
        }
        self.next_heartbeat = instant + self.opts.heartbeat;
        match self.journal.flush() {
            Settlement::Recorded => self.ledger.settle(),
            Settlement::Pending => {}
            Settlement::Lost => self.ledger.lose_unsettled(),
        }
        // A recorder that dropped records goes on from a checkpoint of the engine, taken
        // between two steps (the queue is empty after `process_queue`).
        if self.journal.wants_checkpoint() && self.engine.queued() == 0 {
            let checkpoint = Entry::Checkpoint {
                time: self.engine.now(),
                state: self.engine.state().to_vec(),
                deadlines: self.engine.deadlines().to_vec(),
            };
            self.journal.checkpoint(&checkpoint);
        }
        self.count_journal();
        for gone in self.ledger.prune(&self.ports.events.live_senders()) {
            self.ports.events.forget_sender(gone);
        }
        let max = self.ports.heartbeat.spec().max_body_len;
        let mut hb = Heartbeat {
            uptime_ms: self.t0.elapsed().as_millis() as u64,
            period_ms: self.opts.heartbeat.as_millis() as u32,
            progress: self.step_no,
            status: String::new(),
            acks: self.ledger.acks(),
            recorder: petrel_ipc::Recorder {
                state: self.journal.state(),
                reason: self.journal.reason().to_string(),
            },
        };
        hb.bound();
        let snapshot = StatusSnapshot {
            version: self.version.clone(),
            reloading: self.pending.is_some(),
            ..StatusSnapshot::of(&self.engine, &self.report, &self.ledger, &self.journal)
        };
        hb.status = status_json(&snapshot);
        if Heartbeat::max_encoded_len(hb.status.len()) > max {
            // Only a project past the largest body a service carries gets here (see `new`).
            hb.status = status_json(&StatusSnapshot {
                marking: None,
                ..snapshot
            });
        }
        match self.ports.heartbeat.send(&hb) {
            // Latest-value service: a heartbeat nobody reads is not an error, and one that
            // missed a receiver still connecting (buffers never fill: they overwrite) reaches
            // it with the next period.
            Ok(_) | Err(SendError::NoReceiver { .. } | SendError::Refused { .. }) => {
                self.report.heartbeats_sent += 1
            }
            Err(e) => {
                self.report.heartbeats_refused += 1;
                let n = self.report.heartbeats_refused;
                if n == 1 || n.is_multiple_of(100) {
                    error!(error = %e, refused = n, "heartbeat not published: status and acknowledgements are not seen");
                }
            }
        }
    }

    /// Drains the events service into the engine ([`Intake`]); true when iceoryx2 saw a
    /// sender die.
    fn take_events(&mut self) -> bool {
        let mut intake = Intake {
            engine: &mut self.engine,
            journal: &mut self.journal,
            ledger: &mut self.ledger,
            report: &mut self.report,
            bad_message: self.builtins.bad_message,
            leaves: &mut self.leaves,
        };
        // Each event is decoded where it lies: its name read from the sample, its parameters
        // into `decoded` (kept from one drain to the next), then moved into one of the
        // engine's buffers. No event is built, and no name copied.
        let drained = self
            .ports
            .events
            .drain_in_place(&mut self.decoded, |r, decoded| match r {
                Ok(rcv) => intake.event(Header::from(&rcv), rcv.msg, decoded),
                Err(RecvError::Undecodable {
                    origin,
                    seq,
                    error,
                    sender,
                    missed,
                    ..
                }) => intake.undecodable(
                    Header {
                        sender,
                        origin,
                        seq,
                        missed,
                    },
                    &error.to_string(),
                ),
                Err(e @ RecvError::Foreign { .. }) => {
                    let origin = match &e {
                        RecvError::Foreign { origin, .. } => origin.to_string(),
                        _ => String::new(),
                    };
                    intake.foreign(&origin, &e.to_string())
                }
                Err(e) => intake.failed(&e),
            });
        match drained {
            Ok(d) => d.wakeups.senders_died > 0,
            Err(e) => {
                warn!(error = %e, "draining events failed");
                false
            }
        }
    }

    /// Lists the vehicle's nodes: a program whose process went becomes `program_lost`, or, if it
    /// said it leaves in good order, a stop (journaled, logged at INFO); the calls held for it
    /// fail.
    fn check_liveness(&mut self) {
        self.next_liveness = Instant::now() + self.opts.liveness;
        let changes = match self.watch.check() {
            Ok(changes) => changes,
            Err(e) => return warn!(error = %e, "liveness check failed"),
        };
        if changes.iter().any(|c| c.is_lost()) {
            // A leave sent just before the process went is read before its going is judged:
            // the listing saw the node gone, so the leave (sent before) is there to read.
            self.take_events();
        }
        for c in changes {
            if !c.is_lost() {
                if !c.from.is_running() {
                    // A new process of the program: what the old one said is forgotten.
                    self.leaves.remove(&c.program);
                }
                info!(program = %c.program, status = ?c.to, "program status");
                continue;
            }
            let because = if self.leaves.remove(&c.program) {
                info!(program = %c.program, "program stopped in good order");
                self.journal.append(&Entry::ProgramStopped {
                    time: self.engine.now(),
                    program: c.program.clone(),
                });
                "it stopped"
            } else {
                warn!(program = %c.program, status = ?c.to, "program lost");
                let params = vec![Value::Text(c.program.clone())];
                self.raise(self.builtins.program_lost, params);
                "it was lost"
            };
            let failed = self.held.drop_program(self.project, &c.program, because);
            for (program, function, why) in failed {
                self.call_failed(program, function, &why);
            }
        }
    }

    /// Takes the reload requests that arrived: each is read, checked and mapped at once (the
    /// engine is between two steps), then verified in a thread of its own.
    fn take_reload_requests(&mut self) {
        let mut requests = Vec::new();
        let drained = self.ports.reload.drain(|r| match r {
            Ok(rcv) => requests.push((rcv.sender, rcv.seq, rcv.origin.to_string(), rcv.msg)),
            Err(e) => warn!(error = %e, "a reload request could not be read"),
        });
        if let Err(e) = drained {
            warn!(error = %e, "reload requests could not be read");
        }
        for (sender, seq, origin, request) in requests {
            info!(from = %origin, dir = %request.dir, hash = %request.source_hash, dry_run = request.dry_run, "reload requested");
            self.begin_reload(sender, seq, request);
        }
    }

    /// Answers a reload request (to every listener: the requester finds its own).
    fn answer_reload(&mut self, mut answer: ReloadAnswer) {
        if !answer.accepted || answer.dry_run {
            self.report.reloads_refused += 1;
        }
        if answer.accepted {
            info!(dry_run = answer.dry_run, hash = %answer.source_hash, states = answer.states, ms = answer.millis, summary = ?answer.summary, "reload accepted");
        } else {
            warn!(dry_run = answer.dry_run, hash = %answer.source_hash, reasons = ?answer.reasons, trace = ?answer.trace, "reload refused: the mission goes on unchanged");
        }
        answer.bound();
        if let Err(e) = self.ports.reload_answers.send(&answer) {
            warn!(error = %e, "the reload answer could not be sent");
        }
    }

    fn refuse_reload(
        &mut self,
        sender: u64,
        seq: u64,
        request: &ReloadRequest,
        since: Instant,
        reasons: Vec<String>,
    ) {
        self.answer_reload(ReloadAnswer {
            request_sender: sender,
            request_seq: seq,
            accepted: false,
            dry_run: request.dry_run,
            dir: request.dir.clone(),
            source_hash: request.source_hash.clone(),
            reasons,
            millis: since.elapsed().as_millis() as u64,
            ..ReloadAnswer::default()
        });
    }

    /// The old version's state, mapped onto `candidate`.
    fn map_onto(
        &self,
        candidate: &crate::reload::Candidate,
    ) -> Result<petrel_nets::reload::Mapped, petrel_nets::reload::MapRefusal> {
        let from = petrel_nets::reload::OldState {
            state: self.engine.state(),
            deadlines: self.engine.deadlines(),
            net_args: self.engine.all_net_args(),
        };
        petrel_nets::reload::map_state(self.project, &from, &candidate.project, &candidate.mapping)
    }

    fn begin_reload(&mut self, sender: u64, seq: u64, request: ReloadRequest) {
        let since = Instant::now();
        if self.pending.is_some() {
            let why = "another reload is being verified: ask again when it is answered".to_string();
            return self.refuse_reload(sender, seq, &request, since, vec![why]);
        }
        let candidate = match crate::reload::load_candidate(
            std::path::Path::new(&request.dir),
            &request.source_hash,
            &request.mapping,
        ) {
            Ok(c) => c,
            Err(reasons) => return self.refuse_reload(sender, seq, &request, since, reasons),
        };
        let mapped = match self.map_onto(&candidate) {
            Ok(m) => m,
            Err(r) => return self.refuse_reload(sender, seq, &request, since, r.reasons),
        };
        // The verifier gets its own copy: a refused version is dropped whole.
        let project = candidate.project.clone();
        let state = mapped.clone();
        let verdict = std::thread::Builder::new()
            .name("reload-verify".into())
            .spawn(move || {
                petrel_nets::reload::verify_mapped(&project, &state, Some(RELOAD_MAX_STATES))
            });
        match verdict {
            Ok(verdict) => {
                self.pending = Some(PendingReload {
                    request,
                    sender,
                    seq,
                    received: since,
                    candidate,
                    summary: mapped.summary,
                    verdict,
                })
            }
            Err(e) => {
                let why = format!("cannot start the verification: {e}");
                self.refuse_reload(sender, seq, &request, since, vec![why])
            }
        }
    }

    /// Answers the reload under verification once the verdict is in, and swaps versions if it
    /// is accepted (between two steps: none was taken since the mapping).
    fn finish_reload(&mut self) {
        if !self
            .pending
            .as_ref()
            .is_some_and(|p| p.verdict.is_finished())
        {
            return;
        }
        let Some(p) = self.pending.take() else { return };
        let verdict = p.verdict.join().unwrap_or_else(|_| {
            Err(petrel_nets::reload::Finding {
                what: "the verification failed (its thread panicked): a bug in Petrel".into(),
                trace: Vec::new(),
            })
        });
        let states = match verdict {
            Ok(states) => states,
            Err(f) => {
                let mut reasons = vec![format!("verification from the mapped state: {}", f.what)];
                reasons.push(if f.trace.is_empty() {
                    "in the mapped state itself".to_string()
                } else {
                    format!("from the mapped state by: {}", f.trace.join(", "))
                });
                return self.answer_reload(ReloadAnswer {
                    request_sender: p.sender,
                    request_seq: p.seq,
                    accepted: false,
                    dry_run: p.request.dry_run,
                    dir: p.request.dir.clone(),
                    source_hash: p.candidate.source_hash.clone(),
                    summary: p.summary,
                    reasons,
                    trace: f.trace,
                    millis: p.received.elapsed().as_millis() as u64,
                    ..ReloadAnswer::default()
                });
            }
        };
        let mut answer = ReloadAnswer {
            request_sender: p.sender,
            request_seq: p.seq,
            accepted: true,
            dry_run: p.request.dry_run,
            dir: p.request.dir.clone(),
            source_hash: p.candidate.source_hash.clone(),
            step: self.step_no,
            summary: p.summary,
            states,
            ..ReloadAnswer::default()
        };
        if !p.request.dry_run {
            match self.swap(p.candidate, &p.request.dir) {
                Ok(handed) => answer.summary.push(handed),
                Err(reasons) => {
                    answer.accepted = false;
                    answer.reasons = reasons;
                }
            }
        }
        answer.millis = p.received.elapsed().as_millis() as u64;
        let swapped = answer.accepted && !answer.dry_run;
        self.answer_reload(answer);
        if swapped {
            // After the answer: a shadow reading the snapshot has the answer already, and
            // knows which version the snapshot's names are of.
            self.publish_delta();
        }
    }

    /// Swaps to the candidate version: the state mapped again (a timer may have fallen due
    /// during the verification: its event is queued, and goes to the new version), its files
    /// kept beside the journal and the reload journaled, then the engine, the record, the
    /// calls and the liveness watch of the new version.
    fn swap(
        &mut self,
        candidate: crate::reload::Candidate,
        dir: &str,
    ) -> Result<String, Vec<String>> {
        let mapped = self.map_onto(&candidate).map_err(|r| r.reasons)?;
        if let Some(journal) = &self.opts.journal {
            crate::reload::keep(journal, &candidate.source_hash, &candidate.files).map_err(
                |e| {
                    vec![format!(
                        "cannot keep the new version beside the journal in {}: {e}",
                        journal.display()
                    )]
                },
            )?;
        }
        let setup =
            |e: petrel_ipc::SetupError| vec![format!("cannot open the new version's calls: {e}")];
        // The calls of programs both versions have are kept: no program sees an interruption.
        let mut old_calls: Vec<Option<CallSender>> = std::mem::take(&mut self.ports.calls)
            .into_iter()
            .map(Some)
            .collect();
        let mut calls = Vec::new();
        let mut failed = None;
        for prog in &candidate.project.programs {
            // A sender sized for the old version is kept if the new version's calls fit.
            let bound = call_bound(prog);
            let kept = self
                .project
                .programs
                .iter()
                .position(|p| p.name == prog.name)
                .filter(|&i| {
                    old_calls[i].as_ref().is_some_and(|c| {
                        c.spec().max_body_len
                            >= bound.unwrap_or(petrel_ipc::port::CALLS.max_body_len)
                    })
                })
                .and_then(|i| old_calls[i].take());
            match kept {
                Some(c) => calls.push(c),
                None => match self.ports._me.call_sender_sized(&prog.name, bound) {
                    Ok(c) => calls.push(c),
                    Err(e) => {
                        failed = Some(setup(e));
                        break;
                    }
                },
            }
        }
        if let Some(reasons) = failed {
            // Put the old calls back as they were.
            self.ports.calls = old_calls.into_iter().flatten().collect();
            return Err(reasons);
        }
        let time = self.engine.now();
        let new = crate::reload::leak(candidate.project);
        let queued = self.engine.take_queue();
        let carried = queued.clone();
        let carried_len = carried.len();
        let mut engine = Engine::new(new);
        let refused = engine
            .adopt(
                time,
                &mapped.state,
                &mapped.deadlines,
                mapped.net_args,
                self.engine.stats(),
                queued,
                &candidate.mapping.nets,
            )
            .unwrap_or_default();
        self.journal.append(&Entry::Reload {
            time,
            dir: dir.to_string(),
            source_hash: candidate.source_hash.clone(),
            digest: crate::journal::project_digest(new),
            mapping: candidate.mapping_text,
            state: mapped.state,
            deadlines: mapped.deadlines,
            queued: carried,
        });
        let handed = format!(
            "queue: {} event(s) handed over to the new version, {} refused",
            carried_len,
            refused.len()
        );
        for (event, why) in refused {
            warn!(event, reason = %why, "a queued event refused at the reload");
        }
        self.ports.calls = calls;
        self.engine = engine;
        self.project = new;
        self.record = StepRecord::new(new).without_calls();
        match ProgramWatch::new(&self.ports._me, new.programs.iter().map(|p| p.name.clone())) {
            Ok(watch) => self.watch = watch,
            Err(e) => {
                warn!(error = %e, "the new version's programs cannot be watched: the old version's are")
            }
        }
        if let Err(e) = self.watch.check() {
            warn!(error = %e, "liveness check failed");
        }
        self.held.refresh(new);
        self.builtins = Builtins {
            program_lost: new.event_id("program_lost"),
            call_failed: new.event_id("call_failed"),
            bad_message: new.event_id("bad_message"),
            recorder_failed: new.event_id("recorder_failed"),
            recorder_restored: new.event_id("recorder_restored"),
        };
        // A larger version gets a heartbeat publisher sized for it.
        let heartbeat_max = Heartbeat::max_encoded_len(status_bound(new));
        if heartbeat_max > self.ports.heartbeat.spec().max_body_len {
            match self.ports._me.heartbeat_publisher_sized(heartbeat_max) {
                Ok(h) => self.ports.heartbeat = h,
                Err(e) => {
                    warn!(error = %e, "the heartbeat publisher could not grow for the new version: a status too large leaves its marking out")
                }
            }
        }
        // The snapshot of the new state follows the answer (see `finish_reload`).
        self.previous = vec![0; self.engine.state().len()];
        self.snapshot_next = true;
        self.report.reloads += 1;
        self.version = Some(candidate.source_hash);
        Ok(handed)
    }

    /// Publishes what the last step changed (the first message of a run is a full snapshot).
    fn publish_delta(&mut self) {
        if self.step_no != 0 && self.ports.marking.receivers() == 0 {
            // No monitor follows: the delta's names would be built for nobody. The first
            // monitor to come gets a snapshot (a monitor that just connected may miss this
            // step: the snapshot makes up for it).
            self.snapshot_next = true;
            self.previous.clear();
            self.previous.extend_from_slice(self.engine.state());
            self.record.forget_taken();
            self.record.activated.clear();
            self.record.deactivated.clear();
            return;
        }
        let project = self.project;
        let layout = self.engine.layout();
        let now = self.engine.state();
        let snapshot = self.step_no == 0 || std::mem::take(&mut self.snapshot_next);
        // Only the places that changed are named (a snapshot names every marked one).
        let (changed, unmarked) = place_changes(project, layout, &self.previous, now);
        let marked = if snapshot {
            marked_places(project, layout, now)
        } else {
            changed
        };
        let record = &mut self.record;
        let net_names = |ids: &mut Vec<NetId>| -> Vec<String> {
            ids.drain(..)
                .map(|n| project.nets[n as usize].name.clone())
                .collect()
        };
        let (event, params) = match record.taken.take() {
            Some((e, p)) => (Some(e), p),
            None => (None, Vec::new()),
        };
        let msg = MarkingMsg {
            step: self.step_no,
            event,
            time_us: self.engine.now(),
            params,
            actions: record.actions.clone(),
            fired: record.fired_names(),
            marked,
            unmarked,
            activated: if snapshot {
                // A snapshot lists the whole state: every active net.
                record.activated.clear();
                (0..project.nets.len() as NetId)
                    .filter(|&n| self.engine.is_active(n))
                    .map(|n| project.nets[n as usize].name.clone())
                    .collect()
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

/// What the status JSON shows: a snapshot of the player, or the largest one its project can
/// have ([`status_bound`]).
struct StatusSnapshot {
    project: String,
    time_s: f64,
    over: bool,
    /// The marked places of each active net (`global` last); `None`: left out (too large).
    marking: Option<Vec<(String, Vec<String>)>>,
    /// The counters of `stats`, in [`STATS_FIELDS`] order.
    stats: [u64; 16],
    /// Each sender: origin, last_seq, received, undecodable, missing, taken, refused, pending,
    /// unrecorded, settled_seq.
    senders: Vec<(String, [u64; 9])>,
    /// The flight recorder: its state, why it fails, and its counters in [`RECORDER_FIELDS`]
    /// order.
    recorder: (&'static str, String, [u64; 4]),
    /// The content hash of the version running, once a reload brought one.
    version: Option<String>,
    /// A reload is being verified.
    reloading: bool,
}

/// The names of the recorder's counters in the status JSON's `recorder`.
const RECORDER_FIELDS: [&str; 4] = [
    "failures",
    "lost_entries",
    "backlog_records",
    "backlog_bytes",
];

/// The names of the counters in the status JSON's `stats`, in [`StatusSnapshot::stats`] order.
const STATS_FIELDS: [&str; 16] = [
    "messages",
    "bad_messages",
    "received",
    "processed",
    "unused",
    "refused",
    "queued",
    "calls_sent",
    "calls_failed",
    "calls_held",
    "journal_records",
    "resumed_steps",
    "heartbeats_sent",
    "heartbeats_refused",
    "reloads",
    "reloads_refused",
];

/// The names of a sender's counters in the status JSON, in [`StatusSnapshot::senders`] order.
const SENDER_FIELDS: [&str; 9] = [
    "last_seq",
    "received",
    "undecodable",
    "missing",
    "taken",
    "refused",
    "pending",
    "unrecorded",
    "settled_seq",
];

impl StatusSnapshot {
    fn of(engine: &Engine, report: &PlayReport, ledger: &Ledger, journal: &Journal) -> Self {
        let s = engine.stats();
        // Oldest first, so that two senders of one origin show the most recent one.
        let mut senders: Vec<(String, [u64; 9])> = ledger
            .recent()
            .into_iter()
            .map(|a| {
                let k = &a.ack;
                (
                    k.origin.clone(),
                    [
                        k.last_seq,
                        k.received,
                        a.undecodable,
                        k.missing,
                        k.taken,
                        k.refused,
                        k.pending,
                        k.unrecorded,
                        k.settled_seq,
                    ],
                )
            })
            .collect();
        senders.reverse();
        let (records, bytes) = journal.backlog();
        let mut reason = journal.reason().to_string();
        petrel_ipc::wire::cut_text(&mut reason, petrel_ipc::wire::MAX_REASON_LEN);
        StatusSnapshot {
            recorder: (
                journal.state().as_str(),
                reason,
                [journal.failures, journal.lost, records as u64, bytes as u64],
            ),
            project: engine.project().name.clone(),
            time_s: engine.now() as f64 / 1e6,
            over: engine.is_over(),
            marking: Some(engine.marking()),
            stats: [
                report.messages,
                report.bad_messages,
                s.received,
                s.processed,
                s.unused,
                s.refused,
                engine.queued() as u64,
                report.calls_sent,
                report.calls_failed,
                report.calls_held,
                report.journal_records,
                report.resumed_steps,
                report.heartbeats_sent,
                report.heartbeats_refused,
                report.reloads,
                report.reloads_refused,
            ],
            senders,
            version: None,
            reloading: false,
        }
    }
}

/// The live status carried by the heartbeat, for people and tools: JSON with the marking of
/// every active net, the counters, and each sender's account (read by `petrel status`; the
/// acknowledgements senders wait for are the heartbeat's typed [`Heartbeat::acks`]).
fn status_json(s: &StatusSnapshot) -> String {
    let mut doc = serde_json::Map::new();
    doc.insert("project".into(), s.project.clone().into());
    doc.insert("time".into(), s.time_s.into());
    doc.insert("over".into(), s.over.into());
    doc.insert("version".into(), s.version.clone().into());
    doc.insert("reloading".into(), s.reloading.into());
    match &s.marking {
        Some(m) => {
            let marking: serde_json::Map<String, serde_json::Value> = m
                .iter()
                .map(|(n, places)| (n.clone(), places.clone().into()))
                .collect();
            doc.insert("marking".into(), marking.into());
        }
        None => {
            doc.insert("marking".into(), serde_json::Map::new().into());
            doc.insert("marking_omitted".into(), true.into());
        }
    }
    let stats: serde_json::Map<String, serde_json::Value> = STATS_FIELDS
        .iter()
        .zip(&s.stats)
        .map(|(k, v)| (k.to_string(), (*v).into()))
        .collect();
    doc.insert("stats".into(), stats.into());
    let senders: serde_json::Map<String, serde_json::Value> = s
        .senders
        .iter()
        .map(|(origin, counts)| {
            let fields: serde_json::Map<String, serde_json::Value> = SENDER_FIELDS
                .iter()
                .zip(counts)
                .map(|(k, v)| (k.to_string(), (*v).into()))
                .collect();
            (origin.clone(), fields.into())
        })
        .collect();
    doc.insert("senders".into(), senders.into());
    let (state, reason, counts) = &s.recorder;
    let mut recorder = serde_json::Map::new();
    recorder.insert("state".into(), (*state).into());
    recorder.insert("reason".into(), reason.clone().into());
    for (k, v) in RECORDER_FIELDS.iter().zip(counts) {
        recorder.insert(k.to_string(), (*v).into());
    }
    doc.insert("recorder".into(), recorder.into());
    serde_json::Value::Object(doc).to_string()
}

/// The longest call the project can make to `program`, encoded, when its functions take only
/// fixed-size parameters (`None`: text or lists, whose length the project does not bound): the
/// size of the player's call sender to it (docs/benchmarks.md, "Footprint").
fn call_bound(program: &Program) -> Option<usize> {
    let mut bound = 0;
    for function in &program.functions {
        // The longest encoding of each type: a varint takes the most bytes at i64::MIN.
        let args = function
            .params
            .iter()
            .map(|(_, ty)| match ty {
                Type::Int => Some(Value::Int(i64::MIN)),
                Type::Float => Some(Value::Float(f64::MAX)),
                Type::Bool => Some(Value::Bool(true)),
                Type::Text | Type::FloatList => None,
            })
            .collect::<Option<Vec<_>>>()?;
        let len = petrel_ipc::wire::encoded_len(&CallMsg::new(function.name.clone(), args)).ok()?;
        bound = bound.max(len);
    }
    Some(bound)
}

/// What a text or list parameter of an event counts for in [`event_bound`]: 256 bytes (a
/// 256-byte text, 32 floats). Longer ones still go, in pieces (`petrel_ipc::wire::FRAGMENT`).
const TEXT_ALLOWANCE: usize = 256;

/// The longest event a process may send `project`, encoded: the events service records it
/// when the player creates it, and each program's sender sizes its fixed samples from it
/// (docs/benchmarks.md, "Footprint"). Exact for `int`, `float` and `bool` parameters (the
/// longest encoding of each), [`TEXT_ALLOWANCE`] for each text or list; at least 64 bytes.
/// Internal and built-in events are left out: no process sends them (the data server's
/// `call_failed`, short names, fits the senders' 512 bytes at least).
fn event_bound(project: &CompiledProject) -> usize {
    let allowance_floats = TEXT_ALLOWANCE / 8;
    let builtin = |name: &str| {
        petrel_nets::model::builtin_events()
            .iter()
            .any(|b| b.name.text == name)
    };
    project
        .events
        .iter()
        .filter(|e| !e.internal && !builtin(&e.name))
        .filter_map(|e| {
            let params = e
                .params
                .iter()
                .map(|(_, ty)| match ty {
                    Type::Int => Value::Int(i64::MIN),
                    Type::Float => Value::Float(f64::MAX),
                    Type::Bool => Value::Bool(true),
                    Type::Text => Value::Text("x".repeat(TEXT_ALLOWANCE)),
                    Type::FloatList => Value::FloatList(vec![f64::MAX; allowance_floats]),
                })
                .collect();
            petrel_ipc::wire::encoded_len(&EventMsg::new(e.name.clone(), params)).ok()
        })
        .fold(64, usize::max)
}

/// The length of the marking publisher's fixed samples: twice the largest snapshot `project`
/// can give (every place marked, every net active, the longest event's name), at least 1 KiB.
/// Deltas name only what changed and fit with room to spare; a step whose actions or
/// parameters are longer still goes, in pieces (`petrel_ipc::wire::FRAGMENT`).
fn marking_bound(project: &CompiledProject) -> usize {
    let worst = MarkingMsg {
        step: u64::MAX,
        event: project
            .events
            .iter()
            .map(|e| e.name.clone())
            .max_by_key(|n| n.len()),
        fired: Vec::new(),
        marked: project
            .nets
            .iter()
            .flat_map(|n| n.places.iter().map(|p| format!("{}.{}", n.name, p.name)))
            .chain(project.globals.iter().map(|g| format!("global.{}", g.name)))
            .collect(),
        unmarked: Vec::new(),
        activated: project.nets.iter().map(|n| n.name.clone()).collect(),
        deactivated: Vec::new(),
        snapshot: true,
        time_us: u64::MAX,
        params: Vec::new(),
        actions: Vec::new(),
    };
    let snapshot = petrel_ipc::wire::encoded_len(&worst).unwrap_or(0);
    (2 * snapshot).max(1024)
}

/// The length of the largest status JSON `project` can give: every net active with every place
/// marked, the ledger full of senders whose origins need the most escaping, every counter at
/// its largest. The heartbeat's publisher is sized from it, so that no status is ever refused.
fn status_bound(project: &CompiledProject) -> usize {
    let mut marking: Vec<(String, Vec<String>)> = project
        .nets
        .iter()
        .map(|n| {
            (
                n.name.clone(),
                n.places.iter().map(|p| p.name.clone()).collect(),
            )
        })
        .collect();
    marking.push((
        "global".into(),
        project.globals.iter().map(|g| g.name.clone()).collect(),
    ));
    // A control character is escaped in six bytes (`\u0001`), the most any byte takes; the
    // ledger keys senders by id, so that every one of them may show under its own origin:
    // origins of control characters 1 and 2 only, distinct by the bits of their index.
    let origin = |i: usize| -> String {
        (0..petrel_ipc::wire::ORIGIN_LEN)
            .map(|k| char::from(1 + ((i >> (k % 8)) & 1) as u8))
            .collect()
    };
    let worst = StatusSnapshot {
        project: project.name.clone(),
        time_s: -f64::MAX,
        over: false,
        marking: Some(marking),
        stats: [u64::MAX; 16],
        senders: (0..petrel_ipc::wire::MAX_ACKS)
            .map(|i| (origin(i), [u64::MAX; 9]))
            .collect(),
        recorder: (
            "dropping",
            "\u{1}".repeat(petrel_ipc::wire::MAX_REASON_LEN),
            [u64::MAX; 4],
        ),
        version: Some("f".repeat(16)),
        reloading: true,
    };
    status_json(&worst).len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use petrel_ipc::Origin;

    fn project() -> CompiledProject {
        let manifest = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\", \"B\"]\n\n[globals]\ng_one = 1\n\n[events]\ngo = { category = \"nominal\" }\n";
        let net = "net A {\n    place a_very_long_place_name_one = 1\n    place two = 1\n    transition t on go: two -> two\n}\nnet B {\n    place b = 1\n    transition u on go: b -> b\n}\n";
        let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
        assert!(!d.has_errors(), "{d:?}");
        c.unwrap()
    }

    #[test]
    fn the_journal_s_fired_names_are_the_record_s() {
        let p = project();
        let mut engine = Engine::new(&p);
        let mut record = StepRecord::new(&p).without_calls();
        engine.start(0, &mut record);
        record.clear();
        engine.submit(p.event_id("go").unwrap(), vec![]).unwrap();
        engine.step(&mut record).unwrap();
        let names = record.fired_names();
        assert_eq!(names, ["A.t", "B.u"]);
        let config = bincode::config::standard();
        assert_eq!(
            bincode::encode_to_vec(record.fired_encoded(), config).unwrap(),
            bincode::encode_to_vec(&names, config).unwrap()
        );
        // The next step's record starts empty, whatever it keeps for reuse.
        record.clear();
        assert!(record.taken.is_none() && record.fired.is_empty() && record.actions.is_empty());
    }

    #[test]
    fn the_status_never_exceeds_its_bound() {
        let p = project();
        let bound = status_bound(&p);
        let mut engine = Engine::new(&p);
        engine.start(0, &mut crate::engine::NullSink);
        let mut ledger = Ledger::new();
        // More senders than a heartbeat carries, with origins that escape the most.
        for i in 0..200u64 {
            let origin: String = format!("{i:03}")
                .chars()
                .chain((3..32).map(|k| char::from(((i + k) % 31 + 1) as u8)))
                .collect();
            ledger.taken(i, Origin::new(&origin), u64::MAX, u64::MAX / 2);
        }
        let report = PlayReport {
            messages: u64::MAX,
            heartbeats_refused: u64::MAX,
            ..PlayReport::default()
        };
        let journal = Journal::new(None);
        let json = status_json(&StatusSnapshot::of(&engine, &report, &ledger, &journal));
        assert!(json.len() <= bound, "{} > {bound}", json.len());
        let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(doc["marking"]["A"].as_array().map(Vec::len), Some(2));
        assert_eq!(doc["senders"].as_object().map(|m| m.len()), Some(64));
        assert!(Heartbeat::max_encoded_len(bound) < petrel_ipc::wire::MAX_BODY_LEN);
    }

    #[test]
    fn place_changes_name_what_the_two_markings_differ_in() {
        let p = project();
        let engine = Engine::new(&p);
        let layout = engine.layout();
        let words = engine.state().len();
        // Pseudo-random markings (every bit pattern of the places matters, not realism).
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut state = || -> Vec<u64> {
            (0..words)
                .map(|_| {
                    seed ^= seed << 13;
                    seed ^= seed >> 7;
                    seed ^= seed << 17;
                    seed
                })
                .collect()
        };
        for _ in 0..200 {
            let (before, after) = (state(), state());
            let (b, a) = (
                marked_places(&p, layout, &before),
                marked_places(&p, layout, &after),
            );
            let expected_marked: Vec<_> = a.iter().filter(|x| !b.contains(x)).cloned().collect();
            let expected_unmarked: Vec<_> = b.iter().filter(|x| !a.contains(x)).cloned().collect();
            let (marked, unmarked) = place_changes(&p, layout, &before, &after);
            assert_eq!(marked, expected_marked);
            assert_eq!(unmarked, expected_unmarked);
        }
    }

    fn programs() -> CompiledProject {
        let manifest = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\ngo = { category = \"nominal\" }\n\n[programs.NAV.functions]\ngoto = { params = [\"x: int\", \"speed: float\", \"fast: bool\"] }\nstop = []\n\n[programs.PLN.functions]\nroute = { params = [\"points: [float]\"] }\n\n[programs.LOG.functions]\nsay = { params = [\"what: text\"] }\n";
        let net = "net A {\n    place a = 1\n    transition t on go: a -> a\n}\n";
        let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
        assert!(!d.has_errors(), "{d:?}");
        c.unwrap()
    }

    #[test]
    fn a_call_bound_covers_the_longest_call_and_only_fixed_size_parameters_have_one() {
        let p = programs();
        let program = |name: &str| p.programs.iter().find(|q| q.name == name).unwrap();
        let bound = call_bound(program("NAV")).expect("int, float and bool have a bound");
        // Every extreme of each type encodes within it, the longest exactly at it.
        let mut longest = 0;
        for x in [0, 1, -1, i64::MAX, i64::MIN] {
            for speed in [0.0, f64::MIN, f64::MAX, f64::NAN] {
                for fast in [false, true] {
                    let call = CallMsg::new(
                        "goto",
                        vec![Value::Int(x), Value::Float(speed), Value::Bool(fast)],
                    );
                    let len = petrel_ipc::wire::encoded_len(&call).unwrap();
                    assert!(len <= bound, "{call:?}: {len} > {bound}");
                    longest = longest.max(len);
                }
            }
        }
        assert_eq!(longest, bound);
        assert_eq!(call_bound(program("PLN")), None, "a list has no bound");
        assert_eq!(call_bound(program("LOG")), None, "a text has no bound");
    }

    #[test]
    fn the_event_bound_covers_the_longest_event_a_process_sends_and_leaves_out_built_ins() {
        let manifest = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\narrived = { category = \"nominal\", params = [\"x: int\", \"speed: float\", \"fast: bool\"] }\nnote = { category = \"nominal\", params = [\"what: text\", \"xs: [float]\"] }\n";
        let net = "net A {\n    place a = 1\n    transition t on arrived(x, s, f): a -> a\n    transition n on note(w, xs): a -> a\n}\n";
        let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
        assert!(!d.has_errors(), "{d:?}");
        let p = c.unwrap();
        let bound = event_bound(&p);
        let len = |e: EventMsg| petrel_ipc::wire::encoded_len(&e).unwrap();
        let arrived = len(EventMsg::new(
            "arrived",
            vec![
                Value::Int(i64::MIN),
                Value::Float(f64::MAX),
                Value::Bool(true),
            ],
        ));
        let note = len(EventMsg::new(
            "note",
            vec![
                Value::Text("é".repeat(TEXT_ALLOWANCE / 2)),
                Value::FloatList(vec![0.5; TEXT_ALLOWANCE / 8]),
            ],
        ));
        assert!(arrived < bound);
        assert_eq!(note, bound, "a text and a list at their allowance");
        // Built-in events (program_lost, call_failed... with their texts) do not count.
        let only_ints = programs();
        assert_eq!(
            event_bound(&only_ints),
            64,
            "a project of parameterless events"
        );
        // The marking's fixed samples hold a snapshot of every place and net, twice over.
        let snapshot = MarkingMsg {
            step: 1,
            event: Some("note".into()),
            fired: Vec::new(),
            marked: vec!["A.a".into()],
            unmarked: Vec::new(),
            activated: vec!["A".into()],
            deactivated: Vec::new(),
            snapshot: true,
            time_us: 5,
            params: Vec::new(),
            actions: Vec::new(),
        };
        assert!(2 * petrel_ipc::wire::encoded_len(&snapshot).unwrap() <= marking_bound(&p));
    }
}
