//! The marking deltas: what each step changed, published for monitors and shadows.

use super::player_loop::PlayerLoop;
use crate::record::{marked_places, place_changes};
use petrel_ipc::{MarkingMsg, SendError};
use petrel_nets::compiled::NetId;
use tracing::warn;

impl PlayerLoop<'_> {
    /// Publishes what the last step changed (the first message of a run is a full snapshot).
    pub(super) fn publish_delta(&mut self) {
        if self.step_no != 0 && self.ports.marking.receivers() == 0 {
            // No monitor follows: the delta's names would be built for nobody. The first
            // monitor to come gets a snapshot (a monitor that just connected may miss this
            // step: the snapshot makes up for it).
            self.snapshot_next = true;
            self.previous.clear();
            self.previous.extend_from_slice(self.engine.state());
            self.record.forget_taken();
            self.record.activated.clear();
            self.record.deactivated.clear();
            return;
        }
        let project = self.project;
        let layout = self.engine.layout();
        let now = self.engine.state();
        let snapshot = self.step_no == 0 || std::mem::take(&mut self.snapshot_next);
        // Only the places that changed are named (a snapshot names every marked one).
        let (changed, unmarked) = place_changes(project, layout, &self.previous, now);
        let marked = if snapshot {
            marked_places(project, layout, now)
        } else {
            changed
        };
        let record = &mut self.record;
        let net_names = |ids: &mut Vec<NetId>| -> Vec<String> {
            ids.drain(..)
                .map(|n| project.nets[n as usize].name.clone())
                .collect()
        };
        let (event, params) = match record.taken.take() {
            Some((e, p)) => (Some(e), p),
            None => (None, Vec::new()),
        };
        let msg = MarkingMsg {
            step: self.step_no,
            event,
            time_us: self.engine.now(),
            params,
            actions: record.actions.clone(),
            fired: record.fired_names(),
            marked,
            unmarked,
            activated: if snapshot {
                // A snapshot lists the whole state: every active net.
                record.activated.clear();
                (0..project.nets.len() as NetId)
                    .filter(|&n| self.engine.is_active(n))
                    .map(|n| project.nets[n as usize].name.clone())
                    .collect()
            } else {
                net_names(&mut record.activated)
            },
            deactivated: net_names(&mut record.deactivated),
            snapshot,
        };
        self.previous.clear();
        self.previous.extend_from_slice(now);
        match self.ports.marking.send(&msg) {
            Ok(_) | Err(SendError::NoReceiver { .. }) => {}
            Err(e) => warn!(error = %e, "marking delta not delivered to every monitor"),
        }
    }
}
