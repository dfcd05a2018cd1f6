//! [`PlayerLoop`] and its rounds (the round and the loop's invariants are said in [`super`]):
//! the queue processed (each step journaled from the record and the engine as they are, and
//! published; the calls it could not deliver held or failed), the journal's batch written or
//! held, the wait and its timeout, the events taken through [`crate::intake`], the programs'
//! comings and goings, the recorder's changes raised (`recorder_failed`, `recorder_restored`),
//! and the stop.

use super::options::{PlayError, PlayOptions, PlayReport};
use super::ports::{Builtins, Ports};
use super::sink::RuntimeSink;
use crate::ack::Ledger;
use crate::engine::{Engine, Micros};
use crate::held::{HeldCalls, Undelivered, HOLD_POLL};
use crate::intake::{Header, Intake};
use crate::journal::{
    Entry, Journal, JournalLock, RecorderChange, Settlement, StepParts, BATCH_DELAY,
};
use crate::record::{outcome_name, StepRecord};
use crate::reload::{ReloadJob, Verdict};
use petrel_ipc::{ProgramWatch, Reactor, RecvError, WaitStrategy};
use petrel_nets::compiled::{CompiledProject, EventId, Value};
use std::time::{Duration, Instant};
use tracing::{error, info, warn};

/// The player: the engine, its ports, its journal, and the clocks of its loop.
pub struct PlayerLoop<'p> {
    pub(super) project: &'p CompiledProject,
    pub(super) opts: PlayOptions,
    pub(super) engine: Engine<'p>,
    pub(super) record: StepRecord<'p>,
    /// Calls of the current step that could not be delivered: held or failed after the step.
    pub(super) undelivered: Vec<Undelivered>,
    /// Calls held for programs whose process lives but does not receive them yet.
    pub(super) held: HeldCalls,
    pub(super) journal: Journal,
    pub(super) ports: Ports,
    pub(super) watch: ProgramWatch,
    pub(super) reactor: Reactor,
    pub(super) builtins: Builtins,
    pub(super) report: PlayReport,
    /// What was taken from each sender, refused and settled: the heartbeat's acknowledgements.
    pub(super) ledger: Ledger,
    /// Where each event's parameters are decoded, before they move into an engine's buffer.
    pub(super) decoded: Vec<Value>,
    /// The programs that said they leave in good order (since they last joined): their going
    /// is a stop, not a loss.
    pub(super) leaves: std::collections::BTreeSet<String>,
    /// When the loop started, and the mission time it started at (after a resume).
    pub(super) t0: Instant,
    pub(super) base: Micros,
    /// The state published last, to compute the next marking delta.
    pub(super) previous: Vec<u64>,
    pub(super) step_no: u64,
    pub(super) next_heartbeat: Instant,
    pub(super) next_liveness: Instant,
    /// The next marking message is a snapshot (after a reload, or steps no monitor saw).
    pub(super) snapshot_next: bool,
    /// The reloads: their decisions, and the thread verifying one.
    pub(super) reload: ReloadJob,
    pub(super) verifier: Option<std::thread::JoinHandle<Verdict>>,
    /// The content hash of the version running, once a reload brought one.
    pub(super) version: Option<String>,
    /// The hold on the journal directory: released last, after the journal is closed.
    pub(super) _lock: Option<JournalLock>,
}

impl<'p> PlayerLoop<'p> {
    /// Mission time at `instant`: wall-clock time since the mission started, read from the
    /// monotonic clock within a run (so it never goes backwards), from the wall clock across a
    /// resume.
    pub(super) fn mission_time(&self, instant: Instant) -> Micros {
        let since = instant.saturating_duration_since(self.t0);
        self.base + since.as_micros().min(u64::MAX as u128) as u64
    }

    /// Runs until SIGINT/SIGTERM (or `run_for`) and reports what was done.
    pub fn run(mut self) -> Result<PlayReport, PlayError> {
        info!(project = %self.project.name, vehicle = %self.opts.vehicle, wait = ?self.opts.wait, "player started");
        // The programs already there are known from now on; one that dies later is lost. An
        // error here shows again at the next check, which reports it.
        if let Err(e) = self.watch.check() {
            warn!(error = %e, "liveness check failed");
        }
        loop {
            self.process_queue();
            // The clock is read twice a round: here, for what is due before the wait (the
            // heartbeat, the journal's hold, the wait's timeout), and when the wait ends.
            let now = Instant::now();
            self.heartbeat_if_due(now);
            let hold = self.write_or_hold(now);
            if self.journal.has_changes() {
                // The heartbeat's flush changed the recorder's state: tell the nets now.
                continue;
            }
            if let Some(limit) = self.opts.run_for {
                if now.saturating_duration_since(self.t0) >= limit {
                    info!("run time over");
                    break;
                }
            }
            let timeout = self.wait_timeout(now, hold);
            let ready = match self
                .reactor
                .wait(&[&self.ports.events, &self.ports.reload], Some(timeout))
            {
                Ok(r) => r,
                Err(e) => {
                    warn!(error = %e, "waiting failed; retrying");
                    std::thread::sleep(Duration::from_millis(1));
                    continue;
                }
            };
            if ready.termination_requested() {
                info!("termination requested: stopping");
                break;
            }
            self.take_inputs(Instant::now());
        }
        self.stop()
    }

    /// Writes the journal's batch of records, unless a spinning player may still hold it: how
    /// long it may, then. Everything journaled reaches the operating system before the player
    /// sleeps; a spinning player holds a round's records while the next event may come (at most
    /// [`BATCH_DELAY`]), so that their write is not on that event's path.
    fn write_or_hold(&mut self, now: Instant) -> Option<Duration> {
        let hold = match self.reactor.strategy() {
            WaitStrategy::Block => None,
            WaitStrategy::Spin => Some(None),
            WaitStrategy::SpinThenBlock(window) => Some(Some(window)),
        }
        .and_then(|window| {
            let since = self.journal.batch_since()?;
            let left = BATCH_DELAY.saturating_sub(now.saturating_duration_since(since));
            (!left.is_zero()).then(|| window.map_or(left, |w| w.min(left)))
        });
        if hold.is_none() {
            self.journal.write_batch();
        }
        hold
    }

    /// How long the wait that starts `now` may last: until the next heartbeat, liveness check
    /// or timer deadline, shorter while a reload is verified or calls are held, and within the
    /// journal's `hold`.
    fn wait_timeout(&self, now: Instant, hold: Option<Duration>) -> Duration {
        let mut timeout = self
            .next_heartbeat
            .min(self.next_liveness)
            .saturating_duration_since(now);
        if let Some(d) = self.engine.next_deadline() {
            timeout = timeout.min(Duration::from_micros(
                d.saturating_sub(self.mission_time(now)),
            ));
        }
        if self.reload.is_verifying() {
            // The verifier's thread says nothing when it is done: look again soon.
            timeout = timeout.min(Duration::from_millis(2));
        }
        if !self.held.is_empty() {
            // Nothing says when a receiver connects: look for the held calls' programs.
            timeout = timeout.min(HOLD_POLL);
        }
        if let Some(hold) = hold {
            // Within a spin window, so that the wait ends before it could sleep.
            timeout = timeout.min(hold);
        }
        timeout
    }

    /// After the wait, which ended at `woke`: time moves forward, then the events, the
    /// programs' comings and goings, and the reloads are taken.
    fn take_inputs(&mut self, woke: Instant) {
        self.engine.advance_to(self.mission_time(woke));
        self.ledger.set_clock(woke);
        let someone_died = self.take_events();
        if someone_died || woke >= self.next_liveness {
            self.check_liveness();
        }
        self.take_reload_requests();
        self.finish_reload();
    }

    /// The player stops: a last look at the programs, the journal flushed, the report.
    fn stop(mut self) -> Result<PlayReport, PlayError> {
        // A last look at the programs: one gone since the last check (the programs of a
        // vehicle stop before its player) is journaled, a stop, or a loss as an input that a
        // resumed player takes.
        self.check_liveness();
        if self.journal.flush() != Settlement::Recorded {
            error!(
                state = self.journal.state().as_str(),
                reason = self.journal.reason(),
                backlog = ?self.journal.backlog(),
                lost = self.journal.lost,
                "the player stops with journal records not written: the journal ends at its last good record"
            );
        }
        self.count_journal();
        self.report.stats = self.engine.stats();
        info!(report = ?self.report, "player stopped");
        Ok(self.report)
    }

    /// Submits an event raised by the player itself, journaled like any input.
    pub(super) fn raise(&mut self, event: Option<EventId>, params: Vec<Value>) {
        crate::intake::raise(&mut self.engine, &mut self.journal, event, params);
    }

    /// Processes everything queued (by the start, a timer, an event), journals and publishes
    /// each step, and raises `call_failed` for the calls that could not be delivered.
    pub(super) fn process_queue(&mut self) {
        // The recorder's changes are raised (queued) even while a reload holds the steps, so
        // that the loop does not come back here for them before it waits.
        self.raise_recorder_changes();
        // A reload under way holds the steps: the new version starts from the state it maps.
        if self.reload.holds_steps() {
            return;
        }
        // The start's calls not delivered, then the held calls whose program now receives.
        self.settle_undelivered();
        self.deliver_held();
        loop {
            let mut sink = RuntimeSink {
                record: &mut self.record,
                calls: &self.ports.calls,
                holding: self.held.holding(),
                undelivered: &mut self.undelivered,
                sent: &mut self.report.calls_sent,
            };
            let Some(step) = self.engine.step(&mut sink) else {
                if self.step_no == 0 {
                    self.publish_delta();
                    self.step_no += 1;
                }
                // Journaling these steps may have changed the recorder's state.
                if self.raise_recorder_changes() {
                    continue;
                }
                break;
            };
            let (event, params) = match &self.record.taken {
                Some((event, params)) => (event.as_str(), params.as_slice()),
                None => ("", &[][..]),
            };
            // Encoded from the record and the engine as they are: no copy of the step.
            self.journal.append_step(&StepParts {
                time: self.engine.now(),
                event,
                params,
                outcome: outcome_name(step.outcome),
                fired: self.record.fired_encoded(),
                actions: &self.record.actions,
                state: self.engine.state(),
                deadlines: self.engine.deadlines(),
            });
            self.publish_delta();
            self.step_no += 1;
            self.record.clear();
            self.settle_undelivered();
        }
    }

    /// Holds each call of the last step that could not be delivered, if its program's process
    /// lives (it may be joining: [`HeldCalls`]) or calls to it are held already; raises
    /// `call_failed` for the others.
    pub(super) fn settle_undelivered(&mut self) {
        for u in std::mem::take(&mut self.undelivered) {
            let prog = &self.project.programs[u.program as usize];
            let function = &prog.functions[u.function as usize].name;
            let hold = match &u.body {
                None => false,
                Some(_) if self.held.holding().get(u.program as usize) == Some(&true) => true,
                Some(_) => match self.watch.probe(&prog.name) {
                    Ok(status) => status.is_some_and(|s| s.is_running()),
                    Err(e) => {
                        warn!(error = %e, "liveness check failed");
                        false
                    }
                },
            };
            match u.body {
                Some(body) if hold => {
                    self.report.calls_held += 1;
                    self.held
                        .hold(u.program, &prog.name, function, body, Instant::now());
                }
                _ => {
                    let (program, function) = (prog.name.clone(), function.clone());
                    self.call_failed(program, function, &u.error);
                }
            }
        }
    }

    /// Sends the held calls whose program receives now; raises `call_failed` for those held
    /// too long.
    pub(super) fn deliver_held(&mut self) {
        if self.held.is_empty() {
            return;
        }
        let (sent, failed) = self
            .held
            .deliver(self.project, &self.ports.calls, Instant::now());
        self.report.calls_sent += sent;
        for (program, function, why) in failed {
            self.call_failed(program, function, &why);
        }
    }

    /// A call that could not be delivered, `why`: logged, counted, and raised as
    /// `call_failed(program, function)`.
    pub(super) fn call_failed(&mut self, program: String, function: String, why: &str) {
        warn!(%program, %function, reason = why, "call not delivered: raising call_failed");
        self.report.calls_failed += 1;
        let params = vec![Value::Text(program), Value::Text(function)];
        self.raise(self.builtins.call_failed, params);
    }

    /// Raises `recorder_failed` and `recorder_restored` for the recorder's changes of state;
    /// true when it raised any.
    pub(super) fn raise_recorder_changes(&mut self) -> bool {
        let changes = self.journal.take_changes();
        for change in &changes {
            match change {
                RecorderChange::Failed(reason) => {
                    let mut reason = reason.clone();
                    petrel_ipc::wire::cut_text(&mut reason, petrel_ipc::wire::MAX_REASON_LEN);
                    self.raise(self.builtins.recorder_failed, vec![Value::Text(reason)]);
                }
                RecorderChange::Restored => self.raise(self.builtins.recorder_restored, vec![]),
            }
        }
        !changes.is_empty()
    }

    pub(super) fn count_journal(&mut self) {
        if let Some((records, busy)) = self.journal.written() {
            self.report.journal_records = records;
            self.report.journal_busy = busy;
        }
        self.report.journal_failures = self.journal.failures;
        self.report.journal_lost = self.journal.lost;
    }

    /// Drains the events service into the engine ([`Intake`]); true when iceoryx2 saw a
    /// sender die.
    pub(super) fn take_events(&mut self) -> bool {
        let mut intake = Intake {
            engine: &mut self.engine,
            journal: &mut self.journal,
            ledger: &mut self.ledger,
            messages: &mut self.report.messages,
            bad_messages: &mut self.report.bad_messages,
            bad_message: self.builtins.bad_message,
            leaves: &mut self.leaves,
        };
        // Each event is decoded where it lies: its name read from the sample, its parameters
        // into `decoded` (kept from one drain to the next), then moved into one of the
        // engine's buffers. No event is built, and no name copied.
        let drained = self
            .ports
            .events
            .drain_in_place(&mut self.decoded, |r, decoded| match r {
                Ok(rcv) => intake.event(Header::from(&rcv), rcv.msg, decoded),
                Err(RecvError::Undecodable {
                    origin,
                    seq,
                    error,
                    sender,
                    missed,
                    ..
                }) => intake.undecodable(
                    Header {
                        sender,
                        origin,
                        seq,
                        missed,
                    },
                    &error.to_string(),
                ),
                Err(e @ RecvError::Foreign { .. }) => {
                    let origin = match &e {
                        RecvError::Foreign { origin, .. } => origin.to_string(),
                        _ => String::new(),
                    };
                    intake.foreign(&origin, &e.to_string())
                }
                Err(e) => intake.failed(&e),
            });
        match drained {
            Ok(d) => d.wakeups.senders_died > 0,
            Err(e) => {
                warn!(error = %e, "draining events failed");
                false
            }
        }
    }

    /// Lists the vehicle's nodes: a program whose process went becomes `program_lost`, or, if it
    /// said it leaves in good order, a stop (journaled, logged at INFO); the calls held for it
    /// fail.
    pub(super) fn check_liveness(&mut self) {
        self.next_liveness = Instant::now() + self.opts.liveness;
        let changes = match self.watch.check() {
            Ok(changes) => changes,
            Err(e) => return warn!(error = %e, "liveness check failed"),
        };
        if changes.iter().any(|c| c.is_lost()) {
            // A leave sent just before the process went is read before its going is judged:
            // the listing saw the node gone, so the leave (sent before) is there to read.
            self.take_events();
        }
        for c in changes {
            if !c.is_lost() {
                if !c.from.is_running() {
                    // A new process of the program: what the old one said is forgotten.
                    self.leaves.remove(&c.program);
                }
                info!(program = %c.program, status = ?c.to, "program status");
                continue;
            }
            let because = if self.leaves.remove(&c.program) {
                info!(program = %c.program, "program stopped in good order");
                self.journal.append(&Entry::ProgramStopped {
                    time: self.engine.now(),
                    program: c.program.clone(),
                });
                "it stopped"
            } else {
                warn!(program = %c.program, status = ?c.to, "program lost");
                let params = vec![Value::Text(c.program.clone())];
                self.raise(self.builtins.program_lost, params);
                "it was lost"
            };
            let failed = self.held.drop_program(self.project, &c.program, because);
            for (program, function, why) in failed {
                self.call_failed(program, function, &why);
            }
        }
    }
}
