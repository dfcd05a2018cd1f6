//! Commands that run a vehicle or talk to one: `play`, `send`, `status`.

use crate::common::{compiled, out, vehicle_of, wait_strategy, Outcome};
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
    /// When journal records reach the disk: record (every record, to the OS), sync (every
    /// record, to the disk), or a period such as 50ms.
    #[arg(long, default_value = "record")]
    flush: String,
    /// Start a new journal segment past this many megabytes.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u64).range(1..))]
    rotate_mb: u64,
    /// Restore the mission from the journal (after a crash) and carry on.
    #[arg(long)]
    resume: bool,
    /// Ground-station shadow: follow the vehicle player's steps, run no action, and raise an
    /// alarm the moment this copy's marking differs from the vehicle's.
    #[arg(long, conflicts_with_all = ["resume"])]
    shadow: bool,
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
    opts.rotate_bytes = a.rotate_mb.saturating_mul(1 << 20);
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
                    "shadow stopped: {} vehicle steps followed, {} divergence alarm(s)",
                    r.steps, r.alarms
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
                "player stopped: {} messages ({} refused before the engine), {} events received, {} processed, {} unused, {} refused; {} calls sent, {} failed; journal: {} records, {:.1} us each{}",
                r.messages, r.bad_messages, s.received, s.processed, s.unused, s.refused, r.calls_sent, r.calls_failed,
                r.journal_records, per_record,
                if r.resumed_steps > 0 { format!("; resumed after {} steps", r.resumed_steps) } else { String::new() }
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
}

/// Sends an event to a running player, as the operator, and waits for its acknowledgement.
pub fn send(a: SendArgs) -> Outcome {
    let (event, vehicle, count) = (a.event.as_str(), a.vehicle, a.count);
    let c = match compiled(&a.dir, "send") {
        Ok(c) => c,
        Err(o) => return o,
    };
    // The same reading as a script line, so the operator types what scripts hold.
    let script = match petrel_player::script::parse_script(&format!("0 {event}"), &c) {
        Ok(s) => s,
        Err(errors) => {
            return Outcome::Usage(
                errors
                    .into_iter()
                    .map(|(_, e)| e)
                    .collect::<Vec<_>>()
                    .join("; "),
            )
        }
    };
    let Some((
        _,
        petrel_player::script::Line::At {
            event: Some((name, params)),
            ..
        },
    )) = script.lines.first()
    else {
        return Outcome::Usage(format!("`{event}` is not an event"));
    };
    let (v, me, beats) = match join_as_tool(&c, vehicle, "send") {
        Ok(x) => x,
        Err(o) => return o,
    };
    let sender = match me.event_sender() {
        Ok(s) => s,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let msg = petrel_ipc::EventMsg::new(name.clone(), params.clone());
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
    if absent > 0 {
        out(&format!(
            "sent {count}: {delivered} delivered, {refused} refused, {absent} with no player\n"
        ));
        eprintln!(
            "no player is running for vehicle `{}`: start one with `petrel play`",
            v.name()
        );
        return Outcome::Errors;
    }
    // Shared memory dies with its process: stay until the player says (in its heartbeat) that
    // it has taken our last event, so nothing delivered is lost when we exit.
    let origin = sender.origin().to_string();
    let acknowledged = delivered == 0
        || petrel_ipc::wait_acknowledged(
            &beats,
            &origin,
            last_seq,
            std::time::Duration::from_secs(10),
        );
    out(&format!(
        "sent {count}: {delivered} delivered, {refused} refused (player's buffer full), {absent} with no player\n"
    ));
    if !acknowledged {
        eprintln!("the player did not acknowledge the events within 10 s: they may be lost");
        return Outcome::Errors;
    }
    if refused > 0 {
        Outcome::Errors
    } else {
        Outcome::Clean
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
    let mut bridge_deadline = None;
    loop {
        let _ = beats.drain(|r| {
            if let Ok(rcv) = r {
                match rcv.origin.as_str() {
                    "player" => latest = Some(rcv.msg),
                    "can_bridge" => bridge = Some(rcv.msg),
                    _ => {}
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
    let bridge_doc: Option<serde_json::Value> = bridge
        .as_ref()
        .and_then(|b| serde_json::from_str(&b.status).ok());
    if json {
        if let (Some(b), Some(obj)) = (&bridge_doc, doc.as_object_mut()) {
            obj.insert("can_bridge".into(), b.clone());
        }
        out(&format!("{doc}\n"));
        return Outcome::Clean;
    }
    let mut text = format!(
        "vehicle `{}`, project `{}`, mission time {:.3} s{}\n",
        v.name(),
        doc["project"].as_str().unwrap_or("?"),
        doc["time"].as_f64().unwrap_or(0.0),
        if doc["over"].as_bool() == Some(true) {
            ", OVER (catastrophic event)"
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
    if let Some(b) = &bridge_doc {
        text.push_str(&format!(
            "  CAN data server on `{}`: bus {}, {} frames ({} unknown, {} of a wrong length, {} error frames), {} events sent ({} waiting), {} commands ({} failed)\n",
            b["interface"].as_str().unwrap_or("?"),
            b["bus_state"].as_str().unwrap_or("?"),
            b["frames"],
            b["unknown_id"],
            b["wrong_length"],
            b["error_frames"],
            b["events_sent"],
            b["events_pending"],
            b["commands"],
            b["commands_failed"],
        ));
    }
    out(&text);
    Outcome::Clean
}
