//! The process loop over the memory bus and real iceoryx2 services: frames from a simulated
//! sensor become player events, a call becomes a frame, and the recording replays to the same
//! events.

mod common;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{config, dbc};
use petrel_can_bridge::bridge::BridgeCore;
use petrel_can_bridge::bus::{Bus, MemoryHub};
use petrel_can_bridge::clock::{Clock, ManualClock, SystemClock};
use petrel_can_bridge::frame::CanId;
use petrel_can_bridge::replay::{replay_text, Pacing};
use petrel_can_bridge::runtime::{event_msg, run, RuntimeOptions};
use petrel_ipc::{CallMsg, EventMsg, IsolatedVehicle, Participant, Role, SendError, Value};

#[test]
fn the_bridge_process_loop_over_iceoryx2() {
    let vehicle = IsolatedVehicle::new("auv").unwrap();
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let hub = MemoryHub::new(clock.clone());
    let bridge_bus = hub.endpoint("mem0").unwrap();
    let mut sensor = hub.endpoint("depth").unwrap();
    let mut thrusters = hub.endpoint("thrusters").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let log_path = dir.path().join("bus.log");

    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let events = player.event_receiver().unwrap();

    let stop = Arc::new(AtomicBool::new(false));
    let start = clock.now_us();
    let bridge = {
        let (vehicle, stop, clock, log_path) = (
            vehicle.clone(),
            stop.clone(),
            clock.clone(),
            log_path.clone(),
        );
        std::thread::spawn(move || {
            let core = BridgeCore::new(dbc(), config(), start);
            let opts = RuntimeOptions {
                record: Some(Box::new(std::io::BufWriter::new(
                    std::fs::File::create(&log_path).unwrap(),
                ))),
                handle_signals: false,
                // The fake player sends no heartbeat to acknowledge with.
                ack_grace: Duration::ZERO,
                ..RuntimeOptions::default()
            };
            run(core, move || Ok(bridge_bus), clock, &vehicle, opts, &stop)
        })
    };

    // An operator tool commands 30 m through the bridge's program, CAN.
    let tool = Participant::join(&vehicle, Role::tool("op").unwrap()).unwrap();
    let to_can = tool.call_sender("CAN").unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match to_can.send(&CallMsg::new("DepthCmd", vec![Value::Float(30.0)])) {
            Ok(_) => break,
            Err(SendError::NoReceiver { .. }) if Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(5))
            }
            Err(e) => panic!("{e}"),
        }
    }
    // The thrusters' side of the bus sees the command (and heartbeats).
    let dbc = dbc();
    let mut saw_command = false;
    while !saw_command && Instant::now() < deadline {
        while let Some(tf) = thrusters.recv().unwrap() {
            if tf.frame.id() == CanId::Standard(0x120) {
                assert_eq!(tf.frame.payload(), &[0xB8, 0x0B]); // 3000 = 30.00 m
                saw_command = true;
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(saw_command, "no DepthCmd frame on the bus");
    // 400 m is beyond the DBC's [0|300]: refused, and the player hears it.
    to_can
        .send(&CallMsg::new("DepthCmd", vec![Value::Float(400.0)]))
        .unwrap();

    // The depth sensor descends to the target; the player receives depth_reached.
    let mut got: Vec<EventMsg> = Vec::new();
    let mut depth = 25.0;
    while !got.iter().any(|e| e.name == "depth_reached") && Instant::now() < deadline {
        depth = f64::min(depth + 0.5, 30.0);
        sensor
            .send(
                &dbc.encode("Depth", &[("depth", depth), ("status", 0.0)])
                    .unwrap(),
            )
            .unwrap();
        std::thread::sleep(Duration::from_millis(10));
        events.drain(|r| got.push(r.unwrap().msg)).unwrap();
    }
    let reached = got
        .iter()
        .find(|e| e.name == "depth_reached")
        .expect("depth_reached");
    assert!(
        matches!(reached.params[..], [Value::Float(d)] if (d - 29.5).abs() < 1e-6),
        "{reached:?}"
    );
    let failed = EventMsg::new(
        "call_failed",
        vec![Value::Text("CAN".into()), Value::Text("DepthCmd".into())],
    );
    while !got.contains(&failed) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
        events.drain(|r| got.push(r.unwrap().msg)).unwrap();
    }
    assert!(got.contains(&failed), "{got:?}");
    let received = events.senders();
    assert!(
        received.iter().any(|s| s.origin.as_str() == "can_bridge"),
        "{received:?}"
    );

    stop.store(true, Ordering::Relaxed);
    let report = bridge.join().unwrap().unwrap();
    assert_eq!(report.events_refused + report.events_dropped, 0);
    assert_eq!(report.commands_failed, 1, "{report:?}");
    assert!(report.counters.decoded >= 5, "{report:?}");
    assert!(report.counters.heartbeats >= 1, "{report:?}");

    // The recording replays offline to the same depth_reached, at the same instant.
    let text = std::fs::read_to_string(&log_path).unwrap();
    assert!(text.lines().count() as u64 >= report.counters.decoded);
    let mut offline = BridgeCore::new(dbc.clone(), config(), start);
    let replayed = replay_text(
        &mut offline,
        &text,
        Pacing::AsFastAsPossible,
        &ManualClock::new(0),
    )
    .unwrap();
    let live: Vec<&EventMsg> = got.iter().filter(|e| e.name == "depth_reached").collect();
    let replayed: Vec<EventMsg> = replayed.iter().map(event_msg).collect();
    let off: Vec<&EventMsg> = replayed
        .iter()
        .filter(|e| e.name == "depth_reached")
        .collect();
    assert_eq!(live, off);
}

#[test]
fn decoded_signals_are_published_as_latest_values_for_the_programs() {
    let vehicle = IsolatedVehicle::new("sig").unwrap();
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let hub = MemoryHub::new(clock.clone());
    let bridge_bus = hub.endpoint("mem0").unwrap();
    let mut sensor = hub.endpoint("depth").unwrap();
    // A program reading the signals, as a navigation program would.
    let reader = Participant::join(&vehicle, Role::program("NAV").unwrap()).unwrap();
    let signals = reader.signals_subscriber().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let start = clock.now_us();
    let bridge = {
        let (vehicle, stop, clock) = (vehicle.clone(), stop.clone(), clock.clone());
        std::thread::spawn(move || {
            let core = BridgeCore::new(dbc(), config(), start);
            let opts = RuntimeOptions {
                handle_signals: false,
                // The fake player sends no heartbeat to acknowledge with.
                ack_grace: Duration::ZERO,
                ..RuntimeOptions::default()
            };
            run(core, move || Ok(bridge_bus), clock, &vehicle, opts, &stop)
        })
    };
    let dbc = dbc();
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut latest = None;
    let mut depth = 10.0;
    while Instant::now() < deadline {
        sensor
            .send(
                &dbc.encode("Depth", &[("depth", depth), ("status", 0.0)])
                    .unwrap(),
            )
            .unwrap();
        std::thread::sleep(Duration::from_millis(20));
        signals
            .drain(|r| {
                if let Ok(rcv) = r {
                    latest = Some(rcv.msg);
                }
            })
            .unwrap();
        if latest.as_ref().and_then(|m| m.get("Depth.depth")) == Some(depth) && depth >= 12.0 {
            break;
        }
        depth += 0.5;
    }
    stop.store(true, Ordering::Relaxed);
    bridge.join().unwrap().unwrap();
    let msg = latest.expect("signals were published");
    // The newest depth, decoded with the DBC's scaling, and its status beside it.
    assert_eq!(msg.get("Depth.depth"), Some(depth), "{msg:?}");
    assert_eq!(msg.get("Depth.status"), Some(0.0), "{msg:?}");
    assert!(msg.time_us >= start);
}

/// The core is made, then the vehicle joined (seconds, on a loaded machine): silence counts
/// from the loop's first read, not from the core's creation. A depth sensor speaking every
/// 20 ms since before the bridge started is never reported lost; the AHRS, which never speaks,
/// is, once its 500 ms have passed.
#[test]
fn a_slow_start_does_not_make_a_speaking_sensor_look_lost() {
    let vehicle = IsolatedVehicle::new("slow").unwrap();
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let hub = MemoryHub::new(clock.clone());
    let bridge_bus = hub.endpoint("mem0").unwrap();
    let player = Participant::join(&vehicle, Role::Player).unwrap();
    let events = player.event_receiver().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let sensor = {
        let (hub, stop) = (hub.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut node = hub.endpoint("depth").unwrap();
            let frame = dbc()
                .encode("Depth", &[("depth", 3.0), ("status", 0.0)])
                .unwrap();
            while !stop.load(Ordering::Relaxed) {
                node.send(&frame).unwrap();
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };
    // As if joining the vehicle had taken five seconds since the core was made.
    let made_us = clock.now_us() - 5_000_000;
    let bridge = {
        let (vehicle, stop, clock) = (vehicle.clone(), stop.clone(), clock.clone());
        std::thread::spawn(move || {
            let core = BridgeCore::new(dbc(), config(), made_us);
            let opts = RuntimeOptions {
                handle_signals: false,
                // The fake player sends no heartbeat to acknowledge with.
                ack_grace: Duration::ZERO,
                ..RuntimeOptions::default()
            };
            run(core, move || Ok(bridge_bus), clock, &vehicle, opts, &stop)
        })
    };
    let mut got: Vec<EventMsg> = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    let ahrs = EventMsg::new("sensor_lost", vec![Value::Text("ahrs".into())]);
    while !got.contains(&ahrs) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
        events.drain(|r| got.push(r.unwrap().msg)).unwrap();
    }
    let lost_at = clock.now_us();
    // A few more depth periods: still nothing about the depth sensor.
    std::thread::sleep(Duration::from_millis(200));
    stop.store(true, Ordering::Relaxed);
    let report = bridge.join().unwrap().unwrap();
    sensor.join().unwrap();
    events.drain(|r| got.push(r.unwrap().msg)).unwrap();
    assert!(got.contains(&ahrs), "{got:?}");
    assert!(
        lost_at >= report.started_us + 500_000,
        "the AHRS was reported lost {} us after the loop began",
        lost_at - report.started_us
    );
    assert!(report.started_us >= made_us + 5_000_000);
    let depth_lost: Vec<_> = got
        .iter()
        .filter(|e| e.params == [Value::Text("depth".into())])
        .collect();
    assert!(depth_lost.is_empty(), "{got:?}");
    assert!(report.counters.decoded >= 10, "{report:?}");
}
