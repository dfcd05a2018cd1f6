//! `map.toml`: what a vehicle's map shows, read and checked against the project.
//!
//! The format is documented in docs/monitor.md ("The map"); every error is a diagnostic
//! (E0901 to E0904, docs/diagnostics.md) pointing into the file.

use super::{AreaKind, Coords, Map, Pos, RouteShape, RouteSource, Shape, TrackSource};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, SourceMap, Span};
use petrel_nets::compiled::CompiledProject;
use petrel_nets::model::Type;
use serde::Deserialize;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use toml::Spanned;

/// The file a project's map is in, beside its petrel.toml.
pub const MAP_TOML: &str = "map.toml";

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    #[serde(default)]
    map: RawMap,
    #[serde(default)]
    area: Vec<RawArea>,
    #[serde(default)]
    line: Vec<RawLine>,
    #[serde(default)]
    point: Vec<RawPoint>,
    #[serde(default)]
    track: Vec<RawTrack>,
    #[serde(default)]
    route: Vec<RawRoute>,
    #[serde(default)]
    mark: Vec<RawMark>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawMap {
    title: Option<String>,
    coordinates: Option<Spanned<String>>,
    unit: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawArea {
    name: String,
    kind: Option<Spanned<String>>,
    polygon: Spanned<Vec<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLine {
    name: String,
    points: Spanned<Vec<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPoint {
    name: String,
    at: Spanned<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTrack {
    name: Option<String>,
    signals: Option<Spanned<RawSignals>>,
    event: Option<Spanned<String>>,
    at: Option<Spanned<String>>,
    x: Option<Spanned<String>>,
    y: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSignals {
    x: Spanned<String>,
    y: Spanned<String>,
    z: Option<Spanned<String>>,
    z_label: Option<String>,
    #[serde(default)]
    z_down: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRoute {
    name: Option<String>,
    event: Spanned<String>,
    path: Option<Spanned<String>>,
    at: Option<Spanned<String>>,
    stride: Option<Spanned<i64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMark {
    events: Vec<Spanned<String>>,
    at: Option<Spanned<String>>,
}

/// Reads and checks the map file at `path` against `project` (its events) and, when the
/// project has a CAN data server, `signals` (the DBC's `Message.signal` names). The file joins
/// `sources`, so that findings point into it; `None` when it has an error (in `diags`).
pub fn load(
    path: &Path,
    project: &CompiledProject,
    signals: Option<&BTreeSet<String>>,
    sources: &mut SourceMap,
    diags: &mut Diagnostics,
) -> std::io::Result<Option<Map>> {
    let text = std::fs::read_to_string(path)?;
    let file = sources.add(path.display().to_string(), text.clone());
    Ok(check(file, &text, project, signals, diags))
}

/// Checks the text of a map file; `None` when it has an error (in `diags`).
pub fn check(
    file: FileId,
    text: &str,
    project: &CompiledProject,
    signals: Option<&BTreeSet<String>>,
    diags: &mut Diagnostics,
) -> Option<Map> {
    let raw: Raw = petrel_diag::toml::parse(
        file,
        text,
        "E0901",
        "map.toml",
        "map.toml has a [map] table (title, coordinates, unit) and [[area]], [[line]], [[point]], [[track]], [[route]] and [[mark]] entries; see docs/monitor.md, \"The map\"",
        diags,
    )?;
    let mut c = Checker {
        file,
        diags,
        errors: 0,
        project,
        signals,
    };
    let coords = c.coords(&raw.map);
    let mut map = Map {
        title: raw
            .map
            .title
            .clone()
            .unwrap_or_else(|| project.name.clone()),
        coords,
        shapes: Vec::new(),
        tracks: Vec::new(),
        routes: Vec::new(),
        marks: BTreeMap::new(),
    };
    for a in &raw.area {
        let kind = c.kind(a.kind.as_ref());
        let ring = c.points(&a.polygon, coords, 3, "an area's polygon");
        map.shapes.push(Shape::Area {
            name: a.name.clone(),
            kind,
            ring,
        });
    }
    for l in &raw.line {
        let points = c.points(&l.points, coords, 2, "a line");
        map.shapes.push(Shape::Line {
            name: l.name.clone(),
            points,
        });
    }
    for p in &raw.point {
        let at = c.point(&p.at, coords);
        map.shapes.push(Shape::Point {
            name: p.name.clone(),
            at,
        });
    }
    for (i, t) in raw.track.iter().enumerate() {
        if let Some(t) = c.track(t, i) {
            map.tracks.push(t);
        }
    }
    for r in &raw.route {
        if let Some(r) = c.route(r) {
            map.routes.push(r);
        }
    }
    for m in &raw.mark {
        c.mark(m, &mut map.marks);
    }
    if raw.mark.is_empty() {
        // By default, the events that are news: every category but the nominal one.
        map.marks = project
            .events
            .iter()
            .filter(|e| e.category != petrel_nets::model::Category::Nominal && !e.internal)
            .map(|e| (e.name.clone(), None))
            .collect();
    }
    (c.errors == 0).then_some(map)
}

struct Checker<'a> {
    file: FileId,
    diags: &'a mut Diagnostics,
    errors: usize,
    project: &'a CompiledProject,
    signals: Option<&'a BTreeSet<String>>,
}

impl Checker<'_> {
    fn span<T>(&self, s: &Spanned<T>) -> Span {
        Span::new(self.file, s.span().start, s.span().end)
    }

    fn error(&mut self, code: &'static str, span: Span, message: String, label: &str, help: &str) {
        self.errors += 1;
        self.diags.push(
            Diagnostic::error(code, span, message)
                .label(label)
                .help(help),
        );
    }

    fn coords(&mut self, m: &RawMap) -> Coords {
        let lat_lon = match m.coordinates.as_ref() {
            None => false,
            Some(s) => match s.get_ref().as_str() {
                "xy" => false,
                "lat_lon" => true,
                other => {
                    self.error(
                        "E0902",
                        self.span(s),
                        format!("[map] coordinates = \"{other}\": not a kind of coordinates"),
                        "unknown coordinates",
                        "\"xy\" (x east, y north) or \"lat_lon\" ([latitude, longitude] in degrees)",
                    );
                    false
                }
            },
        };
        let unit = match m.unit.as_ref() {
            None => 1.0,
            Some(s) => match (s.get_ref().as_str(), lat_lon) {
                ("m", false) => 1.0,
                ("km", false) => 1000.0,
                ("deg", true) => 1.0,
                (other, _) => {
                    let help = if lat_lon {
                        "lat_lon coordinates are in degrees: leave `unit` out"
                    } else {
                        "\"m\" (the default) or \"km\""
                    };
                    self.error(
                        "E0902",
                        self.span(s),
                        format!("[map] unit = \"{other}\": not a unit of these coordinates"),
                        "unknown unit",
                        help,
                    );
                    1.0
                }
            },
        };
        if lat_lon {
            Coords::LatLon
        } else {
            Coords::Xy { metres: unit }
        }
    }

    fn kind(&mut self, k: Option<&Spanned<String>>) -> AreaKind {
        let Some(k) = k else {
            return AreaKind::Zone;
        };
        match AreaKind::parse(k.get_ref()) {
            Some(kind) => kind,
            None => {
                self.error(
                    "E0902",
                    self.span(k),
                    format!("area kind `{}`: not a kind of area", k.get_ref()),
                    "unknown kind",
                    "survey, forbidden, end or zone (the default)",
                );
                AreaKind::Zone
            }
        }
    }

    /// One point as the file writes it, `[x, y]` or `[latitude, longitude]`, as (east, north).
    fn pair(&self, v: &[f64], coords: Coords) -> Result<(f64, f64), String> {
        if v.len() != 2 {
            return Err(format!("{} numbers where a point has 2", v.len()));
        }
        if !v.iter().all(|x| x.is_finite()) {
            return Err("a number that is not finite".into());
        }
        match coords {
            Coords::Xy { .. } => Ok((v[0], v[1])),
            Coords::LatLon => {
                if v[0].abs() > 90.0 || v[1].abs() > 180.0 {
                    Err(format!(
                        "[{}, {}] is not [latitude, longitude] in degrees",
                        v[0], v[1]
                    ))
                } else {
                    Ok((v[1], v[0]))
                }
            }
        }
    }

    fn point(&mut self, p: &Spanned<Vec<f64>>, coords: Coords) -> (f64, f64) {
        match self.pair(p.get_ref(), coords) {
            Ok(p) => p,
            Err(e) => {
                self.error(
                    "E0902",
                    self.span(p),
                    format!("not a point: {e}"),
                    "not a point",
                    point_help(coords),
                );
                (0.0, 0.0)
            }
        }
    }

    fn points(
        &mut self,
        list: &Spanned<Vec<Vec<f64>>>,
        coords: Coords,
        least: usize,
        what: &str,
    ) -> Vec<(f64, f64)> {
        let mut out = Vec::new();
        for (i, v) in list.get_ref().iter().enumerate() {
            match self.pair(v, coords) {
                Ok(p) => out.push(p),
                Err(e) => {
                    self.error(
                        "E0902",
                        self.span(list),
                        format!("point {} of {what}: {e}", i + 1),
                        "not a list of points",
                        point_help(coords),
                    );
                    return out;
                }
            }
        }
        if out.len() < least {
            self.error(
                "E0902",
                self.span(list),
                format!(
                    "{what} of {} point(s): it needs {least} at least",
                    out.len()
                ),
                "too few points",
                point_help(coords),
            );
        }
        out
    }

    /// The event `name` of the project, or an error.
    fn event(&mut self, name: &Spanned<String>) -> Option<usize> {
        let found = self
            .project
            .events
            .iter()
            .position(|e| &e.name == name.get_ref());
        if found.is_none() {
            let hint = suggest(
                name.get_ref(),
                self.project.events.iter().map(|e| e.name.as_str()),
            );
            self.error(
                "E0903",
                self.span(name),
                format!("`{}` is not an event of the project", name.get_ref()),
                "unknown event",
                &format!("{hint}the map reads the events petrel.toml declares"),
            );
        }
        found
    }

    /// The position of parameter `param` of event `event`, of type `want`, or an error.
    fn param(&mut self, event: usize, param: &Spanned<String>, want: Type) -> Option<usize> {
        let e = &self.project.events[event];
        let found = e.params.iter().position(|(n, _)| n == param.get_ref());
        match found {
            Some(i) if e.params[i].1 == want => Some(i),
            Some(i) => {
                let msg = format!(
                    "parameter `{}` of event `{}` is {}, not {want}",
                    param.get_ref(),
                    e.name,
                    e.params[i].1
                );
                self.error(
                    "E0903",
                    self.span(param),
                    msg,
                    "wrong type",
                    "a position is a [float] parameter ([x, y, ...]), or two float parameters (x and y)",
                );
                None
            }
            None => {
                let names: Vec<String> =
                    e.params.iter().map(|(n, t)| format!("{n}: {t}")).collect();
                let msg = format!(
                    "event `{}` has no parameter `{}` (it has: {})",
                    e.name,
                    param.get_ref(),
                    if names.is_empty() {
                        "none".to_string()
                    } else {
                        names.join(", ")
                    }
                );
                self.error(
                    "E0903",
                    self.span(param),
                    msg,
                    "unknown parameter",
                    "name one of the event's parameters, as petrel.toml declares them",
                );
                None
            }
        }
    }

    fn signal(&mut self, s: &Spanned<String>) -> String {
        match self.signals {
            Some(known) if !known.contains(s.get_ref()) => {
                let hint = suggest(s.get_ref(), known.iter().map(String::as_str));
                self.error(
                    "E0904",
                    self.span(s),
                    format!("`{}` is not a signal of the project's DBC", s.get_ref()),
                    "unknown signal",
                    &format!("{hint}a signal is named `Message.signal`, as the CAN data server publishes it"),
                );
            }
            None => {
                self.error(
                    "E0904",
                    self.span(s),
                    format!(
                        "signal `{}`: the project has no CAN data server (no can.toml) to publish it",
                        s.get_ref()
                    ),
                    "no signals here",
                    "take the position from an event instead (`event` and `at`)",
                );
            }
            _ => {}
        }
        s.get_ref().clone()
    }

    fn track(&mut self, t: &RawTrack, i: usize) -> Option<TrackSource> {
        let name = t.name.clone().unwrap_or_else(|| {
            if i == 0 {
                "track".into()
            } else {
                format!("track {}", i + 1)
            }
        });
        match (&t.signals, &t.event) {
            (Some(s), None) => {
                if let Some(span) = t.at.as_ref().or(t.x.as_ref()).or(t.y.as_ref()) {
                    let span = self.span(span);
                    self.error(
                        "E0904",
                        span,
                        "a track from signals names its signals in `signals` only".into(),
                        "not for signals",
                        "`at`, `x` and `y` go with `event`",
                    );
                }
                let sig = s.get_ref();
                let (x, y) = (self.signal(&sig.x), self.signal(&sig.y));
                let z = sig.z.as_ref().map(|z| self.signal(z));
                Some(TrackSource {
                    name,
                    from: super::TrackFrom::Signals {
                        x,
                        y,
                        z,
                        z_label: sig.z_label.clone(),
                        z_down: sig.z_down,
                    },
                })
            }
            (None, Some(e)) => {
                let event = self.event(e)?;
                let pos = match (&t.at, &t.x, &t.y) {
                    (Some(at), None, None) => Pos::List(self.param(event, at, Type::FloatList)?),
                    (None, Some(x), Some(y)) => {
                        let px = self.param(event, x, Type::Float);
                        let py = self.param(event, y, Type::Float);
                        Pos::Pair(px?, py?)
                    }
                    _ => {
                        self.error(
                            "E0904",
                            self.span(e),
                            "a track from an event names where the position is: `at` (a [float] parameter) or `x` and `y` (two float parameters)".into(),
                            "no position",
                            "at = \"position\", or x = \"x\" and y = \"y\"",
                        );
                        return None;
                    }
                };
                Some(TrackSource {
                    name,
                    from: super::TrackFrom::Event {
                        event: e.get_ref().clone(),
                        pos,
                    },
                })
            }
            (Some(_), Some(_)) | (None, None) => {
                let span = match &t.signals {
                    Some(s) => self.span(s),
                    None => Span::new(self.file, 0, 0),
                };
                self.error(
                    "E0904",
                    span,
                    format!("track `{name}`: give `signals` or `event`, one of the two"),
                    "where does the position come from?",
                    "signals = { x = \"Msg.x\", y = \"Msg.y\" } (the CAN data server's), or event = \"NAME\" with at = \"PARAM\"",
                );
                None
            }
        }
    }

    fn route(&mut self, r: &RawRoute) -> Option<RouteSource> {
        let event = self.event(&r.event)?;
        let stride = match &r.stride {
            None => 2,
            Some(s) if (2..=16).contains(s.get_ref()) => *s.get_ref() as usize,
            Some(s) => {
                self.error(
                    "E0902",
                    self.span(s),
                    format!("stride {}: from 2 to 16 numbers a point", s.get_ref()),
                    "not a stride",
                    "the numbers of one point in the list: 2 for [x0, y0, x1, y1, ...], 3 with an altitude",
                );
                return None;
            }
        };
        let shape = match (&r.path, &r.at) {
            (Some(p), None) => RouteShape::Path {
                param: self.param(event, p, Type::FloatList)?,
                stride,
            },
            (None, Some(a)) => RouteShape::Waypoint {
                param: self.param(event, a, Type::FloatList)?,
            },
            _ => {
                self.error(
                    "E0904",
                    self.span(&r.event),
                    "a route names its parameter: `path` (the whole route, [x0, y0, x1, y1, ...]) or `at` (one more waypoint [x, y, ...] per event)".into(),
                    "which parameter?",
                    "path = \"waypoints\", or at = \"position\"",
                );
                return None;
            }
        };
        Some(RouteSource {
            name: r
                .name
                .clone()
                .unwrap_or_else(|| format!("planned ({})", r.event.get_ref())),
            event: r.event.get_ref().clone(),
            shape,
        })
    }

    /// The events of one `[[mark]]`, each with where it is drawn: at its own position
    /// parameter (`at`), or where the vehicle was (`None`).
    fn mark(&mut self, m: &RawMark, marks: &mut BTreeMap<String, Option<usize>>) {
        for e in &m.events {
            let Some(i) = self.event(e) else { continue };
            let at = match &m.at {
                Some(a) => match self.param(i, a, Type::FloatList) {
                    Some(p) => Some(p),
                    None => continue,
                },
                None => None,
            };
            marks.insert(e.get_ref().clone(), at);
        }
    }
}

fn point_help(coords: Coords) -> &'static str {
    match coords {
        Coords::Xy { .. } => "a point is [x, y] (x east, y north), two finite numbers",
        Coords::LatLon => "a point is [latitude, longitude] in degrees",
    }
}

fn suggest<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> String {
    let best = candidates
        .map(|c| (petrel_diag::names::distance(name, c), c))
        .min();
    match best {
        Some((d, c)) if d <= 2.max(name.len() / 3) => format!("did you mean `{c}`? "),
        _ => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn redermor() -> CompiledProject {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/redermor");
        let (_, c, d) = petrel_nets::project::load_and_check(&dir).expect("Redermor");
        assert!(!d.has_errors());
        c.expect("it compiles")
    }

    fn signals() -> BTreeSet<String> {
        ["BenchTruth.x", "BenchTruth.y", "Gps.x"]
            .iter()
            .map(|s| s.to_string())
            .collect()
    }

    /// The codes of the findings, and the text a person reads.
    fn check_text(text: &str) -> (Option<Map>, Vec<&'static str>, String) {
        let p = redermor();
        let mut sources = SourceMap::default();
        let file = sources.add("map.toml", text);
        let mut d = Diagnostics::new();
        let m = check(file, text, &p, Some(&signals()), &mut d);
        let codes = d.iter().map(|x| x.code).collect();
        (m, codes, d.render_human(&sources))
    }

    #[test]
    fn redermors_map_reads_clean() {
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/redermor/map.toml"),
        )
        .unwrap();
        let p = redermor();
        let mut sources = SourceMap::default();
        let file = sources.add("map.toml", text.clone());
        let mut d = Diagnostics::new();
        let dbc = petrel_can_bridge::Dbc::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../missions/redermor/redermor.dbc"),
        )
        .unwrap();
        let known: BTreeSet<String> = dbc.signal_paths().collect();
        let m = check(file, &text, &p, Some(&known), &mut d)
            .unwrap_or_else(|| panic!("{}", d.render_human(&sources)));
        assert_eq!(m.shapes.len(), 5);
        assert_eq!(m.tracks.len(), 2);
        assert_eq!(
            m.signals(),
            ["BenchTruth.x", "BenchTruth.y", "BenchTruth.depth"]
        );
        assert_eq!(m.marks.get("inspect_request"), Some(&Some(0)));
        assert_eq!(m.marks.get("alarm"), Some(&None));
    }

    #[test]
    fn bad_maps_are_located_errors() {
        let cases: [(&str, &str, &str); 9] = [
            ("[map]\ntitel = \"x\"\n", "E0901", "map.toml:2:1"),
            ("[[area]]\nname = \"a\"\nkind = \"lake\"\npolygon = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]\n", "E0902", "not a kind of area"),
            ("[[area]]\nname = \"a\"\npolygon = [[0.0, 0.0], [1.0, 0.0]]\n", "E0902", "it needs 3 at least"),
            ("[[point]]\nname = \"p\"\nat = [1.0]\n", "E0902", "1 numbers where a point has 2"),
            ("[map]\ncoordinates = \"lat_lon\"\n[[point]]\nname = \"p\"\nat = [95.0, 2.0]\n", "E0902", "not [latitude, longitude]"),
            ("[[track]]\nevent = \"vehicle_stat\"\nat = \"position\"\n", "E0903", "did you mean `vehicle_state`?"),
            ("[[track]]\nevent = \"vehicle_state\"\nat = \"depth\"\n", "E0903", "is float, not [float]"),
            ("[[track]]\nsignals = { x = \"BenchTruth.x\", y = \"Nav.y\" }\n", "E0904", "`Nav.y` is not a signal"),
            ("[[route]]\nevent = \"trajectory\"\n", "E0904", "a route names its parameter"),
        ];
        for (text, code, says) in cases {
            let (m, codes, human) = check_text(text);
            assert!(m.is_none(), "{text}");
            assert_eq!(codes, [code], "{text}: {human}");
            assert!(human.contains(says), "{text}: {human}");
        }
        // No [[mark]]: the events that are news (not nominal) are marked, where the vehicle was.
        let (m, codes, _) = check_text("[map]\ntitle = \"t\"\n");
        assert!(codes.is_empty());
        let m = m.unwrap();
        assert!(m.marks.contains_key("leak") && !m.marks.contains_key("route_done"));
    }
}
