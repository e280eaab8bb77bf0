//! The multiresolution geometry cache: the paper's "tessellation MIP map" (Christensen et al.
//! 2003, §3 and §5.2), with its statistics in the terms of §6.1.
//!
//! Narrow rays need fine tessellations but are coherent, so a cache of few large entries serves
//! them; wide rays are incoherent but need only coarse tessellations, so a cache of many small,
//! cheap-to-recompute entries serves them. Hence three LRU caches ([`Tier`]s) of 2×2, 5×5 and
//! 17×17 vertices, each with its own byte budget (10 MB each by default, the paper's).
//!
//! This module only stores and counts: the caller chooses the tier from the ray's beam width and
//! passes a closure that tessellates on a miss. The cache is a pure optimisation: every
//! [`CacheMode`] must give the same pixels, only the work and memory differ.
//!
//! ```
//! use std::sync::Arc;
//! use mipray::geometry_cache::{CacheConfig, CacheKey, GeometryCache, Tier};
//!
//! // Entries are object-space vertices; `Vec<[f32; 3]>` is a `CacheEntry` of 12 bytes a vertex.
//! let cache: GeometryCache<Vec<[f32; 3]>> = GeometryCache::new(CacheConfig::default());
//! let key = CacheKey::new(0, 0, 7, Tier::Coarse);
//! let grid = cache.get_or_build(key, || vec![[0.0; 3]; 4]); // a cold tessellation
//! let again = cache.get_or_build(key, || unreachable!("resident")); // a hit
//! assert!(Arc::ptr_eq(&grid, &again));
//! let coarse = cache.stats().tiers[Tier::Coarse.index()].clone();
//! assert_eq!((coarse.lookups, coarse.cold_tessellations, coarse.hits), (2, 1, 1));
//! ```
//!
//! # Threads
//! One [`GeometryCache`] is shared by all render threads. Each tier has one mutex, held only for
//! a hash lookup and an O(1) LRU splice, never while building. A lookup of a key that another
//! thread is building waits for that build (on a per-build condition variable) instead of
//! building it twice, and counts as a hit. Counters are relaxed atomics, so [`GeometryCache::stats`]
//! never stops the renderer. (Sharding each tier by key hash would cut contention further, but
//! would turn one exact LRU into several approximate ones and change the hit rates the paper's
//! tables are compared with; with a lock held for well under a microsecond it is not needed yet.)
//!
//! # What the budget counts
//! A tier's budget is compared with the sum of its resident entries' [`CacheEntry::byte_size`]:
//! the tessellation payload, as the paper counts it (12 bytes a vertex, §5.2), so capacities and
//! hit rates compare with its tables. Bookkeeping is not counted: per resident entry about 36–73
//! bytes of hash-table slot, 40 bytes of LRU node and 16 bytes of `Arc` header, plus the entry's
//! own headers (a `Vec` is 24 bytes). Next to a fine entry (3,468 bytes) that is noise; next to
//! a coarse one (48 bytes) it more than doubles the real memory, so a full 10 MB coarse tier
//! takes about 30 MB. An entry type that must bound real memory can count its overhead in
//! `byte_size` (and in [`CacheConfig::entry_bytes`]). Entries handed out stay alive, uncounted,
//! until the last ray holding one drops it.
//!
//! To tell cold tessellations from misses, each tier remembers every key it ever built: one bit
//! per subpatch id per (mesh, generation) — 121 KB per tier for the paper's 970,000-subpatch
//! city street — see the `seen` module.

mod lru;
mod seen;
mod stats;
#[cfg(test)]
mod tests;
mod tier;

use std::collections::HashMap;
use std::fmt;
use std::hash::{Hash, Hasher};
use std::str::FromStr;
use std::sync::Arc;
use std::thread::{self, ThreadId};

use parking_lot::{Condvar, Mutex};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use lru::LruList;
use seen::{FxBuild, SeenSet};
use stats::TierCounters;

pub use stats::{CacheStats, TierStats};
pub use tier::{ParseTierError, Tier, VERTEX_BYTES};

/// The default budget of each tier in multires mode: 10 MB, the paper's (§5.2). Decimal
/// megabytes: the paper's capacities (220,000 / 35,000 / 3,000 entries) come out of binary
/// ones (10 MiB); see [`CacheConfig::capacity_entries`].
pub const DEFAULT_TIER_BUDGET_BYTES: usize = 10_000_000;

/// A tessellation the cache can hold.
pub trait CacheEntry: Send + Sync + 'static {
    /// Bytes this entry counts against its tier's budget: its tessellation payload (12 bytes a
    /// vertex, plus e.g. the fine tier's sub-bounding boxes if it holds them). Called once, when
    /// the entry is built; it must not change afterwards. For `capacity_entries` to be exact it
    /// should equal [`CacheConfig::entry_bytes`] for the entry's tier.
    fn byte_size(&self) -> usize;

    /// Vertices computed to build this entry (counted as cold or recomputed vertices).
    fn vertex_count(&self) -> usize;
}

/// A bare grid of object-space vertices, 12 bytes each.
impl CacheEntry for Vec<[f32; 3]> {
    fn byte_size(&self) -> usize {
        self.len() * VERTEX_BYTES
    }
    fn vertex_count(&self) -> usize {
        self.len()
    }
}

/// What identifies one tessellation: a subpatch of a mesh at one tier.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct CacheKey {
    /// The mesh (for an instance, its prototype: instances share tessellations).
    pub mesh: u32,
    /// Bumped by the owner whenever the mesh's points or displacement change, so a tessellation
    /// of the old shape, even one still being built, can never answer for the new one.
    pub generation: u32,
    /// The subpatch's id within the mesh (dense ids keep the ever-built set small).
    pub subpatch: u32,
    /// The tessellation rate.
    pub tier: Tier,
}

impl CacheKey {
    /// A key from its parts.
    pub const fn new(mesh: u32, generation: u32, subpatch: u32, tier: Tier) -> Self {
        Self {
            mesh,
            generation,
            subpatch,
            tier,
        }
    }
}

// Two words instead of four writes: cheaper with FxHash, and consistent with the derived `Eq`
// because the packing is one-to-one.
impl Hash for CacheKey {
    fn hash<H: Hasher>(&self, h: &mut H) {
        h.write_u64((u64::from(self.mesh) << 32) | u64::from(self.generation));
        h.write_u64((u64::from(self.subpatch) << 8) | self.tier.index() as u64);
    }
}

/// How the cache stores tessellations. The paper compares the first two (§6); the last two are
/// the bounds: all memory, or no memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CacheMode {
    /// Three LRU tiers (coarse, medium, fine), each with its own budget. The default.
    #[default]
    Multires,
    /// The single-resolution cache the paper compares against: only the fine tier (17×17), with
    /// the whole budget. Callers ask only for [`Tier::Fine`]; a coarse or medium lookup is built
    /// and returned but never stored (its tier has a budget of 0).
    Single,
    /// Never evicts: its peak bytes are what a full tessellation of everything touched costs.
    Unbounded,
    /// Never stores: every lookup builds (retessellates for every ray–subpatch test). A key's
    /// first build counts as a cold tessellation, every later one as a miss, and those misses'
    /// vertices as recomputed vertices; hits are always 0. Concurrent lookups of one key do not
    /// wait for each other: each builds.
    None,
}

impl CacheMode {
    /// Every mode, in the order of the docs.
    pub const ALL: [CacheMode; 4] = [
        CacheMode::Multires,
        CacheMode::Single,
        CacheMode::Unbounded,
        CacheMode::None,
    ];

    /// "multires", "single", "unbounded" or "none": the name in stats and options.
    pub const fn name(self) -> &'static str {
        match self {
            CacheMode::Multires => "multires",
            CacheMode::Single => "single",
            CacheMode::Unbounded => "unbounded",
            CacheMode::None => "none",
        }
    }
}

impl fmt::Display for CacheMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A cache mode name that is not one of the four.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error("unknown geometry cache mode \"{name}\" (valid: multires, single, unbounded, none)")]
pub struct ParseCacheModeError {
    /// The name that was given.
    pub name: String,
}

impl FromStr for CacheMode {
    type Err = ParseCacheModeError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        CacheMode::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| ParseCacheModeError { name: s.to_owned() })
    }
}

/// The cache's mode and budgets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CacheConfig {
    /// How entries are stored.
    pub mode: CacheMode,
    /// Bytes each tier may hold, indexed by [`Tier::index`] (coarse, medium, fine). Used as
    /// given in `multires` mode; `single` uses only the fine budget; `unbounded` and `none`
    /// ignore it.
    pub budget_bytes: [usize; 3],
    /// Bytes one entry of each tier is expected to report as its [`CacheEntry::byte_size`]; used
    /// only to report `capacity_entries`. Default [`Tier::vertex_bytes`]: 48, 300, 3,468.
    pub entry_bytes: [usize; 3],
}

impl Default for CacheConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl CacheConfig {
    /// The paper's default: multires, 10 MB per tier.
    pub const DEFAULT: CacheConfig = CacheConfig::multires(3 * DEFAULT_TIER_BUDGET_BYTES);

    const NOMINAL_ENTRY_BYTES: [usize; 3] = [
        Tier::Coarse.vertex_bytes(),
        Tier::Medium.vertex_bytes(),
        Tier::Fine.vertex_bytes(),
    ];

    /// Three tiers sharing `total_bytes` evenly (the fine tier takes the 0–2 bytes of rounding,
    /// so the budgets add up to `total_bytes`).
    pub const fn multires(total_bytes: usize) -> Self {
        let third = total_bytes / 3;
        Self {
            mode: CacheMode::Multires,
            budget_bytes: [third, third, total_bytes - 2 * third],
            entry_bytes: Self::NOMINAL_ENTRY_BYTES,
        }
    }

    /// Only the fine tier, with all of `total_bytes`.
    pub const fn single(total_bytes: usize) -> Self {
        Self {
            mode: CacheMode::Single,
            budget_bytes: [0, 0, total_bytes],
            entry_bytes: Self::NOMINAL_ENTRY_BYTES,
        }
    }

    /// Never evicts.
    pub const fn unbounded() -> Self {
        Self {
            mode: CacheMode::Unbounded,
            budget_bytes: [0; 3],
            entry_bytes: Self::NOMINAL_ENTRY_BYTES,
        }
    }

    /// Never stores.
    pub const fn none() -> Self {
        Self {
            mode: CacheMode::None,
            budget_bytes: [0; 3],
            entry_bytes: Self::NOMINAL_ENTRY_BYTES,
        }
    }

    /// `mode` with a total budget of `total_bytes` (ignored by `unbounded` and `none`): what a
    /// `--cache-mode`/`--cache-bytes` pair of options asks for.
    pub const fn for_mode(mode: CacheMode, total_bytes: usize) -> Self {
        match mode {
            CacheMode::Multires => Self::multires(total_bytes),
            CacheMode::Single => Self::single(total_bytes),
            CacheMode::Unbounded => Self::unbounded(),
            CacheMode::None => Self::none(),
        }
    }

    /// The same config with other per-entry sizes (each at least 1 byte), e.g. when fine entries
    /// also count their 16 sub-bounding boxes (`[48, 300, 3468 + 16 * 24]`).
    pub const fn with_entry_bytes(mut self, entry_bytes: [usize; 3]) -> Self {
        let mut i = 0;
        while i < 3 {
            self.entry_bytes[i] = if entry_bytes[i] == 0 {
                1
            } else {
                entry_bytes[i]
            };
            i += 1;
        }
        self
    }

    /// The bytes `tier` may hold in this mode; `None` when unbounded.
    pub const fn tier_budget_bytes(&self, tier: Tier) -> Option<usize> {
        match self.mode {
            CacheMode::Multires => Some(self.budget_bytes[tier.index()]),
            CacheMode::Single => Some(if matches!(tier, Tier::Fine) {
                self.budget_bytes[2]
            } else {
                0
            }),
            CacheMode::Unbounded => None,
            CacheMode::None => Some(0),
        }
    }

    /// The bytes all tiers may hold together; `None` when unbounded.
    pub const fn total_budget_bytes(&self) -> Option<usize> {
        match (
            self.tier_budget_bytes(Tier::Coarse),
            self.tier_budget_bytes(Tier::Medium),
            self.tier_budget_bytes(Tier::Fine),
        ) {
            (Some(c), Some(m), Some(f)) => Some(c.saturating_add(m).saturating_add(f)),
            _ => None,
        }
    }

    /// How many entries of [`entry_bytes`](Self::entry_bytes) `tier`'s budget holds; `None`
    /// when unbounded.
    ///
    /// At the default 10 MB (10,000,000 bytes) and 12-byte vertices: 208,333 coarse, 33,333
    /// medium and 2,883 fine entries. The paper (§5.2) says 220,000, 35,000 and 3,000, and 9,100
    /// for a single 30 MB fine cache: its megabytes are binary (10 MiB gives 218,453, 34,952,
    /// 3,023; 30 MiB gives 9,070), and its count leaves out the fine tier's sub-bounding boxes.
    pub const fn capacity_entries(&self, tier: Tier) -> Option<usize> {
        let entry = self.entry_bytes[tier.index()];
        match self.tier_budget_bytes(tier) {
            // A zero entry size (only by setting the field directly) reports 0, not a panic.
            Some(budget) => match budget.checked_div(entry) {
                Some(capacity) => Some(capacity),
                None => Some(0),
            },
            None => None,
        }
    }
}

/// The multiresolution geometry cache: three LRU tiers of shared, immutable tessellations.
/// See the [module docs](self).
pub struct GeometryCache<E: CacheEntry> {
    config: CacheConfig,
    tiers: [TierCache<E>; 3],
}

struct TierCache<E> {
    /// Bytes this tier may hold; `usize::MAX` when unbounded.
    budget_bytes: usize,
    state: Mutex<TierState<E>>,
    counters: TierCounters,
}

struct TierState<E> {
    slots: HashMap<CacheKey, Slot<E>, FxBuild>,
    lru: LruList<Resident<E>>,
    /// Sum of the resident entries' `bytes`; never above the tier's budget.
    resident_bytes: usize,
    seen: SeenSet,
}

enum Slot<E> {
    /// In the LRU list at this node.
    Resident(u32),
    /// Being built by one thread; others wait on it.
    Building(Arc<Pending<E>>),
}

struct Resident<E> {
    key: CacheKey,
    entry: Arc<E>,
    /// `entry.byte_size()` when it was stored: exactly what evicting it frees.
    bytes: usize,
}

/// One build in flight, which other lookups of the same key wait for.
struct Pending<E> {
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
        Self {
            builder: thread::current().id(),
            state: Mutex::new(PendingState::Building),
            done: Condvar::new(),
        }
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

/// Unregisters a build if its closure panics, so waiters do not wait forever and the key can be
/// built again.
struct AbandonOnUnwind<'a, E> {
    tier: &'a TierCache<E>,
    key: CacheKey,
    pending: &'a Arc<Pending<E>>,
    armed: bool,
}

impl<E> Drop for AbandonOnUnwind<'_, E> {
    fn drop(&mut self) {
        if self.armed {
            self.tier.unregister(self.key, self.pending);
            self.pending.finish(PendingState::Abandoned);
        }
    }
}

impl<E> TierCache<E> {
    /// Forgets the build `pending` of `key`, if it is still the registered one.
    fn unregister(&self, key: CacheKey, pending: &Arc<Pending<E>>) {
        let mut st = self.state.lock();
        if matches!(st.slots.get(&key), Some(Slot::Building(p)) if Arc::ptr_eq(p, pending)) {
            st.slots.remove(&key);
        }
    }
}

impl<E: CacheEntry> TierCache<E> {
    fn new(budget_bytes: Option<usize>) -> Self {
        Self {
            budget_bytes: budget_bytes.unwrap_or(usize::MAX),
            state: Mutex::new(TierState {
                slots: HashMap::default(),
                lru: LruList::default(),
                resident_bytes: 0,
                seen: SeenSet::default(),
            }),
            counters: TierCounters::default(),
        }
    }

    fn count_build(&self, cold: bool) {
        let counter = if cold {
            &self.counters.cold_tessellations
        } else {
            &self.counters.misses
        };
        TierCounters::add(counter, 1);
    }

    /// Builds `key` as the one thread registered to, stores it if it still may, and wakes the
    /// threads waiting for it.
    fn build_and_store(
        &self,
        key: CacheKey,
        pending: &Arc<Pending<E>>,
        cold: bool,
        build: impl FnOnce() -> E,
    ) -> Arc<E> {
        let mut guard = AbandonOnUnwind {
            tier: self,
            key,
            pending,
            armed: true,
        };
        let entry = Arc::new(build());
        let bytes = entry.byte_size();
        let vertices = entry.vertex_count();
        guard.armed = false;
        self.counters.built(cold, vertices);
        let evicted = self.store(key, pending, &entry, bytes);
        pending.finish(PendingState::Built(Arc::clone(&entry)));
        // Evicted entries are freed here, outside the tier lock (unless a ray still holds them).
        drop(evicted);
        entry
    }

    /// Makes `entry` resident, evicting least recently used entries until it fits. Does nothing
    /// if the build was unregistered meanwhile (its mesh was invalidated); only unregisters it if
    /// it is larger than the whole budget. Returns the evicted entries.
    fn store(
        &self,
        key: CacheKey,
        pending: &Arc<Pending<E>>,
        entry: &Arc<E>,
        bytes: usize,
    ) -> Vec<Arc<E>> {
        let mut evicted = Vec::new();
        let mut st = self.state.lock();
        let ours = matches!(st.slots.get(&key), Some(Slot::Building(p)) if Arc::ptr_eq(p, pending));
        if !ours {
            return evicted;
        }
        if bytes > self.budget_bytes {
            // Too large to ever fit: returned to the caller, not stored, nothing evicted for it.
            st.slots.remove(&key);
            return evicted;
        }
        while st.resident_bytes.saturating_add(bytes) > self.budget_bytes {
            let Some(old) = st.lru.pop_back() else { break };
            st.slots.remove(&old.key);
            st.resident_bytes -= old.bytes;
            evicted.push(old.entry);
        }
        let node = st.lru.push_front(Resident {
            key,
            entry: Arc::clone(entry),
            bytes,
        });
        st.slots.insert(key, Slot::Resident(node));
        st.resident_bytes += bytes;
        self.counters.raise_peak(st.resident_bytes);
        evicted
    }
}

impl<E: CacheEntry> GeometryCache<E> {
    /// An empty cache.
    pub fn new(config: CacheConfig) -> Self {
        let tiers = Tier::ALL.map(|t| TierCache::new(config.tier_budget_bytes(t)));
        Self { config, tiers }
    }

    /// The configuration the cache was made with.
    pub fn config(&self) -> &CacheConfig {
        &self.config
    }

    /// The tessellation of `key`: the resident one, or the one another thread is building (this
    /// thread waits for it), or else `build()`'s, which is then stored in `key.tier`'s LRU,
    /// evicting least recently used entries of that tier to keep within its budget.
    ///
    /// An entry whose [`byte_size`](CacheEntry::byte_size) exceeds its tier's whole budget is
    /// returned but not stored (and evicts nothing); so is every entry in `none` mode, and any
    /// entry of a tier without budget (coarse and medium in `single` mode).
    ///
    /// `build` runs without any cache lock held. It must not look up `key` itself, nor wait on a
    /// thread that is looking up `key`: that would wait for itself. For the same reason it should
    /// not run rayon work: while it waits in a rayon join, its thread may steal a render job that
    /// looks up `key` (which then panics, see below, rather than hanging).
    ///
    /// # Panics
    /// If `build` panics (the panic is passed on; threads waiting for this build then build the
    /// entry themselves), or if `build` looks up `key` (instead of deadlocking).
    pub fn get_or_build(&self, key: CacheKey, build: impl FnOnce() -> E) -> Arc<E> {
        let tier = &self.tiers[key.tier.index()];
        TierCounters::add(&tier.counters.lookups, 1);

        if self.config.mode == CacheMode::None {
            let cold = tier
                .state
                .lock()
                .seen
                .insert(key.mesh, key.generation, key.subpatch);
            tier.count_build(cold);
            let entry = Arc::new(build());
            tier.counters.built(cold, entry.vertex_count());
            return entry;
        }

        loop {
            let found = {
                let mut st = tier.state.lock();
                match st.slots.get(&key) {
                    Some(&Slot::Resident(node)) => {
                        st.lru.touch(node);
                        let entry = Arc::clone(&st.lru.get(node).entry);
                        drop(st);
                        TierCounters::add(&tier.counters.hits, 1);
                        return entry;
                    }
                    Some(Slot::Building(pending)) => Err(Arc::clone(pending)),
                    None => {
                        let cold = st.seen.insert(key.mesh, key.generation, key.subpatch);
                        let pending = Arc::new(Pending::new());
                        st.slots.insert(key, Slot::Building(Arc::clone(&pending)));
                        Ok((pending, cold))
                    }
                }
            };
            match found {
                Ok((pending, cold)) => {
                    tier.count_build(cold);
                    return tier.build_and_store(key, &pending, cold, build);
                }
                Err(pending) => {
                    assert!(
                        pending.builder != thread::current().id(),
                        "geometry cache: the build of {key:?} looked up the same key; it would wait for itself"
                    );
                    if let Some(entry) = pending.wait() {
                        TierCounters::add(&tier.counters.hits, 1);
                        return entry;
                    }
                    // The builder panicked and unregistered the key: look it up again.
                }
            }
        }
    }

    /// Drops every entry of `mesh` (all generations, all tiers) and frees their bytes; builds of
    /// it in flight are returned to their callers but not stored. The tiers also forget that
    /// `mesh` was ever built, so its next builds count as cold tessellations (they are of new
    /// geometry). Other meshes' entries, recency and statistics are untouched. Takes time in
    /// proportion to the resident entries: meant for edits, not for every frame.
    pub fn invalidate_mesh(&self, mesh: u32) {
        for tier in &self.tiers {
            let mut dropped = Vec::new();
            let mut st = tier.state.lock();
            let TierState {
                slots,
                lru,
                resident_bytes,
                seen,
            } = &mut *st;
            slots.retain(|key, slot| {
                if key.mesh != mesh {
                    return true;
                }
                if let Slot::Resident(node) = *slot {
                    let old = lru.remove(node);
                    *resident_bytes -= old.bytes;
                    dropped.push(old.entry);
                }
                false
            });
            seen.forget_mesh(mesh);
            drop(st);
            drop(dropped);
        }
    }

    /// Whether `key` is resident now. Does not count as a lookup nor refresh its recency.
    pub fn contains(&self, key: CacheKey) -> bool {
        let st = self.tiers[key.tier.index()].state.lock();
        matches!(st.slots.get(&key), Some(Slot::Resident(_)))
    }

    /// Entries resident in `tier` now.
    pub fn resident_entries(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].state.lock().lru.len()
    }

    /// Bytes (as entries report them) resident in `tier` now; never more than its budget.
    pub fn resident_bytes(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].state.lock().resident_bytes
    }

    /// Heap bytes of `tier`'s set of ever-built keys (bookkeeping, not counted in any budget).
    pub fn seen_set_bytes(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].state.lock().seen.heap_bytes()
    }

    /// A snapshot of the statistics, without locking (see the `stats` module on consistency).
    pub fn stats(&self) -> CacheStats {
        let tiers = Tier::ALL.map(|t| {
            let capacity = self.config.capacity_entries(t).map(|c| c as u64);
            self.tiers[t.index()].counters.snapshot(t, capacity)
        });
        CacheStats {
            mode: self.config.mode,
            budget_bytes: self.config.total_budget_bytes().map(|b| b as u64),
            cold_vertices: tiers.iter().map(|t| t.cold_vertices).sum(),
            recomputed_vertices: tiers.iter().map(|t| t.recomputed_vertices).sum(),
            tiers,
        }
    }

    /// The statistics as a plain-text table, like the paper's (for `--stats -`).
    pub fn table(&self) -> String {
        self.stats().table()
    }
}

impl<E: CacheEntry> fmt::Debug for GeometryCache<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GeometryCache")
            .field("config", &self.config)
            .field(
                "resident_entries",
                &Tier::ALL.map(|t| self.resident_entries(t)),
            )
            .field("resident_bytes", &Tier::ALL.map(|t| self.resident_bytes(t)))
            .finish()
    }
}
