//! The vehicle's map, for `petrel monitor` (live and in replay) and `petrel plot`: one
//! format, one core, one drawing.
//!
//! - [`file`]: `map.toml` (docs/monitor.md, "The map"): the areas, lines and points to draw,
//!   and where the vehicle's positions come from: the CAN data server's signals or the
//!   parameters of the project's events. Petrel knows no vehicle: a project says it all there.
//! - [`feed`]: the sans-I/O core: signals and steps in, tracks, planned routes and marked
//!   events out (bounded: thinned by distance, halved when too long).
//! - [`record`]: a recorded run fed to that core in time order: the journal's steps and, for
//!   positions from signals, the data server's recording of the bus (`petrel bridge --record`).
//! - [`svg`]: the SVG drawing (legend, scale, axes, nothing cut off) that `petrel plot` writes
//!   and the monitor serves (`/api/map.svg`): the same Rust code for both.

pub mod feed;
pub mod file;
pub mod record;
pub mod svg;

use std::collections::BTreeMap;

/// How the file writes positions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Coords {
    /// `[x, y]`, x east and y north, in a unit of `metres` metres.
    Xy {
        /// Metres in one unit of the file (1 for `m`, 1000 for `km`).
        metres: f64,
    },
    /// `[latitude, longitude]` in degrees (drawn on a local equirectangular projection).
    LatLon,
}

/// What an area is, which decides how it is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum AreaKind {
    /// An area to survey.
    Survey,
    /// An area the vehicle must stay out of.
    Forbidden,
    /// Where the mission ends (recovery).
    End,
    /// Any other area.
    Zone,
}

impl AreaKind {
    /// The kind the file names.
    pub fn parse(s: &str) -> Option<AreaKind> {
        Some(match s {
            "survey" => AreaKind::Survey,
            "forbidden" => AreaKind::Forbidden,
            "end" => AreaKind::End,
            "zone" => AreaKind::Zone,
            _ => return None,
        })
    }

    /// Its name in the legend.
    pub fn legend(self) -> &'static str {
        match self {
            AreaKind::Survey => "survey area",
            AreaKind::Forbidden => "forbidden zone",
            AreaKind::End => "end area",
            AreaKind::Zone => "zone",
        }
    }
}

/// What the map file draws, positions as (east, north): (x, y), or (longitude, latitude).
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A polygon.
    Area {
        /// Its name, drawn inside it.
        name: String,
        /// Its kind.
        kind: AreaKind,
        /// Its outline.
        ring: Vec<(f64, f64)>,
    },
    /// A polyline known beforehand (a planned route, a coastline).
    Line {
        /// Its name.
        name: String,
        /// Its points.
        points: Vec<(f64, f64)>,
    },
    /// A named point (a start, a buoy).
    Point {
        /// Its name.
        name: String,
        /// Where.
        at: (f64, f64),
    },
}

/// Where a position is among an event's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pos {
    /// A `[float]` parameter: `[x, y, ...]` or `[latitude, longitude, ...]`.
    List(usize),
    /// Two `float` parameters: x (or longitude), then y (or latitude).
    Pair(usize, usize),
}

/// Where a track's positions come from.
#[derive(Clone, Debug, PartialEq)]
pub enum TrackFrom {
    /// The CAN data server's signals (`Message.signal`).
    Signals {
        /// x, or longitude.
        x: String,
        /// y, or latitude.
        y: String,
        /// A third value drawn against time (`petrel plot`'s profile): a depth, an altitude.
        z: Option<String>,
        /// Its name on the profile.
        z_label: Option<String>,
        /// Drawn downwards (a depth).
        z_down: bool,
    },
    /// A parameter of each `event` the player takes.
    Event {
        /// The event.
        event: String,
        /// The parameter(s).
        pos: Pos,
    },
}

/// A moving position: the vehicle's, or an estimate of it.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackSource {
    /// Its name in the legend.
    pub name: String,
    /// Where it comes from.
    pub from: TrackFrom,
}

/// How an event carries a planned route.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RouteShape {
    /// The whole route in one `[float]` parameter, `stride` numbers a point.
    Path {
        /// The parameter.
        param: usize,
        /// Numbers per point (2: x, y; 3: with an altitude).
        stride: usize,
    },
    /// One more waypoint per event, in a `[float]` parameter.
    Waypoint {
        /// The parameter.
        param: usize,
    },
}

/// Planned routes, carried by an event.
#[derive(Clone, Debug, PartialEq)]
pub struct RouteSource {
    /// Its name in the legend.
    pub name: String,
    /// The event.
    pub event: String,
    /// How it carries the route.
    pub shape: RouteShape,
}

/// A project's map (`map.toml`), checked against the project.
#[derive(Clone, Debug, PartialEq)]
pub struct Map {
    /// The drawing's title.
    pub title: String,
    /// How positions are written.
    pub coords: Coords,
    /// What is drawn under the vehicle.
    pub shapes: Vec<Shape>,
    /// The tracks, the first one the vehicle's (where marked events are drawn).
    pub tracks: Vec<TrackSource>,
    /// The planned routes events carry.
    pub routes: Vec<RouteSource>,
    /// The events marked on the map, each with its own position parameter or `None` (where
    /// the vehicle was).
    pub marks: BTreeMap<String, Option<usize>>,
}

impl Map {
    /// The signals the map reads (`Message.signal`).
    pub fn signals(&self) -> Vec<&str> {
        let mut out = Vec::new();
        for t in &self.tracks {
            if let TrackFrom::Signals { x, y, z, .. } = &t.from {
                out.push(x.as_str());
                out.push(y.as_str());
                out.extend(z.as_deref());
            }
        }
        out
    }
}

/// Metres east and north of (`e0`, `n0`) of a position, in the map's coordinates: scaled for
/// x/y, on a local equirectangular projection for latitude and longitude (good to a few
/// metres in ten kilometres, all a vehicle's map needs).
pub fn metres(coords: Coords, origin: (f64, f64), p: (f64, f64)) -> (f64, f64) {
    match coords {
        Coords::Xy { metres } => ((p.0 - origin.0) * metres, (p.1 - origin.1) * metres),
        Coords::LatLon => {
            const EARTH_RADIUS: f64 = 6_371_000.0;
            let k = std::f64::consts::PI / 180.0 * EARTH_RADIUS;
            let lat0 = origin.1.to_radians();
            ((p.0 - origin.0) * k * lat0.cos(), (p.1 - origin.1) * k)
        }
    }
}
