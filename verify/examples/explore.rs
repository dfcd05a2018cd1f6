//! Explores a P/T net read from PNML and prints the report as JSON (or for humans with
//! `--human`): the stand-in for `petrel verify FILE.pnml --format json` used by
//! `scripts/bench-verify.sh` until the CLI calls [`petrel_verify::reach`] itself.
//!
//! Usage: `explore FILE.pnml [--human] [--no-traces] [--deadlocks] [--max-states N] [--progress]`.
//! Exit codes: 0 explored, 1 exploration stopped (state limit, unbounded net...), 2 bad usage or
//! unreadable PNML.

use petrel_diag::report::Diagnostics;
use petrel_diag::source::FileId;
use petrel_nets::pnml::parse_pnml;
use petrel_verify::reach::{
    error_to_json, explore, render_error, render_human, to_json, ExploreOptions,
};
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut path = None;
    let mut human = false;
    let mut opts = ExploreOptions::default();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--human" => human = true,
            "--no-traces" => opts.keep_traces = false,
            "--deadlocks" => opts.deadlocks_only = true,
            "--progress" => {
                opts.progress = Some(Box::new(|p| {
                    eprintln!(
                        "{:>8.1} s  {} states  {} expanded  {} edges  {:.0} states/s",
                        p.seconds, p.states, p.expanded, p.edges, p.states_per_second
                    )
                }))
            }
            "--max-states" => match args.next().and_then(|n| n.parse().ok()) {
                Some(n) => opts.max_states = Some(n),
                None => return usage("--max-states needs a number"),
            },
            _ if path.is_none() && !a.starts_with('-') => path = Some(a),
            _ => return usage(&format!("unexpected argument `{a}`")),
        }
    }
    let Some(path) = path else {
        return usage("no PNML file given");
    };
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: cannot read {path}: {e}");
            return ExitCode::from(2);
        }
    };
    let mut diags = Diagnostics::new();
    let nets = parse_pnml(FileId(0), &text, &mut diags);
    let Some(net) = nets.first().filter(|_| !diags.has_errors()) else {
        for d in diags.iter() {
            eprintln!("error[{}]: {}", d.code, d.message);
        }
        eprintln!("error: {path} holds no readable P/T net");
        return ExitCode::from(2);
    };
    match explore(net, opts) {
        Ok(r) if human => {
            print!("{}", render_human(net, &r));
            ExitCode::SUCCESS
        }
        Ok(r) => {
            println!("{}", to_json(net, &r));
            ExitCode::SUCCESS
        }
        Err(e) => {
            if human {
                eprint!("error: {}", render_error(net, &e));
            } else {
                println!("{}", error_to_json(net, &e));
            }
            ExitCode::from(1)
        }
    }
}

fn usage(msg: &str) -> ExitCode {
    eprintln!("error: {msg}\nusage: explore FILE.pnml [--human] [--no-traces] [--deadlocks] [--max-states N] [--progress]");
    ExitCode::from(2)
}
