//! Time, injected: the system clock in flight, a manual clock in tests and offline replay.

use std::fmt;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// A source of time in microseconds, and a way to wait for an instant of it.
pub trait Clock: Send + Sync + fmt::Debug {
    /// The time now, in microseconds.
    fn now_us(&self) -> u64;

    /// Returns at `time_us` (at once if it has passed).
    fn sleep_until_us(&self, time_us: u64);
}

/// Microseconds since the Unix epoch, the clock of SocketCAN's receive timestamps.
#[derive(Clone, Copy, Debug, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now_us(&self) -> u64 {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
    }

    fn sleep_until_us(&self, time_us: u64) {
        let now = self.now_us();
        if time_us > now {
            std::thread::sleep(Duration::from_micros(time_us - now));
        }
    }
}

/// A clock that moves only when told to: sleeping until an instant sets it there at once.
/// Clones share the time.
#[derive(Clone, Debug, Default)]
pub struct ManualClock {
    now: Arc<AtomicU64>,
}

impl ManualClock {
    /// A clock at `time_us`.
    pub fn new(time_us: u64) -> Self {
        ManualClock {
            now: Arc::new(AtomicU64::new(time_us)),
        }
    }

    /// Sets the time (it may go back: the caller decides).
    pub fn set(&self, time_us: u64) {
        self.now.store(time_us, Ordering::SeqCst);
    }

    /// Moves the time forward by `us`.
    pub fn advance(&self, us: u64) {
        self.now.fetch_add(us, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now_us(&self) -> u64 {
        self.now.load(Ordering::SeqCst)
    }

    fn sleep_until_us(&self, time_us: u64) {
        self.now.fetch_max(time_us, Ordering::SeqCst);
    }
}
