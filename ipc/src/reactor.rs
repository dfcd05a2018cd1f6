//! Waiting for something to do: a small reactor around an epoll instance of its own, with the wait
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
//! polled without a system call, and its listener's descriptor wakes epoll), and [`FdSource`] wraps
//! any other file descriptor, such as a CAN socket.

use std::cell::{Cell, RefCell};
use std::fmt;
use std::io;
use std::os::fd::RawFd;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::prelude::FileDescriptorBased;
use iceoryx2_bb_posix::signal::SignalHandler;

use crate::doorbell::{self, Doorbell, Slept};
use crate::epoll::Epoll;
use crate::port::Receiver;
use crate::wire::Message;

/// How a process waits for work.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitStrategy {
    /// Sleep in the kernel until a source is signalled (no CPU used). A round trip between two
    /// sleeping receivers costs about 7 µs on busy CPUs through their doorbells (about 10 µs
    /// through epoll), and the idle CPU's wake-up (45-60 µs here) when the CPUs idle.
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

/// A number that tells one [`Source`] from every other of the process, for as long as the
/// process lives (never reused): the [`Reactor`] keeps a source registered between waits while
/// the same source comes back, and registers anew a source it has not seen, even if it got the
/// file descriptor number of one that was closed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SourceKey(u64);

impl SourceKey {
    /// A key no other source of this process has.
    pub fn new() -> Self {
        static NEXT: AtomicU64 = AtomicU64::new(1);
        SourceKey(NEXT.fetch_add(1, Ordering::Relaxed))
    }
}

impl Default for SourceKey {
    fn default() -> Self {
        Self::new()
    }
}

/// Something the [`Reactor`] watches.
pub trait Source {
    /// Whether work is waiting, found without a system call; `None` when only the file
    /// descriptor can tell.
    fn pending(&self) -> Option<bool>;

    /// The file descriptor that becomes readable when the source is signalled. It must stay
    /// open, and the same, for as long as the source lives.
    fn fd(&self) -> RawFd;

    /// This source's key (keep one [`SourceKey`] per source, made when the source is).
    fn key(&self) -> SourceKey;

    /// Called when the file descriptor was found readable, to consume the wake-up (a
    /// level-triggered wait wakes again at once on a wake-up left unconsumed). Returns whether
    /// the caller has something to do. Receivers consume their notifications, keep them for
    /// [`Receiver::take_wakeups`], and report work when samples wait or a sender joined, left or
    /// died; a raw file descriptor reports work and the caller reads it.
    fn signalled(&self) -> bool {
        true
    }

    /// The source's doorbell, when its senders ring it (a [`Receiver`]'s): a reactor whose
    /// sources all have one sleeps on their futex words instead of epoll (see
    /// [`crate::doorbell`]).
    fn doorbell(&self) -> Option<&Doorbell> {
        None
    }

    /// When the source must be looked at again whatever wakes the reactor (a receiver's
    /// connection iceoryx2 could not make: [`crate::mending`]); `None`: only when woken.
    fn mend_by(&self) -> Option<Instant> {
        None
    }
}

impl<M: Message> Source for Receiver<M> {
    fn pending(&self) -> Option<bool> {
        Some(self.has_pending())
    }

    fn fd(&self) -> RawFd {
        // SAFETY: the descriptor is only read (registered with epoll), never closed or used
        // for I/O here; the listener owns it for as long as the receiver lives.
        unsafe { self.listener_fd().file_descriptor().native_handle() }
    }

    fn key(&self) -> SourceKey {
        self.source_key()
    }

    fn doorbell(&self) -> Option<&Doorbell> {
        Receiver::doorbell(self)
    }

    fn mend_by(&self) -> Option<Instant> {
        Receiver::mend_by(self)
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
/// descriptor: keep it open while it is watched, and make a new `FdSource` for a new
/// descriptor.
#[derive(Debug)]
pub struct FdSource {
    fd: RawFd,
    key: SourceKey,
}

impl FdSource {
    /// Watches `fd`.
    pub fn new(fd: RawFd) -> Result<Self, ReactorError> {
        // SAFETY: F_GETFD only reads the descriptor's flags; it fails with EBADF on a
        // descriptor that is not open.
        if fd < 0 || unsafe { libc::fcntl(fd, libc::F_GETFD) } < 0 {
            return Err(ReactorError::InvalidFd(fd));
        }
        Ok(FdSource {
            fd,
            key: SourceKey::new(),
        })
    }
}

impl Source for FdSource {
    fn pending(&self) -> Option<bool> {
        None
    }

    fn fd(&self) -> RawFd {
        self.fd
    }

    fn key(&self) -> SourceKey {
        self.key
    }
}

/// The reactor failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReactorError {
    /// The epoll instance could not be created.
    Create {
        /// The system's error number.
        errno: i32,
    },
    /// A source could not be watched.
    Attach {
        /// Index of the source in the slice given to [`Reactor::wait`].
        source: usize,
        /// The system's error number.
        errno: i32,
    },
    /// Waiting failed.
    Wait {
        /// The system's error number.
        errno: i32,
    },
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
            ReactorError::Create { errno } => write!(
                f,
                "cannot create the reactor's epoll instance: {}",
                io::Error::from_raw_os_error(*errno)
            ),
            ReactorError::Attach { source, errno } => write!(
                f,
                "cannot watch source {source}: {}",
                io::Error::from_raw_os_error(*errno)
            ),
            ReactorError::Wait { errno } => write!(
                f,
                "waiting failed: {}",
                io::Error::from_raw_os_error(*errno)
            ),
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

/// Sources whose futex words a doorbell sleep keeps on the stack (more go in a `Vec`): the
/// player waits on two, a program on one per hosted name.
const INLINE_WORDS: usize = 4;

/// While spinning, how often file descriptors without a shared-memory check are polled.
const FD_POLL_PERIOD: Duration = Duration::from_micros(500);

/// Longest sleep on doorbells before the reactor looks at its receivers' listeners anyway: news
/// of senders that iceoryx2 gives without a ring (a dead node it cleaned up by itself while
/// another process started) comes at most this late, and so would a sample whose sender did
/// not ring (a process of another Petrel). See [`Reactor::set_doorbell_slice`].
pub const DOORBELL_SLICE: Duration = Duration::from_millis(50);

/// Doorbell sleeps that found a sample no doorbell rang for ([`ReactorStats::unrung`]) after
/// which a reactor sleeps on epoll for good (see [`Reactor::doorbells`]).
pub const UNRUNG_LIMIT: u64 = 3;

/// Environment variable that, set to `off`, makes every reactor of the process sleep on epoll
/// (iceoryx2's notifications) even when its sources have doorbells: to compare, or as a way
/// out.
pub const DOORBELL_ENV: &str = "PETREL_DOORBELL";

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
    /// Waits that went to sleep: under `spin-then-block`, those whose spin
    /// window ended with nothing to do.
    pub sleeps: u64,
    /// Times a spinning wait offered the CPU to another thread.
    pub yields: u64,
    /// Futex sleeps on the sources' doorbells rather than epoll, one per slice
    /// ([`DOORBELL_SLICE`]): a wait that slept on them counts one `sleeps` and at least one of
    /// these.
    pub doorbell_sleeps: u64,
    /// Doorbell sleeps that ran to the end of their slice ([`DOORBELL_SLICE`]) and then found
    /// a sample waiting that no doorbell rang for: a sender that does not ring, a sample sent
    /// just as the slice ended, or a lost wake-up.
    pub unrung: u64,
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
/// The reactor registers a source's file descriptor with its own epoll instance the first time
/// it has to sleep on it and keeps it registered while the following waits name the same
/// sources (by [`SourceKey`]): a caller that waits on the same sources in a loop pays no
/// `epoll_ctl` per wait. A wait on other sources unregisters those no longer named. The sources
/// stay free for the caller between waits (the reactor keeps their numbers, not them).
#[derive(Debug)]
pub struct Reactor {
    epoll: Epoll,
    /// The sources registered with `epoll` now: key and file descriptor.
    attached: RefCell<Vec<(SourceKey, RawFd)>>,
    strategy: WaitStrategy,
    /// SIGINT and SIGTERM are caught and reported (not left their default action).
    handles_signals: bool,
    /// Sleep on doorbells when every source has one (off: after ENOSYS, or by choice).
    doorbells: Cell<bool>,
    /// Longest doorbell sleep.
    slice: Duration,
    stats: Cell<ReactorStats>,
}

impl Reactor {
    /// A reactor that reports SIGINT and SIGTERM as [`Ready::termination_requested`], whatever
    /// its strategy: iceoryx2's signal handler is installed at the first wait (a sleeping
    /// wait's look before it sleeps, or a spinning wait's first poll), and a spinning wait polls
    /// it.
    pub fn new(strategy: WaitStrategy) -> Result<Self, ReactorError> {
        Self::build(strategy, true)
    }

    /// A reactor that leaves signals alone. A signal that interrupts its sleep (one the caller
    /// handles itself) is reported as [`Ready::termination_requested`].
    pub fn without_signal_handling(strategy: WaitStrategy) -> Result<Self, ReactorError> {
        Self::build(strategy, false)
    }

    fn build(strategy: WaitStrategy, handles_signals: bool) -> Result<Self, ReactorError> {
        let epoll = Epoll::new().map_err(|e| ReactorError::Create {
            errno: e.raw_os_error().unwrap_or(0),
        })?;
        // iceoryx2 installs its SIGINT/SIGTERM handlers at the first look for a termination
        // request: the first sleep, or a spinning wait's first poll, which a spinning reactor
        // needs since it may never sleep. Not earlier: the install keeps the timing iceoryx2's
        // own WaitSet gave it.
        let doorbells = std::env::var(DOORBELL_ENV).map_or(true, |v| v != "off");
        Ok(Reactor {
            epoll,
            attached: RefCell::new(Vec::new()),
            strategy,
            handles_signals,
            doorbells: Cell::new(doorbells),
            slice: DOORBELL_SLICE,
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

    /// Whether this reactor sleeps on its sources' doorbells when they all have one (the
    /// default, unless `PETREL_DOORBELL=off`), or always on epoll.
    pub fn set_doorbells(&mut self, on: bool) {
        self.doorbells.set(on);
    }

    /// Whether this reactor sleeps on doorbells (see [`set_doorbells`](Self::set_doorbells)):
    /// false after ENOSYS from `futex_waitv`, or after [`UNRUNG_LIMIT`] samples came that no
    /// doorbell rang for.
    pub fn doorbells(&self) -> bool {
        self.doorbells.get()
    }

    /// Changes the longest doorbell sleep ([`DOORBELL_SLICE`] by default). A test that must
    /// see a lost wake-up as a failure sets it far beyond its own deadline.
    pub fn set_doorbell_slice(&mut self, slice: Duration) {
        self.slice = slice.max(Duration::from_millis(1));
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
        // Inside a wait and between waits the reactor looks at the receivers before it
        // sleeps: their senders need not wake them.
        for source in sources {
            if let Some(bell) = source.doorbell() {
                bell.set_awake();
            }
        }
        if sources.is_empty() {
            // Nothing to watch: this is only a timer.
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
        // A blocking wait on doorbells looks for work once it announced its sleep (the
        // doorbell's argument needs that look): a look here too would read every receiver's
        // shared memory twice when nothing waits, the usual case.
        let looks_before_sleep = self.strategy == WaitStrategy::Block && self.on_doorbells(sources);
        if !looks_before_sleep {
            let ready = poll_pending(sources);
            if ready != 0 {
                return Ok(Ready {
                    mask: ready,
                    ..Ready::default()
                });
            }
        }
        match self.strategy {
            WaitStrategy::Block => self.block(sources, deadline, Some(start)),
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
                self.block(sources, deadline, None)
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

    /// Sleeps in epoll until a source is signalled or `deadline` passes.
    fn block(
        &self,
        sources: &[&dyn Source],
        deadline: Option<Instant>,
        mut now: Option<Instant>,
    ) -> Result<Ready, ReactorError> {
        let mut slept = false;
        loop {
            // A receiver mending a connection is looked at when its retry is due: reported
            // ready (its drain retries), and the sleep until then no longer.
            let mut mend = None::<Instant>;
            let mut due_now = 0u64;
            for (index, source) in sources.iter().enumerate() {
                if let Some(by) = source.mend_by() {
                    if by <= *now.get_or_insert_with(Instant::now) {
                        due_now |= 1 << index;
                    }
                    mend = Some(mend.map_or(by, |m: Instant| m.min(by)));
                }
            }
            if due_now != 0 {
                return Ok(Ready {
                    mask: due_now,
                    ..Ready::default()
                });
            }
            let deadline = match (deadline, mend) {
                (Some(d), Some(m)) => Some(d.min(m)),
                (d, m) => d.or(m),
            };
            let remaining = match deadline {
                Some(d) => {
                    // The caller's reading of the clock for the first round, if it just made one.
                    let now = now.take().unwrap_or_else(Instant::now);
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
            let ready = if self.on_doorbells(sources) {
                // Counts its sleep itself, once its last look found nothing to do.
                self.doorbell_sleep(sources, remaining, &mut slept)?
            } else {
                if !slept {
                    // Counted once it is sure to sleep: a deadline that passed while spinning
                    // returns above without a system call.
                    slept = true;
                    self.count(|s| s.sleeps += 1);
                }
                self.epoll_sleep(sources, remaining)?
            };
            if ready.any() || ready.termination_requested {
                return Ok(ready);
            }
        }
    }

    /// Whether a sleep on `sources` goes on their doorbells (all have one, and the kernel and
    /// the senders ring them) rather than epoll.
    fn on_doorbells(&self, sources: &[&dyn Source]) -> bool {
        self.doorbells.get() && sources.iter().all(|s| s.doorbell().is_some())
    }

    /// Sleeps in epoll, the receivers' doorbells saying so (their senders notify through
    /// iceoryx2), after a last look for samples.
    fn epoll_sleep(
        &self,
        sources: &[&dyn Source],
        timeout: Option<Duration>,
    ) -> Result<Ready, ReactorError> {
        let mut bells = false;
        for bell in sources.iter().filter_map(|s| s.doorbell()) {
            bell.announce(doorbell::EPOLL);
            bells = true;
        }
        if bells {
            doorbell::announced();
            let mask = poll_pending(sources);
            if mask != 0 {
                wake_all(sources);
                return Ok(Ready {
                    mask,
                    ..Ready::default()
                });
            }
        }
        let ready = self.epoll(sources, timeout);
        if bells {
            wake_all(sources);
        }
        ready
    }

    /// Sleeps on the futex words of the sources' doorbells (all have one) for at most
    /// `timeout` and the slice, after a last look for samples and news.
    fn doorbell_sleep(
        &self,
        sources: &[&dyn Source],
        timeout: Option<Duration>,
        slept: &mut bool,
    ) -> Result<Ready, ReactorError> {
        if self.handles_signals && SignalHandler::termination_requested() {
            return Ok(Ready {
                termination_requested: true,
                ..Ready::default()
            });
        }
        // Every source has a doorbell (the caller checked): each is asked for it again
        // rather than collected, and the words go on the stack for a few sources, so that a
        // sleep allocates nothing.
        let bells = || sources.iter().filter_map(|s| s.doorbell());
        for bell in bells() {
            bell.announce(doorbell::FUTEX);
        }
        doorbell::announced();
        // The words before the last look: a ring after this changes them, so the sleep below
        // returns at once (the module's argument).
        let mut inline = [(&doorbell::NO_WORD, 0u32); INLINE_WORDS];
        let spilled: Vec<(&AtomicU32, u32)>;
        let words: &[(&AtomicU32, u32)] = if sources.len() <= INLINE_WORDS {
            let mut n = 0;
            for (slot, bell) in inline.iter_mut().zip(bells()) {
                *slot = (bell.word_ref(), bell.word());
                n += 1;
            }
            &inline[..n]
        } else {
            spilled = bells().map(|b| (b.word_ref(), b.word())).collect();
            &spilled
        };
        let look = |listeners: bool| {
            let mut mask = 0u64;
            for (index, source) in sources.iter().enumerate() {
                let Some(bell) = source.doorbell() else {
                    continue;
                };
                let news = bell.take_news();
                let ready = if news || listeners {
                    source.signalled()
                } else {
                    source.pending() == Some(true)
                };
                if ready {
                    mask |= 1 << index;
                }
            }
            mask
        };
        let mask = look(false);
        if mask != 0 {
            wake_all(sources);
            return Ok(Ready {
                mask,
                ..Ready::default()
            });
        }
        if !*slept {
            *slept = true;
            self.count(|s| s.sleeps += 1);
        }
        self.count(|s| s.doorbell_sleeps += 1);
        let slice = timeout.map_or(self.slice, |t| t.min(self.slice));
        let slept = match words {
            [(word, expected)] => doorbell::futex_wait(word, *expected, slice),
            _ => doorbell::futex_waitv(words, slice),
        };
        wake_all(sources);
        match slept {
            Slept::Interrupted => {
                // As in `epoll`: with our handler only SIGINT/SIGTERM end the wait.
                let terminate = !self.handles_signals || SignalHandler::termination_requested();
                if terminate {
                    return Ok(Ready {
                        termination_requested: true,
                        ..Ready::default()
                    });
                }
                Ok(Ready::default())
            }
            Slept::Unsupported => {
                // A kernel before 5.16: epoll from now on (the caller's loop sleeps again).
                self.doorbells.set(false);
                Ok(Ready::default())
            }
            Slept::Woken => Ok(Ready {
                mask: look(false),
                ..Ready::default()
            }),
            Slept::TimedOut => {
                // The slice ran out: the listeners may hold news iceoryx2 gave without a ring.
                let unchanged = words
                    .iter()
                    .all(|(word, seen)| word.load(Ordering::Acquire) == *seen);
                if unchanged && poll_pending(sources) != 0 {
                    self.count(|s| s.unrung += 1);
                    if self.stats().unrung >= UNRUNG_LIMIT {
                        // Senders that do not ring (a process of an older Petrel): each of
                        // their samples would wait for the end of a slice. Epoll from now on,
                        // where their notifications wake this reactor.
                        self.doorbells.set(false);
                    }
                }
                Ok(Ready {
                    mask: look(true),
                    ..Ready::default()
                })
            }
        }
    }

    /// Registers with epoll the sources not registered yet, and unregisters those registered
    /// that `sources` no longer names. Nothing to do (no system call) when the caller waits on
    /// the same sources as last time.
    fn attach(&self, sources: &[&dyn Source]) -> Result<(), ReactorError> {
        let mut attached = self.attached.borrow_mut();
        let same = attached.len() == sources.len()
            && attached
                .iter()
                .zip(sources)
                .all(|(&(key, fd), s)| key == s.key() && fd == s.fd());
        if same {
            return Ok(());
        }
        // Unregister first: a source that is gone may have left its descriptor number to one
        // of the new sources, which must then be registered afresh.
        attached.retain(|&(key, fd)| {
            let named = sources.iter().any(|s| s.key() == key && s.fd() == fd);
            if !named {
                self.epoll.delete(fd);
            }
            named
        });
        for (index, source) in sources.iter().enumerate() {
            let entry = (source.key(), source.fd());
            if attached.contains(&entry) {
                continue;
            }
            self.epoll.add(entry.1).map_err(|e| ReactorError::Attach {
                source: index,
                errno: e.raw_os_error().unwrap_or(0),
            })?;
            attached.push(entry);
        }
        Ok(())
    }

    /// One epoll round: register the sources (if they changed), wait up to `timeout` (`None`:
    /// forever), consume the wake-ups of the signalled sources.
    fn epoll(
        &self,
        sources: &[&dyn Source],
        timeout: Option<Duration>,
    ) -> Result<Ready, ReactorError> {
        self.attach(sources)?;
        if self.handles_signals && SignalHandler::termination_requested() {
            return Ok(Ready {
                termination_requested: true,
                ..Ready::default()
            });
        }
        let mut signalled = 0u64;
        let result = self.epoll.wait(timeout, |fd| {
            for (index, source) in sources.iter().enumerate() {
                if source.fd() == fd {
                    signalled |= 1 << index;
                }
            }
        });
        if let Err(e) = result {
            if e.kind() != io::ErrorKind::Interrupted {
                return Err(ReactorError::Wait {
                    errno: e.raw_os_error().unwrap_or(0),
                });
            }
            // A signal: with our handler, SIGINT/SIGTERM end the wait and others do not (the
            // caller's loop sleeps again); without, the caller handles its signals and is told.
            let terminate = !self.handles_signals || SignalHandler::termination_requested();
            return Ok(Ready {
                termination_requested: terminate,
                ..Ready::default()
            });
        }
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
            termination_requested: false,
        })
    }
}

/// The receivers are awake again: their senders need not ring.
fn wake_all(sources: &[&dyn Source]) {
    for bell in sources.iter().filter_map(|s| s.doorbell()) {
        bell.set_awake();
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
