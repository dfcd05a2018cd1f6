//! The candump -L log: round trips, malformed lines, and replay to the same events.

mod common;

use common::{config, dbc};
use petrel_can_bridge::bridge::BridgeCore;
use petrel_can_bridge::clock::{Clock, ManualClock};
use petrel_can_bridge::frame::{err, CanId, Frame};
use petrel_can_bridge::log::{
    format_record, parse_line, read_log, Direction, LogError, LogLineError, LogRecord, LogWriter,
};
use petrel_can_bridge::replay::{replay, replay_text, Pacing};
use proptest::prelude::*;

const MS: u64 = 1000;

#[test]
fn every_kind_of_line_reads_and_writes_back_identically() {
    let lines = [
        "(1700000000.123456) vcan0 123#DEADBEEF",
        "(1700000000.123457) vcan0 123#",
        "(1700000000.123789) vcan0 18FF0100#0102",
        "(1700000000.124000) can0 123##1AABBCCDD",
        "(1700000000.124001) can0 12345678##500112233445566778899AABB",
        "(1700000000.125000) vcan0 123#R",
        "(1700000000.125001) vcan0 123#R3",
        "(1700000000.126000) vcan0 20000040#0000000000000000",
        "(1700000000.126001) vcan0 20000004#000C000000000000",
        "(1700000000.127000) vcan0 123#1122334455667788_C",
        "(0.000001) mem0 7FF#00 T",
        "(12.000000) mem0 000#01 R",
    ];
    for line in lines {
        let r = parse_line(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        assert_eq!(format_record(&r), line);
    }
    let r = parse_line(lines[0]).unwrap();
    assert_eq!(r.time_us, 1_700_000_000_123_456);
    assert_eq!(r.interface, "vcan0");
    assert_eq!(r.frame.id(), CanId::Standard(0x123));
    assert_eq!(r.frame.payload(), &[0xDE, 0xAD, 0xBE, 0xEF]);
    let e = parse_line(lines[7]).unwrap();
    assert!(e.frame.is_error());
    assert_eq!(e.frame.error_class(), err::BUSOFF);
    assert_eq!(
        parse_line(lines[10]).unwrap().direction,
        Some(Direction::Transmitted)
    );
    // Lowercase hex reads too (and is written back uppercase).
    let r = parse_line("(1.000000) vcan0 1ab#beef").unwrap();
    assert_eq!(format_record(&r), "(1.000000) vcan0 1AB#BEEF");
}

#[test]
fn malformed_lines_are_errors_with_their_line_number() {
    type Check = fn(&LogLineError) -> bool;
    let cases: &[(&str, Check)] = &[
        ("1700000000.1 vcan0 123#00", |e| {
            matches!(e, LogLineError::Timestamp(_))
        }),
        ("(1700000000.12345) vcan0 123#00", |e| {
            matches!(e, LogLineError::Timestamp(_))
        }),
        ("(1700000000.123456)", |e| {
            matches!(e, LogLineError::MissingInterface)
        }),
        ("(1700000000.123456) vcan0", |e| {
            matches!(e, LogLineError::MissingFrame)
        }),
        ("(1700000000.123456) vcan0 12300", |e| {
            matches!(e, LogLineError::MissingSeparator(_))
        }),
        ("(1700000000.123456) vcan0 800#00", |e| {
            matches!(e, LogLineError::Identifier(_))
        }),
        ("(1700000000.123456) vcan0 12#00", |e| {
            matches!(e, LogLineError::Identifier(_))
        }),
        ("(1700000000.123456) vcan0 4FFFFFFF#00", |e| {
            matches!(e, LogLineError::Identifier(_))
        }),
        ("(1700000000.123456) vcan0 123#0", |e| {
            matches!(e, LogLineError::Data(_))
        }),
        ("(1700000000.123456) vcan0 123#001122334455667788", |e| {
            matches!(e, LogLineError::Data(_))
        }),
        ("(1700000000.123456) vcan0 123#ZZ", |e| {
            matches!(e, LogLineError::Data(_))
        }),
        ("(1700000000.123456) vcan0 123#R9", |e| {
            matches!(e, LogLineError::RemoteDlc(_))
        }),
        ("(1700000000.123456) vcan0 123##G00", |e| {
            matches!(e, LogLineError::Fd(_))
        }),
        ("(1700000000.123456) vcan0 123##1001122334455667788", |e| {
            matches!(e, LogLineError::Fd(_))
        }),
        ("(1700000000.123456) vcan0 123#0011_C", |e| {
            matches!(e, LogLineError::Len8Dlc(_))
        }),
        ("(1700000000.123456) vcan0 123#00 X", |e| {
            matches!(e, LogLineError::TrailingText(_))
        }),
        ("(99999999999999999999.000000) vcan0 123#00", |e| {
            matches!(e, LogLineError::Timestamp(_))
        }),
    ];
    for (line, check) in cases {
        let text = format!("(1.000000) vcan0 123#00\n\n{line}\n(2.000000) vcan0 123#00\n");
        match read_log(&text) {
            Err(LogError::Line { line: 3, error }) => {
                assert!(check(&error), "{line}: {error:?}");
                assert!(!error.to_string().is_empty());
            }
            other => panic!("{line}: {other:?}"),
        }
    }
    let e = read_log("(1.000000) vcan0 123#0\n").unwrap_err();
    assert_eq!(
        e.to_string(),
        "line 1: `0` is not frame data: pairs of hex digits, at most 8 bytes (64 for CAN FD)"
    );
}

proptest! {
    /// Any line is an error or a record, never a panic; a record writes back to a line that
    /// reads as the same record.
    #[test]
    fn lines_never_panic(line in "\\(?[0-9]{0,3}\\.?[0-9]{0,7}\\)? ?[a-z0-9]{0,5} ?[0-9A-Fa-f]{0,9}#{0,2}[0-9A-FRa-f_]{0,20} ?[RTX]?") {
        if let Ok(r) = parse_line(&line) {
            prop_assert_eq!(parse_line(&format_record(&r)).unwrap(), r);
        }
    }

    /// Data frames round-trip through the log.
    #[test]
    fn frames_round_trip(id in 0u32..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8), t in 0u64..4_000_000_000_000_000) {
        let r = LogRecord {
            time_us: t,
            interface: "vcan0".into(),
            frame: Frame::data(CanId::standard(id).unwrap(), &data).unwrap(),
            direction: None,
        };
        prop_assert_eq!(parse_line(&format_record(&r)).unwrap(), r);
    }
}

/// A dive as the bus carries it: depth every 100 ms going down to 30 m, the supervisor's depth
/// command, a leak, an AHRS that stops, garbage, a bus fault.
fn dive(dbc: &petrel_can_bridge::Dbc) -> Vec<LogRecord> {
    let mut out = Vec::new();
    let mut push = |t: u64, frame: Frame, direction: Option<Direction>| {
        out.push(LogRecord {
            time_us: 1_700_000_000_000_000 + t,
            interface: "vcan0".into(),
            frame,
            direction,
        })
    };
    push(
        0,
        dbc.encode("DepthCmd", &[("target", 30.0)]).unwrap(),
        Some(Direction::Transmitted),
    );
    for i in 0..60u64 {
        let t = i * 100 * MS;
        let depth = (i as f64 * 0.8).min(30.2);
        push(
            t + 10 * MS,
            dbc.encode("Depth", &[("depth", depth), ("status", 0.0)])
                .unwrap(),
            None,
        );
        if i < 20 {
            push(
                t + 20 * MS,
                dbc.encode("Ahrs", &[("heading", 90.0), ("pitch", -5.0), ("roll", 0.0)])
                    .unwrap(),
                Some(Direction::Received),
            );
        }
        let leak = f64::from(u8::from((40..43).contains(&i)));
        push(
            t + 30 * MS,
            dbc.encode("Leak", &[("leak", leak), ("sensor_ok", 1.0)])
                .unwrap(),
            None,
        );
    }
    push(
        3_100 * MS,
        Frame::data(CanId::Standard(0x7FF), &[1, 2, 3]).unwrap(),
        None,
    );
    push(
        3_200 * MS,
        Frame::data(CanId::Standard(0x200), &[1]).unwrap(),
        None,
    );
    push(3_300 * MS, Frame::error(err::BUSOFF, [0; 8]).unwrap(), None);
    push(
        3_400 * MS,
        Frame::error(err::RESTARTED, [0; 8]).unwrap(),
        None,
    );
    out.sort_by_key(|r| r.time_us);
    out
}

#[test]
fn a_recorded_mission_replays_to_the_same_events() {
    let dbc = dbc();
    let records = dive(&dbc);
    let start = records[0].time_us;
    // Live: the core fed frame by frame, recording the bus as it goes.
    let mut live = BridgeCore::new(dbc.clone(), config(), start);
    let mut writer = LogWriter::new(Vec::new());
    let mut live_events = Vec::new();
    for r in &records {
        writer.write(r).unwrap();
        match r.direction {
            Some(Direction::Transmitted) => live_events.extend(live.on_sent(r.time_us, &r.frame)),
            _ => live_events.extend(live.on_frame(r.time_us, &r.frame).events),
        }
    }
    let text = String::from_utf8(writer.into_inner()).unwrap();
    assert_eq!(text.lines().count(), records.len());
    let names: Vec<&str> = live_events.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(
        names,
        // AHRS silent from 1.92 s: lost 500 ms later; bus-off at 3.3 s and back at 3.4 s;
        // 29.6 m (within 0.5 of 30) at 3.71 s; the leak set from 4.03 s for 200 ms.
        [
            "sensor_lost",
            "bus_fault",
            "bus_lost",
            "bus_fault",
            "depth_reached",
            "leak",
        ],
        "{live_events:#?}"
    );
    // Offline, as fast as possible: the same events, times and parameters.
    let clock = ManualClock::new(0);
    let mut offline = BridgeCore::new(dbc.clone(), config(), start);
    let replayed = replay_text(&mut offline, &text, Pacing::AsFastAsPossible, &clock).unwrap();
    assert_eq!(replayed, live_events);
    assert_eq!(offline.counters(), live.counters());
    assert_eq!(clock.now_us(), 0, "as fast as possible never waits");
    // Time-faithfully at 10x on a manual clock: the same events; the clock ran the log's span
    // divided by 10.
    let clock = ManualClock::new(5_000_000);
    let mut faithful = BridgeCore::new(dbc.clone(), config(), start);
    let again = replay(
        &mut faithful,
        &read_log(&text).unwrap(),
        Pacing::TimeFaithful { speed: 10.0 },
        &clock,
    );
    assert_eq!(again, live_events);
    let span = records.last().unwrap().time_us - start;
    assert_eq!(clock.now_us(), 5_000_000 + span / 10);
    // The counters saw the garbage.
    let c = offline.counters();
    assert_eq!((c.unknown_id, c.wrong_length, c.error_frames), (1, 1, 2));
}
