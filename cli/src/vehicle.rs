//! Commands that run a vehicle or talk to one: `play`, `send`, `status`.

use crate::common::{compiled, out, vehicle_of, wait_strategy, Outcome};
use petrel_nets::plural::{self, count};
use std::path::PathBuf;

/// `petrel play`.
#[derive(clap::Args)]
pub struct PlayArgs {
    /// The project directory.
    dir: PathBuf,
    /// The vehicle (its services are petrel/<vehicle>/...); default: the project's name.
    #[arg(long)]
    vehicle: Option<String>,
    /// How the reactor waits: block, spin, or spin-then-block:<microseconds>.
    #[arg(long, default_value = "block")]
    wait: String,
    /// Stop after this many seconds (for demos and tests).
    #[arg(long, value_parser = crate::common::seconds)]
    run_for: Option<f64>,
    /// The flight recorder's directory (default: journal/<vehicle>).
    #[arg(long)]
    journal: Option<PathBuf>,
    /// Run without a flight recorder.
    #[arg(long, conflicts_with_all = ["journal", "resume"])]
    no_journal: bool,
    /// When journal records reach the disk: record (every record, to the OS, before the
    /// player sleeps or within 1 ms under a spinning --wait, and always before the events
    /// are acknowledged), sync (the same, to the disk), or a period such as 50ms.
    #[arg(long, default_value = "record")]
    flush: String,
    /// Start a new journal segment past this many megabytes.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u64).range(1..))]
    rotate_mb: u64,
    /// While the journal cannot be written (a full disk), keep up to this many megabytes of
    /// its records in memory (the events they hold are not acknowledged until written); past
    /// it the recorder drops records, and the journal goes on from a checkpoint of the state.
    #[arg(long, default_value_t = 32.0)]
    journal_backlog_mb: f64,
    /// Restore the mission from the journal (after a crash) and carry on.
    #[arg(long)]
    resume: bool,
    /// Ground-station shadow: follow the vehicle player's steps, run no action, and raise an
    /// alarm the moment this copy's marking differs from the vehicle's.
    #[arg(long, conflicts_with_all = ["resume"])]
    shadow: bool,
    /// Share the vehicle's files with this Unix group (name or number), so that operator
    /// accounts in it can `petrel send` and `petrel status` (with PETREL_RUNTIME_DIR set to the
    /// vehicle's base directory): see docs/security.md. Default: PETREL_GROUP, or none.
    #[arg(long, value_name = "GROUP")]
    group: Option<String>,
}

/// Runs the player (or, with `--shadow`, the ground-station copy) until SIGINT or SIGTERM.
pub fn play(a: PlayArgs) -> Outcome {
    let dir = a.dir.as_path();
    let c = match compiled(dir, "play") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let strategy = match wait_strategy(&a.wait) {
        Ok(s) => s,
        Err(o) => return o,
    };
    let vehicle = a.vehicle.clone().unwrap_or_else(|| c.name.clone());
    let mut opts = petrel_player::runtime::PlayOptions::new(&vehicle);
    opts.wait = strategy;
    opts.project_dir = dir.display().to_string();
    opts.resume = a.resume;
    opts.group = a.group.clone();
    opts.rotate_bytes = a.rotate_mb.saturating_mul(1 << 20);
    if !(a.journal_backlog_mb.is_finite() && a.journal_backlog_mb >= 0.0) {
        return Outcome::Usage(format!(
            "--journal-backlog-mb takes a number of megabytes, not {}",
            a.journal_backlog_mb
        ));
    }
    opts.journal_backlog = (a.journal_backlog_mb * (1u64 << 20) as f64) as usize;
    opts.flush = match a.flush.parse() {
        Ok(f) => f,
        Err(e) => return Outcome::Usage(e),
    };
    if !a.no_journal && !a.shadow {
        opts.journal = Some(
            a.journal
                .clone()
                .unwrap_or_else(|| PathBuf::from("journal").join(&vehicle)),
        );
    }
    let run_for = a.run_for;
    if let Some(secs) = run_for {
        // `from_secs_f64` panics past what a Duration holds: ask, never assume.
        match std::time::Duration::try_from_secs_f64(secs) {
            Ok(d) => opts.run_for = Some(d),
            Err(_) => {
                return Outcome::Usage(format!("--run-for takes a number of seconds, not {secs}"))
            }
        }
    }
    if a.shadow {
        return match petrel_player::shadow::shadow(&c, &opts) {
            Ok(r) => {
                eprintln!(
                    "shadow stopped: {} followed, {} followed, {}",
                    count(r.steps, "vehicle step"),
                    count(r.reloads, "reload"),
                    count(r.alarms, "divergence alarm")
                );
                if r.alarms == 0 {
                    Outcome::Clean
                } else {
                    Outcome::Errors
                }
            }
            Err(e) => Outcome::Usage(e.to_string()),
        };
    }
    match petrel_player::runtime::play(&c, &opts) {
        Ok(r) => {
            let s = r.stats;
            let per_record = if r.journal_records > 0 {
                r.journal_busy.as_secs_f64() * 1e6 / r.journal_records as f64
            } else {
                0.0
            };
            eprintln!(
                "player stopped: {} ({} refused before the engine), {} received, {} processed, {} unused, {} refused; {} sent, {} held, {} failed; journal: {}, {:.1} us each, {}, {} lost{}",
                count(r.messages, "message"), r.bad_messages, count(s.received, "event"), s.processed, s.unused, s.refused,
                count(r.calls_sent, "call"), r.calls_held, r.calls_failed, count(r.journal_records, "record"), per_record,
                count(r.journal_failures, "failed write"), count(r.journal_lost, "entry"),
                if r.resumed_steps > 0 { format!("; resumed after {}", count(r.resumed_steps, "step")) } else { String::new() }
            );
            Outcome::Clean
        }
        Err(e) => Outcome::Usage(e.to_string()),
    }
}

/// Joins the project's vehicle as an operator tool (`tool/<what><pid>`), with a subscription
/// to the player's heartbeat (its status and acknowledgements).
fn join_as_tool(
    c: &petrel_nets::compiled::CompiledProject,
    vehicle: Option<String>,
    what: &str,
) -> Result<
    (
        petrel_ipc::Vehicle,
        petrel_ipc::Participant,
        petrel_ipc::HeartbeatSubscriber,
    ),
    Outcome,
> {
    let v = vehicle_of(c, vehicle)?;
    let role = petrel_ipc::Role::tool(&format!("{what}{}", std::process::id()))
        .map_err(|e| Outcome::Usage(e.to_string()))?;
    let me = petrel_ipc::Participant::join(&v, role)
        .map_err(|e| Outcome::Usage(format!("cannot join vehicle `{}`: {e}", v.name())))?;
    let beats = me
        .heartbeat_subscriber()
        .map_err(|e| Outcome::Usage(e.to_string()))?;
    Ok((v, me, beats))
}

/// `petrel send`.
#[derive(clap::Args)]
pub struct SendArgs {
    /// The project directory (the event is checked against it before sending).
    dir: PathBuf,
    /// The event, as in a script: `name` or `name(1, 2.5, "text", [1.0, 2.0])`.
    event: String,
    /// The vehicle; default: the project's name.
    #[arg(long)]
    vehicle: Option<String>,
    /// Send the event this many times, as fast as possible (a stress test of the vehicle).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    count: u64,
    /// How long to wait for the player's verdict on the events, in seconds.
    #[arg(long, default_value_t = 10.0)]
    timeout: f64,
}

/// Sends an event to a running player, as the operator, and waits for the player's verdict:
/// taken (and on the flight record), refused (and why), or not acknowledged. Exits 0 only when
/// every event was taken and is on record.
pub fn send(a: SendArgs) -> Outcome {
    let (event, vehicle, count) = (a.event.as_str(), a.vehicle, a.count);
    if !(a.timeout.is_finite() && a.timeout >= 0.0) {
        return Outcome::Usage(format!(
            "--timeout takes a number of seconds, not {}",
            a.timeout
        ));
    }
    let timeout = std::time::Duration::from_secs_f64(a.timeout);
    let c = match compiled(&a.dir, "send") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let (name, params) = match crate::common::operator_event(event, &c) {
        Ok(e) => e,
        Err(e) => return Outcome::Usage(e),
    };
    let (v, me, beats) = match join_as_tool(&c, vehicle, "send") {
        Ok(x) => x,
        Err(o) => return o,
    };
    let sender = match me.event_sender_sized() {
        Ok(s) => s,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let msg = petrel_ipc::EventMsg::new(name.clone(), params);
    let (mut delivered, mut refused, mut absent, mut last_seq) = (0u64, 0u64, 0u64, 0u64);
    for _ in 0..count {
        match sender.send(&msg) {
            Ok(sent) => {
                delivered += 1;
                last_seq = sent.seq;
            }
            Err(petrel_ipc::SendError::NoReceiver { .. }) => absent += 1,
            Err(e) if e.is_refusal() => refused += 1,
            Err(e) => return Outcome::Usage(format!("cannot send: {e}")),
        }
    }
    let origin = sender.origin().to_string();
    if absent > 0 {
        out(&format!(
            "sent {count} as {origin}: {delivered} delivered, {refused} refused, {absent} with no player\n"
        ));
        eprintln!(
            "no player is running for vehicle `{}`: start one with `petrel play`",
            v.name()
        );
        return Outcome::Errors;
    }
    // Shared memory dies with its process: stay until the player says (in its heartbeat) that
    // every event we delivered is settled, so nothing delivered is lost when we exit.
    let heard = if delivered > 0 {
        petrel_ipc::wait_acknowledged(&beats, sender.sender_id(), last_seq, timeout)
    } else {
        petrel_ipc::Acknowledgement::default()
    };
    out(&format!(
        "sent {count} as {origin}: {delivered} delivered, {refused} refused (player's buffer full), {absent} with no player\n"
    ));
    let verdict = Verdict::of(&heard, delivered);
    out(&verdict.text(&origin, &name));
    let mut safe = refused == 0 && verdict.is_clean();
    if verdict.not_on_record > 0 {
        let why = match heard.recorder.state {
            petrel_ipc::RecorderState::Failing | petrel_ipc::RecorderState::Dropping => format!(
                "the flight recorder is {} ({})",
                heard.recorder.state.as_str(),
                heard.recorder.reason
            ),
            _ => "the flight recorder had not written them".to_string(),
        };
        eprintln!(
            "taken by the player but not on record: {} ({why}); they would not survive a crash of the player",
            plural::count(verdict.not_on_record, "event")
        );
    }
    if verdict.unacknowledged > 0 {
        eprintln!(
            "the player did not acknowledge {} within {:.1} s: they may be lost",
            plural::count(verdict.unacknowledged, "event"),
            timeout.as_secs_f64()
        );
    }
    if verdict.refused > 0 {
        eprintln!(
            "the player refused {}: see the reasons above",
            plural::count(verdict.refused, "event")
        );
    }
    if refused > 0 {
        eprintln!(
            "refused by the transport (the player's buffer was full): {}",
            plural::count(refused, "event")
        );
        safe = false;
    }
    if safe {
        Outcome::Clean
    } else {
        Outcome::Errors
    }
}

/// The player's verdict on the events one `petrel send` delivered.
struct Verdict {
    delivered: u64,
    /// Taken, and on the flight record.
    on_record: u64,
    /// Refused by the player.
    refused: u64,
    /// Taken, but not on the flight record (pending, or dropped by the recorder).
    not_on_record: u64,
    /// Never acknowledged.
    unacknowledged: u64,
    /// The latest refusals: sequence number and the player's reason.
    refusals: Vec<(u64, String)>,
}

impl Verdict {
    fn of(heard: &petrel_ipc::Acknowledgement, delivered: u64) -> Self {
        let Some(ack) = &heard.ack else {
            return Verdict {
                delivered,
                on_record: 0,
                refused: 0,
                not_on_record: 0,
                unacknowledged: delivered,
                refusals: Vec::new(),
            };
        };
        // The sender is this process's own: every count of its account is about our events.
        let not_on_record = ack.unrecorded + ack.pending;
        Verdict {
            delivered,
            on_record: ack.taken.saturating_sub(not_on_record),
            refused: ack.refused,
            not_on_record,
            unacknowledged: delivered.saturating_sub(ack.taken + ack.refused),
            refusals: ack
                .refusals
                .iter()
                .map(|r| (r.seq, r.reason.clone()))
                .collect(),
        }
    }

    fn is_clean(&self) -> bool {
        self.on_record == self.delivered
            && self.refused == 0
            && self.not_on_record == 0
            && self.unacknowledged == 0
    }

    /// One line per event for a single event; a summary and the refusals otherwise.
    fn text(&self, origin: &str, event: &str) -> String {
        let mut text = format!(
            "verdict of the player on the {} of {origin}: {} taken and on record, {} refused, {} taken but not on record, {} unacknowledged\n",
            count(self.delivered, "event"), self.on_record, self.refused, self.not_on_record, self.unacknowledged
        );
        for (seq, reason) in &self.refusals {
            text.push_str(&format!(
                "  `{event}` #{seq} refused by the player: {reason}\n"
            ));
        }
        let unlisted = self.refused.saturating_sub(self.refusals.len() as u64);
        if unlisted > 0 {
            text.push_str(&format!(
                "  and {unlisted} more refused by the player (the heartbeat lists the latest {})\n",
                self.refusals.len()
            ));
        }
        text
    }
}

/// `petrel status`.
#[derive(clap::Args)]
pub struct StatusArgs {
    /// The project directory.
    dir: PathBuf,
    /// The vehicle; default: the project's name.
    #[arg(long)]
    vehicle: Option<String>,
    /// Print the status as JSON.
    #[arg(long)]
    json: bool,
}

/// Prints the live marking of every active net, the player's counters and the CAN data
/// server's.
pub fn status(a: StatusArgs) -> Outcome {
    let (vehicle, json) = (a.vehicle, a.json);
    let c = match compiled(&a.dir, "status") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let (v, _me, beats) = match join_as_tool(&c, vehicle, "status") {
        Ok(x) => x,
        Err(o) => return o,
    };
    // The player's heartbeat carries its status; wait for the next one (about 100 ms).
    // The CAN data server's, if one runs, comes at the same pace: take it when it is there by
    // then, or wait a little more (one of its periods) once the player's came.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
    let mut latest = None;
    let mut bridge: Option<petrel_ipc::Heartbeat> = None;
    // Gateways (docs/gateway.md) beat as `tool/gw-COMPUTER`, at the player's pace.
    let mut gateways: std::collections::BTreeMap<String, serde_json::Value> = Default::default();
    let mut bridge_deadline = None;
    loop {
        let _ = beats.drain(|r| {
            if let Ok(rcv) = r {
                match rcv.origin.as_str() {
                    "player" => latest = Some(rcv.msg),
                    "can_bridge" => bridge = Some(rcv.msg),
                    o => {
                        if let Some(computer) = o.strip_prefix("tool/gw-") {
                            if let Ok(doc) = serde_json::from_str(&rcv.msg.status) {
                                gateways.insert(computer.to_owned(), doc);
                            }
                        }
                    }
                }
            }
        });
        let now = std::time::Instant::now();
        if latest.is_some() && bridge_deadline.is_none() {
            bridge_deadline = Some(now + std::time::Duration::from_millis(150));
        }
        let bridge_done = bridge.is_some() || bridge_deadline.is_some_and(|d| now >= d);
        if (latest.is_some() && bridge_done) || now >= deadline {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let Some(beat) = latest else {
        eprintln!(
            "no player answered for vehicle `{}` within 2 s: is `petrel play` running?",
            v.name()
        );
        return Outcome::Errors;
    };
    let mut doc: serde_json::Value = serde_json::from_str(&beat.status).unwrap_or_default();
    // Each program's liveness, as this command sees the vehicle's nodes (not the player's
    // word): alive, dead (crashed, not yet cleaned up) or absent.
    let programs: serde_json::Map<String, serde_json::Value> = c
        .programs
        .iter()
        .map(|p| {
            let st = match petrel_ipc::program_status(&v, &p.name) {
                Ok(petrel_ipc::ProgramStatus::Alive) => "alive",
                Ok(petrel_ipc::ProgramStatus::Joining) => "joining",
                Ok(petrel_ipc::ProgramStatus::Dead) => "dead",
                Ok(petrel_ipc::ProgramStatus::Absent) => "absent",
                Err(_) => "unknown",
            };
            (p.name.clone(), st.into())
        })
        .collect();
    if let Some(obj) = doc.as_object_mut() {
        obj.insert("programs".into(), programs.clone().into());
    }
    let bridge_doc: Option<serde_json::Value> = bridge
        .as_ref()
        .and_then(|b| serde_json::from_str(&b.status).ok());
    if json {
        if let (Some(b), Some(obj)) = (&bridge_doc, doc.as_object_mut()) {
            obj.insert("can_bridge".into(), b.clone());
        }
        if let (false, Some(obj)) = (gateways.is_empty(), doc.as_object_mut()) {
            obj.insert(
                "gateways".into(),
                serde_json::to_value(&gateways).unwrap_or_default(),
            );
        }
        out(&format!("{doc}\n"));
        return Outcome::Clean;
    }
    let mut text = format!(
        "vehicle `{}`, project `{}`{}, mission time {:.3} s{}{}\n",
        v.name(),
        doc["project"].as_str().unwrap_or("?"),
        match doc["version"].as_str() {
            Some(h) => format!(" (reloaded: version {h})"),
            None => String::new(),
        },
        doc["time"].as_f64().unwrap_or(0.0),
        if doc["over"].as_bool() == Some(true) {
            ", OVER (catastrophic event)"
        } else {
            ""
        },
        if doc["reloading"].as_bool() == Some(true) {
            ", a reload is being verified"
        } else {
            ""
        }
    );
    if let Some(m) = doc["marking"].as_object() {
        for (net, places) in m {
            let list: Vec<&str> = places
                .as_array()
                .map(|a| a.iter().filter_map(|p| p.as_str()).collect())
                .unwrap_or_default();
            text.push_str(&format!("  {net}: {}\n", list.join(", ")));
        }
    }
    text.push_str(&format!("  counters: {}\n", doc["stats"]));
    if !programs.is_empty() {
        let list: Vec<String> = programs
            .iter()
            .map(|(p, st)| format!("{p} {}", st.as_str().unwrap_or("?")))
            .collect();
        text.push_str(&format!("  programs: {}\n", list.join(", ")));
    }
    let recorder = &doc["recorder"];
    match recorder["state"].as_str() {
        Some("ok") => text.push_str("  flight recorder: ok\n"),
        Some("none") | None => text.push_str("  flight recorder: none (--no-journal)\n"),
        Some(state) => text.push_str(&format!(
            "  flight recorder: {}: {} ({} waiting in memory, {} lost); events are processed but not acknowledged\n",
            state.to_uppercase(),
            recorder["reason"].as_str().unwrap_or("?"),
            count(recorder["backlog_records"].as_u64().unwrap_or(0), "record"),
            count(recorder["lost_entries"].as_u64().unwrap_or(0), "entry"),
        )),
    }
    if let Some(b) = &bridge_doc {
        text.push_str(&format!(
            "  CAN data server on `{}`: bus {}, {} ({} unknown, {} of a wrong length, {}), {} sent ({} waiting), {} ({} failed)\n",
            b["interface"].as_str().unwrap_or("?"),
            b["bus_state"].as_str().unwrap_or("?"),
            count(b["frames"].as_u64().unwrap_or(0), "frame"),
            b["unknown_id"],
            b["wrong_length"],
            count(b["error_frames"].as_u64().unwrap_or(0), "error frame"),
            count(b["events_sent"].as_u64().unwrap_or(0), "event"),
            b["events_pending"],
            count(b["commands"].as_u64().unwrap_or(0), "command"),
            b["commands_failed"],
        ));
    }
    for (computer, g) in &gateways {
        let peers: Vec<String> = g["peers"]
            .as_object()
            .map(|m| {
                m.iter()
                    .map(|(name, p)| {
                        format!(
                            "{name} {} ({} lost, {} missing)",
                            p["state"].as_str().unwrap_or("?"),
                            p["losses"],
                            p["missing"]
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        // Second gateways claiming a computer whose gateway is up, refused (one per computer).
        let claims: Vec<String> = g["counters"]["claims_refused"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(c, n)| format!("{n} message(s) of a second gateway of `{c}`"))
            .collect();
        text.push_str(&format!(
            "  gateway of `{computer}`: peers {}; link: {}{}\n",
            peers.join(", "),
            g["security"].as_str().unwrap_or("?"),
            if claims.is_empty() {
                String::new()
            } else {
                format!("; refused {}", claims.join(", "))
            }
        ));
        if let Some(kinds) = g["counters"]["kinds"].as_object() {
            for (kind, c) in kinds {
                text.push_str(&format!(
                    "    {kind}: to the link {} ({} refused, {} its own), from the link {}: {} delivered, {} refused, {} for others, {} unheard\n",
                    c["to_link"], c["to_link_refused"], c["own"], c["from_link"], c["delivered"], c["refused"], c["not_mine"], c["unheard"]
                ));
            }
        }
    }
    out(&text);
    Outcome::Clean
}
