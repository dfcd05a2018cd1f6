//! What the checks of issue 13 (progress, stuck nets, starvation, minimal traces) cost
//! `petrel verify`: each project verified with and without them, in the same run, each
//! verification in a process of its own so that its peak memory is its own.
//!
//! Usage:
//! - `verify_bench [--limit SECONDS] [DIR...]`: the missions given (by default
//!   `missions/uav`, `missions/auv`, `missions/ugv`), then the generated family of N robots
//!   through one bottleneck, N = 2, 3, ... until a verification with the checks takes more
//!   than `--limit` seconds (60 by default). Prints a Markdown table.
//! - `verify_bench --one (DIR | robots:N) (with | without)`: one verification; prints
//!   `states edges seconds peak_kb errors` on one line (what the table is made of).
//!
//! The family: N instances of one ROBOT net; each asks, is granted the bottleneck (taking the
//! global place `free`), goes through, gives it back, and may be shocked on the way (a loop);
//! the end is every robot done.

use petrel_nets::project::{from_sources, load_and_check};
use petrel_verify::{verify, VerifyOptions};
use std::path::Path;
use std::process::{Command, ExitCode};
use std::time::Instant;

/// The manifest and net file of the family with `n` robots.
fn robots(n: usize) -> (String, String) {
    let mut m = String::from("[project]\nname = \"robots\"\nfiles = [\"robot.pn\"]\nstart = [");
    let names: Vec<String> = (1..=n).map(|k| format!("\"R{k}\"")).collect();
    m.push_str(&names.join(", "));
    m.push_str("]\n\n[globals]\nfree = 1\n\n[instances]\n");
    for k in 1..=n {
        m.push_str(&format!(
            "R{k} = {{ net = \"ROBOT\", args = [\"r{k}\"] }}\n"
        ));
    }
    m.push_str(
        "\n[events]\n\
         start_mission = { category = \"nominal\" }\n\
         granted = { category = \"nominal\", params = [\"robot: text\"] }\n\
         through = { category = \"nominal\", params = [\"robot: text\"] }\n\
         shock = { category = \"safety\", params = [\"robot: text\"] }\n\
         resumed = { category = \"nominal\", params = [\"robot: text\"] }\n\
         \n[programs.MOVES.functions]\ngo = [\"robot: text\"]\nstop = [\"robot: text\"]\n\
         \n[verify]\nfinal = [[",
    );
    let done: Vec<String> = (1..=n).map(|k| format!("\"R{k}.done\"")).collect();
    m.push_str(&done.join(", "));
    m.push_str("]]\n");
    let net = "net ROBOT(robot: text) {
    place idle = 1
    place waiting
    place inside
    place stopped
    place done

    transition ask on start_mission: idle -> waiting
    transition enter on granted(r) if r == self.robot: waiting, free -> inside {
        call MOVES.go(self.robot)
    }
    transition leave on through(r) if r == self.robot: inside -> done, free
    transition jolt on shock(r) if r == self.robot: inside -> stopped {
        call MOVES.stop(self.robot)
    }
    transition resume on resumed(r) if r == self.robot: stopped -> inside {
        call MOVES.go(self.robot)
    }
}
"
    .to_string();
    (m, net)
}

/// Peak resident memory of this process so far, in kB (Linux; 0 elsewhere).
fn peak_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn one(what: &str, with: bool) -> Result<String, String> {
    let project = if let Some(n) = what.strip_prefix("robots:") {
        let n: usize = n.parse().map_err(|_| format!("bad N in `{what}`"))?;
        let (manifest, net) = robots(n);
        let (_, c, d, _) = from_sources(&manifest, &[("robot.pn", &net)]);
        c.ok_or_else(|| format!("the generated project does not check: {d:?}"))?
    } else {
        let (_, c, d) = load_and_check(Path::new(what)).map_err(|e| e.to_string())?;
        c.ok_or_else(|| format!("{what} does not check: {} errors", d.error_count()))?
    };
    let started = Instant::now();
    let r = verify(
        &project,
        VerifyOptions {
            skip_liveness: !with,
            ..Default::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let secs = started.elapsed().as_secs_f64();
    Ok(format!(
        "{} {} {secs:.3} {} {}",
        r.states,
        r.edges,
        peak_kb(),
        r.errors()
    ))
}

/// Runs one verification in a child process: (states, edges, seconds, peak kB, errors).
fn child(what: &str, with: bool) -> Result<(u64, u64, f64, u64, u64), String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let o = Command::new(exe)
        .args(["--one", what, if with { "with" } else { "without" }])
        .output()
        .map_err(|e| e.to_string())?;
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    let text = String::from_utf8_lossy(&o.stdout);
    let f: Vec<&str> = text.split_whitespace().collect();
    let num = |k: usize| f.get(k).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
    Ok((
        num(0) as u64,
        num(1) as u64,
        num(2),
        num(3) as u64,
        num(4) as u64,
    ))
}

fn row(label: &str, what: &str) -> Result<f64, String> {
    let (states, edges, s0, m0, _) = child(what, false)?;
    let (_, _, s1, m1, errors) = child(what, true)?;
    println!(
        "| {label} | {states} | {edges} | {s0:.3} | {s1:.3} | {:.2} | {:.1} | {:.1} | {:.2} | {errors} |",
        s1 / s0.max(1e-6),
        m0 as f64 / 1024.0,
        m1 as f64 / 1024.0,
        m1 as f64 / (m0 as f64).max(1.0)
    );
    Ok(s1)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--one") {
        let (Some(what), Some(mode)) = (args.get(1), args.get(2)) else {
            eprintln!("usage: verify_bench --one (DIR | robots:N) (with | without)");
            return ExitCode::from(2);
        };
        return match one(what, mode == "with") {
            Ok(line) => {
                println!("{line}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(1)
            }
        };
    }
    let mut limit = 60.0;
    let mut dirs = Vec::new();
    let mut it = args.into_iter();
    while let Some(a) = it.next() {
        if a == "--limit" {
            match it.next().and_then(|x| x.parse().ok()) {
                Some(x) => limit = x,
                None => {
                    eprintln!("--limit needs a number of seconds");
                    return ExitCode::from(2);
                }
            }
        } else {
            dirs.push(a);
        }
    }
    if dirs.is_empty() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions");
        for m in ["uav", "auv", "ugv"] {
            dirs.push(root.join(m).display().to_string());
        }
    }
    println!("| project | states | edges | s without | s with | time ratio | MB without | MB with | memory ratio | errors |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for d in &dirs {
        let label = Path::new(d)
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_else(|| d.clone());
        if let Err(e) = row(&label, d) {
            eprintln!("error: {d}: {e}");
            return ExitCode::from(1);
        }
    }
    for n in 2.. {
        match row(&format!("{n} robots"), &format!("robots:{n}")) {
            Ok(s) if s > limit => break,
            Ok(_) => {}
            Err(e) => {
                eprintln!("{n} robots: {e}");
                break;
            }
        }
    }
    ExitCode::SUCCESS
}
