//! `petrel monitor`: the web monitor of a running mission, or the replay of a recorded one.
//!
//! One page, embedded in the binary (no build step, no network), served on 127.0.0.1 by
//! default. The nets are drawn once, when the monitor starts, by Graphviz from `petrel dot`'s
//! text ([`layout`]); the page colours that drawing as the marking changes.
//!
//! - Live ([`live`]): a thread joins the vehicle as a tool and reads what the player already
//!   publishes (its marking deltas and its heartbeat), so the player does no more work for a
//!   monitor than for none; it keeps the current marking, the latest steps and the status, and
//!   pushes each change to every open page over Server-Sent Events. A page that falls behind
//!   gets the latest marking instead of the steps it missed, and says so.
//! - Replay ([`replay`]): the journal's steps, each with its state, for the page's time slider;
//!   the replay's check of every recorded state gives the divergence alarms.
//! - Operator actions ([`operator`]): with `--operator` only, and only with the token printed at
//!   start, the page sends events as `petrel send` does.

mod layout;
mod live;
mod names;
mod operator;
mod replay;
mod server;

use crate::common::{require_clean, Outcome, Scope};
use std::net::SocketAddr;
use std::path::PathBuf;

/// `petrel monitor`.
#[derive(clap::Args)]
pub struct MonitorArgs {
    /// The project directory (for a replay, default: the directory the journal recorded).
    dir: Option<PathBuf>,
    /// The vehicle to follow; default: the project's name.
    #[arg(long, conflicts_with = "journal")]
    vehicle: Option<String>,
    /// Replay this journal (a directory of segments) instead of following a vehicle.
    #[arg(long)]
    journal: Option<PathBuf>,
    /// The address to serve the page on. The default serves this computer only; another
    /// address exposes the mission's state to whoever reaches it (see docs/monitor.md).
    #[arg(long, default_value = "127.0.0.1:7878")]
    listen: SocketAddr,
    /// Let the page send events to the player, with the token printed at start.
    #[arg(long, conflicts_with = "journal")]
    operator: bool,
    /// Stop after this many seconds (for tests and demos).
    #[arg(long, value_parser = crate::common::seconds)]
    run_for: Option<f64>,
}

/// Runs the monitor until Ctrl-C (or `--run-for`).
pub fn monitor(a: MonitorArgs) -> Outcome {
    let journal_entries = match &a.journal {
        Some(j) => match replay::read(j) {
            Ok(r) => Some(r),
            Err(o) => return o,
        },
        None => None,
    };
    let dir = match (&a.dir, &journal_entries) {
        (Some(d), _) => d.clone(),
        (None, Some(r)) => r.project_dir.clone(),
        (None, None) => {
            return Outcome::Usage(
                "give the project directory (or --journal DIR to replay a recorded mission)".into(),
            )
        }
    };
    let checked = match require_clean(&dir, Scope::default(), "monitor") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let Some(compiled) = checked.compiled else {
        return Outcome::Usage("the project did not compile".into());
    };
    let drawing = match layout::draw(&checked.loaded.project) {
        Ok(d) => d,
        Err(e) => return Outcome::Usage(e),
    };
    let names = names::Names::new(&compiled);
    let mode = match journal_entries {
        Some(read) => match replay::timeline(&compiled, &names, read) {
            Ok(t) => server::Mode::Replay(t),
            Err(o) => return o,
        },
        None => {
            let vehicle = match crate::common::vehicle_of(&compiled, a.vehicle.clone()) {
                Ok(v) => v,
                Err(o) => return o,
            };
            server::Mode::Live {
                vehicle: Box::new(vehicle),
                operator: a.operator,
            }
        }
    };
    let run_for = a
        .run_for
        .and_then(|s| std::time::Duration::try_from_secs_f64(s).ok());
    server::serve(compiled, names, drawing, mode, a.listen, run_for)
}
