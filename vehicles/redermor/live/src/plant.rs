//! The Redermor simulator on the bus: [`RedermorPlant`] runs [`Simulator`] (the vehicle, its
//! sensors at their rates, the scenario's faults) under the supervisor's frames, and sends its
//! readings as the messages of Redermor's bus.
//!
//! The vehicle waits at the surface, its time at 0 and its sensors repeating their first
//! readings, until the supervisor first enables the thrusters (the mission's start): the
//! scenario's times count from then. The simulated time then runs `speed` times faster than
//! the bus's clock, in steps of 100 ms, so a
//! mission of an hour flies in minutes; the readings of one wall-clock tick are sent once each
//! (the newest of every sensor), with the simulator's time. The thrusters obey the last
//! `ThrusterCmd` and `DepthCmd` while the supervisor's heartbeat is fresh on the bus's clock
//! (300 ms); without it they stop, as the vehicle's engine nodes do.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use petrel_can_bridge::dbc::{Dbc, DecodeOutcome};
use petrel_can_bridge::frame::Frame;
use petrel_can_bridge::plant::Plant;
use redermor::mission::Mission;
use redermor::sensors::{Fault, Sample, Scenario};
use redermor::sim::Simulator;
use redermor::vehicle::{Commands, VehicleConfig};

use crate::bus;

/// How long the thrusters run on after the last heartbeat (µs of the bus's clock).
pub const HEARTBEAT_TIMEOUT_US: u64 = 300_000;

/// The simulation's step (µs of simulated time).
pub const STEP_US: u64 = 100_000;

/// Most simulated steps taken in one tick: a stalled thread catches up over several ticks.
const MAX_STEPS_PER_TICK: u64 = 200;

/// The Redermor simulator as a plant of the memory bus.
pub struct RedermorPlant {
    dbc: Arc<Dbc>,
    sim: Simulator,
    speed: f64,
    start_us: Option<u64>,
    commands: Commands,
    last_heartbeat_us: Option<u64>,
    samples: Vec<Sample>,
    /// A bus-off happened: the vehicle falls silent (the data server's own bus is not
    /// touched: it is the server's).
    silent: bool,
    trace: Option<Box<dyn std::io::Write + Send>>,
    next_trace_us: u64,
    /// What the sensors say before the start.
    idle_frames: Vec<Frame>,
}

/// The header of the trace [`RedermorPlant::with_trace`] writes: one line a second of the
/// vehicle's time, its true state.
pub const TRACE_HEADER: &str = "time_s,x,y,depth,heading_deg,rpm_left,rpm_right";

impl std::fmt::Debug for RedermorPlant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RedermorPlant")
            .field("time_us", &self.sim.time_us())
            .field("speed", &self.speed)
            .finish_non_exhaustive()
    }
}

impl RedermorPlant {
    /// The vehicle at `mission`'s start under `scenario`, its time running `speed` times faster
    /// than the bus's clock (`speed` finite and > 0).
    pub fn new(dbc: Arc<Dbc>, mission: &Mission, scenario: &Scenario, speed: f64) -> Self {
        RedermorPlant {
            dbc,
            sim: Simulator::new(mission, scenario, VehicleConfig::default()),
            speed,
            start_us: None,
            commands: Commands::default(),
            last_heartbeat_us: None,
            samples: Vec::new(),
            silent: false,
            trace: None,
            next_trace_us: 0,
            idle_frames: Vec::new(),
        }
    }

    /// Writes the vehicle's true track to `out` (CSV, [`TRACE_HEADER`]), for the plots and
    /// the tests: where the vehicle really went, which no program knows.
    pub fn with_trace(mut self, mut out: Box<dyn std::io::Write + Send>) -> Self {
        // A trace that cannot be written is dropped: the vehicle flies on.
        self.trace = writeln!(out, "{TRACE_HEADER}").is_ok().then_some(out);
        self
    }

    fn record(&mut self) {
        let Some(out) = &mut self.trace else {
            return;
        };
        let t = self.sim.time_us();
        if t < self.next_trace_us {
            return;
        }
        self.next_trace_us = t + 1_000_000;
        let s = self.sim.vehicle().state();
        let line = writeln!(
            out,
            "{:.1},{:.2},{:.2},{:.2},{:.1},{:.0},{:.0}",
            t as f64 / 1e6,
            s.position.x,
            s.position.y,
            s.depth,
            s.heading.to_degrees().rem_euclid(360.0),
            s.rpm[0],
            s.rpm[1]
        );
        if line.and_then(|()| out.flush()).is_err() {
            self.trace = None;
        }
    }

    /// The simulator (the vehicle's true state).
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The commands the vehicle last received.
    pub fn commands(&self) -> &Commands {
        &self.commands
    }
}

impl Plant for RedermorPlant {
    fn on_frame(&mut self, time_us: u64, frame: &Frame) {
        let DecodeOutcome::Message(dm) = self.dbc.decode(frame) else {
            return;
        };
        let Some(m) = self.dbc.message(dm.message) else {
            return;
        };
        let value = |name: &str| dm.value(&self.dbc, name);
        match m.name.as_str() {
            "ThrusterCmd" => {
                if let Some(v) = value("rpm_left") {
                    self.commands.rpm_left = v;
                }
                if let Some(v) = value("rpm_right") {
                    self.commands.rpm_right = v;
                }
                self.commands.enable = value("enable").is_some_and(|e| e != 0.0);
                if self.commands.enable && self.start_us.is_none() {
                    self.start_us = Some(time_us);
                }
            }
            "DepthCmd" => {
                if let Some(v) = value("target") {
                    self.commands.depth = v;
                }
            }
            "SupervisorHeartbeat" => self.last_heartbeat_us = Some(time_us),
            _ => {}
        }
    }

    fn step(&mut self, time_us: u64) -> Vec<Frame> {
        let Some(start) = self.start_us else {
            // Not started: the first readings, again, so that nobody finds a sensor silent.
            if self.idle_frames.is_empty() {
                self.sim.step(0, None, &mut self.samples);
                let samples = std::mem::take(&mut self.samples);
                self.idle_frames = self.frames(&samples);
            }
            return self.idle_frames.clone();
        };
        let target = (time_us.saturating_sub(start) as f64 * self.speed) as u64;
        let fed = self
            .last_heartbeat_us
            .is_some_and(|t| time_us.saturating_sub(t) <= HEARTBEAT_TIMEOUT_US);
        self.samples.clear();
        let mut steps = 0;
        while self.sim.time_us() + STEP_US <= target && steps < MAX_STEPS_PER_TICK {
            let commands = fed.then_some(self.commands);
            for f in self.sim.step(STEP_US, commands.as_ref(), &mut self.samples) {
                if matches!(f.fault, Fault::BusOff) {
                    self.silent = true;
                }
            }
            steps += 1;
            self.record();
        }
        if self.silent {
            return Vec::new();
        }
        let samples = std::mem::take(&mut self.samples);
        let frames = self.frames(&samples);
        self.samples = samples;
        frames
    }

    fn period(&self) -> Duration {
        Duration::from_millis(20)
    }
}

/// The simulator's options, the same for both its hosts (`redermor-bridge`, `redermor-sim`).
#[derive(Clone, Debug, clap::Args)]
pub struct SimArgs {
    /// The mission file (where the vehicle starts, the seabed).
    #[arg(long, value_name = "FILE")]
    pub mission: PathBuf,
    /// The scenario file (current, faults at their times); default: a calm sea, no fault.
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    /// How many times faster than the wall clock the vehicle's time runs.
    #[arg(long, value_name = "FACTOR", default_value_t = 1.0)]
    pub speed: f64,
    /// Write the vehicle's true track here (CSV, one line a second of its time), for
    /// `petrel plot` and the tests.
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
}

/// What a Redermor simulator is made of, read from its files and checked before the bus is
/// opened: `redermor-bridge` (the memory bus's thread) and `redermor-sim` (a
/// process on a SocketCAN interface) both build their plant from one.
pub struct PlantFiles {
    mission: Mission,
    scenario: Scenario,
    speed: f64,
    trace: Option<Box<dyn std::io::Write + Send>>,
}

impl std::fmt::Debug for PlantFiles {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PlantFiles")
            .field("speed", &self.speed)
            .field("trace", &self.trace.is_some())
            .finish_non_exhaustive()
    }
}

impl PlantFiles {
    /// Reads the mission file (where the vehicle starts, the seabed) and the scenario file
    /// (current, faults at their times; none: a calm sea), checks `speed` (finite, above 0)
    /// and creates the trace file, as `args` give them. An error names the file, or the option.
    pub fn read(args: &SimArgs) -> Result<Self, String> {
        let (mission, scenario, speed, trace) = (
            args.mission.as_path(),
            args.scenario.as_deref(),
            args.speed,
            args.trace.as_deref(),
        );
        if !(speed.is_finite() && speed > 0.0) {
            return Err(format!("--speed {speed}: a factor above 0"));
        }
        let read =
            |p: &Path| std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()));
        let mission = Mission::from_toml(&read(mission)?)
            .map_err(|e| format!("{}: {e}", mission.display()))?;
        let scenario = match scenario {
            Some(p) => {
                Scenario::from_toml(&read(p)?).map_err(|e| format!("{}: {e}", p.display()))?
            }
            None => Scenario::default(),
        };
        let trace: Option<Box<dyn std::io::Write + Send>> = match trace {
            Some(p) => Some(Box::new(std::io::BufWriter::new(
                std::fs::File::create(p)
                    .map_err(|e| format!("cannot create {}: {e}", p.display()))?,
            ))),
            None => None,
        };
        Ok(PlantFiles {
            mission,
            scenario,
            speed,
            trace,
        })
    }

    /// The plant, speaking `dbc`'s messages.
    pub fn build(self, dbc: Arc<Dbc>) -> RedermorPlant {
        let plant = RedermorPlant::new(dbc, &self.mission, &self.scenario, self.speed);
        match self.trace {
            Some(t) => plant.with_trace(t),
            None => plant,
        }
    }
}

impl RedermorPlant {
    /// The frames of the newest reading of each sensor in `samples`, after the simulator's time.
    fn frames(&self, samples: &[Sample]) -> Vec<Frame> {
        let mut frames = Vec::new();
        // The newest reading of each sensor: the programs read latest values.
        let mut newest: Vec<&Sample> = Vec::new();
        for s in samples.iter().rev() {
            if !newest
                .iter()
                .any(|n| n.reading.sensor() == s.reading.sensor())
            {
                newest.push(s);
            }
        }
        let time_ms = (self.sim.time_us() / 1000) as f64;
        if let Ok(f) = self.dbc.encode("BenchTime", &[("time_ms", time_ms)]) {
            frames.push(f);
        }
        // The ground truth, for the monitor's map (no program reads it).
        let s = self.sim.vehicle().state();
        let truth = [
            ("x", s.position.x),
            ("y", s.position.y),
            ("depth", s.depth.max(0.0)),
        ];
        if let Ok(f) = self.dbc.encode(bus::TRUTH_MESSAGE, &truth) {
            frames.push(f);
        }
        for s in newest.into_iter().rev() {
            let (message, signals) = bus::encode(&s.reading);
            // A value out of the DBC's range is not sent: the sensor says nothing this tick.
            if let Ok(f) = self.dbc.encode(message, &signals) {
                frames.push(f);
            }
        }
        frames
    }
}
