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
//! use mipray::geometry_cache::{CacheConfig, CacheKey, GeometryCache, Tier};
//!
//! // Entries are object-space vertices; `Vec<[f32; 3]>` is a `CacheEntry` of 12 bytes a vertex.
//! let cache: GeometryCache<Vec<[f32; 3]>> = GeometryCache::new(CacheConfig::default());
//! let key = CacheKey::new(0, 0, 7, Tier::Coarse);
//! let grid = cache.get_or_build(key, || vec![[0.5; 3]; 4]); // a cold tessellation
//! let again = cache.get_or_build(key, || unreachable!("resident")); // a hit
//! assert_eq!(grid, again);
//! let coarse = cache.stats().tiers[Tier::Coarse.index()].clone();
//! assert_eq!((coarse.lookups, coarse.cold_tessellations, coarse.hits), (2, 1, 1));
//! ```
//!
//! # Threads
//! One [`GeometryCache`] is shared by all render threads. Each tier is split by key into shards
//! ([`CacheConfig::shard_count`]), each with a mutex held only for a hash lookup and an O(1)
//! change of recency, never while building. A hit writes only the lock's cache line and, the
//! first time, a mark in its own node: recency is kept by second chance (CLOCK), a hit marking
//! its entry and eviction sending a marked least recent entry to the front once more, because
//! relinking the found node to the front at every hit wrote its neighbours and the list's head,
//! lines the other render threads' hits kept taking back (on two threads a fifth of a displaced
//! AO render's time went to look-ups that were a twentieth of its instructions). Where hits are
//! rare the order is LRU's. A lookup of a key that another thread is building waits for
//! that build (on a per-build condition variable) instead of building it twice, and counts as a
//! hit. Counters are relaxed atomics, one set per shard on its own cache line, so lookups do not
//! contend on them and [`GeometryCache::stats`] never stops the renderer; a hit on a resident
//! entry counts under the lock, without a locked add (`stats::LookupCounters`). Sharding makes eviction
//! LRU per shard rather than per tier, so it is used only where each shard still holds hundreds
//! of entries; small caches, whose hit rates depend most on the replacement order, keep one
//! recency order over the whole tier.
//!
//! # What the budget counts
//! A tier's budget is compared with the sum of its resident entries' [`CacheEntry::byte_size`]:
//! the tessellation payload, as the paper counts it (12 bytes a vertex, §5.2, plus for a
//! [`Tessellation`](crate::tessellate::Tessellation) its two error floats, a medium or fine
//! grid's two cull boxes and a fine grid's 16 sub-boxes), so capacities and hit rates compare with its tables (208,333 / 33,333 / 2,883
//! bare-vertex entries at 10 MB). Counting the bookkeeping too would cut the coarse tier to
//! about half the paper's entries (and its hit rate with it), so the bookkeeping is kept small
//! and fixed instead. A resident entry is one slot of its shard's LRU slab, holding the entry by
//! value in its [`CacheEntry::Stored`] form beside its 12-byte key, its size and two 4-byte
//! links, and one 8-byte bucket of the shard's hash index (kept 37.5–75% full); the cache adds
//! no allocation, reference count or hash-map slot of its own (see the `lru` and `table`
//! modules). For tessellations:
//!
//! | tier | counted | real, per resident entry | before this layout |
//! |---|---|---|---|
//! | coarse (vertices inline) | 56 B | 88-byte node + 11–21 B of index: 113 B | 244 B |
//! | medium | 372 B | node, index, a 316-byte shared vertex block (336 with malloc's header) and an 80-byte one of cull boxes (96): ~544 B | 506 B |
//! | fine | 4,052 B | node, index and 3,484- and 592-byte shared blocks: ~4,210 B | ~4,200 B |
//!
//! (measured filling an unbounded cache; before, a coarse entry was an `Arc` of a 72-byte struct,
//! a separate vertex `Vec`, a 40-byte LRU node and a 33-byte hash-map slot at the map's load.)
//! So a full default 30 MB (10 MB a tier: 178,571 / 26,881 / 2,467 tessellations) takes about
//! 20 + 14.6 + 10.4 = 45 MB (the cull boxes, added later, are counted: they cost the medium
//! tier a sixth of its entries); in the geometry cache benchmark (`docs/cache-benchmark.md`) the
//! render's peak RSS is 44 MB above the same render in `none` mode, against 78 MB before. Builds
//! also refill evicted entries' blocks ([`GeometryCache::get_or_build_reusing`]) rather than
//! free and allocate them, which spares the allocator the holes that churn leaves in its
//! per-thread arenas (5 MB more in that benchmark with two render threads, 6.5 MB with four).
//! [`GeometryCache::table_bytes`] reports the slabs and indexes as allocated. Entries handed out
//! share their vertex blocks with the cache's copy; an evicted block stays alive, uncounted,
//! until the last ray holding it drops it.
//!
//! To tell cold tessellations from misses, each tier remembers every key it ever built: one bit
//! per subpatch id per (mesh, generation) — 121 KB per tier for the paper's 970,000-subpatch
//! city street — see the `seen` module. Ids stay dense because split subpatches are numbered
//! after their mesh's roots by the cache itself ([`GeometryCache::split_ids`]), which also keeps
//! each child's id fixed for as long as entries under it may be resident.

mod lru;
mod seen;
mod split_ids;
mod stats;
mod table;
#[cfg(test)]
mod tests;
mod tier;
mod tier_cache;

use std::fmt;
use std::hash::{Hash, Hasher};
use std::str::FromStr;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use split_ids::SplitIdTables;
use tier_cache::{TierCache, MAX_FORCED_SHARDS, MAX_SHARDS, MIN_ENTRIES_PER_SHARD};

pub use split_ids::SplitIds;
pub use stats::{CacheStats, TierStats};
pub use tier::{ParseTierError, Tier, VERTEX_BYTES};

/// The default budget of each tier in multires mode: 10 MB, the paper's (§5.2). Decimal
/// megabytes: the paper's capacities (220,000 / 35,000 / 3,000 entries) come out of binary
/// ones (10 MiB); see [`CacheConfig::capacity_entries`].
pub const DEFAULT_TIER_BUDGET_BYTES: usize = 10_000_000;

/// A tessellation the cache can hold.
///
/// A resident entry is kept by value, as its [`Stored`](Self::Stored) form, inside the tier's
/// LRU node; a lookup hands out a fresh `Self` made from it. Both should be small and cheap to
/// make: the stored form's size is paid by every resident entry (see "What the budget counts" in
/// the module docs), and a hit makes a `Self` under the shard's lock. Large data belongs behind
/// an `Arc` shared by both; [`crate::tessellate::Tessellation`] keeps a coarse grid inline in 64
/// bytes and larger grids shared. An entry type that is simply shared can be wrapped in `Arc`
/// (one allocation and reference count per entry; lookups hand out that allocation).
pub trait CacheEntry: Send + Sync + 'static {
    /// The form a resident entry is kept in.
    type Stored: Send + Sync + 'static;

    /// Bytes this entry counts against its tier's budget: its tessellation payload (12 bytes a
    /// vertex, plus e.g. the fine tier's sub-bounding boxes if it holds them). Called once, when
    /// the entry is built; it must not change afterwards. Every entry of a tier should report the
    /// same size (a tier is one fixed grid): its `capacity_entries` is the budget over the largest.
    fn byte_size(&self) -> usize;

    /// Vertices computed to build this entry (counted as cold or recomputed vertices).
    fn vertex_count(&self) -> usize;

    /// The form to keep this entry in while it is resident (called when it is stored, and for
    /// threads that waited for its build).
    fn to_stored(&self) -> Self::Stored;

    /// The entry a lookup of a resident one returns; equal to the one that was stored.
    fn from_stored(stored: &Self::Stored) -> Self;
}

/// A bare grid of object-space vertices, 12 bytes each. Kept and handed out as copies: fine for
/// tests and examples; a renderer shares its grids instead.
impl CacheEntry for Vec<[f32; 3]> {
    type Stored = Vec<[f32; 3]>;
    fn byte_size(&self) -> usize {
        self.len() * VERTEX_BYTES
    }
    fn vertex_count(&self) -> usize {
        self.len()
    }
    fn to_stored(&self) -> Self {
        self.clone()
    }
    fn from_stored(stored: &Self) -> Self {
        stored.clone()
    }
}

/// A shared entry: lookups hand out the one allocation that was built.
impl<T: CacheEntry> CacheEntry for Arc<T> {
    type Stored = Arc<T>;
    fn byte_size(&self) -> usize {
        (**self).byte_size()
    }
    fn vertex_count(&self) -> usize {
        (**self).vertex_count()
    }
    fn to_stored(&self) -> Self {
        Arc::clone(self)
    }
    fn from_stored(stored: &Self) -> Self {
        Arc::clone(stored)
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
    /// The subpatch's id within the mesh: a root subpatch's index, or a split child's id from
    /// [`GeometryCache::split_ids`] (dense ids keep the ever-built set small).
    pub subpatch: u32,
    /// The tessellation rate.
    pub tier: Tier,
}

impl CacheKey {
    /// A key from its parts.
    pub const fn new(mesh: u32, generation: u32, subpatch: u32, tier: Tier) -> Self {
        Self { mesh, generation, subpatch, tier }
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
    pub const ALL: [CacheMode; 4] = [CacheMode::Multires, CacheMode::Single, CacheMode::Unbounded, CacheMode::None];

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
        CacheMode::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| ParseCacheModeError { name: s.to_owned() })
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
    /// only to report `capacity_entries` until the tier has built an entry, whose real size is
    /// used from then on. Default [`Tier::vertex_bytes`]: 48, 300, 3,468.
    pub entry_bytes: [usize; 3],
    /// Shards per tier: 0 (the default) chooses automatically, see
    /// [`shard_count`](Self::shard_count).
    pub shards: usize,
}

impl Default for CacheConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl CacheConfig {
    /// The paper's default: multires, 10 MB per tier.
    pub const DEFAULT: CacheConfig = CacheConfig::multires(3 * DEFAULT_TIER_BUDGET_BYTES);

    const NOMINAL_ENTRY_BYTES: [usize; 3] = [Tier::Coarse.vertex_bytes(), Tier::Medium.vertex_bytes(), Tier::Fine.vertex_bytes()];

    /// Three tiers sharing `total_bytes` evenly (the fine tier takes the 0–2 bytes of rounding,
    /// so the budgets add up to `total_bytes`).
    pub const fn multires(total_bytes: usize) -> Self {
        let third = total_bytes / 3;
        Self {
            mode: CacheMode::Multires,
            budget_bytes: [third, third, total_bytes - 2 * third],
            entry_bytes: Self::NOMINAL_ENTRY_BYTES,
            shards: 0,
        }
    }

    /// The total budget that gives `tier` at least `tier_bytes` in this config's mode (what
    /// [`CacheConfig::multires`] and [`CacheConfig::single`] split); 0 when the mode has no
    /// budget or does not use the tier.
    pub const fn total_for_tier(&self, tier: Tier, tier_bytes: u64) -> u64 {
        match (self.mode, tier) {
            (CacheMode::Multires, _) => 3 * tier_bytes,
            (CacheMode::Single, Tier::Fine) => tier_bytes,
            _ => 0,
        }
    }

    /// Only the fine tier, with all of `total_bytes`.
    pub const fn single(total_bytes: usize) -> Self {
        Self { mode: CacheMode::Single, budget_bytes: [0, 0, total_bytes], entry_bytes: Self::NOMINAL_ENTRY_BYTES, shards: 0 }
    }

    /// Never evicts.
    pub const fn unbounded() -> Self {
        Self { mode: CacheMode::Unbounded, budget_bytes: [0; 3], entry_bytes: Self::NOMINAL_ENTRY_BYTES, shards: 0 }
    }

    /// Never stores.
    pub const fn none() -> Self {
        Self { mode: CacheMode::None, budget_bytes: [0; 3], entry_bytes: Self::NOMINAL_ENTRY_BYTES, shards: 0 }
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

    /// The same config with each tier split into `shards` shards (rounded up to a power of two,
    /// at most 64; 0 restores the automatic choice). One shard gives one recency order per tier.
    pub const fn with_shards(mut self, shards: usize) -> Self {
        self.shards = shards;
        self
    }

    /// Shards `tier` is split into. Each shard has its own lock, LRU, counters and an equal
    /// share of the budget, so threads rarely wait for each other; but eviction is then LRU per
    /// shard, not over the whole tier. So, unless [`shards`](Self::shards) says otherwise, a
    /// budgeted tier is halved only while each shard keeps at least 256 entries of
    /// [`entry_bytes`](Self::entry_bytes), up to 16 shards: at the default 10 MB, 16 coarse, 16
    /// medium and 8 fine shards (of 360 fine entries each); a tier of fewer than 512 entries
    /// stays one recency order. `unbounded` and `none` tiers never evict, so sharding changes nothing
    /// there but contention: 16.
    pub const fn shard_count(&self, tier: Tier) -> usize {
        if self.shards > 0 {
            let n = self.shards.next_power_of_two();
            return if n < MAX_FORCED_SHARDS { n } else { MAX_FORCED_SHARDS };
        }
        let capacity = match self.mode {
            CacheMode::Unbounded | CacheMode::None => return MAX_SHARDS,
            CacheMode::Multires | CacheMode::Single => match self.capacity_entries(tier) {
                Some(c) => c,
                None => return MAX_SHARDS,
            },
        };
        let mut n = 1;
        while n < MAX_SHARDS && capacity / (2 * n) >= MIN_ENTRIES_PER_SHARD {
            n *= 2;
        }
        n
    }

    /// The same config with other per-entry sizes (each at least 1 byte), e.g. when fine entries
    /// also count their 16 sub-bounding boxes (`[48, 300, 3468 + 16 * 32]` for `Vec3A` boxes).
    pub const fn with_entry_bytes(mut self, entry_bytes: [usize; 3]) -> Self {
        let mut i = 0;
        while i < 3 {
            self.entry_bytes[i] = if entry_bytes[i] == 0 { 1 } else { entry_bytes[i] };
            i += 1;
        }
        self
    }

    /// The bytes `tier` may hold in this mode; `None` when unbounded.
    pub const fn tier_budget_bytes(&self, tier: Tier) -> Option<usize> {
        match self.mode {
            CacheMode::Multires => Some(self.budget_bytes[tier.index()]),
            CacheMode::Single => Some(if matches!(tier, Tier::Fine) { self.budget_bytes[2] } else { 0 }),
            CacheMode::Unbounded => None,
            CacheMode::None => Some(0),
        }
    }

    /// The bytes all tiers may hold together; `None` when unbounded.
    pub const fn total_budget_bytes(&self) -> Option<usize> {
        match (self.tier_budget_bytes(Tier::Coarse), self.tier_budget_bytes(Tier::Medium), self.tier_budget_bytes(Tier::Fine)) {
            (Some(c), Some(m), Some(f)) => Some(c.saturating_add(m).saturating_add(f)),
            _ => None,
        }
    }

    /// How many entries of [`entry_bytes`](Self::entry_bytes) `tier`'s budget holds; `None`
    /// when unbounded. A cache's stats use [`GeometryCache::capacity_entries`] instead, which
    /// knows the real entry size once the tier has built one.
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

/// The multiresolution geometry cache: three LRU tiers of immutable tessellations.
/// See the [module docs](self).
pub struct GeometryCache<E: CacheEntry> {
    config: CacheConfig,
    tiers: [TierCache<E>; 3],
    /// Split subpatches' ids, kept as long as the entries they name.
    split_ids: SplitIdTables,
    /// Per tier: its budget was already reported too small ([`GeometryCache::too_small`] warns
    /// once per cache, not once per render or pass).
    warned_too_small: [std::sync::atomic::AtomicBool; 3],
}

/// `bytes` in MB (10^6 bytes) for a message, with three decimals below 1 MB.
fn megabytes(bytes: u64) -> String {
    let mb = bytes as f64 / 1e6;
    if mb < 1.0 {
        format!("{mb:.3} MB")
    } else {
        format!("{mb:.1} MB")
    }
}

/// A tier whose budget is too small for what renders used of it: a render rebuilt more evicted
/// entries than the tier has ever built distinct ones (each entry built more than twice on
/// average), the cliff where an LRU thrashes and renders slow by orders of magnitude.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct TooSmall {
    /// "coarse", "medium" or "fine".
    pub tier: &'static str,
    /// The tier's budget, bytes.
    pub budget_bytes: u64,
    /// Distinct tessellations the tier has built over the cache's life.
    pub distinct: u64,
    /// Evicted tessellations the render built again (its misses).
    pub rebuilt: u64,
    /// A tier budget that holds every distinct tessellation, bytes (at the tier's entry size).
    pub fits_bytes: u64,
    /// The total budget (`geometryCacheMb`, MB = 10^6 bytes, rounded up) that gives the tier
    /// `fits_bytes` in this mode.
    pub total_mb: u64,
}
impl<E: CacheEntry> GeometryCache<E> {
    /// An empty cache.
    pub fn new(config: CacheConfig) -> Self {
        let tiers = Tier::ALL.map(|t| TierCache::new(config.shard_count(t), config.tier_budget_bytes(t), config.mode != CacheMode::None));
        Self { config, tiers, split_ids: SplitIdTables::default(), warned_too_small: Default::default() }
    }

    /// The tiers whose budget was too small for the render that began when the stats were
    /// `before` (see [`TooSmall`]). Each is also logged as a warning naming the tier and the
    /// budget that would fit, the first time only for this cache.
    pub fn too_small(&self, before: &CacheStats) -> Vec<TooSmall> {
        let now = self.stats();
        let render = now.since(before);
        let mut out = Vec::new();
        for t in Tier::ALL {
            let Some(budget) = self.config.tier_budget_bytes(t) else { continue };
            let distinct = now.tiers[t.index()].cold_tessellations;
            let rebuilt = render.tiers[t.index()].misses;
            if budget == 0 || rebuilt <= distinct.max(1) {
                continue;
            }
            // The real entry size once one is built (a budget below it stores nothing at all).
            let largest = self.tiers[t.index()].largest_entry_bytes();
            let entry_bytes = if largest > 0 { largest } else { self.config.entry_bytes[t.index()] } as u64;
            let fits_bytes = distinct * entry_bytes;
            let total_bytes = self.config.total_for_tier(t, fits_bytes);
            let too_small = TooSmall {
                tier: t.name(),
                budget_bytes: budget as u64,
                distinct,
                rebuilt,
                fits_bytes,
                total_mb: total_bytes.div_ceil(1_000_000),
            };
            if !self.warned_too_small[t.index()].swap(true, std::sync::atomic::Ordering::Relaxed) {
                log::warn!(
                    "geometry cache: the {} tier's budget of {} is too small for this render: it rebuilt evicted \
                     tessellations {} times, of {} distinct; geometryCacheMb {} ({} for the tier) would hold them all",
                    too_small.tier,
                    megabytes(budget as u64),
                    rebuilt,
                    distinct,
                    too_small.total_mb,
                    megabytes(fits_bytes),
                );
            }
            out.push(too_small);
        }
        out
    }

    /// The configuration the cache was made with.
    pub fn config(&self) -> &CacheConfig {
        &self.config
    }

    /// The tessellation of `key`: the resident one, or the one another thread is building (this
    /// thread waits for it), or else `build()`'s, which is then stored in `key.tier`'s LRU,
    /// evicting least recently used entries (of the key's shard) to keep within the budget.
    /// (Resident entries are kept as their [`CacheEntry::Stored`] form; what is returned is made
    /// from it.)
    ///
    /// An entry whose [`byte_size`](CacheEntry::byte_size) exceeds its shard's whole budget
    /// (the tier's budget over [`CacheConfig::shard_count`], which leaves room for at least 256
    /// entries of the configured size), or is 2 GiB or more, is returned but not stored, and
    /// evicts nothing; so is every entry in `none` mode, and any entry of a tier without budget
    /// (coarse and medium in `single` mode).
    ///
    /// `build` runs without any cache lock held. It must not look up `key` itself, nor wait on a
    /// thread that is looking up `key`: that would wait for itself. For the same reason it should
    /// not run rayon work: while it waits in a rayon join, its thread may steal a render job that
    /// looks up `key` (which then panics, see below, rather than hanging).
    ///
    /// # Panics
    /// If `build` panics (the panic is passed on; threads waiting for this build then build the
    /// entry themselves), or if `build` looks up `key` (instead of deadlocking).
    pub fn get_or_build(&self, key: CacheKey, build: impl FnOnce() -> E) -> E {
        self.tiers[key.tier.index()].get_or_build(key, |_| build())
    }

    /// As [`get_or_build`](Self::get_or_build), but `build` may reuse the storage of an entry
    /// the key's shard evicted: it gets one, if the shard kept one, to refill in place (where no
    /// ray still shares it) or to drop. A full tier evicts about one entry per build, so its
    /// entries' blocks are recycled rather than freed and allocated again, which keeps the
    /// allocator from scattering holes over its per-thread arenas. Each shard keeps at most 4
    /// evicted entries for this, not counted as resident.
    pub fn get_or_build_reusing(&self, key: CacheKey, build: impl FnOnce(Option<E::Stored>) -> E) -> E {
        self.tiers[key.tier.index()].get_or_build(key, build)
    }

    /// Drops every entry of `mesh` (all generations, all tiers) and frees their bytes; builds of
    /// it in flight are returned to their callers but not stored. The tiers also forget that
    /// `mesh` was ever built, so its next builds count as cold tessellations (they are of new
    /// geometry). Other meshes' entries, recency and statistics are untouched. Takes time in
    /// proportion to the resident entries: meant for edits, not for every frame.
    ///
    /// The mesh's [`split_ids`](Self::split_ids) tables go too: ids are given afresh to the new
    /// geometry. A render still holding an old table must not go on rendering the mesh under
    /// the same generation (an owner bumps the generation with every edit, so none does).
    pub fn invalidate_mesh(&self, mesh: u32) {
        for tier in &self.tiers {
            tier.invalidate_mesh(mesh);
        }
        self.split_ids.forget_mesh(mesh);
    }

    /// The ids of the split subpatches of `mesh` at `generation`, whose `roots` root subpatches
    /// keep ids 0 to `roots` − 1: children get `roots`, `roots` + 1, … in order of first use,
    /// each keeping its id for as long as the cache may hold its entries, so every render on
    /// this cache (and every thread) gets the same id for the same child. See the `split_ids`
    /// module.
    pub fn split_ids(&self, mesh: u32, generation: u32, roots: u32) -> Arc<SplitIds> {
        self.split_ids.get(mesh, generation, roots)
    }

    /// Heap bytes of the [`split_ids`](Self::split_ids) tables (bookkeeping, not counted in any
    /// budget).
    pub fn split_id_bytes(&self) -> usize {
        self.split_ids.heap_bytes()
    }

    /// Whether `key` is resident now. Does not count as a lookup nor refresh its recency.
    pub fn contains(&self, key: CacheKey) -> bool {
        self.tiers[key.tier.index()].contains(&key)
    }

    /// Entries resident in `tier` now.
    pub fn resident_entries(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].resident_entries()
    }

    /// Bytes (as entries report them) resident in `tier` now; never more than its budget.
    pub fn resident_bytes(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].resident_bytes()
    }

    /// Shards `tier` is split into (see [`CacheConfig::shard_count`]).
    pub fn shard_count(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].shard_count()
    }

    /// Heap bytes of `tier`'s set of ever-built keys (bookkeeping, not counted in any budget).
    pub fn seen_set_bytes(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].seen_set_bytes()
    }

    /// Heap bytes of `tier`'s LRU nodes (each holding an entry by value, with its key and
    /// size) and hash index, as allocated now: the resident entries' bookkeeping plus their
    /// inline parts; not what the entries allocate themselves, nor the ever-built set.
    pub fn table_bytes(&self, tier: Tier) -> usize {
        self.tiers[tier.index()].table_bytes()
    }

    /// How many entries `tier`'s budget holds: the budget over the largest entry built in the
    /// tier so far. A tier is one fixed grid, so its entries are normally all one size, counting
    /// whatever the entry type stores beyond its vertices (the fine tier's sub-bounding boxes, for
    /// one): 3,984-byte fine entries give 2,510 at 10 MB, not the 2,883 of bare vertices. Before
    /// the tier's first build, [`CacheConfig::capacity_entries`]. `None` when unbounded.
    pub fn capacity_entries(&self, tier: Tier) -> Option<usize> {
        let largest = self.tiers[tier.index()].largest_entry_bytes();
        match self.config.tier_budget_bytes(tier) {
            Some(budget) if largest > 0 => Some(budget / largest),
            _ => self.config.capacity_entries(tier),
        }
    }

    /// A snapshot of the statistics, without locking (see the `stats` module on consistency).
    pub fn stats(&self) -> CacheStats {
        let tiers = Tier::ALL.map(|t| {
            let capacity = self.capacity_entries(t).map(|c| c as u64);
            self.tiers[t.index()].stats(t, capacity)
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
            .field("resident_entries", &Tier::ALL.map(|t| self.resident_entries(t)))
            .field("resident_bytes", &Tier::ALL.map(|t| self.resident_bytes(t)))
            .finish()
    }
}
