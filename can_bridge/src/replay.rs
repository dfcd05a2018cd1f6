//! Replaying a recorded bus into the data server's core, to reproduce a mission's events
//! offline.
//!
//! Frames received (`R`, or no direction) go to [`BridgeCore::on_frame`], frames the bridge
//! sent (`T`: commands, heartbeats) to [`BridgeCore::on_sent`], each at its recorded time, so
//! that the events come out with the same parameters and the same timestamps as in flight.
//! As fast as possible, nothing waits; time-faithfully, each record waits for its instant on
//! the injected [`Clock`] (scaled by a speed factor), which changes when events come out, not
//! what they are.
//!
//! Time in a log should only go forward, as it does on a live bus. A record whose time is
//! earlier than one before it (a shuffled or spliced log) is replayed at the latest time seen
//! so far, in the file's order, as the live data server would have taken it, and counted with
//! its line ([`ReplaySummary::time_backwards`]): fed its own earlier time, the rules would see
//! signals age backwards and staleness rules fire falsely (a shuffled log gave 51 false
//! `sensor_lost`).

use crate::bridge::{BridgeCore, Counters};
use crate::clock::Clock;
use crate::event::EventOut;
use crate::log::{read_log_lines, Direction, LogError, LogRecord};
use std::fmt;

/// How many records going back in time [`ReplaySummary`] keeps the detail of (it counts them
/// all).
pub const MAX_BACKWARDS_KEPT: usize = 10;

/// A record whose time is earlier than a record before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeBackwards {
    /// Its 1-based line in the log (0 when the records came without lines).
    pub line: usize,
    /// Its recorded time, in microseconds.
    pub time_us: u64,
    /// The latest time before it, at which it was replayed.
    pub replayed_at_us: u64,
}

impl fmt::Display for TimeBackwards {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = |us: u64| format!("{}.{:06}", us / 1_000_000, us % 1_000_000);
        write!(
            f,
            "line {}: time goes back from {} s to {} s ({} s earlier); replayed at {} s",
            self.line,
            s(self.replayed_at_us),
            s(self.time_us),
            s(self.replayed_at_us.saturating_sub(self.time_us)),
            s(self.replayed_at_us)
        )
    }
}

/// What a replay went through: the records, the times that went back, and the core's
/// counters at the end (frames decoded, unknown, of the wrong length...).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReplaySummary {
    /// Records replayed.
    pub records: u64,
    /// Of them, frames the bridge sent (`T`).
    pub transmitted: u64,
    /// Records whose time went back.
    pub time_backwards: u64,
    /// The first [`MAX_BACKWARDS_KEPT`] of them.
    pub backwards: Vec<TimeBackwards>,
    /// The core's counters once the log is replayed.
    pub counters: Counters,
}

impl fmt::Display for ReplaySummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.counters;
        write!(
            f,
            "replayed {} records ({} received, {} sent): {} decoded, {} of a length other than the DBC's (dropped), {} with an identifier the DBC does not know, {} remote, {} error frames; {} events; time went back {} times",
            self.records,
            self.records - self.transmitted,
            self.transmitted,
            c.decoded,
            c.wrong_length,
            c.unknown_id,
            c.remote,
            c.error_frames,
            c.events,
            self.time_backwards
        )
    }
}

/// The events of a replay and what it went through.
#[derive(Clone, Debug, PartialEq)]
pub struct Replayed {
    /// Every event, in order, with its time.
    pub events: Vec<EventOut>,
    /// The counts.
    pub summary: ReplaySummary,
}

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
    replay_lines(core, records.into_iter().map(|r| (0, r)), pacing, clock).events
}

/// Replays `records`, each with its line number, into `core`: the events and the summary.
pub fn replay_lines<'a>(
    core: &mut BridgeCore,
    records: impl IntoIterator<Item = (usize, &'a LogRecord)>,
    pacing: Pacing,
    clock: &dyn Clock,
) -> Replayed {
    let mut events = Vec::new();
    let mut summary = ReplaySummary::default();
    let mut origin: Option<(u64, u64)> = None;
    let mut latest: Option<u64> = None;
    for (line, r) in records {
        summary.records += 1;
        let time_us = match latest {
            Some(l) if r.time_us < l => {
                summary.time_backwards += 1;
                if summary.backwards.len() < MAX_BACKWARDS_KEPT {
                    summary.backwards.push(TimeBackwards {
                        line,
                        time_us: r.time_us,
                        replayed_at_us: l,
                    });
                }
                l
            }
            _ => r.time_us,
        };
        latest = Some(time_us);
        if let Pacing::TimeFaithful { speed } = pacing {
            let speed = if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            };
            let (first, wall0) = *origin.get_or_insert((time_us, clock.now_us()));
            let offset = (time_us.saturating_sub(first) as f64 / speed) as u64;
            clock.sleep_until_us(wall0.saturating_add(offset));
        }
        match r.direction {
            Some(Direction::Transmitted) => {
                summary.transmitted += 1;
                events.extend(core.on_sent(time_us, &r.frame))
            }
            _ => events.extend(core.on_frame(time_us, &r.frame).events),
        }
    }
    summary.counters = core.counters();
    Replayed { events, summary }
}

/// Reads a `candump -L` log and replays it; a malformed line is an error (with its number)
/// before anything is replayed.
pub fn replay_text(
    core: &mut BridgeCore,
    text: &str,
    pacing: Pacing,
    clock: &dyn Clock,
) -> Result<Vec<EventOut>, LogError> {
    Ok(replay_counted(core, text, pacing, clock)?.events)
}

/// Reads a `candump -L` log and replays it: the events and the summary (time going back, with
/// the lines, and the counters). A malformed line is an error (with its number) before
/// anything is replayed.
pub fn replay_counted(
    core: &mut BridgeCore,
    text: &str,
    pacing: Pacing,
    clock: &dyn Clock,
) -> Result<Replayed, LogError> {
    let records = read_log_lines(text)?;
    Ok(replay_lines(
        core,
        records.iter().map(|(n, r)| (*n, r)),
        pacing,
        clock,
    ))
}
