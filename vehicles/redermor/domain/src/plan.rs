//! PLN, the planning program: the itinerary (the order the areas are joined in), paths between
//! two points around the forbidden zones, the survey of an area (its operative sequence), and
//! the three replans of the paper's non-nominal scenario (section 3.1.3): go to the end area
//! now, a new survey for a measured current, and an inspection around a point.
//!
//! Trajectories are straight [`Leg`]s; the course changes are the heading changes between
//! consecutive legs ([`Trajectory::course_changes`]).
//!
//! Paths: a visibility graph over the vertices of the forbidden zones inflated by the safety
//! margin (geo's buffer, mitred so that a zone keeps about its vertex count, corners sharper
//! than 0.5 rad bevelled; then the union of the inflated zones, so that overlapping ones merge), searched with `pathfinding`'s A*. A segment is
//! usable when it does not enter the interior of an inflated zone (geo's DE-9IM relate); running
//! along an inflated zone's edge is allowed, that edge being the safety margin away. A point
//! already inside an inflated zone (but outside the zone itself) may leave it by any segment
//! that stays out of every zone proper.
//!
//! Surveys: boustrophedon lines (lawnmower) across the area, `swath × (1 − overlap)` apart. The
//! lines are laid **along the current**, so that the vehicle flies up-current and down-current
//! alternately: no crab angle on a line, so the sonar's swath is not skewed and the line is
//! flown straight; only the speed over the ground changes from line to line. In still water (or
//! below 5 cm/s) the lines follow the direction that makes the area narrowest, which gives the
//! fewest lines and turns. Each line spans its band of the area (`spacing` wide) from one end
//! to the other, so every point of the area is within `spacing / 2 ≤ swath / 2` of a line. Of
//! the four ways to fly the pattern, the one whose first point is nearest to the vehicle's
//! arrival is chosen. Lines are cut where they would come nearer a forbidden zone than the
//! safety margin (coverage there is given up) and the pieces joined by paths around it.

use std::fmt;

use geo::algorithm::buffer::{BufferStyle, LineJoin};
use geo::{BooleanOps, Buffer, ConvexHull, LineString, MultiLineString, MultiPolygon, Polygon};
use pathfinding::prelude::astar;

use crate::geom::{self, Position};
use crate::mission::{representative_point, Current, DepthTarget, Mission};

/// Below this current speed (m/s) the survey lines ignore the current.
pub const CURRENT_THRESHOLD: f64 = 0.05;

/// Up to this many areas, the itinerary is the shortest of all orders; beyond, nearest
/// neighbour first.
pub const EXACT_ITINERARY_MAX_AREAS: usize = 7;

/// What a leg is for.
#[derive(Clone, Debug, PartialEq)]
pub enum LegKind {
    /// A transit between areas, or to the end area.
    Transit,
    /// A survey line: the sonar records.
    SurveyLine {
        /// The area.
        area: String,
        /// The line's rank in the survey, from 0 in flight order.
        line: usize,
    },
    /// From the end of a survey line to the start of the next.
    LineChange {
        /// The area.
        area: String,
    },
    /// Part of an inspection pattern around an object.
    Inspection,
    /// Back from an inspection to where the survey stopped.
    Return,
}

/// A straight leg of a trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Leg {
    /// What it is for.
    pub kind: LegKind,
    /// Where it starts.
    pub from: Position,
    /// Where it ends.
    pub to: Position,
    /// How deep it is flown.
    pub depth: DepthTarget,
    /// Speed through the water (m/s).
    pub speed: f64,
}

impl Leg {
    /// Its nautical heading (radians).
    pub fn heading(&self) -> f64 {
        geom::heading_between(self.from, self.to)
    }

    /// Its length (m).
    pub fn length(&self) -> f64 {
        geom::distance(self.from, self.to)
    }
}

/// A heading change between two legs, at the waypoint joining them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CourseChange {
    /// The waypoint.
    pub at: Position,
    /// Index of the leg it leads into.
    pub leg: usize,
    /// Heading before (radians).
    pub from_heading: f64,
    /// Heading after (radians).
    pub to_heading: f64,
}

impl CourseChange {
    /// The signed turn in `(-π, π]`: positive to starboard (clockwise).
    pub fn turn(&self) -> f64 {
        geom::wrap_pi(self.to_heading - self.from_heading)
    }
}

/// A sequence of straight legs, each starting where the previous ends.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// The legs in flight order.
    pub legs: Vec<Leg>,
}

impl Trajectory {
    /// Its length (m).
    pub fn length(&self) -> f64 {
        self.legs.iter().map(Leg::length).sum()
    }

    /// Its waypoints: the first leg's start, then every leg's end.
    pub fn waypoints(&self) -> Vec<Position> {
        let mut points: Vec<Position> = self.legs.first().map(|l| l.from).into_iter().collect();
        points.extend(self.legs.iter().map(|l| l.to));
        points
    }

    /// Where it ends, if it has a leg.
    pub fn end(&self) -> Option<Position> {
        self.legs.last().map(|l| l.to)
    }

    /// The course changes, one per waypoint between two legs (none for a straight go-on).
    pub fn course_changes(&self) -> Vec<CourseChange> {
        self.legs
            .windows(2)
            .enumerate()
            .filter_map(|(i, w)| {
                let change = CourseChange {
                    at: w[0].to,
                    leg: i + 1,
                    from_heading: w[0].heading(),
                    to_heading: w[1].heading(),
                };
                (change.turn().abs() > 1e-9).then_some(change)
            })
            .collect()
    }

    /// What is left of it from `at` on leg `leg`: that leg from `at`, then the following ones
    /// (where a survey resumes after an inspection). Empty past the last leg.
    pub fn remainder_from(&self, leg: usize, at: Position) -> Trajectory {
        let mut legs: Vec<Leg> = self.legs.iter().skip(leg).cloned().collect();
        if let Some(first) = legs.first_mut() {
            first.from = at;
        }
        Trajectory { legs }
    }
}

/// Why a plan could not be made.
#[derive(Clone, Debug, PartialEq)]
pub enum PlanError {
    /// No survey area of this name.
    UnknownArea(String),
    /// A point to plan from or to lies inside a forbidden zone.
    InForbidden {
        /// The point.
        point: Position,
        /// The zone's name.
        zone: String,
    },
    /// The forbidden zones (with the safety margin) wall off the destination.
    NoPath {
        /// From.
        from: Position,
        /// To.
        to: Position,
    },
    /// A number given to a replan is out of its range.
    BadArgument(&'static str),
}

impl fmt::Display for PlanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlanError::UnknownArea(name) => write!(f, "no survey area is named \"{name}\""),
            PlanError::InForbidden { point, zone } => write!(
                f,
                "({:.1}, {:.1}) is inside the forbidden zone \"{zone}\"",
                point.x, point.y
            ),
            PlanError::NoPath { from, to } => write!(
                f,
                "no path from ({:.1}, {:.1}) to ({:.1}, {:.1}) keeps clear of the forbidden zones",
                from.x, from.y, to.x, to.y
            ),
            PlanError::BadArgument(what) => write!(f, "{what}"),
        }
    }
}

impl std::error::Error for PlanError {}

/// The order the areas are joined in.
#[derive(Clone, Debug, PartialEq)]
pub struct Itinerary {
    /// Indices into [`Mission::areas`], in visiting order.
    pub order: Vec<usize>,
    /// Length of the path from the start through each area's representative point to the end
    /// area's (m): what the order minimises.
    pub length: f64,
}

/// The operative sequence of one area.
#[derive(Clone, Debug, PartialEq)]
pub struct Survey {
    /// The area's name.
    pub area: String,
    /// Heading of the lines (radians, in `[0, π)`; every other line is flown the other way).
    pub line_heading: f64,
    /// Distance between neighbouring lines (m).
    pub spacing: f64,
    /// The current the lines were laid for, if any.
    pub current: Option<Current>,
    /// The survey lines in flight order and direction (before any cut around forbidden zones).
    pub lines: Vec<(Position, Position)>,
    /// The legs: survey lines and line changes.
    pub trajectory: Trajectory,
}

impl Survey {
    /// Where the survey starts.
    pub fn entry(&self) -> Option<Position> {
        self.trajectory.legs.first().map(|l| l.from)
    }
}

/// What a stage of the mission does (the paper's Mission_Phases loop).
#[derive(Clone, Debug, PartialEq)]
pub enum StageKind {
    /// Transit to an area (Transit_to_Area).
    TransitToArea(String),
    /// Survey an area (Operation).
    Survey(String),
    /// Transit to the end area.
    TransitToEnd,
}

/// A stage of the mission and its trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Stage {
    /// What it does.
    pub kind: StageKind,
    /// Its legs (a transit may have none when the vehicle is already there).
    pub trajectory: Trajectory,
}

/// The whole mission's plan.
#[derive(Clone, Debug, PartialEq)]
pub struct MissionPlan {
    /// The order of the areas.
    pub itinerary: Itinerary,
    /// Transit, survey, transit, survey... then transit to the end area.
    pub stages: Vec<Stage>,
    /// The surveys, in itinerary order.
    pub surveys: Vec<Survey>,
}

impl MissionPlan {
    /// Every leg of every stage, in flight order.
    pub fn trajectory(&self) -> Trajectory {
        Trajectory {
            legs: self
                .stages
                .iter()
                .flat_map(|s| s.trajectory.legs.iter().cloned())
                .collect(),
        }
    }
}

/// The planner of a mission: the inflated zones and their visibility graph, computed once.
#[derive(Clone, Debug)]
pub struct Planner {
    mission: Mission,
    /// The forbidden zones inflated by the safety margin, overlapping ones merged.
    obstacles: Vec<Polygon<f64>>,
    /// Vertices of the obstacles: the visibility graph's fixed nodes.
    nodes: Vec<Position>,
    /// Edges between fixed nodes, with their lengths in millimetres.
    edges: Vec<Vec<(usize, u64)>>,
}

/// A length in whole millimetres: A* needs a totally ordered cost.
fn cost(a: Position, b: Position) -> u64 {
    (geom::distance(a, b) * 1000.0).round() as u64
}

impl Planner {
    /// A planner for `mission`.
    pub fn new(mission: &Mission) -> Planner {
        let margin = mission.vehicle.safety_margin;
        let mut merged = MultiPolygon::<f64>::new(vec![]);
        for zone in &mission.forbidden {
            let inflated = if margin > 0.0 {
                zone.polygon
                    .buffer_with_style(BufferStyle::new(margin).line_join(LineJoin::Miter(0.5)))
            } else {
                MultiPolygon::new(vec![zone.polygon.clone()])
            };
            merged = merged.union(&inflated);
        }
        let obstacles = merged.0;
        let mut nodes = Vec::new();
        for obstacle in &obstacles {
            for ring in std::iter::once(obstacle.exterior()).chain(obstacle.interiors()) {
                let coords = &ring.0[..ring.0.len().saturating_sub(1)];
                let n = coords.len();
                for (i, &c) in coords.iter().enumerate() {
                    // A vertex in line with its neighbours is no corner to go round.
                    let (prev, next) = (coords[(i + n - 1) % n], coords[(i + 1) % n]);
                    let cross = (c - prev).x * (next - c).y - (c - prev).y * (next - c).x;
                    if cross.abs() > 1e-6 * geom::distance(prev, c).max(1.0) {
                        nodes.push(c);
                    }
                }
            }
        }
        let mut planner = Planner {
            mission: mission.clone(),
            obstacles,
            nodes,
            edges: Vec::new(),
        };
        let n = planner.nodes.len();
        let mut edges = vec![Vec::new(); n];
        for i in 0..n {
            for j in i + 1..n {
                let (a, b) = (planner.nodes[i], planner.nodes[j]);
                if planner.segment_is_clear(a, b) {
                    edges[i].push((j, cost(a, b)));
                    edges[j].push((i, cost(a, b)));
                }
            }
        }
        planner.edges = edges;
        planner
    }

    /// The mission planned for.
    pub fn mission(&self) -> &Mission {
        &self.mission
    }

    /// The forbidden zones inflated by the safety margin (overlapping ones merged): what the
    /// paths go round.
    pub fn obstacles(&self) -> &[Polygon<f64>] {
        &self.obstacles
    }

    /// Whether the straight segment `a`-`b` is usable: it enters no inflated zone, except one
    /// that `a` or `b` is already inside, and then no zone proper.
    pub fn segment_is_clear(&self, a: Position, b: Position) -> bool {
        for obstacle in &self.obstacles {
            if geom::segment_enters(obstacle, a, b)
                && !geom::strictly_inside(obstacle, a)
                && !geom::strictly_inside(obstacle, b)
            {
                return false;
            }
        }
        !self
            .mission
            .forbidden
            .iter()
            .any(|z| geom::segment_enters(&z.polygon, a, b))
    }

    fn check_point(&self, p: Position) -> Result<(), PlanError> {
        match self.mission.forbidden_at(p) {
            Some(zone) => Err(PlanError::InForbidden {
                point: p,
                zone: zone.name.clone(),
            }),
            None => Ok(()),
        }
    }

    /// The shortest path from `from` to `to` that keeps the safety margin from every forbidden
    /// zone: its waypoints, `from` first and `to` last.
    pub fn path(&self, from: Position, to: Position) -> Result<Vec<Position>, PlanError> {
        self.check_point(from)?;
        self.check_point(to)?;
        if self.segment_is_clear(from, to) {
            return Ok(vec![from, to]);
        }
        // Node 0 is `from`, 1 is `to`, 2.. the fixed nodes.
        let fixed = |i: usize| self.nodes[i - 2];
        let from_edges: Vec<(usize, u64)> = (0..self.nodes.len())
            .filter(|&i| self.segment_is_clear(from, self.nodes[i]))
            .map(|i| (i + 2, cost(from, self.nodes[i])))
            .collect();
        let to_visible: Vec<bool> = self
            .nodes
            .iter()
            .map(|&n| self.segment_is_clear(n, to))
            .collect();
        let result = astar(
            &0usize,
            |&i| {
                let mut next: Vec<(usize, u64)> = if i == 0 {
                    from_edges.clone()
                } else {
                    self.edges[i - 2].iter().map(|&(j, c)| (j + 2, c)).collect()
                };
                if i >= 2 && to_visible[i - 2] {
                    next.push((1, cost(fixed(i), to)));
                }
                next
            },
            |&i| match i {
                0 => cost(from, to),
                1 => 0,
                _ => cost(fixed(i), to),
            },
            |&i| i == 1,
        );
        let (route, _) = result.ok_or(PlanError::NoPath { from, to })?;
        Ok(route
            .into_iter()
            .map(|i| match i {
                0 => from,
                1 => to,
                _ => fixed(i),
            })
            .collect())
    }

    /// The length of [`Planner::path`] (m).
    pub fn path_length(&self, from: Position, to: Position) -> Result<f64, PlanError> {
        let path = self.path(from, to)?;
        Ok(path.windows(2).map(|w| geom::distance(w[0], w[1])).sum())
    }

    /// The legs of a path from `from` to `to`, all of one kind, depth and speed.
    pub fn route(
        &self,
        from: Position,
        to: Position,
        kind: LegKind,
        depth: DepthTarget,
    ) -> Result<Vec<Leg>, PlanError> {
        let path = self.path(from, to)?;
        Ok(path
            .windows(2)
            .filter(|w| w[0] != w[1])
            .map(|w| Leg {
                kind: kind.clone(),
                from: w[0],
                to: w[1],
                depth,
                speed: self.mission.vehicle.cruise_speed,
            })
            .collect())
    }

    /// The itinerary from `from`: the order of the areas that makes the shortest way through
    /// them to the end area (exact up to [`EXACT_ITINERARY_MAX_AREAS`] areas, nearest
    /// neighbour beyond). Areas count by their representative point.
    pub fn itinerary(&self, from: Position) -> Result<Itinerary, PlanError> {
        let n = self.mission.areas.len();
        let mut points = vec![from];
        points.extend(
            self.mission
                .areas
                .iter()
                .map(|a| representative_point(&a.polygon)),
        );
        points.push(self.mission.end.target());
        let m = points.len();
        let mut dist = vec![vec![0.0; m]; m];
        for i in 0..m {
            for j in i + 1..m {
                let d = self.path_length(points[i], points[j])?;
                dist[i][j] = d;
                dist[j][i] = d;
            }
        }
        let end = m - 1;
        let total = |order: &[usize]| {
            let mut at = 0;
            let mut length = 0.0;
            for &a in order {
                length += dist[at][a + 1];
                at = a + 1;
            }
            length + dist[at][end]
        };
        let order = if n <= EXACT_ITINERARY_MAX_AREAS {
            let mut best = (f64::INFINITY, Vec::new());
            let mut order: Vec<usize> = (0..n).collect();
            permutations(&mut order, 0, &mut |o| {
                let l = total(o);
                if l < best.0 {
                    best = (l, o.to_vec());
                }
            });
            best.1
        } else {
            let mut left: Vec<usize> = (0..n).collect();
            let mut at = 0;
            let mut order = Vec::with_capacity(n);
            while !left.is_empty() {
                let (k, _) = left
                    .iter()
                    .enumerate()
                    .fold((0, f64::INFINITY), |best, (k, &a)| {
                        if dist[at][a + 1] < best.1 {
                            (k, dist[at][a + 1])
                        } else {
                            best
                        }
                    });
                let a = left.remove(k);
                order.push(a);
                at = a + 1;
            }
            order
        };
        Ok(Itinerary {
            length: total(&order),
            order,
        })
    }

    /// The operative sequence of area `area` for a vehicle arriving at `arrival`, with the
    /// lines laid along `current` (see the module's documentation). This is also the replan
    /// when the current measured on arrival differs from the predicted one.
    pub fn survey(
        &self,
        area: &str,
        arrival: Position,
        current: Option<Current>,
    ) -> Result<Survey, PlanError> {
        let survey_area = self
            .mission
            .area(area)
            .ok_or_else(|| PlanError::UnknownArea(area.to_string()))?;
        let polygon = &survey_area.polygon;
        let spacing = self.mission.vehicle.line_spacing();
        let current = current.filter(|c| c.speed() >= CURRENT_THRESHOLD);
        let line_heading = match current {
            Some(c) => c.set_towards() % std::f64::consts::PI,
            None => narrowest_direction(polygon),
        };
        // Along-line (u) and across (w) axes; coordinates (s, t) = (p·u, p·w).
        let u = geom::heading_vector(line_heading);
        let w = geom::pos(u.y, -u.x);
        let dot = |a: Position, b: Position| a.x * b.x + a.y * b.y;
        let coords = &polygon.exterior().0;
        let (mut smin, mut smax, mut tmin, mut tmax) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &c in coords {
            smin = smin.min(dot(c, u));
            smax = smax.max(dot(c, u));
            tmin = tmin.min(dot(c, w));
            tmax = tmax.max(dot(c, w));
        }
        let width = tmax - tmin;
        let count = ((width / spacing) - 1e-9).ceil().max(1.0) as usize;
        let first = tmin + (width - (count - 1) as f64 * spacing) / 2.0;
        let to_world = |s: f64, t: f64| u * s + w * t;
        // Lines as (across t, start s, end s), each spanning its band of the area, the bands
        // `spacing` wide and the outer ones reaching past the area's sides.
        let mut rows: Vec<Vec<(f64, f64, f64)>> = Vec::new();
        for k in 0..count {
            let t = first + k as f64 * spacing;
            let t0 = if k == 0 {
                tmin - 1.0
            } else {
                t - spacing / 2.0
            };
            let t1 = if k + 1 == count {
                tmax + 1.0
            } else {
                t + spacing / 2.0
            };
            let band = Polygon::new(
                LineString::from(vec![
                    to_world(smin - 1.0, t0),
                    to_world(smax + 1.0, t0),
                    to_world(smax + 1.0, t1),
                    to_world(smin - 1.0, t1),
                ]),
                vec![],
            );
            let pieces = polygon.intersection(&band);
            let mut spans: Vec<(f64, f64)> = pieces
                .iter()
                .map(|piece| {
                    piece
                        .exterior()
                        .0
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &c| {
                            (lo.min(dot(c, u)), hi.max(dot(c, u)))
                        })
                })
                .filter(|(lo, hi)| lo.is_finite() && hi.is_finite())
                .collect();
            spans.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut merged: Vec<(f64, f64, f64)> = Vec::new();
            for (lo, hi) in spans {
                // A line shorter than a metre still needs a heading: give it one metre.
                let (lo, hi) = if hi - lo < 1.0 {
                    ((lo + hi) / 2.0 - 0.5, (lo + hi) / 2.0 + 0.5)
                } else {
                    (lo, hi)
                };
                match merged.last_mut() {
                    Some(last) if lo <= last.2 => last.2 = last.2.max(hi),
                    _ => merged.push((t, lo, hi)),
                }
            }
            if !merged.is_empty() {
                rows.push(merged);
            }
        }
        // Of the four ways to fly the rows (first or last row first, along or against the
        // line heading), the one starting nearest to the arrival.
        let mut best: Option<(f64, Vec<(Position, Position)>)> = None;
        for reverse_rows in [false, true] {
            for forward_first in [true, false] {
                let mut lines = Vec::new();
                let ordered: Vec<&Vec<(f64, f64, f64)>> = if reverse_rows {
                    rows.iter().rev().collect()
                } else {
                    rows.iter().collect()
                };
                for (r, row) in ordered.into_iter().enumerate() {
                    let forward = (r % 2 == 0) == forward_first;
                    let mut segs: Vec<(Position, Position)> = row
                        .iter()
                        .map(|&(t, lo, hi)| {
                            if forward {
                                (to_world(lo, t), to_world(hi, t))
                            } else {
                                (to_world(hi, t), to_world(lo, t))
                            }
                        })
                        .collect();
                    if !forward {
                        segs.reverse();
                    }
                    lines.extend(segs);
                }
                let d = lines
                    .first()
                    .map_or(f64::INFINITY, |l| geom::distance(arrival, l.0));
                if best.as_ref().is_none_or(|(bd, _)| d < *bd) {
                    best = Some((d, lines));
                }
            }
        }
        let lines = best.map(|(_, l)| l).unwrap_or_default();
        let depth = survey_area.depth;
        let speed = self.mission.vehicle.cruise_speed;
        let mut legs: Vec<Leg> = Vec::new();
        for (rank, &(a, b)) in lines.iter().enumerate() {
            let pieces = self.clear_pieces(a, b);
            for (p, q) in pieces {
                if let Some(prev) = legs.last().map(|l| l.to) {
                    legs.extend(self.route(
                        prev,
                        p,
                        LegKind::LineChange {
                            area: area.to_string(),
                        },
                        depth,
                    )?);
                }
                legs.push(Leg {
                    kind: LegKind::SurveyLine {
                        area: area.to_string(),
                        line: rank,
                    },
                    from: p,
                    to: q,
                    depth,
                    speed,
                });
            }
        }
        Ok(Survey {
            area: area.to_string(),
            line_heading,
            spacing,
            current,
            lines,
            trajectory: Trajectory { legs },
        })
    }

    /// The parts of the segment `a`-`b` outside every inflated zone, in order from `a`.
    fn clear_pieces(&self, a: Position, b: Position) -> Vec<(Position, Position)> {
        if self.segment_is_clear(a, b) {
            return vec![(a, b)];
        }
        let obstacles = MultiPolygon::new(self.obstacles.clone());
        let outside = obstacles.clip(
            &MultiLineString::new(vec![LineString::from(vec![a, b])]),
            true,
        );
        let along = |p: Position| (p - a).x * (b - a).x + (p - a).y * (b - a).y;
        let mut pieces: Vec<(Position, Position)> = outside
            .iter()
            .filter_map(|ls| {
                let (p, q) = (*ls.0.first()?, *ls.0.last()?);
                let (p, q) = if along(p) <= along(q) { (p, q) } else { (q, p) };
                (geom::distance(p, q) >= 1.0).then_some((p, q))
            })
            .collect();
        pieces.sort_by(|x, y| along(x.0).total_cmp(&along(y.0)));
        pieces
    }

    /// The whole mission: the itinerary, then for each area a transit to its survey's entry
    /// and the survey (with the area's predicted current), then the transit to the end area.
    pub fn plan_mission(&self) -> Result<MissionPlan, PlanError> {
        let itinerary = self.itinerary(self.mission.start)?;
        let transit = DepthTarget::Depth(self.mission.vehicle.transit_depth);
        let mut at = self.mission.start;
        let mut stages = Vec::new();
        let mut surveys = Vec::new();
        for &i in &itinerary.order {
            let area = &self.mission.areas[i];
            let survey = self.survey(&area.name, at, area.predicted_current)?;
            let entry = survey.entry().unwrap_or(at);
            stages.push(Stage {
                kind: StageKind::TransitToArea(area.name.clone()),
                trajectory: Trajectory {
                    legs: self.route(at, entry, LegKind::Transit, transit)?,
                },
            });
            at = survey.trajectory.end().unwrap_or(entry);
            stages.push(Stage {
                kind: StageKind::Survey(area.name.clone()),
                trajectory: survey.trajectory.clone(),
            });
            surveys.push(survey);
        }
        stages.push(Stage {
            kind: StageKind::TransitToEnd,
            trajectory: self.to_end_area(at)?,
        });
        Ok(MissionPlan {
            itinerary,
            stages,
            surveys,
        })
    }

    /// The alarm replan: straight to the end area from `from`, round the forbidden zones, at
    /// transit depth.
    pub fn to_end_area(&self, from: Position) -> Result<Trajectory, PlanError> {
        let depth = DepthTarget::Depth(self.mission.vehicle.transit_depth);
        Ok(Trajectory {
            legs: self.route(from, self.mission.end.target(), LegKind::Transit, depth)?,
        })
    }

    /// The inspection replan: from `from` (where the survey stopped) to a square of half-side
    /// `radius` around `object`, flown once round so the sonar sees the object from four sides,
    /// then back to `from`, at `depth`. Every piece goes round the forbidden zones.
    pub fn inspection(
        &self,
        from: Position,
        object: Position,
        radius: f64,
        depth: DepthTarget,
    ) -> Result<Trajectory, PlanError> {
        if !(radius.is_finite() && radius > 0.0) {
            return Err(PlanError::BadArgument(
                "the inspection radius must be a positive number of metres",
            ));
        }
        self.check_point(object)?;
        let corners = [
            object + geom::pos(-radius, -radius),
            object + geom::pos(-radius, radius),
            object + geom::pos(radius, radius),
            object + geom::pos(radius, -radius),
        ];
        // Enter the square at the corner nearest to where the vehicle is.
        let nearest = (0..4)
            .min_by(|&a, &b| {
                geom::distance(from, corners[a]).total_cmp(&geom::distance(from, corners[b]))
            })
            .unwrap_or(0);
        let mut legs = self.route(from, corners[nearest], LegKind::Inspection, depth)?;
        for k in 0..4 {
            let (a, b) = (corners[(nearest + k) % 4], corners[(nearest + k + 1) % 4]);
            legs.extend(self.route(a, b, LegKind::Inspection, depth)?);
        }
        legs.extend(self.route(corners[nearest], from, LegKind::Return, depth)?);
        Ok(Trajectory { legs })
    }
}

/// Calls `visit` with every permutation of `items[k..]` (the prefix fixed).
fn permutations(items: &mut Vec<usize>, k: usize, visit: &mut impl FnMut(&[usize])) {
    if k >= items.len() {
        visit(items);
        return;
    }
    for i in k..items.len() {
        items.swap(k, i);
        permutations(items, k + 1, visit);
        items.swap(k, i);
    }
}

/// The line heading (in `[0, π)`) across which `polygon` is narrowest: parallel to an edge of
/// its convex hull (rotating callipers), which gives the fewest survey lines.
pub fn narrowest_direction(polygon: &Polygon<f64>) -> f64 {
    let hull = polygon.convex_hull();
    let coords = &hull.exterior().0;
    let mut best = (f64::INFINITY, 0.0);
    for pair in coords.windows(2) {
        if pair[0] == pair[1] {
            continue;
        }
        let heading = geom::heading_between(pair[0], pair[1]);
        let u = geom::heading_vector(heading);
        let w = geom::pos(u.y, -u.x);
        let (lo, hi) = coords
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |acc, c| {
                let t = c.x * w.x + c.y * w.y;
                (acc.0.min(t), acc.1.max(t))
            });
        // Ties (a rectangle's two pairs of sides) go to the first found: deterministic.
        if hi - lo < best.0 - 1e-9 {
            best = (hi - lo, heading % std::f64::consts::PI);
        }
    }
    best.1
}
