//! The transition cache of the full exploration (docs/verification.md, "The transition
//! cache"), as LTSmin caches short vectors.
//!
//! A delivery of component `c` ([`super::reduction::Components`]) reads and writes only `c`'s
//! bits of a stable state: its nets' active bits and places, its global places, its timers'
//! bits and its environment counters (what joins nets into one component is exactly what one
//! net's firing could read or write of another's). Bits of no component (the catastrophic
//! flag, places no net touches) are read by every delivery and written by none that is cached.
//! So in a stable state `s` where no immediate transition is enabled, the moves of `c`, and
//! each move's successor restricted to `c`'s bits, its label and its fired set, are a function
//! of `c` and `s & key_mask(c)`: computed once per such key, and every successor then built as
//! `(s & !mask(c)) | local`.
//!
//! What is never cached (computed as without the cache, each time): a component's moves in a
//! state where a step recorded something (a firing refused for safety, a loop of immediate
//! transitions, a conflict) or asked the oracle about a guard; a delivery of no component (a
//! catastrophic event) or addressed to a net of another component than its event's; a state
//! with an enabled immediate transition (refused or undecided: the fixpoint of any step would
//! try it again, whatever its component); everything once a loop of immediate transitions has
//! been found; the timed exploration (the clocks are everybody's). A step that writes a bit
//! outside its component is not cached either (a check, not an expected case).
//!
//! Its memory is bounded: it stores no more successors than a quarter of the states explored
//! (and a few thousand), about 6 bytes per state at most; a component with as many local
//! states as the project has states gains nothing from it anyway.

use super::env::{Delivery, Env};
use super::reduction::Components;
use super::store::FxMap;
use petrel_nets::compiled::CompiledProject;
use petrel_nets::semantics::Layout;
use std::ops::Range;

/// The cached moves of each component, by the component's bits of the state.
pub(super) struct Cache {
    words: usize,
    /// Per delivery, its component when its steps may be cached.
    pub of_delivery: Vec<Option<u32>>,
    /// Per component, its bits (`words` words each).
    mask: Vec<u64>,
    /// Per component, the bits its key holds: its own and those of no component.
    key_mask: Vec<u64>,
    /// Per component, whether some delivery of it may be cached (else it is never looked up).
    cacheable: Vec<bool>,
    /// Per component, the entry of each key (by its word when a state is one word: no slice
    /// hashed and compared).
    maps: Vec<FxMap<Vec<u64>, u32>>,
    maps_one: Vec<FxMap<u64, u32>>,
    /// Each entry's successors (a range of the lists below), in delivery order.
    entries: Vec<Range<u32>>,
    /// Each cached successor's delivery, its component's bits (`words` words), and its label,
    /// fired set and step kind.
    delivery: Vec<u32>,
    local: Vec<u64>,
    meta: Vec<(u32, u32, u32)>,
    key: Vec<u64>,
    /// Components' moves taken from the cache.
    pub hits: u64,
}

impl Cache {
    /// The cache of `p`'s full exploration, with its deliveries `deliveries`; `None` when the
    /// nets make one component (a key would be the whole state) or no delivery may be cached.
    pub fn new(
        p: &CompiledProject,
        l: &Layout,
        env: &Env,
        deliveries: &[Delivery],
        comps: &Components,
    ) -> Option<Cache> {
        if comps.count < 2 {
            return None;
        }
        let words = env.words;
        let n = comps.count as usize;
        let mut mask = vec![0u64; n * words];
        let mut set = |c: Option<u32>, b: u32| {
            if let Some(c) = c {
                mask[c as usize * words + (b / 64) as usize] |= 1 << (b % 64);
            }
        };
        for (net, &c) in comps.of_net.iter().enumerate() {
            set(Some(c), l.net_active[net]);
            for k in 0..p.nets[net].places.len() as u32 {
                set(Some(c), l.net_base[net] + k);
            }
        }
        for (g, &c) in comps.of_global.iter().enumerate() {
            set(c, l.global_base + g as u32);
        }
        for (t, &c) in comps.of_timer.iter().enumerate() {
            set(c, l.timer_base + t as u32);
        }
        for ((program, function), bit) in env.function_counter_bits() {
            let c = comps.of_function[program as usize][function as usize];
            set(c, bit);
            set(c, bit + 1);
        }
        for (event, bit) in env.internal_counter_bits() {
            let c = comps.of_event[event as usize];
            set(c, bit);
            set(c, bit + 1);
        }
        // The bits of no component: read by all, so in every key.
        let mut none = vec![!0u64; words];
        for c in 0..n {
            for w in 0..words {
                none[w] &= !mask[c * words + w];
            }
        }
        let key_mask = (0..n * words).map(|k| mask[k] | none[k % words]).collect();
        // A delivery addressed to a net reads the counter of its event's emitter: cached only
        // when that is the net's component.
        let of_delivery: Vec<Option<u32>> = deliveries
            .iter()
            .map(|d| {
                comps
                    .of_delivery(p, l, d)
                    .filter(|&c| comps.of_event[d.event as usize] == Some(c))
            })
            .collect();
        let mut cacheable = vec![false; n];
        for c in of_delivery.iter().flatten() {
            cacheable[*c as usize] = true;
        }
        if !cacheable.iter().any(|&b| b) {
            return None;
        }
        Some(Cache {
            words,
            of_delivery,
            mask,
            key_mask,
            cacheable,
            maps: (0..n).map(|_| FxMap::default()).collect(),
            maps_one: (0..n).map(|_| FxMap::default()).collect(),
            entries: Vec::new(),
            delivery: Vec::new(),
            local: Vec::new(),
            meta: Vec::new(),
            key: vec![0; words],
            hits: 0,
        })
    }

    /// How many components.
    pub fn components(&self) -> usize {
        self.cacheable.len()
    }

    /// How many successors the cache holds (about 24 bytes each).
    pub fn successors(&self) -> usize {
        self.delivery.len()
    }

    /// Whether some delivery of component `c` may be cached.
    pub fn cacheable(&self, c: usize) -> bool {
        self.cacheable[c]
    }

    /// Component `c`'s bits.
    pub fn mask(&self, c: usize) -> &[u64] {
        &self.mask[c * self.words..(c + 1) * self.words]
    }

    fn key_of(&mut self, c: usize, s: &[u64]) {
        let km = &self.key_mask[c * self.words..(c + 1) * self.words];
        for ((k, &a), &m) in self.key.iter_mut().zip(s).zip(km) {
            *k = a & m;
        }
    }

    /// The entry of component `c` in state `s`, if it is cached.
    pub fn lookup(&mut self, c: usize, s: &[u64]) -> Option<u32> {
        if !self.cacheable[c] {
            return None;
        }
        let e = if self.words == 1 {
            self.maps_one[c].get(&(s[0] & self.key_mask[c])).copied()
        } else {
            self.key_of(c, s);
            self.maps[c].get(self.key.as_slice()).copied()
        };
        self.hits += u64::from(e.is_some());
        e
    }

    /// The successors of entry `e`: a range of [`Cache::successor`]'s numbers.
    pub fn entry(&self, e: u32) -> Range<u32> {
        self.entries[e as usize].clone()
    }

    /// Cached successor `k`: its delivery, its component's bits, its label, fired set and
    /// step kind.
    #[inline]
    pub fn successor(&self, k: u32) -> (u32, &[u64], (u32, u32, u32)) {
        let k = k as usize;
        (
            self.delivery[k],
            &self.local[k * self.words..(k + 1) * self.words],
            self.meta[k],
        )
    }

    /// Stores the moves of component `c` in state `s`: `successors`, (delivery, state, (label,
    /// fired set, step kind)) in delivery order. Not when a successor differs from `s` outside `c`'s bits
    /// (returns whether it stored).
    pub fn store<'a>(
        &mut self,
        c: usize,
        s: &[u64],
        successors: impl Iterator<Item = (u32, &'a [u64], (u32, u32, u32))> + Clone,
    ) -> bool {
        let w = self.words;
        let m = &self.mask[c * w..(c + 1) * w];
        let outside = successors.clone().any(|(_, t, _)| {
            t.iter()
                .zip(s)
                .zip(m)
                .any(|((&a, &b), &m)| (a ^ b) & !m != 0)
        });
        if outside {
            return false;
        }
        let from = self.delivery.len() as u32;
        for (d, t, meta) in successors {
            self.delivery.push(d);
            self.local.extend(t.iter().zip(m).map(|(&a, &m)| a & m));
            self.meta.push(meta);
        }
        let e = self.entries.len() as u32;
        self.entries.push(from..self.delivery.len() as u32);
        if self.words == 1 {
            self.maps_one[c].insert(s[0] & self.key_mask[c], e);
        } else {
            self.key_of(c, s);
            self.maps[c].insert(self.key.clone(), e);
        }
        true
    }
}
