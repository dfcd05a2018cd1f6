//! The vehicle's sensors at their real rates, and the fault scenario of a simulated run.
//!
//! [`Sensors::sample`] gives every reading that fell due up to the time asked, each stamped with
//! its own due time (microseconds), so a caller stepping at 10 Hz still gets the AHRS's 20 Hz.
//! Readings carry the units of the bus (`auv.dbc`): metres, degrees, m/s, volts, amperes.
//! Noise, when asked for, comes from a seeded generator: a run is reproducible.
//!
//! A [`Scenario`] (TOML) gives the real current and the faults to inject, each at a time:
//!
//! ```toml
//! seed = 7                  # noise seed (optional)
//! noise = true              # sensor noise (optional, default true)
//! current = [0.2, 0.0]      # the real current, m/s east and north (optional)
//!
//! [[fault]]
//! at = 120.0                # seconds from the start
//! kind = "leak"             # leak | sensor_silent | thruster | bus_off | current
//!
//! [[fault]]
//! at = 60.0
//! kind = "sensor_silent"
//! sensor = "dvl"            # depth | ahrs | dvl | gps | altimeter | battery | leak | thrusters
//!
//! [[fault]]
//! at = 200.0
//! kind = "thruster"
//! thruster = "left"         # left | right
//! efficiency = 0.0          # fraction of thrust left (optional, default 0)
//!
//! [[fault]]
//! at = 300.0
//! kind = "current"
//! current = [0.0, -0.4]
//! ```

use std::fmt;

use serde::Deserialize;

use crate::geom::{self, Position};
use crate::mission::{Current, Seabed};
use crate::vehicle::{Faults, Thruster, VehicleState};

/// A sensor of the vehicle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Sensor {
    /// Pressure depth sensor, 10 Hz.
    Depth,
    /// Attitude and heading reference, 20 Hz.
    Ahrs,
    /// Doppler velocity log (bottom and water track), 5 Hz.
    Dvl,
    /// GPS, 1 Hz, only at the surface.
    Gps,
    /// Altimeter, 5 Hz.
    Altimeter,
    /// Battery monitor, 1 Hz.
    Battery,
    /// Leak detector, 2 Hz.
    Leak,
    /// Thruster status, 10 Hz.
    Thrusters,
}

impl Sensor {
    /// Every sensor.
    pub const ALL: [Sensor; 8] = [
        Sensor::Depth,
        Sensor::Ahrs,
        Sensor::Dvl,
        Sensor::Gps,
        Sensor::Altimeter,
        Sensor::Battery,
        Sensor::Leak,
        Sensor::Thrusters,
    ];

    /// Its period (µs).
    pub fn period_us(self) -> u64 {
        match self {
            Sensor::Depth => 100_000,
            Sensor::Ahrs => 50_000,
            Sensor::Dvl => 200_000,
            Sensor::Gps => 1_000_000,
            Sensor::Altimeter => 200_000,
            Sensor::Battery => 1_000_000,
            Sensor::Leak => 500_000,
            Sensor::Thrusters => 100_000,
        }
    }

    /// Its name in scenario files and events.
    pub fn name(self) -> &'static str {
        match self {
            Sensor::Depth => "depth",
            Sensor::Ahrs => "ahrs",
            Sensor::Dvl => "dvl",
            Sensor::Gps => "gps",
            Sensor::Altimeter => "altimeter",
            Sensor::Battery => "battery",
            Sensor::Leak => "leak",
            Sensor::Thrusters => "thrusters",
        }
    }

    /// The sensor of this name.
    pub fn from_name(name: &str) -> Option<Sensor> {
        Sensor::ALL.into_iter().find(|s| s.name() == name)
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// One reading, in the bus's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reading {
    /// Depth (m).
    Depth {
        /// Depth below the surface (m).
        depth: f64,
    },
    /// Attitude.
    Ahrs {
        /// Heading (degrees, `[0, 360)`).
        heading: f64,
        /// Pitch (degrees).
        pitch: f64,
        /// Roll (degrees).
        roll: f64,
        /// Yaw rate (degrees per second, clockwise positive).
        yaw_rate: f64,
    },
    /// Velocities in the vehicle's axes (m/s): forward and to starboard.
    Dvl {
        /// Forward speed over the ground (bottom track).
        forward: f64,
        /// Starboard speed over the ground (bottom track).
        starboard: f64,
        /// Forward speed through the water (water track).
        water_forward: f64,
        /// Starboard speed through the water (water track).
        water_starboard: f64,
    },
    /// A fix in the local frame (at the surface only).
    Gps {
        /// East (m).
        x: f64,
        /// North (m).
        y: f64,
    },
    /// Height above the seabed.
    Altimeter {
        /// Altitude (m).
        altitude: f64,
        /// Quality of the echo (%): 0 when the seabed is out of range.
        quality: f64,
    },
    /// Battery.
    Battery {
        /// Voltage (V).
        voltage: f64,
        /// Current (A, negative discharging, as the bus has it).
        current: f64,
        /// State (0 idle, 1 discharging, 3 fault, 4 empty).
        state: u8,
    },
    /// Leak detector.
    Leak {
        /// Water detected in the hull.
        leak: bool,
        /// The detector works.
        sensor_ok: bool,
    },
    /// Thruster status.
    Thrusters {
        /// Left rpm.
        rpm_left: f64,
        /// Right rpm.
        rpm_right: f64,
        /// A thruster reports a fault.
        fault: bool,
    },
}

impl Reading {
    /// The sensor that gives it.
    pub fn sensor(&self) -> Sensor {
        match self {
            Reading::Depth { .. } => Sensor::Depth,
            Reading::Ahrs { .. } => Sensor::Ahrs,
            Reading::Dvl { .. } => Sensor::Dvl,
            Reading::Gps { .. } => Sensor::Gps,
            Reading::Altimeter { .. } => Sensor::Altimeter,
            Reading::Battery { .. } => Sensor::Battery,
            Reading::Leak { .. } => Sensor::Leak,
            Reading::Thrusters { .. } => Sensor::Thrusters,
        }
    }
}

/// A timestamped reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// When it was taken (µs).
    pub time_us: u64,
    /// What was read.
    pub reading: Reading,
}

/// A small deterministic generator (splitmix64) for sensor noise: no dependency, and the same
/// seed gives the same run on every machine.
#[derive(Clone, Debug, PartialEq)]
pub struct Noise {
    state: u64,
    enabled: bool,
}

impl Noise {
    /// A generator from `seed`; `enabled = false` gives zeros.
    pub fn new(seed: u64, enabled: bool) -> Noise {
        Noise {
            state: seed,
            enabled,
        }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A uniform number in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A normal number of standard deviation `sigma` (Box-Muller), 0 when disabled.
    pub fn gauss(&mut self, sigma: f64) -> f64 {
        if !self.enabled || sigma == 0.0 {
            return 0.0;
        }
        let u1 = self.uniform().max(f64::MIN_POSITIVE);
        let u2 = self.uniform();
        sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Standard deviations of the sensors' noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseLevels {
    /// Depth (m).
    pub depth: f64,
    /// Heading (degrees).
    pub heading: f64,
    /// DVL velocities (m/s).
    pub velocity: f64,
    /// GPS position (m).
    pub gps: f64,
    /// Altitude (m).
    pub altitude: f64,
    /// Voltage (V).
    pub voltage: f64,
}

impl Default for NoiseLevels {
    fn default() -> Self {
        NoiseLevels {
            depth: 0.02,
            heading: 0.2,
            velocity: 0.01,
            gps: 2.0,
            altitude: 0.05,
            voltage: 0.01,
        }
    }
}

/// Below this depth (m) the GPS antenna is out of the water.
pub const GPS_MAX_DEPTH: f64 = 0.3;

/// Beyond this altitude (m) the altimeter finds no seabed.
pub const ALTIMETER_RANGE: f64 = 100.0;

/// The sensors: their schedules, silences, and noise.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensors {
    next_due_us: [u64; 8],
    silent: [bool; 8],
    noise: Noise,
    levels: NoiseLevels,
}

impl Sensors {
    /// Sensors whose first readings fall due at time 0, with noise from `noise`.
    pub fn new(noise: Noise, levels: NoiseLevels) -> Sensors {
        Sensors {
            next_due_us: [0; 8],
            silent: [false; 8],
            noise,
            levels,
        }
    }

    /// Silences a sensor (it gives no reading from now on) or brings it back.
    pub fn set_silent(&mut self, sensor: Sensor, silent: bool) {
        self.silent[sensor.index()] = silent;
    }

    /// Whether a sensor is silenced.
    pub fn is_silent(&self, sensor: Sensor) -> bool {
        self.silent[sensor.index()]
    }

    /// Appends to `out` every reading due up to `now_us`, from the vehicle's state `state`, its
    /// faults and the seabed, in time order.
    pub fn sample(
        &mut self,
        now_us: u64,
        state: &VehicleState,
        faults: &Faults,
        seabed: &Seabed,
        out: &mut Vec<Sample>,
    ) {
        let start = out.len();
        for sensor in Sensor::ALL {
            let i = sensor.index();
            while self.next_due_us[i] <= now_us {
                let time_us = self.next_due_us[i];
                self.next_due_us[i] += sensor.period_us();
                if self.silent[i] {
                    continue;
                }
                if let Some(reading) = self.read(sensor, state, faults, seabed) {
                    out.push(Sample { time_us, reading });
                }
            }
        }
        out[start..].sort_by_key(|s| s.time_us);
    }

    fn read(
        &mut self,
        sensor: Sensor,
        s: &VehicleState,
        faults: &Faults,
        seabed: &Seabed,
    ) -> Option<Reading> {
        let l = self.levels;
        let n = &mut self.noise;
        Some(match sensor {
            Sensor::Depth => Reading::Depth {
                depth: (s.depth + n.gauss(l.depth)).max(-0.5),
            },
            Sensor::Ahrs => Reading::Ahrs {
                heading: geom::wrap_2pi(s.heading + n.gauss(l.heading).to_radians()).to_degrees(),
                pitch: 0.0,
                roll: 0.0,
                yaw_rate: s.yaw_rate.to_degrees(),
            },
            Sensor::Dvl => {
                // Body axes: forward along the heading, starboard 90° clockwise from it.
                let fwd = geom::heading_vector(s.heading);
                let stb = geom::pos(fwd.y, -fwd.x);
                let ground = s.ground_velocity();
                let water = fwd * s.surge;
                let dot = |a: Position, b: Position| a.x * b.x + a.y * b.y;
                Reading::Dvl {
                    forward: dot(ground, fwd) + n.gauss(l.velocity),
                    starboard: dot(ground, stb) + n.gauss(l.velocity),
                    water_forward: dot(water, fwd) + n.gauss(l.velocity),
                    water_starboard: dot(water, stb) + n.gauss(l.velocity),
                }
            }
            Sensor::Gps => {
                if s.depth > GPS_MAX_DEPTH {
                    return None;
                }
                Reading::Gps {
                    x: s.position.x + n.gauss(l.gps),
                    y: s.position.y + n.gauss(l.gps),
                }
            }
            Sensor::Altimeter => {
                let altitude = seabed.depth_at(s.position) - s.depth;
                if altitude > ALTIMETER_RANGE {
                    Reading::Altimeter {
                        altitude: 0.0,
                        quality: 0.0,
                    }
                } else {
                    Reading::Altimeter {
                        altitude: (altitude + n.gauss(l.altitude)).max(0.0),
                        quality: 90.0,
                    }
                }
            }
            Sensor::Battery => Reading::Battery {
                voltage: s.voltage + n.gauss(l.voltage),
                current: -s.battery_current,
                state: if s.charge <= 0.0 {
                    4
                } else if s.battery_current > 0.0 {
                    1
                } else {
                    0
                },
            },
            Sensor::Leak => Reading::Leak {
                leak: faults.leak,
                sensor_ok: true,
            },
            Sensor::Thrusters => Reading::Thrusters {
                rpm_left: s.rpm[0],
                rpm_right: s.rpm[1],
                fault: faults.thruster_fault(Thruster::Left)
                    || faults.thruster_fault(Thruster::Right),
            },
        })
    }
}

/// A fault to inject.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// The hull starts leaking.
    Leak,
    /// A sensor falls silent.
    SensorSilent(Sensor),
    /// A thruster loses thrust, keeping `efficiency` of it.
    Thruster {
        /// Which.
        thruster: Thruster,
        /// Fraction of thrust left.
        efficiency: f64,
    },
    /// The CAN bus goes bus-off: no reading arrives, no command reaches the thrusters.
    BusOff,
    /// The current changes.
    Current(Current),
}

/// A fault at a time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduledFault {
    /// When (s from the start).
    pub at: f64,
    /// What.
    pub fault: Fault,
}

/// The conditions of a simulated run.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    /// Noise seed.
    pub seed: u64,
    /// Whether the sensors are noisy.
    pub noise: bool,
    /// The real current at the start.
    pub current: Current,
    /// The faults, in time order.
    pub faults: Vec<ScheduledFault>,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            seed: 1,
            noise: true,
            current: Current::default(),
            faults: Vec::new(),
        }
    }
}

/// A problem of a scenario file, naming its field.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenarioError {
    /// The field (`fault[2].sensor`), empty for a syntax error toml could not place.
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "{}", self.message)
        } else {
            write!(f, "{}: {}", self.field, self.message)
        }
    }
}

impl std::error::Error for ScenarioError {}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioFile {
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    noise: Option<bool>,
    #[serde(default)]
    current: Option<[f64; 2]>,
    #[serde(default)]
    fault: Vec<FaultFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FaultFile {
    at: f64,
    kind: String,
    sensor: Option<String>,
    thruster: Option<String>,
    efficiency: Option<f64>,
    current: Option<[f64; 2]>,
}

fn current_of(field: &str, c: [f64; 2]) -> Result<Current, ScenarioError> {
    if c.iter().all(|v| v.is_finite()) && c[0].hypot(c[1]) <= 3.0 {
        Ok(Current::new(c[0], c[1]))
    } else {
        Err(ScenarioError {
            field: field.to_string(),
            message: "a current is [east, north] in m/s, finite, at most 3 m/s".to_string(),
        })
    }
}

impl Scenario {
    /// Reads a scenario file's text (format in the module's documentation).
    pub fn from_toml(text: &str) -> Result<Scenario, ScenarioError> {
        let file: ScenarioFile = toml::from_str(text).map_err(|e| ScenarioError {
            field: String::new(),
            message: e.message().trim().to_string(),
        })?;
        let defaults = Scenario::default();
        let current = match file.current {
            Some(c) => current_of("current", c)?,
            None => defaults.current,
        };
        let mut faults = Vec::new();
        for (i, f) in file.fault.iter().enumerate() {
            let field = |name: &str| format!("fault[{i}].{name}");
            let err = |name: &str, message: String| ScenarioError {
                field: field(name),
                message,
            };
            if !(f.at.is_finite() && f.at >= 0.0) {
                return Err(err("at", format!("{} is not a time in seconds ≥ 0", f.at)));
            }
            let unexpected = |name: &str, given: bool| {
                if given {
                    Err(err(name, format!("a `{}` fault takes no `{name}`", f.kind)))
                } else {
                    Ok(())
                }
            };
            let fault = match f.kind.as_str() {
                "leak" | "bus_off" | "sensor_silent" | "thruster" | "current" => {
                    unexpected("sensor", f.sensor.is_some() && f.kind != "sensor_silent")?;
                    unexpected(
                        "thruster",
                        f.thruster.is_some() && f.kind != "thruster",
                    )?;
                    unexpected(
                        "efficiency",
                        f.efficiency.is_some() && f.kind != "thruster",
                    )?;
                    unexpected("current", f.current.is_some() && f.kind != "current")?;
                    match f.kind.as_str() {
                        "leak" => Fault::Leak,
                        "bus_off" => Fault::BusOff,
                        "sensor_silent" => {
                            let name = f.sensor.as_deref().ok_or_else(|| {
                                err("sensor", "a sensor_silent fault names its sensor".into())
                            })?;
                            let sensor = Sensor::from_name(name).ok_or_else(|| {
                                err(
                                    "sensor",
                                    format!(
                                        "unknown sensor \"{name}\", expected one of {}",
                                        Sensor::ALL.map(Sensor::name).join(", ")
                                    ),
                                )
                            })?;
                            Fault::SensorSilent(sensor)
                        }
                        "thruster" => {
                            let thruster = match f.thruster.as_deref() {
                                Some("left") => Thruster::Left,
                                Some("right") => Thruster::Right,
                                Some(other) => {
                                    return Err(err(
                                        "thruster",
                                        format!(
                                            "unknown thruster \"{other}\", expected left or right"
                                        ),
                                    ))
                                }
                                None => {
                                    return Err(err(
                                        "thruster",
                                        "a thruster fault names its thruster".into(),
                                    ))
                                }
                            };
                            let efficiency = f.efficiency.unwrap_or(0.0);
                            if !(0.0..=1.0).contains(&efficiency) {
                                return Err(err(
                                    "efficiency",
                                    format!("{efficiency} is not a fraction from 0 to 1"),
                                ));
                            }
                            Fault::Thruster {
                                thruster,
                                efficiency,
                            }
                        }
                        _ => {
                            let c = f.current.ok_or_else(|| {
                                err("current", "a current fault gives the new current".into())
                            })?;
                            Fault::Current(current_of(&field("current"), c)?)
                        }
                    }
                }
                other => {
                    return Err(err(
                        "kind",
                        format!(
                            "unknown fault \"{other}\", expected leak, sensor_silent, thruster, bus_off or current"
                        ),
                    ))
                }
            };
            faults.push(ScheduledFault { at: f.at, fault });
        }
        // Stable: faults at the same time keep the file's order.
        faults.sort_by(|a, b| a.at.total_cmp(&b.at));
        Ok(Scenario {
            seed: file.seed.unwrap_or(defaults.seed),
            noise: file.noise.unwrap_or(defaults.noise),
            current,
            faults,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::{Vehicle, VehicleConfig};

    #[test]
    fn rates_are_the_sensors_own() {
        let v = Vehicle::new(VehicleConfig::default(), geom::pos(0.0, 0.0), 0.0);
        let mut sensors = Sensors::new(Noise::new(1, false), NoiseLevels::default());
        let mut out = Vec::new();
        // Ten seconds stepped at 10 Hz: readings stamped at their own times.
        for k in 0..=100u64 {
            sensors.sample(
                k * 100_000,
                v.state(),
                v.faults(),
                &Seabed::default(),
                &mut out,
            );
        }
        let count = |s: Sensor| out.iter().filter(|r| r.reading.sensor() == s).count();
        assert_eq!(count(Sensor::Depth), 101);
        assert_eq!(count(Sensor::Ahrs), 201);
        assert_eq!(count(Sensor::Dvl), 51);
        assert_eq!(count(Sensor::Gps), 11, "at the surface");
        assert_eq!(count(Sensor::Altimeter), 51);
        assert_eq!(count(Sensor::Battery), 11);
        assert_eq!(count(Sensor::Leak), 21);
        let ahrs: Vec<u64> = out
            .iter()
            .filter(|r| r.reading.sensor() == Sensor::Ahrs)
            .map(|r| r.time_us)
            .take(3)
            .collect();
        assert_eq!(ahrs, vec![0, 50_000, 100_000]);
    }

    #[test]
    fn noise_is_deterministic() {
        let mut a = Noise::new(42, true);
        let mut b = Noise::new(42, true);
        let xs: Vec<f64> = (0..10).map(|_| a.gauss(1.0)).collect();
        let ys: Vec<f64> = (0..10).map(|_| b.gauss(1.0)).collect();
        assert_eq!(xs, ys);
        assert!(xs.iter().any(|&x| x != 0.0));
        assert_eq!(Noise::new(42, false).gauss(1.0), 0.0);
    }

    #[test]
    fn scenario_files() {
        let s = Scenario::from_toml(
            r#"
            seed = 3
            current = [0.1, -0.2]
            [[fault]]
            at = 50.0
            kind = "sensor_silent"
            sensor = "dvl"
            [[fault]]
            at = 10
            kind = "leak"
            [[fault]]
            at = 20.0
            kind = "thruster"
            thruster = "right"
            efficiency = 0.5
            [[fault]]
            at = 30.0
            kind = "bus_off"
            [[fault]]
            at = 40.0
            kind = "current"
            current = [0.0, 0.3]
            "#,
        )
        .unwrap();
        assert_eq!(s.seed, 3);
        assert_eq!(s.current, Current::new(0.1, -0.2));
        let kinds: Vec<Fault> = s.faults.iter().map(|f| f.fault).collect();
        assert_eq!(
            kinds,
            vec![
                Fault::Leak,
                Fault::Thruster {
                    thruster: Thruster::Right,
                    efficiency: 0.5
                },
                Fault::BusOff,
                Fault::Current(Current::new(0.0, 0.3)),
                Fault::SensorSilent(Sensor::Dvl),
            ]
        );
        let e =
            Scenario::from_toml("[[fault]]\nat = 1\nkind = \"sensor_silent\"\nsensor = \"sonar\"")
                .unwrap_err();
        assert_eq!(e.field, "fault[0].sensor");
        assert!(e.to_string().contains("unknown sensor \"sonar\""), "{e}");
        let e = Scenario::from_toml("[[fault]]\nat = 1\nkind = \"fire\"").unwrap_err();
        assert_eq!(e.field, "fault[0].kind");
        let e = Scenario::from_toml("[[fault]]\nat = -1\nkind = \"leak\"").unwrap_err();
        assert_eq!(e.field, "fault[0].at");
        let e = Scenario::from_toml("[[fault]]\nat = 1\nkind = \"leak\"\nsensor = \"dvl\"")
            .unwrap_err();
        assert_eq!(e.field, "fault[0].sensor");
        let e = Scenario::from_toml("[[fault]]\nat = 1\nkind = \"thruster\"").unwrap_err();
        assert_eq!(e.field, "fault[0].thruster");
        assert!(Scenario::from_toml("speed = 3").is_err());
    }
}
