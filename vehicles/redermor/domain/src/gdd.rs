//! GDD, the dynamic data manager: the vehicle's state as the programs know it, built from
//! sensor readings only (never from the simulator's truth).
//!
//! Position is dead reckoned: the DVL's bottom-track velocity, turned into the local frame by
//! the AHRS heading, integrated between readings; a GPS fix (at the surface) resets it. The
//! water current is the difference of bottom track (over the ground) and water track (through
//! the water), smoothed. Each sensor's last reading time is kept so that silence shows.

use crate::geom::{self, Position};
use crate::mission::Current;
use crate::sensors::{Reading, Sample, Sensor};

/// Weight of a new DVL reading in the smoothed current (per reading, 5 Hz).
const CURRENT_SMOOTHING: f64 = 0.05;

/// The vehicle's state as estimated from its sensors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NavState {
    /// Time of the estimate (µs).
    pub time_us: u64,
    /// Dead-reckoned position.
    pub position: Position,
    /// Depth (m).
    pub depth: f64,
    /// Nautical heading (radians).
    pub heading: f64,
    /// Yaw rate (rad/s, clockwise positive).
    pub yaw_rate: f64,
    /// Forward speed over the ground (m/s).
    pub speed: f64,
    /// Forward speed through the water (m/s).
    pub water_speed: f64,
    /// Velocity over the ground in the local frame (m/s).
    pub ground_velocity: Position,
    /// The water current measured (m/s).
    pub current: Current,
    /// Altitude above the seabed, when the altimeter has an echo (m).
    pub altitude: Option<f64>,
    /// Battery voltage (V).
    pub voltage: f64,
    /// Water in the hull.
    pub leak: bool,
    /// A thruster reports a fault.
    pub thruster_fault: bool,
}

/// The dynamic data manager.
#[derive(Clone, Debug, PartialEq)]
pub struct Gdd {
    state: NavState,
    last_seen_us: [Option<u64>; 8],
    /// Time up to which the position has been integrated.
    integrated_us: u64,
    current_known: bool,
    /// The DVL's last starboard speed over the ground (m/s), the velocity's other half.
    starboard: f64,
}

impl Gdd {
    /// A manager that knows the vehicle starts at `position`, at rest, at time `time_us`.
    pub fn new(position: Position, time_us: u64) -> Gdd {
        Gdd {
            state: NavState {
                time_us,
                position,
                depth: 0.0,
                heading: 0.0,
                yaw_rate: 0.0,
                speed: 0.0,
                water_speed: 0.0,
                ground_velocity: geom::pos(0.0, 0.0),
                current: Current::default(),
                altitude: None,
                voltage: 0.0,
                leak: false,
                thruster_fault: false,
            },
            last_seen_us: [None; 8],
            integrated_us: time_us,
            current_known: false,
            starboard: 0.0,
        }
    }

    /// Dead-reckons the position up to `now_us` with the last known ground velocity.
    pub fn advance(&mut self, now_us: u64) {
        if now_us > self.integrated_us {
            let dt = (now_us - self.integrated_us) as f64 / 1e6;
            self.state.position = self.state.position + self.state.ground_velocity * dt;
            self.integrated_us = now_us;
        }
        self.state.time_us = self.state.time_us.max(now_us);
    }

    /// Takes one reading. Readings older than the last integration still update the values
    /// they carry; the position is not integrated backwards.
    pub fn on_sample(&mut self, sample: &Sample) {
        self.advance(sample.time_us);
        self.last_seen_us[sample.reading.sensor() as usize] = Some(sample.time_us);
        let starboard = self.starboard;
        let s = &mut self.state;
        match sample.reading {
            Reading::Depth { depth } => s.depth = depth.max(0.0),
            Reading::Ahrs {
                heading, yaw_rate, ..
            } => {
                s.heading = geom::wrap_2pi(heading.to_radians());
                s.yaw_rate = yaw_rate.to_radians();
                // The last velocity turns with the vehicle until the DVL speaks again.
                s.ground_velocity = body_to_frame(s.heading, s.speed, starboard);
            }
            Reading::Dvl {
                forward,
                starboard,
                water_forward,
                water_starboard,
            } => {
                s.speed = forward;
                s.water_speed = water_forward;
                s.ground_velocity = body_to_frame(s.heading, forward, starboard);
                let water = body_to_frame(s.heading, water_forward, water_starboard);
                let measured = s.ground_velocity - water;
                let k = if self.current_known {
                    CURRENT_SMOOTHING
                } else {
                    1.0
                };
                s.current = Current::new(
                    s.current.east + k * (measured.x - s.current.east),
                    s.current.north + k * (measured.y - s.current.north),
                );
                self.current_known = true;
                self.starboard = starboard;
            }
            Reading::Gps { x, y } => s.position = geom::pos(x, y),
            Reading::Altimeter { altitude, quality } => {
                s.altitude = (quality > 0.0).then_some(altitude)
            }
            Reading::Battery { voltage, .. } => s.voltage = voltage,
            Reading::Leak { leak, .. } => s.leak = leak,
            Reading::Thrusters { fault, .. } => s.thruster_fault = fault,
        }
    }

    /// The state, dead-reckoned to the last reading or [`Gdd::advance`].
    pub fn state(&self) -> &NavState {
        &self.state
    }

    /// When `sensor` last gave a reading, if ever.
    pub fn last_seen(&self, sensor: Sensor) -> Option<u64> {
        self.last_seen_us[sensor as usize]
    }

    /// Whether `sensor` has been silent for longer than `timeout_us` at `now_us` (or never
    /// spoke since `since_us`, the start of the watch).
    pub fn is_stale(&self, sensor: Sensor, now_us: u64, since_us: u64, timeout_us: u64) -> bool {
        let last = self.last_seen(sensor).unwrap_or(since_us).max(since_us);
        now_us.saturating_sub(last) > timeout_us
    }

    /// Whether a current has been measured yet.
    pub fn current_known(&self) -> bool {
        self.current_known
    }
}

/// A velocity in the vehicle's axes (forward, starboard) in the local frame.
fn body_to_frame(heading: f64, forward: f64, starboard: f64) -> Position {
    let fwd = geom::heading_vector(heading);
    let stb = geom::pos(fwd.y, -fwd.x);
    fwd * forward + stb * starboard
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(time_us: u64, reading: Reading) -> Sample {
        Sample { time_us, reading }
    }

    #[test]
    fn dead_reckons_and_measures_the_current() {
        let mut g = Gdd::new(geom::pos(0.0, 0.0), 0);
        g.on_sample(&sample(
            0,
            Reading::Ahrs {
                heading: 90.0,
                pitch: 0.0,
                roll: 0.0,
                yaw_rate: 0.0,
            },
        ));
        // Heading east at 1.5 m/s through the water, the current 0.5 m/s north: the ground
        // track has 0.5 m/s to port.
        g.on_sample(&sample(
            0,
            Reading::Dvl {
                forward: 1.5,
                starboard: -0.5,
                water_forward: 1.5,
                water_starboard: 0.0,
            },
        ));
        g.advance(10_000_000);
        let s = g.state();
        assert!((s.position.x - 15.0).abs() < 1e-9, "{:?}", s.position);
        assert!((s.position.y - 5.0).abs() < 1e-9, "{:?}", s.position);
        assert!((s.current.north - 0.5).abs() < 1e-9 && s.current.east.abs() < 1e-9);
        g.on_sample(&sample(10_000_000, Reading::Gps { x: 100.0, y: 50.0 }));
        assert_eq!(g.state().position, geom::pos(100.0, 50.0));
        assert!(g.is_stale(Sensor::Depth, 10_000_000, 0, 300_000));
        assert!(!g.is_stale(Sensor::Gps, 10_100_000, 0, 300_000));
    }
}
