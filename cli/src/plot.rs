//! `petrel plot`: the pictures of a Redermor run (Figure 9 of the paper): the map (survey
//! areas blue, forbidden areas red, planned routes yellow, the vehicle's track green, events
//! where they happened) and the depth against time, from a run directory of `petrel up`: the
//! simulator's true track (`trace.csv`, `redermor-bridge --trace`) and the player's journal
//! (the routes PLN gave, the events).

use std::path::{Path, PathBuf};

use crate::common::Outcome;
use petrel_redermor::geom::{self, Position};
use petrel_redermor::mission::Mission;
use petrel_redermor::plot::{self, Trace, TraceEvent, TracePoint};

/// `petrel plot`.
#[derive(clap::Args)]
pub struct PlotArgs {
    /// The run directory (`petrel up --logs`): its trace.csv and journal/.
    logs: PathBuf,
    /// The mission file the run flew (its areas, forbidden zones and end area).
    #[arg(long, value_name = "FILE")]
    mission: PathBuf,
    /// How many times faster than the wall clock the simulator ran (redermor-bridge's
    /// --speed), to place the journal's events on the track.
    #[arg(long, default_value_t = 20.0, value_parser = crate::common::finite)]
    speed: f64,
    /// Where to write map.svg and depth.svg; default: the run directory.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
}

/// The events drawn on the map.
const SHOWN: [&str; 12] = [
    "next_area",
    "areas_done",
    "current_differs",
    "alarm",
    "inspect_request",
    "inspection_flown",
    "battery_low",
    "depth_sensor_lost",
    "leak",
    "bus_lost",
    "planning_failed",
    "surfaced",
];

/// Reads `trace.csv`: one line a second of the vehicle's time; an error names the line.
fn read_trace(path: &Path) -> Result<Vec<TracePoint>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut points = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let v: Result<Vec<f64>, _> = line.split(',').map(str::parse::<f64>).collect();
        match v {
            Ok(v) if v.len() >= 4 => points.push(TracePoint {
                time: v[0],
                position: geom::pos(v[1], v[2]),
                depth: v[3],
                surveying: None,
            }),
            _ => {
                return Err(format!(
                    "{}:{}: not a trace line: {line}",
                    path.display(),
                    i + 1
                ))
            }
        }
    }
    Ok(points)
}

fn floats(v: Option<&petrel_nets::compiled::Value>) -> Vec<Position> {
    match v {
        Some(petrel_nets::compiled::Value::FloatList(f)) => {
            f.chunks_exact(2).map(|c| geom::pos(c[0], c[1])).collect()
        }
        _ => Vec::new(),
    }
}

/// Draws the run's map and depth plot.
pub fn plot(a: PlotArgs) -> Outcome {
    match run(&a) {
        Ok((map, depth)) => {
            println!("map: {}\ndepth: {}", map.display(), depth.display());
            Outcome::Clean
        }
        Err(e) => Outcome::Usage(e),
    }
}

fn run(a: &PlotArgs) -> Result<(PathBuf, PathBuf), String> {
    use petrel_player::journal::Entry;
    if a.speed <= 0.0 {
        return Err(format!("--speed {}: a factor above 0", a.speed));
    }
    let text =
        std::fs::read_to_string(&a.mission).map_err(|e| format!("{}: {e}", a.mission.display()))?;
    let mission = Mission::from_toml(&text).map_err(|e| format!("{}: {e}", a.mission.display()))?;
    let points = read_trace(&a.logs.join("trace.csv"))?;
    let journal = a.logs.join("journal");
    let read = petrel_player::journal::read_journal(&journal)
        .map_err(|e| format!("{}: {e}", journal.display()))?;
    let mut trace = Trace {
        points,
        ..Trace::default()
    };
    // The vehicle's time starts when the thrusters are first enabled, at the mission's start.
    let mut start_us = None;
    for e in &read.entries {
        let Entry::Step {
            time,
            event,
            params,
            outcome,
            ..
        } = e
        else {
            continue;
        };
        if event == "start_mission" && start_us.is_none() {
            start_us = Some(*time);
        }
        match event.as_str() {
            "trajectory" | "inspection_planned" => trace.planned.push(floats(params.first())),
            "sequence" => trace.planned.push(floats(params.get(1))),
            _ => {}
        }
        if outcome == "processed" && SHOWN.contains(&event.as_str()) {
            let since = time.saturating_sub(start_us.unwrap_or(0)) as f64 / 1e6;
            let t = since * a.speed;
            let at = trace
                .points
                .iter()
                .min_by(|p, q| (p.time - t).abs().total_cmp(&(q.time - t).abs()))
                .map_or(mission.start, |p| p.position);
            let args: Vec<String> = params.iter().map(|v| v.literal()).collect();
            let label = if args.is_empty() {
                event.clone()
            } else {
                format!("{event}({})", args.join(", "))
            };
            trace.events.push(TraceEvent {
                time: t,
                position: at,
                label,
            });
        }
    }
    let out = a.out.clone().unwrap_or_else(|| a.logs.clone());
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let map = out.join("map.svg");
    let depth = out.join("depth.svg");
    plot::write_map(&map, &mission, &trace).map_err(|e| format!("{}: {e}", map.display()))?;
    plot::write_depth(&depth, &trace).map_err(|e| format!("{}: {e}", depth.display()))?;
    Ok((map, depth))
}
