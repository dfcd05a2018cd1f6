//! Replay of a recorded mission: the journal's states, one frame per step, for the page's time
//! slider, and the replay's check of every recorded state (`petrel replay`), whose divergences
//! the page shows as alarms.

use super::names::{self, Names};
use crate::common::Outcome;
use petrel_nets::compiled::CompiledProject;
use petrel_nets::semantics::Layout;
use petrel_player::journal::Entry;
use serde_json::{json, Value as Json};
use std::path::{Path, PathBuf};

/// A journal read, with the project it recorded.
pub struct Read {
    entries: Vec<Entry>,
    digest: u64,
    /// The project directory the journal names.
    pub project_dir: PathBuf,
    /// What the reading found wrong (a torn tail, damage).
    warnings: Vec<String>,
    corrupt: bool,
}

/// Reads journal `path` (a directory of segments, or one segment).
pub fn read(path: &Path) -> Result<Read, Outcome> {
    let read =
        petrel_player::journal::read_journal(path).map_err(|e| Outcome::Usage(e.to_string()))?;
    let mut warnings = Vec::new();
    // Space a running player reserved and has not written loses nothing: no warning.
    if let (Some(t), false) = (&read.torn, read.unwritten) {
        warnings.push(format!(
            "the last record is torn (a crash while writing it): {t}; it is left out"
        ));
    }
    if let Some(c) = &read.corrupt {
        warnings.push(format!(
            "the journal is damaged at {c}: the replay stops before it"
        ));
    }
    let (project_dir, digest) = match read.entries.first() {
        Some(Entry::Header {
            project_dir,
            digest,
            ..
        }) => (PathBuf::from(project_dir), *digest),
        _ => {
            return Err(Outcome::Usage(format!(
                "{} does not start with a journal header",
                path.display()
            )))
        }
    };
    Ok(Read {
        corrupt: read.corrupt.is_some(),
        entries: read.entries,
        digest,
        project_dir,
        warnings,
    })
}

/// The page's timeline of the journal: `frames` (each state the journal records, with the
/// step that led to it), `alarms` (divergences of the replay), `notes` (what else happened:
/// refused messages, resumes, gaps).
pub fn timeline(project: &CompiledProject, names: &Names, read: Read) -> Result<Json, Outcome> {
    if petrel_player::journal::project_digest(project) != read.digest {
        eprintln!(
            "error: this is not the project the journal recorded (its nets or manifest changed): give the right one"
        );
        return Err(Outcome::Errors);
    }
    let layout = Layout::new(project);
    let frame = |state: &[u64]| -> (Vec<String>, Vec<String>) {
        if state.len() != layout.words {
            return (Vec::new(), Vec::new());
        }
        let marked = petrel_player::record::marked_places(project, &layout, state)
            .iter()
            .map(|p| names::place_id(p))
            .collect();
        let active = project
            .nets
            .iter()
            .enumerate()
            .filter(|(n, _)| Layout::bit(state, layout.net_active[*n]))
            .map(|(_, net)| net.name.clone())
            .collect();
        (marked, active)
    };
    let mut frames = Vec::new();
    let mut notes = Vec::new();
    let mut step = 0u64;
    for e in &read.entries {
        match e {
            Entry::Start { time, state } => {
                let (marked, active) = frame(state);
                step = 0;
                frames.push(json!({
                    "type": "step", "step": 0, "time": *time as f64 / 1e6, "event": null,
                    "category": null, "params": [], "fired": [], "actions": ["mission start"],
                    "marked": marked, "active": active,
                }));
            }
            Entry::Step {
                time,
                event,
                params,
                fired,
                actions,
                state,
                ..
            } => {
                step += 1;
                let (marked, active) = frame(state);
                let mut f = names.step_json(
                    step,
                    *time,
                    Some(event),
                    params,
                    fired,
                    actions,
                    &[],
                    &[],
                    &[],
                    &[],
                );
                f["marked"] = json!(marked);
                f["active"] = json!(active);
                frames.push(f);
            }
            Entry::Checkpoint { time, state, .. } => {
                let (marked, active) = frame(state);
                frames.push(json!({
                    "type": "step", "step": step, "time": *time as f64 / 1e6, "event": null,
                    "category": null, "params": [], "fired": [],
                    "actions": ["checkpoint of the recorder after a gap"],
                    "marked": marked, "active": active,
                }));
            }
            Entry::Resume { time } => notes.push(json!({
                "time": *time as f64 / 1e6, "text": "the player resumed from the journal (after a crash)"
            })),
            Entry::Refused {
                time,
                what,
                reason,
                origin,
            } => notes.push(json!({
                "time": *time as f64 / 1e6, "text": format!("refused `{what}` from {origin}: {reason}")
            })),
            Entry::ProgramStopped { time, program } => notes.push(json!({
                "time": *time as f64 / 1e6, "text": format!("program {program} stopped in good order")
            })),
            Entry::Gap { time, lost, reason } => notes.push(json!({
                "time": *time as f64 / 1e6, "text": format!("the recorder dropped {lost} entries: {reason}")
            })),
            _ => {}
        }
    }
    let (_, report) = petrel_player::replay::replay(project, &read.entries, None);
    let mut alarms: Vec<Json> = read
        .warnings
        .iter()
        .map(|w| json!({"time": null, "text": w}))
        .collect();
    if let Some(d) = &report.divergence {
        alarms.push(json!({
            "time": d.time as f64 / 1e6,
            "text": format!(
                "divergence at entry {}, event `{}`: {} (recorded: {}; replayed: {})",
                d.entry, d.event, d.what, d.recorded.join(" "), d.replayed.join(" ")
            ),
        }));
    }
    Ok(json!({
        "frames": frames,
        "notes": notes,
        "alarms": alarms,
        "corrupt": read.corrupt,
    }))
}
