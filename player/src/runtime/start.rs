//! Starting the player: the vehicle joined, the journal directory taken (and, for `--resume`,
//! the engine rebuilt from it), the ports opened at the sizes of the project, the journal
//! opened and the mission started or carried on.

use super::options::{PlayError, PlayOptions, PlayReport};
use super::player_loop::PlayerLoop;
use super::ports::{Builtins, Ports};
use super::sink::RuntimeSink;
use crate::ack::Ledger;
use crate::engine::{Engine, Micros};
use crate::held::HeldCalls;
use crate::journal::{Entry, Journal, JournalLock, JournalWriter};
use crate::record::StepRecord;
use crate::reload::ReloadJob;
use crate::sizing::{call_bound, event_bound, marking_bound, status_bound};
use petrel_ipc::{Heartbeat, Participant, ProgramWatch, Reactor, Vehicle, WaitStrategy};
use petrel_nets::compiled::CompiledProject;
use std::time::{Duration, Instant};
use tracing::{info, warn};

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

/// A mission restored from its journal (`--resume`).
struct Resumed<'p> {
    /// The engine in the state the journal reached (on the version of its last reload).
    engine: Engine<'p>,
    /// The mission time of the journal's last entry.
    last: Micros,
    /// The steps restored.
    steps: u64,
    /// The content hash of the version running, if a reload brought it.
    version: Option<String>,
}

/// Rebuilds the engine from the journal (`--resume`).
fn resume<'p>(project: &'p CompiledProject, opts: &PlayOptions) -> Result<Resumed<'p>, PlayError> {
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
    Ok(Resumed {
        engine,
        last: r.last_time,
        steps: r.steps,
        version,
    })
}

/// The content hash of the version the journal's last reload brought ("" without a reload).
fn engine_version(entries: &[Entry]) -> String {
    match crate::replay::last_reload(entries).map(|k| &entries[k]) {
        Some(Entry::Reload { source_hash, .. }) => source_hash.clone(),
        _ => String::new(),
    }
}

/// Joins the vehicle's services (with the operators' group, if any), after removing what
/// dead processes left there.
fn join_vehicle(opts: &PlayOptions) -> Result<Vehicle, PlayError> {
    let mut vehicle = Vehicle::new(&opts.vehicle).map_err(|e| PlayError::Vehicle(e.to_string()))?;
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
    Ok(vehicle)
}

/// Opens the player's ports on the vehicle, each sized from `project` ([`crate::sizing`]), and
/// the watch on its programs.
fn open_ports(
    vehicle: &Vehicle,
    project: &CompiledProject,
    wait: WaitStrategy,
) -> Result<(Ports, ProgramWatch), PlayError> {
    let setup = |e: petrel_ipc::SetupError| PlayError::Setup(e.to_string());
    let me = Participant::join_player(vehicle, project.programs.len()).map_err(setup)?;
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
    if wait != WaitStrategy::Block {
        // Spinning, the player sees events in shared memory: their notifications are
        // consumed now and then, not at every event (two system calls fewer each).
        ports
            .events
            .consume_wakeups_every(Some(petrel_ipc::SPIN_WAKEUP_PERIOD));
    }
    let watch = ProgramWatch::new(&ports._me, project.programs.iter().map(|p| p.name.clone()))
        .map_err(setup)?;
    Ok((ports, watch))
}

/// Opens the journal (a recorder that writes nothing without a journal directory), its header
/// naming the mission's first version and its start.
fn open_journal(
    project: &CompiledProject,
    opts: &PlayOptions,
    mission_start_ms: u64,
) -> Result<Journal, PlayError> {
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
            let w = JournalWriter::open(dir, header, opts.flush, opts.rotate_bytes)
                .map_err(|e| PlayError::Journal(format!("cannot write {}: {e}", dir.display())))?;
            info!(dir = %dir.display(), flush = ?opts.flush, "journal open");
            Some(w)
        }
    };
    let mut journal = Journal::with_backlog(writer, opts.journal_backlog);
    journal.batch_records();
    Ok(journal)
}

/// Starts a new mission at time 0 (its calls go through `sink`) and journals its start.
fn start_mission<'p>(
    project: &'p CompiledProject,
    sink: &mut RuntimeSink<'_, 'p>,
    journal: &mut Journal,
) -> Engine<'p> {
    let mut engine = Engine::new(project);
    engine.start(0, sink);
    // The start's actions are the start's, not the first event's.
    sink.record.clear();
    journal.append(&Entry::Start {
        time: 0,
        state: engine.state().to_vec(),
    });
    engine
}

/// Carries a restored mission on, from now: the engine, the mission time it goes on from, and
/// the instant that time is counted from.
///
/// Mission time went on while the player was down: timers keep their wall-clock deadlines, and
/// those that passed expire now, in deadline order. The resume entry says when, so that replay
/// expires them at the same time.
fn carry_on<'p>(
    mut engine: Engine<'p>,
    last: Micros,
    mission_start_ms: u64,
    journal: &mut Journal,
) -> (Engine<'p>, Micros, Instant) {
    let t0 = Instant::now();
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
    (engine, time, t0)
}

impl<'p> PlayerLoop<'p> {
    /// Sets the player up: removes what dead processes left, restores the journal for
    /// `--resume`, joins the vehicle, opens the journal and starts the mission (or carries on
    /// the restored one).
    pub fn new(project: &'p CompiledProject, opts: &PlayOptions) -> Result<Self, PlayError> {
        let vehicle = join_vehicle(opts)?;
        // Mission time is wall-clock time since the mission started; a new mission starts now.
        let (t0, now_ms) = (Instant::now(), unix_ms());
        // The journal directory is this player's alone, and this vehicle's.
        let (lock, mission_start_ms) = match &opts.journal {
            Some(dir) => {
                let (lock, start) = take_journal(dir, opts, now_ms)?;
                (Some(lock), start)
            }
            None => (None, now_ms),
        };
        // Recovery first: the engine is rebuilt from the journal before anything else happens.
        let resumed = match opts.resume {
            true => Some(resume(project, opts)?),
            false => None,
        };
        // A resume after a reload runs the reloaded version.
        let project: &'p CompiledProject = resumed.as_ref().map_or(project, |r| r.engine.project());
        let (ports, watch) = open_ports(&vehicle, project, opts.wait)?;
        let reactor = Reactor::new(opts.wait).map_err(|e| PlayError::Setup(e.to_string()))?;
        let mut journal = open_journal(project, opts, mission_start_ms)?;
        let mut record = StepRecord::new(project).without_calls();
        let mut undelivered = Vec::new();
        let mut report = PlayReport::default();
        let held = HeldCalls::new(project.programs.len());
        let version = resumed.as_ref().and_then(|r| r.version.clone());
        let (engine, base, t0) = match resumed {
            Some(r) => {
                report.resumed_steps = r.steps;
                carry_on(r.engine, r.last, mission_start_ms, &mut journal)
            }
            None => {
                let mut sink = RuntimeSink {
                    record: &mut record,
                    calls: &ports.calls,
                    holding: held.holding(),
                    undelivered: &mut undelivered,
                    sent: &mut report.calls_sent,
                };
                (start_mission(project, &mut sink, &mut journal), 0, t0)
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
            builtins: Builtins::of(project),
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
            reload: ReloadJob::default(),
            verifier: None,
            version,
            _lock: lock,
        })
    }
}
