//! The signals `petrel up` listens to: a stop request (SIGINT, SIGTERM, SIGHUP) and a child's
//! end (SIGCHLD), read from a signalfd.
//!
//! Why not iceoryx2's handler, as `petrel play` uses: it keeps only the last signal received,
//! so a SIGCHLD or SIGCONT right after a SIGTERM hides the stop request, and the supervisor of
//! a vehicle must never lose one. Here the signals are blocked and queued by the kernel, read
//! one by one, and the wait wakes at once when a child ends. Blocked signals are not a
//! child's business: `std::process::Command` gives every child an empty signal mask.

use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};
use std::os::fd::AsFd;
use std::time::Duration;

/// The stop signals and SIGCHLD, blocked for this thread and read from a signalfd.
///
/// The mask stays for the rest of the process: `petrel up` ends when its supervision does, and
/// a stop request that comes during the summary must not kill it before its exit code.
pub struct Signals {
    fd: SignalFd,
}

impl Signals {
    /// Blocks SIGINT, SIGTERM, SIGHUP and SIGCHLD (call it before any other thread starts,
    /// so that none of them is delivered elsewhere) and opens the signalfd.
    pub fn new() -> nix::Result<Self> {
        let mut set = SigSet::empty();
        for s in [
            Signal::SIGINT,
            Signal::SIGTERM,
            Signal::SIGHUP,
            Signal::SIGCHLD,
        ] {
            set.add(s);
        }
        set.thread_block()?;
        let fd = SignalFd::with_flags(&set, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)?;
        Ok(Signals { fd })
    }

    /// Waits up to `timeout` for a signal; returns the stop signal received, if any (a child's
    /// end only wakes the wait: the caller reaps its children every round).
    pub fn wait(&self, timeout: Duration) -> Option<Signal> {
        let timeout = PollTimeout::try_from(timeout).unwrap_or(PollTimeout::MAX);
        let mut fds = [PollFd::new(self.fd.as_fd(), PollFlags::POLLIN)];
        // EINTR or another error: the round ends early and the caller looks again.
        let _ = poll(&mut fds, timeout);
        let mut stop = None;
        while let Ok(Some(info)) = self.fd.read_signal() {
            match Signal::try_from(info.ssi_signo as i32) {
                Ok(Signal::SIGCHLD) | Err(_) => {}
                Ok(s) => stop = stop.or(Some(s)),
            }
        }
        stop
    }
}
