//! The vehicle file, `vehicle.toml`: which processes make up the vehicle, how each is started,
//! waited for, restarted and stopped, on which computer, and the operator's timed events
//! (docs/vehicle.md describes it; codes E08xx in docs/diagnostics.md).
//!
//! Like the manifest and can.toml, it is read with serde and toml with every span kept, and
//! every problem is reported at once, at its file, line and column. Nothing here starts a
//! process: [`super::run`] does, from the [`VehicleFile`] this module builds.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::compiled::Value;
use petrel_nets::diag::{Diagnostic, Diagnostics};
use petrel_nets::manifest::{toml_error, Ordered};
use petrel_nets::source::{FileId, SourceMap, Span};
use serde::Deserialize;
use std::path::Path;
use std::time::Duration;
use toml::Spanned;

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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    vehicle: RawVehicle,
    #[serde(default)]
    computers: Ordered<RawComputer>,
    #[serde(default, rename = "process")]
    processes: Vec<RawProcess>,
    #[serde(default, rename = "send")]
    sends: Vec<RawSend>,
    link: Option<RawLink>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLink {
    detection: Option<Spanned<String>>,
    retention: Option<Spanned<String>>,
    lost_event: Option<Spanned<String>>,
    restored_event: Option<Spanned<String>>,
    user: Option<Spanned<String>>,
    credentials: Option<Spanned<String>>,
    security: Option<Spanned<String>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawVehicle {
    name: Option<Spanned<String>>,
    logs: Option<Spanned<String>>,
    stop_grace: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawComputer {
    address: Option<String>,
    description: Option<String>,
    gateway: Option<String>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawJournal {
    On(bool),
    Path(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProcess {
    name: Spanned<String>,
    kind: Spanned<String>,
    #[allow(dead_code)]
    description: Option<String>,
    executable: Option<Spanned<String>>,
    #[serde(default)]
    args: Vec<Spanned<String>>,
    #[serde(default)]
    env: Ordered<Spanned<String>>,
    computer: Option<Spanned<String>>,
    wait: Option<Spanned<String>>,
    programs: Option<Spanned<Vec<Spanned<String>>>>,
    after: Option<Spanned<Vec<Spanned<String>>>>,
    restart: Option<Spanned<String>>,
    max_restarts: Option<Spanned<i64>>,
    backoff: Option<Spanned<String>>,
    ready_timeout: Option<Spanned<String>>,
    stop_grace: Option<Spanned<String>>,
    journal: Option<Spanned<RawJournal>>,
    critical: Option<Spanned<bool>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSend {
    at: Spanned<String>,
    event: Spanned<String>,
    computer: Option<Spanned<String>>,
}

/// A scenario file: timed operator events only, to run one vehicle file several ways.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    #[serde(default, rename = "send")]
    sends: Vec<RawSend>,
}

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
        .map(|c| (petrel_nets::names::distance(name, c), c))
        .min();
    match best {
        Some((d, c)) if d <= 2.max(name.len() / 3) => format!("did you mean `{c}`? "),
        _ => String::new(),
    }
}

struct Checker<'a> {
    file: FileId,
    diags: &'a mut Diagnostics,
    errors: usize,
    project: Option<&'a CompiledProject>,
}

impl Checker<'_> {
    /// The `[link]` table: its events must be the project's, of the communication category,
    /// with one `text` parameter (the computer's name).
    fn link(&mut self, l: &RawLink, computers: &[Computer]) -> LinkSpec {
        if computers.is_empty() {
            let span = l
                .detection
                .as_ref()
                .or(l.lost_event.as_ref())
                .map(|d| self.span(d))
                .unwrap_or(Span::new(self.file, 0, 0));
            self.error(
                "E0812",
                span,
                "a [link] table but no [computers]".into(),
                "nothing to link",
                "declare the computers ([computers.NAME] with `gateway = \"tcp/ADDRESS:PORT\"`), or remove [link]",
            );
        }
        let detection = l
            .detection
            .as_ref()
            .and_then(|d| self.duration(d, "[link] detection"));
        let retention = l.retention.as_ref().and_then(|r| {
            let retention = self.duration(r, "[link] retention")?;
            let bound = detection.unwrap_or(crate::gateway::DEFAULT_DETECTION);
            if retention <= bound {
                self.error(
                    "E0812",
                    self.span(r),
                    format!(
                        "[link] retention ({}) must be longer than the detection bound ({:?})",
                        r.get_ref(),
                        bound
                    ),
                    "not longer than detection",
                    "a carried message is sent again while it is younger than retention - detection: give retention several detection bounds (default 30s)",
                );
                return None;
            }
            Some(retention)
        });
        let mut event = |e: &Option<Spanned<String>>, what: &str| -> Option<String> {
            let e = e.as_ref()?;
            let name = e.get_ref();
            if let Some(project) = self.project {
                let found = project.events.iter().find(|ev| &ev.name == name);
                let ok = found.is_some_and(|ev| {
                    ev.category == petrel_nets::model::Category::Communication
                        && ev.params.len() == 1
                        && ev.params[0].1 == petrel_nets::model::Type::Text
                });
                if !ok {
                    let why = match found {
                        None => format!("`{name}` is not an event of the project"),
                        Some(_) => format!(
                            "`{name}` is not of category communication with one `text` parameter"
                        ),
                    };
                    self.error(
                        "E0812",
                        self.span(e),
                        format!("[link] {what}: {why}"),
                        "not a link event",
                        &format!("declare it in petrel.toml: {name} = {{ category = \"communication\", params = [\"computer: text\"] }}"),
                    );
                    return None;
                }
            }
            Some(name.clone())
        };
        let lost_event = event(&l.lost_event, "lost_event");
        let restored_event = event(&l.restored_event, "restored_event");
        if l.user.is_some() != l.credentials.is_some() {
            let span = l
                .user
                .as_ref()
                .or(l.credentials.as_ref())
                .map(|d| self.span(d))
                .unwrap_or(Span::new(self.file, 0, 0));
            self.error(
                "E0812",
                span,
                "[link] `user` and `credentials` go together".into(),
                "only one of them",
                "give both: `user`, the gateways' zenoh user, and `credentials`, the file of `user:password` lines they accept",
            );
        }
        if let Some(cred) = &l.credentials {
            if let Err(e) = petrel_nets::paths::check_relative(cred.get_ref()) {
                self.error(
                    "E0812",
                    self.span(cred),
                    format!("[link] credentials: {e}"),
                    "not a path inside the project",
                    "give a path relative to the project directory",
                );
            }
        }
        let insecure = l.security.as_ref().is_some_and(|s| self.security(s));
        LinkSpec {
            detection,
            retention,
            lost_event,
            restored_event,
            user: l.user.as_ref().map(|u| u.get_ref().clone()),
            credentials: l.credentials.as_ref().map(|u| u.get_ref().clone()),
            insecure,
        }
    }

    /// `[link] security`: "tls" (the default) or "none", a lab bench's opt-out, which is
    /// warned of. True for "none".
    fn security(&mut self, s: &Spanned<String>) -> bool {
        match s.get_ref().as_str() {
            "tls" => false,
            "none" => {
                self.diags.push(
                    Diagnostic::warning(
                        "W0802",
                        self.span(s),
                        petrel_gateway::session::INSECURE_WARNING.to_string(),
                    )
                    .label("the link is open")
                    .help("remove `security = \"none\"`: the gateways then use mutual TLS with the vehicle's keys (docs/gateway.md)"),
                );
                true
            }
            other => {
                self.error(
                    "E0812",
                    self.span(s),
                    format!("[link] security `{other}` is not \"tls\" or \"none\""),
                    "not a security",
                    "leave it out (mutual TLS, the default), or write \"none\" for a lab bench whose link needs no protection",
                );
                false
            }
        }
    }

    fn span<T>(&self, s: &Spanned<T>) -> Span {
        Span::new(self.file, s.span().start, s.span().end)
    }

    fn error(&mut self, code: &'static str, span: Span, message: String, label: &str, help: &str) {
        self.errors += 1;
        self.diags.push(
            Diagnostic::error(code, span, message)
                .label(label)
                .help(help),
        );
    }

    fn duration(&mut self, d: &Spanned<String>, what: &str) -> Option<Duration> {
        match petrel_nets::duration::parse_duration_us(d.get_ref()) {
            Some(us) => Some(Duration::from_micros(us)),
            None => {
                self.error(
                    "E0806",
                    self.span(d),
                    format!("`{}` is not a duration ({what})", d.get_ref()),
                    "not a duration",
                    "write a number and a unit: `500ms`, `2s`, `1.5s`, `1min`",
                );
                None
            }
        }
    }

    fn template(&mut self, t: &Spanned<String>, vars: &[&str], what: &str) {
        if let Err(e) = expand(t.get_ref(), &|n| vars.contains(&n).then(String::new)) {
            let list: Vec<String> = vars.iter().map(|v| format!("{{{v}}}")).collect();
            self.error(
                "E0808",
                self.span(t),
                format!("{e} in {what}"),
                "bad substitution",
                &format!("{what} may use {}", list.join(", ")),
            );
        }
    }

    fn not_for_kind(&mut self, span: Span, field: &str, process: &str, kind: Kind, help: &str) {
        self.error(
            "E0805",
            span,
            format!(
                "`{field}` does not apply to process `{process}` (kind {})",
                kind.as_str()
            ),
            "not for this kind",
            help,
        );
    }

    /// An operator event, read as a script line holds it.
    fn send(&mut self, raw: &RawSend) -> Option<SendSpec> {
        let at = self.duration(&raw.at, "`at` of a [[send]]");
        let text = raw.event.get_ref().trim().to_string();
        let event = match self.project {
            // Without a project that checks, the event cannot be read: the project's own
            // errors are reported instead.
            None => None,
            Some(c) => match crate::common::operator_event(&text, c) {
                Ok(e) => Some(e),
                Err(e) => {
                    self.error(
                        "E0809",
                        self.span(&raw.event),
                        format!("the event `{text}` cannot be sent: {e}"),
                        "not an event of the project",
                        "write an event of the manifest's [events] as in a script: `start_mission` or `payload_failure(\"camera\")`",
                    );
                    None
                }
            },
        };
        let (name, params) = event?;
        Some(SendSpec {
            at: at?,
            text,
            name,
            params,
            computer: raw.computer.as_ref().map(|c| c.get_ref().clone()),
        })
    }

    fn computer_ref(&mut self, c: &Spanned<String>, computers: &[Computer], what: &str) {
        if computers.iter().any(|k| &k.name == c.get_ref()) {
            return;
        }
        let help = if computers.is_empty() {
            format!("declare it in a [computers.{}] table (with its address), or remove `computer`: without [computers] the vehicle is one computer", c.get_ref())
        } else {
            format!(
                "{}the computers are {}",
                suggest(c.get_ref(), computers.iter().map(|k| k.name.as_str())),
                computers
                    .iter()
                    .map(|k| format!("`{}`", k.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        self.error(
            "E0804",
            self.span(c),
            format!("{what} names an unknown computer `{}`", c.get_ref()),
            "no such computer",
            &help,
        );
    }
}

/// Arguments `petrel up` gives a player or a bridge itself, from fields of the file.
const SET_BY_UP: &[(&str, &str)] = &[
    (
        "--vehicle",
        "the vehicle is the file's [vehicle] name, or `petrel up --vehicle`",
    ),
    ("--wait", "use the process's `wait` field"),
    ("--journal", "use the process's `journal` field"),
    ("--no-journal", "write `journal = false`"),
    (
        "--resume",
        "`petrel up` resumes a restarted player from its journal by itself",
    ),
];

/// Checks a vehicle file's text. Findings go to `diags`; `None` when there is an error.
/// `project` (when the project checks clean) lets the programs and events be checked;
/// `can_program` is the program the CAN data server serves (can.toml's `[commands]`).
pub fn check_file(
    file: FileId,
    text: &str,
    project: Option<&CompiledProject>,
    can_program: Option<&str>,
    diags: &mut Diagnostics,
) -> Option<VehicleFile> {
    let raw: RawFile = match toml::from_str(text) {
        Ok(r) => r,
        Err(e) => {
            let (span, msg) = toml_error(file, &e);
            diags.push(
                Diagnostic::error("E0801", span, format!("vehicle.toml is not valid: {msg}"))
                    .label(msg)
                    .help("vehicle.toml has an optional [vehicle] table (name, logs, stop_grace), [computers.NAME] tables, [[process]] entries and [[send]] entries; see docs/vehicle.md"),
            );
            return None;
        }
    };
    let mut c = Checker {
        file,
        diags,
        errors: 0,
        project,
    };

    // [vehicle]
    let name =
        raw.vehicle
            .name
            .as_ref()
            .and_then(|n| match petrel_ipc::Vehicle::new(n.get_ref()) {
                Ok(_) => Some(n.get_ref().clone()),
                Err(e) => {
                    c.error(
                        "E0802",
                        c.span(n),
                        format!("`{}` is not a valid vehicle name: {e}", n.get_ref()),
                        "not a vehicle name",
                        "a vehicle name holds letters, digits and `_`",
                    );
                    None
                }
            });
    let logs = match &raw.vehicle.logs {
        Some(l) => {
            c.template(l, LOGS_VARS, "[vehicle] logs");
            l.get_ref().clone()
        }
        None => DEFAULT_LOGS.to_string(),
    };
    let stop_grace = raw
        .vehicle
        .stop_grace
        .as_ref()
        .and_then(|g| c.duration(g, "[vehicle] stop_grace"))
        .unwrap_or(DEFAULT_STOP_GRACE);

    // [computers.NAME]
    let mut computers = Vec::new();
    for (key, comp) in raw.computers.0 {
        if !is_process_name(key.get_ref()) {
            c.error(
                "E0802",
                c.span(&key),
                format!("`{}` is not a valid computer name", key.get_ref()),
                "not a name",
                "a computer name starts with a letter and holds letters, digits, `_` and `-`",
            );
        }
        computers.push(Computer {
            name: key.get_ref().clone(),
            address: comp.address,
            description: comp.description,
            gateway: comp.gateway,
        });
    }

    // [[process]]: names first, so that `after` can refer to a later entry.
    let mut seen: Vec<(String, Span)> = Vec::new();
    for p in &raw.processes {
        let n = p.name.get_ref();
        if !is_process_name(n) {
            c.error(
                "E0802",
                c.span(&p.name),
                format!("`{n}` is not a valid process name"),
                "not a name",
                "a process name starts with a letter and holds letters, digits, `_` and `-` (it names the process's log file)",
            );
        }
        if let Some((_, first)) = seen.iter().find(|(s, _)| s == n) {
            let first = *first;
            c.errors += 1;
            c.diags.push(
                Diagnostic::error(
                    "E0803",
                    c.span(&p.name),
                    format!("process `{n}` is declared twice"),
                )
                .label("second declaration")
                .related(first, "first declared here")
                .help("give each process its own name"),
            );
        } else {
            seen.push((n.clone(), c.span(&p.name)));
        }
    }
    let players: Vec<String> = raw
        .processes
        .iter()
        .filter(|p| p.kind.get_ref() == "player")
        .map(|p| p.name.get_ref().clone())
        .collect();
    if players.len() > 1 {
        let second = raw
            .processes
            .iter()
            .filter(|p| p.kind.get_ref() == "player")
            .nth(1)
            .map(|p| c.span(&p.kind))
            .unwrap_or(Span::new(file, 0, 0));
        c.error(
            "E0810",
            second,
            "a second player: a vehicle has one".into(),
            "second player",
            "a vehicle has one player (its events service takes one receiver); run a ground-station shadow as a command: executable = \"{petrel}\", args = [\"play\", \"{project}\", \"--shadow\", \"--vehicle\", \"{vehicle}\"]",
        );
    }
    let mut program_owner: Vec<(String, String, Span)> = Vec::new();
    let mut processes = Vec::new();
    for p in &raw.processes {
        let pname = p.name.get_ref().clone();
        let Some(kind) = Kind::parse(p.kind.get_ref()) else {
            c.error(
                "E0806",
                c.span(&p.kind),
                format!(
                    "process `{pname}` has an unknown kind `{}`",
                    p.kind.get_ref()
                ),
                "not a kind",
                "the kinds are player (petrel play), bridge (the CAN data server: petrel bridge, or the vehicle's own data server as `executable`), program (an executable running programs of the manifest) and command (any other executable)",
            );
            continue;
        };
        // The executable.
        let executable = match (&p.executable, kind) {
            (Some(e), Kind::Player) => {
                c.not_for_kind(
                    c.span(e),
                    "executable",
                    &pname,
                    kind,
                    "a player is the running `petrel` itself; for another build, use kind = \"command\" with executable = \"...\" and its arguments",
                );
                None
            }
            (Some(e), _) => {
                c.template(e, PROCESS_VARS, "`executable`");
                if e.get_ref().trim().is_empty() {
                    c.error(
                        "E0806",
                        c.span(e),
                        format!("process `{pname}` has an empty executable"),
                        "empty",
                        "a path relative to the project, an absolute path, a name looked up in PATH, or {target}/examples/NAME",
                    );
                }
                Some(e.get_ref().clone())
            }
            (None, Kind::Program | Kind::Command) => {
                c.error(
                    "E0805",
                    c.span(&p.kind),
                    format!("process `{pname}` (kind {}) has no `executable`", kind.as_str()),
                    "no executable",
                    "add executable = \"...\": a path relative to the project, an absolute path, a name looked up in PATH, or {target}/examples/NAME for a cargo example",
                );
                None
            }
            (None, _) => None,
        };
        for a in &p.args {
            c.template(a, PROCESS_VARS, "an argument");
            if matches!(kind, Kind::Player | Kind::Bridge) {
                let word = a.get_ref().split('=').next().unwrap_or("");
                if let Some((flag, help)) = SET_BY_UP.iter().find(|(f, _)| *f == word) {
                    c.error(
                        "E0811",
                        c.span(a),
                        format!("`{flag}` is given by `petrel up` itself"),
                        "set by petrel up",
                        help,
                    );
                }
            }
        }
        let mut env = Vec::new();
        for (k, v) in &p.env.0 {
            let key = k.get_ref();
            if key.is_empty() || key.contains(['=', '\0']) {
                c.error(
                    "E0802",
                    c.span(k),
                    format!("`{key}` is not an environment variable name"),
                    "not a variable name",
                    "a variable name is not empty and holds no `=`",
                );
            }
            c.template(v, PROCESS_VARS, "an environment value");
            env.push((key.clone(), v.get_ref().clone()));
        }
        // The computer.
        let computer = match &p.computer {
            Some(k) => {
                c.computer_ref(k, &computers, &format!("process `{pname}`"));
                Some(k.get_ref().clone())
            }
            None if !computers.is_empty() => {
                c.error(
                    "E0805",
                    c.span(&p.name),
                    format!("process `{pname}` names no computer"),
                    "which computer runs it?",
                    "the file declares [computers]: give every process `computer = \"NAME\"`",
                );
                None
            }
            None => None,
        };
        // The wait strategy.
        let wait = match (&p.wait, kind) {
            (Some(w), Kind::Player | Kind::Bridge) => {
                if let Err(e) = w.get_ref().parse::<petrel_ipc::WaitStrategy>() {
                    c.error(
                        "E0806",
                        c.span(w),
                        e,
                        "not a wait strategy",
                        "write block, spin, or spin-then-block:<microseconds>",
                    );
                }
                Some(w.get_ref().clone())
            }
            (Some(w), _) => {
                c.not_for_kind(
                    c.span(w),
                    "wait",
                    &pname,
                    kind,
                    "`wait` is passed to petrel play or petrel bridge as --wait; give another executable its own flag in `args`",
                );
                None
            }
            (None, _) => None,
        };
        // The programs it runs.
        let mut programs = Vec::new();
        match (&p.programs, kind) {
            (Some(list), Kind::Program) => {
                if list.get_ref().is_empty() {
                    c.error(
                        "E0805",
                        c.span(list),
                        format!("process `{pname}` runs no program"),
                        "empty",
                        "name the manifest's programs it joins the vehicle as: programs = [\"GUI\"]",
                    );
                }
                for prog in list.get_ref() {
                    let pn = prog.get_ref();
                    if let Some(proj) = project {
                        if !proj.programs.iter().any(|x| &x.name == pn) {
                            let help = format!(
                                "{}the manifest's programs are {}",
                                suggest(pn, proj.programs.iter().map(|x| x.name.as_str())),
                                proj.programs
                                    .iter()
                                    .map(|x| format!("`{}`", x.name))
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            );
                            c.error(
                                "E0804",
                                c.span(prog),
                                format!("process `{pname}` runs `{pn}`, which the manifest does not declare"),
                                "no such program",
                                &help,
                            );
                        }
                    }
                    if let Some((_, owner, first)) =
                        program_owner.iter().find(|(x, _, _)| x == pn)
                    {
                        let (owner, first) = (owner.clone(), *first);
                        c.errors += 1;
                        c.diags.push(
                            Diagnostic::error(
                                "E0810",
                                c.span(prog),
                                format!("program `{pn}` is run by `{owner}` and by `{pname}`"),
                            )
                            .label("second process")
                            .related(first, "first here")
                            .help("a program has one process (its calls service takes one receiver)"),
                        );
                    } else {
                        program_owner.push((pn.clone(), pname.clone(), c.span(prog)));
                    }
                    programs.push(pn.clone());
                }
            }
            (None, Kind::Program) => c.error(
                "E0805",
                c.span(&p.kind),
                format!("process `{pname}` (kind program) names no programs"),
                "which programs?",
                "name the manifest's programs it joins the vehicle as: programs = [\"GUI\", \"PLD\"]; an executable that runs none is kind = \"command\"",
            ),
            (Some(list), _) => c.not_for_kind(
                c.span(list),
                "programs",
                &pname,
                kind,
                "only a process of kind program runs programs of the manifest",
            ),
            (None, _) => {}
        }
        // Dependencies: by default, everything after the player.
        let after = match &p.after {
            Some(list) => {
                let mut out = Vec::new();
                for a in list.get_ref() {
                    let an = a.get_ref();
                    if an == &pname {
                        c.error(
                            "E0807",
                            c.span(a),
                            format!("process `{pname}` waits for itself"),
                            "itself",
                            "remove it from `after`",
                        );
                    } else if !seen.iter().any(|(s, _)| s == an) {
                        let help = format!(
                            "{}`after` names processes of this file",
                            suggest(an, seen.iter().map(|(s, _)| s.as_str()))
                        );
                        c.error(
                            "E0804",
                            c.span(a),
                            format!("process `{pname}` comes after `{an}`, which is not a process of this file"),
                            "no such process",
                            &help,
                        );
                    } else {
                        out.push(an.clone());
                    }
                }
                out
            }
            None if kind == Kind::Player => Vec::new(),
            None => players.clone(),
        };
        // Restarts.
        let policy = p.restart.as_ref().map(|r| r.get_ref().as_str());
        let restart = match policy {
            None | Some("never") => {
                for (field, span) in [
                    ("max_restarts", p.max_restarts.as_ref().map(|m| c.span(m))),
                    ("backoff", p.backoff.as_ref().map(|b| c.span(b))),
                ] {
                    if let Some(span) = span {
                        c.error(
                            "E0805",
                            span,
                            format!("`{field}` of process `{pname}`, which is never restarted"),
                            "no restarts",
                            "write restart = \"on-failure\" to restart it, or remove this field",
                        );
                    }
                }
                Restart::Never
            }
            Some("on-failure") => {
                let max = match &p.max_restarts {
                    None => DEFAULT_MAX_RESTARTS,
                    Some(m) => match u32::try_from(*m.get_ref()) {
                        Ok(n) if n >= 1 => n,
                        _ => {
                            c.error(
                                "E0806",
                                c.span(m),
                                format!("max_restarts = {} for process `{pname}`", m.get_ref()),
                                "not a count of restarts",
                                "write a whole number of at least 1 (or restart = \"never\")",
                            );
                            DEFAULT_MAX_RESTARTS
                        }
                    },
                };
                let backoff = p
                    .backoff
                    .as_ref()
                    .and_then(|b| c.duration(b, "`backoff`"))
                    .unwrap_or(DEFAULT_BACKOFF);
                Restart::OnFailure { max, backoff }
            }
            Some(other) => {
                let span = p
                    .restart
                    .as_ref()
                    .map(|r| c.span(r))
                    .unwrap_or(Span::new(file, 0, 0));
                c.error(
                    "E0806",
                    span,
                    format!("process `{pname}` has an unknown restart policy `{other}`"),
                    "not a policy",
                    "write restart = \"never\" or restart = \"on-failure\" (with max_restarts and backoff)",
                );
                Restart::Never
            }
        };
        let ready_timeout = p
            .ready_timeout
            .as_ref()
            .and_then(|d| c.duration(d, "`ready_timeout`"))
            .unwrap_or(DEFAULT_READY_TIMEOUT);
        let own_grace = p
            .stop_grace
            .as_ref()
            .and_then(|d| c.duration(d, "`stop_grace`"))
            .unwrap_or(stop_grace);
        let journal = match (&p.journal, kind) {
            (None, _) => Journal::Default,
            (Some(j), Kind::Player) => match j.get_ref() {
                RawJournal::On(true) => Journal::Default,
                RawJournal::On(false) => Journal::Off,
                RawJournal::Path(path) => {
                    let t = Spanned::new(j.span(), path.clone());
                    c.template(&t, PROCESS_VARS, "`journal`");
                    Journal::Path(path.clone())
                }
            },
            (Some(j), _) => {
                c.not_for_kind(
                    c.span(j),
                    "journal",
                    &pname,
                    kind,
                    "only the player keeps a journal",
                );
                Journal::Default
            }
        };
        let critical = match (&p.critical, kind) {
            (Some(v), Kind::Player) if !v.get_ref() => {
                c.not_for_kind(
                    c.span(v),
                    "critical = false",
                    &pname,
                    kind,
                    "nothing runs without the player: its failure always stops the vehicle",
                );
                true
            }
            (_, Kind::Player) => true,
            (Some(v), _) => *v.get_ref(),
            (None, _) => false,
        };
        processes.push(ProcessSpec {
            name: pname,
            kind,
            executable,
            args: p.args.iter().map(|a| a.get_ref().clone()).collect(),
            env,
            computer,
            wait,
            programs,
            after,
            restart,
            ready_timeout,
            stop_grace: own_grace,
            journal,
            critical,
        });
    }
    // Cycles among `after` (self-references are reported above).
    if c.errors == 0 {
        if let Some(cycle) = find_cycle(&processes) {
            let first = raw
                .processes
                .iter()
                .find(|p| p.name.get_ref() == &cycle[0])
                .and_then(|p| p.after.as_ref().map(|a| c.span(a)))
                .unwrap_or(Span::new(file, 0, 0));
            c.error(
                "E0807",
                first,
                format!(
                    "the processes wait for each other: {} -> {}",
                    cycle.join(" -> "),
                    cycle[0]
                ),
                "a cycle of `after`",
                "break the cycle: `after` lists what must be ready before a process starts",
            );
        }
    }
    // Programs of the manifest nobody runs: their calls would fail.
    if let Some(proj) = project {
        if !raw.processes.is_empty() {
            for prog in &proj.programs {
                let served = program_owner.iter().any(|(x, _, _)| x == &prog.name)
                    || (can_program == Some(prog.name.as_str())
                        && processes.iter().any(|p| p.kind == Kind::Bridge));
                if !served {
                    c.diags.push(
                        Diagnostic::warning(
                            "W0801",
                            Span::new(file, 0, 0),
                            format!("no process of vehicle.toml runs program `{}`", prog.name),
                        )
                        .label("in this file")
                        .help(format!(
                            "calls to {} will fail (call_failed) unless it is started some other way; add a [[process]] of kind program with programs = [\"{}\"]",
                            prog.name, prog.name
                        )),
                    );
                }
            }
        }
    }
    // [[send]]
    let default_computer = processes
        .iter()
        .find(|p| p.kind == Kind::Player)
        .and_then(|p| p.computer.clone());
    let mut sends = Vec::new();
    for s in &raw.sends {
        if let Some(k) = &s.computer {
            c.computer_ref(k, &computers, "a [[send]]");
        }
        if let Some(mut spec) = c.send(s) {
            if spec.computer.is_none() {
                spec.computer = default_computer.clone();
            }
            sends.push(spec);
        }
    }
    sends.sort_by_key(|s| s.at);
    let link = match &raw.link {
        Some(l) => c.link(l, &computers),
        None => LinkSpec::default(),
    };
    if c.errors > 0 {
        return None;
    }
    Some(VehicleFile {
        name,
        logs,
        computers,
        processes,
        sends,
        link,
    })
}

/// A cycle of `after` dependencies, as the names along it, if there is one.
fn find_cycle(processes: &[ProcessSpec]) -> Option<Vec<String>> {
    // 0 unvisited, 1 on the current path, 2 done.
    let mut mark = vec![0u8; processes.len()];
    let index = |n: &str| processes.iter().position(|p| p.name == n);
    fn visit(
        i: usize,
        processes: &[ProcessSpec],
        mark: &mut [u8],
        path: &mut Vec<usize>,
        index: &dyn Fn(&str) -> Option<usize>,
    ) -> Option<Vec<String>> {
        mark[i] = 1;
        path.push(i);
        for a in &processes[i].after {
            let Some(j) = index(a) else { continue };
            if mark[j] == 1 {
                let from = path.iter().position(|&k| k == j).unwrap_or(0);
                return Some(
                    path[from..]
                        .iter()
                        .map(|&k| processes[k].name.clone())
                        .collect(),
                );
            }
            if mark[j] == 0 {
                if let Some(c) = visit(j, processes, mark, path, index) {
                    return Some(c);
                }
            }
        }
        path.pop();
        mark[i] = 2;
        None
    }
    for i in 0..processes.len() {
        if mark[i] == 0 {
            let mut path = Vec::new();
            if let Some(c) = visit(i, processes, &mut mark, &mut path, &index) {
                return Some(c);
            }
        }
    }
    None
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
    Ok(check_file(file, &text, project, can_program, diags))
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
    let raw: RawScenario = match toml::from_str(&text) {
        Ok(r) => r,
        Err(e) => {
            let (span, msg) = toml_error(file, &e);
            diags.push(
                Diagnostic::error("E0801", span, format!("the scenario is not valid: {msg}"))
                    .label(msg)
                    .help("a scenario file holds [[send]] entries (at, event, and optionally computer); see docs/vehicle.md"),
            );
            return Ok(None);
        }
    };
    let mut c = Checker {
        file,
        diags,
        errors: 0,
        project: Some(project),
    };
    let default_computer = vehicle
        .processes
        .iter()
        .find(|p| p.kind == Kind::Player)
        .and_then(|p| p.computer.clone());
    let mut sends = Vec::new();
    for s in &raw.sends {
        if let Some(k) = &s.computer {
            c.computer_ref(k, &vehicle.computers, "a [[send]]");
        }
        if let Some(mut spec) = c.send(s) {
            if spec.computer.is_none() {
                spec.computer = default_computer.clone();
            }
            sends.push(spec);
        }
    }
    sends.sort_by_key(|s| s.at);
    Ok((c.errors == 0).then_some(sends))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(text: &str) -> (Option<VehicleFile>, Diagnostics, SourceMap) {
        let mut sources = SourceMap::default();
        let file = sources.add("vehicle.toml", text);
        let mut d = Diagnostics::new();
        let v = check_file(file, text, None, None, &mut d);
        (v, d, sources)
    }

    fn codes(d: &Diagnostics) -> Vec<&'static str> {
        d.iter().map(|x| x.code).collect()
    }

    #[test]
    fn substitutions_expand_and_escape() {
        let var = |n: &str| (n == "vehicle").then(|| "uav1".to_string());
        assert_eq!(expand("a-{vehicle}-b", &var).unwrap(), "a-uav1-b");
        assert_eq!(expand("{{x}} }}", &var).unwrap(), "{x} }");
        assert!(expand("{nope}", &var).unwrap_err().contains("{nope}"));
        assert!(expand("{vehicle", &var).is_err());
        assert!(expand("x}", &var).is_err());
    }

    #[test]
    fn a_complete_file_reads() {
        let (v, d, _) = check(
            r#"
[vehicle]
name = "uav1"
logs = "runs/{vehicle}-{time}"
stop_grace = "2s"

[computers.avionics]
address = "10.0.0.2"

[[process]]
name = "player"
kind = "player"
computer = "avionics"
wait = "spin-then-block:200"
restart = "on-failure"
max_restarts = 2
backoff = "100ms"

[[process]]
name = "gui"
kind = "program"
programs = ["GUI", "PLD"]
computer = "avionics"
executable = "{target}/uav-gui"
args = ["--vehicle", "{vehicle}"]
env = { RUST_LOG = "info" }

[[process]]
name = "logger"
kind = "command"
computer = "avionics"
executable = "sh"
args = ["-c", "echo {{braces}}"]
after = []
"#,
        );
        assert!(d.is_empty(), "{d:?}");
        let v = v.unwrap();
        assert_eq!(v.name.as_deref(), Some("uav1"));
        assert_eq!(v.processes.len(), 3);
        assert_eq!(v.processes[1].after, vec!["player".to_string()]);
        assert!(v.processes[2].after.is_empty());
        assert!(v.processes[0].critical && !v.processes[1].critical);
        assert_eq!(
            v.processes[0].restart,
            Restart::OnFailure {
                max: 2,
                backoff: Duration::from_millis(100)
            }
        );
        assert_eq!(v.processes[1].stop_grace, Duration::from_secs(2));
    }

    /// A bridge may be the vehicle's own data server (its simulator with it); a player is
    /// always the running petrel.
    #[test]
    fn a_bridge_may_name_its_executable_and_a_player_may_not() {
        let (v, d, _) = check(
            r#"
[[process]]
name = "player"
kind = "player"

[[process]]
name = "can"
kind = "bridge"
executable = "{target}/auv-bridge"
args = ["--bus", "memory", "--leak-at", "5"]
"#,
        );
        assert!(d.is_empty(), "{d:?}");
        let can = &v.unwrap().processes[1];
        assert_eq!(can.executable.as_deref(), Some("{target}/auv-bridge"));
        let (v, d, _) = check(
            "[[process]]\nname = \"player\"\nkind = \"player\"\nexecutable = \"{target}/petrel\"\n",
        );
        assert!(v.is_none());
        assert_eq!(codes(&d), ["E0805"]);
        // An empty one is refused as any process's.
        let (v, d, _) = check(
            "[[process]]\nname = \"p\"\nkind = \"player\"\n[[process]]\nname = \"can\"\nkind = \"bridge\"\nexecutable = \" \"\n",
        );
        assert!(v.is_none());
        assert_eq!(codes(&d), ["E0806"]);
    }

    #[test]
    fn every_error_is_reported_with_its_place() {
        let (v, d, sources) = check(
            r#"
[[process]]
name = "player"
kind = "player"
executable = "x"
args = ["--vehicle", "v"]

[[process]]
name = "gui"
kind = "progam"

[[process]]
name = "dec"
kind = "program"
executable = "{target}/examples/{nope}"
after = ["playr"]
restart = "sometimes"

[[process]]
name = "dec"
kind = "command"
executable = "true"
computer = "avionics"
wait = "block"
backoff = "1s"
"#,
        );
        assert!(v.is_none());
        let c = codes(&d);
        for code in ["E0805", "E0806", "E0808", "E0804", "E0811", "E0803"] {
            assert!(c.contains(&code), "{code} missing: {c:?}");
        }
        let text = d.render_human(&sources);
        assert!(text.contains("vehicle.toml:10:8"), "{text}");
        assert!(text.contains("did you mean `player`?"), "{text}");
    }

    #[test]
    fn cycles_are_found() {
        let (v, d, _) = check(
            r#"
[[process]]
name = "a"
kind = "command"
executable = "true"
after = ["b"]

[[process]]
name = "b"
kind = "command"
executable = "true"
after = ["a"]
"#,
        );
        assert!(v.is_none());
        let e = d.iter().next().unwrap();
        assert_eq!(e.code, "E0807");
        assert!(e.message.contains("a -> b -> a"), "{}", e.message);
    }

    #[test]
    fn toml_errors_and_unknown_keys_point_at_the_line() {
        let (_, d, sources) =
            check("[[process]]\nname = \"a\"\nkind = \"command\"\nexecutabel = \"x\"\n");
        assert_eq!(codes(&d), vec!["E0801"]);
        let text = d.render_human(&sources);
        assert!(text.contains("vehicle.toml:4:1"), "{text}");
    }

    #[test]
    fn declared_computers_need_every_process_to_name_one() {
        let (v, d, _) = check(
            "[computers.a]\n[[process]]\nname = \"x\"\nkind = \"command\"\nexecutable = \"true\"\n",
        );
        assert!(v.is_none());
        assert_eq!(codes(&d), vec!["E0805"]);
    }

    #[test]
    fn the_link_table_is_checked() {
        let (v, d, _) = check("[link]\ndetection = \"1s\"\n");
        assert!(v.is_none());
        assert_eq!(codes(&d), vec!["E0812"], "no computers to link");
        let base = "[computers.a]\ngateway = \"tcp/127.0.0.1:7447\"\n[computers.b]\n";
        let (v, d, _) = check(&format!("{base}[link]\nuser = \"petrel\"\n"));
        assert!(v.is_none());
        assert_eq!(codes(&d), vec!["E0812"], "a user without credentials");
        let (v, d, _) = check(&format!(
            "{base}[link]\nuser = \"petrel\"\ncredentials = \"/etc/shadow\"\n"
        ));
        assert!(v.is_none());
        assert_eq!(codes(&d), vec!["E0812"], "credentials outside the project");
        let (v, d, _) = check(&format!("{base}[link]\nsecurity = \"none\"\n"));
        assert!(
            v.is_some_and(|v| v.link.insecure) && codes(&d) == ["W0802"],
            "{d:?}"
        );
        let (v, d, _) = check(&format!("{base}[link]\nsecurity = \"ssl\"\n"));
        assert!(v.is_none() && codes(&d) == ["E0812"], "{d:?}");
        let (v, d, _) = check(&format!(
            "{base}[link]\ndetection = \"250ms\"\nuser = \"petrel\"\ncredentials = \"link.txt\"\n"
        ));
        let v = v.unwrap_or_else(|| panic!("{d:?}"));
        assert_eq!(v.link.detection, Some(Duration::from_millis(250)));
        assert!(!v.link.insecure, "secured by default");
        let (v, d, _) = check(&format!("{base}[link]\nretention = \"1s\"\n"));
        assert!(v.is_none());
        assert_eq!(
            codes(&d),
            vec!["E0812"],
            "retention not longer than detection"
        );
        let (v, d, _) = check(&format!(
            "{base}[link]\ndetection = \"250ms\"\nretention = \"10s\"\n"
        ));
        let v = v.unwrap_or_else(|| panic!("{d:?}"));
        assert_eq!(v.link.retention, Some(Duration::from_secs(10)));
        assert_eq!(
            v.computers[0].gateway.as_deref(),
            Some("tcp/127.0.0.1:7447")
        );
    }
}
