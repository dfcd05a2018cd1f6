//! [`RuntimeSink`]: what the engine asks for during one of the player's steps, done: calls
//! sent at once (encoded from the borrowed arguments straight into the loaned sample), or
//! handed back undelivered (held or `call_failed` after the step); everything kept in the
//! step's record.

use crate::engine::{Args, Micros, Sink};
use crate::held::Undelivered;
use crate::record::StepRecord;
use petrel_ipc::{CallRef, CallSender, SendError};
use petrel_nets::compiled::{EventId, FunctionId, NetId, ProgramId, TimerId, Value};
use petrel_nets::semantics::Notice;
use tracing::{debug, error, info, warn};

/// Sends what the engine asks for, during one step, and keeps its record.
pub(super) struct RuntimeSink<'a, 'p> {
    pub(super) record: &'a mut StepRecord<'p>,
    pub(super) calls: &'a [CallSender],
    /// By program: calls to it are held ([`HeldCalls`]); a new one goes behind them.
    pub(super) holding: &'a [bool],
    /// Calls that could not be delivered in this step: each is held, or becomes `call_failed`.
    pub(super) undelivered: &'a mut Vec<Undelivered>,
    pub(super) sent: &'a mut u64,
}

impl Sink for RuntimeSink<'_, '_> {
    fn taken(&mut self, event: EventId, params: &[Value]) {
        self.record.taken(event, params);
    }

    fn fired(&mut self, net: NetId, transition: u32) {
        let n = &self.record.project.nets[net as usize];
        debug!(net = %n.name, transition = %n.transitions[transition as usize].name, "fired");
        self.record.fired(net, transition);
    }

    fn activated(&mut self, net: NetId) {
        self.record.activated(net);
    }

    fn deactivated(&mut self, net: NetId) {
        self.record.deactivated(net);
    }

    fn call(&mut self, program: ProgramId, function: FunctionId, args: Args<'_>) {
        let project = self.record.project;
        let prog = &project.programs[program as usize];
        let fname = &prog.functions[function as usize].name;
        let body = CallRef {
            function: fname,
            args: args.iter(),
        };
        // Behind calls to the same program held, or not yet settled, in order.
        let behind = self.holding.get(program as usize) == Some(&true)
            || self
                .undelivered
                .iter()
                .any(|u| u.program == program && u.body.is_some());
        // Encoded from the borrowed arguments straight into the loaned sample.
        let sent = match behind {
            false => self.calls[program as usize].send_body(&body).map_err(Some),
            true => Err(None),
        };
        match sent {
            Ok(_) => {
                *self.sent += 1;
                debug!(program = %prog.name, function = %fname, "call sent");
            }
            Err(e) => {
                // A call that found no receiver may be held (the program may be joining):
                // encoded apart, for later.
                let holdable = e
                    .as_ref()
                    .is_none_or(|e| matches!(e, SendError::NoReceiver { .. }));
                let body = holdable
                    .then(|| {
                        let mut bytes = vec![0; petrel_ipc::wire::encoded_len(&body).ok()?];
                        petrel_ipc::wire::encode_into(&body, &mut bytes).ok()?;
                        Some(bytes)
                    })
                    .flatten();
                let error = e.map_or_else(
                    || "calls to this program are held".to_string(),
                    |e| e.to_string(),
                );
                self.undelivered.push(Undelivered {
                    program,
                    function,
                    body,
                    error,
                });
            }
        }
        // The call's text for the journal and the monitors once the call is out.
        self.record.call(program, function, args);
    }

    fn emitted(&mut self, event: EventId, params: &[Value]) {
        self.record.emitted(event, params);
    }

    fn timer_started(&mut self, timer: TimerId, deadline: Micros) {
        self.record.timer_started(timer, deadline);
    }

    fn timer_cancelled(&mut self, timer: TimerId) {
        self.record.timer_cancelled(timer);
    }

    fn safety_violation(&mut self, net: NetId, transition: u32, place: &str) {
        let n = &self.record.project.nets[net as usize];
        warn!(net = %n.name, transition = %n.transitions[transition as usize].name, place, "firing refused: a second token; raising safety_violation");
        self.record.safety_violation(net, transition, place);
    }

    fn conflict(&mut self, net: NetId, transition: u32) {
        self.record.conflict(net, transition);
    }

    fn notice(&mut self, notice: Notice) {
        info!(?notice, "notice");
        self.record.notice(notice);
    }

    fn livelock(&mut self) {
        warn!("immediate transitions did not settle: fixpoint stopped, raising livelock");
        self.record.livelock();
    }

    fn cascade_stopped(&mut self, steps: u32, dropped: u64) {
        warn!(
            steps,
            dropped,
            "events produced at one instant did not settle: cascade stopped, produced events dropped, raising livelock"
        );
        self.record.cascade_stopped(steps, dropped);
    }

    fn invariant_violated(&mut self, name: &str) {
        error!(
            invariant = name,
            "an invariant of the manifest stopped holding: raising invariant_violated"
        );
        self.record.invariant_violated(name);
    }
}
