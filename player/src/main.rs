//! `petrel`: the command line of the Petrel mission supervisor.
//!
//! Exit codes, for every command: 0 clean, 1 the project or file has errors, 2 usage or I/O
//! error.

use clap::{Parser, Subcommand, ValueEnum};
use petrel_nets::diag::Diagnostics;
use petrel_nets::project::{self, LoadError};
use petrel_nets::source::SourceMap;
use petrel_nets::verify;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "petrel",
    version,
    about = "Petrel: a mission supervisor for autonomous vehicles, written as safe Petri nets",
    after_help = "Exit codes: 0 clean, 1 errors found, 2 usage or I/O error."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum, PartialEq)]
enum Format {
    /// For people: each finding with its line and a caret.
    Human,
    /// For tools: one JSON document.
    Json,
}

#[derive(Subcommand)]
enum JournalCommand {
    /// Print every entry.
    Show {
        /// The journal directory (or one segment file).
        journal: PathBuf,
        /// Output format: text, json (one document a line) or csv.
        #[arg(long, default_value = "text")]
        format: String,
    },
}

#[derive(Subcommand)]
enum Command {
    /// Check a mission project: syntax, names, types, markings.
    Check {
        /// The project directory (the one holding petrel.toml).
        dir: PathBuf,
        /// Output format.
        #[arg(long, value_enum, default_value = "human")]
        format: Format,
        /// Skip the quick verification (reachable states, up to 100,000) that runs after a
        /// clean check.
        #[arg(long)]
        no_verify: bool,
    },
    /// Verify a project (or one net of it): safety, dead markings, loops, conflicts, with the
    /// shortest event sequence to each finding. Given a PNML file, explore it as a plain P/T
    /// net (arc weights and token counts above one allowed).
    Verify {
        /// The project directory, or a PNML file.
        dir: PathBuf,
        /// Verify this net alone, its global places and events being free choices.
        #[arg(long)]
        net: Option<String>,
        /// Output format.
        #[arg(long, value_enum, default_value = "human")]
        format: Format,
        /// Stop with an error beyond this many states.
        #[arg(long)]
        max_states: Option<u64>,
    },
    /// Play the mission: the player process on iceoryx2, talking to the vehicle's programs.
    /// Stops on SIGINT or SIGTERM.
    Play {
        /// The project directory.
        dir: PathBuf,
        #[command(flatten)]
        args: PlayArgs,
    },
    /// The CAN data server: frames from the vehicle bus become events for the player (by the
    /// rules of the project's can.toml), calls to the commands program become frames.
    Bridge {
        /// The project directory (petrel.toml, can.toml and its DBC).
        dir: PathBuf,
        /// The vehicle; default: the project's name.
        #[arg(long)]
        vehicle: Option<String>,
        /// `memory` (an in-process bus with a simulated AUV that obeys the commands), or a
        /// SocketCAN interface such as vcan0; default: can.toml's [bus] interface.
        #[arg(long)]
        bus: Option<String>,
        /// On the memory bus: the simulated vehicle's hull leaks once it is this deep (metres).
        #[arg(long, value_name = "METRES")]
        sim_leak_at: Option<f64>,
        /// Record every frame in and out to this candump -L log.
        #[arg(long)]
        record: Option<PathBuf>,
        /// Instead of serving, replay this candump -L log and print the events it gives, one
        /// JSON document a line.
        #[arg(long)]
        replay: Option<PathBuf>,
        /// How the reactor waits: block, spin, or spin-then-block:<microseconds>.
        #[arg(long, default_value = "block")]
        wait: String,
    },
    /// Replay a journal through the engine and check every recorded marking.
    Replay {
        /// The journal directory (or one segment file).
        journal: PathBuf,
        /// The project (default: the directory recorded in the journal).
        #[arg(long)]
        project: Option<PathBuf>,
        /// Stop at this mission time (seconds) and print the state there.
        #[arg(long)]
        until: Option<f64>,
    },
    /// Print a journal for people (text) or for plotting (json, csv).
    Journal {
        #[command(subcommand)]
        command: JournalCommand,
    },
    /// Send an event to a running player, as the operator: `petrel send DIR 'payload_failure("camera")'`.
    Send {
        /// The project directory (the event is checked against it before sending).
        dir: PathBuf,
        /// The event, as in a script: `name` or `name(1, 2.5, "text", [1.0, 2.0])`.
        event: String,
        /// The vehicle; default: the project's name.
        #[arg(long)]
        vehicle: Option<String>,
        /// Send the event this many times, as fast as possible (a stress test of the vehicle).
        #[arg(long, default_value_t = 1)]
        count: u64,
    },
    /// Print the live marking of every active net and the player's counters.
    Status {
        /// The project directory.
        dir: PathBuf,
        /// The vehicle; default: the project's name.
        #[arg(long)]
        vehicle: Option<String>,
        /// Print the status as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Run a mission script in virtual time, with no process: events at given times and
    /// expectations; each step prints as a JSON line. A failed expectation exits 1.
    Run {
        /// The project directory.
        dir: PathBuf,
        /// The script: lines `TIME EVENT(args)`, `TIME wait`, `expect ...`.
        #[arg(long)]
        script: PathBuf,
        /// Print nothing but the result of the expectations.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Rewrite the project's net files in canonical layout (running it twice changes nothing).
    Fmt {
        /// The project directory.
        dir: PathBuf,
        /// Change nothing; exit 1 if a file is not in canonical layout.
        #[arg(long)]
        check: bool,
    },
    /// Print the project's nets as Graphviz DOT.
    Dot {
        /// The project directory.
        dir: PathBuf,
        /// Only this net (and the global places it uses).
        #[arg(long)]
        net: Option<String>,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Export the project as PNML (ISO/IEC 15909-2); events and actions travel in a
    /// `<toolspecific tool="petrel">` block.
    Export {
        /// The project directory.
        dir: PathBuf,
        /// Write PNML (the only export format for now).
        #[arg(long, required = true)]
        pnml: bool,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Import a PNML file as a Petrel project.
    Import {
        /// The PNML file.
        file: PathBuf,
        /// The project directory to create (default: the file's name without extension).
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Overwrite files in an existing directory.
        #[arg(long)]
        force: bool,
    },
}

/// How a command ended.
enum Outcome {
    Clean,
    Errors,
    Usage(String),
}

impl From<LoadError> for Outcome {
    fn from(e: LoadError) -> Self {
        Outcome::Usage(e.to_string())
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Logs go to stderr; RUST_LOG sets the level (default: warnings and info of the player).
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let outcome = match cli.command {
        Command::Check {
            dir,
            format,
            no_verify,
        } => check(&dir, format, !no_verify),
        Command::Verify {
            dir,
            net,
            format,
            max_states,
        } => verify(&dir, net, format, max_states),
        Command::Fmt { dir, check } => fmt(&dir, check),
        Command::Run { dir, script, quiet } => run(&dir, &script, quiet),
        Command::Play { dir, args } => play(&dir, args),
        Command::Replay {
            journal,
            project,
            until,
        } => replay(&journal, project.as_deref(), until),
        Command::Bridge {
            dir,
            vehicle,
            bus,
            record,
            replay,
            wait,
            sim_leak_at,
        } => bridge(&dir, vehicle, bus, record, replay, &wait, sim_leak_at),
        Command::Journal {
            command: JournalCommand::Show { journal, format },
        } => journal_show(&journal, &format),
        Command::Send {
            dir,
            event,
            vehicle,
            count,
        } => send(&dir, &event, vehicle, count),
        Command::Status { dir, vehicle, json } => status(&dir, vehicle, json),
        Command::Dot { dir, net, output } => dot(&dir, net.as_deref(), output.as_deref()),
        Command::Export { dir, output, .. } => export(&dir, output.as_deref()),
        Command::Import {
            file,
            output,
            force,
        } => import(&file, output, force),
    };
    match outcome {
        Outcome::Clean => ExitCode::SUCCESS,
        Outcome::Errors => ExitCode::from(1),
        Outcome::Usage(msg) => {
            eprintln!("error: {msg}");
            ExitCode::from(2)
        }
    }
}

/// Writes to standard output. A closed pipe (`petrel ... | head`) ends the command quietly:
/// the reader has what it wanted.
fn out(text: &str) {
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

fn report(d: &Diagnostics, sources: &SourceMap) {
    if !d.is_empty() {
        eprint!("{}", d.render_human(sources));
    }
}

fn write_output(output: Option<&Path>, text: &str) -> Result<(), Outcome> {
    match output {
        Some(p) => std::fs::write(p, text)
            .map_err(|e| Outcome::Usage(format!("cannot write {}: {e}", p.display()))),
        None => {
            out(text);
            Ok(())
        }
    }
}

/// States explored by the quick verification of `petrel check`.
const QUICK_VERIFY_STATES: u64 = 100_000;

fn check(dir: &Path, format: Format, quick_verify: bool) -> Outcome {
    let (mut loaded, compiled, mut d) = match project::load_and_check(dir) {
        Ok(r) => r,
        Err(e) => return e.into(),
    };
    // The CAN data server's rules (can.toml and its DBC), checked against the events.
    if let Some(c) = &compiled {
        if let Err(e) = petrel_can_bridge::load_project_can(dir, c, &mut loaded.sources, &mut d) {
            return Outcome::Usage(format!("cannot read the project's CAN files: {e}"));
        }
        d.sort();
    }
    if let (Some(c), true) = (&compiled, quick_verify) {
        let opts = verify::VerifyOptions {
            max_states: Some(QUICK_VERIFY_STATES),
            ..Default::default()
        };
        match verify::verify(c, opts) {
            Ok(report) => d.extend(verify::diagnostics(&loaded.project, &report)),
            Err(e) => d.push(petrel_nets::diag::Diagnostic {
                severity: petrel_nets::diag::Severity::Warning,
                ..petrel_nets::diag::Diagnostic::global(
                    "W0605",
                    format!("the quick verification did not finish: {e}"),
                )
                .help("run `petrel verify` on the project for the full analysis")
            }),
        }
        d.sort();
    }
    match format {
        Format::Json => {
            let doc = d.to_json(&loaded.sources);
            out(&format!(
                "{}\n",
                serde_json::to_string_pretty(&doc).unwrap_or_default()
            ));
        }
        Format::Human => {
            report(&d, &loaded.sources);
            if let Some(c) = compiled.as_ref().filter(|_| !d.has_errors()) {
                let places: usize = c.nets.iter().map(|n| n.places.len()).sum();
                let transitions: usize = c.nets.iter().map(|n| n.transitions.len()).sum();
                out(&format!(
                    "project `{}` checks clean: {} nets ({} active at start), {} places, {} global places, {} transitions, {} events, {} programs, {} timers, {} warnings\n",
                    c.name,
                    c.nets.len(),
                    c.start.len(),
                    places,
                    c.globals.len(),
                    transitions,
                    c.events.len(),
                    c.programs.len(),
                    c.timers.len(),
                    d.warning_count()
                ));
            }
        }
    }
    if d.has_errors() {
        Outcome::Errors
    } else {
        Outcome::Clean
    }
}

fn verify_pnml(file: &Path, format: Format, max_states: Option<u64>) -> Outcome {
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
    let interactive =
        format == Format::Human && std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut clean = true;
    let mut docs = Vec::new();
    for net in &nets {
        let opts = reach::ExploreOptions {
            max_states,
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
                docs.push(reach::to_json(net, &r));
            }
            (Err(e), Format::Human) => {
                clean = false;
                eprintln!("error: {}", reach::render_error(net, &e));
            }
            (Err(e), Format::Json) => {
                clean = false;
                docs.push(reach::error_to_json(net, &e));
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

fn verify(dir: &Path, net: Option<String>, format: Format, max_states: Option<u64>) -> Outcome {
    if dir.is_file() {
        return verify_pnml(dir, format, max_states);
    }
    let (loaded, compiled, d) = match project::load_and_check(dir) {
        Ok(r) => r,
        Err(e) => return e.into(),
    };
    report(&d, &loaded.sources);
    let Some(c) = compiled else {
        eprintln!("fix the errors above first: only a project that checks can be verified");
        return Outcome::Errors;
    };
    let interactive =
        format == Format::Human && std::io::IsTerminal::is_terminal(&std::io::stderr());
    let opts = verify::VerifyOptions {
        max_states,
        only_net: net,
        progress: interactive.then(|| {
            Box::new(|states: u64, rate: f64| {
                eprint!("\r{states} states, {rate:.0} states/s   ");
            }) as Box<dyn FnMut(u64, f64)>
        }),
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
    match format {
        Format::Json => out(&format!(
            "{}\n",
            serde_json::to_string_pretty(&verify::to_json(&r)).unwrap_or_default()
        )),
        Format::Human => out(&verify::render_human(&c.name, &r)),
    }
    if r.is_clean() {
        Outcome::Clean
    } else {
        Outcome::Errors
    }
}

fn run(dir: &Path, script_path: &Path, quiet: bool) -> Outcome {
    let (loaded, compiled, d) = match project::load_and_check(dir) {
        Ok(r) => r,
        Err(e) => return e.into(),
    };
    report(&d, &loaded.sources);
    let Some(c) = compiled else {
        eprintln!("fix the errors above first: only a project that checks can run");
        return Outcome::Errors;
    };
    let text = match std::fs::read_to_string(script_path) {
        Ok(t) => t,
        Err(e) => return Outcome::Usage(format!("cannot read {}: {e}", script_path.display())),
    };
    let script = match petrel_player::script::parse_script(&text, &c) {
        Ok(s) => s,
        Err(errors) => {
            let list: Vec<String> = errors
                .iter()
                .map(|(n, e)| format!("{}:{n}: {e}", script_path.display()))
                .collect();
            return Outcome::Usage(format!("the script has errors:\n{}", list.join("\n")));
        }
    };
    let outcome = petrel_player::script::run_script(&c, &script, |step| {
        if !quiet {
            out(&format!("{step}\n"));
        }
    });
    let expectations = script
        .lines
        .iter()
        .filter(|(_, l)| matches!(l, petrel_player::script::Line::Expect { .. }))
        .count();
    match outcome.failure {
        Some((line, msg)) => {
            eprintln!(
                "{}:{line}: expectation failed: {msg}",
                script_path.display()
            );
            Outcome::Errors
        }
        None => {
            eprintln!(
                "{}: {} steps, {expectations} expectations met",
                script_path.display(),
                outcome.steps.len()
            );
            Outcome::Clean
        }
    }
}

/// Loads and checks a project for the commands that talk to a vehicle.
fn compiled(dir: &Path) -> Result<petrel_nets::compiled::CompiledProject, Outcome> {
    let (loaded, compiled, d) = project::load_and_check(dir)?;
    report(&d, &loaded.sources);
    compiled.ok_or_else(|| {
        eprintln!("fix the errors above first (`petrel check` lists them)");
        Outcome::Errors
    })
}

/// The options of `petrel play`.
#[derive(clap::Args)]
struct PlayArgs {
    /// The vehicle (its services are petrel/<vehicle>/...); default: the project's name.
    #[arg(long)]
    vehicle: Option<String>,
    /// How the reactor waits: block, spin, or spin-then-block:<microseconds>.
    #[arg(long, default_value = "block")]
    wait: String,
    /// Stop after this many seconds (for demos and tests).
    #[arg(long)]
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
    #[arg(long, default_value_t = 64)]
    rotate_mb: u64,
    /// Restore the mission from the journal (after a crash) and carry on.
    #[arg(long)]
    resume: bool,
    /// Ground-station shadow: follow the vehicle player's steps, run no action, and raise an
    /// alarm the moment this copy's marking differs from the vehicle's.
    #[arg(long, conflicts_with_all = ["resume"])]
    shadow: bool,
}

fn play(dir: &Path, a: PlayArgs) -> Outcome {
    let c = match compiled(dir) {
        Ok(c) => c,
        Err(o) => return o,
    };
    let strategy: petrel_ipc::WaitStrategy = match a.wait.parse() {
        Ok(s) => s,
        Err(e) => return Outcome::Usage(e),
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
        if !(secs.is_finite() && secs >= 0.0) {
            return Outcome::Usage(format!("--run-for takes a number of seconds, not {secs}"));
        }
        opts.run_for = Some(std::time::Duration::from_secs_f64(secs));
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

fn bridge(
    dir: &Path,
    vehicle: Option<String>,
    bus: Option<String>,
    record: Option<PathBuf>,
    replay_log: Option<PathBuf>,
    wait: &str,
    sim_leak_at: Option<f64>,
) -> Outcome {
    use petrel_can_bridge::serve::{replay_log as replay_can, serve, ServeOptions};
    let (mut loaded, compiled, mut d) = match project::load_and_check(dir) {
        Ok(r) => r,
        Err(e) => return e.into(),
    };
    let Some(c) = compiled else {
        report(&d, &loaded.sources);
        return Outcome::Errors;
    };
    let can = match petrel_can_bridge::load_project_can(dir, &c, &mut loaded.sources, &mut d) {
        Ok(x) => x,
        Err(e) => return Outcome::Usage(format!("cannot read the project's CAN files: {e}")),
    };
    d.sort();
    report(&d, &loaded.sources);
    if d.has_errors() {
        return Outcome::Errors;
    }
    let Some((config, dbc)) = can else {
        return Outcome::Usage(format!(
            "{} has no can.toml: the CAN data server has nothing to serve",
            dir.display()
        ));
    };
    if let Some(log) = replay_log {
        return match replay_can(&log, config, dbc) {
            Ok(events) => {
                let mut text = String::new();
                for e in events {
                    let params: Vec<serde_json::Value> = e
                        .params
                        .iter()
                        .map(|v| match v {
                            petrel_nets::compiled::Value::Int(i) => (*i).into(),
                            petrel_nets::compiled::Value::Float(f) => (*f).into(),
                            petrel_nets::compiled::Value::Bool(b) => (*b).into(),
                            petrel_nets::compiled::Value::Text(s) => s.clone().into(),
                            petrel_nets::compiled::Value::FloatList(l) => l.clone().into(),
                        })
                        .collect();
                    let doc = serde_json::json!({"time_us": e.time_us, "event": e.name, "params": params});
                    text.push_str(&format!("{doc}\n"));
                }
                out(&text);
                Outcome::Clean
            }
            Err(e) => {
                eprintln!("error: {e}");
                Outcome::Errors
            }
        };
    }
    let strategy: petrel_ipc::WaitStrategy = match wait.parse() {
        Ok(s) => s,
        Err(e) => return Outcome::Usage(e),
    };
    let v = match vehicle_of(&c, vehicle) {
        Ok(v) => v,
        Err(o) => return o,
    };
    let opts = ServeOptions {
        bus,
        record,
        wait: strategy,
        sim_faults: petrel_can_bridge::sim::SimFaults {
            leak_at_depth: sim_leak_at,
        },
    };
    match serve(&v, config, dbc, opts) {
        Ok(r) => {
            eprintln!("bridge stopped: {r:?}");
            Outcome::Clean
        }
        Err(e) => Outcome::Usage(e.to_string()),
    }
}

fn replay(journal: &Path, project_dir: Option<&Path>, until: Option<f64>) -> Outcome {
    use petrel_player::journal::{read_journal, Entry};
    let read = match read_journal(journal) {
        Ok(r) => r,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    if let Some(t) = &read.torn {
        eprintln!(
            "warning: the last record of {} (byte {}) is torn: {}; replaying what precedes it",
            t.segment.display(),
            t.offset,
            t.what
        );
    }
    let (recorded_dir, digest) = match read.entries.first() {
        Some(Entry::Header {
            project_dir,
            digest,
            ..
        }) => (PathBuf::from(project_dir), *digest),
        _ => {
            return Outcome::Usage(format!(
                "{} does not start with a journal header",
                journal.display()
            ))
        }
    };
    let dir = project_dir.map(Path::to_path_buf).unwrap_or(recorded_dir);
    let c = match compiled(&dir) {
        Ok(c) => c,
        Err(o) => return o,
    };
    if petrel_player::journal::project_digest(&c) != digest {
        eprintln!(
            "error: {} is not the project this journal recorded (its nets or manifest changed): replay would not mean anything",
            dir.display()
        );
        return Outcome::Errors;
    }
    let until_us = until.map(|s| (s * 1e6).round().max(0.0) as u64);
    let (engine, r) = petrel_player::replay::replay(&c, &read.entries, until_us);
    if let Some(d) = &r.divergence {
        eprintln!(
            "divergence at entry {} (t = {:.6} s), event `{}`: {}\n  recorded: {}\n  replayed: {}",
            d.entry,
            d.time as f64 / 1e6,
            d.event,
            d.what,
            d.recorded.join(" "),
            d.replayed.join(" ")
        );
        return Outcome::Errors;
    }
    if let Some(c) = &read.corrupt {
        eprintln!(
            "error: {} is damaged at record {} (byte {}): {}; the {} entries before it replay to the recorded markings",
            c.segment.display(),
            c.record,
            c.offset,
            c.what,
            r.entries
        );
        return Outcome::Errors;
    }
    let marking: Vec<String> = engine
        .marking()
        .into_iter()
        .map(|(n, p)| format!("{n}{{{}}}", p.join(", ")))
        .collect();
    out(&format!(
        "replayed {} entries, {} steps: every recorded marking reproduced{}\nstate at t = {:.6} s: {}\n",
        r.entries,
        r.steps,
        if r.stopped_early { " (stopped at --until)" } else { "" },
        match until {
            Some(u) if r.stopped_early => u,
            _ => r.last_time as f64 / 1e6,
        },
        marking.join(" ")
    ));
    Outcome::Clean
}

fn journal_show(journal: &Path, format: &str) -> Outcome {
    use petrel_player::journal::{read_journal, Entry};
    let read = match read_journal(journal) {
        Ok(r) => r,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let wire = |params: &[petrel_ipc::Value]| -> Vec<String> {
        params
            .iter()
            .map(|v| match v {
                petrel_ipc::Value::Int(i) => i.to_string(),
                petrel_ipc::Value::Float(f) => petrel_nets::fmt::format_float(*f),
                petrel_ipc::Value::Bool(b) => b.to_string(),
                petrel_ipc::Value::Text(s) => petrel_nets::fmt::quote(s),
                petrel_ipc::Value::FloatList(l) => format!(
                    "[{}]",
                    l.iter()
                        .map(|f| petrel_nets::fmt::format_float(*f))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })
            .collect()
    };
    let csv_field = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    let mut text = String::new();
    if format == "csv" {
        text.push_str("index,time_s,kind,event,params,origin,outcome,fired,actions\n");
    } else if format != "text" && format != "json" {
        return Outcome::Usage(format!("unknown format `{format}`: use text, json or csv"));
    }
    for (i, e) in read.entries.iter().enumerate() {
        let t = e.time().map(|t| t as f64 / 1e6);
        let (kind, event, params, origin, outcome, fired, actions) = match e {
            Entry::Header {
                project, vehicle, ..
            } => (
                "header",
                project.clone(),
                vec![],
                vehicle.clone(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Start { .. } => (
                "start",
                String::new(),
                vec![],
                String::new(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Resume { .. } => (
                "resume",
                String::new(),
                vec![],
                String::new(),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Submit {
                event,
                params,
                origin,
                seq,
                ..
            } => (
                "submit",
                event.clone(),
                wire(params),
                format!("{origin}#{seq}"),
                String::new(),
                vec![],
                vec![],
            ),
            Entry::Refused {
                what,
                reason,
                origin,
                ..
            } => (
                "refused",
                what.clone(),
                vec![],
                origin.clone(),
                reason.clone(),
                vec![],
                vec![],
            ),
            Entry::Step {
                event,
                params,
                outcome,
                fired,
                actions,
                ..
            } => (
                "step",
                event.clone(),
                wire(params),
                String::new(),
                outcome.clone(),
                fired.clone(),
                actions.clone(),
            ),
        };
        match format {
            "json" => {
                let doc = serde_json::json!({
                    "index": i, "time": t, "kind": kind, "event": event, "params": params,
                    "origin": origin, "outcome": outcome, "fired": fired, "actions": actions,
                });
                text.push_str(&format!("{doc}\n"));
            }
            "csv" => text.push_str(&format!(
                "{i},{},{kind},{},{},{},{},{},{}\n",
                t.map(|t| format!("{t:.6}")).unwrap_or_default(),
                csv_field(&event),
                csv_field(&params.join(", ")),
                csv_field(&origin),
                csv_field(&outcome),
                csv_field(&fired.join(" ")),
                csv_field(&actions.join("; "))
            )),
            _ => {
                let time = t
                    .map(|t| format!("{t:>12.6}"))
                    .unwrap_or_else(|| " ".repeat(12));
                let args = if params.is_empty() {
                    String::new()
                } else {
                    format!("({})", params.join(", "))
                };
                let mut line = format!("{i:>6} {time}  {kind:<7} {event}{args}");
                if !origin.is_empty() {
                    line.push_str(&format!("  from {origin}"));
                }
                if !outcome.is_empty() {
                    line.push_str(&format!("  [{outcome}]"));
                }
                if !fired.is_empty() {
                    line.push_str(&format!("  fired {}", fired.join(", ")));
                }
                if !actions.is_empty() {
                    line.push_str(&format!("  => {}", actions.join("; ")));
                }
                text.push_str(&line);
                text.push('\n');
            }
        }
    }
    out(&text);
    if let Some(t) = &read.torn {
        eprintln!(
            "warning: torn last record in {} at byte {}: {}",
            t.segment.display(),
            t.offset,
            t.what
        );
    }
    if let Some(c) = &read.corrupt {
        eprintln!(
            "error: {} damaged at record {} (byte {}): {}",
            c.segment.display(),
            c.record,
            c.offset,
            c.what
        );
        return Outcome::Errors;
    }
    Outcome::Clean
}

fn vehicle_of(
    c: &petrel_nets::compiled::CompiledProject,
    vehicle: Option<String>,
) -> Result<petrel_ipc::Vehicle, Outcome> {
    let name = vehicle.unwrap_or_else(|| c.name.clone());
    petrel_ipc::Vehicle::new(&name)
        .map_err(|e| Outcome::Usage(format!("bad vehicle name `{name}`: {e}")))
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

fn send(dir: &Path, event: &str, vehicle: Option<String>, count: u64) -> Outcome {
    let c = match compiled(dir) {
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
    let wire: Vec<petrel_ipc::Value> = params
        .iter()
        .map(petrel_player::runtime::value_to_wire)
        .collect();
    let msg = petrel_ipc::EventMsg::new(name.clone(), wire);
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

fn status(dir: &Path, vehicle: Option<String>, json: bool) -> Outcome {
    let c = match compiled(dir) {
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

fn fmt(dir: &Path, check_only: bool) -> Outcome {
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
                let path = dir.join(&file.path);
                if let Err(e) = std::fs::write(&path, &text) {
                    return Outcome::Usage(format!("cannot write {}: {e}", path.display()));
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

/// Loads and checks; on errors reports them and returns `Err(Outcome::Errors)`.
fn checked(dir: &Path) -> Result<project::LoadedProject, Outcome> {
    let (loaded, _, d) = project::load_and_check(dir)?;
    report(&d, &loaded.sources);
    if d.has_errors() {
        eprintln!("fix the errors above first (`petrel check` lists them)");
        return Err(Outcome::Errors);
    }
    Ok(loaded)
}

fn dot(dir: &Path, net: Option<&str>, output: Option<&Path>) -> Outcome {
    let loaded = match checked(dir) {
        Ok(l) => l,
        Err(o) => return o,
    };
    match petrel_nets::dot::project_to_dot(&loaded.project, net) {
        Ok(text) => match write_output(output, &text) {
            Ok(()) => Outcome::Clean,
            Err(o) => o,
        },
        Err(msg) => Outcome::Usage(msg),
    }
}

fn export(dir: &Path, output: Option<&Path>) -> Outcome {
    let loaded = match checked(dir) {
        Ok(l) => l,
        Err(o) => return o,
    };
    let text = petrel_nets::pnml::export_pnml(&loaded.project);
    match write_output(output, &text) {
        Ok(()) => Outcome::Clean,
        Err(o) => o,
    }
}

fn import(file: &Path, output: Option<PathBuf>, force: bool) -> Outcome {
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
        "imported {} into {}: {nets} net(s), {places} places, {transitions} transitions\n",
        file.display(),
        dest.display()
    ));
    Outcome::Clean
}
