//! The data server's core over the memory bus: garbage, a simulated dive end to end,
//! commands, the heartbeat, bus-off and back-pressure.

mod common;

use std::sync::Arc;

use common::{config, dbc};
use petrel_can_bridge::bridge::{BridgeCore, CommandError};
use petrel_can_bridge::bus::{Bus, BusError, MemoryHub, Sent};
use petrel_can_bridge::bus_state::{state_from_error_frame, BusState};
use petrel_can_bridge::clock::{Clock, ManualClock};
use petrel_can_bridge::dbc::{DecodeOutcome, EncodeError, ValueError};
use petrel_can_bridge::event::EventOut;
use petrel_can_bridge::frame::{err, CanId, Frame};
use petrel_nets::compiled::Value;
use proptest::prelude::*;

const MS: u64 = 1000;

#[test]
fn garbage_frames_are_counted_without_a_crash() {
    let dbc = dbc();
    let mut core = BridgeCore::new(dbc.clone(), config(), 0);
    let frames = [
        Frame::data(CanId::Standard(0x7FF), &[1, 2, 3]).unwrap(), // unknown
        Frame::data(CanId::Extended(0x200), &[1, 2, 3]).unwrap(), // unknown (29-bit)
        Frame::data(CanId::Standard(0x200), &[1]).unwrap(),       // Depth, too short
        Frame::data(CanId::Standard(0x200), &[0; 8]).unwrap(),    // Depth, too long
        Frame::fd(CanId::Standard(0x210), &[0xFF; 64], 0x5).unwrap(), // Ahrs as FD, too long
        Frame::remote(CanId::Standard(0x200), 3).unwrap(),
        Frame::error(err::PROT | err::BUSERROR, [0, 0, 0x08, 0x02, 0, 0, 0, 0]).unwrap(),
        Frame::error(0, [0; 8]).unwrap(),
        Frame::data(CanId::Standard(0x260), &[0x00, 0x00, 0xC0, 0x7F]).unwrap(), // Sonar: NaN
    ];
    let mut events = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let report = core.on_frame(i as u64 * MS, f);
        events.extend(report.events);
    }
    let c = core.counters();
    assert_eq!(c.frames, 9);
    assert_eq!(c.unknown_id, 2);
    assert_eq!(c.wrong_length, 3);
    assert_eq!(c.remote, 1);
    assert_eq!(c.error_frames, 2);
    assert_eq!(c.decoded, 1);
    assert_eq!(c.decode_errors, 1, "a NaN float is a decode error");
    // Protocol errors change no state: no event.
    assert!(events.is_empty(), "{events:?}");
    assert_eq!(core.bus_state(), BusState::ErrorActive);
    assert_eq!(
        core.on_frame(10 * MS, &frames[2]).outcome,
        DecodeOutcome::WrongLength {
            message: dbc.message_by_name("Depth").unwrap(),
            expected: 3,
            got: 1
        }
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Any sequence of frames, whatever their kind: counted, never a panic.
    #[test]
    fn random_traffic_never_panics(frames in proptest::collection::vec((0u32..0x800, any::<bool>(), proptest::collection::vec(any::<u8>(), 0..=8), 0u8..4), 0..64)) {
        let mut core = BridgeCore::new(dbc(), config(), 0);
        for (i, (id, ext, data, kind)) in frames.iter().enumerate() {
            let cid = if *ext { CanId::Extended(*id) } else { CanId::Standard(*id as u16) };
            let f = match kind {
                0 => Frame::data(cid, data).unwrap(),
                1 => Frame::remote(cid, data.len() as u8).unwrap(),
                2 => Frame::error(*id, data.iter().copied().chain([0; 8]).take(8).collect::<Vec<_>>().try_into().unwrap()).unwrap(),
                _ => Frame::fd(cid, &[data.clone(), data.clone()].concat()[..data.len().min(8)], 1).unwrap(),
            };
            let _ = core.on_frame(i as u64 * 10 * MS, &f);
            let _ = core.on_time(i as u64 * 10 * MS + 5 * MS);
        }
        prop_assert_eq!(core.counters().frames, frames.len() as u64);
    }
}

#[test]
fn error_frames_tell_the_bus_state() {
    let e = |class, d1| Frame::error(class, [0, d1, 0, 0, 0, 0, 0, 0]).unwrap();
    assert_eq!(
        state_from_error_frame(&e(err::BUSOFF, 0)),
        Some(BusState::BusOff)
    );
    assert_eq!(
        state_from_error_frame(&e(err::CRTL, err::CRTL_TX_PASSIVE)),
        Some(BusState::ErrorPassive)
    );
    assert_eq!(
        state_from_error_frame(&e(err::CRTL, err::CRTL_RX_WARNING)),
        Some(BusState::ErrorWarning)
    );
    assert_eq!(
        state_from_error_frame(&e(err::CRTL, err::CRTL_ACTIVE)),
        Some(BusState::ErrorActive)
    );
    assert_eq!(
        state_from_error_frame(&e(err::RESTARTED, 0)),
        Some(BusState::ErrorActive)
    );
    assert_eq!(state_from_error_frame(&e(err::ACK, 0)), None);
    let counters = Frame::error(err::CNT, [0, 0, 0, 0, 0, 0, 130, 5]).unwrap();
    assert_eq!(
        state_from_error_frame(&counters),
        Some(BusState::ErrorPassive)
    );
    assert_eq!(
        petrel_can_bridge::bus_state::describe_error_frame(&e(err::BUSOFF | err::CRTL, 0)),
        "controller problem, bus-off"
    );
}

/// Drains the bridge's endpoint into the core; returns the events.
fn pump(core: &mut BridgeCore, bus: &mut impl Bus) -> Vec<EventOut> {
    let mut out = Vec::new();
    while let Some(tf) = bus.recv().unwrap() {
        out.extend(core.on_frame(tf.time_us, &tf.frame).events);
    }
    out
}

#[test]
fn a_simulated_dive_end_to_end_on_the_memory_bus() {
    let clock = ManualClock::new(1_000_000);
    let hub = MemoryHub::new(Arc::new(clock.clone()));
    let mut bridge_bus = hub.endpoint("mem0").unwrap();
    let mut sensor = hub.endpoint("depth_sensor").unwrap();
    let mut thrusters = hub.endpoint("thrusters").unwrap();
    let dbc = dbc();
    let mut c = config();
    c.rules.retain(|r| r.event != "sensor_lost");
    let mut core = BridgeCore::new(dbc.clone(), c, clock.now_us());

    // The supervisor commands 30 m and the thrusters, as the player's calls would.
    let target = core
        .command_call("DepthCmd", &[Value::Float(30.0)])
        .unwrap();
    assert_eq!(bridge_bus.send(&target).unwrap(), Sent::Now);
    assert!(core.on_sent(clock.now_us(), &target).is_empty());
    let cmd = core
        .command_call(
            "ThrusterCmd",
            &[Value::Int(-1500), Value::Float(1500.0), Value::Bool(true)],
        )
        .unwrap();
    bridge_bus.send(&cmd).unwrap();
    // The thrusters see the DBC's bytes: -1500 = 0xFA24, 1500 = 0x05DC, enable at bit 32.
    let got = thrusters.recv().unwrap().unwrap();
    assert_eq!(got.frame.id(), CanId::Standard(0x120));
    let got = thrusters.recv().unwrap().unwrap();
    assert_eq!(got.frame.id(), CanId::Standard(0x100));
    assert_eq!(got.frame.payload(), &[0x24, 0xFA, 0xDC, 0x05, 0x01]);

    // The depth sensor node descends 1 m every 100 ms.
    let mut events = Vec::new();
    for i in 0..40 {
        clock.advance(100 * MS);
        let depth = f64::from(i).min(30.2);
        let f = dbc
            .encode("Depth", &[("depth", depth), ("status", 0.0)])
            .unwrap();
        sensor.send(&f).unwrap();
        events.extend(pump(&mut core, &mut bridge_bus));
        events.extend(core.on_time(clock.now_us()));
        while let Some(hb) = core.poll_heartbeat(clock.now_us()) {
            bridge_bus.send(&hb).unwrap();
        }
    }
    let reached: Vec<&EventOut> = events
        .iter()
        .filter(|e| e.name == "depth_reached")
        .collect();
    assert_eq!(reached.len(), 1, "{events:?}");
    // 30 m at i = 30: 1 s + 31 x 100 ms.
    assert_eq!(reached[0].time_us, 1_000_000 + 31 * 100 * MS);
    assert_eq!(reached[0].params, vec![Value::Float(30.0)]);
    let latest = core.signals().get_path(&dbc, "Depth.depth").unwrap();
    assert!((latest.physical - 30.2).abs() < 1e-9, "{latest:?}");

    // The heartbeat went out every 100 ms with its counter; the thrusters saw them.
    let mut alive = Vec::new();
    while let Some(tf) = thrusters.recv().unwrap() {
        if tf.frame.id() == CanId::Standard(0x110) {
            // alive in byte 0, mode "mission" (1) in byte 1.
            assert_eq!(tf.frame.payload()[1], 1);
            alive.push(tf.frame.payload()[0]);
        }
    }
    assert_eq!(alive, (0..40).collect::<Vec<u8>>());

    // Bus-off: the bridge hears it as an error frame and says so; frames wait meanwhile.
    hub.set_state(BusState::BusOff);
    let faults = pump(&mut core, &mut bridge_bus);
    let names: Vec<(&str, &[Value])> = faults
        .iter()
        .map(|e| (e.name.as_str(), &e.params[..]))
        .collect();
    assert_eq!(
        names,
        [
            ("bus_fault", &[Value::Text("bus_off".into())][..]),
            ("bus_lost", &[][..])
        ]
    );
    let again = core
        .command("ThrusterCmd", &[("rpm_left", Value::Int(0))])
        .unwrap();
    assert_eq!(bridge_bus.send(&again).unwrap(), Sent::Queued { queued: 1 });
    assert!(thrusters
        .recv()
        .unwrap()
        .is_some_and(|f| f.frame.is_error()));
    assert!(thrusters.recv().unwrap().is_none());
    bridge_bus.restart().unwrap();
    assert_eq!(bridge_bus.flush().unwrap(), 0);
    // The restart (an error frame) and the waiting command; its other signals kept their
    // last commanded values (rpm_right 1500, enable 1).
    let restarted = thrusters.recv().unwrap().unwrap();
    assert!(restarted.frame.is_error());
    let sent = thrusters.recv().unwrap().unwrap();
    assert_eq!(sent.frame.payload(), &[0x00, 0x00, 0xDC, 0x05, 0x01]);
    let back = pump(&mut core, &mut bridge_bus);
    assert_eq!(back[0].params, vec![Value::Text("error_active".into())]);
    assert_eq!(bridge_bus.stats().deferred, 1);
}

#[test]
fn commands_are_checked_before_they_become_frames() {
    let mut core = BridgeCore::new(dbc(), config(), 0);
    let e = core
        .command("Depth", &[("depth", Value::Float(1.0))])
        .unwrap_err();
    assert!(matches!(e, CommandError::NotAllowed(_)), "{e}");
    let e = core
        .command("ThrusterCmd", &[("rpm_left", Value::Float(5000.0))])
        .unwrap_err();
    assert!(
        matches!(&e, CommandError::Encode(EncodeError::Value { signal, error: ValueError::OutOfRange { .. }, .. }) if signal == "rpm_left"),
        "{e}"
    );
    let e = core
        .command_call("ThrusterCmd", &[Value::Int(1)])
        .unwrap_err();
    assert!(
        matches!(
            e,
            CommandError::Arity {
                expected: 3,
                got: 1,
                ..
            }
        ),
        "{e}"
    );
    let e = core
        .command("ThrusterCmd", &[("enable", Value::Text("yes".into()))])
        .unwrap_err();
    assert!(matches!(e, CommandError::UnknownLabel { .. }), "{e}");
    assert_eq!(core.counters().commands_refused, 4);
    // Signals not given take the DBC's GenSigStartValue (0) on the first command.
    let f = core
        .command("ThrusterCmd", &[("rpm_left", Value::Int(10))])
        .unwrap();
    assert_eq!(f.payload(), &[10, 0, 0, 0, 0]);
}

#[test]
fn back_pressure_queues_then_refuses_never_drops() {
    let clock: Arc<dyn Clock> = Arc::new(ManualClock::new(0));
    let hub = MemoryHub::new(clock);
    let mut a = hub.endpoint("a").unwrap();
    let mut b = hub.endpoint("b").unwrap();
    a.set_tx_capacity(3);
    hub.set_tx_blocked(true);
    let f = |i: u8| Frame::data(CanId::Standard(0x100), &[i]).unwrap();
    for i in 0..3 {
        assert_eq!(
            a.send(&f(i)).unwrap(),
            Sent::Queued {
                queued: usize::from(i) + 1
            }
        );
    }
    match a.send(&f(3)) {
        Err(BusError::QueueFull { frame, capacity: 3 }) => assert_eq!(frame, f(3)),
        other => panic!("{other:?}"),
    }
    assert!(b.recv().unwrap().is_none());
    hub.set_tx_blocked(false);
    // The next send goes behind the waiting ones: order kept.
    assert_eq!(a.send(&f(4)).unwrap(), Sent::Now);
    let got: Vec<u8> = std::iter::from_fn(|| b.recv().unwrap())
        .map(|t| t.frame.payload()[0])
        .collect();
    assert_eq!(got, [0, 1, 2, 4]);
    let s = a.stats();
    assert_eq!((s.sent, s.deferred, s.refused), (4, 3, 1));
}

#[test]
fn the_memory_bus_wakes_a_waiting_reactor() {
    let clock: Arc<dyn Clock> = Arc::new(ManualClock::new(0));
    let (mut a, mut b) = MemoryHub::pair(clock, "a", "b").unwrap();
    let reactor =
        petrel_ipc::Reactor::without_signal_handling(petrel_ipc::WaitStrategy::Block).unwrap();
    let fd = petrel_ipc::FdSource::new(b.wait_fd().unwrap()).unwrap();
    let ready = reactor
        .wait(&[&fd], Some(std::time::Duration::from_millis(20)))
        .unwrap();
    assert!(ready.timed_out());
    a.send(&Frame::data(CanId::Standard(1), &[1]).unwrap())
        .unwrap();
    let ready = reactor
        .wait(&[&fd], Some(std::time::Duration::from_secs(5)))
        .unwrap();
    assert!(ready.is_ready(0));
    assert!(b.recv().unwrap().is_some());
    // Drained: the descriptor is quiet again.
    let ready = reactor
        .wait(&[&fd], Some(std::time::Duration::from_millis(20)))
        .unwrap();
    assert!(ready.timed_out());
}
