//! The set of keys a tier has ever built, which tells a *cold tessellation* (the first build of
//! a key) from a *cache miss* (a rebuild after eviction), the paper's §6.1 terms.
//!
//! Memory: subpatch ids are dense per mesh (patch index, then split children), so each
//! (mesh, generation) gets a bitset of one bit per id up to the highest id seen, behind a
//! 33-byte hash-map slot: 970,000 subpatches (the paper's city street, §6.4) cost 121 KB per
//! tier against its 10 MB of entries, and even 46,000 one-subpatch meshes cost about 3.5 MB. Ids
//! at or above [`DENSE_LIMIT`] go to a hash set instead (about 14 bytes each), so a stray huge
//! id cannot allocate a 512 MB bitset.

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

/// Subpatch ids below this are kept in a bitset (at most 2 MiB per mesh and tier); larger ones
/// in a hash set.
pub(crate) const DENSE_LIMIT: u32 = 1 << 24;

/// The multiplicative hash rustc uses (FxHash): keys here are small integers chosen by the
/// renderer, not by an adversary, so SipHash's flooding resistance would only cost time on
/// every lookup.
#[derive(Default, Clone, Copy)]
pub(crate) struct FxHasher {
    hash: u64,
}

impl FxHasher {
    const SEED: u64 = 0x51_7c_c1_b7_27_22_0a_95;

    #[inline]
    fn add(&mut self, word: u64) {
        self.hash = (self.hash.rotate_left(5) ^ word).wrapping_mul(Self::SEED);
    }
}

impl Hasher for FxHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.add(u64::from_le_bytes(word));
        }
    }
    #[inline]
    fn write_u8(&mut self, i: u8) {
        self.add(u64::from(i));
    }
    #[inline]
    fn write_u32(&mut self, i: u32) {
        self.add(u64::from(i));
    }
    #[inline]
    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }
    #[inline]
    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }
    #[inline]
    fn finish(&self) -> u64 {
        self.hash
    }
}

/// `BuildHasher` for [`FxHasher`].
pub(crate) type FxBuild = BuildHasherDefault<FxHasher>;

/// Ever-built keys of one tier.
#[derive(Default)]
pub(crate) struct SeenSet {
    /// Per (mesh, generation): bit `id % 64` of word `id / 64` is set once subpatch
    /// `id < DENSE_LIMIT` was built.
    dense: HashMap<(u32, u32), Vec<u64>, FxBuild>,
    /// (mesh, generation, subpatch) of ids at or above `DENSE_LIMIT`.
    sparse: HashSet<(u32, u32, u32), FxBuild>,
}

impl SeenSet {
    /// Records that (`mesh`, `generation`, `subpatch`) was built; true if it never was before.
    pub(crate) fn insert(&mut self, mesh: u32, generation: u32, subpatch: u32) -> bool {
        if subpatch >= DENSE_LIMIT {
            return self.sparse.insert((mesh, generation, subpatch));
        }
        let bits = self.dense.entry((mesh, generation)).or_default();
        let word = (subpatch / 64) as usize;
        let bit = 1u64 << (subpatch % 64);
        if word >= bits.len() {
            // `resize` reserves with amortised doubling, so growing id by id stays linear.
            bits.resize(word + 1, 0);
        }
        let first = bits[word] & bit == 0;
        bits[word] |= bit;
        first
    }

    /// Forgets every generation of `mesh`: its next builds count as cold tessellations.
    pub(crate) fn forget_mesh(&mut self, mesh: u32) {
        self.dense.retain(|&(m, _), _| m != mesh);
        self.sparse.retain(|&(m, _, _)| m != mesh);
    }

    /// Heap bytes the set holds, roughly (bitset words plus hash set slots).
    pub(crate) fn heap_bytes(&self) -> usize {
        let slot = std::mem::size_of::<((u32, u32), Vec<u64>)>() + 1;
        let sparse_slot = std::mem::size_of::<(u32, u32, u32)>() + 1;
        self.dense.capacity() * slot
            + self.dense.values().map(|bits| bits.capacity() * 8).sum::<usize>()
            + self.sparse.capacity() * sparse_slot
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::BuildHasher;

    #[test]
    fn first_insert_is_new_later_ones_are_not() {
        let mut s = SeenSet::default();
        assert!(s.insert(1, 0, 5));
        assert!(!s.insert(1, 0, 5));
        assert!(s.insert(1, 0, 6));
        assert!(s.insert(1, 0, 64)); // the next bitset word
        assert!(!s.insert(1, 0, 64));
        // Another mesh, or another generation of the same mesh, is a different key.
        assert!(s.insert(2, 0, 5));
        assert!(s.insert(1, 1, 5));
    }

    #[test]
    fn huge_ids_use_the_sparse_set() {
        let mut s = SeenSet::default();
        assert!(s.insert(0, 0, u32::MAX));
        assert!(!s.insert(0, 0, u32::MAX));
        assert!(s.insert(0, 0, DENSE_LIMIT));
        assert!(s.insert(0, 0, DENSE_LIMIT - 1));
        // The dense part did not grow to cover the huge ids.
        assert!(s.heap_bytes() < (DENSE_LIMIT as usize / 8) + 4096);
        assert!(s.heap_bytes() >= (DENSE_LIMIT as usize / 8));
    }

    #[test]
    fn dense_cost_is_one_bit_per_id() {
        let mut s = SeenSet::default();
        for id in 0..970_000 {
            assert!(s.insert(3, 0, id));
        }
        // 970,000 bits = 121,250 bytes; amortised growth may reserve up to twice that.
        let bytes = s.heap_bytes();
        assert!((121_250..2 * 121_250 + 1024).contains(&bytes), "{bytes}");
    }

    #[test]
    fn forget_mesh_forgets_only_that_mesh() {
        let mut s = SeenSet::default();
        for id in [3, u32::MAX] {
            s.insert(1, 0, id);
            s.insert(1, 7, id);
            s.insert(2, 0, id);
        }
        s.forget_mesh(1);
        for id in [3, u32::MAX] {
            assert!(s.insert(1, 0, id));
            assert!(s.insert(1, 7, id));
            assert!(!s.insert(2, 0, id));
        }
    }

    #[test]
    fn many_small_meshes_stay_small() {
        let mut s = SeenSet::default();
        for mesh in 0..46_000 {
            assert!(s.insert(mesh, 0, 0));
        }
        // A 33-byte slot (at hashbrown's load factor) plus one 8-byte word per mesh.
        let per_mesh = s.heap_bytes() as f64 / 46_000.0;
        assert!(per_mesh < 90.0, "{per_mesh} bytes per mesh");
    }

    #[test]
    fn fx_hash_spreads_sequential_keys() {
        // hashbrown takes its control bits from the top 7 bits: sequential ids must not share them.
        let b = FxBuild::default();
        let tops: HashSet<u64> = (0u32..256).map(|i| b.hash_one((1u32, 0u32, i)) >> 57).collect();
        assert!(tops.len() > 64, "only {} distinct top-7-bit values", tops.len());
    }
}
