//! `petrel reload`: a new version of the project for a running player (docs/reload.md).

use crate::common::{require_clean, Outcome, Scope};
use petrel_ipc::{ReloadAnswer, ReloadRequest};
use petrel_nets::plural::count;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// `petrel reload`.
#[derive(clap::Args)]
pub struct ReloadArgs {
    /// The new version's project directory (checked here, then read and checked again by the
    /// player, which runs on this computer).
    dir: PathBuf,
    /// The vehicle; default: the new version's project name.
    #[arg(long)]
    vehicle: Option<String>,
    /// Say what would happen (the mapping and the verification), swap nothing.
    #[arg(long)]
    dry_run: bool,
    /// The mapping file (TOML: renames, and what to do with marked places, active nets and
    /// running timers the new version no longer has).
    #[arg(long, value_name = "FILE")]
    mapping: Option<PathBuf>,
    /// How long to wait for the player's answer, in seconds.
    #[arg(long, default_value_t = 60.0)]
    timeout: f64,
    /// Output format: text for people, json for tools.
    #[arg(long, default_value = "text")]
    format: String,
}

/// Sends the new version to the running player and prints its answer: exit 0 accepted, 1
/// refused, 2 usage or I/O (no player, no answer, unreadable files).
pub fn reload(a: ReloadArgs) -> Outcome {
    if !(a.timeout.is_finite() && a.timeout >= 0.0) {
        return Outcome::Usage(format!(
            "--timeout takes a number of seconds, not {}",
            a.timeout
        ));
    }
    if a.format != "text" && a.format != "json" {
        return Outcome::Usage(format!("unknown format `{}`: use text or json", a.format));
    }
    // The player reads the directory itself: it needs a path that does not depend on ours.
    let dir = match a.dir.canonicalize() {
        Ok(d) => d,
        Err(e) => return Outcome::Usage(format!("cannot read {}: {e}", a.dir.display())),
    };
    let mapping = match &a.mapping {
        None => String::new(),
        Some(path) => {
            let text = match std::fs::read_to_string(path) {
                Ok(t) => t,
                Err(e) => return Outcome::Usage(format!("cannot read {}: {e}", path.display())),
            };
            if let Err(e) = petrel_nets::reload::Mapping::parse(&text) {
                return Outcome::Usage(format!("{}:{e}", path.display()));
            }
            text
        }
    };
    let checked = match require_clean(&dir, Scope::default(), "reload") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let Some(c) = checked.compiled.as_ref() else {
        return Outcome::Usage("the project did not compile".into());
    };
    let files = checked.loaded.source_files();
    let source_hash =
        petrel_nets::reload::source_digest(files.iter().map(|(p, t)| (p.as_str(), t.as_str())));
    let v = match crate::common::vehicle_of(c, a.vehicle) {
        Ok(v) => v,
        Err(o) => return o,
    };
    let role = match petrel_ipc::Role::tool(&format!("reload{}", std::process::id())) {
        Ok(r) => r,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let me = match petrel_ipc::Participant::join(&v, role) {
        Ok(m) => m,
        Err(e) => return Outcome::Usage(format!("cannot join vehicle `{}`: {e}", v.name())),
    };
    // Listening before asking, so that the answer cannot come before the ear.
    let answers = match me.reload_answer_subscriber() {
        Ok(s) => s,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let requester = match me.reload_requester() {
        Ok(s) => s,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let request = ReloadRequest {
        dir: dir.display().to_string(),
        source_hash: source_hash.clone(),
        mapping,
        dry_run: a.dry_run,
    };
    let sent = match requester.send(&request) {
        Ok(s) => s,
        Err(e) => {
            return Outcome::Usage(format!(
                "cannot reach the player of vehicle `{}`: {e}",
                v.name()
            ))
        }
    };
    let me_id = requester.sender_id();
    let deadline = Instant::now() + Duration::from_secs_f64(a.timeout);
    let mut answer: Option<ReloadAnswer> = None;
    while answer.is_none() {
        if Instant::now() >= deadline {
            return Outcome::Usage(format!(
                "no answer from the player of vehicle `{}` in {} s (is it running? a large project takes longer to verify: --timeout)",
                v.name(),
                a.timeout
            ));
        }
        let drained = answers.drain(|r| {
            if let Ok(rcv) = r {
                if rcv.origin.as_str() == "player"
                    && rcv.msg.request_sender == me_id
                    && rcv.msg.request_seq == sent.seq
                {
                    answer = Some(rcv.msg);
                }
            }
        });
        if let Err(e) = drained {
            return Outcome::Usage(format!("cannot read the player's answer: {e}"));
        }
        if answer.is_none() {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    let Some(answer) = answer else {
        return Outcome::Usage("no answer".into());
    };
    if a.format == "json" {
        let doc = serde_json::json!({
            "accepted": answer.accepted,
            "dry_run": answer.dry_run,
            "dir": answer.dir,
            "source_hash": answer.source_hash,
            "step": answer.step,
            "summary": answer.summary,
            "reasons": answer.reasons,
            "trace": answer.trace,
            "states": answer.states,
            "millis": answer.millis,
        });
        crate::common::out(&format!("{doc}\n"));
    } else {
        crate::common::out(&render(&answer));
    }
    if answer.accepted {
        Outcome::Clean
    } else {
        Outcome::Errors
    }
}

/// The answer for people.
fn render(a: &ReloadAnswer) -> String {
    let mut out = String::new();
    let verdict = match (a.accepted, a.dry_run) {
        (true, false) => format!(
            "reload accepted: version {} runs from step {} on ({} verified from the mapped state, {} ms)",
            a.source_hash,
            a.step,
            count(a.states, "state"),
            a.millis
        ),
        (true, true) => format!(
            "dry run: the reload would be accepted ({} verified from the mapped state, {} ms); nothing swapped",
            count(a.states, "state"),
            a.millis
        ),
        (false, dry) => format!(
            "{}reload refused: the mission goes on unchanged ({} ms)",
            if dry { "dry run: " } else { "" },
            a.millis
        ),
    };
    out.push_str(&verdict);
    out.push('\n');
    if !a.summary.is_empty() {
        out.push_str("mapping:\n");
        for l in &a.summary {
            out.push_str(&format!("  {l}\n"));
        }
    }
    if !a.reasons.is_empty() {
        out.push_str("why:\n");
        for l in &a.reasons {
            out.push_str(&format!("  {l}\n"));
        }
    }
    out
}
