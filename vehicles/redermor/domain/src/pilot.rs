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
//! - Braking ([`Pilot::brake`]): thrust against the speed through the water in proportion to
//!   it, so that it fades as the vehicle slows; no integral, so nothing winds up. A command
//!   held over a long control step (a slow computer) then cannot drive the vehicle far the
//!   other way, as a fixed astern order does once it has passed zero.
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
    /// Braking: rpm against the motion per square root of the speed through the water
    /// (rpm per √(m/s)). The thrust, as the square of the rpm, is then proportional to the
    /// speed: the speed decays exponentially (at about 0.22/s for Redermor) and the command
    /// fades with it.
    pub brake_rpm: f64,
    /// The most rpm braking uses: the thrusters' power goes as the cube of their rpm, and a
    /// hard brake from cruise speed would pull the battery's voltage under its alarm level.
    pub brake_max_rpm: f64,
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
            // 2 × 1.5e-4 N/rpm² × 1500² rpm² per m/s over 3000 kg: 0.225/s. A command held
            // up to 4 s does not reverse the vehicle (1/0.225 = 4.4 s), and it stops from half
            // the cruise speed within about 3 m.
            brake_rpm: 1500.0,
            // 2 × 150 W × 1.2³ ≈ 520 W, about 21 A: a volt under the battery's no-load voltage
            // (uncapped, braking from 1.5 m/s took 1840 rpm and the voltage to 21.5 V, under
            // the data server's battery_low level of 22 V).
            brake_max_rpm: 1200.0,
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

        let depth = self.depth_command(dt, sp.depth, nav);
        Commands {
            rpm_left: mean + diff,
            rpm_right: mean - diff,
            depth,
            enable: true,
        }
    }

    /// The commands that brake the vehicle to a stop after `dt` seconds, holding `heading` and
    /// `depth`: both thrusters against the speed through the water, at
    /// [`PilotConfig::brake_rpm`] times the square root of its magnitude (less what the
    /// heading needs), and none once it is zero.
    pub fn brake(&mut self, dt: f64, heading: f64, depth: DepthTarget, nav: &NavState) -> Commands {
        let c = self.config;
        let error = geom::wrap_pi(heading - nav.heading);
        let diff = self.heading.update(error, -nav.yaw_rate, dt);
        // The speed loop's integral belongs to the speed it held: braking does without it,
        // and whatever comes after starts afresh.
        self.speed.reset();
        let speed = if nav.water_speed.is_finite() {
            nav.water_speed
        } else {
            0.0
        };
        let mean = -speed.signum() * (c.brake_rpm * speed.abs().sqrt()).min(c.brake_max_rpm);
        let room = (c.max_rpm - diff.abs()).max(0.0);
        let mean = mean.clamp(-room, room);
        let depth = self.depth_command(dt, depth, nav);
        Commands {
            rpm_left: mean + diff,
            rpm_right: mean - diff,
            depth,
            enable: true,
        }
    }

    /// The depth to command for `target` after `dt` seconds: the target trimmed by its PI,
    /// never into the seabed.
    fn depth_command(&mut self, dt: f64, target: DepthTarget, nav: &NavState) -> f64 {
        let target = self.target_depth(target, nav);
        let trim = self.depth_trim.update(target - nav.depth, 0.0, dt);
        let mut depth = (target + trim).clamp(0.0, self.config.max_depth);
        if let Some(altitude) = nav.altitude {
            // Never command into the seabed, whatever the trim says.
            let floor = (nav.depth + altitude - self.config.min_altitude).max(0.0);
            depth = depth.min(floor);
        }
        depth
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
    fn the_brake_opposes_the_motion_and_fades_with_it() {
        let mut pilot = Pilot::new(PilotConfig::default());
        let mut nav = *Gdd::new(geom::pos(0.0, 0.0), 0).state();
        let depth = DepthTarget::Depth(0.0);
        let mean = |c: Commands| (c.rpm_left + c.rpm_right) / 2.0;
        nav.water_speed = 0.5;
        let ahead = mean(pilot.brake(0.1, 0.0, depth, &nav));
        assert!(ahead < 0.0, "astern while going ahead: {ahead}");
        nav.water_speed = 0.05;
        let slow = mean(pilot.brake(0.1, 0.0, depth, &nav));
        assert!(
            slow < 0.0 && slow > ahead,
            "weaker as it slows: {slow} against {ahead}"
        );
        nav.water_speed = 0.0;
        assert_eq!(
            mean(pilot.brake(0.1, 0.0, depth, &nav)),
            0.0,
            "nothing once stopped"
        );
        nav.water_speed = -0.5;
        assert!(
            mean(pilot.brake(0.1, 0.0, depth, &nav)) > 0.0,
            "ahead while going astern"
        );
        nav.water_speed = 3.0;
        let hard = mean(pilot.brake(0.1, 0.0, depth, &nav));
        assert_eq!(hard, -PilotConfig::default().brake_max_rpm, "capped");
        assert!(pilot.brake(0.1, 0.0, depth, &nav).enable);
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
