//! Replaying a recorded bus into the data server's core, to reproduce a mission's events
//! offline.
//!
//! Frames received (`R`, or no direction) go to [`BridgeCore::on_frame`], frames the bridge
//! sent (`T`: commands, heartbeats) to [`BridgeCore::on_sent`], each at its recorded time, so
//! that the events come out with the same parameters and the same timestamps as in flight.
//! As fast as possible, nothing waits; time-faithfully, each record waits for its instant on
//! the injected [`Clock`] (scaled by a speed factor), which changes when events come out, not
//! what they are.

use crate::bridge::BridgeCore;
use crate::clock::Clock;
use crate::event::EventOut;
use crate::log::{read_log, Direction, LogError, LogRecord};

/// How fast a log is replayed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pacing {
    /// Every record at once.
    AsFastAsPossible,
    /// Each record at its recorded offset from the first, divided by `speed` (1.0: real time,
    /// 2.0: twice as fast), on the injected clock.
    TimeFaithful {
        /// The speed factor (above 0; anything else is read as 1.0).
        speed: f64,
    },
}

/// Replays `records` into `core`; returns every event, in order, with its recorded time.
pub fn replay<'a>(
    core: &mut BridgeCore,
    records: impl IntoIterator<Item = &'a LogRecord>,
    pacing: Pacing,
    clock: &dyn Clock,
) -> Vec<EventOut> {
    let mut events = Vec::new();
    let mut origin: Option<(u64, u64)> = None;
    for r in records {
        if let Pacing::TimeFaithful { speed } = pacing {
            let speed = if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            };
            let (first, wall0) = *origin.get_or_insert((r.time_us, clock.now_us()));
            let offset = (r.time_us.saturating_sub(first) as f64 / speed) as u64;
            clock.sleep_until_us(wall0.saturating_add(offset));
        }
        match r.direction {
            Some(Direction::Transmitted) => events.extend(core.on_sent(r.time_us, &r.frame)),
            _ => events.extend(core.on_frame(r.time_us, &r.frame).events),
        }
    }
    events
}

/// Reads a `candump -L` log and replays it; a malformed line is an error (with its number)
/// before anything is replayed.
pub fn replay_text(
    core: &mut BridgeCore,
    text: &str,
    pacing: Pacing,
    clock: &dyn Clock,
) -> Result<Vec<EventOut>, LogError> {
    let records = read_log(text)?;
    Ok(replay(core, &records, pacing, clock))
}
