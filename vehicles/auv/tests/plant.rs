//! The simulated AUV of the memory bus, in virtual time: it obeys the supervisor's commands
//! only while the heartbeat comes, and its sensors say where it is.

use std::sync::Arc;

use auv::plant::{AuvPlant, SimFaults};
use petrel_can_bridge::dbc::DecodeOutcome;
use petrel_can_bridge::{Dbc, Frame};

/// The AUV's DBC (missions/auv/auv.dbc).
fn dbc() -> Arc<Dbc> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../missions/auv/auv.dbc");
    Arc::new(Dbc::load(std::path::Path::new(path)).unwrap())
}

/// The physical value of `MESSAGE.signal` in the frames, if one of them is that message.
fn value(frames: &[Frame], message: &str, signal: &str) -> Option<f64> {
    let dbc = dbc();
    frames.iter().find_map(|f| match dbc.decode(f) {
        DecodeOutcome::Message(dm) if dbc.message(dm.message)?.name == message => {
            dm.value(&dbc, signal)
        }
        _ => None,
    })
}

fn command(plant: &mut AuvPlant, t: u64, message: &str, values: &[(&str, f64)]) {
    plant.on_frame(t, &dbc().encode(message, values).unwrap());
}

/// Runs the plant in 100 ms ticks from `t` for `ticks`, with a heartbeat each tick when
/// `heartbeat`; returns the time reached and the last frames.
fn fly(plant: &mut AuvPlant, mut t: u64, ticks: u32, heartbeat: bool) -> (u64, Vec<Frame>) {
    let mut frames = Vec::new();
    for _ in 0..ticks {
        if heartbeat {
            command(
                plant,
                t,
                "SupervisorHeartbeat",
                &[("alive", 0.0), ("mode", 1.0)],
            );
        }
        frames = plant.step(t);
        t += 100_000;
    }
    (t, frames)
}

#[test]
fn the_vehicle_dives_to_the_commanded_depth_while_the_heartbeat_comes() {
    let mut plant = AuvPlant::new(dbc(), SimFaults::default());
    let (t, frames) = fly(&mut plant, 0, 5, true);
    // Thrusters not enabled: at the surface.
    assert_eq!(value(&frames, "Depth", "depth"), Some(0.0));
    command(&mut plant, t, "DepthCmd", &[("target", 10.0)]);
    command(
        &mut plant,
        t,
        "ThrusterCmd",
        &[("rpm_left", 1000.0), ("rpm_right", 1000.0), ("enable", 1.0)],
    );
    // 0.5 m per 100 ms at 1,000 rpm: 10 m in 20 ticks.
    let (t, frames) = fly(&mut plant, t, 10, true);
    assert_eq!(value(&frames, "Depth", "depth"), Some(5.0));
    assert_eq!(value(&frames, "ThrusterStatus", "rpm_left"), Some(1000.0));
    let (t, frames) = fly(&mut plant, t, 15, true);
    assert_eq!(value(&frames, "Depth", "depth"), Some(10.0));

    // The heartbeat stops: 300 ms later the thrusters stop and the vehicle rises, slowly.
    let (t, frames) = fly(&mut plant, t, 4, false);
    assert!(!plant.thrusting(t));
    assert_eq!(value(&frames, "ThrusterStatus", "rpm_left"), Some(0.0));
    let d = value(&frames, "Depth", "depth").unwrap();
    assert!(d < 10.0 && d > 9.0, "{d}");

    // Disabled: no thrust even with the heartbeat; back up to the surface in time.
    command(
        &mut plant,
        t,
        "ThrusterCmd",
        &[("rpm_left", 1000.0), ("rpm_right", 1000.0), ("enable", 0.0)],
    );
    let (_, frames) = fly(&mut plant, t, 250, true);
    assert_eq!(value(&frames, "Depth", "depth"), Some(0.0));
}

#[test]
fn the_hull_leaks_at_its_depth_and_the_battery_reports_every_second() {
    let mut plant = AuvPlant::new(
        dbc(),
        SimFaults {
            leak_at_depth: Some(2.0),
        },
    );
    command(&mut plant, 0, "DepthCmd", &[("target", 5.0)]);
    command(
        &mut plant,
        0,
        "ThrusterCmd",
        &[("rpm_left", 1000.0), ("rpm_right", 1000.0), ("enable", 1.0)],
    );
    let mut batteries = 0;
    let mut leak_from = None;
    for tick in 0..30u64 {
        let t = tick * 100_000;
        command(
            &mut plant,
            t,
            "SupervisorHeartbeat",
            &[("alive", 0.0), ("mode", 1.0)],
        );
        let frames = plant.step(t);
        if value(&frames, "Battery", "voltage").is_some() {
            batteries += 1;
        }
        let leak = value(&frames, "Leak", "leak") == Some(1.0);
        if leak_from.is_none() && leak {
            leak_from = Some(value(&frames, "Depth", "depth").unwrap());
        }
        // Once set, the bit stays: the water is in.
        assert_eq!(leak, leak_from.is_some());
        assert_eq!(value(&frames, "Leak", "sensor_ok"), Some(1.0));
    }
    assert_eq!(batteries, 3);
    assert_eq!(leak_from, Some(2.0));
}
