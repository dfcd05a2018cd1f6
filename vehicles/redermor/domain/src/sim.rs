//! The Redermor simulator ([`Simulator`]: the vehicle, its sensors and a fault scenario) and
//! the closed loop of a whole mission in pure simulation ([`MissionRun`]: PLN, GDD, EVT, GUI
//! and IDC on the simulator, one step at a time), which records a [`Trace`] for the plots.
//!
//! The simulator obeys the commands the way the bus's thrusters do: a delivered command is
//! also the heartbeat, and without one for [`HEARTBEAT_TIMEOUT_US`] the thrusters stop. After a
//! bus-off no command is delivered and no reading comes out.

use crate::evt::{Detection, EventListener, EvtConfig, MissionEvent, OperatorRequest};
use crate::gdd::{Gdd, NavState};
use crate::geom::{self, Position};
use crate::guidance::{Guidance, GuidanceConfig, GuidanceEvent};
use crate::mission::{DepthTarget, Mission, Seabed};
use crate::pilot::{Pilot, PilotConfig};
use crate::plan::{LegKind, MissionPlan, PlanError, Planner, StageKind, Trajectory};
use crate::plot::{Trace, TraceEvent, TracePoint};
use crate::sensors::{
    Fault, Noise, NoiseLevels, Sample, Scenario, ScheduledFault, Sensor, Sensors,
};
use crate::vehicle::{Commands, Thruster, Vehicle, VehicleConfig};

/// How long the thrusters run on after the last command delivered (µs), as on the bus.
pub const HEARTBEAT_TIMEOUT_US: u64 = 300_000;

/// The simulated vehicle with its sensors under a scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulator {
    vehicle: Vehicle,
    sensors: Sensors,
    seabed: Seabed,
    faults: Vec<ScheduledFault>,
    next_fault: usize,
    time_us: u64,
    bus_off: bool,
    commands: Commands,
    last_command_us: Option<u64>,
}

/// Seconds to microseconds, saturating (scenario times are checked finite and ≥ 0).
fn to_us(seconds: f64) -> u64 {
    (seconds * 1e6).round().clamp(0.0, u64::MAX as f64) as u64
}

impl Simulator {
    /// A vehicle at the mission's start, at the surface, heading north, at time 0.
    pub fn new(mission: &Mission, scenario: &Scenario, config: VehicleConfig) -> Simulator {
        let mut vehicle = Vehicle::new(config, mission.start, 0.0);
        vehicle.set_current(scenario.current);
        Simulator {
            vehicle,
            sensors: Sensors::new(
                Noise::new(scenario.seed, scenario.noise),
                NoiseLevels::default(),
            ),
            seabed: mission.seabed,
            faults: scenario.faults.clone(),
            next_fault: 0,
            time_us: 0,
            bus_off: false,
            commands: Commands::default(),
            last_command_us: None,
        }
    }

    /// The simulated time (µs).
    pub fn time_us(&self) -> u64 {
        self.time_us
    }

    /// The vehicle (its true state).
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// Whether the bus is off.
    pub fn bus_off(&self) -> bool {
        self.bus_off
    }

    /// Advances by `dt_us`, delivering `commands` first (unless the bus is off; `None` sends
    /// nothing). Appends the readings that fell due to `out` and returns the faults that came
    /// into force, each applied at its own time: a reading due at or after a fault shows it,
    /// one due before does not.
    pub fn step(
        &mut self,
        dt_us: u64,
        commands: Option<&Commands>,
        out: &mut Vec<Sample>,
    ) -> Vec<ScheduledFault> {
        if let Some(c) = commands.filter(|_| !self.bus_off) {
            self.commands = *c;
            self.last_command_us = Some(self.time_us);
        }
        let end = self.time_us.saturating_add(dt_us);
        let mut fired = Vec::new();
        loop {
            let next_fault = self
                .faults
                .get(self.next_fault)
                .filter(|f| to_us(f.at) <= end)
                .copied();
            let until = next_fault.map_or(end, |f| to_us(f.at).max(self.time_us));
            self.advance_to(until, out, next_fault.is_some());
            match next_fault {
                Some(f) => {
                    self.apply(f.fault);
                    fired.push(f);
                    self.next_fault += 1;
                }
                None => break,
            }
        }
        if self.time_us < end {
            self.advance_to(end, out, false);
        }
        fired
    }

    /// Moves the dynamics to `until` and samples the readings due up to it (up to just before
    /// it when a fault strikes at `until`).
    fn advance_to(&mut self, until: u64, out: &mut Vec<Sample>, fault_at_until: bool) {
        // The thrusters obey while the heartbeat is fresh; a stale one stops them at its
        // timeout, inside this interval.
        let fresh_until = self
            .last_command_us
            .map_or(0, |t| t.saturating_add(HEARTBEAT_TIMEOUT_US));
        let stopped = Commands {
            enable: false,
            ..self.commands
        };
        if self.time_us < until {
            if fresh_until > self.time_us && fresh_until < until {
                self.integrate(fresh_until, self.commands);
                self.integrate(until, stopped);
            } else if fresh_until >= until {
                self.integrate(until, self.commands);
            } else {
                self.integrate(until, stopped);
            }
        }
        let due = if fault_at_until {
            until.saturating_sub(1)
        } else {
            until
        };
        let start = out.len();
        self.sensors.sample(
            due,
            self.vehicle.state(),
            self.vehicle.faults(),
            &self.seabed,
            out,
        );
        if self.bus_off {
            out.truncate(start);
        }
    }

    fn integrate(&mut self, until: u64, commands: Commands) {
        let dt = until.saturating_sub(self.time_us) as f64 / 1e6;
        self.vehicle.step(dt, &commands);
        // The seabed stops a vehicle commanded too deep.
        let floor = self.seabed.depth_at(self.vehicle.state().position);
        self.vehicle.limit_depth(floor);
        self.time_us = until;
    }

    /// Applies a fault now.
    pub fn apply(&mut self, fault: Fault) {
        match fault {
            Fault::Leak => self.vehicle.faults_mut().leak = true,
            Fault::SensorSilent(sensor) => self.sensors.set_silent(sensor, true),
            Fault::Thruster {
                thruster,
                efficiency,
            } => {
                let i = match thruster {
                    Thruster::Left => 0,
                    Thruster::Right => 1,
                };
                self.vehicle.faults_mut().thruster_efficiency[i] = efficiency.clamp(0.0, 1.0);
            }
            Fault::BusOff => self.bus_off = true,
            Fault::Current(current) => self.vehicle.set_current(current),
        }
    }
}

/// The closed loop's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RunConfig {
    /// The loop's period (µs): 100 ms, 10 Hz.
    pub step_us: u64,
    /// The run stops after this many steps whatever happens.
    pub max_steps: u64,
    /// Vehicle constants.
    pub vehicle: VehicleConfig,
    /// Guidance tuning (the arrival radius is the mission's).
    pub guidance: GuidanceConfig,
    /// Pilot tuning.
    pub pilot: PilotConfig,
    /// Event thresholds.
    pub evt: EvtConfig,
    /// Re-plan an area's survey when the current measured on arrival differs.
    pub replan_on_current: bool,
    /// A sensor silent this long is lost (µs).
    pub sensor_timeout_us: u64,
    /// Half-side of the inspection square (m).
    pub inspection_radius: f64,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            step_us: 100_000,
            max_steps: 200_000,
            vehicle: VehicleConfig::default(),
            guidance: GuidanceConfig::default(),
            pilot: PilotConfig::default(),
            evt: EvtConfig::default(),
            replan_on_current: true,
            sensor_timeout_us: 2_000_000,
            inspection_radius: 25.0,
        }
    }
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum RunOutcome {
    /// Every area surveyed and the end area reached.
    Completed,
    /// An alarm sent the vehicle to the end area, which it reached.
    Aborted(MissionEvent),
    /// No plan could be made (the vehicle stopped where it was).
    Stranded(PlanError),
    /// The step limit came first.
    StepLimit,
}

/// What the loop is doing.
#[derive(Clone, Debug, PartialEq)]
enum Phase {
    /// Stage `stage` of the plan.
    Stage(usize),
    /// Going to the end area after an alarm.
    Returning(MissionEvent),
    Finished,
}

/// A whole mission in closed loop on the simulator.
#[derive(Clone, Debug)]
pub struct MissionRun {
    mission: Mission,
    config: RunConfig,
    planner: Planner,
    plan: MissionPlan,
    sim: Simulator,
    gdd: Gdd,
    evt: EventListener,
    guidance: Guidance,
    pilot: Pilot,
    phase: Phase,
    commands: Commands,
    steps: u64,
    samples: Vec<Sample>,
    trace: Trace,
    surveyed: Vec<String>,
    outcome: Option<RunOutcome>,
    pending: Vec<MissionEvent>,
}

/// What a finished run reports.
#[derive(Clone, Debug)]
pub struct RunReport {
    /// How it ended.
    pub outcome: RunOutcome,
    /// Steps taken.
    pub steps: u64,
    /// The plan made at the start.
    pub plan: MissionPlan,
    /// The recorded trace (true positions), with the planned polylines and events.
    pub trace: Trace,
    /// Areas whose survey was finished, in order.
    pub surveyed: Vec<String>,
}

impl MissionRun {
    /// Plans `mission` and puts the vehicle at its start under `scenario`.
    pub fn new(
        mission: &Mission,
        scenario: &Scenario,
        config: RunConfig,
    ) -> Result<MissionRun, PlanError> {
        let planner = Planner::new(mission);
        let plan = planner.plan_mission()?;
        let mut guidance_config = config.guidance;
        guidance_config.arrival_radius = mission.vehicle.arrival_radius;
        let first = plan
            .stages
            .first()
            .map(|s| s.trajectory.clone())
            .unwrap_or_default();
        let mut trace = Trace::default();
        trace.planned.push(plan.trajectory().waypoints());
        Ok(MissionRun {
            mission: mission.clone(),
            sim: Simulator::new(mission, scenario, config.vehicle.clone()),
            gdd: Gdd::new(mission.start, 0),
            evt: EventListener::new(config.evt),
            guidance: Guidance::new(first, guidance_config),
            pilot: Pilot::new(config.pilot),
            config: RunConfig {
                guidance: guidance_config,
                ..config
            },
            planner,
            plan,
            phase: Phase::Stage(0),
            commands: Commands::default(),
            steps: 0,
            samples: Vec::new(),
            trace,
            surveyed: Vec::new(),
            outcome: None,
            pending: Vec::new(),
        })
    }

    /// The plan made at the start.
    pub fn plan(&self) -> &MissionPlan {
        &self.plan
    }

    /// The simulator.
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The estimated state.
    pub fn nav(&self) -> &NavState {
        self.gdd.state()
    }

    /// The trace so far.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// The outcome, once the run has ended.
    pub fn outcome(&self) -> Option<&RunOutcome> {
        self.outcome.as_ref()
    }

    /// An operator's request, taken at the next step.
    pub fn request(&mut self, request: OperatorRequest) {
        self.pending.extend(self.evt.operator(request));
    }

    /// A payload detection, taken at the next step.
    pub fn detection(&mut self, detection: &Detection) {
        self.pending.extend(self.evt.detection(detection));
    }

    fn event(&mut self, label: impl Into<String>) {
        let s = self.sim.vehicle().state();
        self.trace.events.push(TraceEvent {
            time: self.sim.time_us() as f64 / 1e6,
            position: s.position,
            label: label.into(),
        });
    }

    /// Follows `trajectory` from now on. A trajectory that starts away from the vehicle (a
    /// survey replanned with a new entry point) is joined by a path to its start first, so that
    /// no leg is begun from the side.
    /// A replan (`replan`, or a trajectory that needed joining) is recorded for the map; the
    /// nominal stages are already in the plan recorded at the start.
    fn start_trajectory(&mut self, mut trajectory: Trajectory, replan: bool) {
        let here = self.gdd.state().position;
        let mut replan = replan;
        if let Some(first) = trajectory.legs.first() {
            if geom::distance(here, first.from) > self.config.guidance.arrival_radius {
                match self
                    .planner
                    .route(here, first.from, LegKind::Transit, first.depth)
                {
                    Ok(mut legs) => {
                        legs.append(&mut trajectory.legs);
                        trajectory.legs = legs;
                        replan = true;
                    }
                    Err(e) => return self.strand(e),
                }
            }
        }
        if replan {
            self.trace.planned.push(trajectory.waypoints());
        }
        self.guidance = Guidance::new(trajectory, self.config.guidance);
    }

    /// One loop period: commands out, readings in, state, events, guidance, pilot. Returns the
    /// outcome once the run has ended.
    pub fn step(&mut self) -> Option<&RunOutcome> {
        if self.outcome.is_some() {
            return self.outcome.as_ref();
        }
        if self.steps >= self.config.max_steps {
            self.outcome = Some(RunOutcome::StepLimit);
            return self.outcome.as_ref();
        }
        self.steps += 1;
        self.samples.clear();
        let commands = self.commands;
        let fired = self
            .sim
            .step(self.config.step_us, Some(&commands), &mut self.samples);
        for f in fired {
            self.event(format!("fault: {:?}", f.fault));
        }
        for s in &self.samples {
            self.gdd.on_sample(s);
        }
        let now = self.sim.time_us();
        self.gdd.advance(now);
        let nav = *self.gdd.state();

        let lost: Vec<Sensor> = [Sensor::Depth, Sensor::Ahrs, Sensor::Dvl]
            .into_iter()
            .filter(|&s| self.gdd.is_stale(s, now, 0, self.config.sensor_timeout_us))
            .collect();
        let mut events = self.evt.watch(&nav, &lost);
        events.append(&mut self.pending);
        for e in events {
            self.on_event(e, &nav);
        }

        // An arrival starts the next stage's trajectory at once (several, when a transit has
        // no leg because the vehicle is already there): the pilot never goes a step without a
        // setpoint until the mission is over.
        let mut setpoint = None;
        for _ in 0..=self.plan.stages.len() + 1 {
            let (sp, guidance_events) = self.guidance.update(nav.position, nav.current);
            setpoint = sp;
            if matches!(self.phase, Phase::Finished)
                || !guidance_events.contains(&GuidanceEvent::Arrived)
            {
                break;
            }
            self.on_arrival(&nav);
        }
        if matches!(self.phase, Phase::Finished) {
            setpoint = None;
        }
        let dt = self.config.step_us as f64 / 1e6;
        self.commands = self.pilot.update(dt, setpoint.as_ref(), &nav);

        let truth = self.sim.vehicle().state();
        let area = match (&self.phase, self.guidance.current_leg()) {
            (
                Phase::Stage(_),
                Some(crate::plan::Leg {
                    kind: LegKind::SurveyLine { area, .. },
                    ..
                }),
            ) => self.mission.areas.iter().position(|a| &a.name == area),
            _ => None,
        };
        self.trace.points.push(TracePoint {
            time: now as f64 / 1e6,
            position: truth.position,
            depth: truth.depth,
            surveying: area,
        });
        self.outcome.as_ref()
    }

    fn on_event(&mut self, event: MissionEvent, nav: &NavState) {
        self.event(event.to_string());
        match &event {
            MissionEvent::Alarm(_) => {
                if matches!(self.phase, Phase::Returning(_) | Phase::Finished) {
                    return;
                }
                match self.planner.to_end_area(nav.position) {
                    Ok(t) => {
                        self.phase = Phase::Returning(event.clone());
                        self.start_trajectory(t, true);
                    }
                    Err(e) => self.strand(e),
                }
            }
            MissionEvent::Inspect { at, .. } => {
                let Phase::Stage(_) = self.phase else {
                    return;
                };
                let depth = self
                    .guidance
                    .current_leg()
                    .map_or(DepthTarget::Depth(nav.depth), |l| l.depth);
                let rest = self
                    .guidance
                    .trajectory()
                    .remainder_from(self.guidance.leg_index(), nav.position);
                match self.planner.inspection(
                    nav.position,
                    *at,
                    self.config.inspection_radius,
                    depth,
                ) {
                    Ok(mut t) => {
                        t.legs.extend(rest.legs);
                        self.start_trajectory(t, true);
                    }
                    // An object that cannot be reached is left alone: the survey goes on.
                    Err(e) => self.event(format!("inspection refused: {e}")),
                }
            }
            MissionEvent::CurrentDiffers { area, measured, .. } => {
                if !self.config.replan_on_current {
                    return;
                }
                let Phase::Stage(i) = self.phase else {
                    return;
                };
                match self.planner.survey(area, nav.position, Some(*measured)) {
                    Ok(survey) => {
                        if let Some(stage) = self.plan.stages.get_mut(i) {
                            stage.trajectory = survey.trajectory.clone();
                        }
                        // The transit to the end starts where the new survey ends.
                        let end = survey.trajectory.end().unwrap_or(nav.position);
                        if let Some(StageKind::TransitToArea(_) | StageKind::TransitToEnd) =
                            self.plan.stages.get(i + 1).map(|s| &s.kind)
                        {
                            let target = self.stage_target(i + 1);
                            let depth = DepthTarget::Depth(self.mission.vehicle.transit_depth);
                            match self.planner.route(end, target, LegKind::Transit, depth) {
                                Ok(legs) => self.plan.stages[i + 1].trajectory.legs = legs,
                                Err(e) => return self.strand(e),
                            }
                        }
                        self.start_trajectory(survey.trajectory, true);
                    }
                    Err(e) => self.event(format!("survey replan refused: {e}")),
                }
            }
        }
    }

    /// Where stage `i` ends: its last waypoint, or (an empty transit) where the next begins.
    fn stage_target(&self, i: usize) -> Position {
        let stages = &self.plan.stages;
        stages
            .get(i)
            .and_then(|s| s.trajectory.end())
            .or_else(|| {
                stages
                    .get(i + 1)
                    .and_then(|s| s.trajectory.legs.first())
                    .map(|l| l.from)
            })
            .unwrap_or(self.mission.end.target())
    }

    fn strand(&mut self, error: PlanError) {
        self.event(format!("stranded: {error}"));
        self.phase = Phase::Finished;
        self.outcome = Some(RunOutcome::Stranded(error));
    }

    fn on_arrival(&mut self, nav: &NavState) {
        match self.phase.clone() {
            Phase::Returning(event) => {
                self.event("end area reached");
                self.phase = Phase::Finished;
                self.outcome = Some(RunOutcome::Aborted(event));
            }
            Phase::Finished => {}
            Phase::Stage(i) => {
                let kind = self.plan.stages.get(i).map(|s| s.kind.clone());
                match &kind {
                    Some(StageKind::Survey(area)) => {
                        self.event(format!("survey done: {area}"));
                        self.surveyed.push(area.clone());
                    }
                    Some(StageKind::TransitToEnd) | None => {
                        self.event("end area reached");
                        self.phase = Phase::Finished;
                        self.outcome = Some(RunOutcome::Completed);
                        return;
                    }
                    Some(StageKind::TransitToArea(area)) => {
                        self.event(format!("area reached: {area}"));
                    }
                }
                self.phase = Phase::Stage(i + 1);
                let next = self
                    .plan
                    .stages
                    .get(i + 1)
                    .map(|s| s.trajectory.clone())
                    .unwrap_or_default();
                self.start_trajectory(next, false);
                if let Some(StageKind::TransitToArea(area)) = kind {
                    let predicted = self.mission.area(&area).and_then(|a| a.predicted_current);
                    if self.gdd.current_known() {
                        if let Some(e) = self.evt.arrival(&area, predicted, nav.current) {
                            self.on_event(e, nav);
                        }
                    }
                }
            }
        }
    }

    /// Steps until the run ends (or the step limit) and reports.
    pub fn run(mut self) -> RunReport {
        while self.step().is_none() {}
        self.report()
    }

    /// The report so far (the outcome is the step limit if the run has not ended).
    pub fn report(self) -> RunReport {
        RunReport {
            outcome: self.outcome.unwrap_or(RunOutcome::StepLimit),
            steps: self.steps,
            plan: self.plan,
            trace: self.trace,
            surveyed: self.surveyed,
        }
    }
}
