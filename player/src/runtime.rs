//! The player process: the engine wired to iceoryx2 (`petrel play`).
//!
//! One reactor thread waits, with the chosen strategy, on the events service, the next timer
//! deadline, the heartbeat and the liveness check. On each wake-up it moves time forward,
//! drains incoming events into the engine (refusing malformed ones with a `bad_message` event),
//! turns dead programs into `program_lost`, processes the queue, sends calls (an absent program
//! gives `call_failed`), and publishes marking deltas and a heartbeat carrying the live status.

use crate::engine::{ArgValue, Args, Engine, Micros, Refusal, Sink, Stats};
use petrel_ipc::{
    CallMsg, CallSender, HeartbeatPublisher, MarkingMsg, MarkingPublisher, Participant,
    ProgramWatch, Reactor, RecvError, Role, SendError, Vehicle, WaitStrategy,
};
use petrel_nets::compiled::{CompiledProject, FunctionId, NetId, ProgramId, Value};
use petrel_nets::semantics::Layout;
use std::time::{Duration, Instant};
use tracing::{debug, info, warn};

/// How to run the player.
#[derive(Clone, Debug)]
pub struct PlayOptions {
    /// The vehicle: its services are `petrel/<vehicle>/...`.
    pub vehicle: String,
    /// How the reactor waits.
    pub wait: WaitStrategy,
    /// Period of the heartbeat (which carries the live status).
    pub heartbeat: Duration,
    /// Period of the check for dead programs (also run whenever a sender is seen dying).
    pub liveness: Duration,
    /// Stop after this long (tests and demos); `None` runs until SIGINT or SIGTERM.
    pub run_for: Option<Duration>,
}

impl PlayOptions {
    /// Defaults for `vehicle`: block, heartbeat every 100 ms, liveness every 50 ms.
    pub fn new(vehicle: &str) -> Self {
        PlayOptions {
            vehicle: vehicle.to_string(),
            wait: WaitStrategy::Block,
            heartbeat: Duration::from_millis(100),
            liveness: Duration::from_millis(50),
            run_for: None,
        }
    }
}

/// Why the player could not run.
#[derive(Debug)]
pub enum PlayError {
    /// The vehicle name is not usable.
    Vehicle(String),
    /// iceoryx2 could not be set up (another player on the vehicle, say).
    Setup(String),
}

impl std::fmt::Display for PlayError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlayError::Vehicle(e) => write!(f, "bad vehicle name: {e}"),
            PlayError::Setup(e) => write!(f, "cannot set up the player: {e}"),
        }
    }
}

impl std::error::Error for PlayError {}

/// What a run of the player did.
#[derive(Clone, Debug, Default)]
pub struct PlayReport {
    /// The engine's counters.
    pub stats: Stats,
    /// Events received from iceoryx2 (decoded or not).
    pub messages: u64,
    /// Messages refused before the engine: undecodable, unknown event, wrong parameters.
    pub bad_messages: u64,
    /// Calls delivered to programs.
    pub calls_sent: u64,
    /// Calls to absent programs (each became `call_failed`).
    pub calls_failed: u64,
}

/// Sends what the engine asks for, during one step.
struct RuntimeSink<'a> {
    project: &'a CompiledProject,
    calls: &'a [CallSender],
    failed: Vec<(ProgramId, FunctionId)>,
    fired: Vec<String>,
    activated: Vec<String>,
    deactivated: Vec<String>,
    event: Option<String>,
    sent: u64,
}

fn to_wire(v: ArgValue<'_>) -> petrel_ipc::Value {
    match v {
        ArgValue::Int(i) => petrel_ipc::Value::Int(i),
        ArgValue::Float(f) => petrel_ipc::Value::Float(f),
        ArgValue::Bool(b) => petrel_ipc::Value::Bool(b),
        ArgValue::Text(s) => petrel_ipc::Value::Text(s.to_string()),
        ArgValue::FloatList(l) => petrel_ipc::Value::FloatList(l.to_vec()),
    }
}

/// A checked value as it travels on the wire.
pub fn value_to_wire(v: &Value) -> petrel_ipc::Value {
    to_wire(crate::engine::ArgValue::of(v))
}

fn from_wire(v: petrel_ipc::Value) -> Value {
    match v {
        petrel_ipc::Value::Int(i) => Value::Int(i),
        petrel_ipc::Value::Float(f) => Value::Float(f),
        petrel_ipc::Value::Bool(b) => Value::Bool(b),
        petrel_ipc::Value::Text(s) => Value::Text(s),
        petrel_ipc::Value::FloatList(l) => Value::FloatList(l),
    }
}

impl Sink for RuntimeSink<'_> {
    fn taken(&mut self, event: petrel_nets::compiled::EventId, _params: &[Value]) {
        self.event = Some(self.project.events[event as usize].name.clone());
    }

    fn fired(&mut self, net: NetId, transition: u32) {
        let n = &self.project.nets[net as usize];
        debug!(net = %n.name, transition = %n.transitions[transition as usize].name, "fired");
        self.fired.push(format!(
            "{}.{}",
            n.name, n.transitions[transition as usize].name
        ));
    }

    fn activated(&mut self, net: NetId) {
        self.activated
            .push(self.project.nets[net as usize].name.clone());
    }

    fn deactivated(&mut self, net: NetId) {
        self.deactivated
            .push(self.project.nets[net as usize].name.clone());
    }

    fn call(&mut self, program: ProgramId, function: FunctionId, args: Args<'_>) {
        let prog = &self.project.programs[program as usize];
        let fname = &prog.functions[function as usize].name;
        let msg = CallMsg::new(fname.clone(), args.iter().map(to_wire).collect());
        match self.calls[program as usize].send(&msg) {
            Ok(_) => {
                self.sent += 1;
                debug!(program = %prog.name, function = %fname, "call sent");
            }
            Err(e) => {
                warn!(program = %prog.name, function = %fname, error = %e, "call not delivered: raising call_failed");
                self.failed.push((program, function));
            }
        }
    }

    fn safety_violation(&mut self, net: NetId, transition: u32, place: &str) {
        let n = &self.project.nets[net as usize];
        warn!(net = %n.name, transition = %n.transitions[transition as usize].name, place, "firing refused: a second token; raising safety_violation");
    }

    fn livelock(&mut self) {
        warn!("immediate transitions did not settle: fixpoint stopped, raising livelock");
    }
}

fn now(t0: Instant) -> Micros {
    t0.elapsed().as_micros().min(u64::MAX as u128) as u64
}

/// The marking as `NET.place` and `global.place`, for marking messages and the status.
fn marked_places(project: &CompiledProject, layout: &Layout, state: &[u64]) -> Vec<String> {
    let mut out = Vec::new();
    for (n, net) in project.nets.iter().enumerate() {
        for (i, p) in net.places.iter().enumerate() {
            if Layout::bit(state, layout.net_base[n] + i as u32) {
                out.push(format!("{}.{}", net.name, p.name));
            }
        }
    }
    for (g, gp) in project.globals.iter().enumerate() {
        if Layout::bit(state, layout.global_base + g as u32) {
            out.push(format!("global.{}", gp.name));
        }
    }
    out
}

/// The live status carried by the heartbeat: JSON with the marking of every active net, the
/// counters, and the last sequence number taken from each sender (read by `petrel status`, and
/// by `petrel send` as its acknowledgement).
fn status_json(engine: &Engine, report: &PlayReport, events: &petrel_ipc::EventReceiver) -> String {
    let senders: serde_json::Map<String, serde_json::Value> = events
        .senders()
        .into_iter()
        .map(|a| {
            (
                a.origin.to_string(),
                serde_json::json!({"last_seq": a.last_seq, "received": a.received, "undecodable": a.undecodable, "missing": a.missing}),
            )
        })
        .collect();
    let marking: serde_json::Map<String, serde_json::Value> = engine
        .marking()
        .into_iter()
        .map(|(n, places)| (n, places.into()))
        .collect();
    let s = engine.stats();
    serde_json::json!({
        "project": engine.project().name,
        "time": engine.now() as f64 / 1e6,
        "over": engine.is_over(),
        "marking": marking,
        "stats": {
            "messages": report.messages,
            "bad_messages": report.bad_messages,
            "received": s.received,
            "processed": s.processed,
            "unused": s.unused,
            "refused": s.refused,
            "queued": engine.queued(),
            "calls_sent": report.calls_sent,
            "calls_failed": report.calls_failed,
        },
        "senders": senders,
    })
    .to_string()
}

/// Runs the player until SIGINT/SIGTERM (or `run_for`).
pub fn play(project: &CompiledProject, opts: &PlayOptions) -> Result<PlayReport, PlayError> {
    let vehicle = Vehicle::new(&opts.vehicle).map_err(|e| PlayError::Vehicle(e.to_string()))?;
    match petrel_ipc::cleanup_dead_nodes(&vehicle, Duration::from_millis(500)) {
        Ok(r) if !r.cleaned.is_empty() => {
            info!(
                cleaned = r.cleaned.len(),
                "removed the resources of dead processes"
            )
        }
        Ok(_) => {}
        Err(e) => warn!(error = %e, "could not look for dead processes"),
    }
    let setup = |e: petrel_ipc::SetupError| PlayError::Setup(e.to_string());
    let me = Participant::join(&vehicle, Role::Player).map_err(setup)?;
    let events = me.event_receiver().map_err(setup)?;
    let calls: Vec<CallSender> = project
        .programs
        .iter()
        .map(|p| me.call_sender(&p.name))
        .collect::<Result<_, _>>()
        .map_err(setup)?;
    let marking_out: MarkingPublisher = me.marking_publisher().map_err(setup)?;
    let heartbeat: HeartbeatPublisher = me.heartbeat_publisher().map_err(setup)?;
    let mut watch = ProgramWatch::new(&vehicle, project.programs.iter().map(|p| p.name.clone()));
    let reactor = Reactor::new(opts.wait).map_err(|e| PlayError::Setup(e.to_string()))?;
    let program_lost = project.event_id("program_lost");
    let call_failed = project.event_id("call_failed");
    let bad_message = project.event_id("bad_message");

    let t0 = Instant::now();
    let mut engine = Engine::new(project);
    let mut report = PlayReport::default();
    let mut sink = RuntimeSink {
        project,
        calls: &calls,
        failed: Vec::new(),
        fired: Vec::new(),
        activated: Vec::new(),
        deactivated: Vec::new(),
        event: None,
        sent: 0,
    };
    let mut previous = engine.state().to_vec();
    let mut step_no = 0u64;
    engine.start(0, &mut sink);
    info!(project = %project.name, vehicle = %opts.vehicle, wait = ?opts.wait, "player started");
    let _ = watch.check();

    let mut next_heartbeat = Instant::now();
    let mut next_liveness = Instant::now() + opts.liveness;
    loop {
        // Everything queued (by the start, a timer, an event) is processed, then published.
        loop {
            let stepped = engine.step(&mut sink).is_some();
            let failed = std::mem::take(&mut sink.failed);
            for (p, f) in failed {
                report.calls_failed += 1;
                if let Some(e) = call_failed {
                    let prog = &project.programs[p as usize];
                    let params = vec![
                        Value::Text(prog.name.clone()),
                        Value::Text(prog.functions[f as usize].name.clone()),
                    ];
                    if let Err(r) = engine.submit(e, params) {
                        warn!(refusal = %r, "call_failed refused");
                    }
                }
            }
            if stepped || step_no == 0 {
                publish_delta(&engine, &mut sink, &mut previous, step_no, &marking_out);
                step_no += 1;
            }
            if !stepped {
                break;
            }
        }
        report.calls_sent = sink.sent;

        let instant = Instant::now();
        if instant >= next_heartbeat {
            let status = status_json(&engine, &report, &events);
            let hb = petrel_ipc::Heartbeat {
                uptime_ms: t0.elapsed().as_millis() as u64,
                period_ms: opts.heartbeat.as_millis() as u32,
                progress: step_no,
                status,
            };
            // Latest-value service: a heartbeat nobody reads is not an error.
            let _ = heartbeat.send(&hb);
            next_heartbeat = instant + opts.heartbeat;
        }
        if let Some(limit) = opts.run_for {
            if t0.elapsed() >= limit {
                info!("run time over");
                break;
            }
        }
        let mut timeout = next_heartbeat
            .min(next_liveness)
            .saturating_duration_since(Instant::now());
        if let Some(d) = engine.next_deadline() {
            let until = Duration::from_micros(d.saturating_sub(now(t0)));
            timeout = timeout.min(until);
        }
        let ready = match reactor.wait(&[&events], Some(timeout)) {
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
        engine.advance_to(now(t0));
        let mut someone_died = false;
        let drained = events.drain(|r| {
            report.messages += 1;
            match r {
                Ok(rcv) => {
                    let origin = rcv.origin.to_string();
                    let mut params = engine.param_buffer();
                    params.extend(rcv.msg.params.into_iter().map(from_wire));
                    if let Err(refusal) = engine.submit_named(&rcv.msg.name, params) {
                        if !matches!(refusal, Refusal::AfterCatastrophic(_)) {
                            report.bad_messages += 1;
                            warn!(from = %origin, seq = rcv.seq, reason = %refusal, "event refused");
                            raise_bad_message(&mut engine, bad_message, &origin, &refusal.to_string());
                        } else {
                            info!(from = %origin, reason = %refusal, "event refused");
                        }
                    }
                }
                Err(RecvError::Undecodable {
                    origin, seq, error, ..
                }) => {
                    report.bad_messages += 1;
                    warn!(from = %origin, seq, error = %error, "undecodable event refused");
                    raise_bad_message(&mut engine, bad_message, &origin.to_string(), &format!("undecodable: {error}"));
                }
                Err(e) => {
                    report.bad_messages += 1;
                    warn!(error = %e, "event could not be received");
                }
            }
        });
        match drained {
            Ok(d) => someone_died = d.wakeups.senders_died > 0,
            Err(e) => warn!(error = %e, "draining events failed"),
        }
        if someone_died || Instant::now() >= next_liveness {
            next_liveness = Instant::now() + opts.liveness;
            match watch.check() {
                Ok(changes) => {
                    for c in changes {
                        if c.is_lost() {
                            warn!(program = %c.program, "program lost");
                            if let Some(e) = program_lost {
                                let _ = engine.submit(e, vec![Value::Text(c.program.clone())]);
                            }
                        } else {
                            info!(program = %c.program, status = ?c.to, "program status");
                        }
                    }
                }
                Err(e) => warn!(error = %e, "liveness check failed"),
            }
        }
    }
    report.stats = engine.stats();
    report.calls_sent = sink.sent;
    info!(?report, "player stopped");
    Ok(report)
}

fn raise_bad_message(
    engine: &mut Engine,
    event: Option<petrel_nets::compiled::EventId>,
    sender: &str,
    reason: &str,
) {
    if let Some(e) = event {
        let params = vec![
            Value::Text(sender.to_string()),
            Value::Text(reason.to_string()),
        ];
        if let Err(r) = engine.submit(e, params) {
            debug!(refusal = %r, "bad_message refused");
        }
    }
}

/// Publishes what the last step changed (the first message is a full snapshot).
fn publish_delta(
    engine: &Engine,
    sink: &mut RuntimeSink,
    previous: &mut Vec<u64>,
    step: u64,
    out: &MarkingPublisher,
) {
    let project = engine.project();
    let layout = engine.layout();
    let now = engine.state();
    let before = marked_places(project, layout, previous);
    let after = marked_places(project, layout, now);
    let snapshot = step == 0;
    let msg = MarkingMsg {
        step,
        event: sink.event.take(),
        fired: std::mem::take(&mut sink.fired),
        marked: if snapshot {
            after.clone()
        } else {
            after
                .iter()
                .filter(|p| !before.contains(p))
                .cloned()
                .collect()
        },
        unmarked: before
            .iter()
            .filter(|p| !after.contains(p))
            .cloned()
            .collect(),
        activated: std::mem::take(&mut sink.activated),
        deactivated: std::mem::take(&mut sink.deactivated),
        snapshot,
    };
    previous.clear();
    previous.extend_from_slice(now);
    match out.send(&msg) {
        Ok(_) | Err(SendError::NoReceiver { .. }) => {}
        Err(e) => warn!(error = %e, "marking delta not delivered to every monitor"),
    }
}
