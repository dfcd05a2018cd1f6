//! Helpers the integration tests share: the example missions and geometric checks made with
//! geo directly, independently of the planner's own tests.
#![allow(dead_code)]

use geo::{Contains, Distance, Euclidean, Intersects, Line, Point, Polygon};
use redermor::geom::Position;
use redermor::mission::Mission;

pub const TWO_AREAS: &str = include_str!("../../missions/two_areas.toml");
pub const ISLAND_PASSAGE: &str = include_str!("../../missions/island_passage.toml");

pub fn mission(text: &str) -> Mission {
    match Mission::from_toml(text) {
        Ok(m) => m,
        Err(e) => panic!("example mission does not load:\n{e}"),
    }
}

pub fn missions() -> Vec<Mission> {
    vec![mission(TWO_AREAS), mission(ISLAND_PASSAGE)]
}

/// The smallest distance from segment `a`-`b` to any forbidden zone (0 if it touches one).
pub fn clearance(mission: &Mission, a: Position, b: Position) -> f64 {
    let line = Line::new(a, b);
    mission
        .forbidden
        .iter()
        .map(|z| {
            if line.intersects(&z.polygon) {
                0.0
            } else {
                Euclidean.distance(&line, &z.polygon)
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// Points of a grid `step` metres apart that lie inside `polygon`.
pub fn grid_inside(polygon: &Polygon<f64>, step: f64) -> Vec<Position> {
    use geo::BoundingRect;
    let Some(r) = polygon.bounding_rect() else {
        return Vec::new();
    };
    let mut points = Vec::new();
    let mut x = r.min().x + step / 2.0;
    while x < r.max().x {
        let mut y = r.min().y + step / 2.0;
        while y < r.max().y {
            let p = Position { x, y };
            if polygon.contains(&Point(p)) {
                points.push(p);
            }
            y += step;
        }
        x += step;
    }
    points
}

/// Distance from `p` to segment `a`-`b`, with geo.
pub fn to_segment(p: Position, a: Position, b: Position) -> f64 {
    Euclidean.distance(p, &Line::new(a, b))
}
