//! The vehicle file, `vehicle.toml`: which processes make up the vehicle, how each is started,
//! waited for, restarted and stopped, on which computer, and the operator's timed events
//! (docs/vehicle.md describes it; codes E08xx in docs/diagnostics.md).
//!
//! Like the manifest and can.toml, it is read with serde and toml with every span kept, and
//! every problem is reported at once, at its file, line and column. Nothing here starts a
//! process: [`super::supervise`] does, from the [`VehicleFile`] this module builds.
//!
//! - this module: what a checked file is ([`VehicleFile`], [`ProcessSpec`]...), the
//!   substitutions ([`expand`]), and loading (the project's file, `--file`, `--scenario`);
//! - `raw`: the tables as serde reads them, every span kept;
//! - `checker`: the findings at their place, and the checks several tables share;
//! - `check`: `check_file`, one function per table and per field of a `[[process]]`.

mod check;
mod checker;
mod raw;

use checker::VehicleChecker;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;
use petrel_nets::compiled::CompiledProject;
use petrel_nets::compiled::Value;
use raw::RawScenario;
use std::path::Path;
use std::time::Duration;

/// The vehicle file's name in a project directory.
pub const VEHICLE_TOML: &str = "vehicle.toml";

/// What a process is, which decides how it is started and when it is ready.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `petrel play` on this project: ready when its heartbeat comes.
    Player,
    /// The CAN data server on this project, `petrel bridge` or the vehicle's own data server
    /// (`executable`, with the same arguments): ready when its heartbeat comes.
    Bridge,
    /// An executable that joins the vehicle as the manifest's programs it names: ready when
    /// the node of each is alive.
    Program,
    /// Any other executable: ready once started.
    Command,
}

impl Kind {
    /// The word the file uses.
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Player => "player",
            Kind::Bridge => "bridge",
            Kind::Program => "program",
            Kind::Command => "command",
        }
    }

    fn parse(s: &str) -> Option<Kind> {
        Some(match s {
            "player" => Kind::Player,
            "bridge" => Kind::Bridge,
            "program" => Kind::Program,
            "command" => Kind::Command,
            _ => return None,
        })
    }
}

/// What happens when a process fails (exits non-zero, or dies of a signal `petrel up` did not
/// send).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Restart {
    /// It stays down.
    Never,
    /// It is started again, at most `max` times, `backoff` after the first failure, the delay
    /// doubling for each further one (a process that fails at once does not spin the CPU).
    OnFailure {
        /// Restarts at most.
        max: u32,
        /// The delay before the first restart.
        backoff: Duration,
    },
}

/// The player's flight recorder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Journal {
    /// `{logs}/journal`: the run directory holds everything of the run.
    Default,
    /// This directory (a template).
    Path(String),
    /// No journal (`--no-journal`).
    Off,
}

/// One `[[process]]` entry, checked. Text fields that may hold substitutions (`{vehicle}`...)
/// are kept as templates: they are expanded when the run directory is known.
#[derive(Clone, Debug)]
pub struct ProcessSpec {
    /// Its name (log file `<logs>/<name>.log`, the status line, `after` entries).
    pub name: String,
    /// What it is.
    pub kind: Kind,
    /// The executable (template), for programs and commands; for a bridge, the vehicle's own
    /// data server (`None`: `petrel bridge`).
    pub executable: Option<String>,
    /// Arguments (templates). For a player or a bridge they follow `petrel play|bridge DIR
    /// --vehicle V` (a bridge's own executable: `EXECUTABLE DIR --vehicle V`).
    pub args: Vec<String>,
    /// Environment variables set for it (values are templates).
    pub env: Vec<(String, String)>,
    /// The computer it runs on, when the file declares computers.
    pub computer: Option<String>,
    /// `--wait` for a player or a bridge.
    pub wait: Option<String>,
    /// The manifest's programs it runs (kind program).
    pub programs: Vec<String>,
    /// The processes that must be ready before it starts.
    pub after: Vec<String>,
    /// Its restart policy.
    pub restart: Restart,
    /// How long it may take to become ready.
    pub ready_timeout: Duration,
    /// How long it has between SIGTERM and SIGKILL.
    pub stop_grace: Duration,
    /// The player's journal.
    pub journal: Journal,
    /// A failure of this process for good stops the vehicle (always true for the player).
    pub critical: bool,
}

/// One `[[send]]` entry: an operator event at a time after the vehicle is up.
#[derive(Clone, Debug)]
pub struct SendSpec {
    /// When, counted from the moment every process is ready.
    pub at: Duration,
    /// The event as written (`payload_failure("camera")`).
    pub text: String,
    /// The event's name.
    pub name: String,
    /// Its parameters.
    pub params: Vec<Value>,
    /// The computer whose `petrel up` sends it.
    pub computer: Option<String>,
}

/// One `[computers.NAME]` table.
#[derive(Clone, Debug)]
pub struct Computer {
    /// Its name.
    pub name: String,
    /// Its network address, as written.
    pub address: Option<String>,
    /// Free text.
    pub description: Option<String>,
    /// The zenoh endpoint its gateway listens on (`tcp/10.0.0.2:7447`), for `petrel gateway`.
    pub gateway: Option<String>,
}

/// The `[link]` table: how the computers' gateways watch and authenticate each other.
#[derive(Clone, Debug, Default)]
pub struct LinkSpec {
    /// A computer silent for this long is lost (default 1 s).
    pub detection: Option<Duration>,
    /// An event or a call the link could not carry within this long is given up and its sender
    /// told (default 30 s; longer than `detection`).
    pub retention: Option<Duration>,
    /// The event (category communication, one `text` parameter) raised on the player's
    /// computer when a computer is lost.
    pub lost_event: Option<String>,
    /// The event raised when it comes back.
    pub restored_event: Option<String>,
    /// The zenoh user of the gateways, when they authenticate each other.
    pub user: Option<String>,
    /// The file of `user:password` lines (relative to the project) the gateways accept.
    pub credentials: Option<String>,
    /// `security = "none"`: the link is neither encrypted nor authenticated (a lab bench's
    /// explicit opt-out of the default, mutual TLS with the vehicle's keys).
    pub insecure: bool,
}

/// A checked vehicle file.
#[derive(Clone, Debug)]
pub struct VehicleFile {
    /// The vehicle's name, if the file gives one (default: the project's).
    pub name: Option<String>,
    /// The run directory (template with `{vehicle}` and `{time}`), relative to the project.
    pub logs: String,
    /// The declared computers, in file order.
    pub computers: Vec<Computer>,
    /// The processes, in file order.
    pub processes: Vec<ProcessSpec>,
    /// The operator's timed events, in time order.
    pub sends: Vec<SendSpec>,
    /// The `[link]` table.
    pub link: LinkSpec,
}

/// The run directory when the file does not say.
pub const DEFAULT_LOGS: &str = "run/{vehicle}-{time}";
/// SIGTERM to SIGKILL when the file does not say.
pub const DEFAULT_STOP_GRACE: Duration = Duration::from_secs(5);
/// How long a process may take to become ready when the file does not say.
pub const DEFAULT_READY_TIMEOUT: Duration = Duration::from_secs(10);
/// Restarts at most, for `on-failure`, when the file does not say.
pub const DEFAULT_MAX_RESTARTS: u32 = 3;
/// The first restart's delay when the file does not say.
pub const DEFAULT_BACKOFF: Duration = Duration::from_secs(1);

/// The substitutions a process's executable, arguments, environment and journal may hold.
pub const PROCESS_VARS: &[&str] = &[
    "vehicle", "project", "logs", "target", "petrel", "name", "computer",
];
/// The substitutions the run directory may hold.
pub const LOGS_VARS: &[&str] = &["vehicle", "time"];

/// Expands `{name}` substitutions in `template` with `var`; `{{` and `}}` stand for braces.
/// The error says what is wrong (an unknown name, a brace left open).
pub fn expand(template: &str, var: &dyn Fn(&str) -> Option<String>) -> Result<String, String> {
    let mut out = String::with_capacity(template.len());
    let mut rest = template;
    while let Some(i) = rest.find(['{', '}']) {
        out.push_str(&rest[..i]);
        let tail = &rest[i..];
        if let Some(after) = tail.strip_prefix("{{") {
            out.push('{');
            rest = after;
        } else if let Some(after) = tail.strip_prefix("}}") {
            out.push('}');
            rest = after;
        } else if tail.starts_with('}') {
            return Err("a `}` with no `{` (write `}}` for a brace)".into());
        } else {
            let Some(end) = tail.find('}') else {
                return Err("a `{` with no `}` (write `{{` for a brace)".into());
            };
            let name = &tail[1..end];
            match var(name) {
                Some(v) => out.push_str(&v),
                None => return Err(format!("no substitution `{{{name}}}`")),
            }
            rest = &tail[end + 1..];
        }
    }
    out.push_str(rest);
    Ok(out)
}

/// A process or computer name: it names a log file and appears in `after` lists.
fn is_process_name(s: &str) -> bool {
    let mut chars = s.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        && s.len() <= 64
}

/// The closest of `candidates` to `name`, as a hint.
fn suggest<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> String {
    let best = candidates
        .map(|c| (petrel_diag::names::distance(name, c), c))
        .min();
    match best {
        Some((d, c)) if d <= 2.max(name.len() / 3) => format!("did you mean `{c}`? "),
        _ => String::new(),
    }
}

/// Reads and checks the project's vehicle.toml, if it has one. The file joins `sources` so
/// that findings point into it.
pub fn load(
    dir: &Path,
    project: Option<&CompiledProject>,
    can_program: Option<&str>,
    sources: &mut SourceMap,
    diags: &mut Diagnostics,
) -> std::io::Result<Option<VehicleFile>> {
    match load_file(
        &dir.join(VEHICLE_TOML),
        project,
        can_program,
        sources,
        diags,
    ) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        other => other,
    }
}

/// Reads and checks the vehicle file at `path` (`petrel up --file`: a variant of the
/// project's vehicle.toml), as [`load`] does; a missing file is an error.
pub fn load_file(
    path: &Path,
    project: Option<&CompiledProject>,
    can_program: Option<&str>,
    sources: &mut SourceMap,
    diags: &mut Diagnostics,
) -> std::io::Result<Option<VehicleFile>> {
    let text = std::fs::read_to_string(path)?;
    let file = sources.add(path.display().to_string(), text.clone());
    Ok(check::check_file(file, &text, project, can_program, diags))
}

/// Reads and checks a scenario file (`[[send]]` entries only) against the project and the
/// vehicle file; `None` when it has an error (reported in `diags`).
pub fn load_scenario(
    path: &Path,
    project: &CompiledProject,
    vehicle: &VehicleFile,
    sources: &mut SourceMap,
    diags: &mut Diagnostics,
) -> std::io::Result<Option<Vec<SendSpec>>> {
    let text = std::fs::read_to_string(path)?;
    let file = sources.add(path.display().to_string(), text.clone());
    let Some(raw) = petrel_diag::toml::parse::<RawScenario>(
        file,
        &text,
        "E0801",
        "the scenario",
        "a scenario file holds [[send]] entries (at, event, and optionally computer); see docs/vehicle.md",
        diags,
    ) else {
        return Ok(None);
    };
    let mut c = VehicleChecker::new(file, diags, Some(project));
    let sends = check::sends(&mut c, &raw.sends, &vehicle.computers, &vehicle.processes);
    Ok((c.errors == 0).then_some(sends))
}
