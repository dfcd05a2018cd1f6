//! The simulated AUV on the bus: what `auv-bridge --bus memory` serves, so that the mission of
//! missions/auv flies on any Linux machine.
//!
//! [`AuvPlant`] is the vehicle, sans-I/O: it takes the frames on the bus (the supervisor's
//! `DepthCmd`, `ThrusterCmd` and `SupervisorHeartbeat`) and, every tick, gives the frames of its
//! sensors (`Depth`, `Ahrs`, `ThrusterStatus`, `Leak`, and `Battery` every second). The
//! thrusters run only while enabled, turning, and fed a heartbeat younger than 300 ms (the
//! vehicle's own safety); the vehicle then moves towards the commanded depth, up to 0.5 m per
//! 100 ms at 1,000 rpm (an accelerated dive); otherwise it rises slowly, being buoyant.
//! [`factory`] makes one for the data server's memory bus ([`petrel_can_bridge::plant`] hosts it).
//!
//! Messages the DBC does not have are neither read nor sent: any project's DBC works, the
//! vehicle then just speaks less.

use std::sync::Arc;

use petrel_can_bridge::dbc::{Dbc, DecodeOutcome};
use petrel_can_bridge::frame::Frame;
use petrel_can_bridge::plant::{Plant, PlantFactory};

/// How long the thrusters run on without a supervisor heartbeat.
pub const HEARTBEAT_TIMEOUT_US: u64 = 300_000;

/// Faults to inject into the simulation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimFaults {
    /// The hull leaks once the vehicle is this deep (metres): the leak detector's bit is set
    /// from then on.
    pub leak_at_depth: Option<f64>,
}

/// The simulated vehicle's state.
#[derive(Clone, Debug, PartialEq)]
pub struct AuvPlant {
    dbc: Arc<Dbc>,
    faults: SimFaults,
    last_step_us: Option<u64>,
    ticks: u64,
    /// Depth in metres (0 at the surface).
    pub depth: f64,
    /// The commanded depth.
    pub target: f64,
    /// Commanded thruster speeds (rpm) and enable.
    pub rpm: (f64, f64),
    /// Whether the thrusters are enabled.
    pub enabled: bool,
    /// When the last supervisor heartbeat arrived.
    pub last_heartbeat_us: Option<u64>,
    /// Battery voltage.
    pub voltage: f64,
    /// Whether the leak detector is set.
    pub leak: bool,
}

impl AuvPlant {
    /// A vehicle at the surface, thrusters off, battery at 25 V.
    pub fn new(dbc: Arc<Dbc>, faults: SimFaults) -> Self {
        AuvPlant {
            dbc,
            faults,
            last_step_us: None,
            ticks: 0,
            depth: 0.0,
            target: 0.0,
            rpm: (0.0, 0.0),
            enabled: false,
            last_heartbeat_us: None,
            voltage: 25.0,
            leak: false,
        }
    }

    /// Takes a frame seen on the bus at `time_us`.
    pub fn on_frame(&mut self, time_us: u64, frame: &Frame) {
        let DecodeOutcome::Message(dm) = self.dbc.decode(frame) else {
            return;
        };
        let Some(m) = self.dbc.message(dm.message) else {
            return;
        };
        let value = |name: &str| dm.value(&self.dbc, name);
        match m.name.as_str() {
            "DepthCmd" => self.target = value("target").unwrap_or(self.target),
            "ThrusterCmd" => {
                self.rpm = (
                    value("rpm_left").unwrap_or(self.rpm.0),
                    value("rpm_right").unwrap_or(self.rpm.1),
                );
                self.enabled = value("enable").is_some_and(|e| e != 0.0);
            }
            "SupervisorHeartbeat" => self.last_heartbeat_us = Some(time_us),
            _ => {}
        }
    }

    /// Whether the thrusters turn at `time_us`.
    pub fn thrusting(&self, time_us: u64) -> bool {
        let fed = self
            .last_heartbeat_us
            .is_some_and(|t| time_us.saturating_sub(t) <= HEARTBEAT_TIMEOUT_US);
        self.enabled && fed && (self.rpm.0.abs() + self.rpm.1.abs()) > 0.0
    }

    /// Advances the vehicle to `time_us` and returns its sensors' frames.
    pub fn step(&mut self, time_us: u64) -> Vec<Frame> {
        let dt = time_us.saturating_sub(self.last_step_us.unwrap_or(time_us)) as f64 / 1e6;
        self.last_step_us = Some(time_us);
        let thrusting = self.thrusting(time_us);
        if thrusting {
            let power = ((self.rpm.0.abs() + self.rpm.1.abs()) / 2000.0).min(1.5);
            let step = 5.0 * power * dt;
            let gap = self.target - self.depth;
            self.depth += gap.clamp(-step, step);
            self.voltage -= 0.02 * power * dt;
        } else {
            self.depth = (self.depth - 0.5 * dt).max(0.0);
        }
        if self.faults.leak_at_depth.is_some_and(|d| self.depth >= d) {
            self.leak = true;
        }
        let shown = |rpm: f64| if thrusting { rpm } else { 0.0 };
        let mut frames = Vec::new();
        // A message the DBC lacks does not encode: the vehicle just says less.
        let mut send = |message: &str, values: &[(&str, f64)]| {
            if let Ok(f) = self.dbc.encode(message, values) {
                frames.push(f);
            }
        };
        send(
            "Depth",
            &[
                ("depth", (self.depth * 100.0).round() / 100.0),
                ("status", 0.0),
            ],
        );
        send("Ahrs", &[("heading", 90.0), ("pitch", 0.0), ("roll", 0.0)]);
        send(
            "ThrusterStatus",
            &[
                ("rpm_left", shown(self.rpm.0)),
                ("rpm_right", shown(self.rpm.1)),
                ("temperature", 20.0),
                ("fault", 0.0),
            ],
        );
        send(
            "Leak",
            &[("leak", f64::from(u8::from(self.leak))), ("sensor_ok", 1.0)],
        );
        if self.ticks.is_multiple_of(10) {
            let state = if thrusting { 1.0 } else { 0.0 };
            send(
                "Battery",
                &[
                    ("voltage", (self.voltage * 100.0).round() / 100.0),
                    ("current", if thrusting { -12.5 } else { -0.5 }),
                    ("state", state),
                ],
            );
        }
        self.ticks += 1;
        frames
    }
}

impl Plant for AuvPlant {
    fn on_frame(&mut self, time_us: u64, frame: &Frame) {
        AuvPlant::on_frame(self, time_us, frame);
    }

    fn step(&mut self, time_us: u64) -> Vec<Frame> {
        AuvPlant::step(self, time_us)
    }
}

/// Makes the AUV, with `faults`, for the data server's memory bus, speaking the project's DBC.
pub fn factory(faults: SimFaults) -> PlantFactory {
    Box::new(move |dbc| Ok(Box::new(AuvPlant::new(dbc, faults)) as Box<dyn Plant>))
}
