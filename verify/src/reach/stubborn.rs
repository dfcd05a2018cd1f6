//! Stubborn sets for place/transition nets: the partial-order reduction behind
//! `petrel verify FILE.pnml --deadlocks`.
//!
//! In a marking M, a set S of transitions is *stubborn* (Valmari's deadlock-preserving
//! conditions) when
//!
//! - **D1**: for an enabled `t` in S, no transition outside S can disable `t` or be disabled by
//!   it: every transition that takes tokens from an input place of `t` is in S. Then `t`
//!   commutes with any sequence of transitions outside S.
//! - **D1'**: for a disabled `t` in S, some input place `p` of `t` (its *scapegoat*) lacks
//!   tokens in M, and every transition that puts more tokens into `p` than it takes is in S:
//!   nothing outside S can enable `t`.
//! - **D2**: S holds an enabled transition (every enabled `t` of S is then a key transition by
//!   D1: nothing outside S disables it).
//!
//! Firing, in each marking, only the enabled transitions of a stubborn set reaches every dead
//! marking of the full graph (and only markings of it): a path to a dead marking can be reordered
//! to start with one of them. So the reduced exploration decides deadlock exactly and counts the
//! same dead markings. It does not decide bounds or safety: a marking the reduced exploration
//! skips may hold more tokens. A bound it does find (two tokens in a place, a covering) is real.
//!
//! The set is found as Valmari does: the relation "t needs u" (D1 for an enabled `t`, D1' with
//! the scapegoat of fewest producers for a disabled one) is a graph over the transitions, the
//! closure of any transition is a stubborn set once it holds an enabled one, and Tarjan's
//! algorithm, started from the enabled transitions, completes the strongly connected components
//! bottom first. The first completed component with an enabled transition is the answer: every
//! component below it has none, so its closure's enabled transitions are its own. The search
//! stops there, so a marking costs at most one pass over the part of the graph it visits.

use super::arcs::Arcs;

/// The net's arcs indexed for closures, with the scratch space of one exploration.
pub(crate) struct Stubborn {
    /// `consumers[cons_start[p]..cons_start[p + 1]]`: transitions that take tokens from `p`.
    cons_start: Vec<usize>,
    consumers: Vec<u32>,
    /// Same layout: transitions that put more tokens into `p` than they take from it.
    prod_start: Vec<usize>,
    producers: Vec<u32>,
    /// Stamps per transition, valid when equal to `generation` (one generation a marking):
    /// enabled in the marking, visited by the search, on Tarjan's stack.
    enabled_at: Vec<u32>,
    visited_at: Vec<u32>,
    stacked_at: Vec<u32>,
    generation: u32,
    /// Tarjan's depth-first number and low link of each visited transition.
    number: Vec<u32>,
    low: Vec<u32>,
    /// Tarjan's stack of visited transitions whose component is not complete yet.
    stack: Vec<u32>,
    /// The depth-first search's frames: the transition, and its successors' range in `succ`.
    frames: Vec<Frame>,
    succ: Vec<u32>,
    /// Per transition, how many transitions D1 makes it need when enabled: roots are tried
    /// cheapest first, so a transition in conflict with nothing is taken alone at once.
    weight: Vec<u32>,
    roots: Vec<u32>,
    /// The current window of markings: how many, their enabled and their kept transitions.
    window: (u32, u64, u64),
    /// Work one marking's search may do, and the work done: transitions visited plus what they
    /// need, listed (see [`BUDGET_PER_ENABLED`]).
    budget: usize,
    work: usize,
    /// Markings left to expand in full before trying again (see [`WINDOW`]), and how many
    /// windows in a row did not pay.
    paused: u32,
    failures: u32,
}

/// Markings over which the reduction's saving is measured. Where the sets found keep more than
/// 90 % of the enabled transitions over a window, searching costs more than it saves: the next
/// [`PAUSE`] markings are expanded in full (the whole enabled set is always stubborn), then a
/// window is measured again; each window in a row that does not pay doubles the pause. Deadlocks are preserved either way.
const WINDOW: u32 = 4096;
/// See [`WINDOW`].
const PAUSE: u32 = 60_000;
/// A marking's search gives up (and fires every enabled transition) after this much work per
/// enabled transition (128 at least), a unit being a transition visited or one it needs listed:
/// past that, the search costs more than the firings it could save.
const BUDGET_PER_ENABLED: usize = 16;

/// One transition being searched from.
struct Frame {
    t: u32,
    start: usize,
    next: usize,
}

impl Stubborn {
    /// Indexes the arcs of a net.
    pub(crate) fn new(arcs: &Arcs) -> Self {
        let (places, transitions) = (arcs.places, arcs.transitions);
        let mut cons: Vec<Vec<u32>> = vec![Vec::new(); places];
        let mut prod: Vec<Vec<u32>> = vec![Vec::new(); places];
        for t in 0..transitions {
            for &(p, _) in arcs.pre(t) {
                if let Some(l) = cons.get_mut(p) {
                    l.push(t as u32);
                }
            }
            for &(p, put) in arcs.post(t) {
                let take = arcs
                    .pre(t)
                    .iter()
                    .find(|&&(q, _)| q == p)
                    .map_or(0, |&(_, w)| w);
                if put > take {
                    if let Some(l) = prod.get_mut(p) {
                        l.push(t as u32);
                    }
                }
            }
        }
        let flatten = |lists: Vec<Vec<u32>>| {
            let mut start = Vec::with_capacity(lists.len() + 1);
            let mut flat = Vec::new();
            start.push(0);
            for l in lists {
                flat.extend(l);
                start.push(flat.len());
            }
            (start, flat)
        };
        let (cons_start, consumers) = flatten(cons);
        let (prod_start, producers) = flatten(prod);
        let weight = (0..transitions)
            .map(|t| {
                arcs.pre(t)
                    .iter()
                    .map(|&(p, _)| range(&cons_start, consumers.len(), p).len() as u32)
                    .sum()
            })
            .collect();
        Stubborn {
            cons_start,
            consumers,
            prod_start,
            producers,
            enabled_at: vec![0; transitions],
            visited_at: vec![0; transitions],
            stacked_at: vec![0; transitions],
            generation: 0,
            number: vec![0; transitions],
            low: vec![0; transitions],
            stack: Vec::new(),
            frames: Vec::new(),
            succ: Vec::new(),
            weight,
            roots: Vec::new(),
            window: (0, 0, 0),
            paused: 0,
            failures: 0,
            budget: 0,
            work: 0,
        }
    }

    /// Narrows `enabled` (every transition enabled in the marking whose token counts `tokens`
    /// gives) to the enabled transitions of a stubborn set.
    pub(crate) fn reduce(
        &mut self,
        arcs: &Arcs,
        enabled: &mut Vec<u32>,
        tokens: impl Fn(usize) -> u64,
    ) {
        if enabled.len() < 2 {
            return;
        }
        if self.paused > 0 {
            self.paused -= 1;
            return;
        }
        let before = enabled.len();
        self.narrow(arcs, enabled, tokens);
        let (n, all, kept) = &mut self.window;
        *n += 1;
        *all += before as u64;
        *kept += enabled.len() as u64;
        if *n == WINDOW {
            if *kept * 10 > *all * 9 {
                // Each window in a row that does not pay doubles the pause.
                self.paused = PAUSE.saturating_mul(1 << self.failures.min(10));
                self.failures += 1;
            } else {
                self.failures = 0;
            }
            self.window = (0, 0, 0);
        }
    }

    /// [`Self::reduce`]'s search, on a marking with two enabled transitions or more.
    fn narrow(&mut self, arcs: &Arcs, enabled: &mut Vec<u32>, tokens: impl Fn(usize) -> u64) {
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // The stamps wrapped: clear them so no stale stamp matches.
            for v in [
                &mut self.enabled_at,
                &mut self.visited_at,
                &mut self.stacked_at,
            ] {
                v.iter_mut().for_each(|s| *s = 0);
            }
            self.generation = 1;
        }
        let generation = self.generation;
        for &t in enabled.iter() {
            if let Some(s) = self.enabled_at.get_mut(t as usize) {
                *s = generation;
            }
        }
        self.stack.clear();
        let mut counter = 0u32;
        self.budget = (BUDGET_PER_ENABLED * enabled.len()).max(128);
        self.work = 0;
        let mut roots = std::mem::take(&mut self.roots);
        roots.clear();
        roots.extend_from_slice(enabled);
        roots.sort_unstable_by_key(|&t| self.weight.get(t as usize).copied().unwrap_or(0));
        let mut found = None;
        for &root in &roots {
            if self.visited_at.get(root as usize) == Some(&generation) {
                continue;
            }
            found = self.search(arcs, root, &mut counter, &tokens);
            if found.is_some() || self.work >= self.budget {
                break;
            }
        }
        self.roots = roots;
        // Without a component (the budget ran out), `enabled` stays whole: always stubborn.
        if let Some(at) = found {
            enabled.clear();
            enabled.extend_from_slice(&self.stack[at..]);
            enabled.retain(|&t| self.enabled_at.get(t as usize) == Some(&generation));
        }
    }

    /// Tarjan's search from `root`. Stops at the first completed component with an enabled
    /// transition and returns where it starts on `stack`.
    fn search(
        &mut self,
        arcs: &Arcs,
        root: u32,
        counter: &mut u32,
        tokens: &impl Fn(usize) -> u64,
    ) -> Option<usize> {
        let generation = self.generation;
        self.frames.clear();
        self.succ.clear();
        self.enter(arcs, root, counter, tokens);
        while let Some(frame) = self.frames.last_mut() {
            let v = frame.t as usize;
            if let Some(&w) = self.succ.get(frame.next) {
                frame.next += 1;
                let wi = w as usize;
                if self.visited_at.get(wi) != Some(&generation) {
                    if self.work >= self.budget {
                        // Searching further costs more than firing everything would.
                        return None;
                    }
                    self.enter(arcs, w, counter, tokens);
                } else if self.stacked_at.get(wi) == Some(&generation) {
                    self.low[v] = self.low[v].min(self.number[wi]);
                }
                continue;
            }
            let start = frame.start;
            self.frames.pop();
            self.succ.truncate(start);
            if let Some(parent) = self.frames.last() {
                let p = parent.t as usize;
                self.low[p] = self.low[p].min(self.low[v]);
            }
            if self.low[v] == self.number[v] {
                // `v` roots a component: the stack above it, `v` included.
                let at = self
                    .stack
                    .iter()
                    .rposition(|&x| x as usize == v)
                    .unwrap_or(0);
                if self.stack[at..]
                    .iter()
                    .any(|&x| self.enabled_at.get(x as usize) == Some(&generation))
                {
                    return Some(at);
                }
                for &x in &self.stack[at..] {
                    self.stacked_at[x as usize] = 0;
                }
                self.stack.truncate(at);
            }
        }
        None
    }

    /// Visits `t`: numbers it, stacks it, and lists what it needs as a new frame.
    fn enter(&mut self, arcs: &Arcs, t: u32, counter: &mut u32, tokens: &impl Fn(usize) -> u64) {
        let ti = t as usize;
        let generation = self.generation;
        self.visited_at[ti] = generation;
        self.stacked_at[ti] = generation;
        self.number[ti] = *counter;
        self.low[ti] = *counter;
        *counter += 1;
        self.stack.push(t);
        let start = self.succ.len();
        let pre = arcs.pre(ti);
        if self.enabled_at[ti] == generation {
            // D1: whatever takes from an input place of `t`.
            for &(p, _) in pre {
                let r = range(&self.cons_start, self.consumers.len(), p);
                self.succ.extend_from_slice(&self.consumers[r]);
            }
        } else {
            // D1': whatever adds to the scapegoat, the short input place with fewest producers.
            let mut scapegoat: Option<(usize, usize)> = None;
            for &(p, w) in pre {
                if tokens(p) < w {
                    let n = range(&self.prod_start, self.producers.len(), p).len();
                    if scapegoat.is_none_or(|(_, best)| n < best) {
                        scapegoat = Some((p, n));
                    }
                }
            }
            if let Some((p, _)) = scapegoat {
                let r = range(&self.prod_start, self.producers.len(), p);
                self.succ.extend_from_slice(&self.producers[r]);
            }
        }
        self.work += 1 + self.succ.len() - start;
        self.frames.push(Frame {
            t,
            start,
            next: start,
        });
    }
}

/// The range of place `p`'s list in a flattened index.
fn range(start: &[usize], len: usize, p: usize) -> std::ops::Range<usize> {
    match (start.get(p), start.get(p + 1)) {
        (Some(&a), Some(&b)) if a <= b && b <= len => a..b,
        _ => 0..0,
    }
}
