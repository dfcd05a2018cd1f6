//! Calls held for programs that are joining (docs/semantics.md, "Held calls").
//!
//! A program's process makes its iceoryx2 node a moment before its calls receiver, so a call
//! made in between finds nobody to receive it. When a call finds no receiver and the program's
//! process lives (its node is alive: [`ProgramStatus::Joining`](petrel_ipc::ProgramStatus)),
//! the player keeps the encoded call and sends it once the receiver is there, in the order the
//! nets made the calls (a later call to the same program waits behind it); a call held for
//! [`CALL_HOLD`] becomes `call_failed`, with the reason in the log, as does every held call of a
//! program that goes (lost or stopped). A call to a program with no live process fails at once,
//! as before. Sans I/O but for the senders it is handed.

use petrel_ipc::{CallSender, SendError};
use petrel_nets::compiled::CompiledProject;
use std::collections::VecDeque;
use std::time::{Duration, Instant};
use tracing::info;

/// The longest a call waits for its program's receiver: far beyond the few milliseconds
/// between a program's node and its calls receiver (or a loaded machine's hundreds), short
/// beside a mission's timeouts, so that a program whose process lives but never receives
/// (hung while it starts) gives `call_failed` soon.
pub const CALL_HOLD: Duration = Duration::from_secs(2);

/// How often the player looks for the receiver of a held call (it is told nothing when a
/// receiver connects): the player's wait is this short while calls are held.
pub const HOLD_POLL: Duration = Duration::from_millis(1);

/// A call the player's sink could not hand over when its step made it.
#[derive(Debug)]
pub struct Undelivered {
    /// The program, by index in the project.
    pub program: u32,
    /// The function, by index in the program.
    pub function: u32,
    /// The encoded call, when it may be held: no receiver (the program may be joining), or
    /// calls to the same program held before it.
    pub body: Option<Vec<u8>>,
    /// Why it was not sent.
    pub error: String,
}

/// A call held for its program's receiver.
#[derive(Debug)]
struct Held {
    program: String,
    function: String,
    body: Vec<u8>,
    since: Instant,
}

/// A held call that failed: the program, the function, and why.
pub type Failed = (String, String, String);

/// The calls held, in the order the nets made them.
#[derive(Debug, Default)]
pub struct HeldCalls {
    held: VecDeque<Held>,
    /// By program index: whether calls to it are held (a new call goes behind them).
    holding: Vec<bool>,
}

impl HeldCalls {
    /// None held, for a project of `programs` programs.
    pub fn new(programs: usize) -> Self {
        HeldCalls {
            held: VecDeque::new(),
            holding: vec![false; programs],
        }
    }

    /// Whether no call is held.
    pub fn is_empty(&self) -> bool {
        self.held.is_empty()
    }

    /// By program index, whether calls to it are held.
    pub fn holding(&self) -> &[bool] {
        &self.holding
    }

    /// Holds `body`, a call of `function` to program `program` (index `index`), made `now`.
    pub fn hold(&mut self, index: u32, program: &str, function: &str, body: Vec<u8>, now: Instant) {
        info!(
            program,
            function,
            bound_s = CALL_HOLD.as_secs_f64(),
            "call held: the program's process lives but does not receive its calls yet"
        );
        if let Some(h) = self.holding.get_mut(index as usize) {
            *h = true;
        }
        self.held.push_back(Held {
            program: program.to_string(),
            function: function.to_string(),
            body,
            since: now,
        });
    }

    /// Sends the held calls whose program receives now, in order; returns how many went, and
    /// those that failed: held for [`CALL_HOLD`] already, refused by the transport, or to a
    /// program the project (reloaded) no longer has. `senders` are the project's, by program.
    pub fn deliver(
        &mut self,
        project: &CompiledProject,
        senders: &[CallSender],
        now: Instant,
    ) -> (u64, Vec<Failed>) {
        let mut sent = 0;
        let mut failed = Vec::new();
        let mut kept = VecDeque::new();
        // Programs whose earlier call still waits: the later ones wait behind it.
        let mut waiting: Vec<String> = Vec::new();
        while let Some(h) = self.held.pop_front() {
            if waiting.contains(&h.program) {
                kept.push_back(h);
                continue;
            }
            let index = project.programs.iter().position(|p| p.name == h.program);
            let Some(sender) = index.and_then(|i| senders.get(i)) else {
                let why = "the project was reloaded without this program".to_string();
                failed.push((h.program, h.function, why));
                continue;
            };
            let result = match sender.receivers() {
                0 => None,
                _ => Some(sender.send_encoded(&h.body)),
            };
            match result {
                Some(Ok(_)) => {
                    sent += 1;
                    let held_ms = now.saturating_duration_since(h.since).as_secs_f64() * 1e3;
                    info!(program = %h.program, function = %h.function, held_ms, "held call delivered");
                }
                None | Some(Err(SendError::NoReceiver { .. })) => {
                    if now.saturating_duration_since(h.since) >= CALL_HOLD {
                        let why = format!(
                            "its process lived {:.1} s without receiving its calls (the bound of a held call)",
                            CALL_HOLD.as_secs_f64()
                        );
                        failed.push((h.program, h.function, why));
                    } else {
                        waiting.push(h.program.clone());
                        kept.push_back(h);
                    }
                }
                Some(Err(e)) => failed.push((h.program, h.function, e.to_string())),
            }
        }
        self.held = kept;
        self.refresh(project);
        (sent, failed)
    }

    /// Takes every call held for `program` (it went: lost or stopped), as failed `because`.
    pub fn drop_program(
        &mut self,
        project: &CompiledProject,
        program: &str,
        because: &str,
    ) -> Vec<Failed> {
        let (gone, kept): (VecDeque<Held>, VecDeque<Held>) =
            self.held.drain(..).partition(|h| h.program == program);
        self.held = kept;
        self.refresh(project);
        gone.into_iter()
            .map(|h| (h.program, h.function, because.to_string()))
            .collect()
    }

    /// Which programs of `project` calls are held for (after a change, or a reload).
    pub fn refresh(&mut self, project: &CompiledProject) {
        self.holding.clear();
        self.holding.extend(
            project
                .programs
                .iter()
                .map(|p| self.held.iter().any(|h| h.program == p.name)),
        );
    }
}
