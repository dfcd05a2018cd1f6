//! The map's core, sans I/O: signals and steps in (with their mission time), tracks, planned
//! routes and marked events out. The monitor feeds it live, [`record`](super::record) from a
//! journal and a bus recording; the drawing reads it.

use super::{metres, Map, Pos, RouteShape, TrackFrom};
use petrel_value::Value;

/// A track's position, at its mission time (s): (east, north) in the map's coordinates, and
/// the third value when the track has one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Mission time, seconds.
    pub t: f64,
    /// x or longitude.
    pub e: f64,
    /// y or latitude.
    pub n: f64,
    /// Depth, altitude... (`z`).
    pub z: Option<f64>,
}

/// A planned route, as an event gave it.
#[derive(Clone, Debug, PartialEq)]
pub struct Route {
    /// When the event came.
    pub t: f64,
    /// Which of the map's routes.
    pub source: usize,
    /// Its points.
    pub points: Vec<(f64, f64)>,
}

/// An event marked where it happened.
#[derive(Clone, Debug, PartialEq)]
pub struct Mark {
    /// When.
    pub t: f64,
    /// Where.
    pub at: (f64, f64),
    /// What: the event and its parameters.
    pub label: String,
}

/// A new position closer than this to the last one kept (metres) is not kept: a vehicle
/// standing still does not grow its track.
pub const MIN_STEP_M: f64 = 0.5;
/// A track longer than this is halved (every other position dropped): the drawing stays
/// light however long the mission.
pub const MAX_SAMPLES: usize = 20_000;
/// Marks kept (the latest).
pub const MAX_MARKS: usize = 2_000;
/// Routes kept (the latest).
pub const MAX_ROUTES: usize = 500;
/// A mark's label longer than this is cut (a route's waypoints are not worth reading there).
const MAX_LABEL: usize = 48;

/// What the map shows so far.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapState {
    /// One list per track of the map, in time order.
    pub tracks: Vec<Vec<Sample>>,
    /// Planned routes, in time order.
    pub routes: Vec<Route>,
    /// Marked events, in time order.
    pub marks: Vec<Mark>,
    /// Changed so far: a page draws the map again when it grew.
    pub version: u64,
}

impl MapState {
    /// Nothing yet, for `map`.
    pub fn new(map: &Map) -> MapState {
        MapState {
            tracks: vec![Vec::new(); map.tracks.len()],
            ..MapState::default()
        }
    }

    /// The latest values of the signals (`get("Message.signal")`) at mission time `t`: the
    /// tracks from signals move. True when the map changed.
    pub fn on_signals(&mut self, map: &Map, t: f64, get: impl Fn(&str) -> Option<f64>) -> bool {
        let mut changed = false;
        for (i, src) in map.tracks.iter().enumerate() {
            let TrackFrom::Signals { x, y, z, .. } = &src.from else {
                continue;
            };
            let (Some(e), Some(n)) = (get(x), get(y)) else {
                continue;
            };
            let z = z.as_deref().and_then(&get);
            changed |= self.push(map, i, Sample { t, e, n, z });
        }
        if changed {
            self.version += 1;
        }
        changed
    }

    /// A step of the player at mission time `t`: event `event` with `params`; `took`: some
    /// transition fired on it (only those are marked). True when the map changed.
    pub fn on_step(
        &mut self,
        map: &Map,
        t: f64,
        event: &str,
        params: &[Value],
        took: bool,
    ) -> bool {
        let mut changed = false;
        for (i, src) in map.tracks.iter().enumerate() {
            let TrackFrom::Event { event: e, pos } = &src.from else {
                continue;
            };
            if e != event {
                continue;
            }
            let at = match *pos {
                Pos::List(p) => point(map, params.get(p)),
                Pos::Pair(x, y) => match (params.get(x), params.get(y)) {
                    (Some(Value::Float(x)), Some(Value::Float(y))) => Some((*x, *y)),
                    _ => None,
                },
            };
            if let Some((e, n)) = at.filter(|(e, n)| e.is_finite() && n.is_finite()) {
                changed |= self.push(map, i, Sample { t, e, n, z: None });
            }
        }
        for (i, src) in map.routes.iter().enumerate() {
            if src.event != event {
                continue;
            }
            match src.shape {
                RouteShape::Path { param, stride } => {
                    let points = path(map, params.get(param), stride);
                    if !points.is_empty() {
                        if self.routes.len() == MAX_ROUTES {
                            self.routes.remove(0);
                        }
                        self.routes.push(Route {
                            t,
                            source: i,
                            points,
                        });
                        changed = true;
                    }
                }
                RouteShape::Waypoint { param } => {
                    let Some(p) = point(map, params.get(param)) else {
                        continue;
                    };
                    // One route per source, growing: a new one only for the first waypoint.
                    match self.routes.iter_mut().rev().find(|r| r.source == i) {
                        Some(r) => r.points.push(p),
                        None => self.routes.push(Route {
                            t,
                            source: i,
                            points: vec![p],
                        }),
                    }
                    changed = true;
                }
            }
        }
        if took {
            if let Some(at) = map.marks.get(event) {
                let place = match at {
                    Some(p) => point(map, params.get(*p)),
                    None => self.vehicle(),
                };
                if let Some(at) = place {
                    if self.marks.len() == MAX_MARKS {
                        self.marks.remove(0);
                    }
                    self.marks.push(Mark {
                        t,
                        at,
                        label: label(event, params),
                    });
                    changed = true;
                }
            }
        }
        if changed {
            self.version += 1;
        }
        changed
    }

    /// Where the vehicle is last known: the latest position of the first track that has one.
    pub fn vehicle(&self) -> Option<(f64, f64)> {
        self.tracks
            .iter()
            .find_map(|t| t.last())
            .map(|s| (s.e, s.n))
    }

    /// Keeps sample `s` on track `i` unless it is within [`MIN_STEP_M`] of the last one.
    fn push(&mut self, map: &Map, i: usize, s: Sample) -> bool {
        let track = &mut self.tracks[i];
        if let Some(last) = track.last() {
            let (dx, dy) = metres(map.coords, (last.e, last.n), (s.e, s.n));
            let dz = match (last.z, s.z) {
                (Some(a), Some(b)) => (a - b).abs(),
                _ => 0.0,
            };
            if dx.hypot(dy) < MIN_STEP_M && dz < MIN_STEP_M {
                return false;
            }
        }
        if track.len() >= MAX_SAMPLES {
            // Every other one, the newest kept.
            let mut k = 0;
            track.retain(|_| {
                k += 1;
                k % 2 == 0
            });
        }
        track.push(s);
        true
    }

    /// What the map showed at mission time `t`: the positions, routes and marks of that time
    /// and before (a replay's slider).
    pub fn until(&self, t: f64) -> MapState {
        MapState {
            tracks: self
                .tracks
                .iter()
                .map(|tr| tr[..tr.partition_point(|s| s.t <= t)].to_vec())
                .collect(),
            routes: self.routes.iter().filter(|r| r.t <= t).cloned().collect(),
            marks: self.marks.iter().filter(|m| m.t <= t).cloned().collect(),
            version: self.version,
        }
    }
}

/// A point of a `[float]` parameter: `[x, y, ...]`, or `[latitude, longitude, ...]` turned
/// into (longitude, latitude).
fn point(map: &Map, v: Option<&Value>) -> Option<(f64, f64)> {
    match v {
        Some(Value::FloatList(f)) if f.len() >= 2 && f[0].is_finite() && f[1].is_finite() => {
            Some(oriented(map, f[0], f[1]))
        }
        _ => None,
    }
}

/// The points of a flat `[float]` list, `stride` numbers each.
fn path(map: &Map, v: Option<&Value>, stride: usize) -> Vec<(f64, f64)> {
    match v {
        Some(Value::FloatList(f)) => f
            .chunks_exact(stride.max(2))
            .filter(|c| c[0].is_finite() && c[1].is_finite())
            .map(|c| oriented(map, c[0], c[1]))
            .collect(),
        _ => Vec::new(),
    }
}

/// (east, north) of a pair as the file writes it.
fn oriented(map: &Map, a: f64, b: f64) -> (f64, f64) {
    match map.coords {
        super::Coords::Xy { .. } => (a, b),
        super::Coords::LatLon => (b, a),
    }
}

/// `event(params)`, cut to [`MAX_LABEL`] characters.
fn label(event: &str, params: &[Value]) -> String {
    let mut s = event.to_string();
    if !params.is_empty() {
        let args: Vec<String> = params.iter().map(Value::literal).collect();
        s = format!("{event}({})", args.join(", "));
    }
    if s.chars().count() > MAX_LABEL {
        s = s.chars().take(MAX_LABEL - 1).collect::<String>() + "\u{2026}";
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Coords, RouteSource, TrackSource};
    use std::collections::BTreeMap;

    fn map() -> Map {
        Map {
            title: "t".into(),
            coords: Coords::Xy { metres: 1.0 },
            shapes: Vec::new(),
            tracks: vec![
                TrackSource {
                    name: "truth".into(),
                    from: TrackFrom::Signals {
                        x: "Nav.x".into(),
                        y: "Nav.y".into(),
                        z: None,
                        z_label: None,
                        z_down: false,
                    },
                },
                TrackSource {
                    name: "estimate".into(),
                    from: TrackFrom::Event {
                        event: "state".into(),
                        pos: Pos::List(0),
                    },
                },
            ],
            routes: vec![
                RouteSource {
                    name: "plan".into(),
                    event: "trajectory".into(),
                    shape: RouteShape::Path {
                        param: 0,
                        stride: 2,
                    },
                },
                RouteSource {
                    name: "waypoints".into(),
                    event: "waypoint".into(),
                    shape: RouteShape::Waypoint { param: 0 },
                },
            ],
            marks: BTreeMap::from([("alarm".to_string(), None)]),
        }
    }

    fn list(v: &[f64]) -> Vec<Value> {
        vec![Value::FloatList(v.to_vec())]
    }

    #[test]
    fn signals_grow_the_track_by_distance_and_marks_go_where_the_vehicle_is() {
        let m = map();
        let mut s = MapState::new(&m);
        let at = |x: f64, y: f64| move |n: &str| if n == "Nav.x" { Some(x) } else { Some(y) };
        assert!(s.on_signals(&m, 1.0, at(0.0, 0.0)));
        // Standing still: nothing new.
        assert!(!s.on_signals(&m, 1.5, at(0.1, 0.1)));
        assert!(s.on_signals(&m, 2.0, at(3.0, 4.0)));
        assert_eq!(s.tracks[0].len(), 2);
        assert!(s.on_step(&m, 2.5, "alarm", &[Value::Text("return".into())], true));
        assert_eq!(s.marks[0].at, (3.0, 4.0));
        assert_eq!(s.marks[0].label, "alarm(\"return\")");
        // An event no transition took is not marked.
        assert!(!s.on_step(&m, 2.6, "alarm", &[], false));
        // The replay's view at a time: what came before it.
        let then = s.until(1.9);
        assert_eq!((then.tracks[0].len(), then.marks.len()), (1, 0));
    }

    #[test]
    fn events_give_positions_routes_and_waypoints() {
        let m = map();
        let mut s = MapState::new(&m);
        assert!(s.on_step(&m, 1.0, "state", &list(&[5.0, 6.0, 7.0]), true));
        assert_eq!(s.tracks[1][0].e, 5.0);
        assert!(s.on_step(
            &m,
            2.0,
            "trajectory",
            &list(&[0.0, 0.0, 10.0, 0.0, 10.0, 10.0]),
            true
        ));
        assert_eq!(s.routes[0].points, [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]);
        s.on_step(&m, 3.0, "waypoint", &list(&[1.0, 1.0]), true);
        s.on_step(&m, 4.0, "waypoint", &list(&[2.0, 2.0]), true);
        assert_eq!(s.routes.len(), 2);
        assert_eq!(s.routes[1].points, [(1.0, 1.0), (2.0, 2.0)]);
        // A parameter that is not a position is ignored, not a panic.
        assert!(!s.on_step(&m, 5.0, "state", &[Value::Int(3)], true));
    }

    #[test]
    fn a_long_track_is_halved_and_stays_bounded() {
        let m = map();
        let mut s = MapState::new(&m);
        for i in 0..(3 * MAX_SAMPLES) {
            let x = i as f64;
            s.on_signals(&m, x, |n| if n == "Nav.x" { Some(x) } else { Some(0.0) });
        }
        let t = &s.tracks[0];
        assert!(
            t.len() <= MAX_SAMPLES && t.len() > MAX_SAMPLES / 2,
            "{}",
            t.len()
        );
        assert_eq!(t.last().unwrap().e, (3 * MAX_SAMPLES - 1) as f64);
        assert!(t.windows(2).all(|w| w[0].t < w[1].t));
    }
}
