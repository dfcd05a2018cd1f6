//! The mission file: where the vehicle starts, the areas it surveys, the zones it must never
//! enter, where it ends, and the vehicle's parameters the planner needs.
//!
//! The file is TOML in the local metric frame (`x` east, `y` north, metres), so no geodesy is
//! needed; `vehicles/redermor/domain/README.md` documents the format with an example. [`Mission::from_toml`]
//! reads and validates it and reports every problem found, each naming its field the way the
//! file spells it (`area[1].polygon`, `vehicle.line_overlap`, `start`...).

use std::collections::HashMap;
use std::fmt;

use geo::{Area, Buffer, ConvexHull, Intersects, LineString, Polygon, Validation};
use serde::Deserialize;

use crate::geom::{self, Position};

/// A water current: the water's velocity over the ground, in m/s (east, north).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Current {
    /// Eastward component (m/s).
    pub east: f64,
    /// Northward component (m/s).
    pub north: f64,
}

impl Current {
    /// A current of these components (m/s).
    pub fn new(east: f64, north: f64) -> Self {
        Current { east, north }
    }

    /// Its speed (m/s).
    pub fn speed(&self) -> f64 {
        self.east.hypot(self.north)
    }

    /// The nautical heading the water flows towards (radians), 0 for still water.
    pub fn set_towards(&self) -> f64 {
        geom::heading_between(geom::pos(0.0, 0.0), self.as_vector())
    }

    /// As a vector of the local frame.
    pub fn as_vector(&self) -> Position {
        geom::pos(self.east, self.north)
    }
}

/// How deep a survey is flown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DepthTarget {
    /// At this depth below the surface (m).
    Depth(f64),
    /// At this height above the seabed (m), measured by the altimeter.
    Altitude(f64),
}

/// An area to survey with the sonar.
#[derive(Clone, Debug, PartialEq)]
pub struct SurveyArea {
    /// Its name, unique in the mission (the events name areas by it).
    pub name: String,
    /// Its outline (exterior ring only).
    pub polygon: Polygon<f64>,
    /// How deep its survey lines are flown.
    pub depth: DepthTarget,
    /// The current predicted there, if any: the survey lines are laid along it.
    pub predicted_current: Option<Current>,
}

/// A zone the vehicle must never enter (forbidden or non-navigable water).
#[derive(Clone, Debug, PartialEq)]
pub struct ForbiddenZone {
    /// Its name, unique in the mission.
    pub name: String,
    /// Its outline.
    pub polygon: Polygon<f64>,
}

/// Where the mission ends.
#[derive(Clone, Debug, PartialEq)]
pub enum EndArea {
    /// An area: the mission ends once inside it.
    Polygon(Polygon<f64>),
    /// A point: the mission ends within `radius` of it.
    Point {
        /// The point.
        at: Position,
        /// How close counts as there (m).
        radius: f64,
    },
}

impl EndArea {
    /// Whether `p` is in the end area.
    pub fn contains(&self, p: Position) -> bool {
        match self {
            EndArea::Polygon(polygon) => geom::inside_or_on(polygon, p),
            EndArea::Point { at, radius } => geom::distance(*at, p) <= *radius,
        }
    }

    /// The waypoint the vehicle heads for: the point, or a point inside the polygon (its
    /// centroid when that is inside, as the paper models areas by their centroid waypoint).
    pub fn target(&self) -> Position {
        match self {
            EndArea::Polygon(polygon) => representative_point(polygon),
            EndArea::Point { at, .. } => *at,
        }
    }
}

/// A point inside `polygon`: its centroid when the centroid is inside (convex areas), otherwise
/// geo's interior point (a concave area's centroid may lie outside it).
pub fn representative_point(polygon: &Polygon<f64>) -> Position {
    use geo::{Centroid, InteriorPoint};
    if let Some(c) = polygon.centroid() {
        if geom::strictly_inside(polygon, c.0) {
            return c.0;
        }
    }
    polygon
        .interior_point()
        .map(|p| p.0)
        .or_else(|| polygon.exterior().0.first().copied())
        .unwrap_or(geom::pos(0.0, 0.0))
}

/// The vehicle's parameters the planner and the guidance need.
#[derive(Clone, Debug, PartialEq)]
pub struct VehicleParams {
    /// Speed through the water on legs (m/s).
    pub cruise_speed: f64,
    /// Depth of the transits between areas (m).
    pub transit_depth: f64,
    /// Width of the seabed the sonar images on one line (m).
    pub swath_width: f64,
    /// Fraction of the swath two neighbouring lines share, in `[0, 0.9]`.
    pub line_overlap: f64,
    /// Clearance kept from every forbidden zone by the planned paths (m).
    pub safety_margin: f64,
    /// Distance to a waypoint at which a leg counts as done (m).
    pub arrival_radius: f64,
}

impl VehicleParams {
    /// The distance between neighbouring survey lines: the swath less the overlap.
    pub fn line_spacing(&self) -> f64 {
        self.swath_width * (1.0 - self.line_overlap)
    }
}

impl Default for VehicleParams {
    fn default() -> Self {
        VehicleParams {
            cruise_speed: 1.5,
            transit_depth: 5.0,
            swath_width: 60.0,
            line_overlap: 0.2,
            safety_margin: 20.0,
            arrival_radius: 8.0,
        }
    }
}

/// The seabed: a plane, flat or sloping, known from the bathymetry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seabed {
    /// Depth of the seabed at the origin of the frame (m).
    pub depth: f64,
    /// Metres of depth gained per metre east.
    pub slope_east: f64,
    /// Metres of depth gained per metre north.
    pub slope_north: f64,
}

impl Seabed {
    /// The seabed's depth under `p` (m), never less than 0.
    pub fn depth_at(&self, p: Position) -> f64 {
        (self.depth + self.slope_east * p.x + self.slope_north * p.y).max(0.0)
    }
}

impl Default for Seabed {
    fn default() -> Self {
        Seabed {
            depth: 50.0,
            slope_east: 0.0,
            slope_north: 0.0,
        }
    }
}

/// A validated mission.
#[derive(Clone, Debug, PartialEq)]
pub struct Mission {
    /// Its name.
    pub name: String,
    /// Free text.
    pub description: String,
    /// Where the vehicle starts, at the surface.
    pub start: Position,
    /// The vehicle's parameters.
    pub vehicle: VehicleParams,
    /// The seabed under the mission.
    pub seabed: Seabed,
    /// The areas to survey, in the file's order (the planner chooses the order flown).
    pub areas: Vec<SurveyArea>,
    /// The zones never to enter.
    pub forbidden: Vec<ForbiddenZone>,
    /// Where the mission ends.
    pub end: EndArea,
}

impl Mission {
    /// Reads and validates a mission file's text. Every problem found is reported, each naming
    /// its field.
    pub fn from_toml(text: &str) -> Result<Mission, MissionErrors> {
        let file: MissionFile = toml::from_str(text).map_err(|e| {
            MissionErrors(vec![MissionError {
                field: syntax_field(&e),
                problem: Problem::Syntax(e.message().trim().to_string()),
            }])
        })?;
        file.validate()
    }

    /// The survey area of this name.
    pub fn area(&self, name: &str) -> Option<&SurveyArea> {
        self.areas.iter().find(|a| a.name == name)
    }

    /// The forbidden zone containing `p` (inside or on its boundary), if any.
    pub fn forbidden_at(&self, p: Position) -> Option<&ForbiddenZone> {
        self.forbidden
            .iter()
            .find(|z| geom::inside_or_on(&z.polygon, p))
    }
}

/// One problem of a mission file.
#[derive(Clone, Debug, PartialEq)]
pub struct MissionError {
    /// The field, as the file spells it: `area[1].polygon`, `vehicle.swath_width`, `start`.
    pub field: String,
    /// What is wrong with it.
    pub problem: Problem,
}

/// What is wrong with a field of a mission file.
#[derive(Clone, Debug, PartialEq)]
pub enum Problem {
    /// The text is not TOML, or not the shape of a mission (toml's message).
    Syntax(String),
    /// A polygon with fewer than 3 distinct points.
    TooFewPoints {
        /// How many distinct points it has.
        points: usize,
    },
    /// A polygon whose outline crosses itself.
    SelfIntersecting,
    /// A polygon of zero area (all its points on one line).
    Degenerate,
    /// A number that is NaN or infinite.
    NotFinite,
    /// A number out of its range.
    OutOfRange {
        /// The value given.
        value: f64,
        /// The range allowed, in words.
        allowed: &'static str,
    },
    /// A name given twice.
    DuplicateName {
        /// The name.
        name: String,
        /// The field where it was first given.
        first: String,
    },
    /// An empty name.
    EmptyName,
    /// An area or the end area overlapping a forbidden zone.
    OverlapsForbidden {
        /// The forbidden zone's name.
        zone: String,
        /// The forbidden zone's field.
        zone_field: String,
    },
    /// The start point inside a forbidden zone.
    StartInForbidden {
        /// The forbidden zone's name.
        zone: String,
    },
    /// Exactly one of two fields must be given.
    OneOf {
        /// The two fields.
        fields: [&'static str; 2],
        /// How many were given (0 or 2).
        given: usize,
    },
    /// The mission has no survey area.
    NoArea,
}

impl fmt::Display for MissionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "{}", self.problem)
        } else {
            write!(f, "{}: {}", self.field, self.problem)
        }
    }
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Syntax(message) => write!(f, "{message}"),
            Problem::TooFewPoints { points } => write!(
                f,
                "a polygon needs at least 3 distinct points, this one has {points}"
            ),
            Problem::SelfIntersecting => write!(f, "the polygon's outline crosses itself"),
            Problem::Degenerate => write!(f, "the polygon has no area (its points are in line)"),
            Problem::NotFinite => write!(f, "a number is NaN or infinite"),
            Problem::OutOfRange { value, allowed } => {
                write!(f, "{value} is out of range, {allowed}")
            }
            Problem::DuplicateName { name, first } => {
                write!(f, "the name \"{name}\" is already used by {first}")
            }
            Problem::EmptyName => write!(f, "the name is empty"),
            Problem::OverlapsForbidden { zone, zone_field } => {
                write!(f, "overlaps the forbidden zone \"{zone}\" ({zone_field})")
            }
            Problem::StartInForbidden { zone } => {
                write!(f, "the start point is inside the forbidden zone \"{zone}\"")
            }
            Problem::OneOf { fields, given } => write!(
                f,
                "give exactly one of `{}` and `{}` ({given} given)",
                fields[0], fields[1]
            ),
            Problem::NoArea => write!(f, "a mission needs at least one [[area]]"),
        }
    }
}

/// Every problem of a mission file (never empty).
#[derive(Clone, Debug, PartialEq)]
pub struct MissionErrors(pub Vec<MissionError>);

impl MissionErrors {
    /// The problem reported for `field`, if any.
    pub fn for_field(&self, field: &str) -> Option<&MissionError> {
        self.0.iter().find(|e| e.field == field)
    }
}

impl fmt::Display for MissionErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for MissionErrors {}

/// The field a toml error is about, when its message names one ("missing field `start`").
fn syntax_field(e: &toml::de::Error) -> String {
    let message = e.message();
    message
        .split('`')
        .nth(1)
        .filter(|_| message.contains("field"))
        .unwrap_or("")
        .to_string()
}

// The file's shape. Kept apart from the validated types so that the file stays simple
// (points as [x, y]) and validation can name fields as the file spells them.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MissionFile {
    name: String,
    #[serde(default)]
    description: String,
    start: [f64; 2],
    #[serde(default)]
    vehicle: VehicleFile,
    #[serde(default)]
    seabed: Option<SeabedFile>,
    #[serde(default)]
    area: Vec<AreaFile>,
    #[serde(default)]
    forbidden: Vec<ZoneFile>,
    end: EndFile,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct VehicleFile {
    cruise_speed: Option<f64>,
    transit_depth: Option<f64>,
    swath_width: Option<f64>,
    line_overlap: Option<f64>,
    safety_margin: Option<f64>,
    arrival_radius: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SeabedFile {
    depth: f64,
    #[serde(default)]
    slope: [f64; 2],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AreaFile {
    name: String,
    polygon: Vec<[f64; 2]>,
    depth: Option<f64>,
    altitude: Option<f64>,
    current: Option<[f64; 2]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ZoneFile {
    name: String,
    polygon: Vec<[f64; 2]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EndFile {
    polygon: Option<Vec<[f64; 2]>>,
    point: Option<[f64; 2]>,
    radius: Option<f64>,
}

/// Collects the problems of a file as validation goes.
#[derive(Default)]
struct Problems(Vec<MissionError>);

impl Problems {
    fn add(&mut self, field: impl Into<String>, problem: Problem) {
        self.0.push(MissionError {
            field: field.into(),
            problem,
        });
    }

    /// `value` if finite and within `[lo, hi]`, otherwise a problem and `None`.
    fn number(
        &mut self,
        field: &str,
        value: f64,
        lo: f64,
        hi: f64,
        allowed: &'static str,
    ) -> Option<f64> {
        if !value.is_finite() {
            self.add(field, Problem::NotFinite);
            None
        } else if value < lo || value > hi {
            self.add(field, Problem::OutOfRange { value, allowed });
            None
        } else {
            Some(value)
        }
    }

    fn point(&mut self, field: &str, p: [f64; 2]) -> Option<Position> {
        if p.iter().all(|v| v.is_finite()) {
            Some(geom::pos(p[0], p[1]))
        } else {
            self.add(field, Problem::NotFinite);
            None
        }
    }

    /// A valid simple polygon from the file's points, or the problem with it.
    fn polygon(&mut self, field: &str, points: &[[f64; 2]]) -> Option<Polygon<f64>> {
        if points.iter().flatten().any(|v| !v.is_finite()) {
            self.add(field, Problem::NotFinite);
            return None;
        }
        let mut coords: Vec<Position> = Vec::with_capacity(points.len());
        for p in points {
            let c = geom::pos(p[0], p[1]);
            // Repeated points (and a closing point equal to the first) add nothing.
            if coords.last() != Some(&c) {
                coords.push(c);
            }
        }
        if coords.len() > 1 && coords.first() == coords.last() {
            coords.pop();
        }
        let mut distinct = coords.clone();
        distinct.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
        distinct.dedup();
        if distinct.len() < 3 {
            self.add(
                field,
                Problem::TooFewPoints {
                    points: distinct.len(),
                },
            );
            return None;
        }
        let polygon = Polygon::new(LineString::from(coords), vec![]);
        // All points in line (a bow tie's area is nil too, but its hull's is not).
        if polygon.convex_hull().unsigned_area() <= 1e-9 {
            self.add(field, Problem::Degenerate);
            return None;
        }
        if !polygon.is_valid() {
            self.add(field, Problem::SelfIntersecting);
            return None;
        }
        Some(polygon)
    }

    fn name(&mut self, field: &str, name: &str, seen: &mut HashMap<String, String>) {
        if name.trim().is_empty() {
            self.add(field, Problem::EmptyName);
        } else if let Some(first) = seen.get(name) {
            self.add(
                field,
                Problem::DuplicateName {
                    name: name.to_string(),
                    first: first.clone(),
                },
            );
        } else {
            seen.insert(name.to_string(), field.to_string());
        }
    }
}

impl MissionFile {
    fn validate(self) -> Result<Mission, MissionErrors> {
        let mut p = Problems::default();
        if self.name.trim().is_empty() {
            p.add("name", Problem::EmptyName);
        }
        let start = p.point("start", self.start);

        let defaults = VehicleParams::default();
        let v = &self.vehicle;
        let mut param = |field: &str, given: Option<f64>, default: f64, lo, hi, allowed| {
            given
                .and_then(|x| p.number(field, x, lo, hi, allowed))
                .unwrap_or(default)
        };
        let vehicle = VehicleParams {
            cruise_speed: param(
                "vehicle.cruise_speed",
                v.cruise_speed,
                defaults.cruise_speed,
                0.2,
                4.0,
                "from 0.2 to 4 m/s",
            ),
            transit_depth: param(
                "vehicle.transit_depth",
                v.transit_depth,
                defaults.transit_depth,
                0.0,
                300.0,
                "from 0 to 300 m",
            ),
            swath_width: param(
                "vehicle.swath_width",
                v.swath_width,
                defaults.swath_width,
                1.0,
                1000.0,
                "from 1 to 1000 m",
            ),
            line_overlap: param(
                "vehicle.line_overlap",
                v.line_overlap,
                defaults.line_overlap,
                0.0,
                0.9,
                "from 0 to 0.9",
            ),
            safety_margin: param(
                "vehicle.safety_margin",
                v.safety_margin,
                defaults.safety_margin,
                0.0,
                1000.0,
                "from 0 to 1000 m",
            ),
            arrival_radius: param(
                "vehicle.arrival_radius",
                v.arrival_radius,
                defaults.arrival_radius,
                0.5,
                200.0,
                "from 0.5 to 200 m",
            ),
        };

        let seabed = match &self.seabed {
            None => Seabed::default(),
            Some(s) => {
                let depth = p.number("seabed.depth", s.depth, 1.0, 11000.0, "from 1 to 11000 m");
                if s.slope.iter().any(|v| !v.is_finite()) {
                    p.add("seabed.slope", Problem::NotFinite);
                }
                Seabed {
                    depth: depth.unwrap_or(Seabed::default().depth),
                    slope_east: s.slope[0],
                    slope_north: s.slope[1],
                }
            }
        };

        let mut names: HashMap<String, String> = HashMap::new();
        let mut forbidden = Vec::new();
        for (i, z) in self.forbidden.iter().enumerate() {
            let field = format!("forbidden[{i}]");
            p.name(&format!("{field}.name"), &z.name, &mut names);
            if let Some(polygon) = p.polygon(&format!("{field}.polygon"), &z.polygon) {
                forbidden.push((
                    field,
                    ForbiddenZone {
                        name: z.name.clone(),
                        polygon,
                    },
                ));
            }
        }
        let overlaps = |polygon: &Polygon<f64>, p: &mut Problems, field: String| {
            for (zone_field, zone) in &forbidden {
                if polygon.intersects(&zone.polygon) {
                    p.add(
                        field.clone(),
                        Problem::OverlapsForbidden {
                            zone: zone.name.clone(),
                            zone_field: zone_field.clone(),
                        },
                    );
                }
            }
        };

        if self.area.is_empty() {
            p.add("area", Problem::NoArea);
        }
        let mut areas = Vec::new();
        for (i, a) in self.area.iter().enumerate() {
            let field = format!("area[{i}]");
            p.name(&format!("{field}.name"), &a.name, &mut names);
            let polygon = p.polygon(&format!("{field}.polygon"), &a.polygon);
            if let Some(polygon) = &polygon {
                overlaps(polygon, &mut p, format!("{field}.polygon"));
            }
            let depth = match (a.depth, a.altitude) {
                (Some(d), None) => p
                    .number(&format!("{field}.depth"), d, 0.0, 300.0, "from 0 to 300 m")
                    .map(DepthTarget::Depth),
                (None, Some(h)) => p
                    .number(
                        &format!("{field}.altitude"),
                        h,
                        1.0,
                        200.0,
                        "from 1 to 200 m",
                    )
                    .map(DepthTarget::Altitude),
                (d, h) => {
                    p.add(
                        format!("{field}.depth"),
                        Problem::OneOf {
                            fields: ["depth", "altitude"],
                            given: usize::from(d.is_some()) + usize::from(h.is_some()),
                        },
                    );
                    None
                }
            };
            let current = match a.current {
                None => None,
                Some(c) => {
                    let field = format!("{field}.current");
                    p.point(&field, c).and_then(|c| {
                        let speed = c.x.hypot(c.y);
                        p.number(&field, speed, 0.0, 3.0, "a speed from 0 to 3 m/s")
                            .map(|_| Current::new(c.x, c.y))
                    })
                }
            };
            if let (Some(polygon), Some(depth)) = (polygon, depth) {
                areas.push(SurveyArea {
                    name: a.name.clone(),
                    polygon,
                    depth,
                    predicted_current: current,
                });
            }
        }

        if let Some(s) = start {
            for (_, zone) in &forbidden {
                if geom::inside_or_on(&zone.polygon, s) {
                    p.add(
                        "start",
                        Problem::StartInForbidden {
                            zone: zone.name.clone(),
                        },
                    );
                }
            }
        }

        let e = &self.end;
        let end = match (&e.polygon, e.point) {
            (Some(points), None) => {
                if e.radius.is_some() {
                    p.add(
                        "end.radius",
                        Problem::OneOf {
                            fields: ["polygon", "radius"],
                            given: 2,
                        },
                    );
                }
                p.polygon("end.polygon", points).map(|polygon| {
                    overlaps(&polygon, &mut p, "end.polygon".to_string());
                    EndArea::Polygon(polygon)
                })
            }
            (None, Some(point)) => {
                let radius = e
                    .radius
                    .and_then(|r| p.number("end.radius", r, 0.5, 10000.0, "from 0.5 to 10000 m"))
                    .unwrap_or(vehicle.arrival_radius);
                p.point("end.point", point).map(|at| {
                    let disc = geo::Point(at).buffer(radius);
                    for polygon in disc {
                        overlaps(&polygon, &mut p, "end.point".to_string());
                    }
                    EndArea::Point { at, radius }
                })
            }
            (polygon, point) => {
                p.add(
                    "end",
                    Problem::OneOf {
                        fields: ["polygon", "point"],
                        given: usize::from(polygon.is_some()) + usize::from(point.is_some()),
                    },
                );
                None
            }
        };

        match (start, end) {
            (Some(start), Some(end)) if p.0.is_empty() => Ok(Mission {
                name: self.name,
                description: self.description,
                start,
                vehicle,
                seabed,
                areas,
                forbidden: forbidden.into_iter().map(|(_, z)| z).collect(),
                end,
            }),
            _ => Err(MissionErrors(p.0)),
        }
    }
}
