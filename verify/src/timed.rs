//! Timed exploration (`petrel verify --timed`): a zone over the running timers' clocks beside
//! each stable state, so that timers expire in the order their durations impose while outside
//! events stay free (docs/verification.md, "Timed verification").
//!
//! Each timer has a clock, reset when a transition starts it. A running timer with a literal
//! duration `d` (milliseconds) expires exactly when its clock reaches `d`: time cannot pass it
//! (the invariant `x <= d`), and its event comes then (the guard `x = d`). A timer started with
//! a duration read from a parameter is **untimed**: its expiry may come at any moment, as in the
//! untimed analysis. The set of clock values a state may be entered with, after any delay, is a
//! convex zone, kept as a canonical difference-bound matrix (DBM): entry `(i, j)` bounds
//! `x_i - x_j`, clock 0 is the reference (always 0). Every constraint the model makes is
//! non-strict with an integer constant (`x <= d`, `x = d`, `x := 0`), so the bounds need no
//! strictness flag, and every clock of a running timed timer stays at most its duration, so
//! the zones are finitely many without extrapolation. A clock whose timer does not run, or runs
//! untimed, is pinned to the reference (a copy of row and column 0), so equal states have equal
//! words.
//!
//! The zone is stored after the state's words: one word per timer for its duration (or
//! [`IDLE`], [`UNTIMED`]), then the matrix, row by row, each bound as an `i64`.

use petrel_nets::compiled::{CompiledProject, TimerDuration, TimerId};
use petrel_nets::semantics::Layout;

/// Duration word of a timer that does not run.
const IDLE: u64 = u64::MAX;
/// Duration word of a timer that runs with a duration not known statically.
const UNTIMED: u64 = u64::MAX - 1;
/// No bound.
pub(super) const INF: i64 = i64::MAX / 4;

/// What a step did to the timers, in order: `Some(duration)` for a start, `None` for a cancel.
pub(super) type TimerOps = Vec<(TimerId, Option<TimerDuration>)>;

/// The zone layout of a project: where the words go, and the timers' events.
pub(super) struct Timing {
    /// Words of the untimed state (the zone starts there).
    pub base: usize,
    /// Number of timers.
    n: usize,
    /// 1 when the zone has an observer's clock after the timers' (a time bound's, reset when
    /// its `from` happens, never bounded: [`super::bound`]), else 0.
    observer: usize,
}

impl Timing {
    /// The zone layout for `p`, after `base` words of untimed state.
    pub fn new(p: &CompiledProject, base: usize) -> Timing {
        Timing {
            base,
            n: p.timers.len(),
            observer: 0,
        }
    }

    /// The same layout with an observer's clock (the last one).
    pub fn with_observer(p: &CompiledProject, base: usize) -> Timing {
        Timing {
            observer: 1,
            ..Timing::new(p, base)
        }
    }

    /// Words a timed state takes.
    pub fn words(&self) -> usize {
        self.base + self.n + self.dim() * self.dim()
    }

    fn dim(&self) -> usize {
        self.n + 1 + self.observer
    }

    fn dur(&self, s: &[u64], k: usize) -> u64 {
        s[self.base + k]
    }

    fn at(&self, s: &[u64], i: usize, j: usize) -> i64 {
        s[self.base + self.n + i * self.dim() + j] as i64
    }

    fn put(&self, s: &mut [u64], i: usize, j: usize, v: i64) {
        let at = self.base + self.n + i * self.dim() + j;
        s[at] = v as u64;
    }

    /// Clock of timer `k` is tracked: the timer runs with a known duration.
    fn tracked(&self, s: &[u64], k: usize) -> bool {
        self.dur(s, k) < UNTIMED
    }

    /// The zone of a start: every timer idle, every clock 0. Timers already running in `s`
    /// (a reload's state) run untimed: their remaining time is not known.
    pub fn init(&self, l: &Layout, s: &mut Vec<u64>) {
        s.resize(self.words(), 0);
        for k in 0..self.n {
            s[self.base + k] = if l.timer_running(s, k as TimerId) {
                UNTIMED
            } else {
                IDLE
            };
        }
        for i in 0..self.dim() {
            for j in 0..self.dim() {
                self.put(s, i, j, 0);
            }
        }
    }

    /// Timer `k`'s event may come in `s`: it runs untimed, or its clock can reach its duration.
    pub fn may_expire(&self, l: &Layout, s: &[u64], k: usize) -> bool {
        if !l.timer_running(s, k as TimerId) {
            return false;
        }
        match self.dur(s, k) {
            IDLE | UNTIMED => true,
            d => self.at(s, k + 1, 0) >= d as i64,
        }
    }

    /// The zone after a step from a state whose zone is in `t` (the step's untimed result is
    /// already in `t`'s first words): timer `expired` expired (its clock at its duration), the
    /// step ran `ops`, then time may pass until the earliest deadline.
    pub fn step(&self, l: &Layout, t: &mut [u64], expired: Option<usize>, ops: &TimerOps) {
        self.apply(l, t, expired, ops);
        self.elapse(t);
    }

    /// The zone at the instant of a step ([`Timing::step`] without the time that passes
    /// after it).
    pub fn apply(&self, l: &Layout, t: &mut [u64], expired: Option<usize>, ops: &TimerOps) {
        if let Some(k) = expired {
            if self.tracked(t, k) {
                // x_k >= d: with x_k <= d, the clock is at its duration.
                let d = self.dur(t, k) as i64;
                self.put(t, 0, k + 1, -d);
                self.close(t);
            }
            t[self.base + k] = IDLE;
            self.pin(t, k);
        }
        for (k, op) in ops {
            let k = *k as usize;
            match op {
                Some(TimerDuration::Millis(ms)) => {
                    t[self.base + k] = (*ms).min(INF as u64 / 4);
                    // Reset: x_k = 0, i.e. a copy of the reference clock.
                    self.pin(t, k);
                }
                Some(_) => {
                    t[self.base + k] = UNTIMED;
                    self.pin(t, k);
                }
                None => {
                    t[self.base + k] = IDLE;
                    self.pin(t, k);
                }
            }
        }
        // The untimed state says which timers run (a deactivation does not stop them; an
        // expiry of another timer with the same event does).
        for k in 0..self.n {
            let running = l.timer_running(t, k as TimerId);
            if !running && self.dur(t, k) != IDLE {
                t[self.base + k] = IDLE;
                self.pin(t, k);
            } else if running && self.dur(t, k) == IDLE {
                t[self.base + k] = UNTIMED;
            }
        }
    }

    /// Time passes after a step: every clock grows alike, up to the earliest deadline.
    pub fn elapse(&self, t: &mut [u64]) {
        // Time passes: no upper bound on any clock (the pinned ones advance with the others,
        // and are pinned again below), but the tracked clocks' durations.
        for k in 0..self.n {
            let d = if self.tracked(t, k) {
                self.dur(t, k) as i64
            } else {
                INF
            };
            self.put(t, k + 1, 0, d);
        }
        if self.observer == 1 {
            self.put(t, self.n + 1, 0, INF);
        }
        self.close(t);
        for k in 0..self.n {
            if !self.tracked(t, k) {
                self.pin(t, k);
            }
        }
    }

    /// Clock `k` equal to the reference clock (reset, or not tracked).
    fn pin(&self, t: &mut [u64], k: usize) {
        let c = k + 1;
        for j in 0..self.dim() {
            let v = self.at(t, 0, j);
            self.put(t, c, j, v);
            let v = self.at(t, j, 0);
            self.put(t, j, c, v);
        }
        self.put(t, c, c, 0);
    }

    /// Canonical form: the tightest bounds (Floyd-Warshall over the constraints' graph).
    fn close(&self, t: &mut [u64]) {
        let n = self.dim();
        for k in 0..n {
            for i in 0..n {
                let ik = self.at(t, i, k);
                if ik >= INF {
                    continue;
                }
                for j in 0..n {
                    let kj = self.at(t, k, j);
                    if kj >= INF {
                        continue;
                    }
                    if ik + kj < self.at(t, i, j) {
                        self.put(t, i, j, ik + kj);
                    }
                }
            }
        }
    }

    /// The observer's clock starts now (`x := 0`).
    pub fn observer_reset(&self, t: &mut [u64]) {
        debug_assert_eq!(self.observer, 1);
        self.pin(t, self.n);
    }

    /// The least and greatest values (milliseconds) of the observer's clock in `t`.
    pub fn observer_range(&self, t: &[u64]) -> (i64, i64) {
        let c = self.n + 1;
        (-self.at(t, 0, c), self.at(t, c, 0))
    }

    /// State `s` of the layout `plain` (no observer) with an observer's clock, pinned to the
    /// reference.
    pub fn extend(&self, plain: &Timing, s: &[u64]) -> Vec<u64> {
        let mut t = s[..self.base + self.n].to_vec();
        t.resize(self.words(), 0);
        for i in 0..plain.dim() {
            for j in 0..plain.dim() {
                self.put(&mut t, i, j, plain.at(s, i, j));
            }
        }
        self.pin(&mut t, self.n);
        t
    }

    /// Every clock at 0: the zone at the instant of a start.
    pub fn at_start(&self, t: &mut [u64]) {
        for i in 0..self.dim() {
            for j in 0..self.dim() {
                self.put(t, i, j, 0);
            }
        }
    }

    /// Some timer with a known duration runs in `s`: time cannot pass beyond its deadline.
    pub fn has_deadline(&self, s: &[u64]) -> bool {
        (0..self.n).any(|k| self.tracked(s, k))
    }

    /// The timers that run in `s` with a duration not known statically.
    pub fn untimed_running(&self, s: &[u64]) -> Vec<usize> {
        (0..self.n).filter(|&k| self.dur(s, k) == UNTIMED).collect()
    }

    /// The longest literal duration among the timers running in `s` (0 if none).
    pub fn longest(&self, s: &[u64]) -> i64 {
        (0..self.n)
            .filter(|&k| self.tracked(s, k))
            .map(|k| self.dur(s, k) as i64)
            .max()
            .unwrap_or(0)
    }

    /// The least and greatest values (milliseconds since the timer started) of timer `k`'s
    /// clock in `s`, when it is tracked.
    pub fn clock(&self, s: &[u64], k: usize) -> Option<(i64, i64)> {
        self.tracked(s, k)
            .then(|| (-self.at(s, 0, k + 1), self.at(s, k + 1, 0)))
    }

    /// The timer whose event is `event`, if it is a timer's.
    pub fn timer_of(p: &CompiledProject, event: petrel_nets::compiled::EventId) -> Option<usize> {
        p.timers.iter().position(|t| t.event == event)
    }

    /// For people: each tracked timer's clock range (`timer T at 0..600s of 600s`).
    pub fn describe(&self, p: &CompiledProject, s: &[u64]) -> Vec<String> {
        let mut out = Vec::new();
        if s.len() < self.words() {
            return out;
        }
        for k in 0..self.n {
            if let Some((lo, hi)) = self.clock(s, k) {
                out.push(format!(
                    "timer {} clock in [{}, {}] of {}",
                    p.timers[k].name,
                    ms(lo),
                    ms(hi),
                    ms(self.dur(s, k) as i64)
                ));
            }
        }
        out
    }
}

/// Milliseconds for people: `600s`, `1.5s`, `200ms`.
pub(super) fn ms(v: i64) -> String {
    if v >= INF {
        "inf".into()
    } else if v % 1000 == 0 {
        format!("{}s", v / 1000)
    } else {
        format!("{v}ms")
    }
}
