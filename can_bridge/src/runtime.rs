//! The data server's process loop: a [`Bus`], the [`BridgeCore`], and the vehicle's iceoryx2
//! services.
//!
//! One thread waits (with a [`Reactor`], the same kind of WaitSet as the player's) on the bus's
//! file descriptor, on the commands program's calls if can.toml names one, and on the next
//! deadline of the core (staleness, hold times, heartbeat). It then:
//!
//! 1. reads every frame the bus has, records it (`candump -L`, direction `R`), and feeds it to
//!    the core; unusual frames (unknown identifier, wrong length, error frames) are counted by
//!    the core and logged here (the first ones of each kind, then one in 1,000);
//! 2. turns calls into command frames and sends them (recorded with direction `T`, then fed to
//!    the core as sent); a command refused (by the DBC's ranges, or a full transmit queue)
//!    becomes `call_failed(program, function)` for the player;
//! 3. advances the core's time, sends the heartbeat when due (skipped, and counted, while frames
//!    wait for the interface: a late burst of heartbeats would lie), polls the interface state
//!    every `state_poll` and restarts the interface after a bus-off if can.toml asks;
//! 4. retries frames waiting for the interface ([`Bus::flush`]);
//! 5. sends the events to the player as [`Role::CanBridge`]. Events the player cannot take yet
//!    (no player running) wait in a bounded outbox, in order; beyond its bound the oldest are
//!    dropped, counted and logged. Before leaving, the loop waits (up to `ack_grace`) for the
//!    player's heartbeat to acknowledge the last event sent;
//! 6. publishes its own heartbeat every 100 ms, its status (bus state, counters) as JSON, which
//!    `petrel status` shows.

use std::collections::VecDeque;
use std::fmt;
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use petrel_ipc::{
    CallReceiver, EventMsg, EventSender, FdSource, Participant, Reactor, ReactorError, Role,
    SendError, SetupError, SignalsMsg, Source, Vehicle, WaitStrategy,
};
use petrel_nets::compiled::Value;

use crate::bridge::{BridgeCore, Counters, SignalTable};
use crate::bus::{Bus, BusError, BusStats};
use crate::bus_state::{describe_error_frame, state_from_error_frame, BusState};
use crate::clock::Clock;
use crate::dbc::{Dbc, DecodeOutcome};
use crate::event::{EventCause, EventOut};
use crate::log::{format_record, Direction, LogRecord};

// The one place where the core's types meet `petrel_ipc`'s. The core (everything but this
// module, `serve` and `bus`) does not know the transport; what crosses goes through this pair.

/// An event of the core as the player receives it.
pub fn event_msg(event: &EventOut) -> EventMsg {
    EventMsg::new(event.name.clone(), event.params.clone())
}

/// The latest value of every signal seen, as the `signals` service publishes them.
fn signals_msg(table: &SignalTable, dbc: &Dbc) -> SignalsMsg {
    let values: Vec<(String, f64, u64)> = table
        .iter()
        .map(|(r, s)| (dbc.signal_path(r), s.physical, s.time_us))
        .collect();
    SignalsMsg {
        time_us: values.iter().map(|v| v.2).max().unwrap_or(0),
        values,
    }
}

/// How the loop runs.
pub struct RuntimeOptions {
    /// How to wait for work.
    pub wait: WaitStrategy,
    /// Where to record every frame in and out, as a `candump -L` log (with directions).
    pub record: Option<Box<dyn Write>>,
    /// How often to ask the interface for its state, in microseconds.
    pub state_poll_us: u64,
    /// Events held while no player receives them.
    pub outbox: usize,
    /// Handle SIGINT and SIGTERM (stop in good order); off for tests.
    pub handle_signals: bool,
    /// How long to wait, when stopping, for the player to acknowledge the last events sent.
    pub ack_grace: Duration,
}

impl Default for RuntimeOptions {
    fn default() -> Self {
        RuntimeOptions {
            wait: WaitStrategy::Block,
            record: None,
            state_poll_us: 100_000,
            outbox: 4096,
            handle_signals: true,
            ack_grace: Duration::from_secs(2),
        }
    }
}

impl fmt::Debug for RuntimeOptions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RuntimeOptions")
            .field("wait", &self.wait)
            .field("record", &self.record.is_some())
            .field("state_poll_us", &self.state_poll_us)
            .field("outbox", &self.outbox)
            .field("handle_signals", &self.handle_signals)
            .field("ack_grace", &self.ack_grace)
            .finish()
    }
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunReport {
    /// When the loop began reading the bus (the clock's microseconds): silence counts from
    /// then, so a replay of the run's log starts its core then ([`BridgeCore::begin`]).
    pub started_us: u64,
    /// The core's counters.
    pub counters: Counters,
    /// The bus's counters.
    pub bus: BusStats,
    /// Events delivered to the player.
    pub events_sent: u64,
    /// Events the player's buffer refused (it sees the gap).
    pub events_refused: u64,
    /// Events dropped from a full outbox (no player for too long).
    pub events_dropped: u64,
    /// Events still in the outbox at the end.
    pub events_pending: usize,
    /// Frames refused by a full transmit queue.
    pub frames_refused: u64,
    /// Frames recorded to the log.
    pub frames_recorded: u64,
    /// Heartbeats not sent because earlier frames still waited for the interface.
    pub heartbeats_skipped: u64,
    /// Commands not carried out (refused by the DBC or the transmit queue), each reported to
    /// the player as `call_failed`.
    pub commands_failed: u64,
    /// Frames still waiting for the interface when the bridge stopped: never sent.
    pub frames_unsent: usize,
    /// At the end, the player had not acknowledged the last events sent within the grace
    /// period: they may be lost (a sender's shared memory goes with its process).
    pub unacknowledged: bool,
}

/// The loop could not run.
#[derive(Debug)]
pub enum RuntimeError {
    /// Joining the vehicle or opening a port failed.
    Setup(SetupError),
    /// The reactor failed.
    Reactor(ReactorError),
    /// The bus failed for good (reading it).
    Bus(BusError),
    /// The bus gives no file descriptor to wait on.
    NoFd,
}

impl fmt::Display for RuntimeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RuntimeError::Setup(e) => e.fmt(f),
            RuntimeError::Reactor(e) => e.fmt(f),
            RuntimeError::Bus(e) => e.fmt(f),
            RuntimeError::NoFd => f.write_str("the bus gives no file descriptor to wait on"),
        }
    }
}

impl std::error::Error for RuntimeError {}

impl From<SetupError> for RuntimeError {
    fn from(e: SetupError) -> Self {
        RuntimeError::Setup(e)
    }
}
impl From<ReactorError> for RuntimeError {
    fn from(e: ReactorError) -> Self {
        RuntimeError::Reactor(e)
    }
}

/// How often the bridge publishes its own heartbeat (its status), in microseconds.
const HEARTBEAT_PERIOD_US: u64 = 100_000;

/// Logs the first occurrences of a kind of problem, then one in 1,000.
fn worth_logging(count: u64) -> bool {
    count <= 10 || count.is_multiple_of(1000)
}

struct Loop<B: Bus> {
    core: BridgeCore,
    bus: B,
    clock: Arc<dyn Clock>,
    events: EventSender,
    outbox: VecDeque<EventMsg>,
    opts: RuntimeOptions,
    report: RunReport,
    /// The sequence number of the last event the player received.
    last_seq: u64,
}

impl<B: Bus> Loop<B> {
    fn record(&mut self, time_us: u64, frame: &crate::frame::Frame, dir: Direction) {
        if let Some(out) = &mut self.opts.record {
            let line = format_record(&LogRecord {
                time_us,
                interface: self.bus.interface().to_owned(),
                frame: *frame,
                direction: Some(dir),
            });
            match writeln!(out, "{line}") {
                Ok(()) => self.report.frames_recorded += 1,
                Err(e) => {
                    tracing::error!("cannot record the bus: {e}; recording stops");
                    self.opts.record = None;
                }
            }
        }
    }

    fn queue_events(&mut self, events: Vec<EventOut>) {
        for e in events {
            tracing::info!(time_us = e.time_us, "event {} {:?}", e.name, e.params);
            if self.outbox.len() >= self.opts.outbox.max(1) {
                if let Some(old) = self.outbox.pop_front() {
                    self.report.events_dropped += 1;
                    tracing::error!(
                        "no player took events for too long: event `{}` dropped ({} dropped so far)",
                        old.name,
                        self.report.events_dropped
                    );
                }
            }
            self.outbox.push_back(event_msg(&e));
        }
    }

    /// Sends a frame; false when it was not sent and will not be.
    fn send(&mut self, frame: &crate::frame::Frame, what: &str) -> bool {
        let now = self.clock.now_us();
        match self.bus.send(frame) {
            Ok(_) => {
                self.record(now, frame, Direction::Transmitted);
                let events = self.core.on_sent(now, frame);
                self.queue_events(events);
                true
            }
            Err(BusError::QueueFull { frame, capacity }) => {
                self.report.frames_refused += 1;
                tracing::error!(
                    "{what} {frame} not sent: {capacity} frames already wait for `{}`",
                    self.bus.interface()
                );
                false
            }
            Err(e) => {
                tracing::error!("{what} {frame} not sent: {e}");
                false
            }
        }
    }

    /// The bridge's status, as its heartbeat carries it (a JSON object).
    fn status_json(&self) -> String {
        let c = self.core.counters();
        serde_json::json!({
            "interface": self.bus.interface(),
            "bus_state": self.core.bus_state().name(),
            "frames": c.frames,
            "decoded": c.decoded,
            "unknown_id": c.unknown_id,
            "wrong_length": c.wrong_length,
            "error_frames": c.error_frames,
            "events": c.events,
            "events_sent": self.report.events_sent,
            "events_pending": self.outbox.len(),
            "events_dropped": self.report.events_dropped,
            "commands": c.commands,
            "commands_failed": self.report.commands_failed,
            "heartbeats": c.heartbeats,
            "heartbeats_failed": c.heartbeats_failed,
            "tx_queued": self.bus.queued(),
        })
        .to_string()
    }

    /// A command that was not carried out: the player hears `call_failed(program, function)`,
    /// as for a call no program received, so that a net can react to it.
    fn command_failed(&mut self, function: &str) {
        let Some(program) = self.core.config().commands.program.clone() else {
            return;
        };
        self.report.commands_failed += 1;
        let time_us = self.clock.now_us();
        self.queue_events(vec![EventOut::new(
            time_us,
            EventCause::Command,
            "call_failed",
            vec![Value::Text(program), Value::Text(function.to_owned())],
        )]);
    }

    /// The interface went down or away: the bus is stopped until [`Bus::state`] says
    /// otherwise (polled every `state_poll`); the player hears it once.
    fn interface_down(&mut self, error: &BusError) {
        if self.core.bus_state() == BusState::Stopped {
            return;
        }
        tracing::error!(
            "{error}: the bus is stopped; waiting for `{}` to come back",
            self.bus.interface()
        );
        let now = self.clock.now_us();
        let events = self.core.on_bus_state(now, BusState::Stopped);
        self.queue_events(events);
    }

    fn read_bus(&mut self) -> Result<(), RuntimeError> {
        loop {
            let tf = match self.bus.recv() {
                Ok(Some(tf)) => tf,
                Ok(None) => return Ok(()),
                Err(e) if e.is_interface_down() => {
                    self.interface_down(&e);
                    return Ok(());
                }
                Err(e) => return Err(RuntimeError::Bus(e)),
            };
            self.record(tf.time_us, &tf.frame, Direction::Received);
            let report = self.core.on_frame(tf.time_us, &tf.frame);
            let c = self.core.counters();
            // Error frames tell the state they report here, where it is logged and acted on.
            let error_state = match report.outcome {
                DecodeOutcome::Error => state_from_error_frame(&tf.frame),
                _ => None,
            };
            match &report.outcome {
                DecodeOutcome::Message(_) => {}
                DecodeOutcome::UnknownId(id) if worth_logging(c.unknown_id) => tracing::warn!(
                    "frame {} with identifier {id} unknown to the DBC ({} so far)",
                    tf.frame,
                    c.unknown_id
                ),
                DecodeOutcome::WrongLength {
                    message,
                    expected,
                    got,
                } if worth_logging(c.wrong_length) => tracing::warn!(
                    "frame {} of message `{}` has {got} bytes, the DBC says {expected} ({} so far)",
                    tf.frame,
                    self.core
                        .dbc()
                        .message(*message)
                        .map_or("?", |m| m.name.as_str()),
                    c.wrong_length
                ),
                DecodeOutcome::Error if worth_logging(c.error_frames) => tracing::warn!(
                    "error frame: {}{} ({} so far)",
                    describe_error_frame(&tf.frame),
                    error_state.map_or(String::new(), |s| format!(", bus {s}")),
                    c.error_frames
                ),
                _ => {}
            }
            if error_state == Some(BusState::BusOff) {
                self.restart_if_asked();
            }
            self.queue_events(report.events);
        }
    }

    fn restart_if_asked(&mut self) {
        if self.core.config().bus.restart_after_bus_off {
            match self.bus.restart() {
                Ok(()) => tracing::warn!("bus-off: `{}` restarted", self.bus.interface()),
                Err(e) => tracing::error!("bus-off: cannot restart: {e}"),
            }
        }
    }

    fn take_calls(&mut self, calls: &CallReceiver) {
        let mut received = Vec::new();
        let drained = calls.drain(|r| match r {
            Ok(r) => received.push(r.msg),
            Err(e) => tracing::warn!("a command could not be read: {e}"),
        });
        if let Err(e) = drained {
            tracing::warn!("commands could not be read: {e}");
        }
        for call in received {
            match self.core.command_call(&call.function, &call.args) {
                Ok(frame) => {
                    if !self.send(&frame, "command") {
                        self.command_failed(&call.function);
                    }
                }
                Err(e) => {
                    tracing::error!("command {}: {e}", call.function);
                    self.command_failed(&call.function);
                }
            }
        }
    }

    fn deliver(&mut self) {
        while let Some(msg) = self.outbox.front() {
            match self.events.send(msg) {
                Ok(sent) => {
                    self.last_seq = sent.seq;
                    self.report.events_sent += 1;
                    self.outbox.pop_front();
                }
                Err(SendError::NoReceiver { .. }) => break,
                Err(e) => {
                    self.report.events_refused += 1;
                    tracing::error!("event `{}`: {e}", msg.name);
                    self.outbox.pop_front();
                }
            }
        }
    }
}

/// Says, from the commands program's own sender (origin `program/NAME`), that it leaves in
/// good order ([`LEAVE`](petrel_ipc::wire::LEAVE)); returns the sender and the leave's
/// sequence number, for its acknowledgement. `None` when no player receives (nothing to tell)
/// or the leave could not be sent (the player will take the going for a loss).
fn say_leave(program: &Participant) -> Option<(petrel_ipc::EventSender, u64)> {
    let sender = program.event_sender_sized().ok()?;
    match sender.send(&petrel_ipc::EventMsg::leave()) {
        Ok(sent) => Some((sender, sent.seq)),
        Err(petrel_ipc::SendError::NoReceiver { .. }) => None,
        Err(e) => {
            tracing::warn!("the commands program could not say it leaves: {e}");
            None
        }
    }
}

/// Runs the data server until `stop` is set (or SIGINT/SIGTERM with signal handling on).
///
/// `open_bus` is called once the vehicle is joined, just before the loop reads: frames do
/// not wait in a socket during the set-up (where the kernel may stamp them late), and the
/// core's silence deadlines count from the first read ([`BridgeCore::begin`]).
///
/// `clock` must be the bus's clock (the system clock for SocketCAN, the hub's for a memory
/// bus): frame timestamps and deadlines are compared.
///
/// The bus going down or away is not an error: the player hears `Stopped`, commands wait,
/// and the loop goes on until the interface is back. Other bus errors end the run.
pub fn run<B: Bus>(
    core: BridgeCore,
    open_bus: impl FnOnce() -> Result<B, BusError>,
    clock: Arc<dyn Clock>,
    vehicle: &Vehicle,
    opts: RuntimeOptions,
    stop: &AtomicBool,
) -> Result<RunReport, RuntimeError> {
    let participant = Participant::join(vehicle, Role::CanBridge)?;
    let events = participant.event_sender_sized()?;
    let beats = participant.heartbeat_subscriber()?;
    // The bridge's own heartbeat: its status for `petrel status` and the operators.
    let own_beat = participant.heartbeat_publisher()?;
    let t0 = std::time::Instant::now();
    let mut next_beat = clock.now_us();
    let mut heartbeats_refused = 0u64;
    // Latest values of the decoded signals, for the programs.
    let signals = participant.signals_publisher()?;
    let mut published_updates = 0u64;
    let commands = match &core.config().commands.program {
        Some(p) => {
            let prog = Participant::join(vehicle, Role::program(p).map_err(SetupError::Name)?)?;
            let calls = prog.call_receiver()?;
            Some((prog, calls))
        }
        None => None,
    };
    let reactor = if opts.handle_signals {
        Reactor::new(opts.wait)?
    } else {
        Reactor::without_signal_handling(opts.wait)?
    };
    let bus = open_bus().map_err(RuntimeError::Bus)?;
    let mut fd_raw = bus.wait_fd().ok_or(RuntimeError::NoFd)?;
    let mut fd = FdSource::new(fd_raw)?;
    let state_poll = opts.state_poll_us.max(1000);
    let mut core = core;
    let started_us = clock.now_us();
    core.begin(started_us);
    let mut lp = Loop {
        core,
        bus,
        clock,
        events,
        outbox: VecDeque::new(),
        opts,
        report: RunReport {
            started_us,
            ..RunReport::default()
        },
        last_seq: 0,
    };
    let mut next_poll = lp.clock.now_us();
    while !stop.load(Ordering::Relaxed) {
        let now = lp.clock.now_us();
        let mut deadline = lp
            .core
            .next_deadline()
            .unwrap_or(u64::MAX)
            .min(next_poll)
            .min(next_beat);
        if !lp.outbox.is_empty() || lp.bus.queued() > 0 {
            deadline = deadline.min(now.saturating_add(10_000));
        }
        // Wake at least every 100 ms to see `stop`.
        let timeout = Duration::from_micros(deadline.saturating_sub(now).min(100_000));
        let ready = match &commands {
            Some((_, calls)) => reactor.wait(&[&fd as &dyn Source, calls], Some(timeout))?,
            None => reactor.wait(&[&fd as &dyn Source], Some(timeout))?,
        };
        if ready.termination_requested() {
            break;
        }
        lp.read_bus()?;
        let updates = lp.core.signals().updates();
        if updates != published_updates {
            published_updates = updates;
            let msg = signals_msg(lp.core.signals(), lp.core.dbc());
            match signals.send(&msg) {
                // Latest-value service: nobody reading is not an error.
                Ok(_)
                | Err(
                    petrel_ipc::SendError::NoReceiver { .. }
                    | petrel_ipc::SendError::Refused { .. },
                ) => {}
                Err(e) => tracing::warn!("signals not published: {e}"),
            }
        }
        if let Some((_, calls)) = &commands {
            lp.take_calls(calls);
        }
        let now = lp.clock.now_us();
        let events = lp.core.on_time(now);
        lp.queue_events(events);
        if let Some(frame) = lp.core.poll_heartbeat(now) {
            if lp.bus.queued() > 0 {
                // The interface pushes back (or is off the bus): a heartbeat is a sign of
                // life now, not later; a burst of old ones after a recovery would lie.
                lp.report.heartbeats_skipped += 1;
                tracing::debug!("heartbeat skipped: frames wait for the interface");
            } else {
                lp.send(&frame, "heartbeat");
            }
        }
        if now >= next_poll {
            next_poll = now.saturating_add(state_poll);
            match lp.bus.state() {
                Ok(Some(state)) => {
                    let events = lp.core.on_bus_state(now, state);
                    if !events.is_empty() && state == BusState::BusOff {
                        lp.restart_if_asked();
                    }
                    lp.queue_events(events);
                }
                Ok(None) => {}
                Err(e) => {
                    tracing::debug!("bus state unknown: {e}");
                }
            }
            // A re-created interface comes with a new socket.
            if let Some(raw) = lp.bus.wait_fd() {
                if raw != fd_raw {
                    fd = FdSource::new(raw)?;
                    fd_raw = raw;
                }
            }
        }
        if let Err(e) = lp.bus.flush() {
            tracing::error!("frames waiting for `{}`: {e}", lp.bus.interface());
        }
        lp.deliver();
        let now = lp.clock.now_us();
        if now >= next_beat {
            next_beat = now.saturating_add(HEARTBEAT_PERIOD_US);
            let hb = petrel_ipc::Heartbeat {
                uptime_ms: t0.elapsed().as_millis() as u64,
                period_ms: (HEARTBEAT_PERIOD_US / 1000) as u32,
                progress: lp.core.counters().frames,
                status: lp.status_json(),
                ..petrel_ipc::Heartbeat::default()
            };
            // Latest-value service: a heartbeat nobody reads is not an error; any other
            // failure is said once, not at every period.
            match own_beat.send(&hb) {
                Ok(_)
                | Err(
                    petrel_ipc::SendError::NoReceiver { .. }
                    | petrel_ipc::SendError::Refused { .. },
                ) => {}
                Err(e) => {
                    heartbeats_refused += 1;
                    if heartbeats_refused == 1 {
                        tracing::error!("the data server's heartbeat could not be published: {e}");
                    }
                }
            }
        }
    }
    // Last chance for waiting events and frames.
    match lp.bus.flush() {
        Ok(0) => {}
        Ok(n) => {
            lp.report.frames_unsent = n;
            tracing::error!(
                "{n} frames still waited for `{}` when the bridge stopped: never sent",
                lp.bus.interface()
            );
        }
        Err(e) => {
            lp.report.frames_unsent = lp.bus.queued();
            tracing::error!("the last frames could not be sent: {e}");
        }
    }
    lp.deliver();
    // The commands program leaves in good order: the player records a stop, not a loss, when
    // its node goes (its leave is acknowledged with the events, below).
    let leave = commands.as_ref().and_then(|(prog, _)| say_leave(prog));
    if let Some((sender, seq)) = &leave {
        let heard =
            petrel_ipc::wait_acknowledged(&beats, sender.sender_id(), *seq, lp.opts.ack_grace);
        if !heard.settled(*seq) {
            tracing::warn!("the player did not acknowledge that the commands program leaves: it may record it as lost");
        }
    }
    if lp.last_seq > 0 {
        let heard = petrel_ipc::wait_acknowledged(
            &beats,
            lp.events.sender_id(),
            lp.last_seq,
            lp.opts.ack_grace,
        );
        lp.report.unacknowledged = !heard.is_safe(lp.last_seq);
        if lp.report.unacknowledged {
            tracing::warn!(
                "the player did not acknowledge the last events as on record within {:?}: they may be lost",
                lp.opts.ack_grace
            );
        }
    }
    if let Some(out) = &mut lp.opts.record {
        if let Err(e) = out.flush() {
            tracing::error!("the end of the bus recording could not be written: {e}");
        }
    }
    lp.report.counters = lp.core.counters();
    lp.report.bus = lp.bus.stats();
    lp.report.events_pending = lp.outbox.len();
    Ok(lp.report)
}
