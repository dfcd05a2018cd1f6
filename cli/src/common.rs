//! What every command shares: how a command ends, where its output goes, and the one way a
//! project is loaded and checked.

use petrel_diag::report::{Diagnostic, Diagnostics, Severity};
use petrel_diag::source::SourceMap;
use petrel_nets::compiled::CompiledProject;
use petrel_nets::project::{self, LoadError, LoadedProject};
use std::path::Path;

/// How a command ended; the exit code follows from it.
pub enum Outcome {
    /// Exit 0.
    Clean,
    /// Exit 1: the project or file has errors (already reported).
    Errors,
    /// Exit 2: a usage or I/O error, printed as `error: ...`.
    Usage(String),
}

impl From<LoadError> for Outcome {
    fn from(e: LoadError) -> Self {
        Outcome::Usage(e.to_string())
    }
}

/// Output format of the commands that report findings.
#[derive(Clone, Copy, clap::ValueEnum, PartialEq)]
pub enum Format {
    /// For people: each finding with its line and a caret.
    Human,
    /// For tools: one JSON document.
    Json,
}

/// Writes to standard output. A closed pipe (`petrel ... | head`) ends the command quietly:
/// the reader has what it wanted.
pub fn out(text: &str) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout
        .write_all(text.as_bytes())
        .and_then(|_| stdout.flush())
    {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("error: cannot write to standard output: {e}");
        std::process::exit(2);
    }
}

/// Prints diagnostics for people, on standard error.
pub fn report(d: &Diagnostics, sources: &SourceMap) {
    if !d.is_empty() {
        eprint!("{}", d.render_human(sources));
    }
}

/// Writes `text` to `output`, or to standard output.
pub fn write_output(output: Option<&Path>, text: &str) -> Result<(), Outcome> {
    match output {
        Some(p) => std::fs::write(p, text)
            .map_err(|e| Outcome::Usage(format!("cannot write {}: {e}", p.display()))),
        None => {
            out(text);
            Ok(())
        }
    }
}

/// True when progress lines may be drawn on standard error.
pub fn interactive(format: Format) -> bool {
    format == Format::Human && std::io::IsTerminal::is_terminal(&std::io::stderr())
}

/// States explored by the quick verification of `petrel check`.
pub const QUICK_VERIFY_STATES: u64 = 100_000;

/// What a check covers beyond the project itself.
#[derive(Clone, Copy, Debug, Default)]
pub struct Scope {
    /// The CAN data server's files (can.toml and its DBC), against the project's events.
    pub can: bool,
    /// The quick verification (reachable states, up to [`QUICK_VERIFY_STATES`]).
    pub quick_verify: bool,
    /// The vehicle file (vehicle.toml, when the project has one), against the project's
    /// programs and events.
    pub vehicle: bool,
    /// The map (map.toml, when the project has one), against the project's events and, with
    /// `can`, its DBC's signals.
    pub map: bool,
}

/// A project read and checked: what every command starts from.
pub struct Checked {
    /// The project as written, with its sources.
    pub loaded: LoadedProject,
    /// The project as it runs, when it has no error.
    pub compiled: Option<CompiledProject>,
    /// Every finding, sorted.
    pub diagnostics: Diagnostics,
    /// The CAN data server's configuration and DBC, when asked for and present.
    pub can: Option<(petrel_can_bridge::CanConfig, petrel_can_bridge::Dbc)>,
    /// The vehicle file, when asked for, present and free of errors.
    pub vehicle: Option<crate::up::file::VehicleFile>,
    /// The map, when asked for, present and free of errors.
    pub map: Option<crate::map::Map>,
}

/// What `petrel check` means: the project (syntax, names, types, markings), then, within
/// `scope`, its can.toml and DBC against the project's events, its vehicle.toml, and the quick
/// verification. Nothing is printed.
pub fn check_project(dir: &Path, scope: Scope) -> Result<Checked, Outcome> {
    let (mut loaded, compiled, mut d) = project::load_and_check(dir)?;
    let mut can = None;
    if let (Some(c), true) = (&compiled, scope.can) {
        can = petrel_can_bridge::load_project_can(dir, c, &mut loaded.sources, &mut d)
            .map_err(|e| Outcome::Usage(format!("cannot read the project's CAN files: {e}")))?;
        d.sort();
    }
    let mut vehicle = None;
    if scope.vehicle {
        // The file's own structure is checked even when the project has errors; its programs
        // and events only against a project that compiled.
        let can_program = can
            .as_ref()
            .and_then(|(config, _)| config.commands.program.as_deref());
        vehicle = crate::up::file::load(
            dir,
            compiled.as_ref(),
            can_program,
            &mut loaded.sources,
            &mut d,
        )
        .map_err(|e| {
            Outcome::Usage(format!(
                "cannot read {}: {e}",
                dir.join(crate::up::file::VEHICLE_TOML).display()
            ))
        })?;
        d.sort();
    }
    let mut map = None;
    if let (Some(c), true) = (&compiled, scope.map) {
        let path = dir.join(crate::map::file::MAP_TOML);
        let signals: Option<std::collections::BTreeSet<String>> = can
            .as_ref()
            .map(|(_, dbc): &(_, petrel_can_bridge::Dbc)| dbc.signal_paths().collect());
        match crate::map::file::load(&path, c, signals.as_ref(), &mut loaded.sources, &mut d) {
            Ok(m) => map = m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                return Err(Outcome::Usage(format!(
                    "cannot read {}: {e}",
                    path.display()
                )))
            }
        }
        d.sort();
    }
    if let (Some(c), true) = (&compiled, scope.quick_verify) {
        let opts = petrel_verify::VerifyOptions {
            max_states: Some(QUICK_VERIFY_STATES),
            ..Default::default()
        };
        use petrel_nets::check::{apply_allows, AllowPass};
        match petrel_verify::verify(c, opts) {
            Ok(report) => {
                d.extend(petrel_verify::diagnostics(&loaded.project, &report));
                apply_allows(&loaded.project, &mut d, AllowPass::Final);
            }
            Err(e) => d.push(Diagnostic {
                severity: Severity::Warning,
                ..Diagnostic::global(
                    "W0605",
                    format!("the quick verification did not finish: {e}"),
                )
                .help("run `petrel verify` on the project for the full analysis")
            }),
        }
        d.sort();
    }
    Ok(Checked {
        loaded,
        compiled,
        diagnostics: d,
        can,
        vehicle,
        map,
    })
}

/// For the commands that need a project free of errors: checks it within `scope`, reports the
/// findings on standard error, and ends the command (exit 1) if there is an error.
pub fn require_clean(dir: &Path, scope: Scope, command: &str) -> Result<Checked, Outcome> {
    let checked = check_project(dir, scope)?;
    report(&checked.diagnostics, &checked.loaded.sources);
    if checked.diagnostics.has_errors() || checked.compiled.is_none() {
        eprintln!(
            "fix the errors above first: `petrel {command}` needs a project that checks clean (`petrel check` lists them)"
        );
        return Err(Outcome::Errors);
    }
    Ok(checked)
}

/// The compiled project, for the commands that run it or talk to its vehicle.
pub fn compiled(dir: &Path, command: &str) -> Result<CompiledProject, Outcome> {
    let checked = require_clean(dir, Scope::default(), command)?;
    checked
        .compiled
        .ok_or_else(|| Outcome::Usage("the project did not compile".into()))
}

/// The vehicle to talk to: `--vehicle`, or the project's name.
pub fn vehicle_of(
    c: &CompiledProject,
    vehicle: Option<String>,
) -> Result<petrel_ipc::Vehicle, Outcome> {
    let name = vehicle.unwrap_or_else(|| c.name.clone());
    petrel_ipc::Vehicle::new(&name)
        .map_err(|e| Outcome::Usage(format!("bad vehicle name `{name}`: {e}")))
}

/// Reads an operator event as a script line holds it (`start_mission`,
/// `payload_failure("camera")`), checked against the project: its name and parameters. The
/// one reading of `petrel send` and of vehicle.toml's `[[send]]`, so the operator types what
/// scripts hold.
pub fn operator_event(
    text: &str,
    c: &CompiledProject,
) -> Result<(String, Vec<petrel_nets::compiled::Value>), String> {
    let script =
        petrel_player::script::parse_script(&format!("0 {text}"), c).map_err(|errors| {
            errors
                .into_iter()
                .map(|e| e.message)
                .collect::<Vec<_>>()
                .join("; ")
        })?;
    match script.lines.into_iter().next() {
        Some((
            _,
            petrel_player::script::Line::At {
                event: Some(event), ..
            },
        )) if !text.trim().is_empty() => Ok(event),
        _ => Err(format!("`{text}` is not an event")),
    }
}

/// Reads an option that is a number of seconds (`--until`, `--run-for`): finite, from 0 to
/// what mission time in microseconds holds; `nan`, `inf` and negative numbers are refused
/// with the option's usage, not clamped.
pub fn seconds(text: &str) -> Result<f64, String> {
    petrel_player::script::parse_time(text)
}

/// Parses a wait strategy option (`block`, `spin`, `spin-then-block:<microseconds>`).
pub fn wait_strategy(text: &str) -> Result<petrel_ipc::WaitStrategy, Outcome> {
    text.parse().map_err(Outcome::Usage)
}
