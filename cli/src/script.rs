//! `petrel run`: a mission script in virtual time, with no process.

use crate::common::{compiled, out, Outcome};
use petrel_diag::plural::count;
use std::path::PathBuf;

/// `petrel run`.
#[derive(clap::Args)]
pub struct RunArgs {
    /// The project directory.
    dir: PathBuf,
    /// The script: lines `TIME EVENT(args)`, `TIME wait`, `expect ...` (docs/scripts.md).
    #[arg(long)]
    script: PathBuf,
    /// Print nothing but the result of the expectations.
    #[arg(short, long)]
    quiet: bool,
}

/// Runs a script; a failed expectation exits 1, a script that does not read exits 2.
pub fn run(a: RunArgs) -> Outcome {
    let (script_path, quiet) = (&a.script, a.quiet);
    let c = match compiled(&a.dir, "run") {
        Ok(c) => c,
        Err(o) => return o,
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
                .map(|e| format!("{}:{e}", script_path.display()))
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
    // A cascade stopped at the bound is the player's safety net, not a mission's behaviour:
    // said on stderr whatever the expectations say.
    for step in outcome
        .steps
        .iter()
        .filter(|s| !s["cascade_stopped"].is_null())
    {
        eprintln!(
            "{}: warning: at {} s, events produced at one instant did not settle: the cascade was stopped after {} steps, {} produced event(s) dropped, livelock raised (`petrel verify` locates the loop: E0608)",
            script_path.display(),
            step["time"],
            step["cascade_stopped"]["steps"],
            step["cascade_stopped"]["dropped"]
        );
    }
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
                "{}: {}, {} met",
                script_path.display(),
                count(outcome.steps.len(), "step"),
                count(expectations, "expectation")
            );
            Outcome::Clean
        }
    }
}
