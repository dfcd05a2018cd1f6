//! A receiver's doorbell: a futex word in shared memory that senders ring after delivering a
//! sample, so that a sleeping [`Reactor`](crate::reactor::Reactor) wakes with one `futex` system
//! call each way instead of iceoryx2's notification (a datagram on a Unix socket, an epoll
//! wake-up and the reads that consume it), and a receiver that is awake is not notified at all.
//!
//! iceoryx2 still carries the samples, and still carries the news of senders (joined, left,
//! died) on the receiver's listener. The doorbell only says how the receiver sleeps:
//!
//! - `EPOLL` (the state it is created in): asleep on its listener, or not watched by a reactor
//!   at all. Senders notify through iceoryx2, as without a doorbell.
//! - `AWAKE`: inside or between the waits of a reactor, which polls the receiver's shared memory
//!   before it sleeps. Senders do nothing.
//! - `FUTEX`: asleep on the futex word. The first sender to see it sets `AWAKE`, bumps the word
//!   and wakes the futex; the others see `AWAKE`.
//!
//! **No lost wake-up.** The sleeping side stores its mode, issues a `SeqCst` fence, reads the
//! word, then looks for samples (and news) before `FUTEX_WAIT` on the word's value. The sender
//! delivers, issues a `SeqCst` fence, then reads the mode. Of the two fences one comes first in
//! their single total order: if the receiver's, the sender reads `FUTEX` (or later) and rings;
//! if the sender's, the receiver's look finds the sample. A ring that comes after the receiver
//! read the word changes it, so the `FUTEX_WAIT` returns at once; one that came before was read
//! with `Acquire`, so the look that follows sees the sample delivered before it. The same holds
//! for news (`ring_news` bumps a counter before it reads the mode) and for `EPOLL`.
//!
//! **Where it lives.** `/dev/shm/<session prefix>db_<node id>_<subscriber id>` (hex), one page,
//! created by the receiver (before senders can find it, it is sized and then stamped) and
//! removed when the receiver is dropped; a sender finds the doorbells of a service's receivers
//! by their ids in iceoryx2's list of subscribers. A receiver killed without warning leaves
//! its file: [`cleanup_dead_nodes`](crate::liveness::cleanup_dead_nodes) removes the doorbells
//! of every node that is no longer there (the node id is in the name; iceoryx2 may have
//! removed the dead node itself, when another process created a node or opened a service),
//! and the vehicle's last process removes every file of the session prefix. A sender that cannot open a receiver's doorbell
//! (not there yet, another Petrel) notifies through iceoryx2.
//!
//! **Knowing the receivers.** A sender does not list iceoryx2's subscribers at every send: it
//! rings the doorbells it found last time, and lists again when the service's change counter
//! moved (`/dev/shm/<session prefix>rx_<service hash>`, one page, bumped by every receiver once
//! its doorbell is made and once it is dropped). `Bells` gives the argument that a receiver
//! that joins is rung from the first send after its bump, before it can sleep on its doorbell.

use std::cell::Cell;
use std::fs::{self, File, OpenOptions};
use std::io;
use std::os::fd::AsRawFd;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::PathBuf;
use std::ptr::NonNull;
use std::sync::atomic::{fence, AtomicU32, AtomicU64, Ordering};
use std::time::Duration;

use crate::access::SHM_DIR;

/// Asleep on the listener, or not watched by a reactor: senders notify through iceoryx2.
pub(crate) const EPOLL: u32 = 0;
/// Awake: the reactor polls the receiver before it sleeps; senders do nothing.
pub(crate) const AWAKE: u32 = 1;
/// Asleep on the futex word: the first sender rings.
pub(crate) const FUTEX: u32 = 2;

/// Written last by the creator: the layout (and so the version) of the page.
const MAGIC: u32 = 0x5045_4401;

/// The shared page.
#[repr(C)]
struct Shared {
    magic: AtomicU32,
    mode: AtomicU32,
    /// The futex word: bumped by every ring.
    word: AtomicU32,
    /// Bumped when a sender joined or left, or after dead nodes were cleaned up.
    news: AtomicU32,
}

const PAGE: usize = 4096;

/// The name of the doorbell of subscriber `subscriber` of node `node`.
fn file_name(prefix: &str, node: u128, subscriber: u128) -> String {
    format!("{prefix}db_{node:032x}_{subscriber:032x}")
}

/// A receiver's doorbell, mapped by the receiver (which owns the file) or by a sender.
#[derive(Debug)]
pub struct Doorbell {
    shared: NonNull<Shared>,
    /// The receiver's doorbell removes its file when dropped.
    owned_path: Option<PathBuf>,
    /// Receiver side: the news counter as the reactor last saw it.
    news_seen: Cell<u32>,
    /// Receiver side: the news counter when the listener was last read.
    news_consumed: Cell<u32>,
    /// Receiver side: the listener may hold notifications not read yet (the receiver slept on
    /// it, or has not been read since it was created).
    listener_dirty: Cell<bool>,
}

impl Doorbell {
    /// Creates the doorbell of subscriber `subscriber` of node `node` (the receiver's side).
    pub(crate) fn create(prefix: &str, node: u128, subscriber: u128) -> io::Result<Self> {
        let path = PathBuf::from(SHM_DIR).join(file_name(prefix, node, subscriber));
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(&path)?;
        let bell = match file.set_len(PAGE as u64).and_then(|()| map(&file)) {
            Ok(shared) => Doorbell {
                shared,
                owned_path: Some(path),
                news_seen: Cell::new(0),
                news_consumed: Cell::new(0),
                listener_dirty: Cell::new(true),
            },
            Err(e) => {
                let _ = fs::remove_file(&path);
                return Err(e);
            }
        };
        bell.shared().magic.store(MAGIC, Ordering::Release);
        Ok(bell)
    }

    /// Opens the doorbell of subscriber `subscriber` of node `node` (a sender's side). Fails
    /// while it is being created.
    pub(crate) fn open(prefix: &str, node: u128, subscriber: u128) -> io::Result<Self> {
        let path = PathBuf::from(SHM_DIR).join(file_name(prefix, node, subscriber));
        Self::open_path(&path)
    }

    fn open_path(path: &std::path::Path) -> io::Result<Self> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(path)?;
        // A file not sized yet would fault when touched: treat it as not there.
        if file.metadata()?.len() < PAGE as u64 {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                "doorbell being created",
            ));
        }
        let bell = Doorbell {
            shared: map(&file)?,
            owned_path: None,
            news_seen: Cell::new(0),
            news_consumed: Cell::new(0),
            listener_dirty: Cell::new(true),
        };
        if bell.shared().magic.load(Ordering::Acquire) != MAGIC {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                "doorbell being created, or of another layout",
            ));
        }
        Ok(bell)
    }

    fn shared(&self) -> &Shared {
        // SAFETY: `shared` points to a live shared mapping of at least a page (mapped in
        // `map`, unmapped only in `drop`), and every field is an atomic, so concurrent access
        // from other processes is sound.
        unsafe { self.shared.as_ref() }
    }

    // ---- the receiver's side ----

    /// The mode now (`EPOLL`, `AWAKE` or `FUTEX`).
    #[cfg(test)]
    pub(crate) fn mode(&self) -> u32 {
        self.shared().mode.load(Ordering::Relaxed)
    }

    /// Says the receiver is awake (no store when it already says so: senders read the line).
    pub(crate) fn set_awake(&self) {
        let mode = &self.shared().mode;
        if mode.load(Ordering::Relaxed) != AWAKE {
            mode.store(AWAKE, Ordering::SeqCst);
        }
    }

    /// Announces how the receiver is about to sleep (`EPOLL` or `FUTEX`). The caller then
    /// issues a `SeqCst` fence ([`announced`]) before it looks for work one last time.
    pub(crate) fn announce(&self, how: u32) {
        if how == EPOLL {
            // Senders notify through iceoryx2 from now on.
            self.listener_dirty.set(true);
        }
        self.shared().mode.store(how, Ordering::SeqCst);
    }

    /// Whether the listener may hold notifications not read yet: the receiver slept on it (or
    /// was never read), or news were rung since it was last read. A receiver that is only ever
    /// awake or asleep on its doorbell is not notified of samples, and needs no read of its
    /// listener (a system call) at every drain.
    pub(crate) fn listener_may_hold(&self) -> bool {
        self.listener_dirty.get()
            || self.shared().news.load(Ordering::Acquire) != self.news_consumed.get()
    }

    /// Called before the listener is read: what it holds now is read.
    pub(crate) fn reading_listener(&self) {
        self.listener_dirty.set(false);
        self.news_consumed
            .set(self.shared().news.load(Ordering::Acquire));
    }

    /// The futex word's value, read after the announcement's fence and before the last look.
    pub(crate) fn word(&self) -> u32 {
        self.shared().word.load(Ordering::Acquire)
    }

    /// The futex word itself.
    pub(crate) fn word_ref(&self) -> &AtomicU32 {
        &self.shared().word
    }

    /// Whether news came since the last call (a sender joined or left, dead nodes were cleaned).
    pub(crate) fn take_news(&self) -> bool {
        let news = self.shared().news.load(Ordering::Acquire);
        news != self.news_seen.replace(news)
    }

    // ---- the sender's side ----

    /// After a delivery (and the caller's `SeqCst` fence): wakes the receiver if it sleeps on
    /// the futex. Returns whether the receiver must be notified through iceoryx2 instead.
    pub(crate) fn ring(&self) -> bool {
        let shared = self.shared();
        match shared.mode.load(Ordering::SeqCst) {
            AWAKE => false,
            FUTEX => {
                // Only the first sender to see the sleeper makes the system call.
                if shared
                    .mode
                    .compare_exchange(FUTEX, AWAKE, Ordering::SeqCst, Ordering::SeqCst)
                    .is_ok()
                {
                    shared.word.fetch_add(1, Ordering::SeqCst);
                    futex_wake(&shared.word);
                }
                false
            }
            _ => true,
        }
    }

    /// After iceoryx2 told the receiver's listener that a sender joined, left or died: makes a
    /// futex sleeper look at its listener. (A receiver asleep on the listener is already awake.)
    pub(crate) fn ring_news(&self) {
        let shared = self.shared();
        shared.news.fetch_add(1, Ordering::SeqCst);
        if shared.mode.load(Ordering::SeqCst) == FUTEX
            && shared
                .mode
                .compare_exchange(FUTEX, AWAKE, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
        {
            shared.word.fetch_add(1, Ordering::SeqCst);
            futex_wake(&shared.word);
        }
    }
}

/// The fence between announcing a sleep and the last look for work (see the module's
/// argument).
pub(crate) fn announced() {
    fence(Ordering::SeqCst);
}

/// The fence between a delivery and reading the receivers' modes.
pub(crate) fn delivered() {
    fence(Ordering::SeqCst);
}

impl Drop for Doorbell {
    fn drop(&mut self) {
        // SAFETY: the mapping was made in `map` with this address and length and is not used
        // after this point (the struct is being dropped).
        unsafe {
            libc::munmap(self.shared.as_ptr().cast(), PAGE);
        }
        if let Some(path) = &self.owned_path {
            let _ = fs::remove_file(path);
        }
    }
}

fn map(file: &File) -> io::Result<NonNull<Shared>> {
    // SAFETY: a fresh shared mapping of a page of an open file at least a page long; the
    // kernel chooses the address. The file may be closed afterwards: the mapping stays.
    let ptr = unsafe {
        libc::mmap(
            std::ptr::null_mut(),
            PAGE,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_SHARED,
            file.as_raw_fd(),
            0,
        )
    };
    if ptr == libc::MAP_FAILED {
        return Err(io::Error::last_os_error());
    }
    NonNull::new(ptr.cast::<Shared>()).ok_or_else(|| io::Error::other("mmap returned null"))
}

/// How a futex sleep ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Slept {
    /// Woken, or the word had changed already.
    Woken,
    /// The time passed.
    TimedOut,
    /// A signal came.
    Interrupted,
    /// The kernel has no `futex_waitv` (before Linux 5.16).
    Unsupported,
}

fn timespec(d: Duration) -> libc::timespec {
    libc::timespec {
        tv_sec: d.as_secs().min(i64::MAX as u64) as libc::time_t,
        tv_nsec: d.subsec_nanos() as libc::c_long,
    }
}

/// Sleeps on one futex word while it holds `expected`, for at most `timeout`.
pub(crate) fn futex_wait(word: &AtomicU32, expected: u32, timeout: Duration) -> Slept {
    let ts = timespec(timeout);
    // SAFETY: `word` is a live, aligned 32-bit atomic (in shared memory: no PRIVATE flag);
    // `ts` outlives the call; the unused arguments are null.
    let r = unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAIT,
            expected,
            &ts as *const libc::timespec,
            std::ptr::null::<u32>(),
            0u32,
        )
    };
    if r == 0 {
        return Slept::Woken;
    }
    match io::Error::last_os_error().raw_os_error() {
        Some(libc::ETIMEDOUT) => Slept::TimedOut,
        Some(libc::EINTR) => Slept::Interrupted,
        // EAGAIN: the word changed before the sleep.
        _ => Slept::Woken,
    }
}

/// The kernel's `struct futex_waitv`.
#[repr(C)]
#[derive(Clone, Copy)]
struct FutexWaitv {
    val: u64,
    uaddr: u64,
    flags: u32,
    reserved: u32,
}

impl FutexWaitv {
    const EMPTY: FutexWaitv = FutexWaitv {
        val: 0,
        uaddr: 0,
        flags: 0,
        reserved: 0,
    };
}

/// Words [`futex_waitv`] passes to the kernel from the stack; more go in a `Vec`.
const INLINE_WAITV: usize = 4;

/// A futex word no sleeper waits on, to fill the unused slots of a list of words.
pub(crate) static NO_WORD: AtomicU32 = AtomicU32::new(0);

/// `FUTEX2_SIZE_U32`: the words are 32 bits (shared: no private flag).
const FUTEX2_SIZE_U32: u32 = 0x02;

/// Most words one `futex_waitv` takes.
pub(crate) const MAX_WAITV: usize = 128;

/// Sleeps on several futex words while each holds its expected value, for at most `timeout`.
pub(crate) fn futex_waitv(words: &[(&AtomicU32, u32)], timeout: Duration) -> Slept {
    debug_assert!(words.len() <= MAX_WAITV);
    let waiter = |(word, expected): &(&AtomicU32, u32)| FutexWaitv {
        val: u64::from(*expected),
        uaddr: word.as_ptr() as u64,
        flags: FUTEX2_SIZE_U32,
        reserved: 0,
    };
    // A few words (the usual case) on the stack: a sleep allocates nothing.
    let mut inline = [FutexWaitv::EMPTY; INLINE_WAITV];
    let spilled: Vec<FutexWaitv>;
    let waiters: &[FutexWaitv] = if words.len() <= INLINE_WAITV {
        for (slot, word) in inline.iter_mut().zip(words) {
            *slot = waiter(word);
        }
        &inline[..words.len()]
    } else {
        spilled = words.iter().map(waiter).collect();
        &spilled
    };
    // futex_waitv takes an absolute time on the given clock.
    let mut now = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `now` is a valid timespec to write.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut now) };
    let now = Duration::new(now.tv_sec as u64, now.tv_nsec as u32);
    let deadline = timespec(now.saturating_add(timeout));
    // SAFETY: `waiters` holds `len` valid entries whose addresses are live, aligned 32-bit
    // atomics; `deadline` outlives the call.
    let r = unsafe {
        libc::syscall(
            libc::SYS_futex_waitv,
            waiters.as_ptr(),
            waiters.len() as libc::c_uint,
            0u32,
            &deadline as *const libc::timespec,
            libc::CLOCK_MONOTONIC,
        )
    };
    if r >= 0 {
        return Slept::Woken;
    }
    match io::Error::last_os_error().raw_os_error() {
        Some(libc::ETIMEDOUT) => Slept::TimedOut,
        Some(libc::EINTR) => Slept::Interrupted,
        Some(libc::ENOSYS) => Slept::Unsupported,
        _ => Slept::Woken,
    }
}

fn futex_wake(word: &AtomicU32) {
    // SAFETY: `word` is a live, aligned 32-bit atomic in shared memory; FUTEX_WAKE reads no
    // other argument.
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAKE,
            i32::MAX,
            std::ptr::null::<libc::timespec>(),
            std::ptr::null::<u32>(),
            0u32,
        );
    }
}

/// After dead nodes were cleaned up: removes the doorbells of nodes that are gone (`nodes`
/// lists the ids of those of the vehicle that remain, alive or not; it is called after the
/// doorbells were listed, so that a node created meanwhile is in it), whoever removed the node (this
/// process, or iceoryx2 on its own when a node or service is created), and, when a node died
/// (`died`) or a doorbell was removed, rings the news on every other doorbell of the session
/// so that futex sleepers look at the "sender died" notifications iceoryx2 left on their
/// listeners, and bumps every change counter of the session ([`Changes`]). Returns the
/// number of files removed.
pub(crate) fn after_cleanup(
    prefix: &str,
    nodes: impl FnOnce() -> Option<Vec<u128>>,
    died: bool,
) -> usize {
    let Ok(entries) = fs::read_dir(SHM_DIR) else {
        return 0;
    };
    let ours = format!("{prefix}db_");
    let counters = changes_name(prefix, "");
    let mut found = Vec::new();
    let mut changes = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        if name.starts_with(&counters) {
            changes.push(entry.path());
            continue;
        }
        let Some(rest) = name.strip_prefix(&ours) else {
            continue;
        };
        let node = rest
            .split('_')
            .next()
            .and_then(|hex| u128::from_str_radix(hex, 16).ok());
        found.push((node, entry.path()));
    }
    // Listed after the doorbells: the node of a doorbell found above existed before, and is
    // listed unless it is gone.
    let nodes = nodes();
    let mut removed = 0;
    let mut others = Vec::new();
    for (node, path) in found {
        match (node, &nodes) {
            (Some(node), Some(nodes)) if !nodes.contains(&node) => {
                if fs::remove_file(&path).is_ok() {
                    removed += 1;
                }
            }
            _ => others.push(path),
        }
    }
    if died || removed > 0 {
        for path in others {
            if let Ok(bell) = Doorbell::open_path(&path) {
                bell.ring_news();
            }
        }
        // Senders list their receivers again: those of a dead node are forgotten at once.
        for path in changes {
            if let Ok(counter) = Changes::open_path(&path, None) {
                counter.bump();
            }
        }
    }
    removed
}

/// The name of the change counter of the receivers of the service whose iceoryx2 hash is
/// `service` (not `db_`: [`after_cleanup`] takes every `db_` file for a doorbell).
fn changes_name(prefix: &str, service: &str) -> String {
    format!("{prefix}rx_{service}")
}

/// The shared page of a change counter.
#[repr(C)]
struct ChangesPage {
    /// Bumped by a receiver once its doorbell exists (or could not be made), and once it is
    /// gone.
    changes: AtomicU64,
}

/// The change counter of the receivers of one service: a page of its own in shared memory,
/// mapped by the service's senders and receivers alike, so that a sender lists the receivers
/// again only when the set may have changed (see the module's argument).
///
/// Created by whoever comes first (open or create, then sized: a file being sized by another
/// process is sized again to the same length, which keeps its contents), never removed while
/// the vehicle lives (one per service), removed with every file of the session prefix by the
/// vehicle's last process.
#[derive(Debug)]
pub(crate) struct Changes {
    page: NonNull<ChangesPage>,
}

impl Changes {
    /// Opens (or creates) the change counter of service `service` (iceoryx2's hash of it, a
    /// file name) of a session shared with group `group` (`None`: this user's alone).
    pub(crate) fn open(prefix: &str, service: &str, group: Option<u32>) -> io::Result<Self> {
        let path = PathBuf::from(SHM_DIR).join(changes_name(prefix, service));
        Self::open_path(&path, Some(group))
    }

    /// Opens the counter at `path`; with `create`, creates it if it is not there, for a
    /// session shared with the group it holds.
    ///
    /// Only a file of this user, or of the session's group, is taken: a name squatted by
    /// someone else (the session prefix shows in a listing of /dev/shm) is refused, and
    /// senders then list the receivers at every send, as without a counter.
    fn open_path(path: &std::path::Path, create: Option<Option<u32>>) -> io::Result<Self> {
        let mut options = OpenOptions::new();
        options
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC);
        let group = create.flatten();
        if create.is_some() {
            options
                .create(true)
                .mode(if group.is_some() { 0o660 } else { 0o600 });
        }
        let file = options.open(path)?;
        let meta = file.metadata()?;
        // SAFETY: geteuid has no preconditions and cannot fail.
        let me = unsafe { libc::geteuid() };
        let ours = meta.uid() == me;
        if !(ours || group.is_some_and(|g| meta.gid() == g)) {
            return Err(io::Error::new(
                io::ErrorKind::PermissionDenied,
                "change counter of another user",
            ));
        }
        if let Some(g) = group.filter(|&g| ours && meta.gid() != g) {
            // The group's members take it at once (the session's sharing would later).
            // SAFETY: a valid descriptor; -1 keeps the owner.
            unsafe { libc::fchown(file.as_raw_fd(), u32::MAX, g) };
        }
        // A page of zeroes the first time; the same length (contents kept) if another process
        // sized it meanwhile.
        if meta.len() < PAGE as u64 {
            file.set_len(PAGE as u64)?;
        }
        Ok(Changes {
            page: map(&file)?.cast(),
        })
    }

    fn page(&self) -> &ChangesPage {
        // SAFETY: `page` points to a live shared mapping of a page (mapped in `open`, unmapped
        // only in `drop`), whose only field is an atomic.
        unsafe { self.page.as_ref() }
    }

    /// The counter now. A sender reads it after its delivery's fence, before it decides
    /// whether to list the receivers.
    pub(crate) fn get(&self) -> u64 {
        self.page().changes.load(Ordering::SeqCst)
    }

    /// Says the receivers changed: a receiver that joined (its subscriber is in iceoryx2's
    /// list and its doorbell made), or left (both gone).
    pub(crate) fn bump(&self) {
        self.page().changes.fetch_add(1, Ordering::SeqCst);
    }
}

impl Drop for Changes {
    fn drop(&mut self) {
        // SAFETY: the mapping was made in `map` with this address and length and is not used
        // after this point.
        unsafe {
            libc::munmap(self.page.as_ptr().cast(), PAGE);
        }
    }
}

/// A receiver's membership of its service's change counter: bumped when the receiver is made
/// (its doorbell exists) and when it is dropped (declared after the subscriber and the
/// doorbell, so that both are gone by then).
#[derive(Debug)]
pub(crate) struct Joined(Changes);

impl Joined {
    /// Bumps `changes`: this receiver joined.
    pub(crate) fn new(changes: Changes) -> Self {
        changes.bump();
        Joined(changes)
    }
}

impl Drop for Joined {
    fn drop(&mut self) {
        self.0.bump();
    }
}

/// The monotonic clock, coarse (a read of the kernel's page, no system call): a sender's
/// safety-net listing needs milliseconds, not nanoseconds.
fn coarse_now() -> Duration {
    let mut now = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `now` is a valid timespec to write.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC_COARSE, &mut now) };
    Duration::new(now.tv_sec as u64, now.tv_nsec as u32)
}

/// The doorbells of the receivers of one service, as a sender knows them.
///
/// **Listing only when needed.** The list of iceoryx2's subscribers is a snapshot (an
/// allocation and about a thousand instructions): a sender keeps what it listed and the
/// service's change counter ([`Changes`]) it read before, and rings the doorbells it knows.
/// It lists again when the counter moved, when more receivers got a sample than it knows (a
/// receiver that does not bump the counter, of another build or whose counter page could not
/// be opened), for news, and at least every [`DOORBELL_SLICE`](crate::reactor::DOORBELL_SLICE)
/// (such a receiver that replaced another one; a receiver whose process died is removed by
/// iceoryx2 without a bump, and ringing its doorbell meanwhile is harmless). Without a counter
/// it lists at every ring.
///
/// A receiver bumps the counter after its subscriber is in iceoryx2's list and its doorbell
/// is made, and before it can sleep on the doorbell. A sender reads the counter after its
/// delivery's `SeqCst` fence. If the read does not see the bump, the sender's fence comes
/// before the bump, and so before the receiver's fence of any sleep: that sleep's last look
/// finds the sample. If it sees the bump, the listing that follows finds the receiver and its
/// doorbell, and rings it as before.
#[derive(Debug, Default)]
pub(crate) struct Bells {
    /// Subscriber id, the round it was last listed in, and its doorbell (`None`: not found,
    /// notify through iceoryx2; opening is tried again at the next listing).
    known: Vec<(u128, u64, Option<Doorbell>)>,
    round: u64,
    /// The service's change counter (`None`: it could not be opened; list at every ring).
    changes: Option<Changes>,
    /// The counter as read before the last listing (`None`: never listed).
    seen: Option<u64>,
    /// When the last listing was made ([`coarse_now`]).
    listed_at: Duration,
    /// The longest time between two listings.
    period: Duration,
}

impl Bells {
    /// The doorbells of a service whose change counter is `changes`.
    pub(crate) fn new(changes: Option<Changes>) -> Self {
        Bells {
            changes,
            period: crate::reactor::DOORBELL_SLICE,
            ..Bells::default()
        }
    }

    /// Sets the longest time between two listings.
    pub(crate) fn set_period(&mut self, period: Duration) {
        self.period = period;
    }

    /// The receivers the last listing found, when it can be trusted to be recent (a counter
    /// that says whether they changed); `None` otherwise.
    pub(crate) fn listed(&self) -> Option<usize> {
        match (&self.changes, self.seen) {
            (Some(_), Some(_)) => Some(self.known.len()),
            _ => None,
        }
    }

    /// Rings the doorbell of every receiver of the service (`delivered` of them got the
    /// sample): those known, or, when the set may have changed (see [`Bells`]), those `list`
    /// names (it calls its argument with the node id and the subscriber id of each), opening
    /// those not known yet or whose doorbell could not be opened, and forgetting those no
    /// longer named. With `news`, lists and rings the news instead. Returns whether some
    /// receiver must be notified through iceoryx2. The caller fenced after its delivery.
    pub(crate) fn ring(
        &mut self,
        prefix: &str,
        news: bool,
        delivered: usize,
        list: impl FnOnce(&mut dyn FnMut(u128, u128)),
    ) -> bool {
        let changes = self.changes.as_ref().map(Changes::get);
        if !news
            && changes.is_some()
            && changes == self.seen
            && delivered <= self.known.len()
            && coarse_now().saturating_sub(self.listed_at) < self.period
        {
            let mut notify = false;
            for (_, _, bell) in &self.known {
                match bell {
                    Some(bell) => notify |= bell.ring(),
                    None => notify = true,
                }
            }
            return notify;
        }
        self.seen = changes;
        self.listed_at = coarse_now();
        self.round = self.round.wrapping_add(1);
        let round = self.round;
        let mut notify = false;
        let mut listed = 0usize;
        let known = &mut self.known;
        list(&mut |node, subscriber| {
            listed += 1;
            let index = match known.iter().position(|(id, _, _)| *id == subscriber) {
                Some(i) => i,
                None => {
                    known.push((subscriber, round, None));
                    known.len() - 1
                }
            };
            let entry = &mut known[index];
            entry.1 = round;
            if entry.2.is_none() {
                entry.2 = Doorbell::open(prefix, node, subscriber).ok();
            }
            match &entry.2 {
                Some(bell) if news => bell.ring_news(),
                Some(bell) => notify |= bell.ring(),
                None => notify = true,
            }
        });
        if known.len() != listed {
            known.retain(|(_, seen, _)| *seen == round);
        }
        notify
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;
    use std::sync::Arc;

    fn prefix() -> String {
        format!("ptdbtest{}_", std::process::id())
    }

    #[test]
    fn the_receiver_owns_its_file_and_senders_find_it() {
        let prefix = prefix();
        let bell = Doorbell::create(&prefix, 7, 9).unwrap();
        let path = PathBuf::from(SHM_DIR).join(file_name(&prefix, 7, 9));
        assert!(path.exists());
        assert!(Doorbell::create(&prefix, 7, 9).is_err(), "created twice");
        let sender = Doorbell::open(&prefix, 7, 9).unwrap();
        assert!(Doorbell::open(&prefix, 7, 10).is_err());
        // Created asleep on the listener: a sender must notify.
        assert_eq!(bell.mode(), EPOLL);
        assert!(sender.ring());
        bell.set_awake();
        assert!(!sender.ring(), "an awake receiver is not notified");
        drop(sender);
        drop(bell);
        assert!(!path.exists(), "the receiver's drop removes its doorbell");
    }

    #[test]
    fn a_ring_wakes_a_futex_sleeper_and_leaves_it_awake() {
        let prefix = prefix();
        let bell = Doorbell::create(&prefix, 1, 2).unwrap();
        let sender = Doorbell::open(&prefix, 1, 2).unwrap();
        let woke = Arc::new(AtomicBool::new(false));
        let sample = Arc::new(AtomicBool::new(false));
        let (w, delivered_sample) = (woke.clone(), sample.clone());
        // A doorbell is not Send (a Cell for the news): the sleeper maps its own view.
        let sleeper = std::thread::spawn(move || {
            let mine = Doorbell::open(&prefix, 1, 2).unwrap();
            mine.announce(FUTEX);
            announced();
            let seen = mine.word();
            // The last look, as the reactor's: a sample delivered before it needs no sleep.
            let slept = if delivered_sample.load(Ordering::SeqCst) {
                Slept::Woken
            } else {
                // A generous slice: a lost ring shows as a slept-out sleep, not a hang.
                futex_wait(mine.word_ref(), seen, Duration::from_secs(30))
            };
            w.store(true, Ordering::SeqCst);
            slept
        });
        while bell.mode() != FUTEX {
            std::thread::yield_now();
        }
        sample.store(true, Ordering::SeqCst);
        delivered();
        assert!(!sender.ring(), "a futex sleeper is rung, not notified");
        assert_eq!(sleeper.join().unwrap(), Slept::Woken);
        assert!(woke.load(Ordering::SeqCst));
        assert_eq!(bell.mode(), AWAKE, "the ringer leaves the receiver awake");
        // News bump the counter the receiver reads once.
        sender.ring_news();
        assert!(bell.take_news());
        assert!(!bell.take_news());
    }

    #[test]
    fn a_changed_word_does_not_sleep() {
        let prefix = prefix();
        let bell = Doorbell::create(&prefix, 3, 4).unwrap();
        let seen = bell.word();
        bell.announce(FUTEX);
        Doorbell::open(&prefix, 3, 4).unwrap().ring();
        assert_eq!(
            futex_wait(bell.word_ref(), seen, Duration::from_secs(30)),
            Slept::Woken
        );
        let other = Doorbell::create(&prefix, 3, 5).unwrap();
        let words = [
            (bell.word_ref(), bell.word()),
            (other.word_ref(), other.word()),
        ];
        assert_eq!(
            futex_waitv(&words, Duration::from_millis(1)),
            Slept::TimedOut
        );
    }

    #[test]
    fn a_changed_word_among_a_few_or_many_ends_a_waitv() {
        let prefix = prefix() + "v_";
        let bells: Vec<Doorbell> = (0..6)
            .map(|i| Doorbell::create(&prefix, 21, i).unwrap())
            .collect();
        // Two words go on the stack, six in a Vec.
        for n in [2usize, 6] {
            let words: Vec<_> = bells[..n]
                .iter()
                .map(|b| (b.word_ref(), b.word()))
                .collect();
            assert_eq!(
                futex_waitv(&words, Duration::from_millis(1)),
                Slept::TimedOut
            );
            bells[n - 1].announce(FUTEX);
            Doorbell::open(&prefix, 21, n as u128 - 1).unwrap().ring();
            assert_eq!(futex_waitv(&words, Duration::from_secs(30)), Slept::Woken);
        }
    }

    /// Rings `bells` for a service whose subscribers are `ids`; counts the listings.
    fn ring_listed(
        bells: &mut Bells,
        prefix: &str,
        news: bool,
        delivered: usize,
        ids: &[(u128, u128)],
        lists: &mut usize,
    ) -> bool {
        bells.ring(prefix, news, delivered, |f| {
            *lists += 1;
            for &(node, subscriber) in ids {
                f(node, subscriber);
            }
        })
    }

    #[test]
    fn a_sender_lists_again_only_when_the_receivers_may_have_changed() {
        let prefix = prefix() + "l_";
        let counter_path = PathBuf::from(SHM_DIR).join(changes_name(&prefix, "svc"));
        let first = Doorbell::create(&prefix, 31, 1).unwrap();
        first.set_awake();
        // The receivers' view of the counter, and the sender's.
        let receivers = Changes::open(&prefix, "svc", None).unwrap();
        let mut bells = Bells::new(Some(Changes::open(&prefix, "svc", None).unwrap()));
        let mut lists = 0;
        let one = [(31, 1)];
        assert!(!ring_listed(
            &mut bells, &prefix, false, 1, &one, &mut lists
        ));
        assert_eq!((lists, bells.listed()), (1, Some(1)));
        for _ in 0..3 {
            assert!(!ring_listed(
                &mut bells, &prefix, false, 1, &one, &mut lists
            ));
        }
        assert_eq!(lists, 1, "nothing changed: no listing");
        // The known doorbell is still read at every ring: asleep on its listener, notify.
        first.announce(EPOLL);
        assert!(ring_listed(&mut bells, &prefix, false, 1, &one, &mut lists));
        first.set_awake();
        assert_eq!(lists, 1);
        // A receiver joined: listed at the next ring; its doorbell not there yet.
        let two = [(31, 1), (31, 2)];
        receivers.bump();
        assert!(ring_listed(&mut bells, &prefix, false, 2, &two, &mut lists));
        assert_eq!((lists, bells.listed()), (2, Some(2)));
        // Made later, without a bump: still notified through iceoryx2 until listed again,
        // then opened (a failed open is tried again at every listing).
        let second = Doorbell::create(&prefix, 31, 2).unwrap();
        second.set_awake();
        assert!(ring_listed(&mut bells, &prefix, false, 2, &two, &mut lists));
        assert_eq!(lists, 2);
        receivers.bump();
        assert!(!ring_listed(
            &mut bells, &prefix, false, 2, &two, &mut lists
        ));
        assert_eq!(lists, 3);
        // More deliveries than known receivers (one that does not bump): listed.
        let three = [(31, 1), (31, 2), (32, 3)];
        assert!(ring_listed(
            &mut bells, &prefix, false, 3, &three, &mut lists
        ));
        assert_eq!((lists, bells.listed()), (4, Some(3)));
        // News are rung on a fresh listing.
        ring_listed(&mut bells, &prefix, true, 0, &one, &mut lists);
        assert_eq!((lists, bells.listed()), (5, Some(1)));
        assert!(first.take_news());
        // Without a counter: a listing at every ring, and no count to trust.
        let mut blind = Bells::new(None);
        for n in 1..=2 {
            assert!(!ring_listed(
                &mut blind, &prefix, false, 1, &one, &mut lists
            ));
            assert_eq!(lists, 5 + n);
        }
        assert_eq!(blind.listed(), None);
        drop((receivers, bells, blind));
        fs::remove_file(&counter_path).unwrap();
    }

    #[test]
    fn a_change_counter_of_another_user_is_refused() {
        let prefix = prefix() + "s_";
        let path = PathBuf::from(SHM_DIR).join(changes_name(&prefix, "svc"));
        fs::write(&path, [0u8; PAGE]).unwrap();
        // Squatted by someone else (nobody): only root can make the file theirs.
        let given = std::os::unix::fs::chown(&path, Some(65_534), Some(65_534)).is_ok();
        let opened = Changes::open(&prefix, "svc", None);
        let in_group = Changes::open(&prefix, "svc", Some(65_534));
        fs::remove_file(&path).unwrap();
        if given {
            assert!(opened.is_err(), "a squatted counter was taken");
            assert!(
                in_group.is_ok(),
                "the session's group's counter was refused"
            );
        } else {
            assert!(opened.is_ok());
        }
    }

    #[test]
    fn cleanup_bumps_the_change_counters() {
        let prefix = prefix() + "k_";
        let counter = Changes::open(&prefix, "svc", None).unwrap();
        let alive = Doorbell::create(&prefix, 41, 1).unwrap();
        let gone = Doorbell::create(&prefix, 42, 1).unwrap();
        std::mem::forget(gone);
        let before = counter.get();
        assert_eq!(after_cleanup(&prefix, || Some(vec![41]), false), 1);
        assert_ne!(counter.get(), before, "senders must list again");
        assert!(alive.take_news());
        // The counter is not taken for a doorbell, nor removed.
        let path = PathBuf::from(SHM_DIR).join(changes_name(&prefix, "svc"));
        assert!(path.exists());
        drop(counter);
        fs::remove_file(&path).unwrap();
    }

    #[test]
    fn cleanup_removes_the_doorbells_of_nodes_gone() {
        let prefix = prefix() + "c_";
        let alive = Doorbell::create(&prefix, 11, 1).unwrap();
        let gone = Doorbell::create(&prefix, 12, 1).unwrap();
        let gone_path = PathBuf::from(SHM_DIR).join(file_name(&prefix, 12, 1));
        // A killed process does not unmap or remove: forget the owner.
        std::mem::forget(gone);
        assert_eq!(after_cleanup(&prefix, || Some(vec![11]), false), 1);
        assert!(!gone_path.exists());
        assert!(alive.take_news(), "the others are told");
        // Nothing gone, nobody died: no news.
        assert_eq!(after_cleanup(&prefix, || Some(vec![11]), false), 0);
        assert!(!alive.take_news());
    }
}
