//! `petrel gateway`: joins this computer's part of a vehicle to its other computers over zenoh
//! (docs/gateway.md), from the project's vehicle.toml.

use std::path::PathBuf;
use std::time::Duration;

use crate::common::{require_clean, Outcome, Scope};

/// `petrel gateway`.
#[derive(clap::Args)]
pub struct GatewayArgs {
    /// The project directory (its vehicle.toml says which computer runs what).
    dir: PathBuf,
    /// The vehicle; default: vehicle.toml's name, else the project's.
    #[arg(long)]
    vehicle: Option<String>,
    /// This computer, one of vehicle.toml's [computers].
    #[arg(long)]
    computer: String,
    /// Listen on this zenoh endpoint instead of the computer's `gateway` (`tcp/0.0.0.0:7447`).
    #[arg(long)]
    listen: Option<String>,
    /// Connect to these endpoints instead of the other computers' `gateway` (repeatable).
    #[arg(long)]
    connect: Vec<String>,
    /// This computer's keys are here (ca.pem, COMPUTER.pem, COMPUTER.key) instead of
    /// `keys/VEHICLE` in this user's state directory (`petrel keys` makes them).
    #[arg(long)]
    keys: Option<PathBuf>,
}

/// The default detection bound of a lost computer.
pub const DEFAULT_DETECTION: Duration = Duration::from_secs(1);

/// The default retention bound of a carried event or call (docs/gateway.md).
pub const DEFAULT_RETENTION: Duration = Duration::from_secs(30);

/// Runs the gateway until SIGINT or SIGTERM; prints its final counters as JSON.
pub fn gateway(a: GatewayArgs) -> Outcome {
    let checked = match require_clean(
        &a.dir,
        Scope {
            can: true,
            quick_verify: false,
            vehicle: true,
        },
        "gateway",
    ) {
        Ok(c) => c,
        Err(o) => return o,
    };
    let Some(c) = checked.compiled else {
        return Outcome::Usage("the project did not compile".into());
    };
    let Some(file) = checked.vehicle else {
        return Outcome::Usage(format!(
            "{} has no vehicle.toml: a gateway needs its [computers] and which processes run where (docs/gateway.md)",
            a.dir.display()
        ));
    };
    let Some(me) = file.computers.iter().find(|k| k.name == a.computer) else {
        let known: Vec<String> = file
            .computers
            .iter()
            .map(|k| format!("`{}`", k.name))
            .collect();
        return Outcome::Usage(format!(
            "`{}` is not a computer of {}/vehicle.toml (its computers: {})",
            a.computer,
            a.dir.display(),
            if known.is_empty() {
                "none: declare [computers.NAME] tables".to_string()
            } else {
                known.join(", ")
            }
        ));
    };
    use crate::up::file::Kind;
    let Some(player_computer) = file
        .processes
        .iter()
        .find(|p| p.kind == Kind::Player)
        .and_then(|p| p.computer.clone())
    else {
        return Outcome::Usage(
            "vehicle.toml runs no player on any computer: the gateways need to know where it is"
                .into(),
        );
    };
    let mut hosts = std::collections::BTreeMap::new();
    for p in &file.processes {
        if let Some(k) = &p.computer {
            for prog in &p.programs {
                hosts.insert(prog.clone(), k.clone());
            }
        }
    }
    // The CAN data server: its signals leave its computer for the others, and the program it
    // takes commands as (can.toml's [commands] program) lives there, called from anywhere.
    let signals_computer = file
        .processes
        .iter()
        .find(|p| p.kind == Kind::Bridge)
        .and_then(|p| p.computer.clone());
    if let (Some(k), Some((can, _))) = (&signals_computer, &checked.can) {
        if let Some(program) = &can.commands.program {
            hosts.insert(program.clone(), k.clone());
        }
    }
    let listen: Vec<String> = a
        .listen
        .iter()
        .chain(me.gateway.iter())
        .take(1)
        .cloned()
        .collect();
    let connect: Vec<String> = if a.connect.is_empty() {
        file.computers
            .iter()
            .filter(|k| k.name != me.name)
            .filter_map(|k| k.gateway.clone())
            .collect()
    } else {
        a.connect.clone()
    };
    if listen.is_empty() && connect.is_empty() {
        return Outcome::Usage(format!(
            "computer `{}` has no `gateway` endpoint in vehicle.toml, nor has any other: give one (`gateway = \"tcp/ADDRESS:7447\"`) or --listen/--connect",
            me.name
        ));
    }
    let credentials = match (&file.link.user, &file.link.credentials) {
        (Some(user), Some(path)) => {
            let path = a.dir.join(path);
            let text = match std::fs::read_to_string(&path) {
                Ok(t) => t,
                Err(e) => return Outcome::Usage(format!("cannot read {}: {e}", path.display())),
            };
            let password = text.lines().enumerate().find_map(|(i, l)| {
                let (u, p) = l.split_once(':')?;
                (u == user).then(|| (i, p.to_string()))
            });
            let Some((_, password)) = password else {
                return Outcome::Usage(format!(
                    "{}: no `{user}:PASSWORD` line for the [link] user `{user}`",
                    path.display()
                ));
            };
            let dictionary = match std::fs::canonicalize(&path) {
                Ok(p) => p,
                Err(e) => return Outcome::Usage(format!("{}: {e}", path.display())),
            };
            Some(petrel_gateway::Credentials {
                user: user.clone(),
                password,
                dictionary,
            })
        }
        _ => None,
    };
    let link_events = match (&file.link.lost_event, &file.link.restored_event) {
        (Some(lost), Some(restored)) => Some(petrel_gateway::LinkEvents {
            lost: lost.clone(),
            restored: restored.clone(),
        }),
        (None, None) => None,
        _ => {
            return Outcome::Usage(
                "vehicle.toml's [link] names one of lost_event and restored_event: name both"
                    .into(),
            )
        }
    };
    let name = crate::keys::vehicle_name(a.vehicle.as_deref(), &file, &c.name);
    let vehicle = match petrel_ipc::Vehicle::new(&name) {
        Ok(v) => v,
        Err(e) => return Outcome::Usage(format!("bad vehicle name `{name}`: {e}")),
    };
    let endpoints: Vec<String> = listen.iter().chain(&connect).cloned().collect();
    let security =
        match crate::keys::link_security(&file, &name, &me.name, a.keys.as_deref(), &endpoints) {
            Ok(s) => s,
            Err(e) => return Outcome::Usage(format!("petrel gateway: {e}")),
        };
    let detection = file.link.detection.unwrap_or(DEFAULT_DETECTION);
    let settings = petrel_gateway::Settings {
        vehicle,
        plan: petrel_gateway::Plan {
            computer: me.name.clone(),
            peers: file
                .computers
                .iter()
                .filter(|k| k.name != me.name)
                .map(|k| k.name.clone())
                .collect(),
            player_computer,
            hosts,
            signals_computer,
            detection_us: detection.as_micros() as u64,
            retention_us: file
                .link
                .retention
                .unwrap_or(DEFAULT_RETENTION.max(2 * detection))
                .as_micros() as u64,
        },
        listen,
        connect,
        security,
        credentials,
        link_events,
        status_period: Duration::from_millis(100),
    };
    match petrel_gateway::run(settings) {
        Ok(counters) => {
            crate::common::out(&format!("{counters}\n"));
            Outcome::Clean
        }
        Err(e) => Outcome::Usage(format!("petrel gateway: {e}")),
    }
}
