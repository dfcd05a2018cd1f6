//! A reload of the running project (`petrel reload`, docs/reload.md): what the player decides,
//! sans I/O.
//!
//! A request names a directory. The player reads and checks the new version there
//! ([`version::load_candidate`]: its content hash must be the one the requester read), maps
//! the running state onto it by names (`petrel_nets::reload::map_state`), and verifies it from
//! the mapped state in a thread of its own, while the loop goes on taking events (a reload
//! that swaps holds the steps meanwhile; a dry run does not). Once the verdict is in, the
//! player swaps the engine between two steps, or refuses and the mission goes on unchanged.
//! Every request is answered, to every listener (the requester finds its answer by its sender
//! and sequence number; a shadow follows accepted reloads).
//!
//! [`ReloadJob`] holds these decisions and nothing else: a request in, refused at once (another
//! reload is being verified) or admitted; its new version in, [`Begin::Refuse`] or
//! [`Begin::Verify`] out; a verdict in, [`Settle::Answer`] or [`Settle::Swap`] out, whose answer
//! is finished with what the swap did ([`SwapAnswer::after_swap`]). The clock is injected (an
//! answer says the milliseconds from its request), and so is the reading of the directory, so
//! that the tests run on compiled projects with no player. The verifying thread and the swap
//! itself are the runtime's (`runtime/reload.rs`); [`version`] keeps each version's files
//! beside the journal, for replay and `--resume`.

pub mod version;

use crate::engine::Engine;
use petrel_ipc::{ReloadAnswer, ReloadRequest};
use petrel_nets::compiled::CompiledProject;
use petrel_nets::reload::{Finding, MapRefusal, Mapped, OldState};
use std::time::Instant;
use version::Candidate;

/// The verdict of a verification from the mapped state: the stable states it explored, or
/// what it found that refuses the reload.
pub type Verdict = Result<u64, Finding>;

/// Who asked for a reload: the request's sender and sequence number, which its answer names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Requester {
    /// The requesting port's sender id.
    pub sender: u64,
    /// The request's sequence number.
    pub seq: u64,
}

/// The reloads of one player: at most one is verified at a time.
#[derive(Default)]
pub struct ReloadJob {
    verifying: Option<Verifying>,
}

/// The reload under verification.
struct Verifying {
    from: Requester,
    request: ReloadRequest,
    received: Instant,
    candidate: Candidate,
    summary: Vec<String>,
}

/// A request the job takes: its new version is to be read, then given to [`ReloadJob::begin`].
pub struct Admitted {
    from: Requester,
    request: ReloadRequest,
    received: Instant,
}

impl Admitted {
    /// The request (its directory, content hash and mapping).
    pub fn request(&self) -> &ReloadRequest {
        &self.request
    }
}

/// What to do with an admitted request, once its new version is read.
pub enum Begin {
    /// Answer it: refused.
    Refuse(ReloadAnswer),
    /// Verify `project` from the `mapped` state (in a thread: it may take seconds), then give
    /// the verdict to [`ReloadJob::verdict`] (or, if the verification cannot start, say why to
    /// [`ReloadJob::abandon`]).
    Verify {
        /// The verifier's own copy of the new version (a refused version is dropped whole).
        project: Box<CompiledProject>,
        /// The running state, mapped onto it.
        mapped: Mapped,
    },
}

/// What to do with a verdict.
pub enum Settle {
    /// Answer: refused, or accepted for a dry run.
    Answer(ReloadAnswer),
    /// Swap to `candidate` between two steps, then send the answer
    /// ([`SwapAnswer::after_swap`]).
    Swap {
        /// The new version.
        candidate: Box<Candidate>,
        /// The directory it was read from (journaled with the reload).
        dir: String,
        /// The answer, finished with what the swap did.
        answer: SwapAnswer,
    },
}

/// The answer of an accepted reload, waiting for the swap.
pub struct SwapAnswer {
    answer: ReloadAnswer,
    received: Instant,
}

impl ReloadJob {
    /// A reload is being verified (the status says `reloading`).
    pub fn is_verifying(&self) -> bool {
        self.verifying.is_some()
    }

    /// The steps are held: a reload that swaps (not a dry run) is being verified, and the new
    /// version starts from the state it mapped.
    pub fn holds_steps(&self) -> bool {
        self.verifying.as_ref().is_some_and(|v| !v.request.dry_run)
    }

    /// A request, received at `now`: refused at once while another reload is being verified,
    /// admitted otherwise (its new version is read next).
    pub fn request(
        &self,
        from: Requester,
        request: ReloadRequest,
        now: Instant,
    ) -> Result<Admitted, Box<ReloadAnswer>> {
        if self.verifying.is_some() {
            let why = "another reload is being verified: ask again when it is answered";
            return Err(Box::new(refusal(
                from,
                &request,
                now,
                now,
                vec![why.into()],
            )));
        }
        Ok(Admitted {
            from,
            request,
            received: now,
        })
    }

    /// The new version of an `admitted` request as it was `read` (or every reason it is not
    /// one), at `now`: the `running` version's state is mapped onto it and it is to be
    /// verified, or it is refused with every reason.
    pub fn begin(
        &mut self,
        admitted: Admitted,
        read: Result<Candidate, Vec<String>>,
        running: (&CompiledProject, &OldState),
        now: Instant,
    ) -> Begin {
        let Admitted {
            from,
            request,
            received,
        } = admitted;
        let mapped = read.and_then(|candidate| {
            let mapped = map_onto(running.0, running.1, &candidate).map_err(|r| r.reasons)?;
            Ok((candidate, mapped))
        });
        let (candidate, mapped) = match mapped {
            Ok(m) => m,
            Err(reasons) => return Begin::Refuse(refusal(from, &request, received, now, reasons)),
        };
        let project = Box::new(candidate.project.clone());
        self.verifying = Some(Verifying {
            from,
            request,
            received,
            candidate,
            summary: mapped.summary.clone(),
        });
        Begin::Verify { project, mapped }
    }

    /// The verification could not start (`why`), at `now`: the reload is refused.
    pub fn abandon(&mut self, why: String, now: Instant) -> Option<ReloadAnswer> {
        let v = self.verifying.take()?;
        Some(refusal(v.from, &v.request, v.received, now, vec![why]))
    }

    /// The `verdict` on the reload being verified (the stable states explored, or what the
    /// verification found), in at `now`, after the player's step `step`: the answer of a
    /// refusal or of a dry run, or the swap to carry out. `None` when none is verified.
    pub fn verdict(&mut self, verdict: Verdict, step: u64, now: Instant) -> Option<Settle> {
        let v = self.verifying.take()?;
        let mut answer = ReloadAnswer {
            request_sender: v.from.sender,
            request_seq: v.from.seq,
            dry_run: v.request.dry_run,
            dir: v.request.dir.clone(),
            source_hash: v.candidate.source_hash.clone(),
            summary: v.summary,
            ..ReloadAnswer::default()
        };
        let states = match verdict {
            Ok(states) => states,
            Err(f) => {
                answer.reasons = vec![
                    format!("verification from the mapped state: {}", f.what),
                    if f.trace.is_empty() {
                        "in the mapped state itself".to_string()
                    } else {
                        format!("from the mapped state by: {}", f.trace.join(", "))
                    },
                ];
                answer.trace = f.trace;
                answer.millis = millis(v.received, now);
                return Some(Settle::Answer(answer));
            }
        };
        answer.accepted = true;
        answer.step = step;
        answer.states = states;
        if v.request.dry_run {
            answer.millis = millis(v.received, now);
            return Some(Settle::Answer(answer));
        }
        Some(Settle::Swap {
            candidate: Box::new(v.candidate),
            dir: v.request.dir,
            answer: SwapAnswer {
                answer,
                received: v.received,
            },
        })
    }
}

impl SwapAnswer {
    /// The answer once the swap is done, at `now`: accepted with what the swap did
    /// (`Ok(handed)`: the queue handed over), or refused with why it could not be done.
    pub fn after_swap(self, swapped: Result<String, Vec<String>>, now: Instant) -> ReloadAnswer {
        let mut answer = self.answer;
        match swapped {
            Ok(handed) => answer.summary.push(handed),
            Err(reasons) => {
                answer.accepted = false;
                answer.reasons = reasons;
            }
        }
        answer.millis = millis(self.received, now);
        answer
    }
}

/// The `running` version's state mapped onto `candidate` (at the request, and again at the
/// swap: a timer may have fallen due during the verification).
pub fn map_onto(
    running: &CompiledProject,
    state: &OldState,
    candidate: &Candidate,
) -> Result<Mapped, MapRefusal> {
    petrel_nets::reload::map_state(running, state, &candidate.project, &candidate.mapping)
}

/// The running version's state, as the engine holds it between two steps.
pub fn running_state<'a>(engine: &'a Engine) -> OldState<'a> {
    OldState {
        state: engine.state(),
        deadlines: engine.deadlines(),
        net_args: engine.all_net_args(),
    }
}

/// The answer refusing `request`, received at `received`, at `now`, for `reasons`.
fn refusal(
    from: Requester,
    request: &ReloadRequest,
    received: Instant,
    now: Instant,
    reasons: Vec<String>,
) -> ReloadAnswer {
    ReloadAnswer {
        request_sender: from.sender,
        request_seq: from.seq,
        accepted: false,
        dry_run: request.dry_run,
        dir: request.dir.clone(),
        source_hash: request.source_hash.clone(),
        reasons,
        millis: millis(received, now),
        ..ReloadAnswer::default()
    }
}

/// Milliseconds from `since` to `now`.
fn millis(since: Instant, now: Instant) -> u64 {
    now.saturating_duration_since(since).as_millis() as u64
}

#[cfg(test)]
mod tests;
