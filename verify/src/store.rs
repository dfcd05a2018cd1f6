//! The stable states of an exploration, packed: every state's words one after the other in
//! one vector (a state is a fixed number of words of bits: nets, places, timers, the
//! environment's counters), and an open-addressing table of state numbers to find one. A
//! state costs its words and about eight bytes of table, where a `Vec` per state, kept twice
//! (the list and the map's key), cost over a hundred (docs/benchmarks.md).
//!
//! Beside it, [`Packed`]: numbers (state numbers, edge targets, step kinds) in as few bytes
//! each as the largest of them needs, for the parent pointers and the edges.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// The states, numbered in the order they were added.
pub(super) struct StateStore {
    words: usize,
    data: Vec<u64>,
    /// State numbers, `EMPTY` where free; a power of two long, at most half full. Empty when
    /// states are one word: `slots` then.
    table: Vec<u32>,
    /// States of one word: each slot holds the state's number and its word, so that a lookup
    /// reads one random place of memory (the slot) instead of two (the slot, then the state's
    /// words): 12 bytes a slot where `table` takes 4 (docs/benchmarks.md, the fourth round).
    slots: Vec<Slot>,
}

const EMPTY: u32 = u32::MAX;

/// A slot of a table of one-word states: its number (`EMPTY` where free) and its word, in
/// 32-bit halves so that a slot is 12 bytes, not 16.
#[derive(Clone, Copy)]
struct Slot {
    number: u32,
    lo: u32,
    hi: u32,
}

const FREE: Slot = Slot {
    number: EMPTY,
    lo: 0,
    hi: 0,
};

impl Slot {
    #[inline]
    fn word(self) -> u64 {
        (u64::from(self.hi) << 32) | u64::from(self.lo)
    }
}

fn hash(s: &[u64]) -> u64 {
    // A multiply-xorshift over the words (FxHash-like): states are bit vectors, not chosen by
    // an adversary.
    let mut h: u64 = 0x9e37_79b9_7f4a_7c15 ^ s.len() as u64;
    for &w in s {
        h = (h.rotate_left(5) ^ w).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
    h ^ (h >> 29)
}

impl StateStore {
    /// An empty store of states of `words` words each.
    pub fn new(words: usize) -> StateStore {
        let one = words == 1;
        StateStore {
            words,
            data: Vec::new(),
            table: if one { Vec::new() } else { vec![EMPTY; 64] },
            slots: if one { vec![FREE; 64] } else { Vec::new() },
        }
    }

    /// How many states.
    pub fn len(&self) -> usize {
        self.data.len() / self.words.max(1)
    }

    /// The bytes its states and table take (their lengths: the spare capacity of a growing
    /// vector is not touched, so not resident), for the benchmarks' count.
    pub fn heap_bytes(&self) -> usize {
        self.data.len() * 8 + self.table.len() * 4 + self.slots.len() * std::mem::size_of::<Slot>()
    }

    /// State `i`.
    pub fn get(&self, i: usize) -> &[u64] {
        &self.data[i * self.words..(i + 1) * self.words]
    }

    /// Every state, in order.
    pub fn iter(&self) -> impl Iterator<Item = &[u64]> {
        (0..self.len()).map(|i| self.get(i))
    }

    /// The slot of one-word state `w`, and its number if it is stored.
    #[inline]
    fn slot_one(&self, w: u64) -> (usize, Option<u32>) {
        let mask = self.slots.len() - 1;
        let mut k = hash(&[w]) as usize & mask;
        loop {
            let sl = self.slots[k];
            if sl.number == EMPTY {
                return (k, None);
            }
            if sl.word() == w {
                return (k, Some(sl.number));
            }
            k = (k + 1) & mask;
        }
    }

    fn slot(&self, s: &[u64]) -> (usize, Option<u32>) {
        if !self.slots.is_empty() {
            return self.slot_one(s[0]);
        }
        let mask = self.table.len() - 1;
        self.probe(hash(s) as usize & mask, s)
    }

    /// The slot of `s` from slot `k` on, and its number if it is stored.
    fn probe(&self, mut k: usize, s: &[u64]) -> (usize, Option<u32>) {
        let mask = self.table.len() - 1;
        loop {
            match self.table[k] {
                EMPTY => return (k, None),
                // Word by word: a state is a word or two, where a call to `memcmp` per probe
                // cost a fifth of the exploration (docs/benchmarks.md).
                j if self.get(j as usize).iter().zip(s).all(|(a, b)| a == b) => {
                    return (k, Some(j))
                }
                _ => k = (k + 1) & mask,
            }
        }
    }

    /// The number of state `s`, if it is stored.
    pub fn find(&self, s: &[u64]) -> Option<u32> {
        debug_assert_eq!(s.len(), self.words);
        self.slot(s).1
    }

    /// The numbers of `states` (`None` where not stored), looked up together: the table
    /// entries of all of them are read before any state is compared, so that the cache misses
    /// of a large exploration (a random table entry, then a random state, per lookup) overlap
    /// instead of following one another. `slots` is scratch.
    pub fn find_all<'a>(
        &self,
        states: impl Iterator<Item = &'a [u64]> + Clone,
        slots: &mut Vec<(usize, u32)>,
        out: &mut Vec<Option<u32>>,
    ) {
        if !self.slots.is_empty() {
            // One random read per state, independent of the others: the processor overlaps
            // their cache misses by itself (reading them all first, then comparing, as for
            // wider states, was slower here: docs/benchmarks.md, the fourth round).
            out.clear();
            out.extend(states.map(|s| self.slot_one(s[0]).1));
            return;
        }
        let mask = self.table.len() - 1;
        slots.clear();
        slots.extend(states.clone().map(|s| {
            let k = hash(s) as usize & mask;
            (k, self.table[k])
        }));
        out.clear();
        for (s, &(k, first)) in states.zip(slots.iter()) {
            out.push(match first {
                EMPTY => None,
                j if self.get(j as usize).iter().zip(s).all(|(a, b)| a == b) => Some(j),
                _ => self.probe((k + 1) & mask, s).1,
            });
        }
    }

    /// Stores `s` (not stored yet) and returns its number.
    pub fn push(&mut self, s: &[u64]) -> u32 {
        debug_assert_eq!(s.len(), self.words);
        if !self.slots.is_empty() {
            if 2 * (self.len() + 1) > self.slots.len() {
                let mut table = vec![FREE; self.slots.len() * 2];
                let mask = table.len() - 1;
                for (j, &w) in self.data.iter().enumerate() {
                    let mut k = hash(&[w]) as usize & mask;
                    while table[k].number != EMPTY {
                        k = (k + 1) & mask;
                    }
                    table[k] = Slot {
                        number: j as u32,
                        lo: w as u32,
                        hi: (w >> 32) as u32,
                    };
                }
                self.slots = table;
            }
            let (k, found) = self.slot_one(s[0]);
            debug_assert!(found.is_none());
            let j = self.len() as u32;
            self.data.push(s[0]);
            self.slots[k] = Slot {
                number: j,
                lo: s[0] as u32,
                hi: (s[0] >> 32) as u32,
            };
            return j;
        }
        if 2 * (self.len() + 1) > self.table.len() {
            let mut table = vec![EMPTY; self.table.len() * 2];
            let mask = table.len() - 1;
            for j in 0..self.len() as u32 {
                let mut k = hash(self.get(j as usize)) as usize & mask;
                while table[k] != EMPTY {
                    k = (k + 1) & mask;
                }
                table[k] = j;
            }
            self.table = table;
        }
        let (k, found) = self.slot(s);
        debug_assert!(found.is_none());
        let j = self.len() as u32;
        self.data.extend_from_slice(s);
        self.table[k] = j;
        j
    }
}

impl std::ops::Index<usize> for StateStore {
    type Output = [u64];
    fn index(&self, i: usize) -> &[u64] {
        self.get(i)
    }
}

/// A list of numbers stored in the fewest whole bytes (1 to 8) that hold the largest of them,
/// widened when a larger one comes: edge targets below 2^24 take 3 bytes, step kinds below 256
/// one, where a `u32` each would take 4.
pub(super) struct Packed {
    width: usize,
    len: usize,
    /// The numbers' bytes, then eight zero bytes, so that every number is read with one
    /// eight-byte load (a copy of `width` bytes was a call to `memmove` per read).
    bytes: Vec<u8>,
}

const PAD: [u8; 8] = [0; 8];

/// The fewest whole bytes that hold `v`.
pub(super) fn width_of(v: u64) -> usize {
    (8 - v.leading_zeros() as usize / 8).max(1)
}

impl Packed {
    /// An empty list.
    pub fn new() -> Packed {
        Packed {
            width: 1,
            len: 0,
            bytes: PAD.to_vec(),
        }
    }

    /// An empty list of numbers below 2^(8 * `width`) (a wider one widens it): a stack that
    /// is pushed and truncated often starts at its final width.
    pub fn with_width(width: usize) -> Packed {
        Packed {
            width: width.clamp(1, 8),
            len: 0,
            bytes: PAD.to_vec(),
        }
    }

    /// How many numbers.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Keeps the first `len` numbers (all of them when there are fewer).
    pub fn truncate(&mut self, len: usize) {
        if len < self.len {
            self.bytes.truncate(len * self.width);
            self.bytes.extend_from_slice(&PAD);
            self.len = len;
        }
    }

    /// Adds `v` at the end.
    pub fn push(&mut self, v: u64) {
        let w = width_of(v);
        if w > self.width {
            self.widen(w);
        }
        // The eight bytes of `v` over the padding (its bytes past `width` are zeros: padding
        // again), then `width` more zeros: a copy of a fixed size, where copies of `width`
        // bytes were calls to `memmove` (docs/benchmarks.md, the fourth round).
        let end = self.len * self.width;
        self.bytes[end..end + 8].copy_from_slice(&v.to_le_bytes());
        self.bytes.resize(end + self.width + 8, 0);
        self.len += 1;
    }

    /// Number `k`.
    #[inline]
    pub fn get(&self, k: usize) -> u64 {
        let w = self.width;
        let mut b = [0u8; 8];
        b.copy_from_slice(&self.bytes[k * w..k * w + 8]);
        let v = u64::from_le_bytes(b);
        if w == 8 {
            v
        } else {
            v & ((1u64 << (8 * w)) - 1)
        }
    }

    /// The bytes its numbers take (not the spare capacity), for the benchmarks' count.
    pub fn heap_bytes(&self) -> usize {
        self.bytes.len()
    }

    fn widen(&mut self, w: usize) {
        let mut bytes = Vec::with_capacity(self.len * w + PAD.len());
        for k in 0..self.len {
            bytes.extend_from_slice(&self.get(k).to_le_bytes()[..w]);
        }
        bytes.extend_from_slice(&PAD);
        self.bytes = bytes;
        self.width = w;
    }
}

/// A fast hasher for the exploration's small keys (label keys, sets of rules): the standard
/// SipHash cost a tenth of the exploration on them, and the keys are not chosen by an adversary.
#[derive(Default, Clone, Copy)]
pub(super) struct FxHasher(u64);

impl Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut b = [0u8; 8];
            b[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(b));
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
    fn write_u32(&mut self, v: u32) {
        self.write_u64(u64::from(v));
    }
    fn write_u8(&mut self, v: u8) {
        self.write_u64(u64::from(v));
    }
    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

/// A `HashMap` with [`FxHasher`].
pub(super) type FxMap<K, V> = HashMap<K, V, BuildHasherDefault<FxHasher>>;

#[cfg(test)]
mod tests {
    use super::{Packed, StateStore};

    #[test]
    fn finds_what_it_stores_and_nothing_else() {
        let mut st = StateStore::new(2);
        for k in 0..1000u64 {
            assert_eq!(st.find(&[k, k * 7]), None);
            assert_eq!(st.push(&[k, k * 7]), k as u32);
        }
        for k in 0..1000u64 {
            assert_eq!(st.find(&[k, k * 7]), Some(k as u32));
            assert_eq!(&st[k as usize], &[k, k * 7]);
        }
        assert_eq!(st.find(&[3, 20]), None);
        let (mut slots, mut out) = (Vec::new(), Vec::new());
        let asked: Vec<[u64; 2]> = vec![[5, 35], [3, 20], [999, 6993], [0, 0]];
        st.find_all(asked.iter().map(|s| &s[..]), &mut slots, &mut out);
        assert_eq!(out, vec![Some(5), None, Some(999), Some(0)]);
        assert_eq!(st.len(), 1000);
        assert_eq!(st.iter().count(), 1000);
    }

    #[test]
    fn one_word_states_are_found_in_their_slots() {
        let mut st = StateStore::new(1);
        let word = |k: u64| k.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (k << 40);
        for k in 0..1000u64 {
            assert_eq!(st.find(&[word(k)]), None);
            assert_eq!(st.push(&[word(k)]), k as u32);
        }
        for k in 0..1000u64 {
            assert_eq!(st.find(&[word(k)]), Some(k as u32));
            assert_eq!(&st[k as usize], &[word(k)]);
        }
        let (mut slots, mut out) = (Vec::new(), Vec::new());
        let asked: Vec<[u64; 1]> = vec![[word(5)], [word(1000)], [word(999)], [word(0)]];
        st.find_all(asked.iter().map(|s| &s[..]), &mut slots, &mut out);
        assert_eq!(out, vec![Some(5), None, Some(999), Some(0)]);
        // 2048 slots of 12 bytes for 1000 states of 8.
        assert_eq!(st.heap_bytes(), 1000 * 8 + 2048 * 12);
    }

    #[test]
    fn packed_numbers_widen_and_keep_their_values() {
        let mut p = Packed::new();
        let values = [
            0u64,
            7,
            255,
            256,
            3,
            1 << 24,
            5,
            u64::from(u32::MAX),
            1 << 40,
            9,
        ];
        for (k, &v) in values.iter().enumerate() {
            p.push(v);
            assert_eq!(p.len(), k + 1);
            for (j, &w) in values[..=k].iter().enumerate() {
                assert_eq!(p.get(j), w);
            }
        }
        // A stack at a fixed width: truncated, pushed again, read back.
        let mut q = Packed::with_width(3);
        for v in 0..100u64 {
            q.push(v * 1000);
        }
        q.truncate(40);
        assert_eq!(q.len(), 40);
        q.truncate(50);
        assert_eq!(q.len(), 40);
        q.push(7);
        assert_eq!((q.get(39), q.get(40)), (39_000, 7));
        assert_eq!(q.heap_bytes(), 41 * 3 + 8);
    }
}
