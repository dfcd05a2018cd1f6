//! A simulated AUV on the bus: what `petrel bridge --bus memory` serves, so that a mission
//! flies on any Linux machine (the "Redermor simulator" of the paper's bench, section 3.1.4).
//!
//! [`AuvPlant`] is the vehicle, sans-I/O: it takes the frames on the bus (the supervisor's
//! `DepthCmd`, `ThrusterCmd` and `SupervisorHeartbeat`) and, every tick, gives the frames of its
//! sensors (`Depth`, `Ahrs`, `ThrusterStatus`, `Leak`, and `Battery` every second). The
//! thrusters run only while enabled, turning, and fed a heartbeat younger than 300 ms (the
//! vehicle's own safety); the vehicle then moves towards the commanded depth, up to 0.5 m per
//! 100 ms at 1,000 rpm (an accelerated dive); otherwise it rises slowly, being buoyant.
//! [`spawn`] runs a plant on a [`MemoryHub`] endpoint, on its own thread.
//!
//! Messages the DBC does not have are neither read nor sent: any project's DBC works, the
//! vehicle then just speaks less.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::bus::{Bus, MemoryHub};
use crate::clock::Clock;
use crate::dbc::{Dbc, DecodeOutcome};
use crate::frame::Frame;

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
        let value = |name: &str| {
            dm.signals
                .iter()
                .find(|s| {
                    m.signals
                        .get(s.signal.signal)
                        .is_some_and(|g| g.name == name)
                })
                .map(|s| s.physical)
        };
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

/// A simulated vehicle on a bus, sans-I/O: frames in, frames out, time given. The AUV of this
/// module is one; the Redermor simulator (crate `petrel-redermor-live`) is another, which
/// `petrel bridge --sim redermor` serves in its place.
pub trait Plant: Send {
    /// Takes a frame seen on the bus at `time_us` (the bus's clock).
    fn on_frame(&mut self, time_us: u64, frame: &Frame);

    /// Advances the vehicle to `time_us` and returns the frames its sensors send.
    fn step(&mut self, time_us: u64) -> Vec<Frame>;

    /// How often [`Plant::step`] is to be called.
    fn period(&self) -> Duration {
        Duration::from_millis(100)
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

/// Runs a simulated AUV on `hub`, ticking every 100 ms on the hub's clock, until `stop` is set
/// (or the process ends).
pub fn spawn(
    hub: &MemoryHub,
    dbc: Arc<Dbc>,
    faults: SimFaults,
    stop: Arc<AtomicBool>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    spawn_plant(hub, Box::new(AuvPlant::new(dbc, faults)), stop)
}

/// Runs `plant` on `hub`, stepping it every [`Plant::period`] on the hub's clock, until `stop`
/// is set (or the process ends).
pub fn spawn_plant(
    hub: &MemoryHub,
    mut plant: Box<dyn Plant>,
    stop: Arc<AtomicBool>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    let mut node = hub.endpoint("sim")?;
    let clock = hub.clock();
    Ok(std::thread::spawn(move || {
        run_plant(&mut node, plant.as_mut(), clock.as_ref(), &stop);
    }))
}

/// The host loop of a plant, whatever the bus: every [`Plant::period`], the frames received
/// since the last tick go into the plant (at their receive times), then the frames of its
/// step go out at `clock`'s time; until `stop` is set. The memory bus's thread
/// ([`spawn_plant`]) and a simulator process on a SocketCAN interface (`redermor-sim`) both run
/// it, so one plant behaves the same on both. `clock` must be the bus's receive clock (the
/// hub's, or [`crate::clock::SystemClock`] for SocketCAN's kernel timestamps).
pub fn run_plant(bus: &mut dyn Bus, plant: &mut dyn Plant, clock: &dyn Clock, stop: &AtomicBool) {
    let period = plant.period();
    while !stop.load(Ordering::Relaxed) {
        // A read error (an interface down) ends this tick's reading: the vehicle's sensors
        // go on, as a real one's would, and the data server sees what the bus lets through.
        while let Ok(Some(tf)) = bus.recv() {
            plant.on_frame(tf.time_us, &tf.frame);
        }
        // Frames still waiting from the last tick go first, in order.
        let _ = bus.flush();
        for frame in plant.step(clock.now_us()) {
            // A full bus only delays the next sample: the plant speaks again next tick.
            let _ = bus.send(&frame);
        }
        std::thread::sleep(period);
    }
}
