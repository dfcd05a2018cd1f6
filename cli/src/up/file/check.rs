//! `check_file`: a vehicle file's text to a [`VehicleFile`], every problem reported at its
//! place (E08xx). One function per table, and per field of a `[[process]]`, in the order the
//! findings are reported.

use super::checker::VehicleChecker;
use super::raw::{RawFile, RawJournal, RawProcess, RawSend, RawVehicle};
use super::{
    is_process_name, suggest, Computer, Journal, Kind, LinkSpec, ProcessSpec, Restart, SendSpec,
    VehicleFile, DEFAULT_BACKOFF, DEFAULT_LOGS, DEFAULT_MAX_RESTARTS, DEFAULT_READY_TIMEOUT,
    DEFAULT_STOP_GRACE, LOGS_VARS, PROCESS_VARS,
};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};
use petrel_diag::toml::Ordered;
use petrel_nets::compiled::CompiledProject;
use std::time::Duration;
use toml::Spanned;

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
    let raw: RawFile = petrel_diag::toml::parse(
        file,
        text,
        "E0801",
        "vehicle.toml",
        "vehicle.toml has an optional [vehicle] table (name, logs, stop_grace), [computers.NAME] tables, [[process]] entries and [[send]] entries; see docs/vehicle.md",
        diags,
    )?;
    let mut c = VehicleChecker::new(file, diags, project);
    let vehicle = vehicle_table(&mut c, &raw.vehicle);
    let computers = computers(&mut c, raw.computers);
    let names = process_names(&mut c, &raw.processes);
    let mut owners = Vec::new();
    let mut processes = Vec::new();
    for p in &raw.processes {
        let context = Context {
            computers: &computers,
            names: &names,
            stop_grace: vehicle.stop_grace,
        };
        if let Some(spec) = process(&mut c, p, &context, &mut owners) {
            processes.push(spec);
        }
    }
    if c.errors == 0 {
        after_cycles(&mut c, &raw.processes, &processes);
    }
    if let Some(proj) = project {
        if !raw.processes.is_empty() {
            unrun_programs(&mut c, proj, can_program, &owners, &processes);
        }
    }
    let sends = sends(&mut c, &raw.sends, &computers, &processes);
    let link = match &raw.link {
        Some(l) => c.link(l, &computers),
        None => LinkSpec::default(),
    };
    if c.errors > 0 {
        return None;
    }
    Some(VehicleFile {
        name: vehicle.name,
        logs: vehicle.logs,
        computers,
        processes,
        sends,
        link,
    })
}

/// The `[vehicle]` table, checked.
struct Vehicle {
    name: Option<String>,
    logs: String,
    stop_grace: Duration,
}

/// `[vehicle]`: its name, the run directory's template, the default stop grace.
fn vehicle_table(c: &mut VehicleChecker, raw: &RawVehicle) -> Vehicle {
    let name = raw
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
    let logs = match &raw.logs {
        Some(l) => {
            c.template(l, LOGS_VARS, "[vehicle] logs");
            l.get_ref().clone()
        }
        None => DEFAULT_LOGS.to_string(),
    };
    let stop_grace = raw
        .stop_grace
        .as_ref()
        .and_then(|g| c.duration(g, "[vehicle] stop_grace"))
        .unwrap_or(DEFAULT_STOP_GRACE);
    Vehicle {
        name,
        logs,
        stop_grace,
    }
}

/// `[computers.NAME]`, in file order.
fn computers(c: &mut VehicleChecker, raw: Ordered<super::raw::RawComputer>) -> Vec<Computer> {
    let mut computers = Vec::new();
    for (key, comp) in raw.0 {
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
    computers
}

/// The processes' names, read before the entries so that `after` can refer to a later one.
struct Names {
    /// Each name, at its first declaration.
    declared: Vec<(String, Span)>,
    /// The players' names (what the other processes come after by default).
    players: Vec<String>,
}

/// The `[[process]]` names: valid, each declared once; one player at most.
fn process_names(c: &mut VehicleChecker, processes: &[RawProcess]) -> Names {
    let mut declared: Vec<(String, Span)> = Vec::new();
    for p in processes {
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
        if let Some((_, first)) = declared.iter().find(|(s, _)| s == n) {
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
            declared.push((n.clone(), c.span(&p.name)));
        }
    }
    let players: Vec<&RawProcess> = processes
        .iter()
        .filter(|p| p.kind.get_ref() == "player")
        .collect();
    if let Some(second) = players.get(1) {
        c.error(
            "E0810",
            c.span(&second.kind),
            "a second player: a vehicle has one".into(),
            "second player",
            "a vehicle has one player (its events service takes one receiver); run a ground-station shadow as a command: executable = \"{petrel}\", args = [\"play\", \"{project}\", \"--shadow\", \"--vehicle\", \"{vehicle}\"]",
        );
    }
    Names {
        declared,
        players: players.iter().map(|p| p.name.get_ref().clone()).collect(),
    }
}

/// What a `[[process]]` entry is checked against.
struct Context<'a> {
    computers: &'a [Computer],
    names: &'a Names,
    /// `[vehicle] stop_grace`, the default of each process's.
    stop_grace: Duration,
}

/// Which process runs each program (program, process, where), so that a program is run once.
type Owners = Vec<(String, String, Span)>;

/// One `[[process]]` entry; `None` if its kind is unknown (nothing else can be checked).
fn process(
    c: &mut VehicleChecker,
    p: &RawProcess,
    context: &Context,
    owners: &mut Owners,
) -> Option<ProcessSpec> {
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
        return None;
    };
    let executable = executable(c, p, kind);
    arguments(c, p, kind);
    let env = environment(c, p);
    let computer = computer(c, p, context.computers);
    let wait = wait(c, p, kind);
    let programs = programs(c, p, kind, owners);
    let after = after(c, p, kind, context.names);
    let restart = restart(c, p);
    let ready_timeout = p
        .ready_timeout
        .as_ref()
        .and_then(|d| c.duration(d, "`ready_timeout`"))
        .unwrap_or(DEFAULT_READY_TIMEOUT);
    let stop_grace = p
        .stop_grace
        .as_ref()
        .and_then(|d| c.duration(d, "`stop_grace`"))
        .unwrap_or(context.stop_grace);
    let journal = journal(c, p, kind);
    let critical = critical(c, p, kind);
    Some(ProcessSpec {
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
        stop_grace,
        journal,
        critical,
    })
}

/// `executable`: required for a program or a command, refused for a player (the running
/// `petrel` is its), optional for a bridge (the vehicle's own data server; `petrel bridge`
/// without it).
fn executable(c: &mut VehicleChecker, p: &RawProcess, kind: Kind) -> Option<String> {
    let pname = p.name.get_ref();
    match (&p.executable, kind) {
        (Some(e), Kind::Player) => {
            c.not_for_kind(
                c.span(e),
                "executable",
                pname,
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
    }
}

/// `args`: templates; a player's or a bridge's may not give what `petrel up` gives itself.
fn arguments(c: &mut VehicleChecker, p: &RawProcess, kind: Kind) {
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
}

/// `env`: variable names, and values that are templates.
fn environment(c: &mut VehicleChecker, p: &RawProcess) -> Vec<(String, String)> {
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
    env
}

/// `computer`: a declared one, required when the file declares computers.
fn computer(c: &mut VehicleChecker, p: &RawProcess, computers: &[Computer]) -> Option<String> {
    let pname = p.name.get_ref();
    match &p.computer {
        Some(k) => {
            c.computer_ref(k, computers, &format!("process `{pname}`"));
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
    }
}

/// `wait`: a player's or a bridge's `--wait` strategy.
fn wait(c: &mut VehicleChecker, p: &RawProcess, kind: Kind) -> Option<String> {
    match (&p.wait, kind) {
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
                p.name.get_ref(),
                kind,
                "`wait` is passed to petrel play or petrel bridge as --wait; give another executable its own flag in `args`",
            );
            None
        }
        (None, _) => None,
    }
}

/// `programs`: a program process's, each of the manifest (when the project checks) and run by
/// no other process.
fn programs(
    c: &mut VehicleChecker,
    p: &RawProcess,
    kind: Kind,
    owners: &mut Owners,
) -> Vec<String> {
    let pname = p.name.get_ref();
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
                program(c, prog, pname, owners);
                programs.push(prog.get_ref().clone());
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
            pname,
            kind,
            "only a process of kind program runs programs of the manifest",
        ),
        (None, _) => {}
    }
    programs
}

/// One program of process `pname`: the manifest's, and not already another process's.
fn program(c: &mut VehicleChecker, prog: &Spanned<String>, pname: &str, owners: &mut Owners) {
    let pn = prog.get_ref();
    if let Some(proj) = c.project {
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
    if let Some((_, owner, first)) = owners.iter().find(|(x, _, _)| x == pn) {
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
        owners.push((pn.clone(), pname.to_string(), c.span(prog)));
    }
}

/// `after`: processes of the file, not itself; by default, everything comes after the player.
fn after(c: &mut VehicleChecker, p: &RawProcess, kind: Kind, names: &Names) -> Vec<String> {
    let pname = p.name.get_ref();
    let Some(list) = &p.after else {
        return if kind == Kind::Player {
            Vec::new()
        } else {
            names.players.clone()
        };
    };
    let mut out = Vec::new();
    for a in list.get_ref() {
        let an = a.get_ref();
        if an == pname {
            c.error(
                "E0807",
                c.span(a),
                format!("process `{pname}` waits for itself"),
                "itself",
                "remove it from `after`",
            );
        } else if !names.declared.iter().any(|(s, _)| s == an) {
            let help = format!(
                "{}`after` names processes of this file",
                suggest(an, names.declared.iter().map(|(s, _)| s.as_str()))
            );
            c.error(
                "E0804",
                c.span(a),
                format!(
                    "process `{pname}` comes after `{an}`, which is not a process of this file"
                ),
                "no such process",
                &help,
            );
        } else {
            out.push(an.clone());
        }
    }
    out
}

/// `restart`, with `max_restarts` and `backoff` (which only `on-failure` takes).
fn restart(c: &mut VehicleChecker, p: &RawProcess) -> Restart {
    let pname = p.name.get_ref();
    match p.restart.as_ref().map(|r| r.get_ref().as_str()) {
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
            let span = c.first_span(&[p.restart.as_ref()]);
            c.error(
                "E0806",
                span,
                format!("process `{pname}` has an unknown restart policy `{other}`"),
                "not a policy",
                "write restart = \"never\" or restart = \"on-failure\" (with max_restarts and backoff)",
            );
            Restart::Never
        }
    }
}

/// `journal`: the player's alone (on, off, or a directory template).
fn journal(c: &mut VehicleChecker, p: &RawProcess, kind: Kind) -> Journal {
    match (&p.journal, kind) {
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
                p.name.get_ref(),
                kind,
                "only the player keeps a journal",
            );
            Journal::Default
        }
    }
}

/// `critical`: always true for the player.
fn critical(c: &mut VehicleChecker, p: &RawProcess, kind: Kind) -> bool {
    match (&p.critical, kind) {
        (Some(v), Kind::Player) if !v.get_ref() => {
            c.not_for_kind(
                c.span(v),
                "critical = false",
                p.name.get_ref(),
                kind,
                "nothing runs without the player: its failure always stops the vehicle",
            );
            true
        }
        (_, Kind::Player) => true,
        (Some(v), _) => *v.get_ref(),
        (None, _) => false,
    }
}

/// Cycles among `after` (self-references are reported with each process).
fn after_cycles(c: &mut VehicleChecker, raw: &[RawProcess], processes: &[ProcessSpec]) {
    let Some(cycle) = find_cycle(processes) else {
        return;
    };
    let first = raw
        .iter()
        .find(|p| p.name.get_ref() == &cycle[0])
        .and_then(|p| p.after.as_ref());
    let first = c.first_span(&[first]);
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

/// Programs of the manifest nobody runs (a warning: their calls would fail).
fn unrun_programs(
    c: &mut VehicleChecker,
    proj: &CompiledProject,
    can_program: Option<&str>,
    owners: &Owners,
    processes: &[ProcessSpec],
) {
    for prog in &proj.programs {
        let served = owners.iter().any(|(x, _, _)| x == &prog.name)
            || (can_program == Some(prog.name.as_str())
                && processes.iter().any(|p| p.kind == Kind::Bridge));
        if !served {
            c.diags.push(
                Diagnostic::warning(
                    "W0801",
                    Span::new(c.file, 0, 0),
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

/// `[[send]]` entries (of the vehicle file or a scenario), in time order; a send that names no
/// computer is made by the player's.
pub(super) fn sends(
    c: &mut VehicleChecker,
    raw: &[RawSend],
    computers: &[Computer],
    processes: &[ProcessSpec],
) -> Vec<SendSpec> {
    let default_computer = processes
        .iter()
        .find(|p| p.kind == Kind::Player)
        .and_then(|p| p.computer.clone());
    let mut sends = Vec::new();
    for s in raw {
        if let Some(k) = &s.computer {
            c.computer_ref(k, computers, "a [[send]]");
        }
        if let Some(mut spec) = c.send(s) {
            if spec.computer.is_none() {
                spec.computer = default_computer.clone();
            }
            sends.push(spec);
        }
    }
    sends.sort_by_key(|s| s.at);
    sends
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::up::file::expand;
    use petrel_diag::source::SourceMap;

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

    /// Before: a misspelt event of `[link]` or `[[send]]` had no "did you mean".
    #[test]
    fn a_misspelt_event_gets_a_hint() {
        let manifest = r#"
[project]
name = "p"
files = ["a.pn"]
start = ["A"]
[events]
go = { category = "nominal" }
link_lost = { category = "communication", params = ["computer: text"] }
link_back = { category = "communication", params = ["computer: text"] }
"#;
        let nets = "net A {\n place i = 1\n transition t on go: i -> i\n transition l on link_lost(c): i -> i\n transition b on link_back(c): i -> i\n}\n";
        let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", nets)]);
        let c = c.unwrap_or_else(|| panic!("{d:?}"));
        let text = "[computers.a]\ngateway = \"tcp/127.0.0.1:7447\"\n[computers.b]\n\
                    [link]\nlost_event = \"link_lots\"\nrestored_event = \"link_back\"\n\
                    [[send]]\nat = \"1s\"\nevent = \"g0\"\n";
        let mut sources = SourceMap::default();
        let file = sources.add("vehicle.toml", text);
        let mut d = Diagnostics::new();
        assert!(check_file(file, text, Some(&c), None, &mut d).is_none());
        assert_eq!(codes(&d), ["E0809", "E0812"], "{d:?}");
        let shown = d.render_human(&sources);
        assert!(
            shown.contains("`link_lots` is not an event of the project: did you mean `link_lost`?"),
            "{shown}"
        );
        assert!(
            shown.contains("unknown event `g0`: did you mean `go`?"),
            "{shown}"
        );
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
