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
use petrel_nets::compiled::CompiledProject;
use petrel_nets::semantics::Layout;

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

/// Replaces `engine` (running `project`) by one running the version of content hash `hash`
/// kept beside the journal in `kept`, as the player did at the reload: the state mapped
/// again with the recorded mapping, the queue carried over.
fn reload_engine<'p>(
    project: &'p CompiledProject,
    engine: &mut Engine<'p>,
    kept: Option<&std::path::Path>,
    hash: &str,
    mapping: &str,
    time: Micros,
) -> Result<&'p CompiledProject, String> {
    let dir = kept.ok_or_else(|| {
        format!("a reload to version {hash}: the journal directory is needed to find its files")
    })?;
    let new = crate::reload::load_kept(dir, hash)?;
    let mapping = petrel_nets::reload::Mapping::parse(mapping)
        .map_err(|e| format!("the reload's mapping does not read: {e}"))?;
    let from = petrel_nets::reload::OldState {
        state: engine.state(),
        deadlines: engine.deadlines(),
        net_args: engine.all_net_args(),
    };
    let mapped = petrel_nets::reload::map_state(project, &from, &new, &mapping)
        .map_err(|r| format!("the reload does not map again: {}", r.reasons.join("; ")))?;
    let new = crate::reload::leak(new);
    let queued = engine.take_queue();
    let stats = engine.stats();
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
    *engine = next;
    Ok(new)
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
/// read from the journal directory `kept` ([`crate::reload::load_kept`]), the state is mapped
/// again and checked against the recorded one, and the replay goes on with the new version.
/// With `from_last_reload`, the replay starts at the journal's last reload, on the version it
/// brought (its recorded state restored like a checkpoint's): for `--resume`, and for a
/// replay whose project directory holds a later version than the mission's first.
pub fn replay_in<'p>(
    project: &'p CompiledProject,
    entries: &[Entry],
    until: Option<Micros>,
    kept: Option<&std::path::Path>,
    from_last_reload: bool,
) -> (Engine<'p>, ReplayReport) {
    let mut project = project;
    let mut engine = Engine::new(project);
    let mut report = ReplayReport::default();
    let mut skip_to = 0;
    if let (true, Some(k)) = (from_last_reload, last_reload(entries)) {
        if let Entry::Reload {
            time,
            source_hash,
            mapping,
            state,
            deadlines,
            queued,
            ..
        } = &entries[k]
        {
            let loaded = match kept {
                Some(dir) => crate::reload::load_kept(dir, source_hash),
                None => Err("the journal directory is needed to find the reloaded version".into()),
            };
            match loaded {
                Ok(p) => {
                    project = crate::reload::leak(p);
                    engine = Engine::new(project);
                    let renamed = petrel_nets::reload::Mapping::parse(mapping)
                        .map(|m| m.nets)
                        .unwrap_or_default();
                    // The events queued at the reload were received before it.
                    let stats = crate::engine::Stats {
                        received: queued.len() as u64,
                        ..Default::default()
                    };
                    let args = vec![Vec::new(); project.nets.len()];
                    let adopted = engine.adopt(
                        *time,
                        state,
                        deadlines,
                        args,
                        stats,
                        queued.clone(),
                        &renamed,
                    );
                    if adopted.is_none() {
                        report.divergence = Some(Divergence {
                            kind: DivergenceKind::Replay,
                            entry: k,
                            time: *time,
                            event: "(reload)".into(),
                            what: "the reload's state is not of its version's size".into(),
                            recorded: Vec::new(),
                            replayed: Vec::new(),
                        });
                        return (engine, report);
                    }
                    report.last_time = *time;
                    report.reloads += 1;
                    skip_to = k + 1;
                }
                Err(what) => {
                    report.divergence = Some(Divergence {
                        kind: DivergenceKind::Replay,
                        entry: k,
                        time: *time,
                        event: "(reload)".into(),
                        what,
                        recorded: Vec::new(),
                        replayed: Vec::new(),
                    });
                    return (engine, report);
                }
            }
        }
    }
    let mut log = StepRecord::new(project);
    // After a gap, the next checkpoint is where the replay starts over.
    let mut after_gap = false;
    // The journal's first header, and the time of the last entry that had one.
    let mut first: Option<(&str, u64, Option<u64>)> = None;
    let mut previous: Option<(usize, u64)> = None;
    for (i, entry) in entries.iter().enumerate() {
        // Headers are checked all the same: the journal holds together or not.
        if i < skip_to && !matches!(entry, Entry::Header { .. }) {
            continue;
        }
        if let (Some(limit), Some(t)) = (until, entry.time()) {
            if t > limit {
                report.stopped_early = true;
                break;
            }
        }
        if let Some(what) = inconsistency(entry, &mut first, &mut previous, i) {
            report.divergence = Some(Divergence {
                kind: DivergenceKind::Journal,
                entry: i,
                time: entry.time().unwrap_or(report.last_time),
                event: "(journal)".into(),
                what,
                recorded: Vec::new(),
                replayed: describe(engine.project(), engine.layout(), engine.state()),
            });
            break;
        }
        report.entries = i + 1;
        if let Some(t) = entry.time() {
            report.last_time = t;
        }
        let diverge =
            |engine: &Engine, what: String, event: &str, time: u64, recorded: &[u64]| Divergence {
                kind: DivergenceKind::Replay,
                entry: i,
                time,
                event: event.to_string(),
                what,
                recorded: describe(engine.project(), engine.layout(), recorded),
                replayed: describe(engine.project(), engine.layout(), engine.state()),
            };
        match entry {
            Entry::Header { .. } => {}
            // Refused live and counted so (received and refused): the counters of a resumed
            // engine account for it too.
            Entry::Refused { .. } => engine.count_refused(),
            Entry::ProgramStopped { .. } => {}
            Entry::Reload {
                time,
                source_hash,
                mapping,
                state,
                deadlines,
                queued,
                ..
            } => {
                engine.advance_to(*time);
                let carried = engine.queued_names();
                if &carried != queued {
                    report.divergence = Some(diverge(
                        &engine,
                        format!(
                            "the queue at the reload differs: [{}] in the replay, [{}] in the journal",
                            carried.iter().map(|q| q.0.as_str()).collect::<Vec<_>>().join(", "),
                            queued.iter().map(|q| q.0.as_str()).collect::<Vec<_>>().join(", ")
                        ),
                        "(reload)",
                        *time,
                        state,
                    ));
                    break;
                }
                match reload_engine(project, &mut engine, kept, source_hash, mapping, *time) {
                    Ok(next) => {
                        project = next;
                        log = StepRecord::new(project);
                        report.reloads += 1;
                        if engine.state() != state.as_slice()
                            || engine.deadlines() != deadlines.as_slice()
                        {
                            report.divergence = Some(diverge(
                                &engine,
                                "the state mapped at the reload differs".into(),
                                "(reload)",
                                *time,
                                state,
                            ));
                            break;
                        }
                    }
                    Err(what) => {
                        report.divergence = Some(diverge(&engine, what, "(reload)", *time, state));
                        break;
                    }
                }
            }
            // The player came back at this mission time: timers whose deadline passed while it
            // was down expire now, as they did live.
            Entry::Resume { time } => engine.advance_to(*time),
            Entry::Gap { lost, .. } => {
                report.gaps += 1;
                report.lost += lost;
                after_gap = true;
            }
            Entry::Checkpoint {
                time,
                state,
                deadlines,
            } => {
                if after_gap {
                    after_gap = false;
                    if !engine.restore(*time, state, deadlines) {
                        report.divergence = Some(diverge(
                            &engine,
                            "the checkpoint is not of this project's size".into(),
                            "(checkpoint)",
                            *time,
                            state,
                        ));
                        break;
                    }
                } else if engine.state() != state.as_slice()
                    || engine.deadlines() != deadlines.as_slice()
                {
                    report.divergence = Some(diverge(
                        &engine,
                        "the state at the checkpoint differs".into(),
                        "(checkpoint)",
                        *time,
                        state,
                    ));
                    break;
                }
            }
            Entry::Start { time, state } => {
                engine.start(*time, &mut log);
                log.clear();
                if engine.state() != state.as_slice() {
                    report.divergence = Some(diverge(
                        &engine,
                        "the initial state differs".into(),
                        "(start)",
                        *time,
                        state,
                    ));
                    break;
                }
            }
            Entry::Submit {
                time,
                event,
                params,
                ..
            } => {
                engine.advance_to(*time);
                let params = params.clone();
                if let Err(r) = engine.submit_named(event, params) {
                    report.divergence = Some(Divergence {
                        kind: DivergenceKind::Replay,
                        entry: i,
                        time: *time,
                        event: event.clone(),
                        what: format!("the engine refuses the recorded event: {r}"),
                        recorded: Vec::new(),
                        replayed: describe(engine.project(), engine.layout(), engine.state()),
                    });
                    break;
                }
            }
            Entry::Step {
                time,
                event,
                outcome,
                fired,
                state,
                ..
            } => {
                engine.advance_to(*time);
                log.clear();
                let Some(step) = engine.step(&mut log) else {
                    report.divergence = Some(diverge(
                        &engine,
                        "the journal has a step here, the replay has no event left to take".into(),
                        event,
                        *time,
                        state,
                    ));
                    break;
                };
                report.steps += 1;
                let taken = &project.events[step.event as usize].name;
                let replayed_outcome = outcome_name(step.outcome);
                let found_fired = log.fired_names();
                let what = if taken != event {
                    Some(format!("the replay took `{taken}`, the journal `{event}`"))
                } else if replayed_outcome != outcome {
                    Some(format!(
                        "the event was {replayed_outcome} in the replay, {outcome} in the journal"
                    ))
                } else if &found_fired != fired {
                    Some(format!(
                        "fired [{}] in the replay, [{}] in the journal",
                        found_fired.join(", "),
                        fired.join(", ")
                    ))
                } else if engine.state() != state.as_slice() {
                    Some("the marking after the step differs".to_string())
                } else {
                    None
                };
                if let Some(what) = what {
                    report.divergence = Some(diverge(&engine, what, event, *time, state));
                    break;
                }
            }
        }
    }
    (engine, report)
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
