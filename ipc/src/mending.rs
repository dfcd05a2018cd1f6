//! A receiver's connections to its senders, mended when iceoryx2 could not make one.
//!
//! iceoryx2 connects a subscriber to a publisher when it sees the service's list of publishers
//! change (at the subscriber's next look: `has_samples`, `receive`). If that connection cannot
//! be made (the publisher's process, which creates the connection's shared memory or its data
//! segment, is not scheduled within iceoryx2's creation timeout on a loaded machine; a file
//! cannot be opened for a while), iceoryx2 tells the port's degradation handler and tries again
//! only when the list changes again. The publisher's own side of the connection is made: its
//! samples are delivered and counted as received, and the receiver never sees them. A player
//! asleep on its doorbell slept for ever beside a program's events (issue 38's CI run).
//!
//! A [`Receiver`](crate::port::Receiver) therefore notes every such failure (its degradation
//! handler sets a flag) and mends it: it changes the list itself, by creating and dropping a
//! publisher of its own on the service (without a notifier, so no one is told of a sender),
//! and its next look connects again. A retry that fails again waits twice as long, from
//! [`FIRST_RETRY`] up to [`LAST_RETRY`]; a [`Reactor`](crate::reactor::Reactor) wakes a
//! receiver whose retry is due, so that samples already delivered are not left waiting for a
//! sender's next ring.

use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use iceoryx2::port::{DegradationAction, DegradationCause, DegradationInfo};

/// The wait before the first retry: a connection that failed for a slow peer usually succeeds
/// at once.
pub const FIRST_RETRY: Duration = Duration::from_millis(1);
/// The longest wait between two retries (a file that stays unreadable: each retry creates a
/// publisher, a few system calls).
pub const LAST_RETRY: Duration = Duration::from_secs(1);

/// The mending state of one receiver.
#[derive(Debug)]
pub(crate) struct Mending {
    /// Set by iceoryx2's degradation handler when a connection could not be made.
    failed: Arc<AtomicBool>,
    /// When the next retry is due (`None`: nothing to mend).
    due: Cell<Option<Instant>>,
    /// The wait after the next failed retry.
    backoff: Cell<Duration>,
    /// Retries made.
    retries: Cell<u64>,
}

impl Mending {
    pub(crate) fn new() -> Self {
        Mending {
            failed: Arc::new(AtomicBool::new(false)),
            due: Cell::new(None),
            backoff: Cell::new(FIRST_RETRY),
            retries: Cell::new(0),
        }
    }

    /// The subscriber's degradation handler: notes a connection that could not be made and
    /// lets iceoryx2 go on with the others (the failure is this module's to mend, not the
    /// caller's to see as an error).
    pub(crate) fn handler(
        &self,
    ) -> impl Fn(DegradationCause, &DegradationInfo) -> DegradationAction + Send + 'static {
        let failed = self.failed.clone();
        move |cause, _| {
            if matches!(cause, DegradationCause::FailedToEstablishConnection) {
                failed.store(true, Ordering::Relaxed);
            }
            DegradationAction::Ignore
        }
    }

    /// Whether nothing is to mend (no clock read, no atomic store: the look's hot path).
    fn idle(&self) -> bool {
        self.due.get().is_none() && !self.failed.load(Ordering::Relaxed)
    }

    /// When the receiver must look again to mend a connection (`None`: all are made).
    pub(crate) fn due(&self) -> Option<Instant> {
        if self.idle() {
            return None;
        }
        self.note_failure(Instant::now());
        self.due.get()
    }

    /// Retries made so far.
    pub(crate) fn retries(&self) -> u64 {
        self.retries.get()
    }

    /// Before a look: when a retry is due, calls `change_list` (which makes the list of
    /// publishers change, and says whether it could), so that the look connects again. A list
    /// that could not be changed (no publisher slot free...) is a failed retry: the next one
    /// comes after the backoff, never dropped.
    pub(crate) fn before_look(&self, change_list: impl FnOnce() -> bool) {
        if !self.idle() {
            self.before_look_at(Instant::now(), change_list);
        }
    }

    /// After a look: see [`after_look_at`](Self::after_look_at).
    pub(crate) fn after_look(&self) {
        if !self.idle() || self.backoff.get() != FIRST_RETRY {
            self.after_look_at(Instant::now());
        }
    }

    /// [`before_look`](Self::before_look) at time `now`.
    fn before_look_at(&self, now: Instant, change_list: impl FnOnce() -> bool) {
        self.note_failure(now);
        if self.due.get().is_some_and(|due| due <= now) {
            self.due.set(None);
            self.retries.set(self.retries.get() + 1);
            if !change_list() {
                self.failed.store(true, Ordering::Relaxed);
            }
        }
    }

    /// After a look: a failure it met schedules a retry (backing off if the last retry
    /// failed too); a look after a retry that met none ends the mending.
    fn after_look_at(&self, now: Instant) {
        if !self.note_failure(now) && self.due.get().is_none() {
            self.backoff.set(FIRST_RETRY);
        }
    }

    /// Takes the failure flag: schedules a retry, backing off. Returns whether one was noted.
    fn note_failure(&self, now: Instant) -> bool {
        if !self.failed.swap(false, Ordering::Relaxed) {
            return false;
        }
        if self.due.get().is_none() {
            let wait = self.backoff.get();
            self.due.set(Some(now + wait));
            self.backoff.set((wait * 2).min(LAST_RETRY));
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the degradation handler does for a connection that could not be made.
    fn fail(m: &Mending) {
        let info = DegradationInfo {
            service_id: 1,
            sender_port_id: 2,
            receiver_port_id: 3,
        };
        let action = m.handler()(DegradationCause::FailedToEstablishConnection, &info);
        assert_eq!(action, DegradationAction::Ignore);
    }

    #[test]
    fn a_failure_schedules_a_retry_that_backs_off_until_one_succeeds() {
        let m = Mending::new();
        let t0 = Instant::now();
        assert_eq!(m.due(), None);
        fail(&m);
        m.after_look_at(t0);
        assert_eq!(m.due.get(), Some(t0 + FIRST_RETRY));
        // Not due yet: no retry.
        let mut changed = 0;
        m.before_look_at(t0, || {
            changed += 1;
            true
        });
        assert_eq!(changed, 0);
        // Due: the list is changed once; the look fails again: twice the wait.
        let t1 = t0 + FIRST_RETRY;
        m.before_look_at(t1, || {
            changed += 1;
            true
        });
        assert_eq!(changed, 1);
        fail(&m);
        m.after_look_at(t1);
        assert_eq!(m.due.get(), Some(t1 + FIRST_RETRY * 2));
        // The waits double up to the last one.
        let mut t = t1;
        for _ in 0..20 {
            t = m.due.get().unwrap();
            m.before_look_at(t, || {
                changed += 1;
                true
            });
            fail(&m);
            m.after_look_at(t);
        }
        assert_eq!(m.due.get(), Some(t + LAST_RETRY));
        // A retry whose look meets no failure ends the mending; the next failure starts over.
        let t = m.due.get().unwrap();
        m.before_look_at(t, || {
            changed += 1;
            true
        });
        m.after_look_at(t);
        assert_eq!(m.due(), None);
        assert_eq!(m.retries(), changed);
        fail(&m);
        m.after_look_at(t);
        assert_eq!(m.due.get(), Some(t + FIRST_RETRY));
    }

    #[test]
    fn a_list_that_could_not_change_is_a_failed_retry_tried_again() {
        let m = Mending::new();
        let t0 = Instant::now();
        fail(&m);
        m.after_look_at(t0);
        let t1 = t0 + FIRST_RETRY;
        // The list could not change: the look meets no failure (nothing was tried), yet the
        // connection is still missing: a retry comes again, after twice the wait.
        m.before_look_at(t1, || false);
        m.after_look_at(t1);
        assert_eq!(m.due.get(), Some(t1 + FIRST_RETRY * 2));
    }
}
