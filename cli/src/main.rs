//! `petrel`: the command line of the Petrel mission supervisor.
//!
//! One module per family of commands: [`project`] (check, verify, fmt, dot, export, import),
//! [`script`] (run), [`vehicle`] (play, send, status), [`recorder`] (replay, journal),
//! [`bridge`], [`gateway`] and [`keys`] (a vehicle on several computers and its keys), [`up`] (a
//! whole vehicle from its vehicle.toml), [`monitor`] (the web monitor), [`gen`] (program
//! prototypes); [`common`] holds what they share, first of all the one way a project is loaded
//! and checked ([`common::check_project`]); [`help`] groups the commands in `petrel --help`. A
//! new command is a new module, one line in [`Command`] and its name in [`help::GROUPS`].
//!
//! Exit codes, for every command: 0 clean, 1 the project or file has errors, 2 usage or I/O
//! error.

mod bridge;
mod common;
mod gateway;
mod gen;
mod help;
mod keys;
mod map;
mod monitor;
mod plot;
mod project;
mod recorder;
mod reload;
mod script;
mod up;
mod vehicle;

use clap::{FromArgMatches, Parser, Subcommand};
use common::Outcome;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "petrel",
    version,
    about = "Petrel: a mission supervisor for autonomous vehicles, written as safe Petri nets",
    after_help = "Each command's own help: `petrel help COMMAND` or `petrel COMMAND --help`.\nExit codes: 0 clean, 1 errors found, 2 usage or I/O error."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// Every command, in the order of `petrel --help`'s groups (`help::GROUPS`). The first
// paragraph of each doc comment is the command's one line in `petrel --help`; the rest is for
// its own `--help`. (A doc comment here would become the top-level help's text.)
#[derive(Subcommand)]
enum Command {
    // Design a mission.
    /// Check a project: syntax, names, types, markings, can.toml, vehicle.toml
    ///
    /// Then the quick verification (reachable states, up to 100,000) unless --no-verify.
    Check(project::CheckArgs),
    /// Verify a project or one net: safety, dead ends, progress, stuck nets, loops
    ///
    /// Safety, dead markings, progress to the declared ends, stuck nets, starvation,
    /// invariants, loops, conflicts, each finding located in the text with the shortest event
    /// sequence to it (docs/verification.md). Given a PNML file, explore it as a plain P/T net
    /// (arc weights and token counts above one allowed).
    Verify(project::VerifyArgs),
    /// Run a mission script in virtual time, with no process
    ///
    /// Events at given times and expectations; each step prints as a JSON line. A failed
    /// expectation exits 1. The format is in docs/scripts.md.
    Run(script::RunArgs),
    /// Rewrite the project's net files in canonical layout
    ///
    /// Running it twice changes nothing.
    Fmt(project::FmtArgs),
    /// Print the project's nets, or with --tree the tree of nets, as Graphviz DOT
    ///
    /// Each instance of a template is drawn apart; --tree draws the nets and their
    /// activations.
    Dot(project::DotArgs),
    /// Generate a program prototype (a Cargo project) from the declared interface
    ///
    /// A Cargo project on the programs SDK: one typed handler per function, typed helpers for
    /// the events it may send, a README and a test against `petrel play`. Regenerating keeps
    /// the handlers.
    Gen(gen::GenArgs),
    /// Export the project as PNML (ISO/IEC 15909-2)
    ///
    /// Events and actions travel in a `<toolspecific tool="petrel">` block.
    Export(project::ExportArgs),
    /// Import a PNML file as a Petrel project
    Import(project::ImportArgs),
    // Run a vehicle.
    /// Bring a vehicle up from vehicle.toml: start, watch and stop every process
    ///
    /// Start the player, the data server and the programs in order, show their status, make
    /// the timed sends, restart what fails (by policy), and stop everything on Ctrl-C, at the
    /// mission's end, at --until or at --timeout. Exits 1 if any process failed. Under
    /// systemd (`Type=notify`), it tells the service manager when the vehicle is up and
    /// feeds its watchdog (docs/install.md).
    Up(up::UpArgs),
    /// Play the mission: the player process, talking to the vehicle's programs
    ///
    /// The player on iceoryx2. Stops on SIGINT or SIGTERM.
    Play(vehicle::PlayArgs),
    /// Send an event to a running player, as the operator
    ///
    /// For instance `petrel send DIR 'payload_failure("camera")'`.
    Send(vehicle::SendArgs),
    /// Print the live marking of every active net and the player's counters
    Status(vehicle::StatusArgs),
    /// Reload a running player's project with a new version, mid-mission
    ///
    /// The player maps its state onto the new version by names (and the --mapping file),
    /// verifies the new version from that state, and swaps between two steps; or refuses,
    /// with the reason, the finding and its trace, and the mission goes on unchanged. Exit 0
    /// accepted, 1 refused.
    Reload(reload::ReloadArgs),
    /// A web monitor of a running mission, or the replay of a recorded one
    ///
    /// A running mission with `--vehicle`, a recorded one with `--journal`: every net drawn,
    /// the marking in red, the event log, the programs.
    Monitor(monitor::MonitorArgs),
    /// The CAN data server: bus frames to events, calls to frames (can.toml)
    ///
    /// Frames from the vehicle bus become events for the player (by the rules of the
    /// project's can.toml), calls to the commands program become frames.
    Bridge(petrel_can_bridge::command::BridgeArgs),
    /// Join this computer's part of the vehicle to its other computers over zenoh
    ///
    /// Calls to programs elsewhere, events to a player elsewhere, the player's heartbeat and
    /// marking to ground stations; lost and returning computers become communication events
    /// (docs/gateway.md). Stops on SIGINT or SIGTERM, printing its counters.
    Gateway(gateway::GatewayArgs),
    /// Make the vehicle's keys for the link between its computers
    ///
    /// A certificate authority of the vehicle and a certificate per computer of vehicle.toml,
    /// owner-only, in this user's state directory or --out; an existing key is never replaced.
    /// Say where each computer needs its own (docs/gateway.md).
    Keys(keys::KeysArgs),
    // After a run.
    /// Replay a journal through the engine and check every recorded marking
    Replay(recorder::ReplayArgs),
    /// Print a journal for people (text) or for plotting (json, csv)
    Journal {
        #[command(subcommand)]
        command: recorder::JournalCommand,
    },
    /// Draw a recorded run's map (map.svg) and depth profile (profile.svg)
    ///
    /// map.svg: the project's map.toml, the vehicle's track, the planned routes and the events
    /// where they happened, with a legend and a scale (the monitor's map, by the same code);
    /// profile.svg: a track's depth against time. From a `petrel up` run directory or a journal.
    Plot(plot::PlotArgs),
    /// Internal to `petrel up`, not for people: starts PROGRAM with ARGS in place of this
    /// process, every signal unblocked (`petrel up` keeps its stop signals blocked, and a
    /// blocked mask would pass to the program through exec).
    #[command(name = "__exec", hide = true)]
    Exec(up::ExecArgs),
}

fn main() -> ExitCode {
    // The grouped help (help.rs) is clap's command with another template.
    let cli = match Cli::from_arg_matches(&help::command().get_matches()) {
        Ok(c) => c,
        Err(e) => e.exit(),
    };
    // Logs go to stderr; RUST_LOG sets the level (default: warnings and info of the player).
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                // zenoh's QUIC client warns at each connection that it does not check the
                // server's name: the gateway chose so (docs/gateway.md), the name that matters
                // being the certificate's computer, which zenoh's access control checks.
                .unwrap_or_else(|_| {
                    tracing_subscriber::EnvFilter::new("info,zenoh_link_commons::quic::utils=error")
                }),
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
        Command::Keys(a) => keys::keys(a),
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
