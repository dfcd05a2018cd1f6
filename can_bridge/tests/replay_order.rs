//! Replaying a log whose time goes back, or whose frames have the wrong length (issue 10,
//! item 9): warned, counted, with the lines, and no false event.

mod common;

use petrel_can_bridge::replay::{replay_counted, Pacing};
use petrel_can_bridge::{BridgeCore, ManualClock};

/// Three seconds of a healthy bus: depth every 100 ms, AHRS every 50 ms, battery at 24 V.
fn healthy() -> Vec<(u64, String)> {
    let mut lines = Vec::new();
    for i in 0..60u64 {
        let t = 1_000_000_000 + i * 50_000;
        // AHRS: 6 bytes.
        lines.push((t, "210#000000000000".to_string()));
        if i % 2 == 0 {
            // Depth 10 m: raw (10 + 5) / 0.01 = 1500 = 0x05DC, big-endian from bit 7; status 0.
            lines.push((t + 1, "200#05DC00".to_string()));
        }
        if i % 20 == 0 {
            // Battery 24.00 V: raw 2400 = 0x0960 little-endian, current 0, state 0.
            lines.push((t + 2, "230#6009000000".to_string()));
        }
    }
    lines
}

fn log(lines: &[(u64, String)]) -> String {
    lines
        .iter()
        .map(|(t, f)| format!("({}.{:06}) vcan0 {f} R\n", t / 1_000_000, t % 1_000_000))
        .collect()
}

fn replay(text: &str) -> petrel_can_bridge::replay::Replayed {
    let start = 1_000_000_000;
    let mut core = BridgeCore::new(common::dbc(), common::config(), start);
    replay_counted(
        &mut core,
        text,
        Pacing::AsFastAsPossible,
        &ManualClock::new(0),
    )
    .expect("the log reads")
}

/// Before: a depth frame recorded late in the file, with an earlier time, moved its staleness
/// deadline back, and the next frame found it passed: a false `sensor_lost`, with no warning.
#[test]
fn records_going_back_in_time_are_warned_with_their_lines_and_fire_nothing_false() {
    let ordered = healthy();
    let clean = replay(&log(&ordered));
    assert!(clean.events.is_empty(), "{:?}", clean.events);
    assert_eq!(clean.summary.time_backwards, 0);
    // As from two interfaces merged with a skew: every tenth depth frame is written eight
    // records (about 250 ms) late.
    let mut skewed = ordered.clone();
    let mut moved = Vec::new();
    let mut i = 0;
    while i + 9 < skewed.len() {
        if skewed[i].1.starts_with("200#") && (i / 3) % 10 == 0 {
            let r = skewed.remove(i);
            skewed.insert(i + 8, r);
            moved.push(i + 8 + 1);
            i += 9;
        } else {
            i += 1;
        }
    }
    assert!(moved.len() >= 3, "{moved:?}");
    let r = replay(&log(&skewed));
    let lost: Vec<_> = r
        .events
        .iter()
        .filter(|e| e.name == "sensor_lost")
        .collect();
    assert!(lost.is_empty(), "false sensor_lost: {lost:?}");
    assert_eq!(r.summary.time_backwards, moved.len() as u64);
    let lines: Vec<usize> = r.summary.backwards.iter().map(|b| b.line).collect();
    assert_eq!(lines, moved);
    let text = r.summary.backwards[0].to_string();
    assert!(
        text.starts_with(&format!("line {}: time goes back from", moved[0])),
        "{text}"
    );
    // Every frame was still taken, in the file's order.
    assert_eq!(r.summary.records, ordered.len() as u64);
    assert_eq!(r.summary.counters.decoded, ordered.len() as u64);
}

/// Before: battery frames one byte short were dropped with no count anywhere a replay
/// showed, and `low_battery` silently never fired.
#[test]
fn frames_of_the_wrong_length_are_counted_in_the_summary() {
    let mut lines = healthy();
    // 21.00 V (raw 2100 = 0x0834): low; first in 5 bytes, then in 4.
    lines.push((1_003_000_000, "230#3408000000".to_string()));
    let r = replay(&log(&lines));
    assert_eq!(r.events.len(), 1, "{:?}", r.events);
    assert_eq!(r.events[0].name, "low_battery");
    assert_eq!(r.summary.counters.wrong_length, 0);
    let last = lines.len() - 1;
    lines[last].1 = "230#34080000".to_string();
    let r = replay(&log(&lines));
    assert!(r.events.is_empty(), "{:?}", r.events);
    assert_eq!(r.summary.counters.wrong_length, 1);
    let text = r.summary.to_string();
    assert!(
        text.contains("1 of a length other than the DBC's (dropped)"),
        "{text}"
    );
}
