//! Flies a mission in pure simulation and writes its map and depth plot.
//!
//! ```text
//! cargo run -p redermor --example redermor_run -- MISSION.toml OUT_DIR [SCENARIO.toml]
//! ```

use std::path::PathBuf;
use std::process::ExitCode;

use redermor::mission::Mission;
use redermor::plot;
use redermor::sensors::Scenario;
use redermor::sim::{MissionRun, RunConfig};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(mission_path), Some(out)) = (args.first(), args.get(1)) else {
        eprintln!("usage: redermor_run MISSION.toml OUT_DIR [SCENARIO.toml]");
        return ExitCode::from(2);
    };
    match run(mission_path, &PathBuf::from(out), args.get(2)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("redermor_run: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(
    mission_path: &str,
    out: &std::path::Path,
    scenario_path: Option<&String>,
) -> Result<(), Box<dyn std::error::Error>> {
    let mission = Mission::from_toml(&std::fs::read_to_string(mission_path)?)?;
    let scenario = match scenario_path {
        Some(p) => Scenario::from_toml(&std::fs::read_to_string(p)?)?,
        None => Scenario::default(),
    };
    let report = MissionRun::new(&mission, &scenario, RunConfig::default())?.run();
    println!(
        "{}: {:?} after {} steps ({:.0} s), surveyed {:?}",
        mission.name,
        report.outcome,
        report.steps,
        report.steps as f64 / 10.0,
        report.surveyed
    );
    for e in &report.trace.events {
        println!(
            "  {:8.1} s  ({:7.1}, {:7.1})  {}",
            e.time, e.position.x, e.position.y, e.label
        );
    }
    std::fs::create_dir_all(out)?;
    plot::write_map(
        &out.join(format!("{}_map.svg", mission.name)),
        &mission,
        &report.trace,
    )?;
    plot::write_depth(
        &out.join(format!("{}_depth.svg", mission.name)),
        &report.trace,
    )?;
    Ok(())
}
