//! The stable states of an exploration, packed: every state's words one after the other in
//! one vector (a state is a fixed number of words of bits: nets, places, timers, the
//! environment's counters), and an open-addressing table of state numbers to find one. A
//! state costs its words and about eight bytes of table, where a `Vec` per state, kept twice
//! (the list and the map's key), cost over a hundred (docs/benchmarks.md).

/// The states, numbered in the order they were added.
pub(super) struct StateStore {
    words: usize,
    data: Vec<u64>,
    /// State numbers, `EMPTY` where free; a power of two long, at most half full.
    table: Vec<u32>,
}

const EMPTY: u32 = u32::MAX;

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
        StateStore {
            words,
            data: Vec::new(),
            table: vec![EMPTY; 64],
        }
    }

    /// How many states.
    pub fn len(&self) -> usize {
        self.data.len() / self.words.max(1)
    }

    /// State `i`.
    pub fn get(&self, i: usize) -> &[u64] {
        &self.data[i * self.words..(i + 1) * self.words]
    }

    /// Every state, in order.
    pub fn iter(&self) -> impl Iterator<Item = &[u64]> {
        (0..self.len()).map(|i| self.get(i))
    }

    fn slot(&self, s: &[u64]) -> (usize, Option<u32>) {
        let mask = self.table.len() - 1;
        let mut k = hash(s) as usize & mask;
        loop {
            match self.table[k] {
                EMPTY => return (k, None),
                j if self.get(j as usize) == s => return (k, Some(j)),
                _ => k = (k + 1) & mask,
            }
        }
    }

    /// The number of state `s`, if it is stored.
    pub fn find(&self, s: &[u64]) -> Option<u32> {
        debug_assert_eq!(s.len(), self.words);
        self.slot(s).1
    }

    /// Stores `s` (not stored yet) and returns its number.
    pub fn push(&mut self, s: &[u64]) -> u32 {
        debug_assert_eq!(s.len(), self.words);
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

#[cfg(test)]
mod tests {
    use super::StateStore;

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
        assert_eq!(st.len(), 1000);
        assert_eq!(st.iter().count(), 1000);
    }
}
