//! An epoll instance the [`Reactor`](crate::reactor::Reactor) owns, so that its sources stay
//! registered between waits (iceoryx2's `WaitSet` ties every attachment to a guard borrowed
//! for one wait, which cost two `epoll_ctl` per source per wait).

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::time::Duration;

/// Most readiness reports taken by one [`Epoll::wait`]; more wait for the next call.
const MAX_EVENTS: usize = 64;

/// An owned epoll file descriptor, level-triggered on readability.
#[derive(Debug)]
pub(crate) struct Epoll {
    fd: OwnedFd,
}

impl Epoll {
    /// A new, empty instance (closed on exec).
    pub(crate) fn new() -> io::Result<Self> {
        // SAFETY: epoll_create1 takes no pointer; a non-negative return is a new descriptor we
        // alone own.
        let fd = unsafe { libc::epoll_create1(libc::EPOLL_CLOEXEC) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: `fd` was just returned by the kernel and is owned by nobody else.
        let fd = unsafe { OwnedFd::from_raw_fd(fd) };
        Ok(Epoll { fd })
    }

    /// Watches `fd` for readability; its readiness reports `fd`. Already watched (the same
    /// number, another file that got it after the first was closed): the registration is
    /// replaced.
    pub(crate) fn add(&self, fd: RawFd) -> io::Result<()> {
        match self.ctl(libc::EPOLL_CTL_ADD, fd) {
            Err(e) if e.raw_os_error() == Some(libc::EEXIST) => self.ctl(libc::EPOLL_CTL_MOD, fd),
            other => other,
        }
    }

    /// Stops watching `fd`. A descriptor closed meanwhile left the set by itself (the kernel
    /// removes a closed file), so errors are ignored.
    pub(crate) fn delete(&self, fd: RawFd) {
        let _ = self.ctl(libc::EPOLL_CTL_DEL, fd);
    }

    fn ctl(&self, op: libc::c_int, fd: RawFd) -> io::Result<()> {
        let mut event = libc::epoll_event {
            events: libc::EPOLLIN as u32,
            u64: fd as u64,
        };
        // SAFETY: `event` is a valid epoll_event for the duration of the call; the kernel
        // checks both descriptors.
        let r = unsafe { libc::epoll_ctl(self.fd.as_raw_fd(), op, fd, &mut event) };
        if r < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(())
    }

    /// Waits until a watched descriptor is readable or `timeout` passes (`None`: forever,
    /// rounded up to the millisecond as iceoryx2's `WaitSet` does), and calls `ready` with each
    /// readable one. Returns how many; an `Interrupted` error when a signal came.
    pub(crate) fn wait(
        &self,
        timeout: Option<Duration>,
        mut ready: impl FnMut(RawFd),
    ) -> io::Result<usize> {
        let timeout_ms = match timeout {
            None => -1,
            Some(t) => t.as_nanos().div_ceil(1_000_000).min(i32::MAX as u128) as i32,
        };
        let mut events = [libc::epoll_event { events: 0, u64: 0 }; MAX_EVENTS];
        // SAFETY: `events` holds MAX_EVENTS writable entries, and the kernel writes at most
        // that many.
        let n = unsafe {
            libc::epoll_wait(
                self.fd.as_raw_fd(),
                events.as_mut_ptr(),
                MAX_EVENTS as libc::c_int,
                timeout_ms,
            )
        };
        if n < 0 {
            return Err(io::Error::last_os_error());
        }
        let n = n as usize;
        for event in &events[..n] {
            let fd = event.u64;
            ready(fd as RawFd);
        }
        Ok(n)
    }
}
