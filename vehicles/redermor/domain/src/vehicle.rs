//! The vehicle's dynamics: an AUV in the horizontal plane (position, heading, surge speed, yaw
//! rate) driven by two thrusters, plus depth under its own depth loop, a water current that
//! carries it, a battery that drains with the load, and faults.
//!
//! Two stern thrusters, left and right: their sum pushes forward (surge), their difference
//! turns (yaw; left faster turns to starboard). Thrust goes as rpm·|rpm| and the hull's drag as
//! the speed squared, so the steady speed is proportional to the rpm. Depth follows the
//! commanded depth (`DepthCmd` on the bus) through the vehicle's own proportional loop on its
//! planes, whose authority grows with the speed; the hull is slightly buoyant, so that loop
//! alone settles a little above the command (the pilot's integral trims it). Without thrust the
//! vehicle rises to the surface. Deterministic: the same steps give the same states.

use crate::geom::{self, Position};
use crate::mission::Current;

/// The vehicle's physical constants.
#[derive(Clone, Debug, PartialEq)]
pub struct VehicleConfig {
    /// Mass plus added mass in surge (kg).
    pub mass: f64,
    /// Yaw inertia plus added inertia (kg·m²).
    pub yaw_inertia: f64,
    /// Thrust per rpm² of one thruster (N/rpm²).
    pub thrust_per_rpm2: f64,
    /// Quadratic surge drag (N per (m/s)²).
    pub surge_drag: f64,
    /// Lateral distance from the axis to each thruster (m).
    pub thruster_arm: f64,
    /// Linear yaw damping (N·m per rad/s).
    pub yaw_damping: f64,
    /// Quadratic yaw damping (N·m per (rad/s)²).
    pub yaw_drag: f64,
    /// Thruster speed limit (rpm).
    pub max_rpm: f64,
    /// Time constant of a thruster reaching its commanded rpm (s).
    pub thruster_lag: f64,
    /// Gain of the depth loop (vertical m/s per metre of depth error).
    pub depth_gain: f64,
    /// Vertical speed the planes give at rest (m/s).
    pub vertical_speed_at_rest: f64,
    /// Vertical speed the planes add per m/s of forward speed.
    pub vertical_speed_per_speed: f64,
    /// Rise speed from buoyancy (m/s).
    pub buoyancy_rise: f64,
    /// Battery capacity (Ah).
    pub battery_capacity: f64,
    /// Open-circuit voltage when full (V).
    pub voltage_full: f64,
    /// Open-circuit voltage when empty (V).
    pub voltage_empty: f64,
    /// Internal resistance (Ω).
    pub internal_resistance: f64,
    /// Electrical load of everything but the thrusters (W).
    pub hotel_load: f64,
    /// Electrical power of one thruster at 1,000 rpm (W); it goes as the cube of the rpm.
    pub thruster_power_at_1000: f64,
}

impl Default for VehicleConfig {
    /// A vehicle of Redermor's class: 1.5 m/s at 1,000 rpm, 10°/s turns, a 25 V, 100 Ah battery.
    fn default() -> Self {
        VehicleConfig {
            mass: 3000.0,
            yaw_inertia: 2000.0,
            thrust_per_rpm2: 1.5e-4,
            // 2 × 150 N at 1,000 rpm balance the drag at 1.5 m/s.
            surge_drag: 300.0 / 2.25,
            thruster_arm: 0.3,
            yaw_damping: 200.0,
            yaw_drag: 3000.0,
            max_rpm: 3000.0,
            thruster_lag: 0.3,
            depth_gain: 0.2,
            vertical_speed_at_rest: 0.1,
            vertical_speed_per_speed: 0.25,
            buoyancy_rise: 0.02,
            battery_capacity: 100.0,
            voltage_full: 25.2,
            voltage_empty: 21.0,
            internal_resistance: 0.05,
            hotel_load: 100.0,
            thruster_power_at_1000: 150.0,
        }
    }
}

/// What the pilot commands (the bus's `ThrusterCmd` and `DepthCmd`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Commands {
    /// Left thruster (rpm, negative astern).
    pub rpm_left: f64,
    /// Right thruster (rpm).
    pub rpm_right: f64,
    /// Depth for the depth loop (m).
    pub depth: f64,
    /// Thrusters enabled.
    pub enable: bool,
}

/// A thruster.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Thruster {
    /// Port.
    Left,
    /// Starboard.
    Right,
}

/// The faults in force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Faults {
    /// The hull leaks.
    pub leak: bool,
    /// Fraction of its thrust each thruster still gives (1 healthy, 0 dead): left, right.
    pub thruster_efficiency: [f64; 2],
}

impl Default for Faults {
    fn default() -> Self {
        Faults {
            leak: false,
            thruster_efficiency: [1.0, 1.0],
        }
    }
}

impl Faults {
    /// Whether a thruster is faulty (gives less than its full thrust).
    pub fn thruster_fault(&self, thruster: Thruster) -> bool {
        self.thruster_efficiency[thruster as usize] < 1.0
    }
}

/// The vehicle's true state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleState {
    /// Position in the local frame.
    pub position: Position,
    /// Depth (m, 0 at the surface).
    pub depth: f64,
    /// Nautical heading (radians, `[0, 2π)`).
    pub heading: f64,
    /// Speed through the water along the axis (m/s).
    pub surge: f64,
    /// Yaw rate (rad/s, positive clockwise).
    pub yaw_rate: f64,
    /// Vertical speed (m/s, positive down).
    pub heave: f64,
    /// Thruster speeds (rpm): left, right.
    pub rpm: [f64; 2],
    /// Charge left (Ah).
    pub charge: f64,
    /// Current drawn (A).
    pub battery_current: f64,
    /// Battery voltage under load (V).
    pub voltage: f64,
    /// The water current where the vehicle is.
    pub water: Current,
}

impl VehicleState {
    /// Velocity over the ground (m/s, east and north): through the water plus the current.
    pub fn ground_velocity(&self) -> Position {
        geom::heading_vector(self.heading) * self.surge + self.water.as_vector()
    }
}

/// The simulated vehicle.
#[derive(Clone, Debug, PartialEq)]
pub struct Vehicle {
    config: VehicleConfig,
    state: VehicleState,
    faults: Faults,
}

/// The longest internal integration step (s): steps given longer are cut up, so that a caller
/// stepping at 10 Hz or 1 Hz gets the same stable dynamics.
pub const MAX_SUBSTEP: f64 = 0.02;

impl Vehicle {
    /// A vehicle at rest at the surface at `position`, heading `heading`, battery full.
    pub fn new(config: VehicleConfig, position: Position, heading: f64) -> Vehicle {
        let charge = config.battery_capacity;
        let voltage = config.voltage_full;
        Vehicle {
            config,
            state: VehicleState {
                position,
                depth: 0.0,
                heading: geom::wrap_2pi(heading),
                surge: 0.0,
                yaw_rate: 0.0,
                heave: 0.0,
                rpm: [0.0, 0.0],
                charge,
                battery_current: 0.0,
                voltage,
                water: Current::default(),
            },
            faults: Faults::default(),
        }
    }

    /// Its true state.
    pub fn state(&self) -> &VehicleState {
        &self.state
    }

    /// Its constants.
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// The faults in force.
    pub fn faults(&self) -> &Faults {
        &self.faults
    }

    /// Changes the faults in force.
    pub fn faults_mut(&mut self) -> &mut Faults {
        &mut self.faults
    }

    /// Sets the water current.
    pub fn set_current(&mut self, current: Current) {
        self.state.water = current;
    }

    /// Keeps the vehicle no deeper than `floor` (m): the seabed stops it.
    pub fn limit_depth(&mut self, floor: f64) {
        if floor.is_finite() && self.state.depth > floor {
            self.state.depth = floor.max(0.0);
            self.state.heave = 0.0;
        }
    }

    /// Advances the vehicle by `dt` seconds under `commands` (disabled thrusters spin down).
    /// A non-finite or negative `dt` does nothing; non-finite commands count as zero.
    pub fn step(&mut self, dt: f64, commands: &Commands) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        let max = self.config.max_rpm;
        let target = if commands.enable {
            [
                finite(commands.rpm_left).clamp(-max, max),
                finite(commands.rpm_right).clamp(-max, max),
            ]
        } else {
            [0.0, 0.0]
        };
        let depth_cmd = finite(commands.depth).max(0.0);
        let substeps = (dt / MAX_SUBSTEP).ceil().max(1.0) as usize;
        let h = dt / substeps as f64;
        for _ in 0..substeps {
            self.substep(h, target, depth_cmd);
        }
    }

    fn substep(&mut self, h: f64, target_rpm: [f64; 2], depth_cmd: f64) {
        let c = &self.config;
        let s = &mut self.state;
        let lag = (h / c.thruster_lag).min(1.0);
        for (rpm, target) in s.rpm.iter_mut().zip(target_rpm) {
            *rpm += (target - *rpm) * lag;
        }
        let thrust: Vec<f64> = s
            .rpm
            .iter()
            .zip(self.faults.thruster_efficiency)
            .map(|(&rpm, eff)| c.thrust_per_rpm2 * rpm * rpm.abs() * eff.clamp(0.0, 1.0))
            .collect();
        let (left, right) = (thrust[0], thrust[1]);

        let surge_accel = (left + right - c.surge_drag * s.surge * s.surge.abs()) / c.mass;
        s.surge += surge_accel * h;
        let yaw_accel = (c.thruster_arm * (left - right)
            - c.yaw_damping * s.yaw_rate
            - c.yaw_drag * s.yaw_rate * s.yaw_rate.abs())
            / c.yaw_inertia;
        s.yaw_rate += yaw_accel * h;
        s.heading = geom::wrap_2pi(s.heading + s.yaw_rate * h);

        // The planes' authority grows with the speed; buoyancy always lifts a little.
        let authority = c.vertical_speed_at_rest + c.vertical_speed_per_speed * s.surge.abs();
        let thrusting = s.rpm.iter().any(|r| r.abs() > 50.0);
        let loop_speed = if thrusting {
            (c.depth_gain * (depth_cmd - s.depth)).clamp(-authority, authority)
        } else {
            0.0
        };
        s.heave = loop_speed - c.buoyancy_rise;
        s.depth = (s.depth + s.heave * h).max(0.0);

        let velocity = geom::heading_vector(s.heading) * s.surge + s.water.as_vector();
        s.position = s.position + velocity * h;

        let power = c.hotel_load
            + s.rpm
                .iter()
                .map(|r| c.thruster_power_at_1000 * (r.abs() / 1000.0).powi(3))
                .sum::<f64>();
        let soc = (s.charge / c.battery_capacity).clamp(0.0, 1.0);
        let open_circuit = c.voltage_empty + (c.voltage_full - c.voltage_empty) * soc;
        s.battery_current = power / open_circuit.max(1.0);
        s.voltage = open_circuit - c.internal_resistance * s.battery_current;
        s.charge = (s.charge - s.battery_current * h / 3600.0).max(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(v: &mut Vehicle, seconds: f64, c: &Commands) {
        for _ in 0..(seconds * 10.0) as usize {
            v.step(0.1, c);
        }
    }

    #[test]
    fn equal_thrust_goes_straight_at_the_expected_speed() {
        let mut v = Vehicle::new(VehicleConfig::default(), geom::pos(0.0, 0.0), 0.0);
        let c = Commands {
            rpm_left: 1000.0,
            rpm_right: 1000.0,
            depth: 10.0,
            enable: true,
        };
        run(&mut v, 120.0, &c);
        let s = v.state();
        assert!((s.surge - 1.5).abs() < 0.01, "surge {}", s.surge);
        assert!(s.position.x.abs() < 1e-6 && s.position.y > 150.0);
        assert!((s.depth - 10.0).abs() < 0.5, "depth {}", s.depth);
        assert!(s.voltage < 25.2 && s.charge < 100.0);
    }

    #[test]
    fn left_faster_turns_to_starboard_and_current_drifts() {
        let mut v = Vehicle::new(VehicleConfig::default(), geom::pos(0.0, 0.0), 0.0);
        v.set_current(Current::new(0.5, 0.0));
        let c = Commands {
            rpm_left: 1200.0,
            rpm_right: 800.0,
            depth: 0.0,
            enable: true,
        };
        v.step(2.0, &c);
        assert!(v.state().yaw_rate > 0.0);
        let mut still = Vehicle::new(VehicleConfig::default(), geom::pos(0.0, 0.0), 0.0);
        still.set_current(Current::new(0.5, 0.0));
        still.step(10.0, &Commands::default());
        assert!((still.state().position.x - 5.0).abs() < 1e-9);
        assert_eq!(still.state().depth, 0.0);
    }

    #[test]
    fn a_dead_thruster_makes_the_vehicle_turn_and_bad_input_is_ignored() {
        let mut v = Vehicle::new(VehicleConfig::default(), geom::pos(0.0, 0.0), 0.0);
        v.faults_mut().thruster_efficiency = [0.0, 1.0];
        let c = Commands {
            rpm_left: 1000.0,
            rpm_right: 1000.0,
            depth: 5.0,
            enable: true,
        };
        v.step(3.0, &c);
        assert!(v.state().yaw_rate < 0.0, "turns to port");
        let before = *v.state();
        v.step(f64::NAN, &c);
        v.step(-1.0, &c);
        assert_eq!(*v.state(), before);
        v.step(
            0.1,
            &Commands {
                rpm_left: f64::NAN,
                depth: f64::INFINITY,
                ..c
            },
        );
        assert!(v.state().position.x.is_finite() && v.state().depth.is_finite());
    }
}
