//! What the partial-order reduction saves `petrel verify` (docs/benchmarks.md): the family of
//! N independent nets, each toggled by its own two events, verified with the reduction and
//! without it (`--no-reduction`), each verification in a process of its own so that its peak
//! memory is its own; the missions of the repository likewise.
//!
//! Usage:
//! - `reduction_bench [--limit SECONDS] [--max N] [--baseline EXE]`: the missions, then the
//!   family for N = 2, 4, 8, 12, 16, 18, 20, 50, 100 up to `--max` (100 by default); the full
//!   exploration stops being run once one takes more than `--limit` seconds (20 by default) or
//!   reaches a million states. Prints a Markdown table; then what the full exploration costs
//!   per state (microseconds, and bytes of peak memory above that of the smallest project);
//!   with `--baseline`, another build of this program (built from an older commit, say) runs
//!   the same full explorations in the same run, before and after side by side.
//! - `reduction_bench --one (DIR | toggles:N) (reduced | full) [auto | keep | replay]`: one
//!   verification (the edges kept or recomputed as the last word says, `auto` by default:
//!   `VerifyOptions::edges`); prints `states edges seconds peak_kb errors warnings graph_bytes
//!   explore_seconds` on one line (`graph_bytes`: what the explored graph's states, parent
//!   pointers and edges hold; `explore_seconds`: the part of `seconds` until the exploration
//!   ended, before the analyses and the findings' traces).

use petrel_nets::project::{from_sources, load_and_check};
use petrel_verify::{verify, EdgeMemory, VerifyOptions};
use std::path::Path;
use std::process::{Command, ExitCode};
use std::time::Instant;

/// The manifest and net file of `n` independent two-place nets, `Tk` toggled by `up_k` and
/// `down_k`.
fn toggles(n: usize) -> (String, String) {
    let mut m = String::from("[project]\nname = \"toggles\"\nfiles = [\"t.pn\"]\nstart = [");
    let names: Vec<String> = (1..=n).map(|k| format!("\"T{k}\"")).collect();
    m.push_str(&names.join(", "));
    m.push_str("]\n\n[events]\n");
    let mut nets = String::new();
    for k in 1..=n {
        m.push_str(&format!(
            "up_{k} = {{ category = \"nominal\" }}\ndown_{k} = {{ category = \"nominal\" }}\n"
        ));
        nets.push_str(&format!(
            "net T{k} {{\n    place off = 1\n    place on\n    transition up on up_{k}: off -> on\n    transition down on down_{k}: on -> off\n}}\n"
        ));
    }
    (m, nets)
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

fn one(what: &str, reduced: bool, edges: EdgeMemory) -> Result<String, String> {
    let project = if let Some(n) = what.strip_prefix("toggles:") {
        let n: usize = n.parse().map_err(|_| format!("bad N in `{what}`"))?;
        let (manifest, nets) = toggles(n);
        let (_, c, d, _) = from_sources(&manifest, &[("t.pn", &nets)]);
        c.ok_or_else(|| format!("the generated project does not check: {d:?}"))?
    } else {
        let (_, c, d) = load_and_check(Path::new(what)).map_err(|e| e.to_string())?;
        c.ok_or_else(|| format!("{what} does not check: {} errors", d.error_count()))?
    };
    let started = Instant::now();
    let r = verify(
        &project,
        VerifyOptions {
            no_reduction: !reduced,
            edges,
            ..Default::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let secs = started.elapsed().as_secs_f64();
    Ok(format!(
        "{} {} {secs:.4} {} {} {} {} {:.4}",
        r.states,
        r.edges,
        peak_kb(),
        r.errors(),
        r.warnings(),
        r.graph_bytes,
        r.explore_seconds
    ))
}

/// One verification in a child process (`exe`): states, edges, seconds, peak kB, errors,
/// warnings, graph bytes, seconds of exploration (0 from a build that does not count them).
fn child(exe: &Path, what: &str, reduced: bool) -> Result<[f64; 8], String> {
    let o = Command::new(exe)
        .args(["--one", what, if reduced { "reduced" } else { "full" }])
        .output()
        .map_err(|e| e.to_string())?;
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    let text = String::from_utf8_lossy(&o.stdout);
    let mut out = [0.0; 8];
    for (k, f) in text.split_whitespace().take(8).enumerate() {
        out[k] = f.parse().unwrap_or(0.0);
    }
    Ok(out)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--one") {
        let usage = "usage: reduction_bench --one (DIR | toggles:N) (reduced | full) [auto | keep | replay]";
        let (Some(what), Some(mode)) = (args.get(1), args.get(2)) else {
            eprintln!("{usage}");
            return ExitCode::from(2);
        };
        let edges = match args.get(3).map(String::as_str) {
            None | Some("auto") => EdgeMemory::Auto,
            Some("keep") => EdgeMemory::Keep,
            Some("replay") => EdgeMemory::Replay,
            Some(_) => {
                eprintln!("{usage}");
                return ExitCode::from(2);
            }
        };
        return match one(what, mode == "reduced", edges) {
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
    let (mut limit, mut max) = (20.0, 100usize);
    let mut baseline: Option<std::path::PathBuf> = None;
    let mut it = args.into_iter();
    while let Some(a) = it.next() {
        let text = it.next();
        let value = text.as_deref().and_then(|x| x.parse::<f64>().ok());
        match (a.as_str(), value) {
            ("--limit", Some(x)) => limit = x,
            ("--max", Some(x)) => max = x as usize,
            ("--baseline", _) if text.is_some() => baseline = text.map(Into::into),
            _ => {
                eprintln!("usage: reduction_bench [--limit SECONDS] [--max N] [--baseline EXE]");
                return ExitCode::from(2);
            }
        }
    }
    let me = match std::env::current_exe() {
        Ok(x) => x,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    // The full explorations, for the per-state costs: (label, what, result).
    let mut fulls: Vec<(String, String, [f64; 8])> = Vec::new();
    println!("| project | states full | states reduced | s full | s reduced | time ratio | MB full | MB reduced | memory ratio | same errors, warnings |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions");
    let mut work: Vec<(String, String)> = ["uav", "auv", "ugv", "redermor"]
        .iter()
        .map(|m| (m.to_string(), root.join(m).display().to_string()))
        .collect();
    for n in [2usize, 4, 8, 12, 16, 18, 20, 50, 100] {
        if n <= max {
            work.push((format!("{n} toggles"), format!("toggles:{n}")));
        }
    }
    let mut full_too = true;
    for (label, what) in &work {
        let red = match child(&me, what, true) {
            Ok(x) => x,
            Err(e) => {
                eprintln!("error: {what}: {e}");
                return ExitCode::from(1);
            }
        };
        let full = if full_too {
            match child(&me, what, false) {
                Ok(x) => {
                    fulls.push((label.clone(), what.clone(), x));
                    Some(x)
                }
                Err(e) => {
                    eprintln!("error: {what}: {e}");
                    return ExitCode::from(1);
                }
            }
        } else {
            None
        };
        match full {
            Some(f) => {
                println!(
                    "| {label} | {} | {} | {:.4} | {:.4} | {:.4} | {:.1} | {:.1} | {:.2} | {} |",
                    f[0],
                    red[0],
                    f[2],
                    red[2],
                    red[2] / f[2].max(1e-4),
                    f[3] / 1024.0,
                    red[3] / 1024.0,
                    red[3] / f[3].max(1.0),
                    if f[4] == red[4] && f[5] == red[5] {
                        "yes".to_string()
                    } else {
                        format!("NO: {} {} full, {} {} reduced", f[4], f[5], red[4], red[5])
                    }
                );
                // Beyond a million states the next size (2^50 states) cannot finish.
                if label.ends_with("toggles") && (f[2] > limit || f[0] >= (1u64 << 20) as f64) {
                    full_too = false;
                }
            }
            None => println!(
                "| {label} | (not run) | {} | - | {:.4} | - | - | {:.1} | - | - |",
                red[0],
                red[2],
                red[3] / 1024.0
            ),
        }
    }
    per_state(&fulls, baseline.as_deref())
}

/// What the full exploration costs per state: microseconds, bytes of peak memory above the
/// smallest project's (the process's own), and the graph's counted bytes; with a baseline
/// build, its figures for the same projects, run now.
fn per_state(fulls: &[(String, String, [f64; 8])], baseline: Option<&Path>) -> ExitCode {
    let floor = |runs: &[[f64; 8]]| runs.iter().map(|r| r[3]).fold(f64::INFINITY, f64::min);
    let mut before: Vec<[f64; 8]> = Vec::new();
    if let Some(exe) = baseline {
        for (_, what, _) in fulls {
            match child(exe, what, false) {
                Ok(x) => before.push(x),
                Err(e) => {
                    eprintln!("error: baseline {what}: {e}");
                    return ExitCode::from(1);
                }
            }
        }
    }
    let after: Vec<[f64; 8]> = fulls.iter().map(|f| f.2).collect();
    let (floor_after, floor_before) = (floor(&after), floor(&before));
    let us = |r: &[f64; 8]| r[2] * 1e6 / r[0].max(1.0);
    let explore_us = |r: &[f64; 8]| r[7] * 1e6 / r[0].max(1.0);
    let bytes = |r: &[f64; 8], floor: f64| (r[3] - floor).max(0.0) * 1024.0 / r[0].max(1.0);
    println!();
    println!(
        "Full exploration per state (peak memory above {floor_after:.0} kB, the smallest run's)"
    );
    println!();
    if before.is_empty() {
        println!("| project | states | edges | us/state | exploration us/state | bytes/state | graph bytes/state |");
        println!("|---|---:|---:|---:|---:|---:|---:|");
    } else {
        println!("| project | states | edges | us/state before | us/state after | time ratio | exploration us/state after | bytes/state before | bytes/state after | memory ratio | graph bytes/state after | same errors, warnings |");
        println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    }
    for (k, (label, _, a)) in fulls.iter().enumerate() {
        let graph = a[6] / a[0].max(1.0);
        match before.get(k) {
            None => println!(
                "| {label} | {} | {} | {:.2} | {:.2} | {:.0} | {graph:.0} |",
                a[0],
                a[1],
                us(a),
                explore_us(a),
                bytes(a, floor_after)
            ),
            Some(b) => println!(
                "| {label} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} | {:.0} | {:.2} | {graph:.0} | {} |",
                a[0],
                a[1],
                us(b),
                us(a),
                us(a) / us(b).max(1e-9),
                explore_us(a),
                bytes(b, floor_before),
                bytes(a, floor_after),
                bytes(a, floor_after) / bytes(b, floor_before).max(1e-9),
                if (b[0], b[1], b[4], b[5]) == (a[0], a[1], a[4], a[5]) {
                    "yes"
                } else {
                    "NO"
                }
            ),
        }
    }
    ExitCode::SUCCESS
}
