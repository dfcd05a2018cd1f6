//! Counts: any net, one unsigned count per place (8 bits first; a count that no longer fits
//! starts the search again with 16, then 32, then 64 bits).
//!
//! An unbounded net has no finite graph. Whenever a stored marking sets a record for the tokens
//! in one marking (within a work budget) and whenever a count overflows, the marking is compared
//! with its ancestors on the breadth-first tree: a marking that strictly covers an ancestor
//! proves the net unbounded (the firings between them can be repeated forever, each time adding
//! tokens), and the search stops with that witness.

use super::arcs::Arcs;
use super::search::{path, Marking, Tree};
use super::table::mix;
use super::{ExploreError, PtReport, Representation, Trace, UnboundedWitness, UnsafeWitness};

/// A token count stored per place.
pub(super) trait Count: Copy + Eq + Default + Into<u64> + TryFrom<u64> + 'static {
    const BITS: u32;
}

impl Count for u8 {
    const BITS: u32 = 8;
}
impl Count for u16 {
    const BITS: u32 = 16;
}
impl Count for u32 {
    const BITS: u32 = 32;
}
impl Count for u64 {
    const BITS: u32 = 64;
}

/// A net compiled for counts.
pub(super) struct CountNet {
    /// `(place, weight)` inputs per transition, as in [`Arcs`].
    pre_start: Vec<usize>,
    pre: Vec<(usize, u64)>,
    /// `(place, taken, produced)` per transition: every place a firing changes or tests.
    effect_start: Vec<usize>,
    effects: Vec<(usize, u64, u64)>,
    /// As in [`BitNet`]: transitions to test when a place is marked, and sources.
    index_start: Vec<usize>,
    index: Vec<u32>,
    sources: Vec<u32>,
}

impl CountNet {
    pub(super) fn new(c: &Arcs) -> Self {
        let mut effect_start = vec![0];
        let mut effects = Vec::new();
        let mut by_place: Vec<Vec<u32>> = vec![Vec::new(); c.places];
        let mut sources = Vec::new();
        for t in 0..c.transitions {
            let mut e: Vec<(usize, u64, u64)> = c.pre(t).iter().map(|&(p, w)| (p, w, 0)).collect();
            for &(p, w) in c.post(t) {
                match e.iter_mut().find(|x| x.0 == p) {
                    Some(x) => x.2 = w,
                    None => e.push((p, 0, w)),
                }
            }
            effects.extend(e);
            effect_start.push(effects.len());
            // Index by the input place needing the most tokens: the rarest to be enabling.
            match c.pre(t).iter().max_by_key(|&&(_, w)| w) {
                Some(&(p, _)) => by_place[p].push(t as u32),
                None => sources.push(t as u32),
            }
        }
        let mut index_start = vec![0];
        let mut index = Vec::new();
        for l in by_place {
            index.extend(l);
            index_start.push(index.len());
        }
        CountNet {
            pre_start: c.pre_start.clone(),
            pre: c.pre.clone(),
            effect_start,
            effects,
            index_start,
            index,
            sources,
        }
    }

    fn pre(&self, t: usize) -> &[(usize, u64)] {
        &self.pre[self.pre_start[t]..self.pre_start[t + 1]]
    }

    fn effects(&self, t: usize) -> &[(usize, u64, u64)] {
        &self.effects[self.effect_start[t]..self.effect_start[t + 1]]
    }

    fn enabled<C: Count>(&self, t: usize, cur: &[C]) -> bool {
        self.pre(t)
            .iter()
            .all(|&(p, w)| cur.get(p).is_some_and(|&x| x.into() >= w))
    }

    /// Fires an enabled transition from `cur` into `next`. Returns the hash change, or the place
    /// whose count no longer fits in `C`.
    #[inline]
    fn fire<C: Count>(&self, t: usize, cur: &[C], next: &mut [C]) -> Result<u64, usize> {
        next.copy_from_slice(cur);
        let mut delta = 0;
        for &(p, take, put) in self.effects(t) {
            let (Some(&old), Some(slot)) = (cur.get(p), next.get_mut(p)) else {
                continue;
            };
            let old: u64 = old.into();
            let new = old
                .checked_sub(take)
                .and_then(|v| v.checked_add(put))
                .and_then(|v| C::try_from(v).ok());
            match new {
                Some(v) => {
                    *slot = v;
                    delta ^= mix(p, old) ^ mix(p, v.into());
                }
                None => return Err(p),
            }
        }
        Ok(delta)
    }

    /// The marking after firing `t` from `cur`, in 64 bits saturated: the overflowing successor
    /// that `fire` could not store, for the covering check. Saturation only lowers counts, so a
    /// covering found on it holds for the real marking.
    fn fire_wide<C: Count>(&self, t: usize, cur: &[C]) -> Vec<u64> {
        let mut m: Vec<u64> = cur.iter().map(|&x| x.into()).collect();
        for &(p, take, put) in self.effects(t) {
            if let Some(x) = m.get_mut(p) {
                *x = x.saturating_sub(take).saturating_add(put);
            }
        }
        m
    }
}

/// Looks for an ancestor of `candidate` on the breadth-first tree, starting at `from`, that
/// `candidate` strictly covers. Returns it and a place where `candidate` has more tokens. Stops
/// early (finding nothing, which is always sound) once `budget` place comparisons are spent.
fn covered_ancestor<C: Count>(
    tree: &Tree<'_, C>,
    candidate: &[u64],
    from: usize,
    budget: &mut u64,
) -> Option<(usize, usize)> {
    let stride = tree.stride;
    let mut s = from;
    loop {
        if *budget < stride as u64 {
            return None;
        }
        *budget -= stride as u64;
        let a = tree.marking(s)?;
        let mut greater = None;
        let covers = a.iter().zip(candidate).enumerate().all(|(p, (&x, &y))| {
            let x: u64 = x.into();
            if y > x && greater.is_none() {
                greater = Some(p);
            }
            y >= x
        });
        if let (true, Some(p)) = (covers, greater) {
            return Some((s, p));
        }
        if s == 0 {
            return None;
        }
        match tree.parents.get(s) {
            Some(&p) if (p as usize) < s => s = p as usize,
            _ => return None,
        }
    }
}

/// The counts representation with `C` a count.
pub(super) struct Counts<C> {
    net: CountNet,
    /// Tokens per place in the initial marking.
    initial: Vec<u64>,
    places: usize,
    transitions: usize,
    /// Bounds and the first unsafe marking, measured as states are stored.
    max_place: u64,
    max_total: u64,
    first_unsafe: Option<(usize, usize, u64)>,
    /// The most tokens in one stored marking so far: beating it triggers a covering check.
    record: u64,
    /// Place comparisons the covering checks may still spend: rationed to a few times the work
    /// of storing states, so bounded nets with many tokens do not pay much for them.
    budget: u64,
    _count: std::marker::PhantomData<C>,
}

impl<C: Count> Counts<C> {
    pub(super) fn new(arcs: &Arcs) -> Self {
        Counts {
            net: CountNet::new(arcs),
            initial: arcs.initial.clone(),
            places: arcs.places,
            transitions: arcs.transitions,
            max_place: 0,
            max_total: 0,
            first_unsafe: None,
            record: 0,
            budget: 1 << 22,
            _count: std::marker::PhantomData,
        }
    }

    /// The unboundedness error: `ancestor` is strictly covered by the marking reached from
    /// `end` (by firing `last` from it, when the covering marking could not be stored).
    fn unbounded(
        &self,
        tree: &Tree<'_, C>,
        ancestor: usize,
        end: usize,
        last: Option<usize>,
        place: usize,
    ) -> ExploreError {
        let prefix = path(self, self.transitions, tree, 0, ancestor).unwrap_or_default();
        let mut pump = path(self, self.transitions, tree, ancestor, end).unwrap_or_default();
        pump.extend(last);
        ExploreError::Unbounded(Box::new(UnboundedWitness {
            place,
            prefix: Trace {
                transitions: prefix,
            },
            pump: Trace { transitions: pump },
            states_so_far: tree.states() as u64,
        }))
    }
}

impl<C: Count> Marking for Counts<C> {
    type Word = C;
    const REPRESENTATION: Representation = Representation::Counts { bits: C::BITS };
    const STORES_BEFORE_OVERFLOW: bool = true;

    #[inline(always)]
    fn stride(&self) -> usize {
        self.places.max(1)
    }

    fn initial(&self) -> Option<Vec<C>> {
        let mut init = vec![C::default(); self.stride()];
        for (slot, &m) in init.iter_mut().zip(&self.initial) {
            // The caller picked a width that holds the initial marking; be total anyway.
            *slot = C::try_from(m).ok()?;
        }
        Some(init)
    }

    fn keeps_parents(&self, _: bool) -> bool {
        // The covering proof walks the tree.
        true
    }

    #[inline(always)]
    fn enabled(&self, cur: &[C], out: &mut Vec<u32>) {
        let cn = &self.net;
        for (p, &x) in cur.iter().enumerate() {
            if x == C::default() {
                continue;
            }
            if let (Some(&a), Some(&b)) = (cn.index_start.get(p), cn.index_start.get(p + 1)) {
                for &t in &cn.index[a..b] {
                    if cn.enabled(t as usize, cur) {
                        out.push(t);
                    }
                }
            }
        }
        out.extend_from_slice(&cn.sources);
    }

    fn is_enabled(&self, t: usize, cur: &[C]) -> bool {
        self.net.enabled(t, cur)
    }

    #[inline(always)]
    fn tokens(cur: &[C], p: usize) -> u64 {
        cur.get(p).map_or(0, |&x| x.into())
    }

    #[inline(always)]
    fn fire(&self, t: usize, cur: &[C], next: &mut [C]) -> Result<u64, usize> {
        self.net.fire(t, cur, next)
    }

    #[inline(always)]
    fn expanded(&mut self) {
        // Earn covering budget with ordinary work.
        self.budget = self.budget.saturating_add(self.stride() as u64);
    }

    fn stored(
        &mut self,
        tree: &Tree<'_, C>,
        state: usize,
        parent: usize,
    ) -> Result<(), ExploreError> {
        let Some(m) = tree.marking(state) else {
            return Ok(());
        };
        let mut total = 0u64;
        for (p, &x) in m.iter().enumerate() {
            let x: u64 = x.into();
            total = total.saturating_add(x);
            self.max_place = self.max_place.max(x);
            if x > 1 && self.first_unsafe.is_none() {
                self.first_unsafe = Some((state, p, x));
            }
        }
        self.max_total = self.max_total.max(total);
        if total <= self.record {
            return Ok(());
        }
        self.record = total;
        if state == 0 {
            return Ok(());
        }
        self.budget = self.budget.saturating_add(8 * self.stride() as u64);
        let wide: Vec<u64> = m.iter().map(|&x| x.into()).collect();
        let mut budget = self.budget;
        let found = covered_ancestor(tree, &wide, parent, &mut budget);
        self.budget = budget;
        match found {
            Some((a, p)) => Err(self.unbounded(tree, a, state, None, p)),
            None => Ok(()),
        }
    }

    fn overflow(
        &mut self,
        tree: &Tree<'_, C>,
        state: usize,
        t: usize,
        place: usize,
    ) -> Result<(), ExploreError> {
        // A count outgrew `C`: either the net is unbounded (and a covering shows it), or it
        // needs wider counts.
        let Some(cur) = tree.marking(state) else {
            return Ok(());
        };
        let wide = self.net.fire_wide(t, cur);
        let mut all = u64::MAX;
        if let Some((a, p)) = covered_ancestor(tree, &wide, state, &mut all) {
            return Err(self.unbounded(tree, a, state, Some(t), p));
        }
        if C::BITS == 64 {
            return Err(ExploreError::TokenOverflow {
                place,
                states_so_far: tree.states() as u64,
            });
        }
        Ok(())
    }

    fn conclude(&self, report: &mut PtReport, trace: &dyn Fn(usize) -> Option<Trace>) {
        report.max_tokens_in_place = self.max_place;
        report.max_tokens_per_marking = self.max_total;
        report.safe = self.max_place <= 1;
        report.first_unsafe = self.first_unsafe.map(|(s, place, tokens)| UnsafeWitness {
            place,
            tokens,
            trace: trace(s),
        });
    }
}
