//! `petrel`: the command line of the Petrel mission supervisor.
//!
//! One module per family of commands: [`project`] (check, verify, fmt, dot, export, import),
//! [`script`] (run), [`vehicle`] (play, send, status), [`recorder`] (replay, journal),
//! [`bridge`], [`up`] (a whole vehicle from its vehicle.toml), [`monitor`] (the web monitor), [`gen`] (program prototypes); [`common`] holds what they share, first of all the one way a project is loaded
//! and checked ([`common::check_project`]). A new command is a new module and one line in
//! [`Command`].
//!
//! Exit codes, for every command: 0 clean, 1 the project or file has errors, 2 usage or I/O
//! error.

mod bridge;
mod common;
mod gateway;
mod gen;
mod monitor;
mod plot;
mod project;
mod recorder;
mod reload;
mod script;
mod up;
mod vehicle;

use clap::{Parser, Subcommand};
use common::Outcome;
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

/// Every command.
#[derive(Subcommand)]
enum Command {
    /// Check a mission project: syntax, names, types, markings.
    Check(project::CheckArgs),
    /// Verify a project (or one net of it): safety, dead markings, progress to the declared
    /// ends, stuck nets, starvation, invariants, loops, conflicts, each finding located in the
    /// text with the shortest event sequence to it (docs/verification.md). Given a PNML file, explore it as a plain P/T
    /// net (arc weights and token counts above one allowed).
    Verify(project::VerifyArgs),
    /// Play the mission: the player process on iceoryx2, talking to the vehicle's programs.
    /// Stops on SIGINT or SIGTERM.
    Play(vehicle::PlayArgs),
    /// The CAN data server: frames from the vehicle bus become events for the player (by the
    /// rules of the project's can.toml), calls to the commands program become frames.
    Bridge(petrel_can_bridge::command::BridgeArgs),
    /// The pictures of a Redermor run (Figure 9): map.svg (areas, forbidden zones, planned
    /// routes, the vehicle's track, events) and depth.svg, from a `petrel up` run directory.
    Plot(plot::PlotArgs),
    /// Bring a vehicle up from the project's vehicle.toml: start the player, the data server
    /// and the programs in order, show their status, make the timed sends, restart what fails
    /// (by policy), and stop everything on Ctrl-C, at the mission's end, at --until or at
    /// --timeout. Exits 1 if any process failed.
    Up(up::UpArgs),
    /// Join this computer's part of the vehicle to its other computers over zenoh: calls to
    /// programs elsewhere, events to a player elsewhere, the player's heartbeat and marking to
    /// ground stations; lost and returning computers become communication events
    /// (docs/gateway.md). Stops on SIGINT or SIGTERM, printing its counters.
    Gateway(gateway::GatewayArgs),
    /// Internal to `petrel up`, not for people: starts PROGRAM with ARGS in place of this
    /// process, every signal unblocked (`petrel up` keeps its stop signals blocked, and a
    /// blocked mask would pass to the program through exec).
    #[command(name = "__exec", hide = true)]
    Exec(up::ExecArgs),
    /// Replay a journal through the engine and check every recorded marking.
    Replay(recorder::ReplayArgs),
    /// Print a journal for people (text) or for plotting (json, csv).
    Journal {
        #[command(subcommand)]
        command: recorder::JournalCommand,
    },
    /// Send an event to a running player, as the operator: `petrel send DIR 'payload_failure("camera")'`.
    Send(vehicle::SendArgs),
    /// Print the live marking of every active net and the player's counters.
    Status(vehicle::StatusArgs),
    /// A web monitor of a running mission (`--vehicle`), or the replay of a recorded one
    /// (`--journal`): every net drawn, the marking in red, the event log, the programs.
    Monitor(monitor::MonitorArgs),
    /// Generate a program prototype (a Cargo project on the programs SDK) from the project's
    /// declared interface: one typed handler per function, typed helpers for the events it
    /// may send, a README and a test against `petrel play`. Regenerating keeps the handlers.
    Gen(gen::GenArgs),
    /// Reload a running player's project with a new version, mid-mission: the player maps
    /// its state onto the new version by names (and the --mapping file), verifies the new
    /// version from that state, and swaps between two steps; or refuses, with the reason, the
    /// finding and its trace, and the mission goes on unchanged. Exit 0 accepted, 1 refused.
    Reload(reload::ReloadArgs),
    /// Run a mission script in virtual time, with no process: events at given times and
    /// expectations; each step prints as a JSON line. A failed expectation exits 1. The format
    /// is in docs/scripts.md.
    Run(script::RunArgs),
    /// Rewrite the project's net files in canonical layout (running it twice changes nothing).
    Fmt(project::FmtArgs),
    /// Print the project's nets as Graphviz DOT (each instance of a template drawn apart), or
    /// with --tree the tree of nets and their activations.
    Dot(project::DotArgs),
    /// Export the project as PNML (ISO/IEC 15909-2); events and actions travel in a
    /// `<toolspecific tool="petrel">` block.
    Export(project::ExportArgs),
    /// Import a PNML file as a Petrel project.
    Import(project::ImportArgs),
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
        Command::Check(a) => project::check(a),
        Command::Verify(a) => project::verify(a),
        Command::Fmt(a) => project::fmt(a),
        Command::Dot(a) => project::dot(a),
        Command::Export(a) => project::export(a),
        Command::Import(a) => project::import(a),
        Command::Run(a) => script::run(a),
        Command::Play(a) => vehicle::play(a),
        Command::Send(a) => vehicle::send(a),
        Command::Status(a) => vehicle::status(a),
        Command::Monitor(a) => monitor::monitor(a),
        Command::Gen(a) => gen::gen(a),
        Command::Reload(a) => reload::reload(a),
        Command::Replay(a) => recorder::replay(a),
        Command::Journal { command } => recorder::journal(command),
        Command::Bridge(a) => bridge::bridge(a),
        Command::Plot(a) => plot::plot(a),
        Command::Up(a) => up::up(a),
        Command::Gateway(a) => gateway::gateway(a),
        Command::Exec(a) => up::exec(a),
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
