//! `petrel up`: one command brings a vehicle up from its vehicle file.
//!
//! - [`file`]: `vehicle.toml` (processes, computers, timed sends) and scenario files, checked
//!   with diagnostics (E08xx), as `petrel check` reports them;
//! - this module: the command line, and the plan of a run (which processes on this computer,
//!   their executables and arguments expanded, the run directory);
//! - [`supervise`]: the supervisor that starts, watches, restarts and stops the processes;
//! - [`display`]: the status lines; [`signals`]: stop requests and children's ends;
//!   `build_hint`: the cargo command for a missing executable of the running petrel's build;
//!   [`notify`]: systemd's readiness and watchdog notifications.

mod build_hint;
pub mod display;
pub mod file;
pub mod notify;
pub mod signals;
pub mod supervise;

use crate::common::{require_clean, Outcome, Scope};
use file::{expand, Journal, Kind, ProcessSpec, SendSpec, VehicleFile};
use petrel_diag::source::SourceMap;
use petrel_nets::compiled::CompiledProject;
use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// `petrel up`.
#[derive(clap::Args)]
pub struct UpArgs {
    /// The project directory (petrel.toml and vehicle.toml).
    dir: PathBuf,
    /// The vehicle (its services are petrel/<vehicle>/...); default: vehicle.toml's
    /// [vehicle] name, else the project's name.
    #[arg(long)]
    vehicle: Option<String>,
    /// The run directory: each process's log (<process>.log) and the player's journal
    /// (journal/); default: vehicle.toml's [vehicle] logs, run/<vehicle>-<time> in the project.
    #[arg(long, value_name = "DIR")]
    logs: Option<PathBuf>,
    /// Start only this computer's processes (and make only its timed sends).
    #[arg(long, value_name = "NAME")]
    computer: Option<String>,
    /// Bring up the vehicle this file describes instead of the project's vehicle.toml (a
    /// variant of it: another bus, other computers), e.g. missions/redermor/vehicle-vcan.toml.
    #[arg(long, value_name = "FILE")]
    file: Option<PathBuf>,
    /// Take the timed sends from this file ([[send]] entries) instead of vehicle.toml's.
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// Stop everything (exit 0) once the player has taken this event, or once this place
    /// (NET.place, or global.NAME) is marked. Repeat it: the first one reached ends the run.
    #[arg(long, value_name = "EVENT|NET.place")]
    until: Vec<String>,
    /// Stop everything and exit 1 if the run has not ended after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    timeout: Option<f64>,
    /// Keep the vehicle up after the mission's end (a final marking of the manifest's
    /// [verify], or a catastrophic event): stop it with Ctrl-C, --until or --timeout.
    #[arg(long)]
    keep_running: bool,
    /// A process that fails for good (no restart left) stops the whole vehicle, as the
    /// player's failure always does (for benches and CI).
    #[arg(long)]
    fail_fast: bool,
}

/// `petrel __exec`: how `petrel up` starts each process.
#[derive(clap::Args)]
pub struct ExecArgs {
    /// The executable.
    program: PathBuf,
    /// Its arguments.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    args: Vec<std::ffi::OsString>,
}

/// Becomes `program` with every signal unblocked.
///
/// `petrel up` reads its stop signals from a signalfd, which needs them blocked, and a blocked
/// mask survives fork and exec: a process started straight from it would never see SIGTERM.
/// Setting a child's mask between fork and exec takes `unsafe` code (`pre_exec`), which the
/// workspace forbids outside ipc; going through this small step costs one exec.
pub fn exec(a: ExecArgs) -> Outcome {
    use std::os::unix::process::CommandExt;
    if let Err(e) = nix::sys::signal::SigSet::empty().thread_set_mask() {
        return Outcome::Usage(format!("cannot unblock the signals: {e}"));
    }
    let e = std::process::Command::new(&a.program).args(&a.args).exec();
    Outcome::Usage(format!("cannot start {}: {e}", a.program.display()))
}

/// A condition that ends the run with success.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Until {
    /// The player took this event (a step of its journal).
    Event(String),
    /// This place (`NET.place` or `global.NAME`) is marked.
    Place(String),
}

impl std::fmt::Display for Until {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Until::Event(e) => write!(f, "event `{e}` taken by the player"),
            Until::Place(p) => write!(f, "place `{p}` marked"),
        }
    }
}

/// Reads `--until`: `NET.place` or `global.NAME` is a place, anything else an event; both
/// checked against the project.
fn parse_until(text: &str, c: &CompiledProject) -> Result<Until, String> {
    if let Some((net, place)) = text.split_once('.') {
        let known = if net == "global" {
            c.globals.iter().any(|g| g.name == place)
        } else {
            c.net_id(net)
                .is_some_and(|n| c.nets[n as usize].places.iter().any(|p| p.name == place))
        };
        if !known {
            return Err(format!(
                "--until {text}: no place `{place}` in {}",
                if net == "global" {
                    "the manifest's [globals]".to_string()
                } else if c.net_id(net).is_some() {
                    format!("net `{net}`")
                } else {
                    format!("the project (no net `{net}`)")
                }
            ));
        }
        Ok(Until::Place(text.to_string()))
    } else if c.event_id(text).is_some() {
        Ok(Until::Event(text.to_string()))
    } else {
        Err(format!(
            "--until {text}: not an event of the project, nor a place (write NET.place or global.NAME)"
        ))
    }
}

/// One process as this run starts it: everything expanded and resolved.
#[derive(Clone, Debug)]
pub struct Planned {
    /// The vehicle file's entry.
    pub spec: ProcessSpec,
    /// The executable, resolved to a path.
    pub program: PathBuf,
    /// The arguments, expanded (for a player or a bridge: the whole `petrel` command line).
    pub args: Vec<String>,
    /// Environment variables, expanded.
    pub env: Vec<(String, String)>,
    /// Indices (in the plan) of the processes it waits for; processes of other computers are
    /// not waited for.
    pub after: Vec<usize>,
    /// Its log file.
    pub log: PathBuf,
    /// The player's journal, when it keeps one (a restart resumes from it).
    pub journal: Option<PathBuf>,
}

/// Everything a run needs, decided before the first process starts.
pub struct RunPlan {
    /// The vehicle.
    pub vehicle: petrel_ipc::Vehicle,
    /// The computer this run is for (`--computer`), if the vehicle file declares computers.
    pub computer: Option<file::Computer>,
    /// The project, compiled.
    pub project: CompiledProject,
    /// The project directory, absolute.
    pub project_dir: PathBuf,
    /// The run directory (logs, journal), absolute and created.
    pub run_dir: PathBuf,
    /// The processes of this computer, dependencies first.
    pub processes: Vec<Planned>,
    /// The timed sends, `--until`, `--timeout`, the final markings, `--keep-running`,
    /// `--fail-fast`.
    pub rules: supervise::policy::Rules,
}

/// Brings the vehicle up, supervises it, and brings it down.
pub fn up(a: UpArgs) -> Outcome {
    let start = std::time::Instant::now();
    let plan = match plan(a) {
        Ok(p) => p,
        Err(o) => return o,
    };
    supervise::run(plan, start)
}

/// The current time as `YYYYMMDD-HHMMSS` (UTC), for run directory names.
fn timestamp() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    // Days to a civil date (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}{month:02}{day:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// An absolute path (for children, which run in the run directory).
fn absolute(p: &Path) -> Result<PathBuf, Outcome> {
    std::path::absolute(p)
        .map_err(|e| Outcome::Usage(format!("cannot resolve {}: {e}", p.display())))
}

fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

/// Resolves an executable: a path with a `/` is taken relative to the project directory, a
/// bare name is looked up in PATH. A missing build output of the running petrel's directory
/// (`target`, the `{target}` of vehicle files) gets the cargo command that builds it.
fn resolve_executable(
    text: &str,
    project_dir: &Path,
    process: &str,
    target: &Path,
) -> Result<PathBuf, String> {
    if text.contains('/') {
        let path = project_dir.join(text);
        if is_executable(&path) {
            return Ok(path);
        }
        let why = if path.exists() {
            "is not an executable file"
        } else {
            "does not exist"
        };
        let hint = if path.exists() {
            None
        } else {
            build_hint::hint(&path, target, project_dir)
        };
        return Err(format!(
            "process `{process}`: {} {why}{}",
            path.display(),
            hint.map(|h| format!("; {h}")).unwrap_or_default()
        ));
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|d| d.join(text))
        .find(|p| is_executable(p))
        .ok_or_else(|| format!("process `{process}`: `{text}` is not found in PATH"))
}

/// Refuses to start a process whose node already lives on the vehicle (a player, a bridge or
/// a program of another run): the second would fail to join, or steal the first one's calls.
fn refuse_running(vehicle: &petrel_ipc::Vehicle, processes: &[ProcessSpec]) -> Result<(), Outcome> {
    let nodes = petrel_ipc::list_nodes(vehicle).map_err(|e| Outcome::Usage(e.to_string()))?;
    let mut clashes = Vec::new();
    for p in processes {
        let names: Vec<String> = match p.kind {
            Kind::Player => vec![petrel_ipc::Role::Player.node_name()],
            Kind::Bridge => vec![petrel_ipc::Role::CanBridge.node_name()],
            Kind::Program => p
                .programs
                .iter()
                .map(|x| petrel_ipc::naming::program_node_name(x))
                .collect(),
            Kind::Command => vec![],
        };
        for n in nodes
            .iter()
            .filter(|n| n.status == petrel_ipc::NodeStatus::Alive && names.contains(&n.name))
        {
            clashes.push(format!(
                "`{}` (pid {}) for process `{}`",
                n.name,
                n.pid.map(|p| p.to_string()).unwrap_or_else(|| "?".into()),
                p.name
            ));
        }
    }
    if clashes.is_empty() {
        return Ok(());
    }
    Err(Outcome::Usage(format!(
        "vehicle `{}` is already running {}: stop it first, or bring up another vehicle with --vehicle",
        vehicle.name(),
        clashes.join(", ")
    )))
}

/// The processes in dependency order (file order among equals).
fn order(selected: &[ProcessSpec]) -> Vec<usize> {
    let mut done: Vec<bool> = vec![false; selected.len()];
    let mut out = Vec::new();
    // The file has no cycle (checked): each round places at least one process.
    while out.len() < selected.len() {
        let before = out.len();
        for (i, p) in selected.iter().enumerate() {
            if done[i] {
                continue;
            }
            let ready = p.after.iter().all(|a| {
                selected
                    .iter()
                    .position(|q| &q.name == a)
                    .is_none_or(|j| done[j])
            });
            if ready {
                done[i] = true;
                out.push(i);
            }
        }
        if out.len() == before {
            // Not reachable with a checked file; never loop forever.
            out.extend((0..selected.len()).filter(|&i| !done[i]));
            break;
        }
    }
    out
}

/// Reads, checks and resolves everything before anything starts.
fn plan(a: UpArgs) -> Result<RunPlan, Outcome> {
    let checked = require_clean(
        &a.dir,
        Scope {
            can: true,
            quick_verify: false,
            vehicle: a.file.is_none(),
            map: true,
        },
        "up",
    )?;
    let mut sources = checked.loaded.sources;
    let c = checked
        .compiled
        .ok_or_else(|| Outcome::Usage("the project did not compile".into()))?;
    let can_program = checked
        .can
        .as_ref()
        .and_then(|(config, _)| config.commands.program.as_deref());
    let file = vehicle_file(&a, checked.vehicle, &c, can_program, &mut sources)?;
    let sends = scenario(&a, &c, &file, &mut sources)?;
    let name = a
        .vehicle
        .clone()
        .or_else(|| file.name.clone())
        .unwrap_or_else(|| c.name.clone());
    let vehicle = petrel_ipc::Vehicle::new(&name)
        .map_err(|e| Outcome::Usage(format!("bad vehicle name `{name}`: {e}")))?;
    let (selected, sends) = select_processes(&a, &file, sends)?;
    let until = a
        .until
        .iter()
        .map(|u| parse_until(u, &c))
        .collect::<Result<Vec<_>, _>>()
        .map_err(Outcome::Usage)?;
    let timeout = match a.timeout {
        None => None,
        Some(s) => match Duration::try_from_secs_f64(s) {
            Ok(d) if s > 0.0 => Some(d),
            _ => {
                return Err(Outcome::Usage(format!(
                    "--timeout takes a positive number of seconds, not {s:?}"
                )))
            }
        },
    };
    // Before the run directory is made: a refused run leaves nothing behind.
    refuse_running(&vehicle, &selected)?;
    let project_dir = absolute(&a.dir)?;
    let run_dir = run_directory(&a, &file, &project_dir, vehicle.name())?;
    let petrel = std::env::current_exe()
        .map_err(|e| Outcome::Usage(format!("cannot find the running petrel: {e}")))?;
    let target = petrel
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let places = Places {
        vehicle: vehicle.name(),
        project_dir: &project_dir,
        run_dir: &run_dir,
        target: &target,
        petrel: &petrel,
    };
    let processes = resolve_processes(&selected, &places)?;
    let finals = c
        .finals
        .iter()
        .map(|f| f.iter().map(|&(n, p)| c.place_name(n, p)).collect())
        .collect();
    let computer = a
        .computer
        .as_ref()
        .and_then(|k| file.computers.iter().find(|x| &x.name == k).cloned());
    Ok(RunPlan {
        vehicle,
        computer,
        project: c,
        project_dir,
        run_dir,
        processes,
        rules: supervise::policy::Rules {
            sends,
            until,
            timeout,
            finals,
            keep_running: a.keep_running,
            fail_fast: a.fail_fast,
        },
    })
}

/// The vehicle file: `--file`, checked here (it must check clean), or the project's
/// vehicle.toml, checked with the project.
fn vehicle_file(
    a: &UpArgs,
    checked: Option<VehicleFile>,
    c: &CompiledProject,
    can_program: Option<&str>,
    sources: &mut SourceMap,
) -> Result<VehicleFile, Outcome> {
    let vehicle_file = match &a.file {
        None => checked,
        Some(path) => {
            let mut d = petrel_diag::report::Diagnostics::new();
            let read = file::load_file(path, Some(c), can_program, sources, &mut d)
                .map_err(|e| Outcome::Usage(format!("cannot read {}: {e}", path.display())))?;
            crate::common::report(&d, sources);
            if d.has_errors() {
                eprintln!(
                    "fix the errors above first: `petrel up` needs a vehicle file that checks clean"
                );
                return Err(Outcome::Errors);
            }
            read
        }
    };
    vehicle_file.ok_or_else(|| {
        Outcome::Usage(format!(
            "{} has no vehicle.toml: write one to say which processes make up the vehicle (docs/vehicle.md)",
            a.dir.display()
        ))
    })
}

/// The timed sends: `--scenario`'s (it must read whole), or the vehicle file's.
fn scenario(
    a: &UpArgs,
    c: &CompiledProject,
    file: &VehicleFile,
    sources: &mut SourceMap,
) -> Result<Vec<SendSpec>, Outcome> {
    let Some(path) = &a.scenario else {
        return Ok(file.sends.clone());
    };
    let mut d = petrel_diag::report::Diagnostics::new();
    let read = file::load_scenario(path, c, file, sources, &mut d)
        .map_err(|e| Outcome::Usage(format!("cannot read {}: {e}", path.display())))?;
    crate::common::report(&d, sources);
    read.ok_or_else(|| {
        eprintln!("fix the scenario first: `petrel up` needs every send to read");
        Outcome::Errors
    })
}

/// The processes and the timed sends of this computer (`--computer`, a computer of the file),
/// or all of them.
fn select_processes(
    a: &UpArgs,
    file: &VehicleFile,
    mut sends: Vec<SendSpec>,
) -> Result<(Vec<ProcessSpec>, Vec<SendSpec>), Outcome> {
    if let Some(k) = &a.computer {
        if !file.computers.iter().any(|x| &x.name == k) {
            let known: Vec<String> = file
                .computers
                .iter()
                .map(|x| format!("`{}`", x.name))
                .collect();
            return Err(Outcome::Usage(if known.is_empty() {
                format!("--computer {k}: vehicle.toml declares no computers (without [computers] the vehicle is one computer: leave --computer out)")
            } else {
                format!(
                    "--computer {k}: not a computer of vehicle.toml; they are {}",
                    known.join(", ")
                )
            }));
        }
    }
    let on_this = |computer: &Option<String>| match (&a.computer, computer) {
        (None, _) => true,
        (Some(k), Some(x)) => k == x,
        (Some(_), None) => false,
    };
    let selected: Vec<ProcessSpec> = file
        .processes
        .iter()
        .filter(|p| on_this(&p.computer))
        .cloned()
        .collect();
    if selected.is_empty() {
        return Err(Outcome::Usage(match &a.computer {
            Some(k) => format!("no process of vehicle.toml runs on computer `{k}`"),
            None => "vehicle.toml has no [[process]]: nothing to bring up".into(),
        }));
    }
    sends.retain(|s| on_this(&s.computer));
    Ok((selected, sends))
}

/// Where a run's processes find things: the values of the substitutions.
struct Places<'a> {
    vehicle: &'a str,
    project_dir: &'a Path,
    run_dir: &'a Path,
    /// The running petrel's directory (`{target}`).
    target: &'a Path,
    petrel: &'a Path,
}

/// The selected processes, dependencies first, each resolved and expanded; every problem is
/// reported at once.
fn resolve_processes(selected: &[ProcessSpec], places: &Places) -> Result<Vec<Planned>, Outcome> {
    let mut processes: Vec<Planned> = Vec::new();
    let mut problems = Vec::new();
    for i in order(selected) {
        match resolve_process(&selected[i], places) {
            Ok(mut planned) => {
                planned.after = planned
                    .spec
                    .after
                    .iter()
                    .filter_map(|n| processes.iter().position(|p| &p.spec.name == n))
                    .collect();
                processes.push(planned);
            }
            Err(e) => problems.extend(e),
        }
    }
    if !problems.is_empty() {
        return Err(Outcome::Usage(format!(
            "cannot start the vehicle:\n  {}",
            problems.join("\n  ")
        )));
    }
    Ok(processes)
}

/// One process: its executable resolved, its arguments and environment expanded (`after`
/// is left to the caller, which knows the processes planned before it).
fn resolve_process(spec: &ProcessSpec, places: &Places) -> Result<Planned, Vec<String>> {
    let var = |n: &str| -> Option<String> {
        Some(match n {
            "vehicle" => places.vehicle.to_string(),
            "project" => places.project_dir.display().to_string(),
            "logs" => places.run_dir.display().to_string(),
            "target" => places.target.display().to_string(),
            "petrel" => places.petrel.display().to_string(),
            "name" => spec.name.clone(),
            "computer" => spec.computer.clone().unwrap_or_default(),
            _ => return None,
        })
    };
    // Templates were checked with the file: an error here cannot happen, but is reported
    // rather than trusted.
    let ex = |t: &str| expand(t, &var).map_err(|e| format!("process `{}`: {e}", spec.name));
    let (program, mut args, journal) = match spec.kind {
        Kind::Player | Kind::Bridge => petrel_command(spec, places, &ex).map_err(|e| vec![e])?,
        Kind::Program | Kind::Command => {
            let text = spec.executable.clone().unwrap_or_default();
            let program = ex(&text)
                .and_then(|t| resolve_executable(&t, places.project_dir, &spec.name, places.target))
                .map_err(|e| vec![e])?;
            (program, Vec::new(), None)
        }
    };
    let (extra, env) = expand_args(spec, &ex)?;
    args.extend(extra);
    Ok(Planned {
        log: places.run_dir.join(format!("{}.log", spec.name)),
        spec: spec.clone(),
        program,
        args,
        env,
        after: Vec::new(),
        journal,
    })
}

/// A player's or a bridge's command line: the running petrel, `play|bridge DIR --vehicle V`,
/// its `--wait`, and a player's journal (the directory, also returned). A bridge with an
/// `executable` is the vehicle's own data server (built on petrel-can-bridge, with its
/// simulator): `EXECUTABLE DIR --vehicle V`, `petrel bridge`'s arguments.
fn petrel_command(
    spec: &ProcessSpec,
    places: &Places,
    ex: &dyn Fn(&str) -> Result<String, String>,
) -> Result<(PathBuf, Vec<String>, Option<PathBuf>), String> {
    let mut args = Vec::new();
    let program = match (&spec.executable, spec.kind) {
        (Some(text), Kind::Bridge) => {
            resolve_executable(&ex(text)?, places.project_dir, &spec.name, places.target)?
        }
        _ => {
            args.push(
                if spec.kind == Kind::Player {
                    "play"
                } else {
                    "bridge"
                }
                .to_string(),
            );
            places.petrel.to_path_buf()
        }
    };
    args.extend([
        places.project_dir.display().to_string(),
        "--vehicle".to_string(),
        places.vehicle.to_string(),
    ]);
    if let Some(w) = &spec.wait {
        args.extend(["--wait".to_string(), w.clone()]);
    }
    let mut journal = None;
    if spec.kind == Kind::Player {
        match &spec.journal {
            Journal::Off => args.push("--no-journal".into()),
            j => {
                let dir = match j {
                    Journal::Path(t) => places.run_dir.join(ex(t)?),
                    _ => places.run_dir.join("journal"),
                };
                args.extend(["--journal".to_string(), dir.display().to_string()]);
                journal = Some(dir);
            }
        }
    }
    Ok((program, args, journal))
}

/// Environment variables and their values.
type Env = Vec<(String, String)>;

/// The file's arguments and environment values, expanded; every problem of either.
fn expand_args(
    spec: &ProcessSpec,
    ex: &dyn Fn(&str) -> Result<String, String>,
) -> Result<(Vec<String>, Env), Vec<String>> {
    let mut problems = Vec::new();
    let mut args = Vec::new();
    for t in &spec.args {
        match ex(t) {
            Ok(v) => args.push(v),
            Err(e) => problems.push(e),
        }
    }
    let mut env = Vec::new();
    for (k, t) in &spec.env {
        match ex(t) {
            Ok(v) => env.push((k.clone(), v)),
            Err(e) => problems.push(e),
        }
    }
    if problems.is_empty() {
        Ok((args, env))
    } else {
        Err(problems)
    }
}

/// The run directory: `--logs`, or the file's `logs` template under the project (a new one
/// for each run: `-2`, `-3`... when two runs start in the same second). Created owner-only
/// (`0700`, and so are the directories created on the way), and made so if it was there: its
/// logs hold what the processes print, which is for the vehicle's user alone.
fn run_directory(
    a: &UpArgs,
    file: &VehicleFile,
    project_dir: &Path,
    vehicle: &str,
) -> Result<PathBuf, Outcome> {
    let dir = match &a.logs {
        Some(d) => absolute(d)?,
        None => {
            let time = timestamp();
            let var = |n: &str| match n {
                "vehicle" => Some(vehicle.to_string()),
                "time" => Some(time.clone()),
                _ => None,
            };
            let rel = expand(&file.logs, &var).map_err(Outcome::Usage)?;
            let base = project_dir.join(rel);
            let mut dir = base.clone();
            let mut n = 2;
            while dir.exists() {
                dir = PathBuf::from(format!("{}-{n}", base.display()));
                n += 1;
            }
            dir
        }
    };
    let fail = |what: &str, e: std::io::Error| {
        Outcome::Usage(format!(
            "cannot {what} the run directory {}: {e}",
            dir.display()
        ))
    };
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(&dir)
        .map_err(|e| fail("create", e))?;
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700))
        .map_err(|e| fail("make owner-only", e))?;
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_are_civil_dates() {
        let t = timestamp();
        assert_eq!(t.len(), 15, "{t}");
        assert!(t.starts_with("20"), "{t}");
        assert_eq!(&t[8..9], "-");
    }

    #[test]
    fn processes_start_after_what_they_wait_for() {
        let spec = |name: &str, after: &[&str]| ProcessSpec {
            name: name.into(),
            kind: Kind::Command,
            executable: Some("true".into()),
            args: vec![],
            env: vec![],
            computer: None,
            wait: None,
            programs: vec![],
            after: after.iter().map(|s| s.to_string()).collect(),
            restart: file::Restart::Never,
            ready_timeout: Duration::from_secs(1),
            stop_grace: Duration::from_secs(1),
            journal: Journal::Default,
            critical: false,
        };
        let list = vec![
            spec("gui", &["player"]),
            spec("player", &[]),
            spec("watch", &["gui", "player", "elsewhere"]),
        ];
        assert_eq!(order(&list), vec![1, 0, 2]);
    }
}
