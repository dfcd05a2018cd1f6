//! Bits: safe nets with unit weights, one bit per place (`ceil(places / 64)` words a marking).
//! Each transition is compiled to sparse `(word, pre mask, post mask)` triples, so the enabling
//! test and the firing are a few word operations; transitions are indexed by one input place,
//! the least often marked one over a sample of the first states, and only the transitions
//! indexed by the places of the current marking are tested. The first firing that would put a
//! second token in a place proves the net unsafe: the search stops, to start again with counts.

use super::arcs::Arcs;
use super::search::{Marking, Tree};
use super::table::{mix, words_eq};
use super::{ExploreError, PtReport, Representation, Trace};

/// States sampled before transitions are re-indexed by their least often marked input place.
const INDEX_SAMPLE: usize = 4096;

/// One word of a marking that a transition reads or writes.
#[derive(Clone, Copy, Debug)]
struct Touch {
    word: u32,
    /// Input places in this word: all must be marked, all are emptied.
    pre: u64,
    /// Output places in this word: all are marked after the firing.
    post: u64,
}

/// A safe unit-weight net compiled to word operations.
pub(super) struct BitNet {
    pub(super) words: usize,
    initial: Vec<u64>,
    /// `touches[touch_start[t]..touch_start[t + 1]]`: the words transition `t` touches.
    touch_start: Vec<u32>,
    touches: Vec<Touch>,
    /// `index[index_start[p]..index_start[p + 1]]`: the transitions to test when place `p` is
    /// marked. Each transition with inputs sits under exactly one of its input places.
    index_start: Vec<u32>,
    index: Vec<u32>,
    /// Transitions without input places: enabled in every marking.
    sources: Vec<u32>,
}

impl BitNet {
    pub(super) fn new(c: &Arcs) -> Self {
        let words = c.places.div_ceil(64).max(1);
        let mut initial = vec![0u64; words];
        for (p, &m) in c.initial.iter().enumerate() {
            if m > 0 {
                initial[p / 64] |= 1 << (p % 64);
            }
        }
        let mut touch_start = Vec::with_capacity(c.transitions + 1);
        let mut touches: Vec<Touch> = Vec::new();
        let mut sources = Vec::new();
        touch_start.push(0);
        for t in 0..c.transitions {
            let first = touches.len();
            let mut add = |p: usize, is_pre: bool| {
                let word = (p / 64) as u32;
                let bit = 1u64 << (p % 64);
                let i = match touches[first..].iter().position(|x| x.word == word) {
                    Some(i) => first + i,
                    None => {
                        touches.push(Touch {
                            word,
                            pre: 0,
                            post: 0,
                        });
                        touches.len() - 1
                    }
                };
                if is_pre {
                    touches[i].pre |= bit;
                } else {
                    touches[i].post |= bit;
                }
            };
            for &(p, _) in c.pre(t) {
                add(p, true);
            }
            for &(p, _) in c.post(t) {
                add(p, false);
            }
            if c.pre(t).is_empty() {
                sources.push(t as u32);
            }
            touch_start.push(touches.len() as u32);
        }
        let mut net = BitNet {
            words,
            initial,
            touch_start,
            touches,
            index_start: Vec::new(),
            index: Vec::new(),
            sources,
        };
        // Before any state is seen, guess: places marked initially often stay marked (free
        // resources, idle processes), so prefer an input place that starts empty.
        let guess: Vec<u64> = (0..c.places)
            .map(|p| u64::from(net.initial[p / 64] >> (p % 64) & 1 == 1))
            .collect();
        net.build_index(c.places, &guess);
        net
    }

    fn touches(&self, t: usize) -> &[Touch] {
        &self.touches[self.touch_start[t] as usize..self.touch_start[t + 1] as usize]
    }

    /// Indexes every transition with inputs under its input place with the lowest `freq` (how
    /// often the place was seen marked), so it is tested in as few markings as possible.
    fn build_index(&mut self, places: usize, freq: &[u64]) {
        let transitions = self.touch_start.len() - 1;
        let mut chosen: Vec<Option<usize>> = vec![None; transitions];
        let mut counts = vec![0u32; places + 1];
        for (t, slot) in chosen.iter_mut().enumerate() {
            let mut best: Option<(u64, usize)> = None;
            for tc in self.touches(t) {
                let mut m = tc.pre;
                while m != 0 {
                    let p = tc.word as usize * 64 + m.trailing_zeros() as usize;
                    m &= m - 1;
                    let f = freq.get(p).copied().unwrap_or(0);
                    if best.is_none_or(|(bf, _)| f < bf) {
                        best = Some((f, p));
                    }
                }
            }
            if let Some((_, p)) = best {
                *slot = Some(p);
                counts[p] += 1;
            }
        }
        let mut start = Vec::with_capacity(places + 1);
        let mut acc = 0u32;
        for &n in &counts[..places] {
            start.push(acc);
            acc += n;
        }
        start.push(acc);
        let mut fill = start.clone();
        let mut index = vec![0u32; acc as usize];
        for (t, p) in chosen.iter().enumerate() {
            if let Some(p) = *p {
                index[fill[p] as usize] = t as u32;
                fill[p] += 1;
            }
        }
        self.index_start = start;
        self.index = index;
    }

    /// The transitions indexed under place `p`.
    #[inline(always)]
    fn indexed(&self, p: usize) -> &[u32] {
        match (self.index_start.get(p), self.index_start.get(p + 1)) {
            (Some(&a), Some(&b)) => &self.index[a as usize..b as usize],
            _ => &[],
        }
    }
}

#[inline(always)]
fn bits_enabled(touches: &[Touch], cur: &[u64]) -> bool {
    touches.iter().all(|tc| {
        cur.get(tc.word as usize)
            .is_some_and(|&w| w & tc.pre == tc.pre)
    })
}

/// Fires an enabled transition from `cur` into `next`. Returns the change to the marking's hash,
/// or the first output place that already holds a token (the net is not safe).
#[inline(always)]
fn bits_fire(touches: &[Touch], cur: &[u64], next: &mut [u64]) -> Result<u64, usize> {
    next.copy_from_slice(cur);
    let mut delta = 0;
    for tc in touches {
        let wi = tc.word as usize;
        let (Some(&old), Some(slot)) = (cur.get(wi), next.get_mut(wi)) else {
            continue;
        };
        let rest = old & !tc.pre;
        let clash = rest & tc.post;
        if clash != 0 {
            return Err(wi * 64 + clash.trailing_zeros() as usize);
        }
        let new = rest | tc.post;
        *slot = new;
        delta ^= mix(wi, old) ^ mix(wi, new);
    }
    Ok(delta)
}

/// The bits representation with `N` words a marking when it is known at compile time (1 to 8:
/// most nets), so copies, compares and hashes unroll; 0 means `net.words`.
pub(super) struct Bits<const N: usize> {
    net: BitNet,
    places: usize,
    /// Whether the transitions were re-indexed after [`INDEX_SAMPLE`] states.
    reindexed: bool,
    /// The most tokens in one stored marking.
    max_total: u64,
}

impl<const N: usize> Bits<N> {
    pub(super) fn new(net: BitNet, places: usize) -> Self {
        Bits {
            net,
            places,
            reindexed: false,
            max_total: 0,
        }
    }
}

impl<const N: usize> Marking for Bits<N> {
    type Word = u64;
    const REPRESENTATION: Representation = Representation::Bits;
    const STORES_BEFORE_OVERFLOW: bool = false;

    #[inline(always)]
    fn stride(&self) -> usize {
        if N > 0 {
            N
        } else {
            self.net.words
        }
    }

    fn initial(&self) -> Option<Vec<u64>> {
        Some(self.net.initial.clone())
    }

    fn keeps_parents(&self, keep_traces: bool) -> bool {
        keep_traces
    }

    #[inline(always)]
    fn enabled(&self, cur: &[u64], out: &mut Vec<u32>) {
        for (wi, &word) in cur.iter().enumerate() {
            let mut m = word;
            while m != 0 {
                let p = wi * 64 + m.trailing_zeros() as usize;
                m &= m - 1;
                for &t in self.net.indexed(p) {
                    if bits_enabled(self.net.touches(t as usize), cur) {
                        out.push(t);
                    }
                }
            }
        }
        // Sources need no token: always enabled.
        out.extend_from_slice(&self.net.sources);
    }

    fn is_enabled(&self, t: usize, cur: &[u64]) -> bool {
        bits_enabled(self.net.touches(t), cur)
    }

    #[inline(always)]
    fn tokens(cur: &[u64], p: usize) -> u64 {
        cur.get(p / 64).map_or(0, |&word| word >> (p % 64) & 1)
    }

    #[inline(always)]
    fn fire(&self, t: usize, cur: &[u64], next: &mut [u64]) -> Result<u64, usize> {
        bits_fire(self.net.touches(t), cur, next)
    }

    #[inline(always)]
    fn same(a: &[u64], b: &[u64]) -> bool {
        words_eq(a, b)
    }

    #[inline(always)]
    fn before_expand(&mut self, arena: &[u64], states: usize) {
        if self.reindexed || states < INDEX_SAMPLE {
            return;
        }
        // The first states show which places are rarely marked: index by those.
        self.reindexed = true;
        let mut freq = vec![0u64; self.places];
        for s in arena.chunks_exact(self.stride()) {
            for (wi, &word) in s.iter().enumerate() {
                let mut m = word;
                while m != 0 {
                    let p = wi * 64 + m.trailing_zeros() as usize;
                    m &= m - 1;
                    if let Some(f) = freq.get_mut(p) {
                        *f += 1;
                    }
                }
            }
        }
        self.net.build_index(self.places, &freq);
    }

    #[inline(always)]
    fn stored(&mut self, tree: &Tree<'_, u64>, state: usize, _: usize) -> Result<(), ExploreError> {
        if let Some(m) = tree.marking(state) {
            let total: u64 = m.iter().map(|x| u64::from(x.count_ones())).sum();
            self.max_total = self.max_total.max(total);
        }
        Ok(())
    }

    fn overflow(
        &mut self,
        _: &Tree<'_, u64>,
        _: usize,
        _: usize,
        _: usize,
    ) -> Result<(), ExploreError> {
        // A second token in a place: the net is not safe, counts take over.
        Ok(())
    }

    fn conclude(&self, report: &mut PtReport, _: &dyn Fn(usize) -> Option<Trace>) {
        report.max_tokens_in_place = u64::from(self.max_total > 0);
        report.max_tokens_per_marking = self.max_total;
        report.safe = true;
    }
}
