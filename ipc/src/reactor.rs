//! Waiting for something to do: a small reactor around iceoryx2's `WaitSet`, with the wait
//! strategy chosen per process.
//!
//! Measured on the project's machines (2 vCPUs, `examples/latency.rs`, call then event between
//! two processes, 58-byte body): spinning answers in about 2.3 µs at the median, blocking in
//! 17 µs when the two processes talk back to back and 25 to 40 µs when the CPUs idle between
//! rounds, because waking an idle vCPU dominates. Spinning costs a whole core per process and
//! collapses (p90 of milliseconds) as soon as two spinners share a core, so a whole vehicle
//! cannot spin: each process chooses its [`WaitStrategy`].
//!
//! The reactor watches [`Source`]s: every [`Receiver`] is one (its shared-memory buffer can be
//! polled without a system call, and its listener wakes a `WaitSet`), and [`FdSource`] wraps
//! any other file descriptor, such as a CAN socket.

use std::cell::Cell;
use std::fmt;
use std::os::fd::RawFd;
use std::time::{Duration, Instant};

use iceoryx2::prelude::{
    ipc, CallbackProgression, FileDescriptor, FileDescriptorBased, SignalHandlingMode,
    SynchronousMultiplexing, WaitSet, WaitSetBuilder,
};
use iceoryx2::waitset::{
    WaitSetAttachmentError, WaitSetCreateError, WaitSetRunError, WaitSetRunResult,
};
use iceoryx2_bb_posix::signal::SignalHandler;

use crate::port::Receiver;
use crate::wire::Message;

/// How a process waits for work.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitStrategy {
    /// Sleep in the kernel until a source is signalled (about 55 µs to wake; no CPU used).
    Block,
    /// Poll the sources' shared memory in a loop (about 1 µs to react; one core busy and kept:
    /// give a spinning process a core of its own, a peer that shares its core waits for the
    /// scheduler to preempt it).
    Spin,
    /// Poll for this long, then sleep: fast answers to a quick exchange, no core burnt when idle.
    /// While it polls it offers the core to other runnable threads every microsecond or so,
    /// so that a peer sharing the core can answer within the window.
    ///
    /// Spin longer than the peer takes to wake up (100 µs or more here): with a shorter window
    /// two processes that talk back and forth both fall asleep before the answer comes, and
    /// every round trip pays two wake-ups (about 60 µs, worse than [`Block`](Self::Block)).
    SpinThenBlock(Duration),
}

impl std::str::FromStr for WaitStrategy {
    type Err = String;

    /// `block`, `spin`, or `spin-then-block:<micros>`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "block" => Ok(WaitStrategy::Block),
            "spin" => Ok(WaitStrategy::Spin),
            _ => s
                .strip_prefix("spin-then-block:")
                .and_then(|us| us.parse::<u64>().ok())
                .map(|us| WaitStrategy::SpinThenBlock(Duration::from_micros(us)))
                .ok_or_else(|| {
                    format!(
                        "unknown wait strategy `{s}`; use block, spin or spin-then-block:<micros>"
                    )
                }),
        }
    }
}

impl fmt::Display for WaitStrategy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WaitStrategy::Block => f.write_str("block"),
            WaitStrategy::Spin => f.write_str("spin"),
            WaitStrategy::SpinThenBlock(d) => write!(f, "spin-then-block:{}", d.as_micros()),
        }
    }
}

/// Something a `WaitSet` can wait on: file-descriptor based and printable.
pub trait Waitable: SynchronousMultiplexing + fmt::Debug {}
impl<T: SynchronousMultiplexing + fmt::Debug + ?Sized> Waitable for T {}

/// Something the [`Reactor`] watches.
pub trait Source {
    /// Whether work is waiting, found without a system call; `None` when only the file
    /// descriptor can tell.
    fn pending(&self) -> Option<bool>;

    /// What the `WaitSet` waits on.
    fn waitable(&self) -> &dyn Waitable;

    /// Called when the `WaitSet` reported the source signalled, to consume the wake-up (a
    /// `WaitSet` wakes again at once on a wake-up left unconsumed). Returns whether the caller
    /// has something to do. Receivers consume their notifications, keep them for
    /// [`Receiver::take_wakeups`], and report work when samples wait or a sender joined, left or
    /// died; a raw file descriptor reports work and the caller reads it.
    fn signalled(&self) -> bool {
        true
    }
}

impl<M: Message> Source for Receiver<M> {
    fn pending(&self) -> Option<bool> {
        Some(self.has_pending())
    }

    fn waitable(&self) -> &dyn Waitable {
        self.listener()
    }

    fn signalled(&self) -> bool {
        // An error here shows again at the caller's next take_wakeups or drain: report work so
        // that the caller gets to see it.
        match self.consume_notifications() {
            Ok(()) => self.has_pending() || self.has_sender_news(),
            Err(_) => true,
        }
    }
}

/// Any file descriptor (a CAN socket, a timerfd...) as a [`Source`]. It does not own the
/// descriptor: keep it open while it is watched.
#[derive(Debug)]
pub struct FdSource {
    fd: FileDescriptor,
}

impl FdSource {
    /// Watches `fd`.
    pub fn new(fd: RawFd) -> Result<Self, ReactorError> {
        FileDescriptor::non_owning_new(fd)
            .map(|fd| FdSource { fd })
            .ok_or(ReactorError::InvalidFd(fd))
    }
}

impl FileDescriptorBased for FdSource {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.fd
    }
}

impl SynchronousMultiplexing for FdSource {}

impl Source for FdSource {
    fn pending(&self) -> Option<bool> {
        None
    }

    fn waitable(&self) -> &dyn Waitable {
        self
    }
}

/// The reactor failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReactorError {
    /// The `WaitSet` could not be created.
    Create(WaitSetCreateError),
    /// A source could not be attached to the `WaitSet`.
    Attach {
        /// Index of the source in the slice given to [`Reactor::wait`].
        source: usize,
        /// iceoryx2's reason.
        error: WaitSetAttachmentError,
    },
    /// Waiting failed.
    Wait(WaitSetRunError),
    /// No source and no timeout: the wait would never end.
    NothingToWaitFor,
    /// More sources than [`MAX_SOURCES`].
    TooManySources(usize),
    /// Not an open file descriptor.
    InvalidFd(RawFd),
}

impl fmt::Display for ReactorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReactorError::Create(e) => write!(f, "cannot create the wait set: {e}"),
            ReactorError::Attach { source, error } => {
                write!(f, "cannot watch source {source}: {error}")
            }
            ReactorError::Wait(e) => write!(f, "waiting failed: {e}"),
            ReactorError::NothingToWaitFor => {
                f.write_str("waiting on no source without a timeout would never end")
            }
            ReactorError::TooManySources(n) => {
                write!(
                    f,
                    "{n} sources given; a reactor watches at most {MAX_SOURCES}"
                )
            }
            ReactorError::InvalidFd(fd) => write!(f, "{fd} is not an open file descriptor"),
        }
    }
}

impl std::error::Error for ReactorError {}

/// Most sources one [`Reactor::wait`] watches.
pub const MAX_SOURCES: usize = 64;

/// While spinning, how often file descriptors without a shared-memory check are polled.
const FD_POLL_PERIOD: Duration = Duration::from_micros(500);

/// Under `spin-then-block`, while spinning, the CPU is offered to other runnable threads
/// (`sched_yield`) every this many polls (a power of two: about a microsecond of polling).
///
/// Without it, a spinner that shares its core with the very process it waits for (two cores,
/// more runnable processes than cores) holds the core for its whole spin window while the peer
/// cannot run to answer: `spin-then-block:200` paid one or two 200 µs windows per round trip
/// (p50 450 µs on the loaded machine, 462 µs with both processes on one core; 22 µs with the
/// yield). Yielding only after some spinning costs the peer that long (after 20 µs: p50 67 µs,
/// after 50 µs: 122 µs, docs/benchmarks.md).
///
/// `spin` does not yield: on a loaded machine each `sched_yield` hands the core to another
/// process for a while, which doubled spin's p50 (10-13 µs without, 22-25 µs with, same runs),
/// and a spinning process is meant to have its core.
const YIELD_EVERY: u32 = 16;

/// What a [`Reactor`] did since it was built: how its waits ended.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReactorStats {
    /// Calls to [`Reactor::wait`].
    pub waits: u64,
    /// Waits that went to sleep in the `WaitSet`: under `spin-then-block`, those whose spin
    /// window ended with nothing to do.
    pub sleeps: u64,
    /// Times a spinning wait offered the CPU to another thread.
    pub yields: u64,
}

/// Which sources are ready after a [`Reactor::wait`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ready {
    mask: u64,
    timed_out: bool,
    termination_requested: bool,
}

impl Ready {
    /// Whether source `index` (in the slice given to `wait`) has work.
    pub fn is_ready(&self, index: usize) -> bool {
        index < MAX_SOURCES && self.mask & (1 << index) != 0
    }

    /// Whether any source has work.
    pub fn any(&self) -> bool {
        self.mask != 0
    }

    /// The indices of the sources with work.
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        (0..MAX_SOURCES).filter(|i| self.is_ready(*i))
    }

    /// The timeout passed with no source ready.
    pub fn timed_out(&self) -> bool {
        self.timed_out
    }

    /// SIGINT or SIGTERM was received (only with signal handling on): time to stop.
    pub fn termination_requested(&self) -> bool {
        self.termination_requested
    }
}

/// Waits on several sources with a [`WaitStrategy`].
///
/// Each [`wait`](Self::wait) attaches the sources to the `WaitSet` only if it has to sleep (two
/// `epoll_ctl` calls per source, small beside a wake-up), so the sources stay free for the
/// caller between waits.
#[derive(Debug)]
pub struct Reactor {
    waitset: WaitSet<ipc::Service>,
    strategy: WaitStrategy,
    /// SIGINT and SIGTERM are caught and reported (not left their default action).
    handles_signals: bool,
    stats: Cell<ReactorStats>,
}

impl Reactor {
    /// A reactor that reports SIGINT and SIGTERM as [`Ready::termination_requested`], whatever
    /// its strategy: iceoryx2 installs its handlers at the first wait (a sleeping wait's, or
    /// a spinning wait's first poll for them), and a spinning wait polls them.
    pub fn new(strategy: WaitStrategy) -> Result<Self, ReactorError> {
        Self::build(strategy, SignalHandlingMode::HandleTerminationRequests)
    }

    /// A reactor that leaves signals alone.
    pub fn without_signal_handling(strategy: WaitStrategy) -> Result<Self, ReactorError> {
        Self::build(strategy, SignalHandlingMode::Disabled)
    }

    fn build(strategy: WaitStrategy, mode: SignalHandlingMode) -> Result<Self, ReactorError> {
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(mode)
            .create::<ipc::Service>()
            .map_err(ReactorError::Create)?;
        // iceoryx2 installs its SIGINT/SIGTERM handlers at the first look for a termination
        // request: the WaitSet's first sleep, or (below) a spinning wait's first poll, which a
        // spinning reactor needs since it may never sleep. Not earlier: a process that only
        // blocks keeps exactly iceoryx2's own timing of the install.
        let handles_signals = mode == SignalHandlingMode::HandleTerminationRequests;
        Ok(Reactor {
            waitset,
            strategy,
            handles_signals,
            stats: Cell::new(ReactorStats::default()),
        })
    }

    /// The strategy.
    pub fn strategy(&self) -> WaitStrategy {
        self.strategy
    }

    /// How the waits ended so far.
    pub fn stats(&self) -> ReactorStats {
        self.stats.get()
    }

    fn count(&self, f: impl FnOnce(&mut ReactorStats)) {
        let mut stats = self.stats.get();
        f(&mut stats);
        self.stats.set(stats);
    }

    /// Changes the strategy (for instance spin during a manoeuvre, block when idle).
    pub fn set_strategy(&mut self, strategy: WaitStrategy) {
        self.strategy = strategy;
    }

    /// Waits until a source has work or `timeout` has passed (`None`: no timeout).
    ///
    /// Sources with work already waiting are reported at once. A receiver reported ready may
    /// turn out empty (a wake-up for samples already taken): draining it is harmless.
    pub fn wait(
        &self,
        sources: &[&dyn Source],
        timeout: Option<Duration>,
    ) -> Result<Ready, ReactorError> {
        if sources.len() > MAX_SOURCES {
            return Err(ReactorError::TooManySources(sources.len()));
        }
        let start = Instant::now();
        let deadline = timeout.map(|t| start + t);
        self.count(|s| s.waits += 1);
        if sources.is_empty() {
            // A WaitSet refuses to wait on nothing: this is only a timer.
            let timeout = timeout.ok_or(ReactorError::NothingToWaitFor)?;
            let spin = match self.strategy {
                WaitStrategy::Block => Duration::ZERO,
                WaitStrategy::Spin => timeout,
                WaitStrategy::SpinThenBlock(spin) => spin.min(timeout),
            };
            let yields = matches!(self.strategy, WaitStrategy::SpinThenBlock(_));
            while start.elapsed() < spin {
                if self.handles_signals && SignalHandler::termination_requested() {
                    return Ok(Ready {
                        termination_requested: true,
                        ..Ready::default()
                    });
                }
                if yields {
                    // No peer to starve, but other processes may want the core.
                    self.count(|s| s.yields += 1);
                    std::thread::yield_now();
                } else {
                    std::hint::spin_loop();
                }
            }
            std::thread::sleep(timeout.saturating_sub(start.elapsed()));
            return Ok(Ready {
                timed_out: true,
                ..Ready::default()
            });
        }
        let ready = poll_pending(sources);
        if ready != 0 {
            return Ok(Ready {
                mask: ready,
                ..Ready::default()
            });
        }
        match self.strategy {
            WaitStrategy::Block => self.block(sources, deadline),
            WaitStrategy::Spin => match self.spin(sources, deadline)? {
                Some(ready) => Ok(ready),
                None => Ok(Ready {
                    timed_out: true,
                    ..Ready::default()
                }),
            },
            WaitStrategy::SpinThenBlock(spin) => {
                let spin_until = match deadline {
                    Some(d) => d.min(start + spin),
                    None => start + spin,
                };
                if let Some(ready) = self.spin(sources, Some(spin_until))? {
                    return Ok(ready);
                }
                self.block(sources, deadline)
            }
        }
    }

    /// Polls shared memory until a source has work or `until` passes; file descriptors that
    /// have no shared-memory check are polled (without sleeping) every 500 µs.
    fn spin(
        &self,
        sources: &[&dyn Source],
        until: Option<Instant>,
    ) -> Result<Option<Ready>, ReactorError> {
        let has_fd_only = sources.iter().any(|s| s.pending().is_none());
        let mut next_fd_poll = Instant::now() + FD_POLL_PERIOD;
        let mut spins: u32 = 0;
        let yields = matches!(self.strategy, WaitStrategy::SpinThenBlock(_));
        loop {
            let ready = poll_pending(sources);
            if ready != 0 {
                return Ok(Some(Ready {
                    mask: ready,
                    ..Ready::default()
                }));
            }
            spins = spins.wrapping_add(1);
            // A signal caught while spinning (a lock of iceoryx2's handler): at the first round
            // of every wait, so that a busy reactor whose waits end within a few rounds still
            // looks (and installs the handlers), then every 64 rounds.
            if self.handles_signals && spins & 63 == 1 && SignalHandler::termination_requested() {
                return Ok(Some(Ready {
                    termination_requested: true,
                    ..Ready::default()
                }));
            }
            // Reading the clock costs ~20 ns: do it every 16 rounds.
            if spins & (YIELD_EVERY - 1) == 0 {
                if yields {
                    self.count(|s| s.yields += 1);
                    std::thread::yield_now();
                }
                let now = Instant::now();
                if has_fd_only && now >= next_fd_poll {
                    let ready = self.epoll(sources, Some(Duration::ZERO))?;
                    if ready.any() || ready.termination_requested {
                        return Ok(Some(ready));
                    }
                    next_fd_poll = now + FD_POLL_PERIOD;
                }
                if until.is_some_and(|u| now >= u) {
                    return Ok(None);
                }
            }
            std::hint::spin_loop();
        }
    }

    /// Sleeps in the `WaitSet` until a source is signalled or `deadline` passes.
    fn block(
        &self,
        sources: &[&dyn Source],
        deadline: Option<Instant>,
    ) -> Result<Ready, ReactorError> {
        let mut slept = false;
        loop {
            let remaining = match deadline {
                Some(d) => {
                    let now = Instant::now();
                    if now >= d {
                        return Ok(Ready {
                            timed_out: true,
                            ..Ready::default()
                        });
                    }
                    Some(d - now)
                }
                None => None,
            };
            if !slept {
                // Counted once it is sure to sleep: a deadline that passed while spinning
                // returns above without a system call.
                slept = true;
                self.count(|s| s.sleeps += 1);
            }
            let ready = self.epoll(sources, remaining)?;
            if ready.any() || ready.termination_requested {
                return Ok(ready);
            }
        }
    }

    /// One `WaitSet` round: attach, wait up to `timeout` (`None`: forever), consume the
    /// wake-ups of the signalled sources, detach.
    fn epoll(
        &self,
        sources: &[&dyn Source],
        timeout: Option<Duration>,
    ) -> Result<Ready, ReactorError> {
        let mut guards = Vec::with_capacity(sources.len());
        for (index, source) in sources.iter().enumerate() {
            let guard = self
                .waitset
                .attach_notification(source.waitable())
                .map_err(|error| ReactorError::Attach {
                    source: index,
                    error,
                })?;
            guards.push(guard);
        }
        let mut signalled = 0u64;
        let on_event = |id: iceoryx2::prelude::WaitSetAttachmentId<ipc::Service>| {
            for (index, guard) in guards.iter().enumerate() {
                if id.has_event_from(guard) {
                    signalled |= 1 << index;
                }
            }
            CallbackProgression::Continue
        };
        let result = match timeout {
            Some(t) => self.waitset.wait_and_process_once_with_timeout(on_event, t),
            None => self.waitset.wait_and_process_once(on_event),
        }
        .map_err(ReactorError::Wait)?;
        drop(guards);
        // A signalled receiver whose samples were already taken is not reported (the wake-up
        // is consumed, the caller has nothing to do); a source with data but no signal is.
        let mut mask = 0u64;
        for (index, source) in sources.iter().enumerate() {
            let is_ready = if signalled & (1 << index) != 0 {
                source.signalled()
            } else {
                source.pending() == Some(true)
            };
            if is_ready {
                mask |= 1 << index;
            }
        }
        Ok(Ready {
            mask,
            timed_out: false,
            termination_requested: matches!(
                result,
                WaitSetRunResult::Interrupt | WaitSetRunResult::TerminationRequest
            ),
        })
    }
}

fn poll_pending(sources: &[&dyn Source]) -> u64 {
    let mut mask = 0u64;
    for (index, source) in sources.iter().enumerate() {
        if source.pending() == Some(true) {
            mask |= 1 << index;
        }
    }
    mask
}
