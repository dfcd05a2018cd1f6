//! IDC, the pilot: turns guidance's setpoint (heading, speed, depth or altitude) and the
//! estimated state into thruster and depth commands.
//!
//! - Heading: PID on the heading error (wrapped to ±180°), the yaw rate as derivative; gives
//!   the thrusters' rpm difference.
//! - Speed: feed-forward (rpm proportional to speed, as the hull's drag makes it) plus PI on
//!   the speed through the water; gives their mean rpm. Heading has priority: the mean gives
//!   way so that neither thruster passes its limit.
//! - Depth: the vehicle's own depth loop is proportional and its hull buoyant, so it settles a
//!   little shallow; a PI on the depth error trims the commanded depth. In altitude mode the
//!   target depth is the seabed's (depth + altitude) less the altitude wanted, never closer to
//!   the seabed than the minimum altitude.
//!
//! Each PID saturates its output and stops integrating while saturated in the direction of the
//! error (anti-windup by conditional integration).

use crate::gdd::NavState;
use crate::geom;
use crate::guidance::Setpoint;
use crate::mission::DepthTarget;
use crate::vehicle::Commands;

/// A PID controller with output limits and conditional-integration anti-windup.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pid {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain.
    pub ki: f64,
    /// Derivative gain.
    pub kd: f64,
    /// Lowest output.
    pub min: f64,
    /// Highest output.
    pub max: f64,
    integral: f64,
}

impl Pid {
    /// A controller with these gains and output limits.
    pub fn new(kp: f64, ki: f64, kd: f64, min: f64, max: f64) -> Pid {
        Pid {
            kp,
            ki,
            kd,
            min,
            max,
            integral: 0.0,
        }
    }

    /// The output for `error`, its `derivative` (given, so that a measured rate can serve),
    /// after `dt` seconds. Non-finite inputs count as zero.
    pub fn update(&mut self, error: f64, derivative: f64, dt: f64) -> f64 {
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        let (error, derivative, dt) = (finite(error), finite(derivative), finite(dt).max(0.0));
        let candidate = self.integral + error * dt;
        let unclamped = self.kp * error + self.ki * candidate + self.kd * derivative;
        // Integrate only while that does not push further into saturation.
        let winding_up =
            (unclamped > self.max && error > 0.0) || (unclamped < self.min && error < 0.0);
        if !winding_up {
            self.integral = candidate;
        }
        let output = self.kp * error + self.ki * self.integral + self.kd * derivative;
        output.clamp(self.min, self.max)
    }

    /// The integral accumulated.
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// Forgets the integral.
    pub fn reset(&mut self) {
        self.integral = 0.0;
    }
}

/// Pilot tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PilotConfig {
    /// Heading PID (rpm difference per radian; derivative on the yaw rate).
    pub heading: Pid,
    /// Speed PI around the feed-forward (rpm per m/s).
    pub speed: Pid,
    /// Depth trim PI (metres of command per metre of error).
    pub depth_trim: Pid,
    /// Feed-forward: rpm per m/s of speed.
    pub rpm_per_speed: f64,
    /// Thruster limit (rpm).
    pub max_rpm: f64,
    /// Deepest depth commanded (m).
    pub max_depth: f64,
    /// Closest to the seabed commanded (m).
    pub min_altitude: f64,
}

impl Default for PilotConfig {
    fn default() -> Self {
        PilotConfig {
            heading: Pid::new(900.0, 20.0, 2500.0, -700.0, 700.0),
            speed: Pid::new(300.0, 40.0, 0.0, -600.0, 600.0),
            depth_trim: Pid::new(0.3, 0.02, 0.0, -3.0, 3.0),
            rpm_per_speed: 1000.0 / 1.5,
            max_rpm: 3000.0,
            max_depth: 300.0,
            min_altitude: 2.0,
        }
    }
}

/// The pilot.
#[derive(Clone, Debug, PartialEq)]
pub struct Pilot {
    config: PilotConfig,
    heading: Pid,
    speed: Pid,
    depth_trim: Pid,
    /// The last depth target, held while the altimeter has no echo.
    target_depth: Option<f64>,
}

impl Pilot {
    /// A pilot with this tuning.
    pub fn new(config: PilotConfig) -> Pilot {
        Pilot {
            config,
            heading: config.heading,
            speed: config.speed,
            depth_trim: config.depth_trim,
            target_depth: None,
        }
    }

    /// The depth aimed at for `target` given the state (altitude turned into depth).
    pub fn target_depth(&mut self, target: DepthTarget, nav: &NavState) -> f64 {
        let depth = match target {
            DepthTarget::Depth(d) => d,
            DepthTarget::Altitude(h) => match nav.altitude {
                Some(altitude) => {
                    let seabed = nav.depth + altitude;
                    (seabed - h.max(self.config.min_altitude)).max(0.0)
                }
                // No echo: hold the last target, or the present depth.
                None => self.target_depth.unwrap_or(nav.depth),
            },
        };
        let depth = depth.clamp(0.0, self.config.max_depth);
        self.target_depth = Some(depth);
        depth
    }

    /// The commands for `setpoint` after `dt` seconds; `None` stops the thrusters and commands
    /// the surface.
    pub fn update(&mut self, dt: f64, setpoint: Option<&Setpoint>, nav: &NavState) -> Commands {
        let Some(sp) = setpoint else {
            self.heading.reset();
            self.speed.reset();
            self.depth_trim.reset();
            return Commands {
                rpm_left: 0.0,
                rpm_right: 0.0,
                depth: 0.0,
                enable: false,
            };
        };
        let c = &self.config;
        let error = geom::wrap_pi(sp.heading - nav.heading);
        let diff = self.heading.update(error, -nav.yaw_rate, dt);
        let mean =
            c.rpm_per_speed * sp.speed + self.speed.update(sp.speed - nav.water_speed, 0.0, dt);
        let room = (c.max_rpm - diff.abs()).max(0.0);
        let mean = mean.clamp(-room, room);

        let target = self.target_depth(sp.depth, nav);
        let trim = self.depth_trim.update(target - nav.depth, 0.0, dt);
        let mut depth = (target + trim).clamp(0.0, self.config.max_depth);
        if let Some(altitude) = nav.altitude {
            // Never command into the seabed, whatever the trim says.
            let floor = (nav.depth + altitude - self.config.min_altitude).max(0.0);
            depth = depth.min(floor);
        }
        Commands {
            rpm_left: mean + diff,
            rpm_right: mean - diff,
            depth,
            enable: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gdd::Gdd;

    #[test]
    fn pid_saturates_and_does_not_wind_up() {
        let mut pid = Pid::new(1.0, 1.0, 0.0, -2.0, 2.0);
        for _ in 0..100 {
            assert_eq!(pid.update(10.0, 0.0, 0.1), 2.0);
        }
        // The integral stopped growing once saturated: the output comes off the limit as
        // soon as the error changes sign.
        assert!(pid.integral() < 1.0, "{}", pid.integral());
        assert!(pid.update(-1.5, 0.0, 0.1) < 0.0);
        assert!(pid.update(f64::NAN, f64::INFINITY, 0.1).is_finite());
    }

    #[test]
    fn turns_towards_the_heading_within_limits() {
        let mut pilot = Pilot::new(PilotConfig::default());
        let nav = *Gdd::new(geom::pos(0.0, 0.0), 0).state();
        let sp = Setpoint {
            heading: 1.0,
            speed: 1.5,
            depth: DepthTarget::Depth(10.0),
        };
        let c = pilot.update(0.1, Some(&sp), &nav);
        assert!(c.rpm_left > c.rpm_right, "starboard turn: left faster");
        assert!(c.rpm_left <= 3000.0 && c.rpm_right >= -3000.0);
        assert!(c.depth > 10.0, "trim deepens while shallow: {}", c.depth);
        assert!(c.enable);
        let stop = pilot.update(0.1, None, &nav);
        assert!(!stop.enable && stop.depth == 0.0);
    }

    #[test]
    fn altitude_becomes_depth_above_the_seabed() {
        let mut pilot = Pilot::new(PilotConfig::default());
        let mut nav = *Gdd::new(geom::pos(0.0, 0.0), 0).state();
        nav.depth = 10.0;
        nav.altitude = Some(30.0);
        assert_eq!(pilot.target_depth(DepthTarget::Altitude(8.0), &nav), 32.0);
        nav.altitude = None;
        assert_eq!(pilot.target_depth(DepthTarget::Altitude(8.0), &nav), 32.0);
        nav.altitude = Some(1.0);
        assert_eq!(pilot.target_depth(DepthTarget::Altitude(0.5), &nav), 9.0);
    }
}
