//! One tier of the cache (the paper's §5.2): an LRU of tessellations under a byte budget, with
//! single-flight builds and the §6.1 counters.
//!
//! A tier is split into shards by key, each with its own lock, LRU, budget share and counters,
//! so threads looking up different subpatches rarely meet. Sharding turns one exact LRU into
//! several, which evicts slightly differently; so a tier is only split while every shard still
//! holds at least [`MIN_ENTRIES_PER_SHARD`] entries, where the approximation is close, and small
//! caches (whose hit rates depend most on the replacement order) keep one exact LRU. See
//! [`CacheConfig::shard_count`].

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::sync::Arc;
use std::thread::{self, ThreadId};

use parking_lot::{Condvar, Mutex};

use super::lru::LruList;
use super::seen::{FxBuild, SeenSet};
use super::stats::{tier_stats, LookupCounters};
#[cfg(doc)]
use super::CacheConfig;
use super::{CacheEntry, CacheKey, Tier, TierStats};

/// The most shards an automatic split makes: enough for 16 threads to rarely collide.
pub(crate) const MAX_SHARDS: usize = 16;

/// The fewest entries (of the configured size) an automatic split leaves in each shard.
pub(crate) const MIN_ENTRIES_PER_SHARD: usize = 256;

/// The most shards [`CacheConfig::with_shards`] may ask for.
pub(crate) const MAX_FORCED_SHARDS: usize = 64;

/// Spreads meshes over shards: odd, so `mesh × PHI mod n` visits every shard.
const PHI: u32 = 0x9e37_79b9;

pub(crate) struct TierCache<E> {
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
// adjacent-line prefetcher pairs lines).
#[repr(align(128))]
struct Shard<E> {
    state: Mutex<ShardState<E>>,
    counters: LookupCounters,
}

struct ShardState<E> {
    slots: HashMap<CacheKey, Slot<E>, FxBuild>,
    lru: LruList<Resident<E>>,
    /// Sum of the resident entries' `bytes`; never above the shard's budget.
    resident_bytes: usize,
}

pub(super) enum Slot<E> {
    /// In the LRU list at this node.
    Resident(u32),
    /// Being built by one thread; others wait on it.
    Building(Arc<Pending<E>>),
}

pub(super) struct Resident<E> {
    key: CacheKey,
    entry: Arc<E>,
    /// `entry.byte_size()` when it was stored: exactly what evicting it frees.
    bytes: usize,
}

/// One build in flight, which other lookups of the same key wait for.
pub(super) struct Pending<E> {
    builder: ThreadId,
    state: Mutex<PendingState<E>>,
    done: Condvar,
}

enum PendingState<E> {
    Building,
    Built(Arc<E>),
    /// The build panicked; waiters look up again and one of them builds.
    Abandoned,
}

impl<E> Pending<E> {
    fn new() -> Self {
        Self { builder: thread::current().id(), state: Mutex::new(PendingState::Building), done: Condvar::new() }
    }

    fn finish(&self, state: PendingState<E>) {
        *self.state.lock() = state;
        self.done.notify_all();
    }

    /// The built entry, or `None` if the build was abandoned.
    fn wait(&self) -> Option<Arc<E>> {
        let mut state = self.state.lock();
        loop {
            match &*state {
                PendingState::Building => self.done.wait(&mut state),
                PendingState::Built(entry) => return Some(Arc::clone(entry)),
                PendingState::Abandoned => return None,
            }
        }
    }
}

/// Whether `slot` is still the registration of the build `pending` (invalidation or a panic may
/// have removed it, and a new build may have taken its place).
fn is_build<E>(slot: Option<&Slot<E>>, pending: &Arc<Pending<E>>) -> bool {
    matches!(slot, Some(Slot::Building(p)) if Arc::ptr_eq(p, pending))
}

/// Unregisters a build if its closure panics, so waiters do not wait forever and the key can be
/// built again.
struct AbandonOnUnwind<'a, E> {
    shard: &'a Shard<E>,
    key: CacheKey,
    pending: &'a Arc<Pending<E>>,
    armed: bool,
}

impl<E> Drop for AbandonOnUnwind<'_, E> {
    fn drop(&mut self) {
        if self.armed {
            let mut st = self.shard.state.lock();
            if is_build(st.slots.get(&self.key), self.pending) {
                st.slots.remove(&self.key);
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
                    state: Mutex::new(ShardState { slots: HashMap::default(), lru: LruList::default(), resident_bytes: 0 }),
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

    /// See [`GeometryCache::get_or_build`](super::GeometryCache::get_or_build).
    pub(crate) fn get_or_build(&self, key: CacheKey, build: impl FnOnce() -> E) -> Arc<E> {
        let shard = self.shard_of(&key);
        LookupCounters::add(&shard.counters.lookups, 1);

        if !self.stores {
            let cold = self.first_build(&key);
            shard.counters.count_build(cold);
            let entry = Arc::new(build());
            self.record_build(shard, cold, &entry);
            return entry;
        }

        loop {
            let found = {
                let mut st = shard.state.lock();
                match st.slots.get(&key) {
                    Some(&Slot::Resident(node)) => {
                        st.lru.touch(node);
                        let entry = Arc::clone(&st.lru.get(node).entry);
                        drop(st);
                        LookupCounters::add(&shard.counters.hits, 1);
                        return entry;
                    }
                    Some(Slot::Building(pending)) => Err(Arc::clone(pending)),
                    None => {
                        let pending = Arc::new(Pending::new());
                        st.slots.insert(key, Slot::Building(Arc::clone(&pending)));
                        Ok(pending)
                    }
                }
            };
            match found {
                Ok(pending) => {
                    // Outside the shard lock: only this thread builds `key` now, and a later
                    // builder of it can only start after this one registered and finished.
                    let cold = self.first_build(&key);
                    shard.counters.count_build(cold);
                    return self.build_and_store(shard, key, &pending, cold, build);
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
    fn build_and_store(&self, shard: &Shard<E>, key: CacheKey, pending: &Arc<Pending<E>>, cold: bool, build: impl FnOnce() -> E) -> Arc<E> {
        let mut guard = AbandonOnUnwind { shard, key, pending, armed: true };
        let entry = Arc::new(build());
        // `byte_size` and `vertex_count` are the entry's code too: still under the guard.
        let bytes = self.record_build(shard, cold, &entry);
        guard.armed = false;
        let evicted = self.store(shard, key, pending, &entry, bytes);
        pending.finish(PendingState::Built(Arc::clone(&entry)));
        // Evicted entries are freed here, outside the lock (unless a ray still holds them).
        drop(evicted);
        entry
    }

    /// Makes `entry` resident, evicting least recently used entries of its shard until it fits.
    /// Does nothing if the build was unregistered meanwhile (its mesh was invalidated); only
    /// unregisters it if it is larger than the shard's whole budget. Returns the evicted entries.
    fn store(&self, shard: &Shard<E>, key: CacheKey, pending: &Arc<Pending<E>>, entry: &Arc<E>, bytes: usize) -> Vec<Arc<E>> {
        let mut evicted = Vec::new();
        let mut st = shard.state.lock();
        if !is_build(st.slots.get(&key), pending) {
            return evicted;
        }
        if bytes > self.shard_budget_bytes {
            // Too large to ever fit: returned to the caller, not stored, nothing evicted for it.
            st.slots.remove(&key);
            return evicted;
        }
        while st.resident_bytes.saturating_add(bytes) > self.shard_budget_bytes {
            let Some(old) = st.lru.pop_back() else { break };
            st.slots.remove(&old.key);
            st.resident_bytes -= old.bytes;
            self.resident_bytes.fetch_sub(old.bytes, Relaxed);
            evicted.push(old.entry);
        }
        let node = st.lru.push_front(Resident { key, entry: Arc::clone(entry), bytes });
        st.slots.insert(key, Slot::Resident(node));
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
            let mut dropped = Vec::new();
            let mut st = shard.state.lock();
            let ShardState { slots, lru, resident_bytes } = &mut *st;
            slots.retain(|key, slot| {
                if key.mesh != mesh {
                    return true;
                }
                if let Slot::Resident(node) = *slot {
                    let old = lru.remove(node);
                    *resident_bytes -= old.bytes;
                    self.resident_bytes.fetch_sub(old.bytes, Relaxed);
                    dropped.push(old.entry);
                }
                false
            });
            drop(st);
            drop(dropped);
        }
        self.seen.lock().forget_mesh(mesh);
    }

    pub(crate) fn contains(&self, key: &CacheKey) -> bool {
        let st = self.shard_of(key).state.lock();
        matches!(st.slots.get(key), Some(Slot::Resident(_)))
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
