//! The hash index of one shard: resident key → LRU node, in 8 bytes a bucket.
//!
//! Handwritten rather than a `HashMap<CacheKey, _>` because of what a coarse entry weighs: 48
//! bytes of vertices (§5.2), hundreds of thousands of them per tier. A general map stores the
//! key and value in every bucket (32 bytes for a `(CacheKey, u32)`-sized pair plus a control
//! byte, at a load of 44–87%: 38–75 bytes an entry). Here the key lives once, in the LRU node
//! that also holds the entry, and a bucket holds only the node's index and 32 bits of the key's
//! hash (to skip other keys without reading their nodes): 8 bytes at a load of 37.5–75%, so 11–21
//! bytes an entry.
//!
//! Open addressing with linear probing (neighbouring buckets share cache lines) and
//! backward-shift deletion (no tombstones, so probe sequences never degrade under the cache's
//! constant churn of evictions). The home bucket of a hash is its top bits, so growing rehashes
//! from the stored tags alone, without touching any node.

/// "No node": an empty bucket.
const EMPTY: u32 = u32::MAX;

/// The fewest buckets a table that holds anything has.
const MIN_BUCKETS: usize = 16;

#[derive(Clone, Copy)]
struct Bucket {
    /// The top 32 bits of the key's hash; its top `bits` bits are the home bucket.
    tag: u32,
    /// The LRU node holding the key, or [`EMPTY`].
    node: u32,
}

const VACANT: Bucket = Bucket { tag: 0, node: EMPTY };

/// Key hashes → node indices. The caller hashes (see [`tag`]) and compares keys; the index only
/// knows tags and nodes.
#[derive(Default)]
pub(crate) struct NodeIndex {
    /// A power of two of them, or none before the first insert.
    buckets: Box<[Bucket]>,
    /// log2 of the bucket count.
    bits: u32,
    len: usize,
}

/// The 32-bit tag of a (mesh, generation, subpatch) key: a full 64-bit mix (MurmurHash3's
/// finaliser), so the top bits that pick the home bucket depend on every input bit. Shards are
/// chosen by the subpatch's low bits, so within a shard those are all alike: a hash that left
/// them in place would crowd one bucket in sixteen.
#[inline]
pub(crate) fn tag(mesh: u32, generation: u32, subpatch: u32) -> u32 {
    let mut h = ((u64::from(mesh) << 32) | u64::from(generation)) ^ u64::from(subpatch).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^= h >> 33;
    h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    h ^= h >> 33;
    (h >> 32) as u32
}

impl NodeIndex {
    /// Keys held.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Heap bytes of the bucket array.
    pub(crate) fn heap_bytes(&self) -> usize {
        self.buckets.len() * std::mem::size_of::<Bucket>()
    }

    #[inline]
    fn mask(&self) -> usize {
        self.buckets.len().wrapping_sub(1)
    }

    #[inline]
    fn home(&self, tag: u32) -> usize {
        // `bits` ≥ 4 whenever there are buckets; a 64-bit shift keeps `bits` = 32 defined.
        (u64::from(tag) >> (32 - self.bits)) as usize
    }

    /// The node holding the key with this `tag` for which `is_key(node)` says yes.
    #[inline]
    pub(crate) fn find(&self, tag: u32, mut is_key: impl FnMut(u32) -> bool) -> Option<u32> {
        if self.len == 0 {
            return None;
        }
        let mask = self.mask();
        let mut i = self.home(tag);
        loop {
            let b = self.buckets[i];
            if b.node == EMPTY {
                return None;
            }
            if b.tag == tag && is_key(b.node) {
                return Some(b.node);
            }
            i = (i + 1) & mask;
        }
    }

    /// Adds `node` under `tag`. The caller makes sure its key is not in the index already.
    pub(crate) fn insert(&mut self, tag: u32, node: u32) {
        debug_assert_ne!(node, EMPTY);
        // At most 3/4 full: linear probing's expected probe lengths stay short (2.5 buckets for
        // a hit, at worst).
        if (self.len + 1) * 4 > self.buckets.len() * 3 {
            self.grow();
        }
        self.place(Bucket { tag, node });
        self.len += 1;
    }

    /// Removes `node` (held under `tag`); false if it was not there.
    pub(crate) fn remove(&mut self, tag: u32, node: u32) -> bool {
        if self.len == 0 {
            return false;
        }
        let mask = self.mask();
        let mut i = self.home(tag);
        loop {
            let b = self.buckets[i];
            if b.node == EMPTY {
                return false;
            }
            if b.node == node {
                break;
            }
            i = (i + 1) & mask;
        }
        // Backward shift: pull each later bucket of the run into the hole if the hole lies
        // between its home and where it sits, so every key stays reachable from its home
        // without passing an empty bucket.
        let mut hole = i;
        let mut j = (i + 1) & mask;
        loop {
            let b = self.buckets[j];
            if b.node == EMPTY {
                break;
            }
            let home = self.home(b.tag);
            if (hole.wrapping_sub(home) & mask) < (j.wrapping_sub(home) & mask) {
                self.buckets[hole] = b;
                hole = j;
            }
            j = (j + 1) & mask;
        }
        self.buckets[hole] = VACANT;
        self.len -= 1;
        true
    }

    fn place(&mut self, b: Bucket) {
        let mask = self.mask();
        let mut i = self.home(b.tag);
        while self.buckets[i].node != EMPTY {
            i = (i + 1) & mask;
        }
        self.buckets[i] = b;
    }

    #[cold]
    fn grow(&mut self) {
        let count = (self.buckets.len() * 2).max(MIN_BUCKETS);
        // Homes are the tag's top bits: 2³² buckets at most (3 billion entries in one shard, a
        // few hundred gigabytes of nodes: the LRU slab's u32 indices give out about there too).
        assert!(count.trailing_zeros() <= 32, "geometry cache: a shard's hash index outgrew 2^32 buckets");
        let old = std::mem::replace(&mut self.buckets, vec![VACANT; count].into_boxed_slice());
        self.bits = count.trailing_zeros();
        for b in old.iter().filter(|b| b.node != EMPTY) {
            self.place(*b);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// A small deterministic generator (xorshift) for the model test.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
    }

    #[test]
    fn agrees_with_a_hash_map_under_churn() {
        // Keys (mesh, subpatch) → node numbers. Odd subpatches get a narrow tag (8 distinct
        // values), so many keys share tags and runs are long: the key comparison and the
        // backward shift over mixed runs are both exercised.
        let tag_of = |(m, s): (u32, u32)| if s % 2 == 0 { tag(m, 0, s) } else { tag(m, 0, s) & 0xe000_0000 };
        let mut index = NodeIndex::default();
        let mut model: HashMap<(u32, u32), u32> = HashMap::new();
        let mut nodes: Vec<(u32, u32)> = Vec::new();
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        for step in 0..100_000 {
            let key = ((rng.next() % 3) as u32, (rng.next() % 3_000) as u32);
            let found = index.find(tag_of(key), |n| nodes[n as usize] == key);
            assert_eq!(found, model.get(&key).copied(), "step {step}");
            match found {
                Some(n) if rng.next() % 3 != 0 => {
                    assert!(index.remove(tag_of(key), n));
                    assert!(!index.remove(tag_of(key), n));
                    model.remove(&key);
                }
                Some(_) => {}
                None => {
                    let n = nodes.len() as u32;
                    nodes.push(key);
                    index.insert(tag_of(key), n);
                    model.insert(key, n);
                }
            }
            assert_eq!(index.len(), model.len());
        }
        for (&key, &n) in &model {
            assert_eq!(index.find(tag_of(key), |x| nodes[x as usize] == key), Some(n));
        }
        assert!(index.len() > 1000 && index.len() * 4 <= index.buckets.len() * 3);
    }

    #[test]
    fn empty_index_finds_nothing_and_allocates_nothing() {
        let mut index = NodeIndex::default();
        assert_eq!(index.find(7, |_| true), None);
        assert!(!index.remove(7, 0));
        assert_eq!(index.heap_bytes(), 0);
        index.insert(7, 0);
        assert_eq!(index.heap_bytes(), MIN_BUCKETS * 8);
        assert_eq!(index.find(7, |n| n == 0), Some(0));
    }

    #[test]
    fn tags_spread_one_shards_subpatches_over_the_buckets() {
        // Subpatches of one shard of 16 (all ≡ 5 mod 16), 4,096 of them into 8,192 buckets:
        // home buckets should be about as spread as random ones (~3,150 distinct, not ~512).
        let homes: std::collections::HashSet<u32> = (0..4096u32).map(|k| tag(3, 0, 16 * k + 5) >> (32 - 13)).collect();
        assert!(homes.len() > 2_900, "{} distinct home buckets", homes.len());
    }
}
