//! What the partial-order reduction saves `petrel verify` (docs/benchmarks.md): the family of
//! N independent nets, each toggled by its own two events, verified with the reduction and
//! without it (`--no-reduction`), each verification in a process of its own so that its peak
//! memory is its own; the missions of the repository likewise.
//!
//! Usage:
//! - `reduction_bench [--limit SECONDS] [--max N]`: the missions, then the family for
//!   N = 2, 4, 8, 12, 16, 18, 20, 50, 100 up to `--max` (100 by default); the full exploration stops being
//!   run once one takes more than `--limit` seconds (20 by default) or reaches a million
//!   states. Prints a Markdown table.
//! - `reduction_bench --one (DIR | toggles:N) (reduced | full)`: one verification; prints
//!   `states edges seconds peak_kb errors warnings` on one line.

use petrel_nets::project::{from_sources, load_and_check};
use petrel_nets::verify::{verify, VerifyOptions};
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

fn one(what: &str, reduced: bool) -> Result<String, String> {
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
            ..Default::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let secs = started.elapsed().as_secs_f64();
    Ok(format!(
        "{} {} {secs:.4} {} {} {}",
        r.states,
        r.edges,
        peak_kb(),
        r.errors(),
        r.warnings()
    ))
}

/// One verification in a child process: states, edges, seconds, peak kB, errors, warnings.
fn child(what: &str, reduced: bool) -> Result<[f64; 6], String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let o = Command::new(exe)
        .args(["--one", what, if reduced { "reduced" } else { "full" }])
        .output()
        .map_err(|e| e.to_string())?;
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    let text = String::from_utf8_lossy(&o.stdout);
    let mut out = [0.0; 6];
    for (k, f) in text.split_whitespace().take(6).enumerate() {
        out[k] = f.parse().unwrap_or(0.0);
    }
    Ok(out)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--one") {
        let (Some(what), Some(mode)) = (args.get(1), args.get(2)) else {
            eprintln!("usage: reduction_bench --one (DIR | toggles:N) (reduced | full)");
            return ExitCode::from(2);
        };
        return match one(what, mode == "reduced") {
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
    let mut it = args.into_iter();
    while let Some(a) = it.next() {
        let value = it.next().and_then(|x| x.parse::<f64>().ok());
        match (a.as_str(), value) {
            ("--limit", Some(x)) => limit = x,
            ("--max", Some(x)) => max = x as usize,
            _ => {
                eprintln!("usage: reduction_bench [--limit SECONDS] [--max N]");
                return ExitCode::from(2);
            }
        }
    }
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
        let red = match child(what, true) {
            Ok(x) => x,
            Err(e) => {
                eprintln!("error: {what}: {e}");
                return ExitCode::from(1);
            }
        };
        let full = if full_too {
            match child(what, false) {
                Ok(x) => Some(x),
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
    ExitCode::SUCCESS
}
