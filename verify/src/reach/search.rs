//! The one breadth-first exploration of the P/T explorer, generic over how a marking is stored
//! ([`Marking`]: one bit per place in `bits`, one count per place in `counts`).
//!
//! The loop is written once: the arena of markings (also the queue), the parents, the table
//! with its batched lookups ([`StateTable::touch`]), the limits and out-of-memory, the dead
//! markings, the stubborn-set reduction, the edges and the progress ticks. A representation
//! says how to find the enabled transitions and fire one, and hooks in where it needs to: the
//! bits re-index their transitions after a sample of states (`before_expand`), the counts
//! measure each stored marking and look for a covering of an ancestor (`stored`, `overflow`).

use super::arcs::Arcs;
use super::stubborn::Stubborn;
use super::table::{hash, tree_path, StateTable};
use super::{ExploreError, Progress, PtReport, Representation, Trace};
use std::time::Instant;

/// The store names states by `u32` positions; the last value is kept free so a position plus one
/// never wraps.
pub(super) const MAX_STORE_STATES: u32 = u32::MAX - 1;

/// A way to store markings, and to enable and fire transitions on them.
pub(super) trait Marking {
    /// What a marking is made of: [`Marking::stride`] of them per marking.
    type Word: Copy + Default + Eq + Into<u64>;
    /// How the report names this representation.
    const REPRESENTATION: Representation;
    /// Whether the successors fired before one that does not fit are stored (and measured)
    /// before [`Marking::overflow`] is asked; otherwise the expansion stops at once.
    const STORES_BEFORE_OVERFLOW: bool;

    /// Words per marking.
    fn stride(&self) -> usize;
    /// The initial marking, or `None` when it does not fit this representation.
    fn initial(&self) -> Option<Vec<Self::Word>>;
    /// Whether the search keeps a parent per state: for traces, or because the representation
    /// needs the tree itself (the covering proof of counts).
    fn keeps_parents(&self, keep_traces: bool) -> bool;
    /// Appends to `out` the transitions enabled in `cur`.
    fn enabled(&self, cur: &[Self::Word], out: &mut Vec<u32>);
    /// Whether transition `t` is enabled in `cur`.
    fn is_enabled(&self, t: usize, cur: &[Self::Word]) -> bool;
    /// The tokens of place `p` in `cur` (for the stubborn sets).
    fn tokens(cur: &[Self::Word], p: usize) -> u64;
    /// Fires the enabled transition `t` from `cur` into `next`: the change to the marking's
    /// hash, or the place whose tokens no longer fit this representation.
    fn fire(&self, t: usize, cur: &[Self::Word], next: &mut [Self::Word]) -> Result<u64, usize>;
    /// Whether two markings are equal.
    #[inline(always)]
    fn same(a: &[Self::Word], b: &[Self::Word]) -> bool {
        a == b
    }
    /// Called before each state is expanded, with the states stored so far.
    #[inline(always)]
    fn before_expand(&mut self, _arena: &[Self::Word], _states: usize) {}
    /// Called after each state is expanded.
    #[inline(always)]
    fn expanded(&mut self) {}
    /// Called when state `state` is stored (the initial one included), `parent` being the state
    /// expanded: an error ends the exploration.
    fn stored(
        &mut self,
        tree: &Tree<'_, Self::Word>,
        state: usize,
        parent: usize,
    ) -> Result<(), ExploreError>;
    /// Firing `t` from `state` put more tokens in `place` than this representation holds: an
    /// error ends the exploration, `Ok` starts it again with a wider representation.
    fn overflow(
        &mut self,
        tree: &Tree<'_, Self::Word>,
        state: usize,
        t: usize,
        place: usize,
    ) -> Result<(), ExploreError>;
    /// Fills in the report's bounds and safety, with `trace` giving the shortest firing
    /// sequence to a state (`None` when traces are not kept).
    fn conclude(&self, report: &mut PtReport, trace: &dyn Fn(usize) -> Option<Trace>);
}

/// The stored states, as hooks see them: markings back to back, in the order found, and the
/// parent of each on the breadth-first tree (empty when parents are not kept).
pub(super) struct Tree<'a, W> {
    pub(super) arena: &'a [W],
    pub(super) parents: &'a [u32],
    pub(super) stride: usize,
}

impl<W> Tree<'_, W> {
    /// The marking of state `s`.
    pub(super) fn marking(&self, s: usize) -> Option<&[W]> {
        self.arena.get(s * self.stride..(s + 1) * self.stride)
    }

    /// How many states are stored.
    pub(super) fn states(&self) -> usize {
        self.arena.len() / self.stride.max(1)
    }
}

/// The transitions along the breadth-first tree from state `from` down to its descendant `to`,
/// each found again by firing the parent's transitions (no transition is stored per state).
pub(super) fn path<M: Marking>(
    m: &M,
    transitions: usize,
    tree: &Tree<'_, M::Word>,
    from: usize,
    to: usize,
) -> Option<Vec<usize>> {
    let path = tree_path(tree.parents, to);
    let at = path.iter().position(|&s| s == from)?;
    let mut next = vec![M::Word::default(); tree.stride];
    let mut out = Vec::with_capacity(path.len());
    for pair in path[at..].windows(2) {
        let (a, b) = (tree.marking(pair[0])?, tree.marking(pair[1])?);
        let t = (0..transitions).find(|&t| {
            m.is_enabled(t, a) && m.fire(t, a, &mut next).is_ok() && M::same(&next, b)
        })?;
        out.push(t);
    }
    Some(out)
}

/// Limits, the progress callback and the clock, shared by every run of one exploration.
pub(super) struct Ctl<'a> {
    /// The effective state limit: the user's or the store's.
    pub(super) limit: u64,
    pub(super) keep_traces: bool,
    pub(super) deadlocks_only: bool,
    pub(super) progress: Option<&'a mut (dyn FnMut(Progress) + 'static)>,
    pub(super) start: Instant,
    pub(super) last: Instant,
}

impl Ctl<'_> {
    /// Reports progress when a second has passed; cheap enough to call per expanded state
    /// because it looks at the clock only every 1024 calls.
    #[inline]
    fn tick(&mut self, states: usize, expanded: usize, edges: u64) {
        if expanded & 1023 != 0 {
            return;
        }
        let Some(cb) = self.progress.as_mut() else {
            return;
        };
        let now = Instant::now();
        if now.duration_since(self.last).as_secs_f64() < 1.0 {
            return;
        }
        self.last = now;
        let seconds = now.duration_since(self.start).as_secs_f64();
        cb(Progress {
            states: states as u64,
            expanded: expanded as u64,
            edges,
            seconds,
            states_per_second: states as f64 / seconds.max(1e-9),
        });
    }

    /// The error for a store about to exceed the limit.
    fn too_many(&self, states: usize) -> ExploreError {
        ExploreError::TooManyStates {
            limit: self.limit,
            states_so_far: states as u64,
        }
    }
}

fn oom(states: usize, store_bytes: usize) -> ExploreError {
    ExploreError::OutOfMemory {
        states_so_far: states as u64,
        store_bytes: store_bytes as u64,
    }
}

/// The stored markings: the arena (markings back to back, also the breadth-first queue), the
/// parents and the table that deduplicates.
struct Store<W> {
    arena: Vec<W>,
    parents: Vec<u32>,
    table: StateTable,
    keep_parents: bool,
}

impl<W: Copy + Into<u64>> Store<W> {
    fn bytes(&self) -> usize {
        self.arena.capacity() * std::mem::size_of::<W>()
            + self.parents.capacity() * 4
            + self.table.bytes()
    }

    /// Stores marking `m` (absent, its hash `h` leading to the empty `slot`) as state `n`,
    /// child of `parent`.
    #[inline(always)]
    fn push(
        &mut self,
        slot: usize,
        h: u64,
        m: &[W],
        n: usize,
        parent: usize,
    ) -> Result<(), ExploreError> {
        if self.arena.try_reserve(m.len()).is_err()
            || (self.keep_parents && self.parents.try_reserve(1).is_err())
        {
            return Err(oom(n, self.bytes()));
        }
        self.table.insert_at(slot, h, n as u32);
        self.arena.extend_from_slice(m);
        if self.keep_parents {
            self.parents.push(parent as u32);
        }
        if self.table.full() && self.table.grow().is_err() {
            return Err(oom(n + 1, self.bytes()));
        }
        Ok(())
    }

    fn tree(&self, stride: usize) -> Tree<'_, W> {
        Tree {
            arena: &self.arena,
            parents: &self.parents,
            stride,
        }
    }
}

/// Explores every marking reachable in `arcs`, stored as `m` stores them. Returns `None` when a
/// marking does not fit the representation and [`Marking::overflow`] asks for a wider one.
pub(super) fn search<M: Marking>(
    arcs: &Arcs,
    m: &mut M,
    ctl: &mut Ctl,
) -> Result<Option<PtReport>, ExploreError> {
    let w = m.stride();
    let Some(init) = m.initial() else {
        return Ok(None);
    };
    let mut store = Store {
        arena: Vec::new(),
        parents: Vec::new(),
        table: StateTable::new().map_err(|_| oom(0, 0))?,
        keep_parents: m.keeps_parents(ctl.keep_traces),
    };
    if ctl.limit == 0 {
        return Err(ctl.too_many(0));
    }
    let h0 = hash(&init[..w]);
    if let Err(slot) = store.table.find(h0, |_| false) {
        store.push(slot, h0, &init[..w], 0, 0)?;
    }
    m.stored(&store.tree(w), 0, 0)?;

    let mut cur = vec![M::Word::default(); w];
    let mut succ: Vec<M::Word> = Vec::new();
    let mut hashes: Vec<u64> = Vec::new();
    let mut enabled: Vec<u32> = Vec::new();
    let (mut n, mut i) = (1usize, 0usize);
    let mut edges = 0u64;
    let mut dead = 0u64;
    let mut first_dead: Option<usize> = None;
    let mut stubborn = ctl.deadlocks_only.then(|| Stubborn::new(arcs));

    while i < n {
        m.before_expand(&store.arena, n);
        // Slicing to `w` everywhere lets the compiler see a constant length (bits' `N`).
        let cur = &mut cur[..w];
        cur.copy_from_slice(&store.arena[i * w..][..w]);
        let cur = &*cur;
        let h = hash(cur);

        enabled.clear();
        m.enabled(cur, &mut enabled);
        if enabled.is_empty() {
            dead += 1;
            first_dead.get_or_insert(i);
        }
        if let Some(sb) = stubborn.as_mut() {
            sb.reduce(arcs, &mut enabled, |p| M::tokens(cur, p));
        }
        edges += enabled.len() as u64;

        // All successors first, then their lookups: see `StateTable::touch`.
        succ.clear();
        succ.resize(enabled.len() * w, M::Word::default());
        hashes.clear();
        let mut overflow = None;
        for (&t, next) in enabled.iter().zip(succ.chunks_exact_mut(w)) {
            match m.fire(t as usize, cur, &mut next[..w]) {
                Ok(delta) => hashes.push(h ^ delta),
                Err(place) => {
                    overflow = Some((t as usize, place));
                    break;
                }
            }
        }
        if overflow.is_some() && !M::STORES_BEFORE_OVERFLOW {
            return Ok(None);
        }
        store.table.touch(&hashes, &store.arena, w);
        for (&hn, next) in hashes.iter().zip(succ.chunks_exact(w)) {
            let next = &next[..w];
            let arena = &store.arena;
            let slot = match store
                .table
                .find(hn, |j| M::same(&arena[j as usize * w..][..w], next))
            {
                Ok(_) => continue,
                Err(slot) => slot,
            };
            if n as u64 >= ctl.limit {
                return Err(ctl.too_many(n));
            }
            store.push(slot, hn, next, n, i)?;
            n += 1;
            m.stored(&store.tree(w), n - 1, i)?;
        }
        if let Some((t, place)) = overflow {
            m.overflow(&store.tree(w), i, t, place)?;
            return Ok(None);
        }
        m.expanded();
        i += 1;
        ctl.tick(n, i, edges);
    }

    let (m, tree, keep_traces) = (&*m, store.tree(w), ctl.keep_traces);
    let trace = |s: usize| -> Option<Trace> {
        if !keep_traces {
            return None;
        }
        path(m, arcs.transitions, &tree, 0, s).map(|transitions| Trace { transitions })
    };
    let mut report = PtReport {
        states: n as u64,
        edges,
        max_tokens_in_place: 0,
        max_tokens_per_marking: 0,
        safe: true,
        deadlock: dead > 0,
        dead_markings: dead,
        first_deadlock: first_dead.and_then(trace),
        first_unsafe: None,
        seconds: 0.0,
        store_bytes: store.bytes() as u64,
        representation: M::REPRESENTATION,
        reduced: stubborn.is_some(),
    };
    m.conclude(&mut report, &trace);
    Ok(Some(report))
}
