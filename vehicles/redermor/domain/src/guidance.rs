//! GUI, the guidance program: follows a trajectory's legs one after the other, says when each
//! is done and when the course changes, and gives the pilot its heading, speed and depth.
//!
//! Line of sight: the vehicle aims at the point `lookahead` metres further along the leg than
//! its own projection on it, which brings it back onto the line smoothly. That aim gives the
//! course to make good over the ground; the heading is that course corrected by the crab angle
//! the measured current asks for, so a cross current does not push the vehicle off the line.
//! A leg is done within the arrival radius of its end, or once past its end (a vehicle pushed
//! wide does not circle back for the waypoint).

use crate::geom::{self, Position};
use crate::mission::{Current, DepthTarget};
use crate::plan::{CourseChange, Leg, Trajectory};

/// Guidance tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuidanceConfig {
    /// Line-of-sight distance ahead along the leg (m).
    pub lookahead: f64,
    /// Distance to a leg's end at which it is done (m).
    pub arrival_radius: f64,
    /// Most of the speed through the water the crab angle may use against a cross current.
    pub max_crab_ratio: f64,
}

impl Default for GuidanceConfig {
    fn default() -> Self {
        GuidanceConfig {
            lookahead: 20.0,
            arrival_radius: 8.0,
            max_crab_ratio: 0.8,
        }
    }
}

/// What the pilot is to hold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// Nautical heading (radians).
    pub heading: f64,
    /// Speed through the water (m/s).
    pub speed: f64,
    /// Depth or altitude.
    pub depth: DepthTarget,
}

/// What happened during an update.
#[derive(Clone, Debug, PartialEq)]
pub enum GuidanceEvent {
    /// Leg `leg` is done.
    LegDone {
        /// Its index.
        leg: usize,
    },
    /// The course changes onto the next leg.
    CourseChange(CourseChange),
    /// The last leg is done: the trajectory's end is reached.
    Arrived,
}

/// The guidance of one trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Guidance {
    trajectory: Trajectory,
    leg: usize,
    config: GuidanceConfig,
    arrived_reported: bool,
}

impl Guidance {
    /// Guidance along `trajectory` from its first leg.
    pub fn new(trajectory: Trajectory, config: GuidanceConfig) -> Guidance {
        Guidance {
            trajectory,
            leg: 0,
            config,
            arrived_reported: false,
        }
    }

    /// The trajectory followed.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// The index of the leg followed (the number of legs once done).
    pub fn leg_index(&self) -> usize {
        self.leg
    }

    /// The leg followed, if not done.
    pub fn current_leg(&self) -> Option<&Leg> {
        self.trajectory.legs.get(self.leg)
    }

    /// Whether every leg is done.
    pub fn is_done(&self) -> bool {
        self.leg >= self.trajectory.legs.len()
    }

    /// Signed distance from the current leg's line (m, positive to starboard of the leg).
    pub fn cross_track_error(&self, position: Position) -> Option<f64> {
        let leg = self.current_leg()?;
        let t = geom::heading_vector(leg.heading());
        let stb = geom::pos(t.y, -t.x);
        let d = position - leg.from;
        Some(d.x * stb.x + d.y * stb.y)
    }

    /// Takes the estimated position and current; passes the legs that are done and gives the
    /// setpoint for the one followed (`None` once arrived), with what happened.
    pub fn update(
        &mut self,
        position: Position,
        current: Current,
    ) -> (Option<Setpoint>, Vec<GuidanceEvent>) {
        let mut events = Vec::new();
        while let Some(leg) = self.trajectory.legs.get(self.leg) {
            if !self.leg_done(leg, position) {
                break;
            }
            events.push(GuidanceEvent::LegDone { leg: self.leg });
            if let Some(next) = self.trajectory.legs.get(self.leg + 1) {
                events.push(GuidanceEvent::CourseChange(CourseChange {
                    at: leg.to,
                    leg: self.leg + 1,
                    from_heading: leg.heading(),
                    to_heading: next.heading(),
                }));
            }
            self.leg += 1;
        }
        let Some(leg) = self.trajectory.legs.get(self.leg) else {
            if !self.arrived_reported {
                self.arrived_reported = true;
                events.push(GuidanceEvent::Arrived);
            }
            return (None, events);
        };
        let course = self.line_of_sight(leg, position);
        let heading = self.crab(course, leg.speed, current);
        (
            Some(Setpoint {
                heading,
                speed: leg.speed,
                depth: leg.depth,
            }),
            events,
        )
    }

    fn leg_done(&self, leg: &Leg, position: Position) -> bool {
        let length = leg.length();
        if geom::distance(position, leg.to) <= self.config.arrival_radius || length == 0.0 {
            return true;
        }
        let t = (leg.to - leg.from) / length;
        let d = position - leg.from;
        d.x * t.x + d.y * t.y >= length
    }

    /// The course to make good: towards the point `lookahead` ahead of the vehicle's
    /// projection on the leg, or the leg's end when that is nearer.
    fn line_of_sight(&self, leg: &Leg, position: Position) -> f64 {
        let length = leg.length();
        let t = (leg.to - leg.from) / length;
        let d = position - leg.from;
        let along = d.x * t.x + d.y * t.y;
        let aim = if along + self.config.lookahead >= length {
            leg.to
        } else {
            leg.from + t * (along.max(0.0) + self.config.lookahead)
        };
        geom::heading_between(position, aim)
    }

    /// The heading that makes good `course` at `speed` through the water in `current`.
    fn crab(&self, course: f64, speed: f64, current: Current) -> f64 {
        if speed <= 0.0 {
            return course;
        }
        let h = geom::heading_vector(course);
        let starboard = geom::pos(h.y, -h.x);
        let cross = current.east * starboard.x + current.north * starboard.y;
        let ratio = (cross / speed).clamp(-self.config.max_crab_ratio, self.config.max_crab_ratio);
        geom::wrap_2pi(course - ratio.asin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::LegKind;
    use std::f64::consts::FRAC_PI_2;

    fn leg(from: Position, to: Position) -> Leg {
        Leg {
            kind: LegKind::Transit,
            from,
            to,
            depth: DepthTarget::Depth(5.0),
            speed: 1.5,
        }
    }

    #[test]
    fn steers_back_to_the_line_and_passes_legs() {
        let t = Trajectory {
            legs: vec![
                leg(geom::pos(0.0, 0.0), geom::pos(0.0, 100.0)),
                leg(geom::pos(0.0, 100.0), geom::pos(100.0, 100.0)),
            ],
        };
        let mut g = Guidance::new(t, GuidanceConfig::default());
        // East of the northward line: steer left of north (towards the line).
        let (sp, ev) = g.update(geom::pos(10.0, 20.0), Current::default());
        assert!(ev.is_empty());
        let h = geom::wrap_pi(sp.unwrap().heading);
        assert!(h < 0.0 && h > -FRAC_PI_2, "{h}");
        assert!((g.cross_track_error(geom::pos(10.0, 20.0)).unwrap() - 10.0).abs() < 1e-9);
        // Past the end: the leg is done, course change of +90°.
        let (sp, ev) = g.update(geom::pos(1.0, 101.0), Current::default());
        assert_eq!(ev[0], GuidanceEvent::LegDone { leg: 0 });
        match &ev[1] {
            GuidanceEvent::CourseChange(c) => assert!((c.turn() - FRAC_PI_2).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        assert!(sp.is_some());
        let (sp, ev) = g.update(geom::pos(95.0, 100.0), Current::default());
        assert!(sp.is_none() && g.is_done());
        assert_eq!(ev.last(), Some(&GuidanceEvent::Arrived));
        let (_, ev) = g.update(geom::pos(95.0, 100.0), Current::default());
        assert!(ev.is_empty(), "arrival is reported once");
    }

    #[test]
    fn crabs_into_a_cross_current() {
        let t = Trajectory {
            legs: vec![leg(geom::pos(0.0, 0.0), geom::pos(0.0, 1000.0))],
        };
        let mut g = Guidance::new(t, GuidanceConfig::default());
        // Current setting east: head a little west of north.
        let (sp, _) = g.update(geom::pos(0.0, 10.0), Current::new(0.5, 0.0));
        let h = geom::wrap_pi(sp.unwrap().heading);
        assert!((h + (0.5f64 / 1.5).asin()).abs() < 1e-9, "{h}");
    }
}
