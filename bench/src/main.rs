//! `petrel-bench`: Petrel's latency suite, one command and one report (`scripts/bench.sh`).
//!
//! `petrel-bench run` measures, in one go on the machine at hand: the transport round trip
//! (program -> player -> program) per wait strategy beside raw iceoryx2, Unix-socket and TCP
//! ping-pongs, all measured in alternating blocks; the vehicle path through the CAN data server on the in-memory bus and on vcan0
//! in the VM beside a bare echo; the same round trips under load; the processes'
//! footprint; and the round trip with 1, 10 and 50 programs. It writes docs/benchmarks.md's
//! latency section and CDF plots in docs/bench/. `petrel-bench role ...` are the processes a
//! measurement starts (this binary again); `petrel-bench vcan` is what runs inside the VM.

mod alternate;
mod footprint;
mod measure;
mod project;
mod report;
mod roles;
mod stats;
mod vehicle;

use std::path::PathBuf;
use std::process::{Command, ExitCode};
use std::time::Duration;

use clap::{Parser, Subcommand};
use petrel_ipc::WaitStrategy;

use measure::{Load, Settings};
use report::Report;

#[derive(Parser)]
#[command(name = "petrel-bench", about = "Petrel's latency benchmark suite")]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Measure, and write the report (docs/benchmarks.md's section, docs/bench/*.svg).
    Run(RunArgs),
    /// The vcan measurements, where vcan0 exists (the VM): printed for `run` to read.
    Vcan {
        #[arg(long, default_value = "vcan0")]
        iface: String,
        #[arg(long)]
        rounds: usize,
        #[arg(long)]
        warmup: usize,
        #[arg(long)]
        max_secs: u64,
    },
    /// A process of a measurement (this binary run again).
    #[command(hide = true)]
    Role {
        #[command(subcommand)]
        role: RoleCmd,
    },
}

#[derive(clap::Args)]
struct RunArgs {
    /// A few hundred rounds each (the test suite's mode): nothing is written unless --doc or
    /// --svg is given.
    #[arg(long)]
    short: bool,
    /// Only these parts (comma-separated: transport, vehicle, load, footprint, scale): printed,
    /// nothing written unless --doc or --svg is given.
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// The Markdown file whose latency section is rewritten.
    #[arg(long)]
    doc: Option<PathBuf>,
    /// Where the SVG plots go.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Skip the vcan part (it boots a qemu VM).
    #[arg(long)]
    no_vm: bool,
    /// The repository (missions/, scripts/vcan-vm.sh); default: the one this was built from.
    #[arg(long)]
    repo: Option<PathBuf>,
}

#[derive(Subcommand)]
enum RoleCmd {
    Player {
        #[arg(long)]
        dir: PathBuf,
        #[arg(long)]
        vehicle: String,
        #[arg(long, default_value = "block")]
        wait: WaitStrategy,
        #[arg(long)]
        journal: Option<PathBuf>,
    },
    Program {
        #[arg(long)]
        vehicle: String,
        #[arg(long)]
        name: String,
        #[arg(long)]
        event: String,
        #[arg(long)]
        wait: WaitStrategy,
        #[arg(long)]
        warmup: usize,
        #[arg(long)]
        rounds: usize,
        #[arg(long)]
        max_secs: f64,
        #[arg(long)]
        gate: Option<PathBuf>,
        #[arg(long)]
        out: PathBuf,
    },
    IoxPong {
        #[arg(long)]
        name: String,
        #[arg(long)]
        prefix: String,
        #[arg(long)]
        mode: String,
        #[arg(long)]
        len: usize,
    },
    SockPong {
        #[arg(long)]
        uds: Option<PathBuf>,
        #[arg(long)]
        tcp: Option<String>,
        #[arg(long)]
        len: usize,
    },
    Emitter {
        #[arg(long)]
        vehicle: String,
        #[arg(long)]
        rate: f64,
    },
    StatusReader {
        #[arg(long)]
        vehicle: String,
    },
    Busy,
    Idle {
        #[arg(long)]
        iox: bool,
    },
    Bridge {
        #[arg(long)]
        dir: PathBuf,
        #[arg(long)]
        vehicle: String,
        #[arg(long)]
        iface: String,
        #[arg(long)]
        wait: WaitStrategy,
    },
    CanEcho {
        #[arg(long)]
        iface: String,
    },
    Ports,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Cmd::Run(a) => run(a),
        Cmd::Vcan {
            iface,
            rounds,
            warmup,
            max_secs,
        } => {
            let s = Settings {
                rounds,
                warmup,
                max: Duration::from_secs(max_secs),
                blocks: 1,
                scale_secs: 0.0,
                scale: Vec::new(),
                petrel: None,
                echo: None,
                repo: PathBuf::new(),
            };
            vehicle::vcan_all(&s, &iface)
        }
        Cmd::Role { role } => run_role(role),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("petrel-bench: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run_role(role: RoleCmd) -> roles::Res<()> {
    use std::os::unix::net::UnixStream;
    match role {
        RoleCmd::Player {
            dir,
            vehicle,
            wait,
            journal,
        } => roles::player(&dir, &vehicle, wait, journal),
        RoleCmd::Program {
            vehicle,
            name,
            event,
            wait,
            warmup,
            rounds,
            max_secs,
            gate,
            out,
        } => {
            let max = Duration::try_from_secs_f64(max_secs).map_err(|e| e.to_string())?;
            let m = roles::petrel_round_trips(&roles::RoundTrips {
                vehicle,
                program: name,
                event,
                wait,
                warmup,
                rounds,
                max,
                gate,
            })?;
            std::fs::write(&out, m.latencies.to_text())
                .map_err(|e| format!("{}: {e}", out.display()))
        }
        RoleCmd::IoxPong {
            name,
            prefix,
            mode,
            len,
        } => roles::iox_pong(&name, &prefix, mode == "waitset", len),
        RoleCmd::SockPong { uds, tcp, len } => match (uds, tcp) {
            (Some(path), None) => {
                let s =
                    UnixStream::connect(&path).map_err(|e| format!("{}: {e}", path.display()))?;
                roles::sock_pong(s, len)
            }
            (None, Some(addr)) => {
                let s = std::net::TcpStream::connect(&addr).map_err(|e| format!("{addr}: {e}"))?;
                s.set_nodelay(true).map_err(|e| e.to_string())?;
                roles::sock_pong(s, len)
            }
            _ => Err("sock-pong needs --uds or --tcp".to_owned()),
        },
        RoleCmd::Emitter { vehicle, rate } => roles::emitter(&vehicle, rate),
        RoleCmd::StatusReader { vehicle } => roles::status_reader(&vehicle),
        RoleCmd::Busy => roles::busy(),
        RoleCmd::Idle { iox } => roles::idle(iox),
        RoleCmd::Bridge {
            dir,
            vehicle,
            iface,
            wait,
        } => vehicle::bridge_role(&dir, &vehicle, &iface, wait),
        RoleCmd::CanEcho { iface } => vehicle::can_echo_role(&iface),
        RoleCmd::Ports => roles::ports(),
    }
}

fn sh(cmd: &str, args: &[&str]) -> String {
    Command::new(cmd)
        .args(args)
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
        .unwrap_or_default()
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|t| t.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".to_owned())
}

/// The share of the CPUs' time spent busy over `over` (from `/proc/stat`'s first line), or
/// `None` when it cannot be read.
fn cpu_busy(over: Duration) -> Option<f64> {
    let ticks = || -> Option<(u64, u64)> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let fields: Vec<u64> = stat
            .lines()
            .next()?
            .split_whitespace()
            .skip(1)
            .map(|f| f.parse().ok())
            .collect::<Option<_>>()?;
        // user nice system idle iowait irq softirq steal (guest time is inside user).
        let idle = fields.get(3)? + fields.get(4).unwrap_or(&0);
        let total: u64 = fields.iter().take(8).sum();
        Some((idle, total))
    };
    let (idle0, total0) = ticks()?;
    std::thread::sleep(over);
    let (idle1, total1) = ticks()?;
    let total = total1.checked_sub(total0).filter(|&t| t > 0)?;
    let idle = idle1.saturating_sub(idle0).min(total);
    Some(1.0 - idle as f64 / total as f64)
}

/// What the report says of the machine's other work: from how busy its CPUs were just before
/// the bench started (`busy`, 0 to 1), and the load averages at the start and at the end (the
/// bench's own processes included).
fn machine_note(busy: Option<f64>, load_start: &str, load_end: &str) -> String {
    let what = match busy {
        Some(b) if b < 0.25 => format!(
            "The machine was otherwise idle when this started (its CPUs {:.0} % busy in the \
             second before)",
            b * 100.0
        ),
        Some(b) => format!(
            "**Other work was running on the machine when this started** (its CPUs {:.0} % busy \
             in the second before)",
            b * 100.0
        ),
        None => "**Whether other work ran is not known** (/proc/stat unreadable)".to_owned(),
    };
    format!(
        "{what}; load average {load_start} at the start, {load_end} at the end, the bench's own \
         processes included. Absolute figures move by tens of percent between runs, and the \
         tails (p99.9, max) carry other processes' scheduling; the ratios within one run are \
         what count."
    )
}

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find_map(|l| l.strip_prefix("model name"))
                .map(|m| m.trim_start_matches([' ', '\t', ':']).to_owned())
        })
        .unwrap_or_else(|| "?".to_owned())
}

fn next_to_me(rel: &str) -> Option<PathBuf> {
    let me = std::env::current_exe().ok()?;
    let p = me.parent()?.join(rel);
    p.exists().then_some(p)
}

fn run(a: RunArgs) -> roles::Res<()> {
    let repo = a.repo.clone().unwrap_or_else(|| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .map(PathBuf::from)
            .unwrap_or_default()
    });
    let s = Settings {
        rounds: if a.short { 300 } else { 20_000 },
        warmup: if a.short { 50 } else { 1_000 },
        max: Duration::from_secs(if a.short { 10 } else { 20 }),
        blocks: if a.short { 5 } else { 20 },
        scale_secs: if a.short { 0.5 } else { 5.0 },
        scale: vec![1, 10, 50],
        petrel: next_to_me("petrel"),
        echo: next_to_me("examples/echo"),
        repo: repo.clone(),
    };
    let want = |part: &str| a.only.is_empty() || a.only.iter().any(|o| o == part);
    for o in &a.only {
        if !["transport", "vehicle", "load", "footprint", "scale"].contains(&o.as_str()) {
            return Err(format!(
                "--only: unknown part `{o}` (transport, vehicle, load, footprint, scale)"
            ));
        }
    }
    let started = std::time::Instant::now();
    let busy_start = cpu_busy(Duration::from_secs(1));
    let load_start = loadavg();
    let mut r = Report {
        scale_wait: "block".to_owned(),
        vehicle_vcan: Err("not run (--only)".to_owned()),
        ..Report::default()
    };
    let say = |what: &str| eprintln!("[{:>5.0} s] {what}", started.elapsed().as_secs_f64());

    if want("transport") || want("load") {
        say("transport: starting and warming up each set-up");
        (r.transport, r.transport_blocks) = transport(&s);
    }
    if want("vehicle") {
        say("vehicle path: memory bus");
        r.vehicle_mem
            .push(("bare echo".to_owned(), vehicle::memory_baseline(&s)));
        for wait in measure::strategies() {
            r.vehicle_mem.push((
                report::petrel_name(&wait.to_string()),
                vehicle::memory_path(&s, wait),
            ));
        }
        r.vehicle_vcan = if a.no_vm {
            Err("skipped (--no-vm)".to_owned())
        } else if a.short {
            Err(
                "skipped in the short mode (scripts/test.sh runs the vcan tests in the VM)"
                    .to_owned(),
            )
        } else {
            say("vehicle path: vcan0 in the VM");
            vcan_in_vm(&s, &repo)
        };
    }
    if want("load") {
        for load in [Load::Events, Load::Cpu] {
            say(&format!("under load: {load:?}"));
            if load == Load::Cpu {
                r.load.push((
                    load,
                    report::UDS.to_owned(),
                    measure::uds_rt(&s, load).map(|x| (x, Vec::new())),
                ));
            }
            for wait in measure::strategies() {
                r.load.push((
                    load,
                    report::petrel_name(&wait.to_string()),
                    measure::petrel_rt(&s, wait, load),
                ));
            }
        }
    }
    if want("footprint") {
        say("footprint");
        r.footprint = footprint::all(&s);
        r.ports = footprint::ports();
    }
    if want("scale") {
        for &n in &s.scale {
            say(&format!("scale: {n} programs"));
            r.scale.push(measure::scale(&s, n, WaitStrategy::Block));
        }
    }
    let build = if cfg!(debug_assertions) {
        "debug build"
    } else {
        "release build"
    };
    r.header = format!(
        "{} ({}, {:.0} s), {build}. Machine: {} CPUs ({}), {}. {}",
        sh("date", &["-u", "+%Y-%m-%d %H:%M UTC"]),
        if a.short {
            "`scripts/bench.sh --short`"
        } else {
            "`scripts/bench.sh`"
        },
        started.elapsed().as_secs_f64(),
        measure::cpus(),
        cpu_model(),
        sh("uname", &["-sr"]),
        machine_note(busy_start, &load_start, &loadavg()),
    );
    let svg_rel = "docs/bench";
    let md = r.markdown(&s, svg_rel);
    println!("{md}");
    let write_doc = a
        .doc
        .clone()
        .or_else(|| (a.only.is_empty() && !a.short).then(|| repo.join("docs/benchmarks.md")));
    let write_svg = a
        .svg
        .clone()
        .or_else(|| (a.only.is_empty() && !a.short).then(|| repo.join(svg_rel)));
    if let Some(dir) = write_svg {
        for f in r.plots(&dir)? {
            eprintln!("wrote {f}");
        }
    }
    if let Some(doc) = write_doc {
        let old = std::fs::read_to_string(&doc).unwrap_or_default();
        std::fs::write(&doc, report::splice(&old, &md))
            .map_err(|e| format!("{}: {e}", doc.display()))?;
        eprintln!("wrote {}", doc.display());
    }
    // Anything that failed fails the run (after the report, which says what).
    let failures = count_failures(&r);
    if failures > 0 {
        return Err(format!("{failures} measurement(s) failed: see the report"));
    }
    Ok(())
}

/// A set-up of part 1, started when its turn to warm up comes.
type Start = Box<dyn FnOnce() -> roles::Res<Box<dyn alternate::Side>>>;

/// Part 1: every set-up started and warmed up, then measured in alternating blocks (see
/// `alternate`), so that the goals' ratios compare the same minutes. The turns put each goal's
/// pair next to each other: raw iceoryx2 busy poll and Petrel spin, Petrel block and the Unix
/// socket. Returns the series in the table's order, and each one's blocks.
fn transport(s: &measure::Settings) -> (Vec<report::Series>, Vec<report::Blocks>) {
    let stb = WaitStrategy::SpinThenBlock(Duration::from_micros(200));
    let petrel = |w: WaitStrategy| -> (String, Start) {
        (
            report::petrel_name(&w.to_string()),
            Box::new(move || measure::PetrelSide::start(w)),
        )
    };
    let turns: Vec<(String, Start)> = vec![
        (
            report::IOX_BUSY.to_owned(),
            Box::new(|| measure::IoxPingPong::start(false)),
        ),
        petrel(WaitStrategy::Spin),
        petrel(stb),
        (
            report::IOX_WAITSET.to_owned(),
            Box::new(|| measure::IoxPingPong::start(true)),
        ),
        (report::TCP.to_owned(), Box::new(measure::tcp_side)),
        petrel(WaitStrategy::Block),
        (report::UDS.to_owned(), Box::new(measure::uds_side)),
    ];
    // Each set-up is started and warmed up while the ones before it are paused, then paused.
    let mut names = Vec::new();
    let mut sides = Vec::new();
    for (name, start) in turns {
        sides.push(alternate::prepare(start(), s.warmup));
        names.push(name);
    }
    let plan = alternate::Plan {
        rounds: s.rounds,
        blocks: s.blocks,
        block_warmup: (s.warmup / s.blocks.max(1)).max(1),
        max: s.max,
    };
    eprintln!(
        "  measuring in {} alternating blocks of about {} rounds each",
        s.blocks,
        s.rounds / s.blocks.max(1)
    );
    let mut measured: Vec<_> = names
        .into_iter()
        .zip(alternate::alternate(sides, &plan))
        .collect();
    // The table's order: baselines, then Petrel per strategy.
    let mut order = vec![
        report::IOX_BUSY.to_owned(),
        report::IOX_WAITSET.to_owned(),
        report::UDS.to_owned(),
        report::TCP.to_owned(),
    ];
    order.extend(
        measure::strategies()
            .iter()
            .map(|w| report::petrel_name(&w.to_string())),
    );
    let mut series = Vec::new();
    let mut blocks = Vec::new();
    for name in order {
        let Some(at) = measured.iter().position(|(n, _)| *n == name) else {
            continue;
        };
        let (name, r) = measured.remove(at);
        match r {
            Ok(a) => {
                blocks.push((name.clone(), a.blocks));
                series.push((name, Ok(a.latencies)));
            }
            Err(e) => series.push((name, Err(e))),
        }
    }
    (series, blocks)
}

fn count_failures(r: &Report) -> usize {
    r.transport.iter().filter(|(_, x)| x.is_err()).count()
        + r.vehicle_mem.iter().filter(|(_, x)| x.is_err()).count()
        + r.load.iter().filter(|(_, _, x)| x.is_err()).count()
        + r.footprint.iter().filter(|x| x.is_err()).count()
        + r.scale.iter().filter(|x| x.is_err()).count()
        + usize::from(!r.footprint.is_empty() && r.ports.is_err())
}

/// Runs `petrel-bench vcan` inside the VM and reads its histograms.
fn vcan_in_vm(s: &Settings, repo: &std::path::Path) -> Result<Vec<report::Series>, String> {
    let me = std::env::current_exe().map_err(|e| e.to_string())?;
    let script = repo.join("scripts/vcan-vm.sh");
    // The emulated CPUs are slow: fewer rounds, a longer limit.
    let rounds = (s.rounds / 10).max(200).to_string();
    let warmup = (s.warmup / 10).max(20).to_string();
    let out = Command::new(&script)
        .env("VCAN_VM_QUIET", "1")
        .args([
            "run",
            "--timeout",
            "400",
            "--",
            &me.display().to_string(),
            "vcan",
            "--rounds",
            &rounds,
            "--warmup",
            &warmup,
            "--max-secs",
            "60",
        ])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", script.display()))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let series = vehicle::parse_vcan(&text);
    if series.is_empty() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err.lines().rev().take(5).collect();
        return Err(format!(
            "the VM run gave no figures ({}; {})",
            out.status,
            tail.into_iter().rev().collect::<Vec<_>>().join(" / ")
        ));
    }
    Ok(series
        .into_iter()
        .map(|(n, r)| {
            let name = if n == "echo" {
                "bare SocketCAN echo".to_owned()
            } else {
                report::petrel_name(&n)
            };
            (name, r)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::{cpu_busy, machine_note};
    use std::time::Duration;

    #[test]
    fn the_report_says_whether_other_work_ran_from_the_cpus_at_the_start() {
        let load = ("0.42 1.10 1.30", "2.10 1.20 1.30");
        let idle = machine_note(Some(0.03), load.0, load.1);
        assert!(idle.starts_with("The machine was otherwise idle"), "{idle}");
        assert!(idle.contains("3 % busy"), "{idle}");
        assert!(
            idle.contains("load average 0.42 1.10 1.30 at the start, 2.10 1.20 1.30 at the end"),
            "{idle}"
        );
        let busy = machine_note(Some(0.6), load.0, load.1);
        assert!(busy.starts_with("**Other work was running"), "{busy}");
        assert!(busy.contains("60 % busy"), "{busy}");
        // Unknown: not called idle.
        assert!(machine_note(None, "?", "?").starts_with("**Whether other work ran is not known"));
    }

    #[test]
    fn this_machines_cpus_read_as_a_share() {
        let busy = cpu_busy(Duration::from_millis(50)).expect("/proc/stat");
        assert!((0.0..=1.0).contains(&busy), "{busy}");
    }
}
