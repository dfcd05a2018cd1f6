//! The heartbeat: published every period with the live status (JSON, [`crate::status`]) and,
//! typed, the acknowledgement of each sender; the journal is flushed first, so that what a
//! heartbeat acknowledges as settled is on record.

use super::options::PlayReport;
use super::player_loop::PlayerLoop;
use crate::ack::Ledger;
use crate::engine::Engine;
use crate::journal::{Entry, Journal, Settlement};
use crate::status::{status_json, StatusSnapshot};
use petrel_ipc::{Heartbeat, SendError};
use std::time::Instant;
use tracing::error;

impl PlayerLoop<'_> {
    /// Publishes the heartbeat, with the live status and the acknowledgements, when its period
    /// is over. The journal is flushed first: what it holds is then settled, what it still
    /// keeps in memory stays pending, what it dropped is unrecorded.
    pub(super) fn heartbeat_if_due(&mut self, instant: Instant) {
        if instant < self.next_heartbeat {
            return;
        }
        self.next_heartbeat = instant + self.opts.heartbeat;
        match self.journal.flush() {
            Settlement::Recorded => self.ledger.settle(),
            Settlement::Pending => {}
            Settlement::Lost => self.ledger.lose_unsettled(),
        }
        // A recorder that dropped records goes on from a checkpoint of the engine, taken
        // between two steps (the queue is empty after `process_queue`).
        if self.journal.wants_checkpoint() && self.engine.queued() == 0 {
            let checkpoint = Entry::Checkpoint {
                time: self.engine.now(),
                state: self.engine.state().to_vec(),
                deadlines: self.engine.deadlines().to_vec(),
            };
            self.journal.checkpoint(&checkpoint);
        }
        self.count_journal();
        for gone in self.ledger.prune(&self.ports.events.live_senders()) {
            self.ports.events.forget_sender(gone);
        }
        let max = self.ports.heartbeat.spec().max_body_len;
        let mut hb = Heartbeat {
            uptime_ms: self.t0.elapsed().as_millis() as u64,
            period_ms: self.opts.heartbeat.as_millis() as u32,
            progress: self.step_no,
            status: String::new(),
            acks: self.ledger.acks(),
            recorder: petrel_ipc::Recorder {
                state: self.journal.state(),
                reason: self.journal.reason().to_string(),
            },
        };
        hb.bound();
        let snapshot = StatusSnapshot {
            version: self.version.clone(),
            reloading: self.reload.is_verifying(),
            ..StatusSnapshot::of(&self.engine, &self.report, &self.ledger, &self.journal)
        };
        hb.status = status_json(&snapshot);
        if Heartbeat::max_encoded_len(hb.status.len()) > max {
            // Only a project past the largest body a service carries gets here (see `new`).
            hb.status = status_json(&StatusSnapshot {
                marking: None,
                ..snapshot
            });
        }
        match self.ports.heartbeat.send(&hb) {
            // Latest-value service: a heartbeat nobody reads is not an error, and one that
            // missed a receiver still connecting (buffers never fill: they overwrite) reaches
            // it with the next period.
            Ok(_) | Err(SendError::NoReceiver { .. } | SendError::Refused { .. }) => {
                self.report.heartbeats_sent += 1
            }
            Err(e) => {
                self.report.heartbeats_refused += 1;
                let n = self.report.heartbeats_refused;
                if n == 1 || n.is_multiple_of(100) {
                    error!(error = %e, refused = n, "heartbeat not published: status and acknowledgements are not seen");
                }
            }
        }
    }
}

impl StatusSnapshot {
    pub(super) fn of(
        engine: &Engine,
        report: &PlayReport,
        ledger: &Ledger,
        journal: &Journal,
    ) -> Self {
        let s = engine.stats();
        // Oldest first, so that two senders of one origin show the most recent one.
        let mut senders: Vec<(String, [u64; 9])> = ledger
            .recent()
            .into_iter()
            .map(|a| {
                let k = &a.ack;
                (
                    k.origin.clone(),
                    [
                        k.last_seq,
                        k.received,
                        a.undecodable,
                        k.missing,
                        k.taken,
                        k.refused,
                        k.pending,
                        k.unrecorded,
                        k.settled_seq,
                    ],
                )
            })
            .collect();
        senders.reverse();
        let (records, bytes) = journal.backlog();
        let mut reason = journal.reason().to_string();
        petrel_ipc::wire::cut_text(&mut reason, petrel_ipc::wire::MAX_REASON_LEN);
        StatusSnapshot {
            recorder: (
                journal.state().as_str(),
                reason,
                [journal.failures, journal.lost, records as u64, bytes as u64],
            ),
            project: engine.project().name.clone(),
            time_s: engine.now() as f64 / 1e6,
            over: engine.is_over(),
            marking: Some(engine.marking()),
            stats: [
                report.messages,
                report.bad_messages,
                s.received,
                s.processed,
                s.unused,
                s.refused,
                engine.queued() as u64,
                report.calls_sent,
                report.calls_failed,
                report.calls_held,
                report.journal_records,
                report.resumed_steps,
                report.heartbeats_sent,
                report.heartbeats_refused,
                report.reloads,
                report.reloads_refused,
            ],
            senders,
            version: None,
            reloading: false,
        }
    }
}
