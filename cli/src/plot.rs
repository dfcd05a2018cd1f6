//! `petrel plot`: the map of a recorded run, as SVG, by the code that draws the monitor's
//! map ([`crate::map`]): the project's map.toml (areas, lines, points; where positions come
//! from), the journal's steps (positions and routes in events, events marked where they
//! happened) and, for positions from signals, the data server's recording of the bus. With a
//! track that has a third value (a depth), its profile against time too.

use std::path::{Path, PathBuf};

use crate::common::{require_clean, Outcome, Scope};
use crate::map::{self, record, Map};

/// `petrel plot`.
#[derive(clap::Args)]
pub struct PlotArgs {
    /// The run: a `petrel up` run directory (its journal/ and bus.log), or a journal directory.
    run: PathBuf,
    /// The project (default: the directory the journal recorded).
    #[arg(long, value_name = "DIR")]
    project: Option<PathBuf>,
    /// The map file (default: the project's map.toml).
    #[arg(long, value_name = "FILE")]
    map: Option<PathBuf>,
    /// The data server's recording of the bus (`petrel bridge --record`), for positions from
    /// signals (default: bus.log of the run directory, when there is one).
    #[arg(long, value_name = "FILE")]
    bus_log: Option<PathBuf>,
    /// Where to write map.svg (and profile.svg); default: the run directory.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// The drawing's size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1200x900", value_parser = size)]
    size: (u32, u32),
}

/// Reads `WIDTHxHEIGHT`.
fn size(text: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{text}`: give WIDTHxHEIGHT in pixels, from 320x240 to 8000x8000");
    let (w, h) = text.split_once('x').ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
    if !(320..=8000).contains(&w) || !(240..=8000).contains(&h) {
        return Err(bad());
    }
    Ok((w, h))
}

/// Draws the run's map (and profile).
pub fn plot(a: PlotArgs) -> Outcome {
    match run(&a) {
        Ok(written) => {
            for (what, path) in written {
                crate::common::out(&format!("{what}: {}\n", path.display()));
            }
            Outcome::Clean
        }
        Err(o) => o,
    }
}

/// The journal directory of `run`: its `journal/`, or `run` itself.
fn journal_dir(run: &Path) -> PathBuf {
    let inner = run.join("journal");
    if inner.is_dir() {
        inner
    } else {
        run.to_path_buf()
    }
}

fn run(a: &PlotArgs) -> Result<Vec<(&'static str, PathBuf)>, Outcome> {
    let journal = journal_dir(&a.run);
    let read = petrel_player::journal::read_journal(&journal)
        .map_err(|e| Outcome::Usage(format!("{}: {e}", journal.display())))?;
    let (project_dir, digest) = crate::monitor::replay::header(&read.entries, &journal)?;
    let dir = a.project.clone().unwrap_or(project_dir);
    let scope = Scope {
        can: true,
        map: a.map.is_none(),
        ..Scope::default()
    };
    let mut checked = require_clean(&dir, scope, "plot")?;
    let Some(project) = checked.compiled.take() else {
        return Err(Outcome::Usage("the project did not compile".into()));
    };
    if petrel_player::journal::project_digest(&project) != digest {
        return Err(Outcome::Usage(format!(
            "{} is not the project the journal recorded (its nets or manifest changed): give the right one with --project",
            dir.display()
        )));
    }
    let map = match &a.map {
        Some(path) => load_given(path, &project, &mut checked)?,
        None => checked.map.take().ok_or_else(|| {
            Outcome::Usage(format!(
                "{} has no {}: a map says what to draw and where the positions come from (docs/monitor.md, \"The map\"), or give one with --map FILE",
                dir.display(),
                map::file::MAP_TOML
            ))
        })?,
    };
    let records = bus_records(a, &map)?;
    let bus = match (&records, &checked.can) {
        (Some(r), Some((_, dbc))) => Some(record::BusLog { dbc, records: r }),
        _ => None,
    };
    let state = record::replay(&map, &read.entries, bus);
    for (i, t) in map.tracks.iter().enumerate() {
        if state.tracks[i].is_empty() {
            eprintln!("warning: track `{}` has no position in this run", t.name);
        }
    }
    let out = a.out.clone().unwrap_or_else(|| a.run.clone());
    std::fs::create_dir_all(&out)
        .map_err(|e| Outcome::Usage(format!("cannot create {}: {e}", out.display())))?;
    let (w, h) = a.size;
    let mut written = Vec::new();
    let path = out.join("map.svg");
    crate::common::write_output(Some(&path), &map::svg::map_svg(&map, &state, w, h, None))?;
    written.push(("map", path));
    if let Some(profile) = map::svg::profile_svg(&map, &state, w, h / 2) {
        let path = out.join("profile.svg");
        crate::common::write_output(Some(&path), &profile)?;
        written.push(("profile", path));
    }
    Ok(written)
}

/// The map of `--map FILE`, checked like the project's.
fn load_given(
    path: &Path,
    project: &petrel_nets::compiled::CompiledProject,
    checked: &mut crate::common::Checked,
) -> Result<Map, Outcome> {
    let signals: Option<std::collections::BTreeSet<String>> = checked
        .can
        .as_ref()
        .map(|(_, dbc)| dbc.signal_paths().collect());
    let mut d = petrel_diag::report::Diagnostics::new();
    let loaded = map::file::load(
        path,
        project,
        signals.as_ref(),
        &mut checked.loaded.sources,
        &mut d,
    )
    .map_err(|e| Outcome::Usage(format!("cannot read {}: {e}", path.display())))?;
    crate::common::report(&d, &checked.loaded.sources);
    loaded.ok_or(Outcome::Errors)
}

/// The bus's recording, when the map reads signals: `--bus-log`, or the run's bus.log.
fn bus_records(
    a: &PlotArgs,
    map: &Map,
) -> Result<Option<Vec<petrel_can_bridge::log::LogRecord>>, Outcome> {
    if map.signals().is_empty() {
        return Ok(None);
    }
    let path = match &a.bus_log {
        Some(p) => p.clone(),
        None => {
            let p = a.run.join("bus.log");
            if !p.is_file() {
                eprintln!(
                    "warning: the map's positions from signals come from the bus's recording, and {} has none (give --bus-log FILE)",
                    a.run.display()
                );
                return Ok(None);
            }
            p
        }
    };
    read_bus_log(&path).map(Some).map_err(Outcome::Usage)
}

/// Reads a `candump -L` recording; an error names the file and the line.
pub fn read_bus_log(path: &Path) -> Result<Vec<petrel_can_bridge::log::LogRecord>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    petrel_can_bridge::log::read_log(&text).map_err(|e| format!("{}: {e}", path.display()))
}
