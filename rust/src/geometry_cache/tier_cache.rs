//! One tier of the cache (the paper's §5.2): tessellations under a byte budget, evicted in LRU
//! order approximated by second chance (a hit marks its entry instead of moving it to the
//! front; see the module docs of `geometry_cache`), with single-flight builds and the §6.1
//! counters.
//!
//! A tier is split into shards by key, each with its own lock, LRU, budget share and counters,
//! so threads looking up different subpatches rarely meet. Sharding turns one recency order into
//! several, which evicts slightly differently; so a tier is only split while every shard still
//! holds at least [`MIN_ENTRIES_PER_SHARD`] entries, where the approximation is close, and small
//! caches (whose hit rates depend most on the replacement order) keep one order. See
//! [`CacheConfig::shard_count`].

use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::sync::Arc;
use std::thread::{self, ThreadId};

use parking_lot::{Condvar, Mutex};

use super::lru::LruList;
use super::seen::SeenSet;
use super::stats::{tier_stats, LookupCounters};
use super::table::{tag, NodeIndex};
#[cfg(doc)]
use super::CacheConfig;
use super::{CacheEntry, CacheKey, Tier, TierStats};

/// The most shards an automatic split makes: enough for 16 threads to rarely collide.
pub(crate) const MAX_SHARDS: usize = 16;

/// The fewest entries (of the configured size) an automatic split leaves in each shard.
pub(crate) const MIN_ENTRIES_PER_SHARD: usize = 256;

/// The most shards [`CacheConfig::with_shards`] may ask for.
pub(crate) const MAX_FORCED_SHARDS: usize = 64;

/// Evicted entries a shard keeps for builds to reuse (see [`ShardState::spares`]).
pub(crate) const MAX_SPARES: usize = 4;

/// Spreads meshes over shards: odd, so `mesh × PHI mod n` visits every shard.
const PHI: u32 = 0x9e37_79b9;

pub(crate) struct TierCache<E: CacheEntry> {
    /// A power-of-two number of shards.
    shards: Box<[Shard<E>]>,
    /// Every key this tier ever built. One per tier, not per shard (it would cost each mesh a
    /// record in every shard); it is locked only when a lookup builds, never on a hit.
    seen: Mutex<SeenSet>,
    /// Bytes each shard may hold (the tier's budget over the shard count); `usize::MAX` when
    /// unbounded.
    shard_budget_bytes: usize,
    /// False in `none` mode: every lookup builds, nothing is kept.
    stores: bool,
    /// Bytes resident in all shards.
    resident_bytes: AtomicUsize,
    peak_bytes: AtomicUsize,
    /// The largest `byte_size` of any entry built, for `capacity_entries`.
    largest_entry_bytes: AtomicUsize,
}

// Aligned so neighbouring shards' locks and counters never share a cache line (128: the
// adjacent-line prefetcher pairs lines). `repr(C)` with the counters first puts their last,
// `resident_hits` (written by every hit, under the lock), on the lock word's cache line, which
// the hit owns already: a hit writes no other line of the shard's for its count.
#[repr(C, align(128))]
struct Shard<E: CacheEntry> {
    counters: LookupCounters,
    state: Mutex<ShardState<E>>,
}

/// A shard's resident entries and builds in flight.
///
/// A resident entry is one LRU node holding the entry itself (in its stored form), its key and
/// its size, and one 8-byte bucket of `index` (key hash → node): no allocation per entry beyond
/// what the entry itself holds, no per-entry reference count. Lookups hand out entries made from
/// the stored form (cheap by contract: a tessellation keeps a coarse grid inline and larger grids
/// behind an `Arc`).
struct ShardState<E: CacheEntry> {
    index: NodeIndex,
    lru: LruList<Resident<E>>,
    /// Keys being built, each by one thread that others wait for. Rarely more than a few (at
    /// most one per render thread), so a list beats a map.
    building: Vec<(NodeKey, Arc<Pending<E>>)>,
    /// The last few entries evicted, handed to the next builds of this shard to refill (their
    /// vertex blocks, if no ray still holds them). A full tier evicts about one entry per build,
    /// so in a steady state its vertex blocks are recycled, never freed and allocated again.
    /// Freeing them leaves a hole per eviction in the allocator arena of whichever thread built
    /// the entry, while the evicting thread allocates the next one in its own arena: measured,
    /// 5 MB of holes in the cache benchmark at 30 MB with two render threads, 6.5 MB with four.
    /// At most [`MAX_SPARES`]; not counted as resident.
    spares: Vec<E::Stored>,
    /// Sum of the resident entries' `bytes`; never above the shard's budget.
    resident_bytes: usize,
}

/// A key within its tier: the tier is the cache's, not the node's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct NodeKey {
    mesh: u32,
    generation: u32,
    subpatch: u32,
}

impl NodeKey {
    #[inline]
    fn of(key: &CacheKey) -> Self {
        Self { mesh: key.mesh, generation: key.generation, subpatch: key.subpatch }
    }

    #[inline]
    fn tag(&self) -> u32 {
        tag(self.mesh, self.generation, self.subpatch)
    }
}

/// One resident entry: the value of an LRU node.
pub(super) struct Resident<E: CacheEntry> {
    entry: E::Stored,
    key: NodeKey,
    /// In the low 31 bits `entry.byte_size()` when it was stored: exactly what evicting it
    /// frees (entries of 2 GiB or more are never stored). In the top bit ([`REFERENCED`]): a
    /// lookup found it since it last came to the front of the LRU order. One word for both keeps
    /// a coarse tessellation's node at 88 bytes.
    size_and_referenced: u32,
}

/// The "referenced" bit of [`Resident::size_and_referenced`].
const REFERENCED: u32 = 1 << 31;

impl<E: CacheEntry> Resident<E> {
    /// A new entry of `bytes` (below 2 GiB), not referenced yet.
    fn new(entry: E::Stored, key: NodeKey, bytes: u32) -> Self {
        debug_assert!(bytes < REFERENCED);
        Self { entry, key, size_and_referenced: bytes }
    }

    #[inline]
    fn bytes(&self) -> usize {
        (self.size_and_referenced & !REFERENCED) as usize
    }

    #[inline]
    fn referenced(&self) -> bool {
        self.size_and_referenced & REFERENCED != 0
    }

    /// Clears the mark (eviction's second chance used up).
    #[inline]
    fn unmark(&mut self) {
        self.size_and_referenced &= !REFERENCED;
    }

    /// Marks a found entry. Writes only if it is not marked yet: a hot entry's node is then only
    /// read, and stays in every reading thread's cache.
    #[inline]
    fn mark_referenced(&mut self) {
        if !self.referenced() {
            self.size_and_referenced |= REFERENCED;
        }
    }
}

/// One build in flight, which other lookups of the same key wait for.
struct Pending<E: CacheEntry> {
    builder: ThreadId,
    state: Mutex<PendingState<E>>,
    done: Condvar,
}

enum PendingState<E: CacheEntry> {
    Building,
    Built(E::Stored),
    /// The build panicked; waiters look up again and one of them builds.
    Abandoned,
}

impl<E: CacheEntry> Pending<E> {
    fn new() -> Self {
        Self { builder: thread::current().id(), state: Mutex::new(PendingState::Building), done: Condvar::new() }
    }

    fn finish(&self, state: PendingState<E>) {
        *self.state.lock() = state;
        self.done.notify_all();
    }

    /// The built entry, or `None` if the build was abandoned.
    fn wait(&self) -> Option<E> {
        let mut state = self.state.lock();
        loop {
            match &*state {
                PendingState::Building => self.done.wait(&mut state),
                PendingState::Built(entry) => return Some(E::from_stored(entry)),
                PendingState::Abandoned => return None,
            }
        }
    }
}

impl<E: CacheEntry> ShardState<E> {
    /// The node of resident `key`.
    #[inline]
    fn find(&self, key: &NodeKey) -> Option<u32> {
        self.index.find(key.tag(), |node| self.lru.get(node).key == *key)
    }

    /// Where in `building` the build `pending` of `key` is registered, if it still is
    /// (invalidation or a panic may have removed it, and a new build may have taken its place).
    fn build_position(&self, key: &NodeKey, pending: &Arc<Pending<E>>) -> Option<usize> {
        self.building.iter().position(|(k, p)| k == key && Arc::ptr_eq(p, pending))
    }

    /// Removes resident node `node`, returning its entry and bytes.
    fn remove(&mut self, node: u32) -> Resident<E> {
        let old = self.lru.remove(node);
        let found = self.index.remove(old.key.tag(), node);
        debug_assert!(found, "resident node {node} was not indexed");
        self.resident_bytes -= old.bytes();
        old
    }
}

/// Unregisters a build if its closure panics, so waiters do not wait forever and the key can be
/// built again.
struct AbandonOnUnwind<'a, E: CacheEntry> {
    shard: &'a Shard<E>,
    key: NodeKey,
    pending: &'a Arc<Pending<E>>,
    armed: bool,
}

impl<E: CacheEntry> Drop for AbandonOnUnwind<'_, E> {
    fn drop(&mut self) {
        if self.armed {
            let mut st = self.shard.state.lock();
            if let Some(i) = st.build_position(&self.key, self.pending) {
                st.building.swap_remove(i);
            }
            drop(st);
            self.pending.finish(PendingState::Abandoned);
        }
    }
}

impl<E: CacheEntry> TierCache<E> {
    /// A tier of `shards` shards (a power of two) sharing `budget_bytes` (`None`: unbounded);
    /// `stores` false for `none` mode.
    pub(crate) fn new(shards: usize, budget_bytes: Option<usize>, stores: bool) -> Self {
        debug_assert!(shards.is_power_of_two());
        let shards = shards.max(1);
        Self {
            shards: (0..shards)
                .map(|_| Shard {
                    state: Mutex::new(ShardState {
                        index: NodeIndex::default(),
                        lru: LruList::default(),
                        building: Vec::new(),
                        spares: Vec::new(),
                        resident_bytes: 0,
                    }),
                    counters: LookupCounters::default(),
                })
                .collect(),
            seen: Mutex::new(SeenSet::default()),
            shard_budget_bytes: budget_bytes.map_or(usize::MAX, |b| b / shards),
            stores,
            resident_bytes: AtomicUsize::new(0),
            peak_bytes: AtomicUsize::new(0),
            largest_entry_bytes: AtomicUsize::new(0),
        }
    }

    /// The shard of `key`. Within one mesh, consecutive subpatches go to consecutive shards
    /// (so do the neighbouring subpatches coherent rays visit), and subpatch `s` of mesh `m`
    /// lands where `s + m·PHI` says, so a scene of many one-subpatch meshes spreads too.
    #[inline]
    fn shard_of(&self, key: &CacheKey) -> &Shard<E> {
        let mix = key.subpatch.wrapping_add(key.mesh.wrapping_mul(PHI));
        &self.shards[mix as usize & (self.shards.len() - 1)]
    }

    /// Records that `key` is being built; true if it never was before (a cold tessellation).
    fn first_build(&self, key: &CacheKey) -> bool {
        self.seen.lock().insert(key.mesh, key.generation, key.subpatch)
    }

    /// See [`GeometryCache::get_or_build_reusing`](super::GeometryCache::get_or_build_reusing).
    pub(crate) fn get_or_build(&self, key: CacheKey, build: impl FnOnce(Option<E::Stored>) -> E) -> E {
        let shard = self.shard_of(&key);

        if !self.stores {
            LookupCounters::add(&shard.counters.lookups, 1);
            let cold = self.first_build(&key);
            shard.counters.count_build(cold);
            let entry = build(None);
            self.record_build(shard, cold, &entry);
            return entry;
        }

        let nk = NodeKey::of(&key);
        // Counted once (a lookup that waited for an abandoned build looks up again).
        let mut counted = false;
        loop {
            let found = {
                let mut st = shard.state.lock();
                if let Some(node) = st.find(&nk) {
                    let resident = st.lru.get_mut(node);
                    resident.mark_referenced();
                    shard.counters.count_resident_hit_locked();
                    return E::from_stored(&resident.entry);
                }
                if !counted {
                    LookupCounters::add(&shard.counters.lookups, 1);
                    counted = true;
                }
                match st.building.iter().find(|(k, _)| *k == nk) {
                    Some((_, pending)) => Err(Arc::clone(pending)),
                    None => {
                        let pending = Arc::new(Pending::new());
                        st.building.push((nk, Arc::clone(&pending)));
                        Ok((pending, st.spares.pop()))
                    }
                }
            };
            match found {
                Ok((pending, spare)) => {
                    // Outside the shard lock: only this thread builds `key` now, and a later
                    // builder of it can only start after this one registered and finished.
                    let cold = self.first_build(&key);
                    shard.counters.count_build(cold);
                    return self.build_and_store(shard, nk, &pending, cold, || build(spare));
                }
                Err(pending) => {
                    assert!(
                        pending.builder != thread::current().id(),
                        "geometry cache: the build of {key:?} looked up the same key; \
                         it would wait for itself"
                    );
                    if let Some(entry) = pending.wait() {
                        LookupCounters::add(&shard.counters.hits, 1);
                        return entry;
                    }
                    // The builder panicked and unregistered the key: look it up again.
                }
            }
        }
    }

    fn record_build(&self, shard: &Shard<E>, cold: bool, entry: &E) -> usize {
        let bytes = entry.byte_size();
        shard.counters.built(cold, entry.vertex_count());
        self.largest_entry_bytes.fetch_max(bytes, Relaxed);
        bytes
    }

    /// Builds `key` as the one thread registered to, stores it if it still may, and wakes the
    /// threads waiting for it.
    fn build_and_store(&self, shard: &Shard<E>, key: NodeKey, pending: &Arc<Pending<E>>, cold: bool, build: impl FnOnce() -> E) -> E {
        let mut guard = AbandonOnUnwind { shard, key, pending, armed: true };
        let entry = build();
        // `byte_size`, `vertex_count` and `to_stored` are the entry's code too: still under the
        // guard.
        let bytes = self.record_build(shard, cold, &entry);
        let for_waiters = entry.to_stored();
        let evicted = self.store(shard, key, pending, &entry, bytes);
        guard.armed = false;
        pending.finish(PendingState::Built(for_waiters));
        // Evicted entries not kept as spares are dropped here, outside the lock (what they
        // share with entries still held by rays lives on until those drop too).
        drop(evicted);
        entry
    }

    /// Makes `entry` resident, evicting least recently used entries of its shard until it fits.
    /// Does nothing if the build was unregistered meanwhile (its mesh was invalidated); only
    /// unregisters it if it is larger than the shard's whole budget. Returns the evicted entries.
    fn store(&self, shard: &Shard<E>, key: NodeKey, pending: &Arc<Pending<E>>, entry: &E, bytes: usize) -> Vec<E::Stored> {
        let mut evicted = Vec::new();
        let mut st = shard.state.lock();
        let Some(i) = st.build_position(&key, pending) else {
            return evicted;
        };
        st.building.swap_remove(i);
        let Some(bytes32) = u32::try_from(bytes).ok().filter(|&b| b < REFERENCED) else { return evicted };
        if bytes > self.shard_budget_bytes {
            // Too large to ever fit: returned to the caller, not stored, nothing evicted for it.
            return evicted;
        }
        while st.resident_bytes.saturating_add(bytes) > self.shard_budget_bytes {
            let Some(tail) = st.lru.back() else { break };
            // Second chance: the least recent entry, if found since it came to the front, goes
            // to the front again, unmarked, instead of being evicted. A hit then only marks its
            // node (relinking it to the front at every hit wrote three other nodes and the
            // list's head, lines the other render threads' hits write too). Each pass unmarks
            // what it passes over, so the loop ends. Eviction order is LRU's where hits are
            // rare and close to it otherwise (CLOCK).
            let tail_entry = st.lru.get_mut(tail);
            if tail_entry.referenced() {
                tail_entry.unmark();
                st.lru.touch(tail);
                continue;
            }
            let old = st.remove(tail);
            self.resident_bytes.fetch_sub(old.bytes(), Relaxed);
            if st.spares.len() < MAX_SPARES {
                st.spares.push(old.entry);
            } else {
                evicted.push(old.entry);
            }
        }
        // `to_stored` runs the entry's code under the lock; a panic in it leaves the shard
        // consistent (the key is unregistered and not yet indexed).
        let node = st.lru.push_front(Resident::new(entry.to_stored(), key, bytes32));
        st.index.insert(key.tag(), node);
        debug_assert_eq!(st.index.len(), st.lru.len());
        st.resident_bytes += bytes;
        // Every value in the total's modification order is a real moment's total (evictions
        // above are subtracted first), so the maximum of them is the exact peak.
        let total = self.resident_bytes.fetch_add(bytes, Relaxed) + bytes;
        self.peak_bytes.fetch_max(total, Relaxed);
        evicted
    }

    /// See [`GeometryCache::invalidate_mesh`](super::GeometryCache::invalidate_mesh).
    pub(crate) fn invalidate_mesh(&self, mesh: u32) {
        for shard in self.shards.iter() {
            let mut st = shard.state.lock();
            // Builds in flight are returned to their callers but not stored.
            st.building.retain(|(k, _)| k.mesh != mesh);
            let doomed: Vec<u32> = st.lru.live().filter(|(_, r)| r.key.mesh == mesh).map(|(node, _)| node).collect();
            let mut dropped = Vec::with_capacity(doomed.len());
            for node in doomed {
                let old = st.remove(node);
                self.resident_bytes.fetch_sub(old.bytes(), Relaxed);
                dropped.push(old.entry);
            }
            drop(st);
            drop(dropped);
        }
        self.seen.lock().forget_mesh(mesh);
    }

    pub(crate) fn contains(&self, key: &CacheKey) -> bool {
        let st = self.shard_of(key).state.lock();
        st.find(&NodeKey::of(key)).is_some()
    }

    pub(crate) fn shard_count(&self) -> usize {
        self.shards.len()
    }

    pub(crate) fn resident_entries(&self) -> usize {
        self.shards.iter().map(|s| s.state.lock().lru.len()).sum()
    }

    pub(crate) fn resident_bytes(&self) -> usize {
        self.resident_bytes.load(Relaxed)
    }

    /// Heap bytes of the shards' LRU slabs and hash indexes: the bookkeeping of resident
    /// entries, including the entries' inline parts (not what entries allocate themselves).
    pub(crate) fn table_bytes(&self) -> usize {
        self.shards
            .iter()
            .map(|s| {
                let st = s.state.lock();
                st.lru.heap_bytes() + st.index.heap_bytes()
            })
            .sum()
    }

    pub(crate) fn seen_set_bytes(&self) -> usize {
        self.seen.lock().heap_bytes()
    }

    pub(crate) fn largest_entry_bytes(&self) -> usize {
        self.largest_entry_bytes.load(Relaxed)
    }

    /// This tier's row of the stats, without locking.
    pub(crate) fn stats(&self, tier: Tier, capacity_entries: Option<u64>) -> TierStats {
        let peak = self.peak_bytes.load(Relaxed) as u64;
        tier_stats(tier, capacity_entries, peak, self.shards.iter().map(|s| &s.counters))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry_cache::Tier;

    fn key(subpatch: u32) -> CacheKey {
        CacheKey::new(0, 0, subpatch, Tier::Fine)
    }

    /// (subpatch, referenced) from the most to the least recently used.
    fn order(tier: &TierCache<Vec<[f32; 3]>>) -> Vec<(u32, bool)> {
        tier.shards[0].state.lock().lru.iter().map(|r| (r.key.subpatch, r.referenced())).collect()
    }

    /// A hit writes no link of the LRU list (no other node, not its head): it marks its own
    /// node, once. Eviction gives a marked least recent entry one more round at the front.
    #[test]
    fn a_hit_marks_its_node_and_eviction_gives_marked_entries_a_second_chance() {
        let tier: TierCache<Vec<[f32; 3]>> = TierCache::new(1, Some(3 * 12), true);
        for s in 0..3 {
            tier.get_or_build(key(s), |_| vec![[s as f32; 3]]);
        }
        assert_eq!(order(&tier), [(2, false), (1, false), (0, false)]);
        for _ in 0..2 {
            assert_eq!(tier.get_or_build(key(0), |_| unreachable!("resident")), [[0.0; 3]]);
        }
        assert_eq!(tier.get_or_build(key(1), |_| unreachable!("resident")), [[1.0; 3]]);
        assert_eq!(order(&tier), [(2, false), (1, true), (0, true)], "hits only mark");
        // 0 and 1 were found since they came to the front: 2 is evicted, they go round unmarked.
        tier.get_or_build(key(3), |_| vec![[3.0; 3]]);
        assert_eq!(order(&tier), [(3, false), (1, false), (0, false)]);
        tier.get_or_build(key(4), |_| vec![[4.0; 3]]);
        assert_eq!(order(&tier), [(4, false), (3, false), (1, false)]);
        let s = tier.stats(Tier::Fine, None);
        assert_eq!((s.lookups, s.hits, s.cold_tessellations), (8, 3, 5));
    }

    /// A hit's count is written on the cache line of the shard's lock word, which the hit owns
    /// already; no other counter line is written by hits.
    #[test]
    fn a_hit_counts_on_the_lock_words_cache_line() {
        let tier: TierCache<Vec<[f32; 3]>> = TierCache::new(2, None, true);
        for shard in tier.shards.iter() {
            // SAFETY: only the lock word's address is taken; the lock is not used through it.
            let lock = unsafe { shard.state.raw() } as *const _ as usize;
            let count = shard.counters.resident_hits_addr();
            assert_eq!(lock / 64, count / 64, "lock at {lock:#x}, hit count at {count:#x}");
        }
    }
}
