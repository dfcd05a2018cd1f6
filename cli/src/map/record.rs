//! A recorded run fed to the map's core in time order: the journal's steps (positions and
//! routes in events' parameters, marked events) and, for tracks from signals, the CAN data
//! server's recording of the bus (`petrel bridge --record`, a `candump -L` log), decoded with
//! the project's DBC and put on the journal's clock by the wall-clock time both keep.

use super::feed::MapState;
use super::Map;
use petrel_can_bridge::dbc::{Dbc, DecodeOutcome};
use petrel_can_bridge::log::LogRecord;
use petrel_player::journal::Entry;
use std::collections::HashMap;

/// A recording of the bus, with the DBC that decodes it.
pub struct BusLog<'a> {
    /// The project's DBC.
    pub dbc: &'a Dbc,
    /// The recorded frames, in order.
    pub records: &'a [LogRecord],
}

/// The wall-clock start of the journal's mission (µs since the Unix epoch), from its first
/// header; 0 when it has none.
pub fn mission_start_us(entries: &[Entry]) -> u64 {
    entries
        .iter()
        .find_map(|e| match e {
            Entry::Header {
                started_unix_ms, ..
            } => Some(started_unix_ms.saturating_mul(1000)),
            _ => None,
        })
        .unwrap_or(0)
}

/// The map of a recorded run: the journal's steps and, when given, the bus's signals, in the
/// order they happened. Frames before the mission's start or that the DBC does not decode are
/// left out.
pub fn replay(map: &Map, entries: &[Entry], bus: Option<BusLog>) -> MapState {
    let mut state = MapState::new(map);
    let start = mission_start_us(entries);
    let wanted: Vec<&str> = map.signals();
    // Frames on the mission's clock, in seconds.
    let mut frames = bus
        .as_ref()
        .map(|b| {
            b.records
                .iter()
                .filter(|r| r.time_us >= start)
                .map(move |r| ((r.time_us - start) as f64 / 1e6, r))
                .collect::<Vec<_>>()
        })
        .unwrap_or_default()
        .into_iter()
        .peekable();
    let mut latest: HashMap<String, f64> = HashMap::new();
    let mut feed_frames = |until: f64, state: &mut MapState, latest: &mut HashMap<String, f64>| {
        let Some(b) = bus.as_ref() else { return };
        while let Some((t, r)) = frames.next_if(|(t, _)| *t <= until) {
            let DecodeOutcome::Message(dm) = b.dbc.decode(&r.frame) else {
                continue;
            };
            let mut moved = false;
            for s in &dm.signals {
                let path = b.dbc.signal_path(s.signal);
                if wanted.contains(&path.as_str()) {
                    latest.insert(path, s.physical);
                    moved = true;
                }
            }
            if moved {
                state.on_signals(map, t, |n| latest.get(n).copied());
            }
        }
    };
    for e in entries {
        let Entry::Step {
            time,
            event,
            params,
            fired,
            ..
        } = e
        else {
            continue;
        };
        let t = *time as f64 / 1e6;
        feed_frames(t, &mut state, &mut latest);
        state.on_step(map, t, event, params, !fired.is_empty());
    }
    feed_frames(f64::INFINITY, &mut state, &mut latest);
    state
}
