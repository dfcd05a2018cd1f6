//! The supervisor's process shell: it starts each process (through `petrel __exec`), reaps
//! them (`try_wait`), reads the stop requests (signalfd), the player's heartbeats and marking
//! deltas, the programs' nodes, makes the timed sends, signals process groups, draws the
//! status lines and tells systemd; [`super::policy`] decides all of it.
//!
//! One thread does it all, in rounds of at most 50 ms that a signal (a stop request, a child's
//! end) cuts short: the iceoryx2 ports are single-threaded, and a round is short beside the
//! player's 100 ms heartbeat.

use super::policy::{Action, End, Kill, Observed, PlayerStatus, Policy, Seen, State};
use crate::common::Outcome;
use crate::up::display::{Display, Line};
use crate::up::file::Kind;
use crate::up::notify::{Notifier, VARIABLES};
use crate::up::signals::Signals;
use crate::up::RunPlan;
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

/// The iceoryx2 ports of a run.
struct Ports {
    beats: petrel_ipc::HeartbeatSubscriber,
    deltas: petrel_ipc::MarkingSubscriber,
    events: petrel_ipc::EventSender,
    /// The programs of this computer's processes: ready when they receive their calls.
    watch: petrel_ipc::ProgramWatch,
}

struct Supervisor {
    plan: RunPlan,
    policy: Policy,
    /// Each process's child, while it is not reaped.
    children: Vec<Option<Child>>,
    display: Display,
    t0: Instant,
    seen: Seen,
    observed: Observed,
    /// Our events' origin, under which the player acknowledges them.
    origin: String,
    /// The running petrel, which starts each process (`petrel __exec`).
    petrel: std::path::PathBuf,
    /// systemd's notifications (readiness, watchdog), when it runs us.
    notify: Notifier,
}

/// Runs the plan; prints the summary; the outcome gives the exit code.
pub fn run(plan: RunPlan, t0: Instant) -> Outcome {
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
    let ports = match open_ports(&me, &plan) {
        Ok(p) => p,
        Err(o) => return o,
    };
    let petrel = match std::env::current_exe() {
        Ok(p) => p,
        Err(e) => return Outcome::Usage(format!("cannot find the running petrel: {e}")),
    };
    let mut sup = Supervisor::new(plan, t0, petrel, ports.events.origin().to_string());
    let mut ports = ports;
    let end = sup.supervise(&signals, &mut ports);
    sup.stop_all(&signals, &ports);
    // Our node goes before the dead ones are cleaned, so the vehicle is left as we found it.
    drop(ports);
    drop(me);
    if let Err(e) = petrel_ipc::cleanup_dead_nodes(&sup.plan.vehicle, Duration::from_millis(500)) {
        eprintln!("warning: {e}");
    }
    sup.summary(end)
}

/// Subscribed before the player starts, so that the first marking (a snapshot) is seen.
fn open_ports(me: &petrel_ipc::Participant, plan: &RunPlan) -> Result<Ports, Outcome> {
    let ports = me
        .heartbeat_subscriber()
        .and_then(|b| Ok((b, me.marking_subscriber()?, me.event_sender()?)));
    let (beats, deltas, events) = ports.map_err(|e| Outcome::Usage(e.to_string()))?;
    let programs = plan
        .processes
        .iter()
        .filter(|p| p.spec.kind == Kind::Program)
        .flat_map(|p| p.spec.programs.clone());
    let watch = petrel_ipc::ProgramWatch::new(me, programs)
        .map_err(|e| Outcome::Usage(format!("cannot watch the programs: {e}")))?;
    Ok(Ports {
        beats,
        deltas,
        events,
        watch,
    })
}

impl Supervisor {
    fn new(
        mut plan: RunPlan,
        t0: Instant,
        petrel: std::path::PathBuf,
        origin: String,
    ) -> Supervisor {
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
        let processes = petrel_diag::plural::count(plan.processes.len(), "process");
        display.message(&format!(
            "petrel up: vehicle `{}` (project `{}`), {processes}{on}; run directory {}",
            plan.vehicle.name(),
            plan.project.name,
            plan.run_dir.display()
        ));
        let mut notify = Notifier::from_env();
        notify.status(&format!("starting {processes}"));
        let rules = std::mem::take(&mut plan.rules);
        let policy = Policy::new(&plan.processes, rules, t0);
        Supervisor {
            children: plan.processes.iter().map(|_| None).collect(),
            plan,
            policy,
            display,
            t0,
            seen: Seen::default(),
            observed: Observed::default(),
            origin,
            petrel,
            notify,
        }
    }

    fn elapsed(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// Carries out the policy's actions; returns the first end among them, or why a send
    /// failed.
    fn apply(&mut self, actions: Vec<Action>, events: &petrel_ipc::EventSender) -> Option<End> {
        let mut end = None;
        for a in actions {
            match a {
                Action::Say(text) => self.display.message(&text),
                Action::Signal(i, Kill::Term) => self.signal(i, Signal::SIGTERM),
                Action::Signal(i, Kill::Kill) => self.signal(i, Signal::SIGKILL),
                Action::Send(k) => {
                    if let Err(why) = self.send(k, events) {
                        return end.or(Some(End::Failure(why)));
                    }
                }
                Action::Finish(e) => end = end.or(Some(e)),
            }
        }
        end
    }

    /// Starts process `i` (again, after a failure, when `restarts` > 0).
    fn spawn(&mut self, i: usize) -> Result<(), String> {
        let p = &self.policy.procs[i];
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
        self.policy.spawned(i, child.id(), Instant::now());
        self.children[i] = Some(child);
        Ok(())
    }

    /// Sends `signal` to process `i`'s group (the process and what it started).
    fn signal(&self, i: usize, signal: Signal) {
        if let (Some(pid), Some(_)) = (self.policy.procs[i].pid, &self.children[i]) {
            // The group leader is not reaped yet, so the group id is its own.
            let _ = killpg(Pid::from_raw(pid as i32), signal);
        }
    }

    /// Makes timed send `k`.
    fn send(&mut self, k: usize, events: &petrel_ipc::EventSender) -> Result<(), String> {
        let s = self.policy.send(k);
        let msg = petrel_ipc::EventMsg::new(s.name.clone(), s.params.clone());
        match events.send(&msg) {
            Ok(sent) => {
                self.policy.sent(k, sent.seq, Instant::now());
                Ok(())
            }
            Err(petrel_ipc::SendError::NoReceiver { .. }) => Err(format!(
                "no player received `{}` (is the player of vehicle `{}` running?)",
                s.text,
                self.plan.vehicle.name()
            )),
            Err(e) => Err(format!("cannot send `{}`: {e}", s.text)),
        }
    }

    /// Reaps the processes that ended; the policy says what their end means.
    fn reap(&mut self, stopping: bool, events: &petrel_ipc::EventSender) -> Option<End> {
        let mut actions = Vec::new();
        for i in 0..self.children.len() {
            let status = match self.children[i].as_mut().map(Child::try_wait) {
                Some(Ok(Some(s))) => s,
                Some(Ok(None)) | None => continue,
                Some(Err(e)) => {
                    // Cannot happen for our own child; treat it as gone rather than loop.
                    let name = &self.policy.procs[i].plan.spec.name;
                    self.display
                        .message(&format!("cannot wait for `{name}`: {e}"));
                    self.children[i] = None;
                    self.policy.lost(i);
                    continue;
                }
            };
            self.children[i] = None;
            let now = Instant::now();
            let ended = self
                .policy
                .exited(i, status.code(), status.signal(), now, stopping);
            actions.extend(ended);
        }
        self.apply(actions, events)
    }

    /// Starts what may start, and sees who became ready. Returns why the vehicle cannot come
    /// up, if it cannot.
    fn start_and_check_ready(
        &mut self,
        watch: &mut petrel_ipc::ProgramWatch,
        events: &petrel_ipc::EventSender,
    ) -> Option<End> {
        let mut actions = Vec::new();
        for i in self.policy.due(Instant::now()) {
            if self.policy.procs[i].restarts > 0 {
                // What the failed process left in shared memory goes before its successor
                // joins (its calls service takes one receiver).
                let _ =
                    petrel_ipc::cleanup_dead_nodes(&self.plan.vehicle, Duration::from_millis(200));
            }
            if let Err(e) = self.spawn(i) {
                actions.extend(self.policy.spawn_failed(i, &e));
            }
        }
        if self.policy.awaits_programs() {
            // Not ready this round if the nodes cannot be listed.
            if let Err(e) = watch.check() {
                actions.push(Action::Say(format!("cannot see the programs: {e}")));
            }
            self.seen.live_programs = self
                .policy
                .procs
                .iter()
                .flat_map(|p| &p.plan.spec.programs)
                .filter(|x| watch.status(x) == Some(petrel_ipc::ProgramStatus::Alive))
                .cloned()
                .collect();
        }
        actions.extend(self.policy.readiness(Instant::now(), &self.seen));
        self.apply(actions, events)
    }

    /// The vehicle is up: said, and told to systemd.
    fn vehicle_up(&mut self) {
        self.display
            .message(&format!("vehicle up in {:.2} s", self.elapsed()));
        let status = format!(
            "vehicle `{}` up: {} running",
            self.plan.vehicle.name(),
            petrel_diag::plural::count(self.policy.procs.len(), "process")
        );
        self.notify.ready(&status);
    }

    /// The main loop, until the run ends.
    fn supervise(&mut self, signals: &Signals, ports: &mut Ports) -> End {
        loop {
            self.display.update(&self.lines());
            // The watchdog watches this loop: fed every round it turns.
            self.notify.watchdog(Instant::now());
            if let Some(s) = signals.wait(ROUND) {
                return End::Signal(s);
            }
            if let Some(end) = self.reap(false, &ports.events) {
                return end;
            }
            self.read(ports);
            // A process stopped for not being ready in time gets its grace period too.
            let kills = self.policy.escalate(Instant::now(), None);
            self.apply(kills, &ports.events);
            if let Some(end) = self.start_and_check_ready(&mut ports.watch, &ports.events) {
                return end;
            }
            if self.policy.vehicle_up(Instant::now()) {
                self.vehicle_up();
            }
            if self.policy.is_up() {
                let sends = self.policy.sends_due(Instant::now());
                if let Some(end) = self.apply(sends, &ports.events) {
                    return end;
                }
                if let Some(end) = self.policy.goal(&self.observed) {
                    return end;
                }
            }
            if self.policy.all_ended() {
                return End::AllExited;
            }
            if let Some(end) = self.policy.timed_out(Instant::now()) {
                return end;
            }
        }
    }

    /// Reads the marking deltas (the events the player took, the places marked), then the
    /// heartbeats (the player's status, the data server's sign of life, the acknowledgements
    /// of the timed sends).
    fn read(&mut self, ports: &Ports) {
        self.read_deltas(&ports.deltas);
        self.read_heartbeats(&ports.beats);
    }

    /// Reads the heartbeats.
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
            self.seen.bridge_beat = Some(Instant::now());
        }
        let Some(text) = player else { return };
        self.seen.player_beat = Some(Instant::now());
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
        for t in self.policy.acknowledged(last_seq) {
            self.display
                .message(&format!("sent `{t}`: acknowledged by the player"));
        }
        self.observed.player = Some(PlayerStatus {
            time: doc["time"].as_f64().unwrap_or(0.0),
            processed: doc["stats"]["processed"].as_u64().unwrap_or(0),
            marked,
            over: doc["over"].as_bool() == Some(true),
            doc,
        });
    }

    /// Reads the marking deltas.
    fn read_deltas(&mut self, deltas: &petrel_ipc::MarkingSubscriber) {
        let marked = &mut self.observed.marked;
        let seen = &mut self.observed.events_seen;
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
            if let Some(s) = &self.observed.player {
                self.observed.marked = s.marked.clone();
            }
        }
    }

    /// Stops every process, the last started first: a layer of processes that nothing else
    /// waits for gets SIGTERM, then SIGKILL past its grace period, and the next layer follows
    /// once it is gone. A second stop request kills what is left at once.
    fn stop_all(&mut self, signals: &Signals, ports: &Ports) {
        self.notify.stopping("stopping the vehicle");
        self.policy.begin_stop();
        let mut hurry = false;
        for members in self.policy.stop_layers() {
            let terms = self.policy.stop(&members, Instant::now());
            self.apply(terms, &ports.events);
            while members.iter().any(|&i| self.policy.procs[i].alive) {
                self.display.update(&self.lines());
                self.notify.watchdog(Instant::now());
                if let Some(s) = signals.wait(ROUND) {
                    if !hurry {
                        self.display
                            .message(&format!("{}: killing every process now", s.as_str()));
                    }
                    hurry = true;
                }
                self.reap(true, &ports.events);
                // Keep reading, so the player never finds our buffers full.
                self.read(ports);
                if hurry {
                    let kills = self.policy.hurry(Instant::now());
                    self.apply(kills, &ports.events);
                }
                let kills = self.policy.escalate(Instant::now(), Some(&members));
                self.apply(kills, &ports.events);
            }
        }
        self.display.update(&self.lines());
        self.display.finish();
    }

    /// The status lines.
    fn lines(&self) -> Vec<Line> {
        let procs = &self.policy.procs;
        let w = procs.iter().map(|p| p.plan.spec.name.len()).max();
        let w = w.unwrap_or(0);
        procs
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
                    if let Some(s) = &self.observed.player {
                        text.push_str(&format!(
                            "  mission {:.1} s, {}, {} marked{}",
                            s.time,
                            petrel_diag::plural::count(s.processed, "event"),
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

    /// Prints how the run ended and each process's end; the outcome gives the exit code.
    fn summary(&mut self, end: End) -> Outcome {
        let (reason, ok) = self.policy.verdict(&end);
        let procs = &self.policy.procs;
        let mut text = format!(
            "petrel up: {reason}; vehicle `{}` down after {:.2} s\n",
            self.plan.vehicle.name(),
            self.elapsed()
        );
        let w = procs.iter().map(|p| p.plan.spec.name.len()).max();
        let w = w.unwrap_or(0);
        for p in procs {
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
        if let Some(s) = &self.observed.player {
            text.push_str(&format!(
                "  last player status: mission time {:.1} s, {} processed, marking {}\n",
                s.time,
                petrel_diag::plural::count(s.processed, "event"),
                s.doc["marking"]
            ));
        }
        text.push_str(&format!("logs: {}\n", self.plan.run_dir.display()));
        for j in procs.iter().filter_map(|p| p.plan.journal.as_ref()) {
            text.push_str(&format!(
                "journal: {} (check it with `petrel replay {}`)\n",
                j.display(),
                j.display()
            ));
        }
        // A project with a map says where the vehicle's positions come from: the run can be
        // drawn (docs/monitor.md, "The map").
        let recorded = procs.iter().any(|p| p.plan.journal.is_some());
        if recorded && self.plan.project_dir.join("map.toml").is_file() {
            text.push_str(&format!(
                "map: `petrel plot {}` draws the run on the project's map.toml (map.svg)\n",
                self.plan.run_dir.display()
            ));
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
        for p in procs.iter().filter(|p| p.failure.is_some()) {
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
