//! EVT, the event listener: operator requests, payload detections and what the dynamic data
//! show (water in the hull, a flat battery, a thruster fault, a current other than predicted)
//! become the mission's events, the disruptive events of the paper's section 3.1.3.
//!
//! Each alarm is raised once; detections below a confidence are dropped, and a detection near
//! an object already reported is the same object (one inspection per object, not one per
//! sonar ping).

use std::fmt;

use crate::gdd::NavState;
use crate::geom::{self, Position};
use crate::mission::Current;
use crate::sensors::Sensor;

/// What the operator may ask.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OperatorRequest {
    /// Abandon the mission and go to the end area.
    ReturnToEnd,
    /// Inspect a point, then resume.
    Inspect {
        /// The point.
        at: Position,
    },
}

impl OperatorRequest {
    /// Reads a request as an operator types it: `return`, or `inspect X Y` (metres).
    pub fn parse(text: &str) -> Result<OperatorRequest, String> {
        let words: Vec<&str> = text.split_whitespace().collect();
        match words.as_slice() {
            ["return"] => Ok(OperatorRequest::ReturnToEnd),
            ["inspect", x, y] => {
                let number = |w: &str| {
                    w.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| format!("\"{w}\" is not a coordinate in metres"))
                };
                Ok(OperatorRequest::Inspect {
                    at: geom::pos(number(x)?, number(y)?),
                })
            }
            _ => Err(format!(
                "unknown request \"{}\": expected `return` or `inspect X Y`",
                text.trim()
            )),
        }
    }
}

/// A payload's detection (the sonar's computer-aided detection).
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// When (µs).
    pub time_us: u64,
    /// Where the object is.
    pub position: Position,
    /// How sure the classifier is, from 0 to 1.
    pub confidence: f64,
}

/// Why the mission is to be abandoned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlarmReason {
    /// The operator asked.
    Operator,
    /// Water in the hull.
    Leak,
    /// The battery is below its threshold.
    LowBattery,
    /// A thruster reports a fault.
    ThrusterFault,
    /// A sensor fell silent.
    SensorLost(Sensor),
}

/// Where an inspection request comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// The operator.
    Operator,
    /// A payload detection.
    Payload,
}

/// An event for the mission's nets.
#[derive(Clone, Debug, PartialEq)]
pub enum MissionEvent {
    /// Go to the end area now.
    Alarm(AlarmReason),
    /// Inspect a point, then resume.
    Inspect {
        /// The point.
        at: Position,
        /// Who asked.
        origin: Origin,
    },
    /// The current measured on arrival at an area is not the predicted one: re-plan its
    /// survey.
    CurrentDiffers {
        /// The area.
        area: String,
        /// The prediction (still water if none).
        predicted: Current,
        /// The measurement.
        measured: Current,
    },
}

impl MissionEvent {
    /// The event's name for the nets.
    pub fn name(&self) -> &'static str {
        match self {
            MissionEvent::Alarm(_) => "alarm",
            MissionEvent::Inspect { .. } => "inspect",
            MissionEvent::CurrentDiffers { .. } => "current_differs",
        }
    }
}

impl fmt::Display for MissionEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MissionEvent::Alarm(reason) => write!(f, "alarm ({reason:?})"),
            MissionEvent::Inspect { at, origin } => {
                write!(f, "inspect ({:.0}, {:.0}) for {origin:?}", at.x, at.y)
            }
            MissionEvent::CurrentDiffers {
                area,
                predicted,
                measured,
            } => write!(
                f,
                "current in {area}: ({:.2}, {:.2}) m/s, predicted ({:.2}, {:.2})",
                measured.east, measured.north, predicted.east, predicted.north
            ),
        }
    }
}

/// The listener's thresholds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvtConfig {
    /// Detections below this confidence are dropped.
    pub min_confidence: f64,
    /// Detections within this distance of a known object are that object (m).
    pub merge_radius: f64,
    /// A measured current this far (m/s, vector difference) from the prediction differs.
    pub current_tolerance: f64,
    /// The battery voltage below which the battery is low (V).
    pub low_battery: f64,
}

impl Default for EvtConfig {
    fn default() -> Self {
        EvtConfig {
            min_confidence: 0.7,
            merge_radius: 30.0,
            current_tolerance: 0.15,
            low_battery: 22.0,
        }
    }
}

/// The event listener.
#[derive(Clone, Debug, PartialEq)]
pub struct EventListener {
    config: EvtConfig,
    objects: Vec<Position>,
    raised: Vec<AlarmReason>,
}

impl EventListener {
    /// A listener with these thresholds.
    pub fn new(config: EvtConfig) -> EventListener {
        EventListener {
            config,
            objects: Vec::new(),
            raised: Vec::new(),
        }
    }

    fn alarm(&mut self, reason: AlarmReason) -> Option<MissionEvent> {
        if self.raised.contains(&reason) {
            return None;
        }
        self.raised.push(reason);
        Some(MissionEvent::Alarm(reason))
    }

    /// The event of an operator's request.
    pub fn operator(&mut self, request: OperatorRequest) -> Option<MissionEvent> {
        match request {
            OperatorRequest::ReturnToEnd => self.alarm(AlarmReason::Operator),
            OperatorRequest::Inspect { at } => Some(MissionEvent::Inspect {
                at,
                origin: Origin::Operator,
            }),
        }
    }

    /// The event of a payload detection: an inspection of a new, confident enough object.
    pub fn detection(&mut self, detection: &Detection) -> Option<MissionEvent> {
        // A NaN confidence is no confidence.
        let confident = detection.confidence >= self.config.min_confidence;
        let placed = detection.position.x.is_finite() && detection.position.y.is_finite();
        if !(confident && placed) {
            return None;
        }
        if self
            .objects
            .iter()
            .any(|&o| geom::distance(o, detection.position) <= self.config.merge_radius)
        {
            return None;
        }
        self.objects.push(detection.position);
        Some(MissionEvent::Inspect {
            at: detection.position,
            origin: Origin::Payload,
        })
    }

    /// On arrival at `area`: whether the measured current differs from the predicted one.
    pub fn arrival(
        &self,
        area: &str,
        predicted: Option<Current>,
        measured: Current,
    ) -> Option<MissionEvent> {
        let predicted = predicted.unwrap_or_default();
        let gap = Current::new(
            measured.east - predicted.east,
            measured.north - predicted.north,
        );
        (gap.speed() > self.config.current_tolerance).then(|| MissionEvent::CurrentDiffers {
            area: area.to_string(),
            predicted,
            measured,
        })
    }

    /// The alarms the state shows (each once): a leak, a low battery, a thruster fault, and the
    /// sensors in `lost` that have fallen silent.
    pub fn watch(&mut self, nav: &NavState, lost: &[Sensor]) -> Vec<MissionEvent> {
        let mut events = Vec::new();
        if nav.leak {
            events.extend(self.alarm(AlarmReason::Leak));
        }
        if nav.voltage > 0.0 && nav.voltage < self.config.low_battery {
            events.extend(self.alarm(AlarmReason::LowBattery));
        }
        if nav.thruster_fault {
            events.extend(self.alarm(AlarmReason::ThrusterFault));
        }
        for &sensor in lost {
            events.extend(self.alarm(AlarmReason::SensorLost(sensor)));
        }
        events
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gdd::Gdd;

    #[test]
    fn requests_and_detections() {
        assert_eq!(
            OperatorRequest::parse(" inspect 10 -20.5 "),
            Ok(OperatorRequest::Inspect {
                at: geom::pos(10.0, -20.5)
            })
        );
        assert_eq!(
            OperatorRequest::parse("return"),
            Ok(OperatorRequest::ReturnToEnd)
        );
        assert!(OperatorRequest::parse("inspect x 3").is_err());
        assert!(OperatorRequest::parse("dance").is_err());

        let mut l = EventListener::new(EvtConfig::default());
        let d = |x: f64, confidence: f64| Detection {
            time_us: 0,
            position: geom::pos(x, 0.0),
            confidence,
        };
        assert!(l.detection(&d(0.0, 0.5)).is_none(), "not confident");
        assert!(l.detection(&d(0.0, f64::NAN)).is_none());
        assert!(matches!(
            l.detection(&d(0.0, 0.9)),
            Some(MissionEvent::Inspect {
                origin: Origin::Payload,
                ..
            })
        ));
        assert!(l.detection(&d(10.0, 0.9)).is_none(), "same object");
        assert!(l.detection(&d(100.0, 0.9)).is_some(), "another object");
    }

    #[test]
    fn alarms_once_and_currents() {
        let mut l = EventListener::new(EvtConfig::default());
        let mut nav = *Gdd::new(geom::pos(0.0, 0.0), 0).state();
        assert!(l.watch(&nav, &[]).is_empty());
        nav.leak = true;
        assert_eq!(
            l.watch(&nav, &[Sensor::Dvl]),
            vec![
                MissionEvent::Alarm(AlarmReason::Leak),
                MissionEvent::Alarm(AlarmReason::SensorLost(Sensor::Dvl))
            ]
        );
        assert!(l.watch(&nav, &[Sensor::Dvl]).is_empty());
        assert!(l
            .arrival("a", Some(Current::new(0.3, 0.0)), Current::new(0.32, 0.0))
            .is_none());
        let e = l.arrival("a", None, Current::new(0.0, 0.4)).unwrap();
        assert_eq!(e.name(), "current_differs");
    }
}
