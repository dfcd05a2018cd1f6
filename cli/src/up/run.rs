//! The supervisor of `petrel up`: starts the planned processes in dependency order, waiting
//! for each to be ready; watches them (restarts by policy), the player's heartbeat and marking
//! deltas (the status lines, `--until`, the mission's end); makes the timed sends; and stops
//! everything in reverse dependency order (SIGTERM, then SIGKILL after the grace period).
//!
//! One thread does it all, in rounds of at most 50 ms that a signal (a stop request, a child's
//! end) cuts short: the iceoryx2 ports are single-threaded, and a round is short beside the
//! player's 100 ms heartbeat.

use super::display::{Display, Line};
use super::file::{Kind, Restart};
use super::notify::{Notifier, VARIABLES};
use super::signals::Signals;
use super::{Plan, Planned, Until};
use crate::common::Outcome;
use nix::sys::signal::{killpg, Signal};
use nix::unistd::Pid;
use std::collections::BTreeSet;
use std::io::Write;
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The longest round of the loop.
const ROUND: Duration = Duration::from_millis(50);
/// How long the player has to acknowledge a timed send (as `petrel send` waits).
const ACK_GRACE: Duration = Duration::from_secs(10);
/// The longest delay between two restarts, however many failures came before.
const MAX_BACKOFF: Duration = Duration::from_secs(30);

/// Where a process is in its life.
#[derive(Clone, Debug, PartialEq, Eq)]
enum State {
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
    fn word(&self) -> String {
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

    fn is_up(&self) -> bool {
        matches!(self, State::Ready | State::Running)
    }
}

fn signal_name(s: i32) -> String {
    Signal::try_from(s)
        .map(|s| s.as_str().to_string())
        .unwrap_or_else(|_| format!("signal {s}"))
}

/// One supervised process.
struct Proc {
    plan: Planned,
    state: State,
    child: Option<Child>,
    pid: Option<u32>,
    restarts: u32,
    spawned_at: Option<Instant>,
    /// We asked it to stop: its death by SIGTERM is expected.
    stop_sent: Option<Instant>,
    /// SIGKILL sent (after the grace period, or at a second stop request).
    kill_sent: bool,
    /// Why SIGKILL was sent.
    killed_because: String,
    /// Why it failed for good.
    failure: Option<String>,
}

impl Proc {
    fn alive(&self) -> bool {
        self.child.is_some()
    }

    /// Done for dependency purposes: ready, or ended cleanly on its own (a one-shot setup).
    fn satisfies(&self) -> bool {
        self.state.is_up() || (self.state == State::Exited(0) && self.failure.is_none())
    }
}

/// The player's latest heartbeat status.
#[derive(Default)]
struct PlayerStatus {
    time: f64,
    processed: u64,
    marked: BTreeSet<String>,
    over: bool,
    doc: serde_json::Value,
}

/// Why the run ended.
enum End {
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

struct Supervisor {
    plan: Plan,
    procs: Vec<Proc>,
    display: Display,
    t0: Instant,
    /// When every process became ready.
    up_at: Option<Instant>,
    player: Option<PlayerStatus>,
    player_beat: Option<Instant>,
    bridge_beat: Option<Instant>,
    /// The marking rebuilt from the deltas (for `--until NET.place`).
    marked: BTreeSet<String>,
    /// Events the player took (for `--until EVENT`).
    events_seen: BTreeSet<String>,
    next_send: usize,
    acks: Vec<PendingAck>,
    origin: String,
    /// The running petrel, which starts each process (`petrel __exec`).
    petrel: std::path::PathBuf,
    /// The programs of this computer's processes: ready when they receive their calls (taken
    /// away at the end: it keeps our node).
    watch: Option<petrel_ipc::ProgramWatch>,
    /// systemd's notifications (readiness, watchdog), when it runs us.
    notify: Notifier,
}

/// Runs the plan; prints the summary; the outcome gives the exit code.
pub fn run(plan: Plan, t0: Instant) -> Outcome {
    // The signals first: from here on, Ctrl-C cannot leave children behind.
    let signals = match Signals::new() {
        Ok(s) => s,
        Err(e) => return Outcome::Usage(format!("cannot watch signals: {e}")),
    };
    let role = match petrel_ipc::Role::tool(&format!("up{}", std::process::id())) {
        Ok(r) => r,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let me = match petrel_ipc::Participant::join(&plan.vehicle, role) {
        Ok(m) => m,
        Err(e) => {
            return Outcome::Usage(format!(
                "cannot join vehicle `{}`: {e}",
                plan.vehicle.name()
            ))
        }
    };
    // Subscribed before the player starts, so the first marking (a snapshot) is seen.
    let ports = me
        .heartbeat_subscriber()
        .and_then(|b| Ok((b, me.marking_subscriber()?, me.event_sender()?)));
    let (beats, deltas, events) = match ports {
        Ok(p) => p,
        Err(e) => return Outcome::Usage(e.to_string()),
    };
    let origin = events.origin().to_string();
    let programs = plan
        .processes
        .iter()
        .filter(|p| p.spec.kind == Kind::Program)
        .flat_map(|p| p.spec.programs.clone());
    let watch = match petrel_ipc::ProgramWatch::new(&me, programs) {
        Ok(w) => w,
        Err(e) => return Outcome::Usage(format!("cannot watch the programs: {e}")),
    };
    let petrel = match std::env::current_exe() {
        Ok(p) => p,
        Err(e) => return Outcome::Usage(format!("cannot find the running petrel: {e}")),
    };
    let mut display = Display::new(t0);
    let on = match &plan.computer {
        Some(k) => format!(
            " on computer `{}`{}{}",
            k.name,
            k.address
                .as_ref()
                .map(|a| format!(" ({a})"))
                .unwrap_or_default(),
            k.description
                .as_ref()
                .map(|d| format!(", {d}"))
                .unwrap_or_default()
        ),
        None => String::new(),
    };
    display.message(&format!(
        "petrel up: vehicle `{}` (project `{}`), {}{on}; run directory {}",
        plan.vehicle.name(),
        plan.project.name,
        petrel_nets::plural::count(plan.processes.len(), "process"),
        plan.run_dir.display()
    ));
    let mut notify = Notifier::from_env();
    notify.status(&format!(
        "starting {}",
        petrel_nets::plural::count(plan.processes.len(), "process")
    ));
    let procs = plan
        .processes
        .iter()
        .map(|p| Proc {
            plan: p.clone(),
            state: State::Waiting,
            child: None,
            pid: None,
            restarts: 0,
            spawned_at: None,
            stop_sent: None,
            kill_sent: false,
            killed_because: String::new(),
            failure: None,
        })
        .collect();
    let mut sup = Supervisor {
        plan,
        procs,
        display,
        t0,
        up_at: None,
        player: None,
        player_beat: None,
        bridge_beat: None,
        marked: BTreeSet::new(),
        events_seen: BTreeSet::new(),
        next_send: 0,
        acks: Vec::new(),
        origin,
        petrel,
        watch: Some(watch),
        notify,
    };
    let end = sup.supervise(&signals, &beats, &deltas, &events);
    sup.stop_all(&signals, &beats, &deltas);
    // Our node goes before the dead ones are cleaned, so the vehicle is left as we found it.
    drop((beats, deltas, events, sup.watch.take()));
    drop(me);
    if let Err(e) = petrel_ipc::cleanup_dead_nodes(&sup.plan.vehicle, Duration::from_millis(500)) {
        eprintln!("warning: {e}");
    }
    sup.summary(end)
}

impl Supervisor {
    fn elapsed(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// The status lines.
    fn lines(&self) -> Vec<Line> {
        let w = self
            .procs
            .iter()
            .map(|p| p.plan.spec.name.len())
            .max()
            .unwrap_or(0);
        self.procs
            .iter()
            .map(|p| {
                let pid = p.pid.map(|x| x.to_string()).unwrap_or_else(|| "-".into());
                let state = p.state.word();
                let key = format!("{state} {pid} {}", p.restarts);
                let mut text = format!(
                    "{:<w$}  {:<7}  pid {:<7}  {:<12}  restarts {}",
                    p.plan.spec.name,
                    p.plan.spec.kind.as_str(),
                    pid,
                    state,
                    p.restarts
                );
                // The player's figures, once this player answers (not a dead one's).
                if p.plan.spec.kind == Kind::Player
                    && (p.state.is_up() || p.state == State::Stopping)
                {
                    if let Some(s) = &self.player {
                        text.push_str(&format!(
                            "  mission {:.1} s, {}, {} marked{}",
                            s.time,
                            petrel_nets::plural::count(s.processed, "event"),
                            s.marked.len(),
                            if s.over { ", OVER" } else { "" }
                        ));
                    }
                }
                if let Some(f) = &p.failure {
                    text.push_str(&format!("  FAILED: {f}"));
                }
                Line { key, text }
            })
            .collect()
    }

    /// Starts process `i` (again, after a failure, when `restarts` > 0).
    fn spawn(&mut self, i: usize) -> Result<(), String> {
        let p = &self.procs[i];
        let plan = &p.plan;
        let mut args = plan.args.clone();
        // A restarted player carries on from its journal rather than starting the mission
        // again.
        if plan.spec.kind == Kind::Player && p.restarts > 0 && plan.journal.is_some() {
            args.push("--resume".into());
        }
        // Owner-only, like the run directory: a log holds whatever the process prints.
        let mut log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .mode(0o600)
            .open(&plan.log)
            .and_then(|f| {
                f.set_permissions(std::fs::Permissions::from_mode(0o600))?;
                Ok(f)
            })
            .map_err(|e| format!("cannot open {}: {e}", plan.log.display()))?;
        let _ = writeln!(
            log,
            "=== petrel up, {:.3} s: start {} of `{}`: {} {}",
            self.elapsed(),
            p.restarts + 1,
            plan.spec.name,
            plan.program.display(),
            args.join(" ")
        );
        let err = log
            .try_clone()
            .map_err(|e| format!("cannot open {}: {e}", plan.log.display()))?;
        // Through `petrel __exec`, which unblocks the signals this process keeps blocked.
        let child = Command::new(&self.petrel)
            .arg("__exec")
            .arg(&plan.program)
            .args(&args)
            .envs(plan.env.iter().map(|(k, v)| (k, v)))
            .env("PETREL_VEHICLE", self.plan.vehicle.name())
            .env("PETREL_PROJECT", &self.plan.project_dir)
            .env("PETREL_LOGS", &self.plan.run_dir)
            .env("PETREL_PROCESS", &plan.spec.name)
            .env("PETREL_RESTARTS", p.restarts.to_string())
            // systemd's notifications are ours alone (notify.rs).
            .env_remove(VARIABLES[0])
            .env_remove(VARIABLES[1])
            .env_remove(VARIABLES[2])
            .current_dir(&self.plan.run_dir)
            .stdin(Stdio::null())
            .stdout(log)
            .stderr(err)
            // Its own process group: a Ctrl-C on the terminal reaches `petrel up` alone, which
            // stops the processes in order, and a stop reaches the process's own children.
            .process_group(0)
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", plan.program.display()))?;
        let p = &mut self.procs[i];
        p.pid = Some(child.id());
        p.child = Some(child);
        p.spawned_at = Some(Instant::now());
        p.state = State::Starting;
        p.stop_sent = None;
        p.kill_sent = false;
        p.killed_because.clear();
        Ok(())
    }

    /// Sends `signal` to process `i`'s group (the process and what it started).
    fn signal(&self, i: usize, signal: Signal) {
        if let (Some(pid), true) = (self.procs[i].pid, self.procs[i].alive()) {
            // The group leader is not reaped yet (it is `alive`), so the group id is its own.
            let _ = killpg(Pid::from_raw(pid as i32), signal);
        }
    }

    /// SIGKILL to the processes (of `among`, or all) still alive past their grace period
    /// after SIGTERM.
    fn escalate(&mut self, among: Option<&[usize]>) {
        for i in 0..self.procs.len() {
            let p = &self.procs[i];
            let overdue = p
                .stop_sent
                .is_some_and(|t| t.elapsed() >= p.plan.spec.stop_grace);
            if overdue && p.alive() && !p.kill_sent && among.is_none_or(|m| m.contains(&i)) {
                let grace = p.plan.spec.stop_grace.as_secs_f64();
                self.signal(i, Signal::SIGKILL);
                self.procs[i].kill_sent = true;
                self.procs[i].killed_because = format!("still running {grace:.1} s after SIGTERM");
            }
        }
    }

    /// Reaps the processes that ended. Outside the stop, a failure follows the restart policy;
    /// returns how the run ends, if the vehicle cannot go on.
    fn reap(&mut self, stopping: bool) -> Option<End> {
        let mut fatal = None;
        for i in 0..self.procs.len() {
            let status = match self.procs[i].child.as_mut().map(Child::try_wait) {
                Some(Ok(Some(s))) => s,
                Some(Ok(None)) | None => continue,
                Some(Err(e)) => {
                    // Cannot happen for our own child; treat it as gone rather than loop.
                    self.display.message(&format!(
                        "cannot wait for `{}`: {e}",
                        self.procs[i].plan.spec.name
                    ));
                    self.procs[i].child = None;
                    continue;
                }
            };
            let p = &mut self.procs[i];
            p.child = None;
            let name = p.plan.spec.name.clone();
            let (code, signal) = (status.code(), status.signal());
            p.state = match (code, signal) {
                (Some(c), _) => State::Exited(c),
                (None, Some(s)) => State::Killed(s),
                (None, None) => State::Exited(-1),
            };
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
                let took = asked.elapsed().as_secs_f64();
                if p.failure.is_none() {
                    p.failure = failure;
                }
                let how = p.state.word();
                self.display
                    .message(&format!("`{name}` stopped: {how} after {took:.2} s"));
                continue;
            }
            let why = match (code, signal) {
                (Some(0), _) => None,
                (Some(c), _) => Some(format!("exited with code {c}")),
                (None, Some(s)) => Some(format!("died of {}", signal_name(s))),
                (None, None) => Some("ended in an unknown way".into()),
            };
            let kind = p.plan.spec.kind;
            let Some(why) = why else {
                self.display.message(&format!("`{name}` exited(0)"));
                if kind == Kind::Player && !stopping {
                    fatal = fatal.or(Some(End::PlayerExited));
                }
                continue;
            };
            let restart = match p.plan.spec.restart {
                Restart::OnFailure { max, backoff } if p.restarts < max && !stopping => {
                    let delay = backoff
                        .saturating_mul(1u32 << p.restarts.min(16))
                        .min(MAX_BACKOFF);
                    Some((delay, max))
                }
                _ => None,
            };
            if let Some((delay, max)) = restart {
                p.state = State::Restarting(Instant::now() + delay);
                let n = p.restarts + 1;
                self.display.message(&format!(
                    "`{name}` {why}: restart {n} of {max} in {:.2} s",
                    delay.as_secs_f64()
                ));
                continue;
            }
            let failure = match p.plan.spec.restart {
                Restart::Never => format!("{why} (restart = \"never\")"),
                Restart::OnFailure { max, .. } if p.restarts >= max => {
                    let restarts = petrel_nets::plural::count(max, "restart");
                    format!("{why}, after {restarts}: none left")
                }
                Restart::OnFailure { .. } => why.clone(),
            };
            p.failure = Some(failure.clone());
            let critical = p.plan.spec.critical || self.plan.fail_fast || self.up_at.is_none();
            self.display.message(&format!("`{name}` failed: {failure}"));
            if critical && !stopping {
                let what = if kind == Kind::Player {
                    "the player".to_string()
                } else {
                    format!("process `{name}`")
                };
                fatal = fatal.or(Some(End::ProcessFailed(format!(
                    "{what} failed: {failure}"
                ))));
            }
        }
        fatal
    }

    /// Reads the heartbeats (the player's status, the data server's sign of life) and the
    /// acknowledgements of the timed sends.
    fn read_heartbeats(&mut self, beats: &petrel_ipc::HeartbeatSubscriber) {
        let mut player = None;
        let mut bridge = false;
        let _ = beats.drain(|r| {
            if let Ok(rcv) = r {
                match rcv.origin.as_str() {
                    "player" => player = Some(rcv.msg.status),
                    "can_bridge" => bridge = true,
                    _ => {}
                }
            }
        });
        if bridge {
            self.bridge_beat = Some(Instant::now());
        }
        let Some(text) = player else { return };
        self.player_beat = Some(Instant::now());
        let doc: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        let mut marked = BTreeSet::new();
        if let Some(m) = doc["marking"].as_object() {
            for (net, places) in m {
                for p in places.as_array().into_iter().flatten() {
                    if let Some(p) = p.as_str() {
                        marked.insert(format!("{net}.{p}"));
                    }
                }
            }
        }
        let last_seq = doc["senders"][&self.origin]["last_seq"]
            .as_u64()
            .unwrap_or(0);
        let acked: Vec<String> = self
            .acks
            .iter()
            .filter(|a| a.seq <= last_seq)
            .map(|a| a.text.clone())
            .collect();
        self.acks.retain(|a| a.seq > last_seq);
        for t in acked {
            self.display
                .message(&format!("sent `{t}`: acknowledged by the player"));
        }
        self.player = Some(PlayerStatus {
            time: doc["time"].as_f64().unwrap_or(0.0),
            processed: doc["stats"]["processed"].as_u64().unwrap_or(0),
            marked,
            over: doc["over"].as_bool() == Some(true),
            doc,
        });
    }

    /// Reads the marking deltas: the events the player took and the places marked.
    fn read_deltas(&mut self, deltas: &petrel_ipc::MarkingSubscriber) {
        let marked = &mut self.marked;
        let seen = &mut self.events_seen;
        let mut lost = false;
        let _ = deltas.drain(|r| match r {
            Ok(rcv) => {
                lost |= rcv.missed > 0;
                let m = rcv.msg;
                if m.snapshot {
                    marked.clear();
                }
                for p in &m.unmarked {
                    marked.remove(p);
                }
                marked.extend(m.marked.iter().cloned());
                if let Some(e) = m.event {
                    seen.insert(e);
                }
            }
            Err(_) => lost = true,
        });
        if lost {
            // Deltas were missed: the heartbeat's marking is the truth until the next snapshot.
            if let Some(s) = &self.player {
                self.marked = s.marked.clone();
            }
        }
    }

    /// Whether an `--until` condition or the mission's end is reached.
    fn goal(&self) -> Option<End> {
        for u in &self.plan.until {
            let reached = match u {
                Until::Event(e) => self.events_seen.contains(e),
                Until::Place(p) => {
                    self.marked.contains(p)
                        || self.player.as_ref().is_some_and(|s| s.marked.contains(p))
                }
            };
            if reached {
                return Some(End::Until(u.to_string()));
            }
        }
        if self.plan.keep_running {
            return None;
        }
        let s = self.player.as_ref()?;
        if s.over {
            return Some(End::MissionOver(
                "the mission is over (a catastrophic event)".into(),
            ));
        }
        for f in &self.plan.finals {
            if !f.is_empty() && f.iter().all(|p| s.marked.contains(p)) {
                return Some(End::MissionOver(format!(
                    "the mission reached its final marking [{}]",
                    f.join(", ")
                )));
            }
        }
        None
    }

    /// Whether process `i`'s readiness is seen (a program's at the watch's last check).
    fn is_ready(&self, i: usize) -> bool {
        let p = &self.procs[i];
        let Some(since) = p.spawned_at else {
            return false;
        };
        match p.plan.spec.kind {
            Kind::Player => self.player_beat.is_some_and(|t| t > since),
            Kind::Bridge => self.bridge_beat.is_some_and(|t| t > since),
            Kind::Command => true,
            // Each of its programs receives its calls (its node alone is not enough: a call
            // sent before its calls receiver connects finds nobody).
            Kind::Program => p.plan.spec.programs.iter().all(|x| {
                let status = self.watch.as_ref().and_then(|w| w.status(x));
                status == Some(petrel_ipc::ProgramStatus::Alive)
            }),
        }
    }

    /// Starts what may start, and sees who became ready. Returns why the vehicle cannot come
    /// up, if it cannot.
    fn start_and_check_ready(&mut self) -> Option<String> {
        let now = Instant::now();
        let mut fatal = None;
        for i in 0..self.procs.len() {
            let due = match self.procs[i].state {
                State::Waiting => self.procs[i]
                    .plan
                    .after
                    .iter()
                    .all(|&j| self.procs[j].satisfies()),
                State::Restarting(at) => now >= at,
                _ => false,
            };
            if !due {
                continue;
            }
            if matches!(self.procs[i].state, State::Restarting(_)) {
                self.procs[i].restarts += 1;
                // What the failed process left in shared memory goes before its successor
                // joins (its calls service takes one receiver).
                let _ =
                    petrel_ipc::cleanup_dead_nodes(&self.plan.vehicle, Duration::from_millis(200));
            }
            if let Err(e) = self.spawn(i) {
                let name = self.procs[i].plan.spec.name.clone();
                self.procs[i].state = State::NotStarted;
                self.procs[i].failure = Some(e.clone());
                self.display.message(&format!("`{name}`: {e}"));
                fatal = fatal.or(Some(format!("process `{name}` could not start: {e}")));
            }
        }
        let starting: Vec<usize> = (0..self.procs.len())
            .filter(|&i| self.procs[i].state == State::Starting)
            .collect();
        if starting.is_empty() {
            return fatal;
        }
        if starting
            .iter()
            .any(|&i| self.procs[i].plan.spec.kind == Kind::Program)
        {
            // Not ready this round if the nodes cannot be listed.
            if let Some(Err(e)) = self.watch.as_mut().map(|w| w.check()) {
                self.display
                    .message(&format!("cannot see the programs: {e}"));
            }
        }
        for i in starting {
            let name = self.procs[i].plan.spec.name.clone();
            let since = self.procs[i].spawned_at.unwrap_or(now);
            if self.is_ready(i) {
                self.procs[i].state = if self.up_at.is_some() {
                    State::Running
                } else {
                    State::Ready
                };
                self.display.message(&format!(
                    "`{name}` ready in {:.2} s",
                    since.elapsed().as_secs_f64()
                ));
            } else if since.elapsed() > self.procs[i].plan.spec.ready_timeout {
                let t = self.procs[i].plan.spec.ready_timeout.as_secs_f64();
                let failure = format!("not ready within {t:.1} s");
                self.display.message(&format!(
                    "`{name}` {failure}: stopping it (its log: {})",
                    self.procs[i].plan.log.display()
                ));
                self.procs[i].failure = Some(failure.clone());
                self.signal(i, Signal::SIGTERM);
                self.procs[i].stop_sent = Some(Instant::now());
                self.procs[i].state = State::Stopping;
                if self.up_at.is_none() || self.procs[i].plan.spec.critical || self.plan.fail_fast {
                    fatal = fatal.or(Some(format!("process `{name}` {failure}")));
                }
            }
        }
        fatal
    }

    /// Makes the timed sends that are due. Returns why the scenario cannot go on, if it
    /// cannot.
    fn send_due(&mut self, events: &petrel_ipc::EventSender) -> Option<String> {
        let up = self.up_at?;
        while let Some(s) = self.plan.sends.get(self.next_send) {
            if up.elapsed() < s.at {
                break;
            }
            self.next_send += 1;
            let msg = petrel_ipc::EventMsg::new(s.name.clone(), s.params.clone());
            match events.send(&msg) {
                Ok(sent) => self.acks.push(PendingAck {
                    text: s.text.clone(),
                    seq: sent.seq,
                    deadline: Instant::now() + ACK_GRACE,
                }),
                Err(petrel_ipc::SendError::NoReceiver { .. }) => {
                    return Some(format!(
                        "no player received `{}` (is the player of vehicle `{}` running?)",
                        s.text,
                        self.plan.vehicle.name()
                    ))
                }
                Err(e) => return Some(format!("cannot send `{}`: {e}", s.text)),
            }
        }
        let late = self.acks.iter().find(|a| Instant::now() >= a.deadline)?;
        Some(format!(
            "the player did not acknowledge `{}` within {} s",
            late.text,
            ACK_GRACE.as_secs()
        ))
    }

    /// The main loop, until the run ends.
    fn supervise(
        &mut self,
        signals: &Signals,
        beats: &petrel_ipc::HeartbeatSubscriber,
        deltas: &petrel_ipc::MarkingSubscriber,
        events: &petrel_ipc::EventSender,
    ) -> End {
        loop {
            self.display.update(&self.lines());
            // The watchdog watches this loop: fed every round it turns.
            self.notify.watchdog(Instant::now());
            if let Some(s) = signals.wait(ROUND) {
                return End::Signal(s);
            }
            if let Some(end) = self.reap(false) {
                return end;
            }
            self.read_deltas(deltas);
            self.read_heartbeats(beats);
            // A process stopped for not being ready in time gets its grace period too.
            self.escalate(None);
            if let Some(why) = self.start_and_check_ready() {
                return End::ProcessFailed(why);
            }
            if self.up_at.is_none() && self.procs.iter().all(Proc::satisfies) {
                self.up_at = Some(Instant::now());
                for p in &mut self.procs {
                    if p.state == State::Ready {
                        p.state = State::Running;
                    }
                }
                self.display
                    .message(&format!("vehicle up in {:.2} s", self.elapsed()));
                let status = format!(
                    "vehicle `{}` up: {} running",
                    self.plan.vehicle.name(),
                    petrel_nets::plural::count(self.procs.len(), "process")
                );
                self.notify.ready(&status);
            }
            if self.up_at.is_some() {
                if let Some(why) = self.send_due(events) {
                    return End::Failure(why);
                }
                if let Some(end) = self.goal() {
                    return end;
                }
            }
            let none_left = self
                .procs
                .iter()
                .all(|p| !p.alive() && !matches!(p.state, State::Restarting(_) | State::Waiting));
            if none_left {
                return End::AllExited;
            }
            if let Some(t) = self.plan.timeout {
                if self.t0.elapsed() >= t {
                    return End::Timeout(t);
                }
            }
        }
    }

    /// Stops every process, the last started first: a layer of processes that nothing else
    /// waits for gets SIGTERM, then SIGKILL past its grace period, and the next layer follows
    /// once it is gone. A second stop request kills what is left at once.
    fn stop_all(
        &mut self,
        signals: &Signals,
        beats: &petrel_ipc::HeartbeatSubscriber,
        deltas: &petrel_ipc::MarkingSubscriber,
    ) {
        self.notify.stopping("stopping the vehicle");
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
        // A process's layer: one more than the deepest of what it comes after.
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
        let mut hurry = false;
        for l in (0..=layer.iter().copied().max().unwrap_or(0)).rev() {
            let members: Vec<usize> = (0..self.procs.len()).filter(|&i| layer[i] == l).collect();
            for &i in &members {
                if self.procs[i].alive() && self.procs[i].stop_sent.is_none() {
                    self.signal(i, Signal::SIGTERM);
                    self.procs[i].stop_sent = Some(Instant::now());
                    self.procs[i].state = State::Stopping;
                }
            }
            while members.iter().any(|&i| self.procs[i].alive()) {
                self.display.update(&self.lines());
                self.notify.watchdog(Instant::now());
                if let Some(s) = signals.wait(ROUND) {
                    if !hurry {
                        self.display
                            .message(&format!("{}: killing every process now", s.as_str()));
                    }
                    hurry = true;
                }
                self.reap(true);
                // Keep reading, so the player never finds our buffers full.
                self.read_deltas(deltas);
                self.read_heartbeats(beats);
                if hurry {
                    for i in 0..self.procs.len() {
                        if self.procs[i].alive() && !self.procs[i].kill_sent {
                            self.signal(i, Signal::SIGKILL);
                            self.procs[i].kill_sent = true;
                            self.procs[i].killed_because = "a second stop request".into();
                            self.procs[i].stop_sent.get_or_insert_with(Instant::now);
                        }
                    }
                }
                self.escalate(Some(&members));
            }
        }
        self.display.update(&self.lines());
        self.display.finish();
    }

    /// Prints how the run ended and each process's end; the outcome gives the exit code.
    fn summary(&mut self, end: End) -> Outcome {
        let (reason, mut ok) = match &end {
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
        let failed: Vec<&Proc> = self.procs.iter().filter(|p| p.failure.is_some()).collect();
        ok &= failed.is_empty();
        let mut text = format!(
            "petrel up: {reason}; vehicle `{}` down after {:.2} s\n",
            self.plan.vehicle.name(),
            self.elapsed()
        );
        let w = self
            .procs
            .iter()
            .map(|p| p.plan.spec.name.len())
            .max()
            .unwrap_or(0);
        for p in &self.procs {
            text.push_str(&format!(
                "  {:<w$}  {:<7}  {:<12}  restarts {}{}\n",
                p.plan.spec.name,
                p.plan.spec.kind.as_str(),
                p.state.word(),
                p.restarts,
                p.failure
                    .as_ref()
                    .map(|f| format!("  FAILED: {f}"))
                    .unwrap_or_default()
            ));
        }
        if let Some(s) = &self.player {
            text.push_str(&format!(
                "  last player status: mission time {:.1} s, {} processed, marking {}\n",
                s.time,
                petrel_nets::plural::count(s.processed, "event"),
                s.doc["marking"]
            ));
        }
        text.push_str(&format!("logs: {}\n", self.plan.run_dir.display()));
        for p in &self.procs {
            if let Some(j) = &p.plan.journal {
                text.push_str(&format!(
                    "journal: {} (check it with `petrel replay {}`)\n",
                    j.display(),
                    j.display()
                ));
            }
        }
        // Not `common::out`, which ends the process quietly on a closed pipe: the exit code
        // must still say whether a process failed.
        let _ = std::io::stdout().lock().write_all(text.as_bytes());
        let _ = std::io::stdout().flush();
        if ok {
            return Outcome::Clean;
        }
        // The reason, unless it is one of the process failures listed next.
        if matches!(end, End::Timeout(_) | End::Failure(_)) {
            eprintln!("error: {reason}");
        }
        for p in failed {
            eprintln!(
                "error: process `{}` failed: {} (log: {})",
                p.plan.spec.name,
                p.failure.as_deref().unwrap_or("?"),
                p.plan.log.display()
            );
        }
        Outcome::Errors
    }
}
