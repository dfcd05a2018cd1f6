//! Replaying a journal through the engine: every recorded step is reproduced and checked.
//!
//! The journal's inputs (the start, each submitted event with its time) are fed to a fresh
//! engine; at each recorded step the engine takes its next event, and the event, the transitions
//! fired and the state after must be the recorded ones. The first difference is a divergence,
//! reported with both markings and the event that caused it. The journal itself must hold
//! together: every segment's header names the same vehicle, project and mission start, and
//! time never goes backwards from one entry to the next; segments spliced from another journal
//! are reported like a divergence ([`DivergenceKind::Journal`]). Recovery (`petrel play
//! --resume`) is the same replay, after which the player carries on live.

use crate::engine::{Engine, Micros};
use crate::journal::Entry;
use crate::record::{outcome_name, StepRecord};
use petrel_nets::compiled::{CompiledProject, Value};
use petrel_nets::semantics::Layout;
use std::path::Path;

/// What kind of difference a [`Divergence`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DivergenceKind {
    /// The engine did not reproduce a recorded step or state.
    Replay,
    /// The journal does not hold together: a segment of another vehicle, project or mission,
    /// or time going backwards (segments spliced from another journal).
    Journal,
}

/// The first place where the replay differs from the journal.
#[derive(Clone, Debug, PartialEq)]
pub struct Divergence {
    /// What kind of difference.
    pub kind: DivergenceKind,
    /// Index of the journal entry.
    pub entry: usize,
    /// Its mission time, microseconds.
    pub time: Micros,
    /// The event of the step (recorded).
    pub event: String,
    /// What differs, in words.
    pub what: String,
    /// The recorded marking after the step.
    pub recorded: Vec<String>,
    /// The marking the replay reached.
    pub replayed: Vec<String>,
}

/// How a replay went.
#[derive(Clone, Debug, Default)]
pub struct ReplayReport {
    /// Entries read.
    pub entries: usize,
    /// Steps reproduced.
    pub steps: u64,
    /// The first divergence, if any.
    pub divergence: Option<Divergence>,
    /// Mission time of the last entry replayed, microseconds.
    pub last_time: Micros,
    /// Replay stopped at `--until` before the end of the journal.
    pub stopped_early: bool,
    /// Gaps: places where the recorder dropped entries (it could not write them) and the
    /// journal goes on from a checkpoint of the state.
    pub gaps: u64,
    /// Entries the recorder dropped, all gaps together.
    pub lost: u64,
    /// Reloads of the project replayed across.
    pub reloads: u64,
}

/// A state as `NET.place` / `global.place` names, active nets as `NET+`, running timers.
pub fn describe(project: &CompiledProject, layout: &Layout, state: &[u64]) -> Vec<String> {
    if state.len() != layout.words {
        return vec![format!(
            "(a state of {} words, expected {})",
            state.len(),
            layout.words
        )];
    }
    layout.describe_state(project, state)
}

/// Replays `entries` on a fresh engine for `project`, up to mission time `until` (included).
/// Returns the engine in the state the journal reached, and the report. A reload in the
/// journal is a divergence here: see [`replay_in`].
pub fn replay<'p>(
    project: &'p CompiledProject,
    entries: &[Entry],
    until: Option<Micros>,
) -> (Engine<'p>, ReplayReport) {
    replay_in(project, entries, until, None, false)
}

/// The index of the last [`Entry::Reload`] of `entries`, if any.
pub fn last_reload(entries: &[Entry]) -> Option<usize> {
    entries
        .iter()
        .rposition(|e| matches!(e, Entry::Reload { .. }))
}

/// Replays `entries` as [`replay`] does, across reloads: the versions a reload brought are
/// read from the journal directory `kept` ([`crate::reload::version::load_kept`]), the state is
/// mapped again and checked against the recorded one, and the replay goes on with the new
/// version. With `from_last_reload`, the replay starts at the journal's last reload, on the
/// version it brought (its recorded state restored like a checkpoint's): for `--resume`, and
/// for a replay whose project directory holds a later version than the mission's first.
pub fn replay_in<'p>(
    project: &'p CompiledProject,
    entries: &[Entry],
    until: Option<Micros>,
    kept: Option<&Path>,
    from_last_reload: bool,
) -> (Engine<'p>, ReplayReport) {
    let mut r = Replayer::new(project, kept);
    let mut skip_to = 0;
    let last = last_reload(entries).and_then(|k| Some((k, ReloadAt::of(&entries[k])?)));
    if let (true, Some((k, at))) = (from_last_reload, last) {
        if let Err(d) = r.start_at_reload(k, at) {
            r.report.divergence = Some(d);
            return (r.engine, r.report);
        }
        skip_to = k + 1;
    }
    for (i, entry) in entries.iter().enumerate() {
        // Headers are checked all the same: the journal holds together or not.
        if i < skip_to && !matches!(entry, Entry::Header { .. }) {
            continue;
        }
        if let (Some(limit), Some(t)) = (until, entry.time()) {
            if t > limit {
                r.report.stopped_early = true;
                break;
            }
        }
        if let Err(d) = r.entry(i, entry) {
            r.report.divergence = Some(d);
            break;
        }
    }
    (r.engine, r.report)
}

/// A replay under way: the version it runs, its engine, and what it saw of the journal.
struct Replayer<'p, 'e> {
    project: &'p CompiledProject,
    engine: Engine<'p>,
    log: StepRecord<'p>,
    report: ReplayReport,
    /// The journal directory, where the versions reloads brought are kept.
    kept: Option<&'e Path>,
    /// After a gap, the next checkpoint is where the replay starts over.
    after_gap: bool,
    /// The journal's first header (vehicle, digest, mission start).
    first: Option<(&'e str, u64, Option<u64>)>,
    /// The last entry that had a time, and its time.
    previous: Option<(usize, u64)>,
}

impl<'p, 'e> Replayer<'p, 'e> {
    fn new(project: &'p CompiledProject, kept: Option<&'e Path>) -> Self {
        Replayer {
            project,
            engine: Engine::new(project),
            log: StepRecord::new(project),
            report: ReplayReport::default(),
            kept,
            after_gap: false,
            first: None,
            previous: None,
        }
    }

    /// Entry `i` replayed: `Err` with the first difference.
    fn entry(&mut self, i: usize, entry: &'e Entry) -> Result<(), Divergence> {
        if let Some(what) = inconsistency(entry, &mut self.first, &mut self.previous, i) {
            return Err(Divergence {
                kind: DivergenceKind::Journal,
                entry: i,
                time: entry.time().unwrap_or(self.report.last_time),
                event: "(journal)".into(),
                what,
                recorded: Vec::new(),
                replayed: self.describe(self.engine.state()),
            });
        }
        self.report.entries = i + 1;
        if let Some(t) = entry.time() {
            self.report.last_time = t;
        }
        match entry {
            Entry::Header { .. } | Entry::ProgramStopped { .. } => Ok(()),
            // Refused live and counted so (received and refused): the counters of a resumed
            // engine account for it too.
            Entry::Refused { .. } => {
                self.engine.count_refused();
                Ok(())
            }
            Entry::Reload { .. } => match ReloadAt::of(entry) {
                Some(at) => self.reload(i, at),
                None => Ok(()),
            },
            // The player came back at this mission time: timers whose deadline passed while it
            // was down expire now, as they did live.
            Entry::Resume { time } => {
                self.engine.advance_to(*time);
                Ok(())
            }
            Entry::Gap { lost, .. } => {
                self.report.gaps += 1;
                self.report.lost += lost;
                self.after_gap = true;
                Ok(())
            }
            Entry::Checkpoint {
                time,
                state,
                deadlines,
            } => self.checkpoint(i, *time, state, deadlines),
            Entry::Start { time, state } => {
                self.engine.start(*time, &mut self.log);
                self.log.clear();
                let what = "the initial state differs";
                self.check_state(i, what, "(start)", *time, state, None)
            }
            Entry::Submit {
                time,
                event,
                params,
                ..
            } => self.submit(i, *time, event, params),
            Entry::Step {
                time,
                event,
                outcome,
                fired,
                state,
                ..
            } => self.step(i, *time, event, (outcome, fired), state),
        }
    }

    /// A state as names, in the version the replay runs.
    fn describe(&self, state: &[u64]) -> Vec<String> {
        describe(self.engine.project(), self.engine.layout(), state)
    }

    /// Entry `i`, at `time` (event `event`), does not replay: `what`; `recorded` is the state
    /// the journal holds there.
    fn diverge(
        &self,
        i: usize,
        what: String,
        event: &str,
        time: u64,
        recorded: &[u64],
    ) -> Divergence {
        Divergence {
            kind: DivergenceKind::Replay,
            entry: i,
            time,
            event: event.to_string(),
            what,
            recorded: self.describe(recorded),
            replayed: self.describe(self.engine.state()),
        }
    }

    /// The engine's state is the recorded `state` (and its deadlines the recorded ones, if
    /// given); otherwise the divergence `what`.
    fn check_state(
        &self,
        i: usize,
        what: &str,
        event: &str,
        time: u64,
        state: &[u64],
        deadlines: Option<&[Option<u64>]>,
    ) -> Result<(), Divergence> {
        let same =
            self.engine.state() == state && deadlines.is_none_or(|d| self.engine.deadlines() == d);
        match same {
            true => Ok(()),
            false => Err(self.diverge(i, what.into(), event, time, state)),
        }
    }

    /// A checkpoint: where the replay starts over after a gap, and a check of the state
    /// otherwise.
    fn checkpoint(
        &mut self,
        i: usize,
        time: u64,
        state: &[u64],
        deadlines: &[Option<u64>],
    ) -> Result<(), Divergence> {
        if !self.after_gap {
            let what = "the state at the checkpoint differs";
            return self.check_state(i, what, "(checkpoint)", time, state, Some(deadlines));
        }
        self.after_gap = false;
        if !self.engine.restore(time, state, deadlines) {
            let what = "the checkpoint is not of this project's size".into();
            return Err(self.diverge(i, what, "(checkpoint)", time, state));
        }
        Ok(())
    }

    /// A submitted event, at its time.
    fn submit(
        &mut self,
        i: usize,
        time: u64,
        event: &str,
        params: &[Value],
    ) -> Result<(), Divergence> {
        self.engine.advance_to(time);
        match self.engine.submit_named(event, params.to_vec()) {
            Ok(()) => Ok(()),
            Err(r) => Err(Divergence {
                kind: DivergenceKind::Replay,
                entry: i,
                time,
                event: event.to_string(),
                what: format!("the engine refuses the recorded event: {r}"),
                recorded: Vec::new(),
                replayed: self.describe(self.engine.state()),
            }),
        }
    }

    /// A recorded step: the engine takes its next event, which must be the recorded one, with
    /// the same outcome, the same transitions fired and the same state after.
    fn step(
        &mut self,
        i: usize,
        time: Micros,
        event: &str,
        (outcome, fired): (&str, &[String]),
        state: &[u64],
    ) -> Result<(), Divergence> {
        self.engine.advance_to(time);
        self.log.clear();
        let Some(step) = self.engine.step(&mut self.log) else {
            let what = "the journal has a step here, the replay has no event left to take";
            return Err(self.diverge(i, what.into(), event, time, state));
        };
        self.report.steps += 1;
        let taken = &self.project.events[step.event as usize].name;
        let replayed_outcome = outcome_name(step.outcome);
        let found_fired = self.log.fired_names();
        let what = if taken != event {
            format!("the replay took `{taken}`, the journal `{event}`")
        } else if replayed_outcome != outcome {
            format!("the event was {replayed_outcome} in the replay, {outcome} in the journal")
        } else if found_fired != fired {
            format!(
                "fired [{}] in the replay, [{}] in the journal",
                found_fired.join(", "),
                fired.join(", ")
            )
        } else {
            let what = "the marking after the step differs";
            return self.check_state(i, what, event, time, state, None);
        };
        Err(self.diverge(i, what, event, time, state))
    }

    /// A reload: the queue at the reload must be the recorded one; the version it brought is
    /// read from the journal directory, the state mapped again with the recorded mapping (and
    /// checked against the recorded state), the queue carried over.
    fn reload(&mut self, i: usize, at: ReloadAt) -> Result<(), Divergence> {
        self.engine.advance_to(at.time);
        let carried = self.engine.queued_names();
        if carried != at.queued {
            let names = |q: &[(String, Vec<Value>, Option<String>)]| {
                q.iter()
                    .map(|q| q.0.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let what = format!(
                "the queue at the reload differs: [{}] in the replay, [{}] in the journal",
                names(&carried),
                names(at.queued)
            );
            return Err(self.diverge(i, what, "(reload)", at.time, at.state));
        }
        match self.reload_engine(at.source_hash, at.mapping, at.time) {
            Ok(()) => {
                self.report.reloads += 1;
                let what = "the state mapped at the reload differs";
                self.check_state(i, what, "(reload)", at.time, at.state, Some(at.deadlines))
            }
            Err(what) => Err(self.diverge(i, what, "(reload)", at.time, at.state)),
        }
    }

    /// Replaces the engine by one running the version of content hash `hash` kept beside the
    /// journal, as the player did at the reload: the state mapped again with the recorded
    /// mapping, the queue carried over.
    fn reload_engine(&mut self, hash: &str, mapping: &str, time: Micros) -> Result<(), String> {
        let dir = self.kept.ok_or_else(|| {
            format!("a reload to version {hash}: the journal directory is needed to find its files")
        })?;
        let new = crate::reload::version::load_kept(dir, hash)?;
        let mapping = petrel_nets::reload::Mapping::parse(mapping)
            .map_err(|e| format!("the reload's mapping does not read: {e}"))?;
        let from = crate::reload::running_state(&self.engine);
        let mapped = petrel_nets::reload::map_state(self.project, &from, &new, &mapping)
            .map_err(|r| format!("the reload does not map again: {}", r.reasons.join("; ")))?;
        let new = crate::reload::version::leak(new);
        let queued = self.engine.take_queue();
        let stats = self.engine.stats();
        let mut next = Engine::new(new);
        next.adopt(
            time,
            &mapped.state,
            &mapped.deadlines,
            mapped.net_args,
            stats,
            queued,
            &mapping.nets,
        )
        .ok_or_else(|| "the mapped state is not of the new version's size".to_string())?;
        self.run_version(new, next);
        Ok(())
    }

    /// Runs version `project` from now on, on `engine`.
    fn run_version(&mut self, project: &'p CompiledProject, engine: Engine<'p>) {
        self.project = project;
        self.engine = engine;
        self.log = StepRecord::new(project);
    }

    /// Starts the replay at the journal's reload `k`, on the version it brought, from its
    /// recorded state (restored like a checkpoint's).
    fn start_at_reload(&mut self, k: usize, at: ReloadAt) -> Result<(), Divergence> {
        let at_reload = |what: String| Divergence {
            kind: DivergenceKind::Replay,
            entry: k,
            time: at.time,
            event: "(reload)".into(),
            what,
            recorded: Vec::new(),
            replayed: Vec::new(),
        };
        let loaded = match self.kept {
            Some(dir) => crate::reload::version::load_kept(dir, at.source_hash),
            None => Err("the journal directory is needed to find the reloaded version".into()),
        };
        let project = crate::reload::version::leak(loaded.map_err(at_reload)?);
        let mut engine = Engine::new(project);
        let renamed = petrel_nets::reload::Mapping::parse(at.mapping)
            .map(|m| m.nets)
            .unwrap_or_default();
        // The events queued at the reload were received before it.
        let stats = crate::engine::Stats {
            received: at.queued.len() as u64,
            ..Default::default()
        };
        let args = vec![Vec::new(); project.nets.len()];
        let adopted = engine.adopt(
            at.time,
            at.state,
            at.deadlines,
            args,
            stats,
            at.queued.to_vec(),
            &renamed,
        );
        self.run_version(project, engine);
        if adopted.is_none() {
            return Err(at_reload(
                "the reload's state is not of its version's size".into(),
            ));
        }
        self.report.last_time = at.time;
        self.report.reloads += 1;
        Ok(())
    }
}

/// What a reload entry holds that the replay needs ([`Entry::Reload`]).
struct ReloadAt<'e> {
    time: Micros,
    source_hash: &'e str,
    mapping: &'e str,
    /// The state recorded after the reload (mapped onto the new version).
    state: &'e [u64],
    deadlines: &'e [Option<u64>],
    /// The events queued at the reload, carried over to the new version.
    queued: &'e [(String, Vec<Value>, Option<String>)],
}

impl<'e> ReloadAt<'e> {
    /// The reload `entry` holds, if it is one.
    fn of(entry: &'e Entry) -> Option<Self> {
        match entry {
            Entry::Reload {
                time,
                source_hash,
                mapping,
                state,
                deadlines,
                queued,
                ..
            } => Some(ReloadAt {
                time: *time,
                source_hash,
                mapping,
                state,
                deadlines,
                queued,
            }),
            _ => None,
        }
    }
}

/// What is inconsistent about entry `i` of a journal, given its first header and the previous
/// entry with a time: a header that disagrees with the first one, or time going backwards.
fn inconsistency<'e>(
    entry: &'e Entry,
    first: &mut Option<(&'e str, u64, Option<u64>)>,
    previous: &mut Option<(usize, u64)>,
    i: usize,
) -> Option<String> {
    if let Entry::Header {
        version,
        vehicle,
        digest,
        started_unix_ms,
        ..
    } = entry
    {
        // Before format 2, a resumed segment's header held the resume's time, not the
        // mission's start: only the vehicle and the project can be compared.
        let start = (*version >= 2).then_some(*started_unix_ms);
        let Some((v, d, s)) = *first else {
            *first = Some((vehicle, *digest, start));
            return None;
        };
        if vehicle != v {
            return Some(format!(
                "a segment of vehicle `{vehicle}` in the journal of vehicle `{v}`: segments of two journals were put together"
            ));
        }
        if *digest != d {
            return Some(
                "a segment recorded with another project in this journal: segments of two journals were put together"
                    .into(),
            );
        }
        if let (Some(a), Some(b)) = (start, s) {
            if a != b {
                return Some(format!(
                    "a segment of another mission of vehicle `{v}` (started at {a} ms since the Unix epoch, not {b}): segments of two journals were put together"
                ));
            }
        }
    }
    let t = entry.time()?;
    if let Some((j, before)) = *previous {
        if t < before {
            return Some(format!(
                "time goes backwards: {:.6} s after {:.6} s at entry {j} (segments spliced from another journal?)",
                t as f64 / 1e6,
                before as f64 / 1e6
            ));
        }
    }
    *previous = Some((i, t));
    None
}
