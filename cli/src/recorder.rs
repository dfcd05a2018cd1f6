//! The flight recorder's commands: `replay` and `journal show`.

use crate::common::{compiled, out, Outcome};
use petrel_nets::plural::count;
use std::path::{Path, PathBuf};

/// `petrel replay`.
#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The journal directory (or one segment file).
    journal: PathBuf,
    /// The project (default: the directory recorded in the journal).
    #[arg(long)]
    project: Option<PathBuf>,
    /// Stop at this mission time (seconds) and print the state there.
    #[arg(long, value_parser = crate::common::seconds)]
    until: Option<f64>,
}

/// `petrel journal ...`.
#[derive(clap::Subcommand)]
pub enum JournalCommand {
    /// Print every entry.
    Show {
        /// The journal directory (or one segment file).
        journal: PathBuf,
        /// Output format: text, json (one document a line) or csv.
        #[arg(long, default_value = "text")]
        format: String,
    },
}

/// Runs a `petrel journal` subcommand.
pub fn journal(c: JournalCommand) -> Outcome {
    match c {
        JournalCommand::Show { journal, format } => journal_show(&journal, &format),
    }
}

/// Reads a journal; a torn last record (a crash while writing it) is said and dropped, and space
/// reserved but not yet written (a running player's) is said.
fn read(journal: &Path) -> Result<petrel_player::journal::JournalRead, Outcome> {
    let read =
        petrel_player::journal::read_journal(journal).map_err(|e| Outcome::Usage(e.to_string()))?;
    match &read.torn {
        Some(t) if read.unwritten => eprintln!(
            "note: the journal ends in zeros, space its player reserved and has not written yet (the player still runs, or was stopped without closing it; or a power loss before the data reached the disk): every record before them was read ({t})"
        ),
        Some(t) => eprintln!(
            "warning: the last record is torn (a crash while writing it): {t}; it is dropped"
        ),
        None => {}
    }
    Ok(read)
}

/// Replays a journal through the engine and checks every recorded marking.
pub fn replay(a: ReplayArgs) -> Outcome {
    let (journal, project_dir, until) = (&a.journal, a.project.as_deref(), a.until);
    use petrel_player::journal::Entry;
    let read = match read(journal) {
        Ok(r) => r,
        Err(o) => return o,
    };
    let (recorded_dir, digest) = match read.entries.first() {
        Some(Entry::Header {
            project_dir,
            digest,
            ..
        }) => (PathBuf::from(project_dir), *digest),
        _ => {
            return Outcome::Usage(format!(
                "{} does not start with a journal header",
                journal.display()
            ))
        }
    };
    let dir = project_dir.map(Path::to_path_buf).unwrap_or(recorded_dir);
    let c = match compiled(&dir, "replay") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let reloaded = petrel_player::replay::last_reload(&read.entries).is_some();
    let from_last_reload = petrel_player::journal::project_digest(&c) != digest && reloaded;
    if from_last_reload {
        eprintln!(
            "note: {} is not the version the mission started with; the journal holds reloads: replaying from its last reload, on the version kept beside the journal (give the first version's directory to replay the whole mission)",
            dir.display()
        );
    } else if petrel_player::journal::project_digest(&c) != digest {
        eprintln!(
            "error: {} is not the project this journal recorded (its nets or manifest changed): replay would not mean anything",
            dir.display()
        );
        return Outcome::Errors;
    }
    // `seconds` bounds it: the product is a whole number of microseconds a u64 holds.
    let until_us = until.map(|s| (s * 1e6).round() as u64);
    let (engine, r) = petrel_player::replay::replay_in(
        &c,
        &read.entries,
        until_us,
        Some(journal.as_path()),
        from_last_reload,
    );
    if let Some(d) = &r.divergence {
        if d.kind == petrel_player::replay::DivergenceKind::Journal {
            eprintln!(
                "error: the journal does not hold together at entry {} (t = {:.6} s): {}",
                d.entry,
                d.time as f64 / 1e6,
                d.what
            );
            return Outcome::Errors;
        }
        eprintln!(
            "divergence at entry {} (t = {:.6} s), event `{}`: {}\n  recorded: {}\n  replayed: {}",
            d.entry,
            d.time as f64 / 1e6,
            d.event,
            d.what,
            d.recorded.join(" "),
            d.replayed.join(" ")
        );
        return Outcome::Errors;
    }
    if let Some(c) = &read.corrupt {
        eprintln!(
            "error: the journal is damaged at {c}; the {} before it replay to the recorded markings",
            count(r.entries, "entry")
        );
        return Outcome::Errors;
    }
    let marking: Vec<String> = engine
        .marking()
        .into_iter()
        .map(|(n, p)| format!("{n}{{{}}}", p.join(", ")))
        .collect();
    if r.gaps > 0 {
        eprintln!(
            "warning: the flight recorder dropped {} (in {}) it could not write; the replay went on from the checkpoint after each gap",
            count(r.lost, "entry"),
            count(r.gaps, "gap")
        );
    }
    out(&format!(
        "replayed {}, {}{}: every recorded marking reproduced{}{}\nstate at t = {:.6} s: {}\n",
        count(r.entries, "entry"),
        count(r.steps, "step"),
        match r.reloads {
            0 => String::new(),
            n => format!(" across {}", count(n, "reload")),
        },
        if r.gaps > 0 {
            " (from a checkpoint after each gap)"
        } else {
            ""
        },
        if r.stopped_early {
            " (stopped at --until)"
        } else {
            ""
        },
        match until {
            Some(u) if r.stopped_early => u,
            _ => r.last_time as f64 / 1e6,
        },
        marking.join(" ")
    ));
    Outcome::Clean
}

fn journal_show(journal: &Path, format: &str) -> Outcome {
    use petrel_player::journal::Entry;
    let read = match read(journal) {
        Ok(r) => r,
        Err(o) => return o,
    };
    let wire = |params: &[petrel_nets::compiled::Value]| -> Vec<String> {
        params.iter().map(|v| v.literal()).collect()
    };
    let csv_field = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    let mut text = String::new();
    if format == "csv" {
        text.push_str("index,time_s,kind,event,params,origin,outcome,fired,actions\n");
    } else if format != "text" && format != "json" {
        return Outcome::Usage(format!("unknown format `{format}`: use text, json or csv"));
    }
    for (i, e) in read.entries.iter().enumerate() {
        let t = e.time().map(|t| t as f64 / 1e6);
        let (kind, event, params, origin, outcome, fired, actions) = match e {
            Entry::Header {
                project, vehicle, ..
            } => (
                "header",
                project.clone(),
                vec![],
                vehicle.clone(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Start { .. } => (
                "start",
                String::new(),
                vec![],
                String::new(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Resume { .. } => (
                "resume",
                String::new(),
                vec![],
                String::new(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Submit {
                event,
                params,
                origin,
                seq,
                ..
            } => (
                "submit",
                event.clone(),
                wire(params),
                format!("{origin}#{seq}"),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Refused {
                what,
                reason,
                origin,
                ..
            } => (
                "refused",
                what.clone(),
                vec![],
                origin.clone(),
                reason.clone(),
                vec![],
                vec![],
            ),
            Entry::Gap { lost, reason, .. } => (
                "gap",
                String::new(),
                vec![],
                String::new(),
                format!("{lost} entries lost: {reason}"),
                vec![],
                vec![],
            ),
            Entry::Reload {
                dir, source_hash, ..
            } => (
                "reload",
                source_hash.clone(),
                vec![],
                dir.clone(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::ProgramStopped { program, .. } => (
                "stopped",
                String::new(),
                vec![],
                format!("program/{program}"),
                "left in good order".to_string(),
                vec![],
                vec![],
            ),
            Entry::Checkpoint { .. } => (
                "checkpoint",
                String::new(),
                vec![],
                String::new(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Step {
                event,
                params,
                outcome,
                fired,
                actions,
                ..
            } => (
                "step",
                event.clone(),
                wire(params),
                String::new(),
                outcome.clone(),
                fired.clone(),
                actions.clone(),
            ),
        };
        match format {
            "json" => {
                let doc = serde_json::json!({
                    "index": i, "time": t, "kind": kind, "event": event, "params": params,
                    "origin": origin, "outcome": outcome, "fired": fired, "actions": actions,
                });
                text.push_str(&format!("{doc}\n"));
            }
            "csv" => text.push_str(&format!(
                "{i},{},{kind},{},{},{},{},{},{}\n",
                t.map(|t| format!("{t:.6}")).unwrap_or_default(),
                csv_field(&event),
                csv_field(&params.join(", ")),
                csv_field(&origin),
                csv_field(&outcome),
                csv_field(&fired.join(" ")),
                csv_field(&actions.join("; "))
            )),
            _ => {
                let time = t
                    .map(|t| format!("{t:>12.6}"))
                    .unwrap_or_else(|| " ".repeat(12));
                let args = if params.is_empty() {
                    String::new()
                } else {
                    format!("({})", params.join(", "))
                };
                let mut line = format!("{i:>6} {time}  {kind:<7} {event}{args}");
                if !origin.is_empty() {
                    line.push_str(&format!("  from {origin}"));
                }
                if !outcome.is_empty() {
                    line.push_str(&format!("  [{outcome}]"));
                }
                if !fired.is_empty() {
                    line.push_str(&format!("  fired {}", fired.join(", ")));
                }
                if !actions.is_empty() {
                    line.push_str(&format!("  => {}", actions.join("; ")));
                }
                text.push_str(&line);
                text.push('\n');
            }
        }
    }
    out(&text);
    if let Some(c) = &read.corrupt {
        eprintln!("error: the journal is damaged at {c}");
        return Outcome::Errors;
    }
    Outcome::Clean
}
