//! Small helpers on the local frame: headings, angles and segment tests that the other modules
//! share. Geometry proper (containment, intersection, buffers, clipping) is `geo`'s.

use geo::{BoundingRect, Coord, Line, Polygon, Relate};

/// A position in the local frame: `x` east, `y` north, metres.
pub type Position = Coord<f64>;

/// Builds a [`Position`].
pub fn pos(x: f64, y: f64) -> Position {
    Coord { x, y }
}

/// The nautical heading (radians, 0 north, clockwise) from `from` towards `to`; 0 when they
/// are the same point.
pub fn heading_between(from: Position, to: Position) -> f64 {
    let d = to - from;
    if d.x == 0.0 && d.y == 0.0 {
        return 0.0;
    }
    wrap_2pi(d.x.atan2(d.y))
}

/// The unit vector (east, north) of a nautical heading.
pub fn heading_vector(heading: f64) -> Position {
    pos(heading.sin(), heading.cos())
}

/// An angle brought into `(-π, π]`: the signed turn between two headings.
pub fn wrap_pi(angle: f64) -> f64 {
    let a = angle.rem_euclid(std::f64::consts::TAU);
    if a > std::f64::consts::PI {
        a - std::f64::consts::TAU
    } else {
        a
    }
}

/// An angle brought into `[0, 2π)`: a heading.
pub fn wrap_2pi(angle: f64) -> f64 {
    let a = angle.rem_euclid(std::f64::consts::TAU);
    // rem_euclid of a tiny negative number can round to exactly 2π.
    if a >= std::f64::consts::TAU {
        0.0
    } else {
        a
    }
}

/// Euclidean distance between two positions.
pub fn distance(a: Position, b: Position) -> f64 {
    (b - a).x.hypot((b - a).y)
}

/// Whether the segment `a`-`b` enters the interior of `polygon`. Running along its boundary or
/// touching a vertex does not count: the planner's paths go from vertex to vertex of inflated
/// obstacles, along their edges.
pub fn segment_enters(polygon: &Polygon<f64>, a: Position, b: Position) -> bool {
    if let Some(r) = polygon.bounding_rect() {
        let (lo, hi) = (r.min(), r.max());
        if a.x.max(b.x) < lo.x || a.x.min(b.x) > hi.x || a.y.max(b.y) < lo.y || a.y.min(b.y) > hi.y
        {
            return false;
        }
    }
    if a == b {
        return geo::Contains::contains(polygon, &geo::Point(a));
    }
    // Interior of the polygon meets interior of the segment: DE-9IM "T********".
    polygon
        .relate(&Line::new(a, b))
        .matches("T********")
        .unwrap_or(true)
}

/// Whether `p` lies strictly inside `polygon` (its boundary is outside).
pub fn strictly_inside(polygon: &Polygon<f64>, p: Position) -> bool {
    geo::Contains::contains(polygon, &geo::Point(p))
}

/// Whether `p` lies inside `polygon` or on its boundary.
pub fn inside_or_on(polygon: &Polygon<f64>, p: Position) -> bool {
    geo::Intersects::intersects(polygon, &geo::Point(p))
}

/// The shortest distance from `p` to the segment `a`-`b`.
pub fn distance_to_segment(p: Position, a: Position, b: Position) -> f64 {
    let ab = b - a;
    let len2 = ab.x * ab.x + ab.y * ab.y;
    if len2 == 0.0 {
        return distance(p, a);
    }
    let t = (((p - a).x * ab.x + (p - a).y * ab.y) / len2).clamp(0.0, 1.0);
    distance(p, a + ab * t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo::polygon;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn headings_are_nautical() {
        let o = pos(0.0, 0.0);
        assert!((heading_between(o, pos(0.0, 1.0)) - 0.0).abs() < 1e-12);
        assert!((heading_between(o, pos(1.0, 0.0)) - FRAC_PI_2).abs() < 1e-12);
        assert!((heading_between(o, pos(0.0, -1.0)) - PI).abs() < 1e-12);
        assert!((heading_between(o, pos(-1.0, 0.0)) - 3.0 * FRAC_PI_2).abs() < 1e-12);
        let v = heading_vector(FRAC_PI_2);
        assert!((v.x - 1.0).abs() < 1e-12 && v.y.abs() < 1e-12);
    }

    #[test]
    fn wraps() {
        assert!((wrap_pi(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_pi(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert!((wrap_2pi(-FRAC_PI_2) - 3.0 * FRAC_PI_2).abs() < 1e-12);
        assert_eq!(wrap_2pi(-1e-300), 0.0);
    }

    #[test]
    fn segments_along_edges_do_not_enter() {
        let sq =
            polygon![(x: 0.0, y: 0.0), (x: 10.0, y: 0.0), (x: 10.0, y: 10.0), (x: 0.0, y: 10.0)];
        assert!(!segment_enters(&sq, pos(0.0, 10.0), pos(10.0, 10.0)));
        assert!(!segment_enters(&sq, pos(-5.0, 10.0), pos(15.0, 10.0)));
        assert!(segment_enters(&sq, pos(-1.0, 5.0), pos(11.0, 5.0)));
        assert!(segment_enters(&sq, pos(0.0, 0.0), pos(10.0, 10.0)));
        assert!(!segment_enters(&sq, pos(20.0, 0.0), pos(20.0, 10.0)));
        assert!(
            (distance_to_segment(pos(5.0, 3.0), pos(0.0, 0.0), pos(10.0, 0.0)) - 3.0).abs() < 1e-12
        );
    }
}
