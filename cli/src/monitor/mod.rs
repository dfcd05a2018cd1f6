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
//! - Operator actions ([`operator`]): with `--operator` only, and only with the token shown at
//!   start (on a terminal, or in an owner-only `--token-file`, never in a log), the page sends
//!   events as `petrel send` does.
//! - Who may ask ([`gate`]: Host and Origin, the headers of every answer) and how many
//!   connections it holds ([`conns`]: a cap, idle ones shed first).

mod conns;
mod gate;
mod layout;
mod live;
mod names;
mod operator;
pub(crate) mod replay;
mod server;

use crate::common::{require_clean, Outcome, Scope};
use std::net::SocketAddr;
use std::path::PathBuf;

/// How long a connection may stay idle (no request being answered): also the time a client
/// has to send a request's head.
const IDLE: std::time::Duration = std::time::Duration::from_secs(10);

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
    /// Let the page send events to the player, with a token shown at start: on the terminal,
    /// or written to --token-file (never into a log).
    #[arg(long, conflicts_with = "journal")]
    operator: bool,
    /// With --operator: write the token to this file (created owner-only, removed at exit)
    /// instead of showing it; needed when the standard output is not a terminal.
    #[arg(long, value_name = "FILE", requires = "operator")]
    token_file: Option<PathBuf>,
    /// Also serve pages of this origin (http://ground-station:7878, a proxy's
    /// https://monitor.example): its host is answered to, its requests taken. Repeat it.
    /// Without it, only localhost, loopback addresses and the listen address.
    #[arg(long, value_name = "ORIGIN")]
    allow_origin: Vec<String>,
    /// The most connections held at once (fewer if the open-files limit is lower); past it,
    /// idle connections are closed first.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(16..))]
    max_connections: u32,
    /// With --journal: the data server's recording of the bus (`petrel bridge --record`), for a
    /// map whose positions come from signals (default: bus.log beside the journal directory,
    /// as `petrel up` leaves them, when there is one).
    #[arg(long, value_name = "FILE", requires = "journal")]
    bus_log: Option<PathBuf>,
    /// Stop after this many seconds (for tests and demos).
    #[arg(long, value_parser = crate::common::seconds)]
    run_for: Option<f64>,
}

/// Runs the monitor until Ctrl-C (or `--run-for`).
pub fn monitor(a: MonitorArgs) -> Outcome {
    use std::io::IsTerminal;
    let gate = match gate::Gate::new(&a.allow_origin) {
        Ok(g) => g,
        Err(e) => return Outcome::Usage(e),
    };
    if a.operator && a.token_file.is_none() && !std::io::stdout().is_terminal() {
        return Outcome::Usage(
            "--operator: the standard output is not a terminal, and the token is never written where others may read it (a log): give --token-file FILE (created owner-only)".into(),
        );
    }
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
    let scope = Scope {
        can: true,
        map: true,
        ..Scope::default()
    };
    let checked = match require_clean(&dir, scope, "monitor") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let Some(compiled) = checked.compiled else {
        return Outcome::Usage("the project did not compile".into());
    };
    let map = checked.map;
    let drawing = match layout::draw(&checked.loaded.project) {
        Ok(d) => d,
        Err(e) => return Outcome::Usage(e),
    };
    let names = names::Names::new(&compiled);
    let mode = match journal_entries {
        Some(read) => {
            let replay_map = match &map {
                Some(m) => {
                    let records = match replay_bus_log(&a, m) {
                        Ok(r) => r,
                        Err(e) => return Outcome::Usage(e),
                    };
                    let bus = match (&records, &checked.can) {
                        (Some(r), Some((_, dbc))) => {
                            Some(crate::map::record::BusLog { dbc, records: r })
                        }
                        _ => None,
                    };
                    let state = crate::map::record::replay(m, read.entries(), bus);
                    Some(Box::new((m.clone(), state)))
                }
                None => None,
            };
            match replay::timeline(&compiled, &names, read) {
                Ok(t) => server::Mode::Replay(t, replay_map),
                Err(o) => return o,
            }
        }
        None => {
            let vehicle = match crate::common::vehicle_of(&compiled, a.vehicle.clone()) {
                Ok(v) => v,
                Err(o) => return o,
            };
            server::Mode::Live {
                vehicle: Box::new(vehicle),
                sending: match (a.operator, &a.token_file) {
                    (false, _) => server::Sending::ReadOnly,
                    (true, None) => server::Sending::Terminal,
                    (true, Some(f)) => server::Sending::TokenFile(f.clone()),
                },
            }
        }
    };
    let run_for = a
        .run_for
        .and_then(|s| std::time::Duration::try_from_secs_f64(s).ok());
    let limits = conns::Limits::for_this_process(a.max_connections as usize, IDLE);
    let web = server::Web {
        listen: a.listen,
        gate,
        limits,
    };
    server::serve(compiled, names, drawing, (mode, map), web, run_for)
}

/// The bus recording a replay's map reads, when the map takes positions from signals:
/// `--bus-log`, or bus.log beside the journal directory (a `petrel up` run's).
fn replay_bus_log(
    a: &MonitorArgs,
    map: &crate::map::Map,
) -> Result<Option<Vec<petrel_can_bridge::log::LogRecord>>, String> {
    if map.signals().is_empty() {
        return Ok(None);
    }
    let path = match (&a.bus_log, &a.journal) {
        (Some(p), _) => p.clone(),
        (None, Some(j)) => match j.parent().map(|d| d.join("bus.log")) {
            Some(p) if p.is_file() => p,
            _ => {
                eprintln!(
                    "note: the map's positions from signals come from the bus's recording, and none is beside the journal (give --bus-log FILE)"
                );
                return Ok(None);
            }
        },
        (None, None) => return Ok(None),
    };
    crate::plot::read_bus_log(&path).map(Some)
}
