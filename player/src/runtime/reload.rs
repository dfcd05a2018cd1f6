//! The runtime's side of a reload: requests taken from the reload service, verified in a thread
//! of their own, answered, and the swap between two steps.

use super::player_loop::PlayerLoop;
use super::ports::Builtins;
use crate::engine::Engine;
use crate::journal::Entry;
use crate::record::StepRecord;
use crate::sizing::{call_bound, status_bound};
use petrel_ipc::{CallSender, Heartbeat, ProgramWatch, ReloadAnswer, ReloadRequest};
use std::time::Instant;
use tracing::{info, warn};

/// A reload whose new version is being verified from the mapped state, in a thread of its
/// own, while the loop goes on taking events (and, for a dry run, processing them).
pub(super) struct PendingReload {
    pub(super) request: ReloadRequest,
    pub(super) sender: u64,
    pub(super) seq: u64,
    pub(super) received: Instant,
    pub(super) candidate: crate::reload::version::Candidate,
    pub(super) summary: Vec<String>,
    pub(super) verdict: std::thread::JoinHandle<Result<u64, petrel_nets::reload::Finding>>,
}

/// The most stable states a reload's verification explores before it refuses the reload.
const RELOAD_MAX_STATES: u64 = 2_000_000;

impl PlayerLoop<'_> {
    /// Takes the reload requests that arrived: each is read, checked and mapped at once (the
    /// engine is between two steps), then verified in a thread of its own.
    pub(super) fn take_reload_requests(&mut self) {
        let mut requests = Vec::new();
        let drained = self.ports.reload.drain(|r| match r {
            Ok(rcv) => requests.push((rcv.sender, rcv.seq, rcv.origin.to_string(), rcv.msg)),
            Err(e) => warn!(error = %e, "a reload request could not be read"),
        });
        if let Err(e) = drained {
            warn!(error = %e, "reload requests could not be read");
        }
        for (sender, seq, origin, request) in requests {
            info!(from = %origin, dir = %request.dir, hash = %request.source_hash, dry_run = request.dry_run, "reload requested");
            self.begin_reload(sender, seq, request);
        }
    }

    /// Answers a reload request (to every listener: the requester finds its own).
    pub(super) fn answer_reload(&mut self, mut answer: ReloadAnswer) {
        if !answer.accepted || answer.dry_run {
            self.report.reloads_refused += 1;
        }
        if answer.accepted {
            info!(dry_run = answer.dry_run, hash = %answer.source_hash, states = answer.states, ms = answer.millis, summary = ?answer.summary, "reload accepted");
        } else {
            warn!(dry_run = answer.dry_run, hash = %answer.source_hash, reasons = ?answer.reasons, trace = ?answer.trace, "reload refused: the mission goes on unchanged");
        }
        answer.bound();
        if let Err(e) = self.ports.reload_answers.send(&answer) {
            warn!(error = %e, "the reload answer could not be sent");
        }
    }

    pub(super) fn refuse_reload(
        &mut self,
        sender: u64,
        seq: u64,
        request: &ReloadRequest,
        since: Instant,
        reasons: Vec<String>,
    ) {
        self.answer_reload(ReloadAnswer {
            request_sender: sender,
            request_seq: seq,
            accepted: false,
            dry_run: request.dry_run,
            dir: request.dir.clone(),
            source_hash: request.source_hash.clone(),
            reasons,
            millis: since.elapsed().as_millis() as u64,
            ..ReloadAnswer::default()
        });
    }

    /// The old version's state, mapped onto `candidate`.
    pub(super) fn map_onto(
        &self,
        candidate: &crate::reload::version::Candidate,
    ) -> Result<petrel_nets::reload::Mapped, petrel_nets::reload::MapRefusal> {
        let from = petrel_nets::reload::OldState {
            state: self.engine.state(),
            deadlines: self.engine.deadlines(),
            net_args: self.engine.all_net_args(),
        };
        petrel_nets::reload::map_state(self.project, &from, &candidate.project, &candidate.mapping)
    }

    pub(super) fn begin_reload(&mut self, sender: u64, seq: u64, request: ReloadRequest) {
        let since = Instant::now();
        if self.pending.is_some() {
            let why = "another reload is being verified: ask again when it is answered".to_string();
            return self.refuse_reload(sender, seq, &request, since, vec![why]);
        }
        let candidate = match crate::reload::version::load_candidate(
            std::path::Path::new(&request.dir),
            &request.source_hash,
            &request.mapping,
        ) {
            Ok(c) => c,
            Err(reasons) => return self.refuse_reload(sender, seq, &request, since, reasons),
        };
        let mapped = match self.map_onto(&candidate) {
            Ok(m) => m,
            Err(r) => return self.refuse_reload(sender, seq, &request, since, r.reasons),
        };
        // The verifier gets its own copy: a refused version is dropped whole.
        let project = candidate.project.clone();
        let state = mapped.clone();
        let verdict = std::thread::Builder::new()
            .name("reload-verify".into())
            .spawn(move || {
                petrel_nets::reload::verify_mapped(&project, &state, Some(RELOAD_MAX_STATES))
            });
        match verdict {
            Ok(verdict) => {
                self.pending = Some(PendingReload {
                    request,
                    sender,
                    seq,
                    received: since,
                    candidate,
                    summary: mapped.summary,
                    verdict,
                })
            }
            Err(e) => {
                let why = format!("cannot start the verification: {e}");
                self.refuse_reload(sender, seq, &request, since, vec![why])
            }
        }
    }

    /// Answers the reload under verification once the verdict is in, and swaps versions if it
    /// is accepted (between two steps: none was taken since the mapping).
    pub(super) fn finish_reload(&mut self) {
        if !self
            .pending
            .as_ref()
            .is_some_and(|p| p.verdict.is_finished())
        {
            return;
        }
        let Some(p) = self.pending.take() else { return };
        let verdict = p.verdict.join().unwrap_or_else(|_| {
            Err(petrel_nets::reload::Finding {
                what: "the verification failed (its thread panicked): a bug in Petrel".into(),
                trace: Vec::new(),
            })
        });
        let states = match verdict {
            Ok(states) => states,
            Err(f) => {
                let mut reasons = vec![format!("verification from the mapped state: {}", f.what)];
                reasons.push(if f.trace.is_empty() {
                    "in the mapped state itself".to_string()
                } else {
                    format!("from the mapped state by: {}", f.trace.join(", "))
                });
                return self.answer_reload(ReloadAnswer {
                    request_sender: p.sender,
                    request_seq: p.seq,
                    accepted: false,
                    dry_run: p.request.dry_run,
                    dir: p.request.dir.clone(),
                    source_hash: p.candidate.source_hash.clone(),
                    summary: p.summary,
                    reasons,
                    trace: f.trace,
                    millis: p.received.elapsed().as_millis() as u64,
                    ..ReloadAnswer::default()
                });
            }
        };
        let mut answer = ReloadAnswer {
            request_sender: p.sender,
            request_seq: p.seq,
            accepted: true,
            dry_run: p.request.dry_run,
            dir: p.request.dir.clone(),
            source_hash: p.candidate.source_hash.clone(),
            step: self.step_no,
            summary: p.summary,
            states,
            ..ReloadAnswer::default()
        };
        if !p.request.dry_run {
            match self.swap(p.candidate, &p.request.dir) {
                Ok(handed) => answer.summary.push(handed),
                Err(reasons) => {
                    answer.accepted = false;
                    answer.reasons = reasons;
                }
            }
        }
        answer.millis = p.received.elapsed().as_millis() as u64;
        let swapped = answer.accepted && !answer.dry_run;
        self.answer_reload(answer);
        if swapped {
            // After the answer: a shadow reading the snapshot has the answer already, and
            // knows which version the snapshot's names are of.
            self.publish_delta();
        }
    }

    /// Swaps to the candidate version: the state mapped again (a timer may have fallen due
    /// during the verification: its event is queued, and goes to the new version), its files
    /// kept beside the journal and the reload journaled, then the engine, the record, the
    /// calls and the liveness watch of the new version.
    pub(super) fn swap(
        &mut self,
        candidate: crate::reload::version::Candidate,
        dir: &str,
    ) -> Result<String, Vec<String>> {
        let mapped = self.map_onto(&candidate).map_err(|r| r.reasons)?;
        if let Some(journal) = &self.opts.journal {
            crate::reload::version::keep(journal, &candidate.source_hash, &candidate.files)
                .map_err(|e| {
                    vec![format!(
                        "cannot keep the new version beside the journal in {}: {e}",
                        journal.display()
                    )]
                })?;
        }
        let setup =
            |e: petrel_ipc::SetupError| vec![format!("cannot open the new version's calls: {e}")];
        // The calls of programs both versions have are kept: no program sees an interruption.
        let mut old_calls: Vec<Option<CallSender>> = std::mem::take(&mut self.ports.calls)
            .into_iter()
            .map(Some)
            .collect();
        let mut calls = Vec::new();
        let mut failed = None;
        for prog in &candidate.project.programs {
            // A sender sized for the old version is kept if the new version's calls fit.
            let bound = call_bound(prog);
            let kept = self
                .project
                .programs
                .iter()
                .position(|p| p.name == prog.name)
                .filter(|&i| {
                    old_calls[i].as_ref().is_some_and(|c| {
                        c.spec().max_body_len
                            >= bound.unwrap_or(petrel_ipc::port::CALLS.max_body_len)
                    })
                })
                .and_then(|i| old_calls[i].take());
            match kept {
                Some(c) => calls.push(c),
                None => match self.ports._me.call_sender_sized(&prog.name, bound) {
                    Ok(c) => calls.push(c),
                    Err(e) => {
                        failed = Some(setup(e));
                        break;
                    }
                },
            }
        }
        if let Some(reasons) = failed {
            // Put the old calls back as they were.
            self.ports.calls = old_calls.into_iter().flatten().collect();
            return Err(reasons);
        }
        let time = self.engine.now();
        let new = crate::reload::version::leak(candidate.project);
        let queued = self.engine.take_queue();
        let carried = queued.clone();
        let carried_len = carried.len();
        let mut engine = Engine::new(new);
        let refused = engine
            .adopt(
                time,
                &mapped.state,
                &mapped.deadlines,
                mapped.net_args,
                self.engine.stats(),
                queued,
                &candidate.mapping.nets,
            )
            .unwrap_or_default();
        self.journal.append(&Entry::Reload {
            time,
            dir: dir.to_string(),
            source_hash: candidate.source_hash.clone(),
            digest: crate::journal::project_digest(new),
            mapping: candidate.mapping_text,
            state: mapped.state,
            deadlines: mapped.deadlines,
            queued: carried,
        });
        let handed = format!(
            "queue: {} event(s) handed over to the new version, {} refused",
            carried_len,
            refused.len()
        );
        for (event, why) in refused {
            warn!(event, reason = %why, "a queued event refused at the reload");
        }
        self.ports.calls = calls;
        self.engine = engine;
        self.project = new;
        self.record = StepRecord::new(new).without_calls();
        match ProgramWatch::new(&self.ports._me, new.programs.iter().map(|p| p.name.clone())) {
            Ok(watch) => self.watch = watch,
            Err(e) => {
                warn!(error = %e, "the new version's programs cannot be watched: the old version's are")
            }
        }
        if let Err(e) = self.watch.check() {
            warn!(error = %e, "liveness check failed");
        }
        self.held.refresh(new);
        self.builtins = Builtins {
            program_lost: new.event_id("program_lost"),
            call_failed: new.event_id("call_failed"),
            bad_message: new.event_id("bad_message"),
            recorder_failed: new.event_id("recorder_failed"),
            recorder_restored: new.event_id("recorder_restored"),
        };
        // A larger version gets a heartbeat publisher sized for it.
        let heartbeat_max = Heartbeat::max_encoded_len(status_bound(new));
        if heartbeat_max > self.ports.heartbeat.spec().max_body_len {
            match self.ports._me.heartbeat_publisher_sized(heartbeat_max) {
                Ok(h) => self.ports.heartbeat = h,
                Err(e) => {
                    warn!(error = %e, "the heartbeat publisher could not grow for the new version: a status too large leaves its marking out")
                }
            }
        }
        // The snapshot of the new state follows the answer (see `finish_reload`).
        self.previous = vec![0; self.engine.state().len()];
        self.snapshot_next = true;
        self.report.reloads += 1;
        self.version = Some(candidate.source_hash);
        Ok(handed)
    }
}
