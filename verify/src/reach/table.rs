//! The set of stored markings ([`StateTable`]) and the hashing and tree helpers every
//! representation shares.
//!
//! Not folded with the project verifier's `StateStore` (crate::store), on purpose: this table
//! holds only positions and hash tags (8 bytes a slot, no copy of a marking, grown from the
//! tags alone), for markings of any width that are compared in the arena; the store packs
//! stable states of a few words and keeps a one-word state in its slot. Different trade-offs,
//! each measured in docs/benchmarks.md.

/// wyhash's multiply-fold: the 128-bit product's halves XORed, so every input bit reaches the
/// high bits, which pick the home slot and the tag in [`StateTable`].
#[inline(always)]
fn fold_mul(a: u64, b: u64) -> u64 {
    let r = u128::from(a) * u128::from(b);
    (r as u64) ^ ((r >> 64) as u64)
}

/// The hash contribution of value `x` at position `i` (a word or a place). The seed depends on
/// the position, so equal values at different positions do not cancel in the XOR.
#[inline(always)]
pub(super) fn mix(i: usize, x: u64) -> u64 {
    let seed = (i as u64)
        .wrapping_add(1)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15);
    fold_mul(x ^ seed, 0xA076_1D64_78BD_642F)
}

/// Equality of two markings without a `memcmp` call: a branch-free fold the compiler unrolls
/// when the length is a constant. Most comparisons are of equal markings (a successor already
/// stored), so an early exit would not save anything.
#[inline(always)]
pub(super) fn words_eq(a: &[u64], b: &[u64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The hash of a marking: the XOR of one [`mix`] per position, so a successor's hash is its
/// parent's corrected for the positions a firing changes.
#[inline(always)]
pub(super) fn hash<W: Copy + Into<u64>>(marking: &[W]) -> u64 {
    marking
        .iter()
        .enumerate()
        .fold(0, |h, (i, &x)| h ^ mix(i, x.into()))
}

/// The set of stored markings: an open-addressing table of state positions, linear probing.
///
/// Each slot is one `u64`: the top 32 bits of the marking's hash (the tag) above the state's
/// position plus one (0 marks an empty slot). A marking's home slot is given by the top bits of
/// its hash, so the tag alone says where an entry goes in a table twice as large: growing never
/// reads the markings again. The tag also filters nearly every probe that is not a match, so the
/// arena is read (one cache miss) only for the marking that is almost surely the one sought.
/// 8 bytes a slot, at most half full (short probes matter more than the bytes): 16 to 32
/// bytes per state.
pub(super) struct StateTable {
    slots: Vec<u64>,
    /// `slots.len() == 1 << bits`, `bits <= 32` (the tag's width bounds the home index).
    bits: u32,
    len: usize,
}

impl StateTable {
    const FIRST_BITS: u32 = 10;

    pub(super) fn new() -> Result<Self, ()> {
        Ok(StateTable {
            slots: zeroed(1 << Self::FIRST_BITS)?,
            bits: Self::FIRST_BITS,
            len: 0,
        })
    }

    #[inline(always)]
    fn home(&self, hash: u64) -> usize {
        (hash >> (64 - self.bits)) as usize
    }

    /// The stored state whose marking `eq` accepts among those with this hash, or the empty
    /// slot where it belongs.
    #[inline(always)]
    pub(super) fn find(&self, hash: u64, mut eq: impl FnMut(u32) -> bool) -> Result<u32, usize> {
        let tag = hash >> 32;
        let mask = self.slots.len() - 1;
        let mut pos = self.home(hash);
        // The table is never full (`grow` keeps half of it free), so the probe ends.
        loop {
            let e = self.slots[pos];
            if e == 0 {
                return Err(pos);
            }
            if e >> 32 == tag {
                let j = (e as u32).wrapping_sub(1);
                if eq(j) {
                    return Ok(j);
                }
            }
            pos = (pos + 1) & mask;
        }
    }

    /// Stores state `state` in the empty slot `slot` that `find` returned.
    #[inline(always)]
    pub(super) fn insert_at(&mut self, slot: usize, hash: u64, state: u32) {
        if let Some(e) = self.slots.get_mut(slot) {
            *e = (hash >> 32) << 32 | (u64::from(state) + 1);
            self.len += 1;
        }
    }

    /// True when the next insertion must wait for `grow`.
    #[inline(always)]
    pub(super) fn full(&self) -> bool {
        self.len * 2 >= self.slots.len()
    }

    /// Brings into cache the home slot of each hash and the first word of the marking it
    /// names, without acting on them. The loads are independent and branch-free, so the
    /// processor overlaps their cache misses; the real lookups that follow then hit the cache.
    /// (Prefetch instructions would say this more directly but need `unsafe`.)
    #[inline(always)]
    pub(super) fn touch<T: Copy + Default + Into<u64>>(
        &self,
        hashes: &[u64],
        arena: &[T],
        stride: usize,
    ) {
        let mut sink = 0u64;
        for &h in hashes {
            let e = self.slots[self.home(h)];
            let j = if e >> 32 == h >> 32 {
                (e as u32).wrapping_sub(1) as usize
            } else {
                0
            };
            sink ^= arena
                .get(j.wrapping_mul(stride))
                .copied()
                .unwrap_or_default()
                .into();
        }
        std::hint::black_box(sink);
    }

    /// Doubles the table, placing each entry by its tag.
    pub(super) fn grow(&mut self) -> Result<(), ()> {
        let bits = self.bits + 1;
        if bits > 32 || bits >= usize::BITS {
            // 2^32 slots would hold more states than `u32` positions name; unreachable
            // because the state limit stops first, but refuse rather than misplace entries.
            return Err(());
        }
        let mut slots = zeroed(1usize << bits)?;
        let mask = slots.len() - 1;
        for &e in &self.slots {
            if e != 0 {
                let mut pos = ((e >> 32) >> (32 - bits)) as usize;
                while slots[pos] != 0 {
                    pos = (pos + 1) & mask;
                }
                slots[pos] = e;
            }
        }
        self.slots = slots;
        self.bits = bits;
        Ok(())
    }

    pub(super) fn bytes(&self) -> usize {
        self.slots.capacity() * 8
    }
}

/// `len` zeros, or the allocation failure instead of an abort.
fn zeroed(len: usize) -> Result<Vec<u64>, ()> {
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| ())?;
    v.resize(len, 0);
    Ok(v)
}

/// The positions on the breadth-first tree from the root to `state`, both included.
pub(super) fn tree_path(parents: &[u32], state: usize) -> Vec<usize> {
    let mut path = vec![state];
    let mut s = state;
    // Parents always precede their children, so this walk ends at the root (state 0).
    while s != 0 {
        match parents.get(s) {
            Some(&p) if (p as usize) < s => s = p as usize,
            _ => break,
        }
        path.push(s);
    }
    path.reverse();
    path
}

// ---------------------------------------------------------------------------------------------
// Bits: safe nets with unit weights
// ---------------------------------------------------------------------------------------------
