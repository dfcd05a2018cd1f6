//! What the Redermor programs do with the nets' calls (missions/redermor/INTERFACE.md), sans
//! I/O: a call in, the answers out; the CAN data server's latest signals in, the answers that
//! fell due and the thruster commands out. The binary `redermor-program` carries them on the
//! programs SDK.
//!
//! - [`Pln`]: PLN, the planner, over [`Planner`].
//! - [`Nav`]: GDD, GUI and IDC in one process, because guidance gives the pilot its
//!   set-point every control step: GDD's state from the readings, GUI's routes, course changes
//!   and legs, IDC's controllers and the thruster commands.
//! - [`Evt`]: EVT, the current checked on arrival, operator requests on a schedule, and the
//!   thrusters' fault as an alarm.

use petrel_programs::{ArgError, Call, Value};
use redermor::evt::{AlarmReason, EventListener, EvtConfig, MissionEvent, OperatorRequest};
use redermor::gdd::{Gdd, NavState};
use redermor::geom::{self, Position};
use redermor::guidance::{Guidance, GuidanceConfig, GuidanceEvent, Setpoint};
use redermor::mission::{Current, DepthTarget, Mission};
use redermor::pilot::{Pilot, PilotConfig};
use redermor::plan::{Leg, LegKind, PlanError, Planner, Survey, Trajectory};
use redermor::sensors::{Reading, Sensor};
use redermor::vehicle::Commands;

use crate::bus::ReadingTracker;

/// An event a program sends: as which program, its name and parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Answer {
    /// The program that sends it.
    pub program: &'static str,
    /// The event.
    pub event: &'static str,
    /// Its parameters.
    pub params: Vec<Value>,
}

fn answer(program: &'static str, event: &'static str, params: Vec<Value>) -> Answer {
    Answer {
        program,
        event,
        params,
    }
}

/// A position from a `[x, y]` argument.
fn point(call: &Call, index: usize) -> Result<Position, ArgError> {
    let v = call.floats(index)?;
    Ok(geom::pos(
        v.first().copied().unwrap_or(0.0),
        v.get(1).copied().unwrap_or(0.0),
    ))
}

/// The flat waypoint list of a trajectory, starting at `from` when it has no leg.
fn flat(trajectory: &Trajectory, from: Position) -> Vec<f64> {
    let points = trajectory.waypoints();
    let points = if points.is_empty() {
        vec![from]
    } else {
        points
    };
    points.iter().flat_map(|p| [p.x, p.y]).collect()
}

/// `(depth, altitude)` as the nets carry a depth target.
fn depth_pair(target: DepthTarget, transit_depth: f64) -> (f64, f64) {
    match target {
        DepthTarget::Depth(d) => (d, 0.0),
        DepthTarget::Altitude(h) => (transit_depth, h),
    }
}

/// A route from its flat waypoints, flown at `depth`, or `altitude` above the seabed when
/// `altitude > 0`.
fn route_of(waypoints: &[f64], depth: f64, altitude: f64, speed: f64, kind: LegKind) -> Trajectory {
    let points: Vec<Position> = waypoints
        .chunks_exact(2)
        .map(|c| geom::pos(c[0], c[1]))
        .collect();
    let depth = if altitude > 0.0 {
        DepthTarget::Altitude(altitude)
    } else {
        DepthTarget::Depth(depth)
    };
    Trajectory {
        legs: points
            .windows(2)
            .filter(|w| w[0] != w[1])
            .map(|w| Leg {
                kind: kind.clone(),
                from: w[0],
                to: w[1],
                depth,
                speed,
            })
            .collect(),
    }
}

fn index(area: i64) -> Option<usize> {
    usize::try_from(area).ok()
}

/// PLN: the itinerary and its cursor, trajectories, operative sequences, inspections.
#[derive(Debug)]
pub struct Pln {
    planner: Planner,
    mission: Mission,
    itinerary: Vec<usize>,
    cursor: usize,
    handed_out: Vec<usize>,
    trajectory: Option<(Trajectory, Position)>,
    sequences: Vec<Option<Survey>>,
    /// The area of the last sequence given: an inspection is flown at its depth.
    last_area: Option<usize>,
    /// Half-side of the inspection square (m).
    pub inspection_radius: f64,
}

impl Pln {
    /// A planner of `mission`.
    pub fn new(mission: &Mission) -> Pln {
        Pln {
            planner: Planner::new(mission),
            mission: mission.clone(),
            itinerary: Vec::new(),
            cursor: 0,
            handed_out: Vec::new(),
            trajectory: None,
            sequences: vec![None; mission.areas.len()],
            last_area: None,
            inspection_radius: 25.0,
        }
    }

    fn failed(e: impl std::fmt::Display) -> Answer {
        answer("PLN", "planning_failed", vec![Value::Text(e.to_string())])
    }

    fn area_name(&self, area: i64) -> Result<(usize, String), PlanError> {
        index(area)
            .and_then(|i| self.mission.areas.get(i).map(|a| (i, a.name.clone())))
            .ok_or_else(|| PlanError::UnknownArea(area.to_string()))
    }

    /// The answer to a call (`None`: the function answers nothing).
    pub fn handle(&mut self, call: &Call) -> Result<Option<Answer>, ArgError> {
        let transit = self.mission.vehicle.transit_depth;
        Ok(Some(match call.function.as_str() {
            "itinerary" => {
                let from = point(call, 0)?;
                let to_end = call.bool(1)?;
                self.cursor = 0;
                if to_end {
                    self.itinerary.clear();
                    match self.planner.to_end_area(from) {
                        Ok(t) => answer(
                            "PLN",
                            "itinerary_planned",
                            vec![Value::Int(0), Value::Float(t.length())],
                        ),
                        Err(e) => Self::failed(e),
                    }
                } else {
                    match self.planner.itinerary(from) {
                        Ok(it) => {
                            self.itinerary = it
                                .order
                                .into_iter()
                                .filter(|a| !self.handed_out.contains(a))
                                .collect();
                            answer(
                                "PLN",
                                "itinerary_planned",
                                vec![
                                    Value::Int(self.itinerary.len() as i64),
                                    Value::Float(it.length),
                                ],
                            )
                        }
                        Err(e) => Self::failed(e),
                    }
                }
            }
            "next_area" => match self.itinerary.get(self.cursor).copied() {
                Some(a) => {
                    self.cursor += 1;
                    self.handed_out.push(a);
                    answer("PLN", "next_area", vec![Value::Int(a as i64)])
                }
                None => answer("PLN", "areas_done", vec![]),
            },
            "trajectory" => {
                let area = call.int(0)?;
                let from = point(call, 1)?;
                let planned = if area < 0 {
                    self.planner.to_end_area(from)
                } else {
                    self.area_name(area).and_then(|(i, name)| {
                        let entry = match &self.sequences[i] {
                            Some(s) => s.entry(),
                            None => {
                                let predicted = self.mission.areas[i].predicted_current;
                                self.planner.survey(&name, from, predicted)?.entry()
                            }
                        }
                        .unwrap_or(from);
                        let depth = DepthTarget::Depth(transit);
                        self.planner
                            .route(from, entry, LegKind::Transit, depth)
                            .map(|legs| Trajectory { legs })
                    })
                };
                match planned {
                    Ok(t) => {
                        let a = answer(
                            "PLN",
                            "trajectory_planned",
                            vec![Value::Int(t.legs.len() as i64), Value::Float(t.length())],
                        );
                        self.trajectory = Some((t, from));
                        a
                    }
                    Err(e) => Self::failed(e),
                }
            }
            "get_trajectory" => {
                let (t, from) = self
                    .trajectory
                    .clone()
                    .unwrap_or((Trajectory::default(), self.mission.start));
                answer(
                    "PLN",
                    "trajectory",
                    vec![
                        Value::FloatList(flat(&t, from)),
                        Value::Float(transit),
                        Value::Float(0.0),
                    ],
                )
            }
            "operative_sequence" => {
                let area = call.int(0)?;
                let from = point(call, 1)?;
                let measured = point(call, 2)?;
                let result = if area < 0 {
                    let mut lines = 0;
                    let mut failed = None;
                    for i in 0..self.mission.areas.len() {
                        let a = &self.mission.areas[i];
                        match self.planner.survey(&a.name, from, a.predicted_current) {
                            Ok(s) => {
                                lines += s.lines.len();
                                self.sequences[i] = Some(s);
                            }
                            Err(e) => {
                                failed = Some(e);
                                break;
                            }
                        }
                    }
                    match failed {
                        Some(e) => Err(e),
                        None => Ok(lines),
                    }
                } else {
                    let current = Current::new(measured.x, measured.y);
                    self.area_name(area).and_then(|(i, name)| {
                        let s = self.planner.survey(&name, from, Some(current))?;
                        let lines = s.lines.len();
                        self.sequences[i] = Some(s);
                        Ok(lines)
                    })
                };
                match result {
                    Ok(lines) => answer(
                        "PLN",
                        "sequence_planned",
                        vec![Value::Int(area), Value::Int(lines as i64)],
                    ),
                    Err(e) => Self::failed(e),
                }
            }
            "get_sequence" => {
                let area = call.int(0)?;
                let i = index(area).filter(|&i| i < self.sequences.len());
                self.last_area = i;
                let (t, target) = match i.and_then(|i| self.sequences[i].clone()) {
                    Some(s) => (s.trajectory, self.mission.areas[i.unwrap_or(0)].depth),
                    None => (Trajectory::default(), DepthTarget::Depth(transit)),
                };
                let (depth, altitude) = depth_pair(target, transit);
                answer(
                    "PLN",
                    "sequence",
                    vec![
                        Value::Int(area),
                        Value::FloatList(flat(&t, self.mission.start)),
                        Value::Float(depth),
                        Value::Float(altitude),
                    ],
                )
            }
            "inspection" => {
                let object = point(call, 0)?;
                let from = point(call, 1)?;
                let target = self
                    .last_area
                    .and_then(|i| self.mission.areas.get(i))
                    .map_or(DepthTarget::Depth(transit), |a| a.depth);
                match self
                    .planner
                    .inspection(from, object, self.inspection_radius, target)
                {
                    Ok(t) => {
                        let (depth, altitude) = depth_pair(target, transit);
                        answer(
                            "PLN",
                            "inspection_planned",
                            vec![
                                Value::FloatList(flat(&t, from)),
                                Value::Float(depth),
                                Value::Float(altitude),
                            ],
                        )
                    }
                    Err(e) => answer(
                        "PLN",
                        "inspection_refused",
                        vec![Value::Text(e.to_string())],
                    ),
                }
            }
            _ => return Ok(None),
        }))
    }
}

/// Within this of the next leg's heading, a course change is over (radians: 5°).
pub const HEADING_TOLERANCE: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// The speed through the water during a course change (m/s).
pub const TURN_SPEED: f64 = 0.2;

/// Above this depth (m) the vehicle is at the surface.
pub const SURFACE_DEPTH: f64 = 0.5;

/// A sensor silent this long (µs of the vehicle's time) is not trusted.
pub const SENSOR_TIMEOUT_US: u64 = 2_000_000;

/// The speed through the water asked for while slowing down to turn round towards the point
/// to surface at (m/s, astern): the thrusters' thrust goes as the square of their rpm, so
/// slowing needs a firm astern command. (The final stop at that point is the pilot's brake,
/// which fades with the speed.)
pub const BRAKE_SPEED: f64 = -0.5;

/// Below this speed through the water (m/s) the vehicle is stopped: what it still drifts
/// once its thrusters are off is a few metres at most. A speed that changed sign while
/// braking means stopped too: the vehicle passed zero between two control steps.
pub const STOPPED_SPEED: f64 = 0.05;

/// The longest IDC brakes at the surface (µs of the vehicle's time) before it reports the
/// vehicle surfaced all the same (a thruster that does not answer must not hold the mission).
pub const BRAKE_TIMEOUT_US: u64 = 30_000_000;

/// The longest IDC steers back to where it was to surface once at the surface (µs of the
/// vehicle's time), before it stops where it is.
pub const RETURN_TIMEOUT_US: u64 = 120_000_000;

/// Turning towards a point more than this off the heading (radians: 45°), the vehicle slows
/// to [`TURN_SPEED`] and gyrates nearly on the spot rather than sweeping a wide circle.
pub const GYRATION_ANGLE: f64 = std::f64::consts::FRAC_PI_4;

/// What GUI was told to do and has not answered yet.
#[derive(Clone, Debug, PartialEq)]
enum Order {
    ChangeCourse { heading: f64, depth: DepthTarget },
    FollowLeg,
}

/// IDC surfacing the vehicle.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Surfacing {
    /// Since when (µs of the vehicle's time): the depth sensor is judged from then on.
    since: u64,
    /// Where the vehicle surfaces: the end of the route it last flew to its end, or where it
    /// was when told to surface. It comes up within GUI's arrival radius of that point, however
    /// late the order came (a slow or loaded computer keeps it cruising meanwhile).
    anchor: Position,
    /// At the surface: since when (µs of the vehicle's time).
    at_surface: Option<u64>,
    /// At the surface at the anchor and braking.
    braking: Option<Braking>,
}

/// IDC braking to a stop at the anchor.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Braking {
    /// Since when (µs of the vehicle's time).
    since: u64,
    /// The heading held meanwhile (radians).
    heading: f64,
    /// The sign of the speed through the water when it began: the vehicle has stopped once
    /// the speed has the other sign, however few control steps saw it slow down.
    direction: f64,
}

/// GDD, GUI and IDC: the vehicle's state, the route flown, the controllers.
#[derive(Debug)]
pub struct Nav {
    mission: Mission,
    gdd: Gdd,
    tracker: ReadingTracker,
    guidance: GuidanceConfig,
    pilot: Pilot,
    route: Option<Guidance>,
    order: Option<Order>,
    inspection: Option<Guidance>,
    suspended: Option<(Option<Guidance>, Option<Order>)>,
    hold: Option<Setpoint>,
    /// GUI stopped every route: the heading and depth the vehicle holds while braking to a
    /// stop where it is, until it is given another order.
    halt: Option<(f64, DepthTarget)>,
    engaged: bool,
    /// The end of the route GUI last flew to its end, until it is given another.
    route_end: Option<Position>,
    /// IDC is surfacing.
    surfacing: Option<Surfacing>,
    last_time_us: u64,
    commands: Commands,
}

impl Nav {
    /// The vehicle at `mission`'s start, thrusters disengaged.
    pub fn new(mission: &Mission) -> Nav {
        let guidance = GuidanceConfig {
            arrival_radius: mission.vehicle.arrival_radius,
            ..GuidanceConfig::default()
        };
        Nav {
            mission: mission.clone(),
            gdd: Gdd::new(mission.start, 0),
            tracker: ReadingTracker::new(),
            guidance,
            pilot: Pilot::new(PilotConfig::default()),
            route: None,
            order: None,
            inspection: None,
            suspended: None,
            hold: None,
            halt: None,
            engaged: false,
            route_end: None,
            surfacing: None,
            last_time_us: 0,
            commands: Commands::default(),
        }
    }

    /// The vehicle's estimated state.
    pub fn gdd(&self) -> &Gdd {
        &self.gdd
    }

    /// The commands of the last control step.
    pub fn commands(&self) -> &Commands {
        &self.commands
    }

    fn route(&self, call: &Call, kind: LegKind) -> Result<Trajectory, ArgError> {
        Ok(route_of(
            call.floats(0)?,
            call.float(1)?,
            call.float(2)?,
            self.mission.vehicle.cruise_speed,
            kind,
        ))
    }

    fn hold_here(&mut self) {
        let nav = self.gdd.state();
        if let Some(h) = &mut self.hold {
            h.heading = nav.heading;
        }
    }

    /// The setpoint that brings the vehicle up at `anchor`: half the cruise speed (the planes
    /// need some speed to climb), heading back to the anchor whenever the vehicle is more than
    /// the arrival radius from it; when that means turning round, braking first, then
    /// gyrating nearly on the spot.
    fn towards(
        anchor: Position,
        nav: &NavState,
        cruise: f64,
        guidance: GuidanceConfig,
    ) -> Setpoint {
        let (heading, speed) = if geom::distance(nav.position, anchor) > guidance.arrival_radius {
            let heading = geom::heading_between(nav.position, anchor);
            let speed = if geom::wrap_pi(heading - nav.heading).abs() <= GYRATION_ANGLE {
                cruise * 0.5
            } else if nav.water_speed > TURN_SPEED {
                // Past the anchor at speed: brake, or the turn is a wide circle.
                BRAKE_SPEED
            } else {
                TURN_SPEED
            };
            (heading, speed)
        } else {
            (nav.heading, cruise * 0.5)
        };
        Setpoint {
            heading,
            speed,
            depth: DepthTarget::Depth(0.0),
        }
    }

    /// The answers to a call (GDD's comes at once; GUI's and IDC's when done, from
    /// [`Nav::tick`]).
    pub fn handle(&mut self, call: &Call) -> Result<Vec<Answer>, ArgError> {
        let mut out = Vec::new();
        match (call.program.as_str(), call.function.as_str()) {
            ("GDD", "vehicle_state") => {
                let s = self.gdd.state();
                out.push(answer(
                    "GDD",
                    "vehicle_state",
                    vec![
                        Value::FloatList(vec![s.position.x, s.position.y]),
                        Value::Float(s.depth),
                        Value::Float(s.heading.to_degrees()),
                        Value::Float(s.water_speed),
                        Value::FloatList(vec![s.current.east, s.current.north]),
                        Value::Float(s.voltage),
                    ],
                ));
            }
            ("GUI", "compute_course") => {
                let t = self.route(call, LegKind::Transit)?;
                let legs = t.legs.len();
                self.route = (legs > 0).then(|| Guidance::new(t, self.guidance));
                self.order = None;
                self.route_end = None;
                out.push(answer(
                    "GUI",
                    "course_computed",
                    vec![Value::Int(legs as i64)],
                ));
            }
            ("GUI", "change_course") => match self.route.as_ref().and_then(|r| r.current_leg()) {
                Some(leg) => {
                    self.order = Some(Order::ChangeCourse {
                        heading: leg.heading(),
                        depth: leg.depth,
                    })
                }
                None => out.push(answer(
                    "GUI",
                    "heading_reached",
                    vec![Value::Float(self.gdd.state().heading.to_degrees())],
                )),
            },
            ("GUI", "follow_leg") => {
                if self.route.as_ref().is_none_or(|r| r.is_done()) {
                    out.push(answer("GUI", "route_done", vec![]));
                } else {
                    self.order = Some(Order::FollowLeg);
                }
            }
            ("GUI", "inspect") => {
                let t = self.route(call, LegKind::Inspection)?;
                self.route_end = None;
                if t.legs.is_empty() {
                    out.push(answer("GUI", "inspection_flown", vec![]));
                } else {
                    self.inspection = Some(Guidance::new(t, self.guidance));
                }
            }
            ("GUI", "suspend") => {
                self.suspended = Some((self.route.take(), self.order.take()));
                self.hold_here();
            }
            ("GUI", "resume") => {
                if let Some((route, order)) = self.suspended.take() {
                    self.route = route;
                    self.order = order;
                }
                self.route_end = None;
                self.inspection = None;
            }
            ("GUI", "stop") => {
                self.route = None;
                self.order = None;
                self.inspection = None;
                self.suspended = None;
                // Brake to a stop where it is rather than cruise on: the next route starts from
                // where GDD said the vehicle was, and a replan on a slow computer takes minutes
                // of the vehicle's time, over 200 m at cruise speed, into a forbidden zone
                // perhaps.
                let heading = self.gdd.state().heading;
                self.halt = self.hold.take().map(|h| (heading, h.depth));
            }
            ("IDC", "engage") => self.engaged = true,
            ("IDC", "surface") => {
                self.halt = None;
                self.surfacing = Some(Surfacing {
                    since: self.tracker.time_us(),
                    anchor: self.route_end.unwrap_or(self.gdd.state().position),
                    at_surface: None,
                    braking: None,
                });
            }
            ("IDC", "stop") | ("IDC", "emergency_surface") => {
                self.engaged = false;
                self.halt = None;
                self.surfacing = None;
                self.route = None;
                self.order = None;
                self.inspection = None;
                self.hold = None;
            }
            _ => {}
        }
        Ok(out)
    }

    /// One control step on the CAN data server's latest signals: the answers that fell due,
    /// and the thruster commands.
    pub fn tick(&mut self, values: &[(String, f64, u64)]) -> (Vec<Answer>, Option<Commands>) {
        let samples = self.tracker.update(values);
        let gps_fix = samples
            .iter()
            .any(|s| matches!(s.reading, Reading::Gps { .. }));
        for s in &samples {
            self.gdd.on_sample(s);
        }
        let now = self.tracker.time_us();
        self.gdd.advance(now);
        // The vehicle's time stands still until the thrusters are first enabled (the simulator
        // starts then): the step still runs, with no time passing, so that they are.
        let dt = now.saturating_sub(self.last_time_us) as f64 / 1e6;
        self.last_time_us = self.last_time_us.max(now);
        let nav = *self.gdd.state();
        let mut out = Vec::new();
        let cruise = self.mission.vehicle.cruise_speed;

        let mut setpoint = self.hold;
        if let Some(insp) = &mut self.inspection {
            let (sp, events) = insp.update(nav.position, nav.current);
            setpoint = sp.or(setpoint);
            if events.contains(&GuidanceEvent::Arrived) {
                self.inspection = None;
                out.push(answer("GUI", "inspection_flown", vec![]));
            }
        } else {
            match self.order.clone() {
                Some(Order::ChangeCourse { heading, depth }) => {
                    // A gyration nearly on the spot (differential thrust): the next leg then
                    // starts at its waypoint, not a turning circle away.
                    setpoint = Some(Setpoint {
                        heading,
                        speed: TURN_SPEED,
                        depth,
                    });
                    if geom::wrap_pi(heading - nav.heading).abs() < HEADING_TOLERANCE {
                        self.order = None;
                        out.push(answer(
                            "GUI",
                            "heading_reached",
                            vec![Value::Float(heading.to_degrees())],
                        ));
                    }
                }
                Some(Order::FollowLeg) => {
                    if let Some(route) = &mut self.route {
                        let (sp, events) = route.update(nav.position, nav.current);
                        setpoint = sp.or(setpoint);
                        if events.contains(&GuidanceEvent::Arrived) {
                            self.order = None;
                            self.route_end = route.trajectory().legs.last().map(|l| l.to);
                            out.push(answer("GUI", "route_done", vec![]));
                        } else if let Some(leg) = events.iter().find_map(|e| match e {
                            GuidanceEvent::LegDone { leg } => Some(*leg),
                            _ => None,
                        }) {
                            self.order = None;
                            out.push(answer("GUI", "leg_done", vec![Value::Int(leg as i64)]));
                        }
                    }
                }
                None => {}
            }
        }
        if setpoint.is_some() {
            self.hold = setpoint;
            // A new order: the stop GUI was told is over.
            self.halt = None;
        }

        // The heading and depth to hold while braking to a stop, when GUI or IDC stops.
        let mut brake = self.halt;
        if let Some(surfacing) = &mut self.surfacing {
            let depth_known =
                !self
                    .gdd
                    .is_stale(Sensor::Depth, now, surfacing.since, SENSOR_TIMEOUT_US);
            brake = None;
            let surfaced = if !depth_known {
                // No depth: stop the thrusters, the buoyant vehicle rises; the GPS's first fix
                // says it is out.
                setpoint = None;
                gps_fix
            } else if surfacing.at_surface.is_none() && nav.depth >= SURFACE_DEPTH && !gps_fix {
                setpoint = Some(Self::towards(surfacing.anchor, &nav, cruise, self.guidance));
                false
            } else if surfacing.braking.is_none()
                && geom::distance(nav.position, surfacing.anchor) > self.guidance.arrival_radius
                && now.saturating_sub(*surfacing.at_surface.get_or_insert(now)) < RETURN_TIMEOUT_US
            {
                // Up, but carried past the anchor on the way: back to it at the surface.
                setpoint = Some(Self::towards(surfacing.anchor, &nav, cruise, self.guidance));
                false
            } else {
                // Up at the anchor: brake to a stop before saying so, so that the vehicle is
                // where it surfaced when its thrusters go off (it would coast on for tens of
                // metres). The pilot's brake fades with the speed, so that a slow computer's
                // long control step does not drive the vehicle astern; a speed that changed
                // sign between two steps is a stop.
                surfacing.at_surface.get_or_insert(now);
                let b = *surfacing.braking.get_or_insert(Braking {
                    since: now,
                    heading: nav.heading,
                    direction: if nav.water_speed < 0.0 { -1.0 } else { 1.0 },
                });
                brake = Some((b.heading, DepthTarget::Depth(0.0)));
                setpoint = None;
                nav.water_speed.abs() <= STOPPED_SPEED
                    || nav.water_speed * b.direction < 0.0
                    || now.saturating_sub(b.since) >= BRAKE_TIMEOUT_US
            };
            if surfaced {
                self.surfacing = None;
                self.hold = None;
                setpoint = None;
                brake = None;
                out.push(answer("IDC", "surfaced", vec![]));
            }
        }
        self.commands = match (self.engaged, brake) {
            (true, Some((heading, depth))) => self.pilot.brake(dt, heading, depth, &nav),
            (true, None) => self.pilot.update(dt, setpoint.as_ref(), &nav),
            (false, _) => self.pilot.update(dt, None, &nav),
        };
        (out, Some(self.commands))
    }
}

/// How long EVT lets the current estimate settle on arrival (µs of the vehicle's time).
pub const CURRENT_SETTLE_US: u64 = 10_000_000;

/// EVT: the current on arrival, operator requests, the thrusters' fault.
#[derive(Debug)]
pub struct Evt {
    mission: Mission,
    gdd: Gdd,
    tracker: ReadingTracker,
    listener: EventListener,
    check: Option<(i64, u64)>,
    requests: Vec<(u64, OperatorRequest)>,
    next_request: usize,
}

/// A problem of an operator request schedule, with its line.
#[derive(Clone, Debug, PartialEq)]
pub struct RequestError {
    /// Line number, from 1.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for RequestError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

/// Reads an operator request schedule: one request a line, `SECONDS REQUEST` in the vehicle's
/// time (`600 return`, `1200 inspect 100 650`); `#` starts a comment.
pub fn parse_requests(text: &str) -> Result<Vec<(u64, OperatorRequest)>, RequestError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let (at, rest) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
        let at: f64 = at
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| RequestError {
                line: line_no,
                message: format!("\"{at}\" is not a time in seconds ≥ 0"),
            })?;
        let request = OperatorRequest::parse(rest).map_err(|message| RequestError {
            line: line_no,
            message,
        })?;
        out.push(((at * 1e6) as u64, request));
    }
    out.sort_by_key(|(t, _)| *t);
    Ok(out)
}

impl Evt {
    /// The listener of `mission`, with the operator's requests due at their times.
    pub fn new(mission: &Mission, requests: Vec<(u64, OperatorRequest)>) -> Evt {
        Evt {
            mission: mission.clone(),
            gdd: Gdd::new(mission.start, 0),
            tracker: ReadingTracker::new(),
            listener: EventListener::new(EvtConfig::default()),
            check: None,
            requests,
            next_request: 0,
        }
    }

    /// Takes a call (its answer comes from [`Evt::tick`]).
    pub fn handle(&mut self, call: &Call) -> Result<(), ArgError> {
        if call.function == "check_current" {
            self.check = Some((call.int(0)?, self.tracker.time_us()));
        }
        Ok(())
    }

    /// The events that fell due on the latest signals.
    pub fn tick(&mut self, values: &[(String, f64, u64)]) -> Vec<Answer> {
        for s in self.tracker.update(values) {
            self.gdd.on_sample(&s);
        }
        let now = self.tracker.time_us();
        self.gdd.advance(now);
        let nav = *self.gdd.state();
        let mut out = Vec::new();
        while let Some(&(at, request)) = self.requests.get(self.next_request) {
            if at > now {
                break;
            }
            self.next_request += 1;
            out.extend(self.listener.operator(request).and_then(|e| self.event(e)));
        }
        for e in self.listener.watch(&nav, &[]) {
            // Leak and battery are the CAN data server's rules; the thrusters' fault is EVT's.
            if e == MissionEvent::Alarm(AlarmReason::ThrusterFault) {
                out.extend(self.event(e));
            }
        }
        if let Some((area, since)) = self.check {
            if now >= since + CURRENT_SETTLE_US && self.gdd.current_known() {
                self.check = None;
                let predicted = index(area)
                    .and_then(|i| self.mission.areas.get(i))
                    .and_then(|a| a.predicted_current);
                let name = index(area)
                    .and_then(|i| self.mission.areas.get(i))
                    .map_or(String::new(), |a| a.name.clone());
                out.push(match self.listener.arrival(&name, predicted, nav.current) {
                    Some(_) => answer(
                        "EVT",
                        "current_differs",
                        vec![
                            Value::Int(area),
                            Value::FloatList(vec![nav.current.east, nav.current.north]),
                        ],
                    ),
                    None => answer("EVT", "current_ok", vec![Value::Int(area)]),
                });
            }
        }
        out
    }

    fn event(&self, e: MissionEvent) -> Option<Answer> {
        match e {
            MissionEvent::Alarm(reason) => Some(answer(
                "EVT",
                "alarm",
                vec![Value::Text(format!("{reason:?}"))],
            )),
            MissionEvent::Inspect { at, .. } => Some(answer(
                "EVT",
                "inspect_request",
                vec![Value::FloatList(vec![at.x, at.y])],
            )),
            MissionEvent::CurrentDiffers { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bench() -> Mission {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../missions/redermor/sim/mission.toml"
        );
        Mission::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap()
    }

    fn call(pln: &mut Pln, function: &str, args: Vec<Value>) -> Answer {
        pln.handle(&Call::new("PLN", function, args))
            .unwrap()
            .expect("an answer")
    }

    #[test]
    fn pln_hands_out_every_area_once_then_areas_done() {
        let mut pln = Pln::new(&bench());
        let here = Value::FloatList(vec![0.0, 0.0]);
        let a = call(
            &mut pln,
            "itinerary",
            vec![here.clone(), Value::Bool(false)],
        );
        assert_eq!(a.event, "itinerary_planned");
        assert_eq!(a.params[0], Value::Int(2));
        let mut areas = Vec::new();
        for _ in 0..2 {
            let a = call(&mut pln, "next_area", vec![]);
            assert_eq!(a.event, "next_area");
            areas.push(a.params[0].clone());
        }
        areas.sort_by_key(|v| format!("{v:?}"));
        assert_eq!(areas, vec![Value::Int(0), Value::Int(1)]);
        assert_eq!(call(&mut pln, "next_area", vec![]).event, "areas_done");
        // The alarm's replan drops the areas left: straight to the end.
        let a = call(&mut pln, "itinerary", vec![here, Value::Bool(true)]);
        assert_eq!(a.params[0], Value::Int(0));
        assert_eq!(call(&mut pln, "next_area", vec![]).event, "areas_done");
    }

    #[test]
    fn pln_trajectory_goes_round_the_buoy_field() {
        let mut pln = Pln::new(&bench());
        let from = Value::FloatList(vec![0.0, 0.0]);
        let a = call(&mut pln, "trajectory", vec![Value::Int(0), from]);
        assert_eq!(a.event, "trajectory_planned");
        let t = call(&mut pln, "get_trajectory", vec![]);
        let Value::FloatList(w) = &t.params[0] else {
            panic!("{t:?}")
        };
        assert_eq!((w[0], w[1]), (0.0, 0.0), "starts where the vehicle is");
        // Alpha is due north, behind the buoy field: the route bends round it.
        assert!(w.len() >= 6, "{w:?}");
        let unknown = call(
            &mut pln,
            "trajectory",
            vec![Value::Int(7), Value::FloatList(vec![0.0, 0.0])],
        );
        assert_eq!(unknown.event, "planning_failed");
    }

    #[test]
    fn request_schedules_are_read_and_bad_lines_named() {
        let r = parse_requests("# operator\n230 inspect 50 240\n40 return\n").unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r[0], (40_000_000, OperatorRequest::ReturnToEnd));
        let e = parse_requests("10 return\nsoon return\n").unwrap_err();
        assert_eq!(e.line, 2);
        let e = parse_requests("5 dance\n").unwrap_err();
        assert!(e.to_string().starts_with("line 1: unknown request"), "{e}");
    }

    #[test]
    fn nav_answers_the_state_and_a_route_of_one_point_at_once() {
        let mut nav = Nav::new(&bench());
        let a = nav
            .handle(&Call::new("GDD", "vehicle_state", vec![]))
            .unwrap();
        assert_eq!(a[0].event, "vehicle_state");
        assert_eq!(a[0].params[0], Value::FloatList(vec![0.0, 0.0]));
        let one = vec![
            Value::FloatList(vec![0.0, 0.0]),
            Value::Float(4.0),
            Value::Float(0.0),
        ];
        let a = nav
            .handle(&Call::new("GUI", "compute_course", one))
            .unwrap();
        assert_eq!(a[0].params[0], Value::Int(0));
        let a = nav.handle(&Call::new("GUI", "follow_leg", vec![])).unwrap();
        assert_eq!(a[0].event, "route_done");
        // Disengaged, the pilot keeps the thrusters off.
        let (_, commands) = nav.tick(&[]);
        assert!(!commands.unwrap().enable);
    }
}
