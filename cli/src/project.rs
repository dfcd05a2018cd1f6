//! Commands on a mission project's files: `check`, `verify`, `fmt`, `dot`, `export`, `import`.

use crate::common::{
    check_project, interactive, out, report, require_clean, write_output, Format, Outcome, Scope,
};
use petrel_nets::diag::Diagnostics;
use petrel_nets::plural::count;
use petrel_nets::project;
use petrel_nets::source::SourceMap;
use petrel_nets::verify;
use std::path::{Path, PathBuf};

/// `petrel check`.
#[derive(clap::Args)]
pub struct CheckArgs {
    /// The project directory (the one holding petrel.toml).
    dir: PathBuf,
    /// Output format.
    #[arg(long, value_enum, default_value = "human")]
    format: Format,
    /// Skip the quick verification (reachable states, up to 100,000) that runs after a
    /// clean check.
    #[arg(long)]
    no_verify: bool,
}

/// Checks a project: syntax, names, types, markings, can.toml, vehicle.toml, and the quick
/// verification.
pub fn check(a: CheckArgs) -> Outcome {
    let checked = match check_project(
        &a.dir,
        Scope {
            can: true,
            quick_verify: !a.no_verify,
            vehicle: true,
        },
    ) {
        Ok(c) => c,
        Err(o) => return o,
    };
    // The link between the vehicle's computers: what this machine has of its keys.
    let mut link = None;
    let mut diagnostics = checked.diagnostics.clone();
    if let (Some(v), Some(c)) = (&checked.vehicle, &checked.compiled) {
        let (line, warning) =
            crate::keys::check_link(v, &crate::keys::vehicle_name(None, v, &c.name));
        link = line;
        if let Some(w) = warning {
            diagnostics.push(w);
        }
    }
    let d = &diagnostics;
    match a.format {
        Format::Json => {
            let doc = d.to_json(&checked.loaded.sources);
            out(&format!(
                "{}\n",
                serde_json::to_string_pretty(&doc).unwrap_or_default()
            ));
        }
        Format::Human => {
            report(d, &checked.loaded.sources);
            if let Some(c) = checked.compiled.as_ref().filter(|_| !d.has_errors()) {
                let places: usize = c.nets.iter().map(|n| n.places.len()).sum();
                let transitions: usize = c.nets.iter().map(|n| n.transitions.len()).sum();
                out(&format!(
                    "project `{}` checks clean: {} ({} active at start), {}, {}, {}, {}, {}, {}, {}\n",
                    c.name,
                    count(c.nets.len(), "net"),
                    c.start.len(),
                    count(places, "place"),
                    count(c.globals.len(), "global place"),
                    count(transitions, "transition"),
                    count(c.events.len(), "event"),
                    count(c.programs.len(), "program"),
                    count(c.timers.len(), "timer"),
                    count(d.warning_count(), "warning")
                ));
                if let Some(v) = &checked.vehicle {
                    let names: Vec<String> = v
                        .processes
                        .iter()
                        .map(|p| format!("{} ({})", p.name, p.kind.as_str()))
                        .collect();
                    out(&format!(
                        "vehicle.toml: {} ({}), {}, {}{}\n",
                        count(v.processes.len(), "process"),
                        names.join(", "),
                        count(v.computers.len(), "computer"),
                        count(v.sends.len(), "timed send"),
                        link.map(|l| format!("; {l}")).unwrap_or_default()
                    ));
                }
            }
        }
    }
    if d.has_errors() {
        Outcome::Errors
    } else {
        Outcome::Clean
    }
}

/// `petrel verify`.
#[derive(clap::Args)]
pub struct VerifyArgs {
    /// The project directory, or a PNML file.
    dir: PathBuf,
    /// Verify this net alone, its global places and events being free choices.
    #[arg(long)]
    net: Option<String>,
    /// Output format.
    #[arg(long, value_enum, default_value = "human")]
    format: Format,
    /// Stop with an error beyond this many states (at least 1).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    max_states: Option<u64>,
    /// List every finding: each dead marking as its own diagnostic, every intended end, every
    /// end after a catastrophic event, every loop and conflict (by default they are grouped,
    /// with counts).
    #[arg(long)]
    all: bool,
    /// Explore every interleaving of independent nets (no partial-order reduction): slower,
    /// but progress, stuck nets, starvation and loops are checked whatever the project.
    #[arg(long)]
    no_reduction: bool,
    /// Timed exploration: timers with literal durations expire in the order their durations
    /// impose (a zone over their clocks), outside events stay free; no partial-order reduction.
    /// Without it, a timer's expiry may come at any moment (the untimed analysis).
    #[arg(long)]
    timed: bool,
    /// Report a time bound: over every occurrence of FROM, the least and greatest time until
    /// the next TO (each an event, or a marking formula such as `EMERGENCY.surfacing`), as
    /// `[verify.bounds]` declares them. Implies --timed. May be given more than once.
    #[arg(long, value_name = "FROM..TO")]
    bound: Vec<String>,
    /// Where the analyses find the explored graph's edges: `auto` keeps them up to about a
    /// million and recomputes them with the firing code beyond, `keep` always keeps them
    /// (fastest, a few bytes per edge), `replay` never does (a state costs about 20 bytes, the
    /// analyses take longer). The findings are the same. The partial-order reduction and
    /// --net keep theirs.
    #[arg(long, value_enum, default_value = "auto")]
    edges: EdgesArg,
    /// A PNML file only: decide deadlocks alone, with stubborn sets (a partial-order reduction
    /// that reaches every dead marking through fewer markings); bounds and safety are then not
    /// decided.
    #[arg(long)]
    deadlocks: bool,
}

/// `--edges`: [`verify::EdgeMemory`] on the command line.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum EdgesArg {
    /// Kept up to about a million edges, recomputed beyond.
    Auto,
    /// Always kept.
    Keep,
    /// Always recomputed.
    Replay,
}

impl From<EdgesArg> for verify::EdgeMemory {
    fn from(e: EdgesArg) -> Self {
        match e {
            EdgesArg::Auto => verify::EdgeMemory::Auto,
            EdgesArg::Keep => verify::EdgeMemory::Keep,
            EdgesArg::Replay => verify::EdgeMemory::Replay,
        }
    }
}

/// Verifies a project (or one of its nets), or explores a PNML file as a P/T net.
pub fn verify(a: VerifyArgs) -> Outcome {
    if a.dir.is_file() {
        if !a.bound.is_empty() {
            return Outcome::Usage("--bound needs a project directory, not a PNML file".into());
        }
        return verify_pnml(&a.dir, a.format, a.max_states, a.deadlocks);
    }
    if a.deadlocks {
        return Outcome::Usage(format!(
            "--deadlocks explores a PNML file's P/T net; {} is a project (its verification reduces by itself: see --no-reduction)",
            a.dir.display()
        ));
    }
    let checked = match require_clean(&a.dir, Scope::default(), "verify") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let Some(mut c) = checked.compiled else {
        return Outcome::Errors;
    };
    for text in &a.bound {
        match petrel_nets::check::command_line_bound(&c, text) {
            Ok(b) => c.bounds.push(b),
            Err(e) => return Outcome::Usage(e),
        }
    }
    let interactive = interactive(a.format);
    let opts = verify::VerifyOptions {
        max_states: a.max_states,
        only_net: a.net,
        no_reduction: a.no_reduction,
        // A bound asked for on the command line needs the timed exploration.
        timed: a.timed || !a.bound.is_empty(),
        edges: a.edges.into(),
        progress: interactive.then(|| {
            Box::new(|states: u64, rate: f64| {
                eprint!("\r{states} states, {rate:.0} states/s   ");
            }) as Box<dyn FnMut(u64, f64)>
        }),
        ..Default::default()
    };
    let r = match verify::verify(&c, opts) {
        Ok(r) => r,
        Err(verify::VerifyError::UnknownNet(n)) => {
            let names: Vec<_> = c.nets.iter().map(|n| n.name.as_str()).collect();
            return Outcome::Usage(format!(
                "no net named `{n}`; the nets are: {}",
                names.join(", ")
            ));
        }
        Err(e) => {
            eprintln!("error: {e}");
            return Outcome::Errors;
        }
    };
    if interactive {
        eprint!("\r\x1b[K");
    }
    // Each finding located in the project's text, as `petrel check` shows its own.
    let mut d = if a.all {
        verify::diagnostics_all(&checked.loaded.project, &r)
    } else {
        verify::diagnostics(&checked.loaded.project, &r)
    };
    petrel_nets::check::apply_allows(
        &checked.loaded.project,
        &mut d,
        petrel_nets::check::AllowPass::FilterOnly,
    );
    d.sort();
    let sources = &checked.loaded.sources;
    match a.format {
        Format::Json => {
            // The report's every finding, and the diagnostics with file, line and column.
            let mut doc = verify::to_json(&r);
            if let Some(map) = doc.as_object_mut() {
                map.insert("errors".into(), r.errors().into());
                map.insert("warnings".into(), r.warnings().into());
                map.insert(
                    "diagnostics".into(),
                    d.to_json(sources)["diagnostics"].clone(),
                );
            }
            out(&format!(
                "{}\n",
                serde_json::to_string_pretty(&doc).unwrap_or_default()
            ));
        }
        Format::Human => {
            let mut text = d.render_human(sources);
            if !text.is_empty() {
                text.push('\n');
            }
            text.push_str(&verify::render_summary(&c.name, &r, a.all));
            out(&text);
        }
    }
    // Warnings do not fail the verification; errors do.
    if r.errors() == 0 {
        Outcome::Clean
    } else {
        Outcome::Errors
    }
}

fn verify_pnml(file: &Path, format: Format, max_states: Option<u64>, deadlocks: bool) -> Outcome {
    use petrel_nets::reach;
    let text = match std::fs::read_to_string(file) {
        Ok(t) => t,
        Err(e) => return Outcome::Usage(format!("cannot read {}: {e}", file.display())),
    };
    let mut sources = SourceMap::new();
    let id = sources.add(file.display().to_string(), text.clone());
    let mut d = Diagnostics::new();
    let nets = petrel_nets::pnml::parse_pnml(id, &text, &mut d);
    report(&d, &sources);
    if d.has_errors() || nets.is_empty() {
        return Outcome::Errors;
    }
    let interactive = interactive(format);
    let mut clean = true;
    let mut docs = Vec::new();
    // A Petrel export is a mission's skeleton: say so before its findings are misread.
    if format == Format::Human && nets.iter().any(|n| n.petrel_export) {
        eprintln!(
            "note: {}: {}",
            file.display(),
            petrel_nets::pnml::SKELETON_NOTE
        );
    }
    for net in &nets {
        let opts = reach::ExploreOptions {
            max_states,
            deadlocks_only: deadlocks,
            progress: interactive.then(|| {
                Box::new(|p: reach::Progress| {
                    eprint!(
                        "\r{} states, {:.0} states/s   ",
                        p.states, p.states_per_second
                    );
                }) as Box<dyn FnMut(reach::Progress)>
            }),
            ..Default::default()
        };
        let result = reach::explore(net, opts);
        if interactive {
            eprint!("\r\x1b[K");
        }
        match (result, format) {
            (Ok(r), Format::Human) => {
                clean &= r.safe && !r.deadlock;
                out(&reach::render_human(net, &r));
            }
            (Ok(r), Format::Json) => {
                clean &= r.safe && !r.deadlock;
                docs.push(with_skeleton_note(net, reach::to_json(net, &r)));
            }
            (Err(e), Format::Human) => {
                clean = false;
                eprintln!("error: {}", reach::render_error(net, &e));
            }
            (Err(e), Format::Json) => {
                clean = false;
                docs.push(with_skeleton_note(net, reach::error_to_json(net, &e)));
            }
        }
    }
    if format == Format::Json {
        let doc = if docs.len() == 1 {
            docs.pop().unwrap_or_default()
        } else {
            serde_json::Value::Array(docs)
        };
        out(&format!(
            "{}\n",
            serde_json::to_string_pretty(&doc).unwrap_or_default()
        ));
    }
    if clean {
        Outcome::Clean
    } else {
        Outcome::Errors
    }
}

/// A JSON report of a PNML net with `petrel_export` (whether the file is a Petrel export), and
/// for an export the `note` that only its P/T skeleton was analysed.
fn with_skeleton_note(
    net: &petrel_nets::pt::PtNet,
    mut doc: serde_json::Value,
) -> serde_json::Value {
    if let Some(map) = doc.as_object_mut() {
        map.insert("petrel_export".into(), net.petrel_export.into());
        if net.petrel_export {
            map.insert("note".into(), petrel_nets::pnml::SKELETON_NOTE.into());
        }
    }
    doc
}

/// `petrel fmt`.
#[derive(clap::Args)]
pub struct FmtArgs {
    /// The project directory.
    dir: PathBuf,
    /// Change nothing; exit 1 if a file is not in canonical layout.
    #[arg(long)]
    check: bool,
}

/// Rewrites the project's net files in canonical layout.
pub fn fmt(a: FmtArgs) -> Outcome {
    let (dir, check_only) = (&a.dir, a.check);
    let loaded = match project::load(dir) {
        Ok(l) => l,
        Err(e) => return e.into(),
    };
    // A file with a syntax error is left alone: formatting it would drop what could not be read.
    let broken: Vec<_> = loaded
        .diagnostics
        .iter()
        .filter(|d| d.code == "E0001")
        .filter_map(|d| d.span.map(|s| s.file))
        .collect();
    report(&loaded.diagnostics, &loaded.sources);
    let mut unformatted = Vec::new();
    for (file, id) in loaded.project.files.iter().zip(&loaded.file_ids) {
        if broken.iter().any(|b| b.0 == id.0) {
            continue;
        }
        let text = petrel_nets::fmt::format_file(file);
        let source = loaded.sources.get(*id);
        if text != source.text {
            unformatted.push(source.name.clone());
            if !check_only {
                if let Err(e) = project::write_net_file(dir, &file.path, &text) {
                    return Outcome::Usage(format!("cannot write {}: {e}", source.name));
                }
            }
        }
    }
    for name in &unformatted {
        if check_only {
            out(&format!("not in canonical layout: {name}\n"));
        } else {
            out(&format!("formatted {name}\n"));
        }
    }
    if loaded.diagnostics.has_errors() || (check_only && !unformatted.is_empty()) {
        Outcome::Errors
    } else {
        Outcome::Clean
    }
}

/// `petrel dot`.
#[derive(clap::Args)]
pub struct DotArgs {
    /// The project directory.
    dir: PathBuf,
    /// Only this net (and the global places it uses); a template's name draws all its
    /// instances.
    #[arg(long)]
    net: Option<String>,
    /// Draw the tree of nets only: one box per net, `children` lines as solid arrows,
    /// `activate` actions as dashed ones.
    #[arg(long, conflicts_with = "net")]
    tree: bool,
    /// Write to this file instead of standard output.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Prints the project's nets, or their tree, as Graphviz DOT.
pub fn dot(a: DotArgs) -> Outcome {
    let checked = match require_clean(&a.dir, Scope::default(), "dot") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let project = &checked.loaded.project;
    let drawing = if a.tree {
        Ok(petrel_nets::dot::project_tree_dot(project))
    } else {
        petrel_nets::dot::project_to_dot(project, a.net.as_deref())
    };
    match drawing {
        Ok(text) => match write_output(a.output.as_deref(), &text) {
            Ok(()) => Outcome::Clean,
            Err(o) => o,
        },
        Err(msg) => Outcome::Usage(msg),
    }
}

/// `petrel export`.
#[derive(clap::Args)]
pub struct ExportArgs {
    /// The project directory.
    dir: PathBuf,
    /// Write PNML (the only export format for now).
    #[arg(long, required = true)]
    pnml: bool,
    /// Write to this file instead of standard output.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Exports the project as PNML.
pub fn export(a: ExportArgs) -> Outcome {
    let checked = match require_clean(&a.dir, Scope::default(), "export") {
        Ok(c) => c,
        Err(o) => return o,
    };
    let text = petrel_nets::pnml::export_pnml(&checked.loaded.project);
    match write_output(a.output.as_deref(), &text) {
        Ok(()) => Outcome::Clean,
        Err(o) => o,
    }
}

/// `petrel import`.
#[derive(clap::Args)]
pub struct ImportArgs {
    /// The PNML file.
    file: PathBuf,
    /// The project directory to create (default: the file's name without extension).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Overwrite files in an existing directory.
    #[arg(long)]
    force: bool,
}

/// Imports a PNML file as a Petrel project.
pub fn import(a: ImportArgs) -> Outcome {
    let (file, output, force) = (&a.file, a.output, a.force);
    let text = match std::fs::read_to_string(file) {
        Ok(t) => t,
        Err(e) => return Outcome::Usage(format!("cannot read {}: {e}", file.display())),
    };
    let dest = output.unwrap_or_else(|| {
        let stem = file.file_stem().unwrap_or_default();
        PathBuf::from(stem)
    });
    let mut sources = SourceMap::new();
    let id = sources.add(file.display().to_string(), text.clone());
    let mut d = Diagnostics::new();
    let project = petrel_nets::pnml::import_pnml(id, &text, &mut d);
    d.sort();
    report(&d, &sources);
    let Some(project) = project.filter(|_| !d.has_errors()) else {
        eprintln!(
            "nothing written: {} cannot be held by a Petrel project as it is",
            file.display()
        );
        return Outcome::Errors;
    };
    let occupied = std::fs::read_dir(&dest)
        .map(|mut e| e.next().is_some())
        .unwrap_or(false);
    if occupied && !force {
        return Outcome::Usage(format!(
            "{} exists and is not empty: choose another directory with --output, or pass --force to overwrite",
            dest.display()
        ));
    }
    if let Err(e) = project::write(&dest, &project) {
        return Outcome::Usage(format!("cannot write {}: {e}", dest.display()));
    }
    let nets = project.nets().count();
    let places: usize = project.nets().map(|n| n.places().count()).sum();
    let transitions: usize = project.nets().map(|n| n.transitions().count()).sum();
    out(&format!(
        "imported {} into {}: {}, {}, {}\n",
        file.display(),
        dest.display(),
        count(nets, "net"),
        count(places, "place"),
        count(transitions, "transition")
    ));
    Outcome::Clean
}
