//! The vehicle's keys for the link between its computers (docs/gateway.md, "Security"):
//! `petrel keys`, which makes them; how `petrel gateway` finds (or, when every computer is on
//! this machine, makes) its computer's; and what `petrel check` says of them.

use std::path::{Path, PathBuf};

use petrel_gateway::keys::{self, KeyError};
use petrel_gateway::session::is_loopback;
use petrel_gateway::Security;
use petrel_nets::diag::{Diagnostic, Severity};

use crate::common::{out, require_clean, Outcome, Scope};
use crate::up::file::VehicleFile;

/// `petrel keys`.
#[derive(clap::Args)]
pub struct KeysArgs {
    /// The project directory (its vehicle.toml names the computers).
    dir: PathBuf,
    /// The vehicle; default: vehicle.toml's name, else the project's.
    #[arg(long)]
    vehicle: Option<String>,
    /// Write them here instead of this user's state directory (`keys/VEHICLE` in
    /// $PETREL_STATE_DIR, $XDG_STATE_HOME/petrel or ~/.local/state/petrel).
    #[arg(long)]
    out: Option<PathBuf>,
}

/// The vehicle's name as the gateways take it: `--vehicle`, the file's, the project's.
pub fn vehicle_name(given: Option<&str>, file: &VehicleFile, project: &str) -> String {
    given
        .map(str::to_owned)
        .or_else(|| file.name.clone())
        .unwrap_or_else(|| project.to_owned())
}

fn computers(file: &VehicleFile) -> Vec<String> {
    file.computers.iter().map(|k| k.name.clone()).collect()
}

/// What a computer needs, and how it gets there, for a message.
fn distribution(vehicle: &str) -> String {
    format!(
        "each computer needs ca.pem and its own NAME.pem and NAME.key in its keys directory \
         (`keys/{vehicle}` in its user's state directory: $PETREL_STATE_DIR, \
         $XDG_STATE_HOME/petrel or ~/.local/state/petrel; or `petrel gateway --keys DIR`), \
         the directory mode 0700 and the files 0600; ca.key makes certificates: keep it off \
         the vehicle"
    )
}

/// Makes (or completes) the vehicle's keys: its CA and a certificate per computer.
pub fn keys(a: KeysArgs) -> Outcome {
    let scope = Scope {
        can: false,
        quick_verify: false,
        vehicle: true,
    };
    let checked = match require_clean(&a.dir, scope, "keys") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let (Some(c), Some(file)) = (&checked.compiled, &checked.vehicle) else {
        return Outcome::Usage(format!(
            "{} has no vehicle.toml: the keys are for the computers it declares",
            a.dir.display()
        ));
    };
    let names = computers(file);
    if names.is_empty() {
        return Outcome::Usage(
            "vehicle.toml declares no [computers]: a vehicle on one computer has no link to secure"
                .into(),
        );
    }
    let vehicle = vehicle_name(a.vehicle.as_deref(), file, &c.name);
    let dir = match a
        .out
        .clone()
        .map(Ok)
        .unwrap_or_else(|| keys::default_dir(&vehicle))
    {
        Ok(d) => d,
        Err(e) => return Outcome::Usage(format!("petrel keys: {e}")),
    };
    match keys::make(&dir, &vehicle, &names) {
        Ok(made) => {
            let had: Vec<&String> = names
                .iter()
                .filter(|n| !made.contains(&format!("{n}.pem")))
                .collect();
            out(&format!(
                "the keys of vehicle `{vehicle}` are in {}: made {}{}\n{}\n",
                dir.display(),
                if made.is_empty() {
                    "nothing".to_string()
                } else {
                    made.join(", ")
                },
                if had.is_empty() {
                    String::new()
                } else {
                    format!(
                        " (already there: {})",
                        had.iter()
                            .map(|s| s.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                },
                distribution(&vehicle)
            ));
            Outcome::Clean
        }
        Err(e) => Outcome::Usage(format!("petrel keys: {e}")),
    }
}

/// How `petrel gateway` secures its link: the file's opt-out, or this computer's keys (from
/// `keys_dir`, else this user's state directory), made on first use when every endpoint the
/// gateway uses is on this machine's loopback (every computer of the vehicle is here).
pub fn link_security(
    file: &VehicleFile,
    vehicle: &str,
    computer: &str,
    keys_dir: Option<&Path>,
    endpoints: &[String],
) -> Result<Security, String> {
    if file.link.insecure {
        return Ok(Security::None);
    }
    let dir = match keys_dir {
        Some(d) => d.to_path_buf(),
        None => keys::default_dir(vehicle).map_err(|e| e.to_string())?,
    };
    let one_machine = !endpoints.is_empty() && endpoints.iter().all(|e| is_loopback(e));
    let loaded = match keys::load(&dir, computer) {
        Err(KeyError::Missing { .. }) if one_machine => {
            let made = keys::make(&dir, vehicle, &computers(file)).map_err(|e| e.to_string())?;
            if !made.is_empty() {
                tracing::info!(
                    "every computer of the vehicle is on this machine: made its keys in {} ({})",
                    dir.display(),
                    made.join(", ")
                );
            }
            keys::load(&dir, computer)
        }
        other => other,
    };
    loaded.map(Security::Tls).map_err(|e| {
        format!(
            "the link between the vehicle's computers is secured by default (mutual TLS), and computer `{computer}` has no usable keys: {e}\n\
             make them on one computer with `petrel keys DIR --vehicle {vehicle}`; {}.\n\
             (For a lab bench only: `[link] security = \"none\"` in vehicle.toml opts out, docs/gateway.md.)",
            distribution(vehicle)
        )
    })
}

/// What `petrel check` says of the link: a line for its summary, and a warning when this
/// machine has no keys and the gateways will not make them.
pub fn check_link(file: &VehicleFile, vehicle: &str) -> (Option<String>, Option<Diagnostic>) {
    if file.computers.is_empty() {
        return (None, None);
    }
    if file.link.insecure {
        return (Some("link: NOT SECURED (security = \"none\")".into()), None);
    }
    let dir = match keys::default_dir(vehicle) {
        Ok(d) => d,
        Err(e) => return (Some(format!("link: mutual TLS, but {e}")), None),
    };
    let names = computers(file);
    let here = keys::present(&dir, &names);
    if !here.is_empty() {
        return (
            Some(format!(
                "link: mutual TLS, keys of {} in {}",
                here.join(", "),
                dir.display()
            )),
            None,
        );
    }
    let one_machine = file
        .computers
        .iter()
        .all(|k| k.gateway.as_deref().is_some_and(is_loopback));
    if one_machine {
        return (
            Some(format!(
                "link: mutual TLS, keys made in {} at the first gateway's start (every computer is on this machine)",
                dir.display()
            )),
            None,
        );
    }
    let warning = Diagnostic {
        severity: Severity::Warning,
        ..Diagnostic::global(
            "W0803",
            format!(
                "the link is secured by default, and this machine has no keys of vehicle `{vehicle}` ({} holds no certificate of {})",
                dir.display(),
                names.join(", ")
            ),
        )
        .help(format!(
            "make them on one computer with `petrel keys DIR --vehicle {vehicle}`; {}",
            distribution(vehicle)
        ))
    };
    (Some("link: mutual TLS, no keys here".into()), Some(warning))
}
