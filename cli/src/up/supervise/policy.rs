//! What `petrel up` decides, without doing any of it: when each process starts (its
//! dependencies satisfied, its restart delay passed), when it is ready, what its end means
//! (a restart with doubling backoff, a failure for good, the end of the run), when the vehicle
//! is up, which timed sends are due and whether the player acknowledged them, whether an
//! `--until` condition or the mission's end is reached, and the order of the stop.
//!
//! Sans I/O: the shell ([`super::shell`]) tells it what happened (a process started, ended,
//! what the heartbeats and the marking deltas show) with the time injected (`now`), and
//! carries out the [`Action`]s it returns (messages, signals, sends, the end of the run).

use crate::up::file::{Kind, Restart, SendSpec};
use crate::up::{Planned, Until};
use nix::sys::signal::Signal;
use std::collections::BTreeSet;
use std::time::{Duration, Instant};

/// How long the player has to acknowledge a timed send (as `petrel send` waits).
pub const ACK_GRACE: Duration = Duration::from_secs(10);
/// The longest delay between two restarts, however many failures came before.
pub const MAX_BACKOFF: Duration = Duration::from_secs(30);

/// Where a process is in its life.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum State {
    /// Not started: waiting for the processes it comes after.
    Waiting,
    /// Started, not yet ready.
    Starting,
    /// Ready, while others are still starting.
    Ready,
    /// Ready, and the vehicle is up.
    Running,
    /// Failed; started again at the given time.
    Restarting(Instant),
    /// Asked to stop (SIGTERM sent).
    Stopping,
    /// Ended with this exit code.
    Exited(i32),
    /// Ended by this signal.
    Killed(i32),
    /// Never started (the run ended first).
    NotStarted,
}

impl State {
    /// The word of the status lines and the summary.
    pub fn word(&self) -> String {
        match self {
            State::Waiting => "waiting".into(),
            State::Starting => "starting".into(),
            State::Ready => "ready".into(),
            State::Running => "running".into(),
            State::Restarting(_) => "restarting".into(),
            State::Stopping => "stopping".into(),
            State::Exited(c) => format!("exited({c})"),
            State::Killed(s) => format!("killed({})", signal_name(*s)),
            State::NotStarted => "not started".into(),
        }
    }

    /// Ready (the vehicle up or not).
    pub fn is_up(&self) -> bool {
        matches!(self, State::Ready | State::Running)
    }
}

fn signal_name(s: i32) -> String {
    Signal::try_from(s)
        .map(|s| s.as_str().to_string())
        .unwrap_or_else(|_| format!("signal {s}"))
}

/// One supervised process, as the policy knows it (its child is the shell's).
pub struct Proc {
    /// How it is started.
    pub plan: Planned,
    /// Where it is in its life.
    pub state: State,
    /// Its process id, once started.
    pub pid: Option<u32>,
    /// Started and not yet reaped.
    pub alive: bool,
    /// Restarts so far (counted when one is due).
    pub restarts: u32,
    spawned_at: Option<Instant>,
    /// We asked it to stop: its death by SIGTERM is expected.
    stop_sent: Option<Instant>,
    /// SIGKILL sent (after the grace period, or at a second stop request).
    kill_sent: bool,
    /// Why SIGKILL was sent.
    killed_because: String,
    /// Why it failed for good.
    pub failure: Option<String>,
}

impl Proc {
    /// Done for dependency purposes: ready, or ended cleanly on its own (a one-shot setup).
    fn satisfies(&self) -> bool {
        self.state.is_up() || (self.state == State::Exited(0) && self.failure.is_none())
    }

    fn name(&self) -> &str {
        &self.plan.spec.name
    }
}

/// The signal a process's group gets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kill {
    /// SIGTERM: stop, in good order.
    Term,
    /// SIGKILL.
    Kill,
}

/// What the shell does for the policy.
#[derive(Debug, PartialEq, Eq)]
pub enum Action {
    /// Print this message above the status lines.
    Say(String),
    /// Send this signal to process `i`'s group (if it is still there).
    Signal(usize, Kill),
    /// Make timed send `k` (then tell [`Policy::sent`] its sequence number).
    Send(usize),
    /// The run ends (the first of a round wins).
    Finish(End),
}

/// Why the run ended.
#[derive(Debug, PartialEq, Eq)]
pub enum End {
    /// SIGINT, SIGTERM or SIGHUP.
    Signal(Signal),
    /// An `--until` condition.
    Until(String),
    /// The mission reached a planned end.
    MissionOver(String),
    /// Every process ended on its own.
    AllExited,
    /// The player ended on its own, cleanly (`--run-for` among its arguments): nothing runs
    /// the mission any more.
    PlayerExited,
    /// `--timeout`.
    Timeout(Duration),
    /// A process failed in a way that stops the vehicle (it is listed with its failure).
    ProcessFailed(String),
    /// The scenario cannot go on (a timed send not received or not acknowledged).
    Failure(String),
}

/// A timed send waiting for the player's acknowledgement.
struct PendingAck {
    text: String,
    seq: u64,
    deadline: Instant,
}

/// What the run is asked to do, beside its processes.
#[derive(Default)]
pub struct Rules {
    /// The timed sends of this computer, in time order.
    pub sends: Vec<SendSpec>,
    /// Conditions that end the run with success.
    pub until: Vec<Until>,
    /// The run fails past this.
    pub timeout: Option<Duration>,
    /// The manifest's final markings, as place names.
    pub finals: Vec<Vec<String>>,
    /// Stay up after the mission's end.
    pub keep_running: bool,
    /// Any failure for good stops the vehicle.
    pub fail_fast: bool,
}

/// The signs of readiness the shell saw.
#[derive(Default)]
pub struct Seen {
    /// The player's last heartbeat.
    pub player_beat: Option<Instant>,
    /// The data server's last heartbeat.
    pub bridge_beat: Option<Instant>,
    /// The programs a live node of which receives their calls (issue 30's rule: a call sent
    /// before the calls receiver connects finds nobody, so a live node alone is not ready).
    pub live_programs: BTreeSet<String>,
}

/// The player's latest heartbeat status.
#[derive(Default)]
pub struct PlayerStatus {
    /// Mission time, in seconds.
    pub time: f64,
    /// Events processed.
    pub processed: u64,
    /// Marked places (`NET.place`).
    pub marked: BTreeSet<String>,
    /// A catastrophic event ended the mission.
    pub over: bool,
    /// The whole status.
    pub doc: serde_json::Value,
}

/// What the player shows of the mission.
#[derive(Default)]
pub struct Observed {
    /// Its last heartbeat status.
    pub player: Option<PlayerStatus>,
    /// The marking rebuilt from the deltas (for `--until NET.place`).
    pub marked: BTreeSet<String>,
    /// Events the player took (for `--until EVENT`).
    pub events_seen: BTreeSet<String>,
}

/// The supervision's decisions.
pub struct Policy {
    /// The processes, dependencies first.
    pub procs: Vec<Proc>,
    rules: Rules,
    t0: Instant,
    /// When every process became ready.
    up_at: Option<Instant>,
    next_send: usize,
    acks: Vec<PendingAck>,
}

impl Policy {
    /// The processes of `processes`, none started, for a run that began at `t0`.
    pub fn new(processes: &[Planned], rules: Rules, t0: Instant) -> Policy {
        let procs = processes
            .iter()
            .map(|p| Proc {
                plan: p.clone(),
                state: State::Waiting,
                pid: None,
                alive: false,
                restarts: 0,
                spawned_at: None,
                stop_sent: None,
                kill_sent: false,
                killed_because: String::new(),
                failure: None,
            })
            .collect();
        Policy {
            procs,
            rules,
            t0,
            up_at: None,
            next_send: 0,
            acks: Vec::new(),
        }
    }

    /// Whether the vehicle came up (every process ready once).
    pub fn is_up(&self) -> bool {
        self.up_at.is_some()
    }

    /// The processes to start now: those whose dependencies are satisfied, and those whose
    /// restart delay passed (a restart is counted here: the start's number is `restarts + 1`).
    pub fn due(&mut self, now: Instant) -> Vec<usize> {
        let mut due = Vec::new();
        for i in 0..self.procs.len() {
            let start = match self.procs[i].state {
                State::Waiting => self.procs[i]
                    .plan
                    .after
                    .iter()
                    .all(|&j| self.procs[j].satisfies()),
                State::Restarting(at) => now >= at,
                _ => false,
            };
            if start {
                if matches!(self.procs[i].state, State::Restarting(_)) {
                    self.procs[i].restarts += 1;
                }
                due.push(i);
            }
        }
        due
    }

    /// Process `i` started, as `pid`.
    pub fn spawned(&mut self, i: usize, pid: u32, now: Instant) {
        let p = &mut self.procs[i];
        p.pid = Some(pid);
        p.alive = true;
        p.spawned_at = Some(now);
        p.state = State::Starting;
        p.stop_sent = None;
        p.kill_sent = false;
        p.killed_because.clear();
    }

    /// Process `i` could not start: the vehicle cannot come up.
    pub fn spawn_failed(&mut self, i: usize, why: &str) -> Vec<Action> {
        let p = &mut self.procs[i];
        p.state = State::NotStarted;
        p.failure = Some(why.to_string());
        let name = p.name();
        vec![
            Action::Say(format!("`{name}`: {why}")),
            Action::Finish(End::ProcessFailed(format!(
                "process `{name}` could not start: {why}"
            ))),
        ]
    }

    /// Process `i` cannot be waited for any more (cannot happen for our own child): it is
    /// taken as gone rather than waited for in a loop.
    pub fn lost(&mut self, i: usize) {
        self.procs[i].alive = false;
    }

    /// Process `i` ended with exit `code` or by `signal`. While the run goes on (`stopping`
    /// false), a failure follows the restart policy, and one that stops the vehicle ends the
    /// run: a critical process's (the player's), any under `--fail-fast`, any before the
    /// vehicle is up. A player that exits 0 on its own ends the run too.
    pub fn exited(
        &mut self,
        i: usize,
        code: Option<i32>,
        signal: Option<i32>,
        now: Instant,
        stopping: bool,
    ) -> Vec<Action> {
        let p = &mut self.procs[i];
        p.alive = false;
        p.state = match (code, signal) {
            (Some(c), _) => State::Exited(c),
            (None, Some(s)) => State::Killed(s),
            (None, None) => State::Exited(-1),
        };
        let name = p.name().to_string();
        if let Some(asked) = p.stop_sent {
            // Stopped by us: a clean exit, or death by our SIGTERM, is what was asked.
            let failure = if p.kill_sent {
                Some(format!("killed with SIGKILL: {}", p.killed_because))
            } else {
                match (code, signal) {
                    (Some(0), _) => None,
                    (None, Some(s)) if s == Signal::SIGTERM as i32 => None,
                    (Some(c), _) => Some(format!("exited with code {c} when stopped")),
                    (None, Some(s)) => Some(format!("died of {} when stopped", signal_name(s))),
                    (None, None) => Some("ended in an unknown way".into()),
                }
            };
            let took = now.saturating_duration_since(asked).as_secs_f64();
            if p.failure.is_none() {
                p.failure = failure;
            }
            let how = p.state.word();
            return vec![Action::Say(format!(
                "`{name}` stopped: {how} after {took:.2} s"
            ))];
        }
        let why = match (code, signal) {
            (Some(0), _) => {
                let mut out = vec![Action::Say(format!("`{name}` exited(0)"))];
                if p.plan.spec.kind == Kind::Player && !stopping {
                    out.push(Action::Finish(End::PlayerExited));
                }
                return out;
            }
            (Some(c), _) => format!("exited with code {c}"),
            (None, Some(s)) => format!("died of {}", signal_name(s)),
            (None, None) => "ended in an unknown way".into(),
        };
        self.failed(i, why, now, stopping)
    }

    /// Process `i` failed (`why`) on its own: restarted if its policy has restarts left, or
    /// failed for good.
    fn failed(&mut self, i: usize, why: String, now: Instant, stopping: bool) -> Vec<Action> {
        let critical = self.procs[i].plan.spec.critical || self.rules.fail_fast || !self.is_up();
        let p = &mut self.procs[i];
        let name = p.name().to_string();
        if let Restart::OnFailure { max, backoff } = p.plan.spec.restart {
            if p.restarts < max && !stopping {
                let delay = backoff
                    .saturating_mul(1u32 << p.restarts.min(16))
                    .min(MAX_BACKOFF);
                p.state = State::Restarting(now + delay);
                let n = p.restarts + 1;
                return vec![Action::Say(format!(
                    "`{name}` {why}: restart {n} of {max} in {:.2} s",
                    delay.as_secs_f64()
                ))];
            }
        }
        let failure = match p.plan.spec.restart {
            Restart::Never => format!("{why} (restart = \"never\")"),
            Restart::OnFailure { max, .. } if p.restarts >= max => {
                let restarts = petrel_nets::plural::count(max, "restart");
                format!("{why}, after {restarts}: none left")
            }
            Restart::OnFailure { .. } => why,
        };
        p.failure = Some(failure.clone());
        let mut out = vec![Action::Say(format!("`{name}` failed: {failure}"))];
        if critical && !stopping {
            let what = if p.plan.spec.kind == Kind::Player {
                "the player".to_string()
            } else {
                format!("process `{name}`")
            };
            out.push(Action::Finish(End::ProcessFailed(format!(
                "{what} failed: {failure}"
            ))));
        }
        out
    }

    /// Whether a program is starting (the shell then looks at the programs' nodes).
    pub fn awaits_programs(&self) -> bool {
        self.procs
            .iter()
            .any(|p| p.state == State::Starting && p.plan.spec.kind == Kind::Program)
    }

    /// Whether process `i`'s readiness is seen: a player's or a data server's heartbeat since
    /// it started, each of a program's programs receiving its calls; a command at once.
    fn is_ready(&self, i: usize, seen: &Seen) -> bool {
        let p = &self.procs[i];
        let Some(since) = p.spawned_at else {
            return false;
        };
        match p.plan.spec.kind {
            Kind::Player => seen.player_beat.is_some_and(|t| t > since),
            Kind::Bridge => seen.bridge_beat.is_some_and(|t| t > since),
            Kind::Command => true,
            Kind::Program => p
                .plan
                .spec
                .programs
                .iter()
                .all(|x| seen.live_programs.contains(x)),
        }
    }

    /// Sees which starting processes became ready; one not ready within its `ready_timeout`
    /// gets SIGTERM and fails, which ends the run before the vehicle is up (after: if it is
    /// critical, or under `--fail-fast`).
    pub fn readiness(&mut self, now: Instant, seen: &Seen) -> Vec<Action> {
        let mut out = Vec::new();
        for i in 0..self.procs.len() {
            if self.procs[i].state != State::Starting {
                continue;
            }
            let since = self.procs[i].spawned_at.unwrap_or(now);
            let waited = now.saturating_duration_since(since);
            let up = self.is_up();
            let fail_fast = self.rules.fail_fast;
            let ready = self.is_ready(i, seen);
            let p = &mut self.procs[i];
            let name = p.name().to_string();
            if ready {
                p.state = if up { State::Running } else { State::Ready };
                out.push(Action::Say(format!(
                    "`{name}` ready in {:.2} s",
                    waited.as_secs_f64()
                )));
            } else if waited > p.plan.spec.ready_timeout {
                let t = p.plan.spec.ready_timeout.as_secs_f64();
                let failure = format!("not ready within {t:.1} s");
                out.push(Action::Say(format!(
                    "`{name}` {failure}: stopping it (its log: {})",
                    p.plan.log.display()
                )));
                p.failure = Some(failure.clone());
                out.push(Action::Signal(i, Kill::Term));
                p.stop_sent = Some(now);
                p.state = State::Stopping;
                if !up || p.plan.spec.critical || fail_fast {
                    out.push(Action::Finish(End::ProcessFailed(format!(
                        "process `{name}` {failure}"
                    ))));
                }
            }
        }
        out
    }

    /// Whether the vehicle came up just now: every process ready (or done, for a one-shot).
    pub fn vehicle_up(&mut self, now: Instant) -> bool {
        if self.is_up() || !self.procs.iter().all(Proc::satisfies) {
            return false;
        }
        self.up_at = Some(now);
        for p in &mut self.procs {
            if p.state == State::Ready {
                p.state = State::Running;
            }
        }
        true
    }

    /// The timed sends due (counted from the moment the vehicle came up), and the end of the
    /// run if the player did not acknowledge one in time.
    pub fn sends_due(&mut self, now: Instant) -> Vec<Action> {
        let Some(up) = self.up_at else {
            return Vec::new();
        };
        let mut out = Vec::new();
        while let Some(s) = self.rules.sends.get(self.next_send) {
            if now.saturating_duration_since(up) < s.at {
                break;
            }
            out.push(Action::Send(self.next_send));
            self.next_send += 1;
        }
        if let Some(late) = self.acks.iter().find(|a| now >= a.deadline) {
            out.push(Action::Finish(End::Failure(format!(
                "the player did not acknowledge `{}` within {} s",
                late.text,
                ACK_GRACE.as_secs()
            ))));
        }
        out
    }

    /// Timed send `k`.
    pub fn send(&self, k: usize) -> &SendSpec {
        &self.rules.sends[k]
    }

    /// Timed send `k` went out as sequence number `seq`: the player has [`ACK_GRACE`] to
    /// acknowledge it.
    pub fn sent(&mut self, k: usize, seq: u64, now: Instant) {
        self.acks.push(PendingAck {
            text: self.rules.sends[k].text.clone(),
            seq,
            deadline: now + ACK_GRACE,
        });
    }

    /// The player acknowledged our sends up to `last_seq`: the texts of those it
    /// acknowledged now.
    pub fn acknowledged(&mut self, last_seq: u64) -> Vec<String> {
        let acked = self
            .acks
            .iter()
            .filter(|a| a.seq <= last_seq)
            .map(|a| a.text.clone())
            .collect();
        self.acks.retain(|a| a.seq > last_seq);
        acked
    }

    /// Whether an `--until` condition or the mission's end (a catastrophic event, a final
    /// marking; unless `--keep-running`) is reached.
    pub fn goal(&self, seen: &Observed) -> Option<End> {
        for u in &self.rules.until {
            let reached = match u {
                Until::Event(e) => seen.events_seen.contains(e),
                Until::Place(p) => {
                    seen.marked.contains(p)
                        || seen.player.as_ref().is_some_and(|s| s.marked.contains(p))
                }
            };
            if reached {
                return Some(End::Until(u.to_string()));
            }
        }
        if self.rules.keep_running {
            return None;
        }
        let s = seen.player.as_ref()?;
        if s.over {
            return Some(End::MissionOver(
                "the mission is over (a catastrophic event)".into(),
            ));
        }
        for f in &self.rules.finals {
            if !f.is_empty() && f.iter().all(|p| s.marked.contains(p)) {
                return Some(End::MissionOver(format!(
                    "the mission reached its final marking [{}]",
                    f.join(", ")
                )));
            }
        }
        None
    }

    /// Whether every process ended, none to be started or restarted.
    pub fn all_ended(&self) -> bool {
        self.procs
            .iter()
            .all(|p| !p.alive && !matches!(p.state, State::Restarting(_) | State::Waiting))
    }

    /// `--timeout`, if it passed.
    pub fn timed_out(&self, now: Instant) -> Option<End> {
        let t = self.rules.timeout?;
        (now.saturating_duration_since(self.t0) >= t).then_some(End::Timeout(t))
    }

    /// The stop begins: what waits will never start, and what waits for its restart fails.
    pub fn begin_stop(&mut self) {
        for p in &mut self.procs {
            match p.state {
                State::Waiting => p.state = State::NotStarted,
                // The failure it would have been restarted for stands.
                State::Restarting(_) if p.failure.is_none() => {
                    p.failure = Some("ended while waiting for its restart".into());
                }
                _ => {}
            }
        }
    }

    /// The processes in stop order: layers, the last started first. A process's layer is one
    /// more than the deepest of what it comes after; nothing in a layer waits for another of
    /// the same layer.
    pub fn stop_layers(&self) -> Vec<Vec<usize>> {
        let mut layer = vec![0usize; self.procs.len()];
        for i in 0..self.procs.len() {
            layer[i] = self.procs[i]
                .plan
                .after
                .iter()
                .map(|&j| layer[j] + 1)
                .max()
                .unwrap_or(0);
        }
        let top = layer.iter().copied().max().unwrap_or(0);
        (0..=top)
            .rev()
            .map(|l| (0..self.procs.len()).filter(|&i| layer[i] == l).collect())
            .collect()
    }

    /// SIGTERM to the processes of `members` still running and not yet asked.
    pub fn stop(&mut self, members: &[usize], now: Instant) -> Vec<Action> {
        let mut out = Vec::new();
        for &i in members {
            let p = &mut self.procs[i];
            if p.alive && p.stop_sent.is_none() {
                out.push(Action::Signal(i, Kill::Term));
                p.stop_sent = Some(now);
                p.state = State::Stopping;
            }
        }
        out
    }

    /// A second stop request: SIGKILL to every process still running.
    pub fn hurry(&mut self, now: Instant) -> Vec<Action> {
        let mut out = Vec::new();
        for (i, p) in self.procs.iter_mut().enumerate() {
            if p.alive && !p.kill_sent {
                out.push(Action::Signal(i, Kill::Kill));
                p.kill_sent = true;
                p.killed_because = "a second stop request".into();
                p.stop_sent.get_or_insert(now);
            }
        }
        out
    }

    /// SIGKILL to the processes (of `among`, or all) still running past their grace period
    /// after SIGTERM.
    pub fn escalate(&mut self, now: Instant, among: Option<&[usize]>) -> Vec<Action> {
        let mut out = Vec::new();
        for (i, p) in self.procs.iter_mut().enumerate() {
            let grace = p.plan.spec.stop_grace;
            let overdue = p
                .stop_sent
                .is_some_and(|t| now.saturating_duration_since(t) >= grace);
            if overdue && p.alive && !p.kill_sent && among.is_none_or(|m| m.contains(&i)) {
                out.push(Action::Signal(i, Kill::Kill));
                p.kill_sent = true;
                p.killed_because =
                    format!("still running {:.1} s after SIGTERM", grace.as_secs_f64());
            }
        }
        out
    }

    /// How the run ended, in words, and whether it succeeded (no process failed, and the end
    /// is not a timeout or a failure).
    pub fn verdict(&self, end: &End) -> (String, bool) {
        let (reason, ok) = match end {
            End::Signal(s) => (format!("stopped by {}", s.as_str()), true),
            End::Until(u) => (format!("reached --until: {u}"), true),
            End::MissionOver(why) => (why.clone(), true),
            End::AllExited => ("every process ended".to_string(), true),
            End::PlayerExited => ("the player exited".to_string(), true),
            End::Timeout(t) => (
                format!("timed out after {:.1} s (--timeout)", t.as_secs_f64()),
                false,
            ),
            End::ProcessFailed(why) | End::Failure(why) => (why.clone(), false),
        };
        (reason, ok && self.procs.iter().all(|p| p.failure.is_none()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::up::file::{Journal, ProcessSpec};
    use std::path::PathBuf;

    const S: Duration = Duration::from_secs(1);

    fn planned(name: &str, kind: Kind, after: &[usize], restart: Restart) -> Planned {
        Planned {
            spec: ProcessSpec {
                name: name.into(),
                kind,
                executable: None,
                args: vec![],
                env: vec![],
                computer: None,
                wait: None,
                programs: if kind == Kind::Program {
                    vec![name.to_string()]
                } else {
                    vec![]
                },
                after: vec![],
                restart,
                ready_timeout: 5 * S,
                stop_grace: 2 * S,
                journal: Journal::Default,
                critical: kind == Kind::Player,
            },
            program: PathBuf::from(name),
            args: vec![],
            env: vec![],
            after: after.to_vec(),
            log: PathBuf::from(format!("{name}.log")),
            journal: None,
        }
    }

    fn policy(procs: &[Planned], t0: Instant) -> Policy {
        Policy::new(procs, Rules::default(), t0)
    }

    fn finish(actions: &[Action]) -> Option<&End> {
        actions.iter().find_map(|a| match a {
            Action::Finish(e) => Some(e),
            _ => None,
        })
    }

    /// Starts what is due at `now` (pids 100 + index).
    fn start(p: &mut Policy, now: Instant) -> Vec<usize> {
        let due = p.due(now);
        for &i in &due {
            p.spawned(i, 100 + i as u32, now);
        }
        due
    }

    /// Brings every process of `p` up: each started and seen ready (programs receiving).
    fn bring_up(p: &mut Policy, t0: Instant) -> Instant {
        let mut now = t0;
        let mut seen = Seen::default();
        for q in &p.procs {
            seen.live_programs
                .extend(q.plan.spec.programs.iter().cloned());
        }
        while !p.vehicle_up(now) {
            start(p, now);
            now += Duration::from_millis(50);
            seen.player_beat = Some(now);
            seen.bridge_beat = Some(now);
            assert_eq!(finish(&p.readiness(now, &seen)), None);
        }
        now
    }

    #[test]
    fn backoff_doubles_and_caps_at_max_backoff() {
        let t0 = Instant::now();
        let restart = Restart::OnFailure {
            max: 10,
            backoff: S,
        };
        let mut p = policy(&[planned("sonar", Kind::Command, &[], restart)], t0);
        let mut now = bring_up(&mut p, t0);
        let mut delays = Vec::new();
        for _ in 0..7 {
            let out = p.exited(0, Some(1), None, now, false);
            assert_eq!(finish(&out), None, "a restart does not end the run");
            let State::Restarting(at) = p.procs[0].state else {
                panic!("not restarting: {:?}", p.procs[0].state)
            };
            delays.push((at - now).as_secs());
            assert!(p.due(at - Duration::from_millis(1)).is_empty());
            now = at;
            assert_eq!(start(&mut p, now), vec![0]);
        }
        assert_eq!(delays, vec![1, 2, 4, 8, 16, 30, 30]);
        assert_eq!(p.procs[0].restarts, 7);
    }

    #[test]
    fn restarts_exhausted_fail_for_good() {
        let t0 = Instant::now();
        let restart = Restart::OnFailure { max: 2, backoff: S };
        let mut p = policy(&[planned("sonar", Kind::Command, &[], restart)], t0);
        let mut now = bring_up(&mut p, t0);
        for _ in 0..2 {
            p.exited(0, Some(3), None, now, false);
            now += MAX_BACKOFF;
            assert_eq!(start(&mut p, now), vec![0]);
        }
        let out = p.exited(0, Some(3), None, now, false);
        assert_eq!(
            p.procs[0].failure.as_deref(),
            Some("exited with code 3, after 2 restarts: none left")
        );
        // Not critical, after up: the vehicle goes on without it.
        assert_eq!(finish(&out), None);
        assert!(p.due(now + MAX_BACKOFF).is_empty());
        assert!(p.all_ended());
        assert!(
            !p.verdict(&End::AllExited).1,
            "a failure makes the run fail"
        );
    }

    #[test]
    fn critical_failure_ends_the_run_a_non_critical_one_after_up_does_not() {
        let t0 = Instant::now();
        let procs = [
            planned("player", Kind::Player, &[], Restart::Never),
            planned("camera", Kind::Command, &[0], Restart::Never),
        ];
        let mut p = policy(&procs, t0);
        let now = bring_up(&mut p, t0);
        let out = p.exited(1, None, Some(Signal::SIGSEGV as i32), now, false);
        assert_eq!(finish(&out), None);
        assert_eq!(
            p.procs[1].failure.as_deref(),
            Some("died of SIGSEGV (restart = \"never\")")
        );
        let out = p.exited(0, Some(2), None, now, false);
        assert_eq!(
            finish(&out),
            Some(&End::ProcessFailed(
                "the player failed: exited with code 2 (restart = \"never\")".into()
            ))
        );
    }

    #[test]
    fn any_failure_before_up_ends_the_run_and_none_while_stopping() {
        let t0 = Instant::now();
        let procs = [
            planned("setup", Kind::Command, &[], Restart::Never),
            planned("late", Kind::Program, &[0], Restart::Never),
        ];
        let mut p = policy(&procs, t0);
        start(&mut p, t0);
        let out = p.exited(0, Some(1), None, t0, false);
        assert_eq!(
            finish(&out),
            Some(&End::ProcessFailed(
                "process `setup` failed: exited with code 1 (restart = \"never\")".into()
            ))
        );
        // While stopping, a failure is recorded, and ends nothing more.
        let mut p = policy(&procs, t0);
        start(&mut p, t0);
        assert_eq!(finish(&p.exited(0, Some(1), None, t0, true)), None);
        assert!(p.procs[0].failure.is_some());
    }

    #[test]
    fn fail_fast_makes_any_failure_after_up_end_the_run() {
        let t0 = Instant::now();
        let procs = [planned("camera", Kind::Command, &[], Restart::Never)];
        let mut p = Policy::new(
            &procs,
            Rules {
                fail_fast: true,
                ..Rules::default()
            },
            t0,
        );
        let now = bring_up(&mut p, t0);
        let out = p.exited(0, Some(1), None, now, false);
        assert!(matches!(finish(&out), Some(End::ProcessFailed(_))));
    }

    #[test]
    fn ready_timeout_sends_sigterm_and_fails() {
        let t0 = Instant::now();
        let procs = [planned("nav", Kind::Program, &[], Restart::Never)];
        let mut p = policy(&procs, t0);
        start(&mut p, t0);
        assert!(p.awaits_programs());
        let seen = Seen::default();
        // Its node may live: not ready while its calls receiver is not connected.
        assert!(p.readiness(t0 + 5 * S, &seen).is_empty());
        let out = p.readiness(t0 + 5 * S + Duration::from_millis(50), &seen);
        assert!(out.contains(&Action::Signal(0, Kill::Term)), "{out:?}");
        assert_eq!(
            finish(&out),
            Some(&End::ProcessFailed(
                "process `nav` not ready within 5.0 s".into()
            ))
        );
        assert_eq!(p.procs[0].state, State::Stopping);
        // Ending by our SIGTERM keeps the failure it was stopped for.
        let now = t0 + 6 * S;
        p.exited(0, None, Some(Signal::SIGTERM as i32), now, false);
        assert_eq!(
            p.procs[0].failure.as_deref(),
            Some("not ready within 5.0 s")
        );
    }

    #[test]
    fn a_program_is_ready_when_each_of_its_programs_receives_its_calls() {
        let t0 = Instant::now();
        let mut nav = planned("nav", Kind::Program, &[], Restart::Never);
        nav.spec.programs = vec!["nav".into(), "gps".into()];
        let mut p = policy(&[nav], t0);
        start(&mut p, t0);
        let mut seen = Seen::default();
        seen.live_programs.insert("nav".into());
        assert!(p.readiness(t0 + S, &seen).is_empty());
        seen.live_programs.insert("gps".into());
        let out = p.readiness(t0 + S, &seen);
        assert_eq!(out, vec![Action::Say("`nav` ready in 1.00 s".into())]);
        assert!(p.vehicle_up(t0 + S));
        assert_eq!(p.procs[0].state, State::Running);
    }

    #[test]
    fn a_heartbeat_from_before_the_start_is_not_readiness() {
        let t0 = Instant::now();
        let mut p = policy(&[planned("player", Kind::Player, &[], Restart::Never)], t0);
        let now = t0 + S;
        start(&mut p, now);
        let seen = Seen {
            player_beat: Some(t0),
            ..Seen::default()
        };
        assert!(p.readiness(now, &seen).is_empty());
        assert_eq!(p.procs[0].state, State::Starting);
    }

    #[test]
    fn a_one_shot_exit_0_satisfies_after() {
        let t0 = Instant::now();
        let procs = [
            planned("setup", Kind::Program, &[], Restart::Never),
            planned("nav", Kind::Command, &[0], Restart::Never),
        ];
        let mut p = policy(&procs, t0);
        assert_eq!(start(&mut p, t0), vec![0]);
        assert!(p.due(t0 + S).is_empty(), "nav waits for setup");
        let out = p.exited(0, Some(0), None, t0 + S, false);
        assert_eq!(out, vec![Action::Say("`setup` exited(0)".into())]);
        assert_eq!(start(&mut p, t0 + S), vec![1]);
        p.readiness(t0 + S, &Seen::default());
        assert!(p.vehicle_up(t0 + S));
        // A one-shot that failed satisfies nothing.
        let mut p = policy(&procs, t0);
        start(&mut p, t0);
        p.exited(0, Some(1), None, t0, false);
        assert!(p.due(t0 + S).is_empty());
    }

    #[test]
    fn a_player_exiting_0_ends_the_run() {
        let t0 = Instant::now();
        let mut p = policy(&[planned("player", Kind::Player, &[], Restart::Never)], t0);
        let now = bring_up(&mut p, t0);
        let out = p.exited(0, Some(0), None, now, false);
        assert_eq!(finish(&out), Some(&End::PlayerExited));
        assert_eq!(
            p.verdict(&End::PlayerExited),
            ("the player exited".into(), true)
        );
    }

    #[test]
    fn stop_order_is_reverse_layers() {
        let t0 = Instant::now();
        let procs = [
            planned("bridge", Kind::Command, &[], Restart::Never),
            planned("player", Kind::Command, &[0], Restart::Never),
            planned("gui", Kind::Command, &[1], Restart::Never),
            planned("nav", Kind::Command, &[0], Restart::Never),
        ];
        let mut p = policy(&procs, t0);
        assert_eq!(p.stop_layers(), vec![vec![2], vec![1, 3], vec![0]]);
        let now = bring_up(&mut p, t0);
        p.begin_stop();
        assert_eq!(p.stop(&[2], now), vec![Action::Signal(2, Kill::Term)]);
        assert_eq!(p.stop(&[2], now), vec![], "SIGTERM goes once");
        // Past its grace period, SIGKILL; its end is then a failure.
        assert!(p.escalate(now + S, Some(&[2])).is_empty());
        assert_eq!(
            p.escalate(now + 2 * S, Some(&[2])),
            vec![Action::Signal(2, Kill::Kill)]
        );
        p.exited(2, None, Some(Signal::SIGKILL as i32), now + 2 * S, true);
        assert_eq!(
            p.procs[2].failure.as_deref(),
            Some("killed with SIGKILL: still running 2.0 s after SIGTERM")
        );
        // A clean end by SIGTERM is no failure.
        p.stop(&[1, 3], now);
        p.exited(1, None, Some(Signal::SIGTERM as i32), now + S, true);
        assert_eq!(p.procs[1].failure, None);
        assert_eq!(p.procs[1].state.word(), "killed(SIGTERM)");
    }

    #[test]
    fn a_second_stop_request_kills_all() {
        let t0 = Instant::now();
        let procs = [
            planned("bridge", Kind::Command, &[], Restart::Never),
            planned("player", Kind::Command, &[0], Restart::Never),
            planned("gui", Kind::Command, &[1], Restart::Never),
        ];
        let mut p = policy(&procs, t0);
        let now = bring_up(&mut p, t0);
        p.begin_stop();
        p.stop(&[2], now);
        let kills = p.hurry(now);
        assert_eq!(
            kills,
            (0..3)
                .map(|i| Action::Signal(i, Kill::Kill))
                .collect::<Vec<_>>()
        );
        assert!(p.hurry(now).is_empty(), "SIGKILL goes once");
        p.exited(0, None, Some(Signal::SIGKILL as i32), now, true);
        assert_eq!(
            p.procs[0].failure.as_deref(),
            Some("killed with SIGKILL: a second stop request")
        );
    }

    #[test]
    fn until_place_and_event_end_the_run() {
        let t0 = Instant::now();
        let rules = Rules {
            until: vec![
                Until::Place("mission.done".into()),
                Until::Event("abort".into()),
            ],
            ..Rules::default()
        };
        let p = Policy::new(&[], rules, t0);
        let mut seen = Observed::default();
        assert_eq!(p.goal(&seen), None);
        seen.events_seen.insert("abort".into());
        assert_eq!(
            p.goal(&seen),
            Some(End::Until("event `abort` taken by the player".into()))
        );
        // From the deltas, or from the heartbeat when deltas were lost.
        let mut seen = Observed::default();
        seen.marked.insert("mission.done".into());
        assert_eq!(
            p.goal(&seen),
            Some(End::Until("place `mission.done` marked".into()))
        );
        let mut status = PlayerStatus::default();
        status.marked.insert("mission.done".into());
        let seen = Observed {
            player: Some(status),
            ..Observed::default()
        };
        assert!(matches!(p.goal(&seen), Some(End::Until(_))));
    }

    #[test]
    fn a_final_marking_or_a_catastrophe_ends_the_mission_unless_kept_running() {
        let t0 = Instant::now();
        let finals = vec![vec!["main.home".to_string(), "nav.idle".to_string()]];
        let p = Policy::new(
            &[],
            Rules {
                finals: finals.clone(),
                ..Rules::default()
            },
            t0,
        );
        let mut status = PlayerStatus::default();
        status.marked.insert("main.home".into());
        let mut seen = Observed {
            player: Some(status),
            ..Observed::default()
        };
        assert_eq!(p.goal(&seen), None, "half the final marking");
        let status = seen.player.as_mut().unwrap();
        status.marked.insert("nav.idle".into());
        assert_eq!(
            p.goal(&seen),
            Some(End::MissionOver(
                "the mission reached its final marking [main.home, nav.idle]".into()
            ))
        );
        seen.player.as_mut().unwrap().marked.clear();
        seen.player.as_mut().unwrap().over = true;
        assert!(matches!(p.goal(&seen), Some(End::MissionOver(_))));
        let kept = Policy::new(
            &[],
            Rules {
                finals,
                keep_running: true,
                ..Rules::default()
            },
            t0,
        );
        assert_eq!(kept.goal(&seen), None);
    }

    #[test]
    fn timeout_fails_the_run() {
        let t0 = Instant::now();
        let p = Policy::new(
            &[],
            Rules {
                timeout: Some(3 * S),
                ..Rules::default()
            },
            t0,
        );
        assert_eq!(p.timed_out(t0 + 2 * S), None);
        let end = p.timed_out(t0 + 3 * S).unwrap();
        assert_eq!(end, End::Timeout(3 * S));
        assert_eq!(
            p.verdict(&end),
            ("timed out after 3.0 s (--timeout)".into(), false)
        );
    }

    #[test]
    fn timed_sends_wait_for_up_and_their_acknowledgement() {
        let t0 = Instant::now();
        let send = |at: u64, text: &str| SendSpec {
            at: Duration::from_secs(at),
            text: text.into(),
            name: text.into(),
            params: vec![],
            computer: None,
        };
        let procs = [planned("player", Kind::Player, &[], Restart::Never)];
        let rules = Rules {
            sends: vec![send(0, "go"), send(5, "abort")],
            ..Rules::default()
        };
        let mut p = Policy::new(&procs, rules, t0);
        assert!(
            p.sends_due(t0).is_empty(),
            "nothing before the vehicle is up"
        );
        let up = bring_up(&mut p, t0);
        assert_eq!(p.sends_due(up), vec![Action::Send(0)]);
        p.sent(0, 7, up);
        assert_eq!(p.sends_due(up + S), vec![]);
        assert_eq!(p.acknowledged(7), vec!["go".to_string()]);
        assert_eq!(p.sends_due(up + 5 * S), vec![Action::Send(1)]);
        p.sent(1, 8, up + 5 * S);
        let out = p.sends_due(up + 15 * S);
        assert_eq!(
            finish(&out),
            Some(&End::Failure(
                "the player did not acknowledge `abort` within 10 s".into()
            ))
        );
    }
}
