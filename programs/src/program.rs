//! The connection of a program process to its vehicle: calls in, events out, an outbox for the
//! events no player is there to receive.

use std::io::Write;
use std::os::fd::AsRawFd;
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};

use petrel_ipc::liveness::list_nodes;
use petrel_ipc::port::EVENTS;
use petrel_ipc::reactor::Source;
use petrel_ipc::wire::{self, WireError};
use petrel_ipc::{
    CallMsg, CallReceiver, CallSender, EventMsg, EventSender, FdSource, NodeStatus, Participant,
    Reactor, RecvError, Role, SendError, SignalsMsg, SignalsSubscriber, Value, Vehicle,
    WaitStrategy,
};

use crate::call::{write_invocation, Call};
use crate::error::ProgramError;
use crate::outbox::{Outbox, Queued};

/// Default capacity of the outbox: events kept while no player receives them.
pub const DEFAULT_OUTBOX_CAPACITY: usize = 1024;

/// How long a [`Program`] dropped without [`close`](Program::close) waits at most for the
/// player to acknowledge that it leaves (a heartbeat or two, when the player is there).
pub const LEAVE_GRACE: Duration = Duration::from_secs(1);

/// Default period between two attempts to deliver queued events while waiting for calls.
pub const DEFAULT_RETRY_PERIOD: Duration = Duration::from_millis(20);

/// How a [`Program`] behaves. `ProgramConfig::default()` suits most programs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProgramConfig {
    /// Events kept while no player receives them (default 1024). Beyond it the oldest are
    /// dropped, counted and reported ([`ProgramError::EventsDropped`]). 0 keeps none.
    pub outbox_capacity: usize,
    /// How [`Program::recv`] waits for calls (default [`WaitStrategy::Block`]).
    pub wait: WaitStrategy,
    /// Report SIGINT and SIGTERM as [`ProgramError::Terminated`] instead of dying at once
    /// (default true). Seen in [`Program::recv`], whatever the wait strategy (a spinning wait
    /// polls for them).
    pub handle_signals: bool,
    /// While events are queued, how often [`Program::recv`] tries to deliver them (default
    /// 20 ms). A player that opens its call sender to this program is noticed at once.
    pub retry_period: Duration,
    /// When to check, before sending, that the player's process lives (default
    /// [`PlayerCheck::Always`]).
    pub player_check: PlayerCheck,
}

/// Whether [`Program`] checks that the player's process lives before it sends an event.
///
/// A player killed without warning (SIGKILL, a crash) leaves its receiving port behind until the
/// next player cleans it up at start: events sent in between would fill a buffer that nobody
/// reads, and be lost. The check lists the vehicle's nodes, which costs about 0.2 ms.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlayerCheck {
    /// Before every send: only an event sent in the instant between the check and the send can
    /// reach a player that just died. For programs that emit a few events a second.
    Always,
    /// Trust a check that found the player alive for this long: events sent within it after
    /// the player died are lost. For programs that emit at a high rate.
    Every(Duration),
    /// Never: an event is sent whenever a port receives. For receivers other than the player.
    Never,
}

impl Default for ProgramConfig {
    fn default() -> Self {
        ProgramConfig {
            outbox_capacity: DEFAULT_OUTBOX_CAPACITY,
            wait: WaitStrategy::Block,
            handle_signals: true,
            retry_period: DEFAULT_RETRY_PERIOD,
            player_check: PlayerCheck::Always,
        }
    }
}

/// What a [`Program`] did since it connected. Every emitted event is accounted for:
/// `emitted = delivered + dropped + queued` (plus events refused as unsendable, which
/// [`Program::emit`] reports and never counts as emitted).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ProgramStats {
    /// Calls received and decoded.
    pub calls: u64,
    /// Calls refused: undecodable, or of another wire version.
    pub bad_calls: u64,
    /// Events given to [`Program::emit`] or [`Program::emit_as`] and accepted.
    pub emitted: u64,
    /// Events handed to a player.
    pub delivered: u64,
    /// Of the delivered events, those that waited in the outbox first.
    pub delivered_late: u64,
    /// Events dropped from a full outbox: lost.
    pub dropped: u64,
    /// Events in the outbox now, waiting for a player.
    pub queued: usize,
    /// Times a player that had received events from this process was found gone (stopped,
    /// killed or not yet replaced).
    pub player_losses: u64,
    /// At [`Program::close`]: the player had not acknowledged the last events delivered as on
    /// its flight record (they may be lost), or its recorder lost some of this program's events.
    pub unacknowledged: bool,
}

/// One program name hosted by the process. Fields drop in order: the ports before the node.
#[derive(Debug)]
struct Hosted {
    calls: CallReceiver,
    /// Recreated for each player: a new player sees its sequence numbers start at 1.
    events: Option<EventSender>,
    /// The sequence number of the last event `events` delivered (0: none yet).
    last_seq: u64,
    name: String,
    participant: Participant,
}

/// A process playing one or several software programs of a vehicle.
///
/// It receives the calls the player addresses to each of its programs ([`recv`](Self::recv))
/// and answers with events ([`emit`](Self::emit), [`emit_as`](Self::emit_as)). It outlives the
/// player: events emitted while no player runs wait in a bounded outbox and are delivered, in
/// order, once a player is there again; the calls of a new player arrive like those of the old
/// one.
///
/// ```no_run
/// use petrel_programs::{Program, ProgramError, Value};
///
/// # fn main() -> Result<(), ProgramError> {
/// let mut program = Program::connect("redermor", "GUI")?;
/// loop {
///     match program.recv(None) {
///         Ok(Some(call)) if call.function == "climb" => {
///             let altitude = call.float(0)?;
///             program.emit("altitude_reached", vec![Value::Float(altitude)])?;
///         }
///         Ok(Some(call)) => eprintln!("{}", call.unknown_function()),
///         Ok(None) => {}
///         Err(e) if e.is_termination() || e.is_fatal() => break,
///         Err(e) => eprintln!("{e}"),
///     }
/// }
/// # Ok(())
/// # }
/// ```
///
/// Like the ports it holds, a `Program` is single-threaded: create it on the thread that uses it.
#[derive(Debug)]
pub struct Program {
    // Fields drop in order: these ports before the hosts' nodes.
    /// Senders to the programs this one calls, opened at the first call.
    callees: Vec<(String, CallSender)>,
    /// The CAN data server's signals, subscribed at the first read, and the newest seen.
    signals: Option<SignalsSubscriber>,
    latest_signals: Option<SignalsMsg>,
    hosts: Vec<Hosted>,
    reactor: Reactor,
    outbox: Outbox,
    config: ProgramConfig,
    vehicle: Vehicle,
    stats: ProgramStats,
    next_host: usize,
    next_retry: Instant,
    /// When a check last found the player alive.
    player_seen_alive: Option<Instant>,
    terminated: bool,
    closed: bool,
}

/// Makes iceoryx2 install its SIGINT/SIGTERM handlers now rather than at the reactor's first
/// sleep in [`Program::recv`], which may come late (a call already waiting is taken without
/// sleeping): until then a SIGTERM would kill the process on the spot, leaving its node behind.
/// The reactor sleeps once on a descriptor that is already readable, so it returns at once.
/// Returns whether a termination request was already pending.
fn install_signal_handlers(reactor: &Reactor) -> Result<bool, ProgramError> {
    let (mut writer, reader) = UnixStream::pair().map_err(ProgramError::Signals)?;
    writer.write_all(&[1]).map_err(ProgramError::Signals)?;
    let ready = FdSource::new(reader.as_raw_fd())?;
    let ready = reactor.wait(&[&ready], Some(Duration::from_secs(5)))?;
    Ok(ready.termination_requested())
}

/// The node name of the player (its [`Role::Player`]).
fn player_node_name() -> String {
    Role::Player.node_name()
}

impl Program {
    /// Joins vehicle `vehicle` (default file prefix, see [`Vehicle::new`]) as program `name`.
    pub fn connect(vehicle: &str, name: &str) -> Result<Self, ProgramError> {
        Self::connect_many(vehicle, &[name])
    }

    /// Joins vehicle `vehicle` as every program of `names`, in one process (the UAV simulator
    /// plays GUI and PLD). Each program is its own node, `program/NAME`, so the player sees each
    /// alive or lost; calls come tagged with the program they were addressed to, and
    /// [`emit`](Self::emit) sends as the first name.
    pub fn connect_many(vehicle: &str, names: &[&str]) -> Result<Self, ProgramError> {
        let vehicle = Vehicle::new(vehicle)?;
        Self::connect_with(&vehicle, names, ProgramConfig::default())
    }

    /// Joins `vehicle` (any file prefix) as every program of `names`, with `config`.
    pub fn connect_with(
        vehicle: &Vehicle,
        names: &[&str],
        config: ProgramConfig,
    ) -> Result<Self, ProgramError> {
        if names.is_empty() {
            return Err(ProgramError::NoProgram);
        }
        // Signals first: once a node of the program is alive, a supervisor (`petrel up`) takes
        // the program as started and may stop it at once; a SIGTERM must then reach a handler
        // (the program leaves in good order at its next `recv`), not the default action.
        let handle_signals = config.handle_signals;
        let mut reactor = if handle_signals {
            Reactor::new(WaitStrategy::Block)?
        } else {
            Reactor::without_signal_handling(WaitStrategy::Block)?
        };
        let terminated = handle_signals && install_signal_handlers(&reactor)?;
        reactor.set_strategy(config.wait);
        let mut hosts: Vec<Hosted> = Vec::with_capacity(names.len());
        for name in names {
            if hosts.iter().any(|h| h.name == *name) {
                return Err(ProgramError::DuplicateProgram((*name).to_owned()));
            }
            let setup = |error| ProgramError::Setup {
                program: (*name).to_owned(),
                error: Box::new(error),
            };
            let participant = Participant::join(vehicle, Role::program(name)?).map_err(setup)?;
            let calls = participant.call_receiver().map_err(setup)?;
            if config.wait != WaitStrategy::Block {
                // Spinning, calls are seen in shared memory: their notifications are consumed
                // now and then, not at every call.
                calls.consume_wakeups_every(Some(petrel_ipc::SPIN_WAKEUP_PERIOD));
            }
            let events = participant.event_sender_sized().map_err(setup)?;
            hosts.push(Hosted {
                calls,
                events: Some(events),
                last_seq: 0,
                name: (*name).to_owned(),
                participant,
            });
        }
        Ok(Program {
            hosts,
            reactor,
            outbox: Outbox::new(config.outbox_capacity),
            config,
            vehicle: vehicle.clone(),
            stats: ProgramStats::default(),
            next_host: 0,
            next_retry: Instant::now(),
            player_seen_alive: None,
            terminated,
            closed: false,
            callees: Vec::new(),
            signals: None,
            latest_signals: None,
        })
    }

    /// The vehicle joined.
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The programs this process plays, in the order given to connect.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.hosts.iter().map(|h| h.name.as_str())
    }

    /// The configuration.
    pub fn config(&self) -> &ProgramConfig {
        &self.config
    }

    /// The participant (iceoryx2 node) of program `name`, for what this crate does not wrap.
    pub fn participant(&self, name: &str) -> Option<&Participant> {
        self.hosts
            .iter()
            .find(|h| h.name == name)
            .map(|h| &h.participant)
    }

    /// What the program did so far.
    pub fn stats(&self) -> ProgramStats {
        ProgramStats {
            queued: self.outbox.len(),
            ..self.stats
        }
    }

    /// Events waiting in the outbox for a player.
    pub fn queued(&self) -> usize {
        self.outbox.len()
    }

    /// Whether SIGINT or SIGTERM was received.
    pub fn terminated(&self) -> bool {
        self.terminated
    }

    /// Waits for the next call to any hosted program, up to `timeout` (`None`: no limit), and
    /// returns it, or `Ok(None)` when the timeout passed.
    ///
    /// While it waits it delivers queued events as soon as a player is there again. A call that
    /// cannot be decoded is skipped and reported as [`ProgramError::BadCall`]: log it and call
    /// `recv` again. Once SIGINT or SIGTERM was received, it returns
    /// [`ProgramError::Terminated`] (every time).
    ///
    /// Each call is a new [`Call`] (its names and arguments allocated); a program that answers
    /// calls at a high rate and minds its latency receives them with
    /// [`recv_into`](Self::recv_into) instead, into one `Call` it keeps.
    pub fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Call>, ProgramError> {
        let mut call = Call::default();
        Ok(self.recv_into(&mut call, timeout)?.then_some(call))
    }

    /// [`recv`](Self::recv) into `call`, reusing its buffers: `Ok(true)` when a call arrived
    /// (written into `call`), `Ok(false)` when the timeout passed, and `recv`'s errors.
    ///
    /// `call`'s program name, function name and argument list keep their capacity, and an
    /// argument that is a text or a list of floats where the previous call had one in the same
    /// position reuses its buffer: once `call` has held a call of each kind the program gets, a
    /// call costs no allocation. Everything else is `recv`'s, to the error. `call` is left as
    /// it was by `Ok(false)` and by every error but [`ProgramError::BadCall`] for an undecodable
    /// call, after which it holds valid values but not a call.
    ///
    /// ```no_run
    /// use petrel_programs::{Call, Program, ProgramError, Value};
    ///
    /// # fn main() -> Result<(), ProgramError> {
    /// let mut program = Program::connect("redermor", "NAV")?;
    /// let mut call = Call::default();
    /// loop {
    ///     match program.recv_into(&mut call, None) {
    ///         Ok(true) if call.function == "track" => {
    ///             let position = call.floats(0)?;
    ///             program.emit("tracked", vec![Value::Float(position[0])])?;
    ///         }
    ///         Ok(true) => eprintln!("{}", call.unknown_function()),
    ///         Ok(false) => {}
    ///         Err(e) if e.is_termination() || e.is_fatal() => break,
    ///         Err(e) => eprintln!("{e}"),
    ///     }
    /// }
    /// # Ok(())
    /// # }
    /// ```
    pub fn recv_into(
        &mut self,
        call: &mut Call,
        timeout: Option<Duration>,
    ) -> Result<bool, ProgramError> {
        if self.terminated {
            return Err(ProgramError::Terminated);
        }
        // The deadline counts from the first look that found no call: a call already there
        // is taken without reading the clock, and a wait reads it once.
        let mut from_first_look: Option<Option<Instant>> = None;
        loop {
            if self.try_take_into(call)? {
                return Ok(true);
            }
            let mut now = Instant::now();
            let deadline = *from_first_look.get_or_insert_with(|| timeout.map(|t| now + t));
            if !self.outbox.is_empty() && now >= self.next_retry {
                self.next_retry = now + self.config.retry_period;
                self.flush()?;
                now = Instant::now();
            }
            let mut wait = match deadline {
                Some(d) if now >= d => return Ok(false),
                Some(d) => Some(d - now),
                None => None,
            };
            if !self.outbox.is_empty() {
                let retry = self.next_retry.saturating_duration_since(now);
                wait = Some(wait.map_or(retry, |w| w.min(retry)));
            }
            // One hosted program (the usual case) waits without collecting its sources.
            let ready = match &self.hosts[..] {
                [host] => self.reactor.wait(&[&host.calls as &dyn Source], wait)?,
                hosts => {
                    let sources: Vec<&dyn Source> =
                        hosts.iter().map(|h| &h.calls as &dyn Source).collect();
                    self.reactor.wait(&sources, wait)?
                }
            };
            if ready.termination_requested() {
                self.terminated = true;
                return Err(ProgramError::Terminated);
            }
            // A player that (re)opens its call sender, or whose death was cleaned up, is news:
            // try the outbox at once.
            for host in &self.hosts {
                let news = host
                    .calls
                    .take_wakeups()
                    .map_err(|error| ProgramError::BadCall {
                        program: host.name.clone(),
                        error: Box::new(error),
                    })?;
                if news.senders_joined + news.senders_left + news.senders_died > 0 {
                    self.next_retry = Instant::now();
                    self.player_seen_alive = None;
                }
            }
        }
    }

    /// Takes a waiting call into `call` without waiting, the hosted programs in turn.
    fn try_take_into(&mut self, call: &mut Call) -> Result<bool, ProgramError> {
        let n = self.hosts.len();
        for k in 0..n {
            let i = (self.next_host + k) % n;
            let host = &self.hosts[i];
            match host.calls.try_recv_into(&mut call.function, &mut call.args) {
                Ok(Some(_)) => {
                    self.next_host = (i + 1) % n;
                    self.stats.calls += 1;
                    call.program.clear();
                    call.program.push_str(&host.name);
                    return Ok(true);
                }
                Ok(None) => {}
                Err(error) => {
                    self.next_host = (i + 1) % n;
                    if matches!(
                        error,
                        RecvError::Undecodable { .. } | RecvError::Foreign { .. }
                    ) {
                        self.stats.bad_calls += 1;
                    }
                    return Err(ProgramError::BadCall {
                        program: host.name.clone(),
                        error: Box::new(error),
                    });
                }
            }
        }
        Ok(false)
    }

    /// Calls `program.function(args)`, as a net's `call` does: the CAN data server's
    /// commands (`program.call("CAN", "ThrusterCmd", ...)`, encoded with the DBC and sent on
    /// the bus), or any other program. Sent as the first hosted program.
    ///
    /// `Ok(())` once the program's process has it. A call is not queued: when no process plays
    /// `program` (or its buffer is full) it is refused with
    /// [`ProgramError::CallUndelivered`], because a command sent late may be worse than none;
    /// the caller decides whether to try again. Whether the program could carry the call out
    /// (a command out of the DBC's range, say) is the program's to report.
    pub fn call(
        &mut self,
        program: &str,
        function: &str,
        args: Vec<Value>,
    ) -> Result<(), ProgramError> {
        let index = match self.callees.iter().position(|(p, _)| p == program) {
            Some(i) => i,
            None => {
                let host = &self.hosts[0];
                let sender =
                    host.participant
                        .call_sender(program)
                        .map_err(|error| ProgramError::Setup {
                            program: host.name.clone(),
                            error: Box::new(error),
                        })?;
                self.callees.push((program.to_owned(), sender));
                self.callees.len() - 1
            }
        };
        let msg = CallMsg::new(function, args);
        self.callees[index]
            .1
            .send(&msg)
            .map(|_| ())
            .map_err(|error| ProgramError::CallUndelivered {
                program: program.to_owned(),
                function: function.to_owned(),
                error: Box::new(error),
            })
    }

    /// The newest decoded CAN signals the data server published (`MESSAGE.signal` to physical
    /// value, [`SignalsMsg::get`]), or `None` while none came. Subscribes at the first call:
    /// the server publishes after every batch of frames it reads, so the first values come with
    /// its next batch (within a frame period); call it once early to have them when needed.
    pub fn signals(&mut self) -> Result<Option<&SignalsMsg>, ProgramError> {
        if self.signals.is_none() {
            let host = &self.hosts[0];
            let sub =
                host.participant
                    .signals_subscriber()
                    .map_err(|error| ProgramError::Setup {
                        program: host.name.clone(),
                        error: Box::new(error),
                    })?;
            self.signals = Some(sub);
        }
        if let Some(sub) = &self.signals {
            let mut newest = None;
            let mut failed = None;
            sub.drain(|r| match r {
                Ok(r) => newest = Some(r.msg),
                Err(e) => failed = Some(e),
            })
            .map_err(|e| ProgramError::BadSignals(Box::new(e)))?;
            if let Some(msg) = newest {
                self.latest_signals = Some(msg);
            }
            if let Some(e) = failed {
                return Err(ProgramError::BadSignals(Box::new(e)));
            }
        }
        Ok(self.latest_signals.as_ref())
    }

    /// Emits event `name(params)` to the player, as the first hosted program.
    ///
    /// `Ok(())` when the player received it or, if no player receives events now, when it was
    /// queued in the outbox to be delivered, in order, once one does. When the outbox was full
    /// the oldest queued event was dropped to make room: the new one is queued all the same
    /// and [`ProgramError::EventsDropped`] reports the loss. An event that can never be sent
    /// (too large) is refused with [`ProgramError::Unsendable`] and not queued.
    pub fn emit(
        &mut self,
        name: impl Into<String>,
        params: Vec<Value>,
    ) -> Result<(), ProgramError> {
        self.emit_from(0, EventMsg::new(name, params))
    }

    /// Emits event `name(params)` as hosted program `program` (the player sees it as the
    /// event's origin); otherwise like [`emit`](Self::emit).
    pub fn emit_as(
        &mut self,
        program: &str,
        name: impl Into<String>,
        params: Vec<Value>,
    ) -> Result<(), ProgramError> {
        let host = self
            .hosts
            .iter()
            .position(|h| h.name == program)
            .ok_or_else(|| ProgramError::UnknownProgram {
                program: program.to_owned(),
                hosted: self.hosts.iter().map(|h| h.name.clone()).collect(),
            })?;
        self.emit_from(host, EventMsg::new(name, params))
    }

    fn emit_from(&mut self, host: usize, msg: EventMsg) -> Result<(), ProgramError> {
        let unsendable = |error| ProgramError::Unsendable {
            event: msg.name.clone(),
            error,
        };
        // Measured once: the send below encodes into exactly this many bytes.
        let len = match wire::encoded_len(&msg) {
            Ok(len) if len <= EVENTS.max_body_len => len,
            Ok(len) => {
                return Err(unsendable(WireError::TooLarge {
                    len,
                    max: EVENTS.max_body_len,
                }))
            }
            Err(error) => return Err(unsendable(error)),
        };
        self.stats.emitted += 1;
        let ready = match self.player_ready() {
            Ok(ready) => ready,
            Err(e) => {
                // Keep the event; report the loss of an older one first, if any.
                return Err(self.enqueue(host, msg, len).err().unwrap_or(e));
            }
        };
        if !ready {
            self.player_gone();
            return self.enqueue(host, msg, len);
        }
        if let Err(e) = self.deliver_queued() {
            return Err(self.enqueue(host, msg, len).err().unwrap_or(e));
        }
        if self.outbox.is_empty() {
            match self.send_now(host, &msg, len) {
                Ok(true) => {
                    self.stats.delivered += 1;
                    return Ok(());
                }
                Ok(false) => {}
                Err(e) => {
                    self.stats.emitted -= 1;
                    return Err(e);
                }
            }
        }
        self.enqueue(host, msg, len)
    }

    fn enqueue(&mut self, host: usize, msg: EventMsg, len: usize) -> Result<(), ProgramError> {
        match self.outbox.push(Queued { host, msg, len }) {
            None => Ok(()),
            Some(dropped) => {
                self.stats.dropped += 1;
                Err(ProgramError::EventsDropped {
                    events: vec![dropped.msg.name],
                    total: self.stats.dropped,
                    capacity: self.outbox.capacity(),
                })
            }
        }
    }

    /// Tries to deliver the queued events now, in order; returns how many were delivered. Does
    /// nothing while no player receives. [`recv`](Self::recv) calls it while it waits.
    pub fn flush(&mut self) -> Result<usize, ProgramError> {
        if self.outbox.is_empty() {
            return Ok(0);
        }
        if !self.player_ready()? {
            self.player_gone();
            return Ok(0);
        }
        self.deliver_queued()
    }

    /// Tries to deliver the queued events for up to `timeout` (sleeping between attempts,
    /// without receiving calls); returns the number of events still queued, 0 when all were
    /// delivered. For the end of a program: see [`close`](Self::close).
    pub fn flush_for(&mut self, timeout: Duration) -> Result<usize, ProgramError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.flush()?;
            let now = Instant::now();
            if self.outbox.is_empty() || now >= deadline {
                return Ok(self.outbox.len());
            }
            std::thread::sleep(self.config.retry_period.min(deadline - now));
        }
    }

    /// Ends the program: tries for up to `grace` to deliver the queued events, says to the
    /// player that each hosted program leaves in good order (so that its going is recorded as
    /// a stop, not as `program_lost`: [`LEAVE`](petrel_ipc::wire::LEAVE)), waits (within
    /// `grace`, and at least the 250 ms of the player's next heartbeat) for the player to
    /// acknowledge the last message delivered, since shared memory goes with its process, then
    /// leaves the vehicle. The returned statistics tell what happened to every event; `queued`
    /// counts those that were never delivered (their names are written to standard error),
    /// `unacknowledged` whether the last delivered ones may be lost.
    ///
    /// A `Program` dropped without `close` (but not while its thread panics) says it leaves
    /// too, and waits up to [`LEAVE_GRACE`] for the player to acknowledge it (a sample whose
    /// sender goes before the player connected to it is lost with it).
    pub fn close(mut self, grace: Duration) -> Result<ProgramStats, ProgramError> {
        let deadline = Instant::now() + grace;
        let flushed = self.flush_for(grace);
        self.say_leave();
        self.stats.unacknowledged = !self.wait_acknowledged(deadline);
        let stats = self.stats();
        if !self.outbox.is_empty() {
            self.report_undelivered();
        }
        if stats.unacknowledged {
            eprintln!(
                "petrel-programs: the player did not acknowledge the last events of {} before it left: they may be lost",
                self.names().collect::<Vec<_>>().join(", ")
            );
        }
        self.closed = true;
        flushed.map(|_| stats)
    }

    /// Waits up to `timeout` (250 ms at least) for the player to acknowledge every event
    /// delivered so far, without leaving: true when all are on its record. For a program that
    /// must know its events are safe before it goes on, or before it ends abruptly (a
    /// simulated crash ends without [`close`](Self::close), so that the player reports
    /// `program_lost` rather than a stop).
    pub fn acknowledged_within(&mut self, timeout: Duration) -> Result<bool, ProgramError> {
        let deadline = Instant::now() + timeout;
        if self.flush_for(timeout)? > 0 {
            return Ok(false);
        }
        Ok(self.wait_acknowledged(deadline))
    }

    /// Whether the player acknowledged every host's last delivered event by `deadline` (250 ms
    /// at least from now).
    fn wait_acknowledged(&self, deadline: Instant) -> bool {
        let pending: Vec<(u64, u64)> = self
            .hosts
            .iter()
            .filter_map(|h| {
                let sender = h.events.as_ref()?;
                (h.last_seq > 0).then(|| (sender.sender_id(), h.last_seq))
            })
            .collect();
        if pending.is_empty() {
            return true;
        }
        let Ok(beats) = self.hosts[0].participant.heartbeat_subscriber() else {
            return false;
        };
        let floor = Instant::now() + Duration::from_millis(250);
        pending.iter().all(|(sender, seq)| {
            let left = deadline
                .max(floor)
                .saturating_duration_since(Instant::now());
            petrel_ipc::wait_acknowledged(&beats, *sender, *seq, left).is_safe(*seq)
        })
    }

    /// Tells the player, from each hosted program's sender, that the program leaves in good
    /// order (nothing to tell when no player receives).
    fn say_leave(&mut self) {
        if !matches!(self.player_ready(), Ok(true)) {
            return;
        }
        let leave = EventMsg::leave();
        let Ok(len) = wire::encoded_len(&leave) else {
            return;
        };
        for host in 0..self.hosts.len() {
            // Not delivered (a full buffer): the player will take the going for a loss.
            let _ = self.send_now(host, &leave, len);
        }
    }

    fn report_undelivered(&self) {
        let names: Vec<&str> = self.outbox.names().collect();
        eprintln!(
            "petrel-programs: {} left the vehicle with {} event(s) never delivered (no player received them): {}",
            self.hosts
                .iter()
                .map(|h| h.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            names.len(),
            names.join(", ")
        );
    }

    /// Sends the queued events while the player takes them. The player is known to be ready.
    fn deliver_queued(&mut self) -> Result<usize, ProgramError> {
        let mut delivered = 0;
        while let Some(item) = self.outbox.pop_front() {
            match self.send_now(item.host, &item.msg, item.len) {
                Ok(true) => {
                    delivered += 1;
                    self.stats.delivered += 1;
                    self.stats.delivered_late += 1;
                }
                Ok(false) => {
                    self.outbox.restore_front(item);
                    break;
                }
                Err(e) => {
                    // Cannot happen for an event checked before it was queued; it is lost.
                    self.stats.dropped += 1;
                    return Err(e);
                }
            }
        }
        Ok(delivered)
    }

    /// Sends `msg`, whose encoded length is `len`, as `host`: `Ok(true)` when the player got
    /// it, `Ok(false)` when it should be tried again later.
    fn send_now(&mut self, host: usize, msg: &EventMsg, len: usize) -> Result<bool, ProgramError> {
        let Some(sender) = self.hosts[host].events.as_ref() else {
            return Ok(false);
        };
        match sender.send_measured(msg, len) {
            Ok(sent) => {
                self.hosts[host].last_seq = sent.seq;
                Ok(true)
            }
            Err(SendError::NoReceiver { .. }) => {
                self.player_gone();
                Ok(false)
            }
            Err(error @ SendError::Wire { .. }) => Err(ProgramError::Send {
                event: msg.name.clone(),
                error: Box::new(error),
            }),
            // The player's buffer is full, shared memory ran short, or the transport failed:
            // the player is there, try again later.
            Err(_) => Ok(false),
        }
    }

    /// Whether a live player receives events: someone receives on the events service and
    /// (unless [`PlayerCheck::Never`]) the vehicle has a live player node and no dead one whose
    /// port may still be what receives.
    pub fn player_present(&mut self) -> Result<bool, ProgramError> {
        self.player_ready()
    }

    fn player_ready(&mut self) -> Result<bool, ProgramError> {
        for host in &mut self.hosts {
            if host.events.is_none() {
                let sender =
                    host.participant
                        .event_sender_sized()
                        .map_err(|error| ProgramError::Setup {
                            program: host.name.clone(),
                            error: Box::new(error),
                        })?;
                host.events = Some(sender);
                host.last_seq = 0;
            }
        }
        let receivers = self.hosts[0].events.as_ref().map_or(0, |s| s.receivers());
        if receivers == 0 {
            self.player_seen_alive = None;
            return Ok(false);
        }
        match (self.config.player_check, self.player_seen_alive) {
            (PlayerCheck::Never, _) => return Ok(true),
            (PlayerCheck::Every(period), Some(seen)) if seen.elapsed() < period => return Ok(true),
            _ => {}
        }
        self.player_seen_alive = None;
        let player = player_node_name();
        let mut alive = false;
        for node in list_nodes(&self.vehicle)?
            .iter()
            .filter(|n| n.name == player)
        {
            match node.status {
                NodeStatus::Alive => alive = true,
                // A dead player's port still counts as a receiver until the next player cleans
                // it up: wait for that.
                NodeStatus::Dead | NodeStatus::Undefined | NodeStatus::Inaccessible => {
                    return Ok(false)
                }
            }
        }
        if alive {
            self.player_seen_alive = Some(Instant::now());
        }
        Ok(alive)
    }

    /// The player is gone: senders that sent to it are recreated for the next player, whose
    /// account of this process then starts afresh (sequence numbers from 1, no false gap).
    fn player_gone(&mut self) {
        self.player_seen_alive = None;
        let mut recycled = false;
        for host in &mut self.hosts {
            if host.events.as_ref().is_some_and(|s| s.stats().sent > 0) {
                host.events = None;
                recycled = true;
            }
        }
        if recycled {
            self.stats.player_losses += 1;
        }
    }
}

impl Drop for Program {
    fn drop(&mut self) {
        if self.closed {
            return;
        }
        if !self.outbox.is_empty() {
            self.report_undelivered();
        }
        // A program dropped in good order says so; one whose thread panics dies.
        if !std::thread::panicking() {
            self.say_leave();
            self.wait_acknowledged(Instant::now() + LEAVE_GRACE);
        }
    }
}

/// `name(v1, v2)`, as logs show an event.
pub fn event_text(name: &str, params: &[Value]) -> String {
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = write_invocation(&mut s, name, params);
    s
}
