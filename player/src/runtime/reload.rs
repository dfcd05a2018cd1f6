//! The runtime's side of a reload: the requests taken from the reload service, the
//! verification in a thread of its own, the answers, and the swap between two steps. What is
//! refused and what is swapped is [`ReloadJob`](crate::reload::ReloadJob)'s to decide.
//!
//! The swap maps the state again (a timer may have fallen due during the verification: its
//! event is queued, and goes to the new version), keeps the new version's files beside the
//! journal, opens the call senders the new version needs (a program both versions have keeps
//! its sender, if the new version's calls fit it: it sees no interruption), hands the engine's
//! queue and counters over (`Engine::take_queue`, `Engine::adopt`), journals a `reload` entry,
//! and runs the new version's record, liveness watch, held calls, built-in events and, if it
//! needs a larger one, heartbeat publisher. The answer goes out, then a snapshot of the new
//! state. The new version's project is leaked on purpose ([`version::leak`]).

use super::player_loop::PlayerLoop;
use super::ports::Builtins;
use crate::engine::Engine;
use crate::journal::Entry;
use crate::record::StepRecord;
use crate::reload::version::{self, Candidate};
use crate::reload::{map_onto, running_state, Begin, Requester, Settle};
use crate::sizing::{call_bound, status_bound};
use petrel_ipc::{CallSender, Heartbeat, ProgramWatch, ReloadAnswer, ReloadRequest};
use petrel_nets::compiled::CompiledProject;
use petrel_nets::reload::{Finding, Mapped, Mapping};
use std::path::Path;
use std::time::Instant;
use tracing::{info, warn};

/// The most stable states a reload's verification explores before it refuses the reload.
const RELOAD_MAX_STATES: u64 = 2_000_000;

impl<'p> PlayerLoop<'p> {
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
            self.begin_reload(Requester { sender, seq }, request);
        }
    }

    /// A request: refused, or its new version read, mapped and handed to a verifying thread.
    fn begin_reload(&mut self, from: Requester, request: ReloadRequest) {
        let admitted = match self.reload.request(from, request, Instant::now()) {
            Ok(admitted) => admitted,
            Err(answer) => return self.answer_reload(*answer),
        };
        let r = admitted.request();
        let read = version::load_candidate(Path::new(&r.dir), &r.source_hash, &r.mapping);
        let running = (self.project, &running_state(&self.engine));
        let (project, mapped) = match self.reload.begin(admitted, read, running, Instant::now()) {
            Begin::Refuse(answer) => return self.answer_reload(answer),
            Begin::Verify { project, mapped } => (project, mapped),
        };
        let verifier = std::thread::Builder::new()
            .name("reload-verify".into())
            .spawn(move || {
                petrel_nets::reload::verify_mapped(&project, &mapped, Some(RELOAD_MAX_STATES))
            });
        match verifier {
            Ok(verifier) => self.verifier = Some(verifier),
            Err(e) => {
                let why = format!("cannot start the verification: {e}");
                if let Some(answer) = self.reload.abandon(why, Instant::now()) {
                    self.answer_reload(answer);
                }
            }
        }
    }

    /// Answers the reload under verification once the verdict is in, and swaps versions if it
    /// is accepted (between two steps: none was taken since the mapping).
    pub(super) fn finish_reload(&mut self) {
        let Some(verifier) = self.verifier.take_if(|v| v.is_finished()) else {
            return;
        };
        let verdict = verifier.join().unwrap_or_else(|_| {
            Err(Finding {
                what: "the verification failed (its thread panicked): a bug in Petrel".into(),
                trace: Vec::new(),
            })
        });
        match self.reload.verdict(verdict, self.step_no, Instant::now()) {
            None => {}
            Some(Settle::Answer(answer)) => self.answer_reload(answer),
            Some(Settle::Swap {
                candidate,
                dir,
                answer,
            }) => {
                let swapped = self.swap(*candidate, &dir);
                let answer = answer.after_swap(swapped, Instant::now());
                let accepted = answer.accepted;
                self.answer_reload(answer);
                if accepted {
                    // After the answer: a shadow reading the snapshot has the answer already,
                    // and knows which version the snapshot's names are of.
                    self.publish_delta();
                }
            }
        }
    }

    /// Answers a reload request (to every listener: the requester finds its own).
    fn answer_reload(&mut self, mut answer: ReloadAnswer) {
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

    /// Swaps to the candidate version (see the module's doc); what became of the queue, for
    /// the answer, or why the swap could not be done (the old version runs on unchanged).
    fn swap(&mut self, candidate: Candidate, dir: &str) -> Result<String, Vec<String>> {
        let mapped = map_onto(self.project, &running_state(&self.engine), &candidate)
            .map_err(|r| r.reasons)?;
        if let Some(journal) = &self.opts.journal {
            version::keep(journal, &candidate.source_hash, &candidate.files).map_err(|e| {
                vec![format!(
                    "cannot keep the new version beside the journal in {}: {e}",
                    journal.display()
                )]
            })?;
        }
        let calls = self.calls_for(&candidate.project)?;
        let Candidate {
            project,
            source_hash,
            mapping_text,
            mapping,
            ..
        } = candidate;
        let new = version::leak(project);
        let reload = Reloaded {
            dir,
            source_hash: &source_hash,
            mapping_text,
            mapping: &mapping,
        };
        let handed = self.adopt(new, mapped, reload);
        self.run_version(new, calls);
        self.version = Some(source_hash);
        Ok(handed)
    }

    /// The call senders of the new version's programs, in its order: a program both versions
    /// have keeps its sender if the new version's calls fit it (it sees no interruption), the
    /// others get one sized for them. On a failure the old senders stay as they were.
    fn calls_for(&mut self, new: &CompiledProject) -> Result<Vec<CallSender>, Vec<String>> {
        let mut old: Vec<Option<CallSender>> = std::mem::take(&mut self.ports.calls)
            .into_iter()
            .map(Some)
            .collect();
        // Each sender, and the index of the old one it is, if kept.
        let mut calls: Vec<(Option<usize>, CallSender)> = Vec::new();
        for prog in &new.programs {
            let bound = call_bound(prog);
            let fits = |c: &CallSender| {
                c.spec().max_body_len >= bound.unwrap_or(petrel_ipc::port::CALLS.max_body_len)
            };
            let kept = self
                .project
                .programs
                .iter()
                .position(|p| p.name == prog.name)
                .and_then(|i| Some((i, old[i].take_if(|c| fits(c))?)));
            let opened = match kept {
                Some((i, c)) => Ok((Some(i), c)),
                None => self
                    .ports
                    ._me
                    .call_sender_sized(&prog.name, bound)
                    .map(|c| (None, c)),
            };
            match opened {
                Ok(c) => calls.push(c),
                Err(e) => {
                    // Put the old senders back as they were.
                    for (i, c) in calls {
                        if let Some(i) = i {
                            old[i] = Some(c);
                        }
                    }
                    self.ports.calls = old.into_iter().flatten().collect();
                    return Err(vec![format!("cannot open the new version's calls: {e}")]);
                }
            }
        }
        Ok(calls.into_iter().map(|(_, c)| c).collect())
    }

    /// The engine of version `new`, from the `mapped` state, with the old one's queue and
    /// counters; the reload journaled. Says what became of the queue.
    fn adopt(&mut self, new: &'p CompiledProject, mapped: Mapped, reload: Reloaded) -> String {
        let time = self.engine.now();
        let queued = self.engine.take_queue();
        let carried = queued.clone();
        let mut engine = Engine::new(new);
        let refused = engine
            .adopt(
                time,
                &mapped.state,
                &mapped.deadlines,
                mapped.net_args,
                self.engine.stats(),
                queued,
                &reload.mapping.nets,
            )
            .unwrap_or_default();
        let handed = format!(
            "queue: {} event(s) handed over to the new version, {} refused",
            carried.len(),
            refused.len()
        );
        self.journal.append(&Entry::Reload {
            time,
            dir: reload.dir.to_string(),
            source_hash: reload.source_hash.to_string(),
            digest: crate::journal::project_digest(new),
            mapping: reload.mapping_text,
            state: mapped.state,
            deadlines: mapped.deadlines,
            queued: carried,
        });
        for (event, why) in refused {
            warn!(event, reason = %why, "a queued event refused at the reload");
        }
        self.engine = engine;
        handed
    }

    /// Runs version `new` from now on: its calls, record, liveness watch, held calls, built-in
    /// events, a heartbeat publisher large enough for its status, and a snapshot next.
    fn run_version(&mut self, new: &'p CompiledProject, calls: Vec<CallSender>) {
        self.ports.calls = calls;
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
        self.builtins = Builtins::of(new);
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
    }
}

/// What the journal's `reload` entry says besides the state: where the version came from.
struct Reloaded<'a> {
    dir: &'a str,
    source_hash: &'a str,
    mapping_text: String,
    mapping: &'a Mapping,
}
