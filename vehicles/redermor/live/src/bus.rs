//! Redermor's bus (missions/redermor/redermor.dbc): the sensors' readings as message signals
//! and back, and the simulator's clock (the message `BenchTime`, named after the paper's test
//! bench).
//!
//! Every reading goes out as one message whose signals carry its fields under the same names
//! (`Depth.depth`, `Ahrs.heading`...); `BenchTime.time_ms` is the simulated time, which the
//! programs stamp the readings with: the simulator may run faster than the wall clock, the
//! programs then see the vehicle's time, not theirs.

use redermor::sensors::{Reading, Sample};

/// The message of the simulator's clock, and its signal (milliseconds of simulated time).
pub const TIME_SIGNAL: &str = "BenchTime.time_ms";

/// The message of the bench's ground truth: the simulated vehicle's true position (`x`, `y`,
/// m) and `depth`, sent with every tick for the monitor's map (missions/redermor/map.toml);
/// no program reads it.
pub const TRUTH_MESSAGE: &str = "BenchTruth";

/// The message name and signals of a reading, in the DBC's units.
pub fn encode(reading: &Reading) -> (&'static str, Vec<(&'static str, f64)>) {
    let b = |v: bool| f64::from(u8::from(v));
    match *reading {
        Reading::Depth { depth } => ("Depth", vec![("depth", depth)]),
        Reading::Ahrs {
            heading,
            pitch,
            roll,
            yaw_rate,
        } => (
            "Ahrs",
            vec![
                ("heading", heading.rem_euclid(360.0).min(359.99)),
                ("pitch", pitch),
                ("roll", roll),
                ("yaw_rate", yaw_rate),
            ],
        ),
        Reading::Dvl {
            forward,
            starboard,
            water_forward,
            water_starboard,
        } => (
            "Dvl",
            vec![
                ("forward", forward),
                ("starboard", starboard),
                ("water_forward", water_forward),
                ("water_starboard", water_starboard),
            ],
        ),
        Reading::Gps { x, y } => ("Gps", vec![("x", x), ("y", y)]),
        Reading::Altimeter { altitude, quality } => (
            "Altimeter",
            vec![("altitude", altitude), ("quality", quality)],
        ),
        Reading::Battery {
            voltage,
            current,
            state,
        } => (
            "Battery",
            vec![
                ("voltage", voltage),
                ("current", current),
                ("state", f64::from(state)),
            ],
        ),
        Reading::Leak { leak, sensor_ok } => {
            ("Leak", vec![("leak", b(leak)), ("sensor_ok", b(sensor_ok))])
        }
        Reading::Thrusters {
            rpm_left,
            rpm_right,
            fault,
        } => (
            "ThrusterStatus",
            vec![
                ("rpm_left", rpm_left),
                ("rpm_right", rpm_right),
                ("fault", b(fault)),
            ],
        ),
    }
}

/// The messages that carry readings.
pub const READING_MESSAGES: [&str; 8] = [
    "Depth",
    "Ahrs",
    "Dvl",
    "Gps",
    "Altimeter",
    "Battery",
    "Leak",
    "ThrusterStatus",
];

/// The reading of message `message` from its signals' latest values (`get("depth")`), if
/// every signal it needs is there.
pub fn decode(message: &str, get: impl Fn(&str) -> Option<f64>) -> Option<Reading> {
    Some(match message {
        "Depth" => Reading::Depth {
            depth: get("depth")?,
        },
        "Ahrs" => Reading::Ahrs {
            heading: get("heading")?,
            pitch: get("pitch").unwrap_or(0.0),
            roll: get("roll").unwrap_or(0.0),
            yaw_rate: get("yaw_rate").unwrap_or(0.0),
        },
        "Dvl" => Reading::Dvl {
            forward: get("forward")?,
            starboard: get("starboard")?,
            water_forward: get("water_forward")?,
            water_starboard: get("water_starboard")?,
        },
        "Gps" => Reading::Gps {
            x: get("x")?,
            y: get("y")?,
        },
        "Altimeter" => Reading::Altimeter {
            altitude: get("altitude")?,
            quality: get("quality").unwrap_or(100.0),
        },
        "Battery" => Reading::Battery {
            voltage: get("voltage")?,
            current: get("current").unwrap_or(0.0),
            state: get("state").unwrap_or(0.0) as u8,
        },
        "Leak" => Reading::Leak {
            leak: get("leak")? != 0.0,
            sensor_ok: get("sensor_ok").is_none_or(|v| v != 0.0),
        },
        "ThrusterStatus" => Reading::Thrusters {
            rpm_left: get("rpm_left")?,
            rpm_right: get("rpm_right")?,
            fault: get("fault").is_some_and(|v| v != 0.0),
        },
        _ => return None,
    })
}

/// The readings new since the last call, from a table of latest values
/// `(MESSAGE.signal, value, received at)`, stamped with the simulator's time.
#[derive(Debug, Default)]
pub struct ReadingTracker {
    /// For each message of [`READING_MESSAGES`], when its newest value was received.
    seen: [u64; 8],
    /// The simulator's time (µs), from [`TIME_SIGNAL`].
    time_us: u64,
}

impl ReadingTracker {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// The simulator's time (µs) last seen.
    pub fn time_us(&self) -> u64 {
        self.time_us
    }

    /// Takes the table; returns the readings received since the last call.
    pub fn update(&mut self, values: &[(String, f64, u64)]) -> Vec<Sample> {
        if let Some((_, t, _)) = values.iter().find(|(p, _, _)| p == TIME_SIGNAL) {
            self.time_us = self.time_us.max((*t * 1000.0) as u64);
        }
        let mut out = Vec::new();
        for (i, message) in READING_MESSAGES.iter().enumerate() {
            let prefix_len = message.len() + 1;
            let mine = |p: &str| {
                p.len() > prefix_len
                    && p.starts_with(message)
                    && &p[message.len()..prefix_len] == "."
            };
            let newest = values
                .iter()
                .filter(|(p, _, _)| mine(p))
                .map(|(_, _, t)| *t)
                .max();
            let Some(newest) = newest.filter(|&t| t > self.seen[i]) else {
                continue;
            };
            self.seen[i] = newest;
            let get = |name: &str| {
                values
                    .iter()
                    .find(|(p, _, _)| mine(p) && &p[prefix_len..] == name)
                    .map(|(_, v, _)| *v)
            };
            if let Some(reading) = decode(message, get) {
                out.push(Sample {
                    time_us: self.time_us,
                    reading,
                });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readings_go_out_and_come_back() {
        let readings = [
            Reading::Depth { depth: 4.25 },
            Reading::Gps { x: -12.5, y: 300.0 },
            Reading::Leak {
                leak: true,
                sensor_ok: true,
            },
        ];
        let mut values = vec![(TIME_SIGNAL.to_string(), 1500.0, 10)];
        for r in &readings {
            let (m, signals) = encode(r);
            for (s, v) in signals {
                values.push((format!("{m}.{s}"), v, 10));
            }
        }
        let mut tracker = ReadingTracker::new();
        let got = tracker.update(&values);
        assert_eq!(got.len(), 3);
        assert!(got.iter().all(|s| s.time_us == 1_500_000));
        for r in &readings {
            assert!(got.iter().any(|s| s.reading == *r), "{r:?} in {got:?}");
        }
        // Nothing new: nothing again.
        assert!(tracker.update(&values).is_empty());
    }
}
