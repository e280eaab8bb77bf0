//! Geometry cache statistics in the paper's terms (§6.1): cold tessellations, lookups, hits,
//! misses, hit rate, and the cache cost as recomputed vertices; per tier, as in the paper's
//! tables of §6.2–6.4. [`CacheStats`] serialises to the `geometry_cache` object of the stats
//! JSON in DESIGN.md ("Statistics and stats JSON"); its field names are stable.
//!
//! Counters are relaxed atomics updated by the render threads as they go, so reading them never
//! stops the renderer. A snapshot taken while threads are still looking up may be off by the
//! lookups in flight; once the cache is quiescent, `lookups = hits + misses + cold_tessellations`
//! holds exactly for every tier.

use std::fmt::{self, Write as _};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

use serde::Serialize;

use super::{CacheMode, Tier};

/// The live lookup counters of one shard of a tier; a tier's figures are their sums. Each shard
/// has its own, so threads looking up different shards do not fight over one cache line.
///
/// A lookup answered by a resident entry (nearly all of a render's) counts only
/// `resident_hits`, under the shard's lock, by a plain load and store: no locked add, and on
/// the lock's own cache line (see `tier_cache::Shard`). The others count `lookups` and their
/// outcome with relaxed adds. So a tier's lookups are `lookups + resident_hits` and its hits
/// `hits + resident_hits`.
#[derive(Default, Debug)]
#[repr(C)]
pub(crate) struct LookupCounters {
    /// Lookups not answered by a resident entry: builds, waits for another thread's build.
    pub(crate) lookups: AtomicU64,
    /// Lookups that waited for another thread's build of their key.
    pub(crate) hits: AtomicU64,
    pub(crate) misses: AtomicU64,
    pub(crate) cold_tessellations: AtomicU64,
    pub(crate) cold_vertices: AtomicU64,
    pub(crate) recomputed_vertices: AtomicU64,
    /// Lookups answered by a resident entry. Written only under the shard's lock; last, next to
    /// the lock (`tier_cache::Shard` is `repr(C)` with these counters first).
    resident_hits: AtomicU64,
}

impl LookupCounters {
    #[inline]
    pub(crate) fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Relaxed);
    }

    /// Where `resident_hits` lies, for the test that it shares the lock word's cache line.
    #[cfg(test)]
    pub(crate) fn resident_hits_addr(&self) -> usize {
        &self.resident_hits as *const AtomicU64 as usize
    }

    /// Counts a lookup answered by a resident entry. Only while holding the shard's lock: the
    /// lock orders the writers, so a load and a store count exactly (a locked add would cost
    /// every hit a full barrier), and readers without the lock still see whole values.
    #[inline]
    pub(crate) fn count_resident_hit_locked(&self) {
        self.resident_hits.store(self.resident_hits.load(Relaxed) + 1, Relaxed);
    }

    /// Counts a lookup that builds: a cold tessellation, or a miss.
    #[inline]
    pub(crate) fn count_build(&self, cold: bool) {
        let counter = if cold { &self.cold_tessellations } else { &self.misses };
        Self::add(counter, 1);
    }

    /// Records a finished build's vertices: cold vertices for a first build, recomputed ones
    /// (the cache cost) for a rebuild.
    #[inline]
    pub(crate) fn built(&self, cold: bool, vertices: usize) {
        let counter = if cold { &self.cold_vertices } else { &self.recomputed_vertices };
        Self::add(counter, vertices as u64);
    }
}

/// One tier's row from its shards' counters.
pub(crate) fn tier_stats<'a>(
    tier: Tier,
    capacity_entries: Option<u64>,
    peak_bytes: u64,
    shards: impl Iterator<Item = &'a LookupCounters>,
) -> TierStats {
    let mut t = TierStats {
        name: tier.name(),
        verts_per_side: tier.verts_per_side(),
        capacity_entries,
        cold_tessellations: 0,
        lookups: 0,
        hits: 0,
        misses: 0,
        hit_rate: 0.0,
        recomputed_vertices: 0,
        peak_bytes,
        cold_vertices: 0,
    };
    for c in shards {
        let resident_hits = c.resident_hits.load(Relaxed);
        t.lookups += c.lookups.load(Relaxed) + resident_hits;
        t.hits += c.hits.load(Relaxed) + resident_hits;
        t.misses += c.misses.load(Relaxed);
        t.cold_tessellations += c.cold_tessellations.load(Relaxed);
        t.cold_vertices += c.cold_vertices.load(Relaxed);
        t.recomputed_vertices += c.recomputed_vertices.load(Relaxed);
    }
    // The paper's hit rate: a cold tessellation is not a lookup of anything cached (§6.1: "if
    // the subpatch has been tessellated at the desired resolution before, the tessellation is
    // looked up"), so the rate is hits / (hits + misses); its tables only add up that way
    // (§6.2.1: 1.3M misses in 100M lookups is 98.7%).
    if t.hits + t.misses > 0 {
        t.hit_rate = t.hits as f64 / (t.hits + t.misses) as f64;
    } else if t.lookups > 0 {
        t.hit_rate = 1.0;
    }
    t
}

/// One tier's figures, one row of the paper's tables.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TierStats {
    /// "coarse", "medium" or "fine".
    pub name: &'static str,
    /// 2, 5 or 17.
    pub verts_per_side: u32,
    /// Entries the tier's budget holds, of the size its entries really are: see
    /// [`GeometryCache::capacity_entries`](super::GeometryCache::capacity_entries). `null`
    /// (None) when unbounded, 0 when the tier stores nothing (`none` mode; coarse and medium in
    /// `single` mode).
    pub capacity_entries: Option<u64>,
    /// First builds ever of a key in this tier.
    pub cold_tessellations: u64,
    /// Calls of `get_or_build` for this tier.
    pub lookups: u64,
    /// Lookups served without building: the entry was resident, or another thread was already
    /// building it and this one waited for it.
    pub hits: u64,
    /// Lookups of a key built before but no longer resident (evicted, too large to store, or
    /// never stored in `none` mode), so it was built again.
    pub misses: u64,
    /// `hits / (hits + misses)`, in [0, 1], as the paper reports it (cold tessellations are not
    /// lookups of cached entries); 1 when every lookup was cold, 0 when there were none.
    pub hit_rate: f64,
    /// Vertices built by misses: the paper's "cache cost".
    pub recomputed_vertices: u64,
    /// Most bytes (as entries report them) resident in this tier at once.
    pub peak_bytes: u64,
    /// Vertices built by cold tessellations. Not in the JSON (the paper gives only the total,
    /// [`CacheStats::cold_vertices`]); shown by [`CacheStats::table`].
    #[serde(skip)]
    pub cold_vertices: u64,
}

/// Everything the cache reports: the `geometry_cache` object of the stats JSON.
///
/// ```json
/// {"mode": "multires", "budget_bytes": 30000000,
///  "tiers": [{"name": "coarse", "verts_per_side": 2, "capacity_entries": 208333,
///             "cold_tessellations": 0, "lookups": 0, "hits": 0, "misses": 0, "hit_rate": 0.0,
///             "recomputed_vertices": 0, "peak_bytes": 0}, ...medium, fine],
///  "cold_vertices": 0, "recomputed_vertices": 0}
/// ```
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CacheStats {
    /// The cache mode, by name.
    pub mode: CacheMode,
    /// The sum of the tiers' budgets in bytes; `null` (None) in `unbounded` mode, 0 in `none`.
    pub budget_bytes: Option<u64>,
    /// Always three rows, coarse, medium, fine (index with [`Tier::index`]), whatever the mode,
    /// so readers can look tiers up by name; a tier the mode does not use shows zeros.
    pub tiers: [TierStats; 3],
    /// Vertices built by cold tessellations, all tiers.
    pub cold_vertices: u64,
    /// Vertices built by misses, all tiers: the paper's cache cost.
    pub recomputed_vertices: u64,
}

impl CacheStats {
    /// The figures of what happened after `before` was taken (counters subtracted, hit rates
    /// recomputed), for a cache that outlives one render: each render's stats are its own.
    /// `peak_bytes` and `capacity_entries` stay as they are now (a peak is not a difference).
    pub fn since(&self, before: &CacheStats) -> CacheStats {
        let mut out = self.clone();
        for (t, b) in out.tiers.iter_mut().zip(&before.tiers) {
            t.cold_tessellations = t.cold_tessellations.saturating_sub(b.cold_tessellations);
            t.lookups = t.lookups.saturating_sub(b.lookups);
            t.hits = t.hits.saturating_sub(b.hits);
            t.misses = t.misses.saturating_sub(b.misses);
            t.recomputed_vertices = t.recomputed_vertices.saturating_sub(b.recomputed_vertices);
            t.cold_vertices = t.cold_vertices.saturating_sub(b.cold_vertices);
            t.hit_rate = if t.hits + t.misses > 0 {
                t.hits as f64 / (t.hits + t.misses) as f64
            } else if t.lookups > 0 {
                1.0
            } else {
                0.0
            };
        }
        out.cold_vertices = self.cold_vertices.saturating_sub(before.cold_vertices);
        out.recomputed_vertices = self.recomputed_vertices.saturating_sub(before.recomputed_vertices);
        out
    }

    /// The row of one tier.
    pub fn tier(&self, tier: Tier) -> &TierStats {
        &self.tiers[tier.index()]
    }

    /// A plain-text table like the paper's (§6), one row per tier, then the totals. Tiers the
    /// mode gives no budget and that saw no lookup are left out.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let budget = match self.budget_bytes {
            Some(b) => format!("budget {} ({b} bytes)", human_bytes(b)),
            None => "no budget".to_owned(),
        };
        // Writing to a String cannot fail.
        let _ = writeln!(s, "geometry cache: {}, {budget}", self.mode);
        let _ = writeln!(
            s,
            "{:<7} {:>6} {:>10} {:>10} {:>13} {:>13} {:>10} {:>9} {:>13} {:>13} {:>10}",
            "tier", "grid", "capacity", "cold tess", "lookups", "hits", "misses", "hit rate", "recomp verts", "cold verts", "peak bytes"
        );
        for t in &self.tiers {
            if t.capacity_entries == Some(0) && t.lookups == 0 {
                continue;
            }
            let capacity = t.capacity_entries.map_or_else(|| "unbounded".to_owned(), |c| c.to_string());
            let hit_rate = if t.lookups == 0 { "-".to_owned() } else { format!("{:.2}%", 100.0 * t.hit_rate) };
            let _ = writeln!(
                s,
                "{:<7} {:>6} {:>10} {:>10} {:>13} {:>13} {:>10} {:>9} {:>13} {:>13} {:>10}",
                t.name,
                format!("{0}x{0}", t.verts_per_side),
                capacity,
                t.cold_tessellations,
                t.lookups,
                t.hits,
                t.misses,
                hit_rate,
                t.recomputed_vertices,
                t.cold_vertices,
                human_bytes(t.peak_bytes),
            );
        }
        let _ = writeln!(s, "cold vertices {}, recomputed vertices (cache cost) {}", self.cold_vertices, self.recomputed_vertices);
        s
    }
}

impl fmt::Display for CacheStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.table())
    }
}

/// Bytes with a decimal unit, as the paper writes cache sizes ("10 MB" = 10,000,000 bytes here).
fn human_bytes(b: u64) -> String {
    const UNITS: [(&str, f64); 3] = [("GB", 1e9), ("MB", 1e6), ("kB", 1e3)];
    UNITS
        .iter()
        .find(|&&(_, scale)| b as f64 >= scale)
        .map_or_else(|| format!("{b} B"), |&(unit, scale)| format!("{:.1} {unit}", b as f64 / scale))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn human_bytes_uses_decimal_units() {
        assert_eq!(human_bytes(0), "0 B");
        assert_eq!(human_bytes(999), "999 B");
        assert_eq!(human_bytes(10_000_000), "10.0 MB");
        assert_eq!(human_bytes(3_400_000_000), "3.4 GB");
        assert_eq!(human_bytes(48_000), "48.0 kB");
    }

    #[test]
    fn tier_stats_sum_the_shards() {
        let shards: [LookupCounters; 2] = Default::default();
        let empty = tier_stats(Tier::Fine, Some(3), 0, shards.iter());
        assert_eq!((empty.lookups, empty.hit_rate), (0, 0.0));
        for c in &shards {
            LookupCounters::add(&c.lookups, 2);
        }
        LookupCounters::add(&shards[0].hits, 2);
        LookupCounters::add(&shards[1].hits, 1);
        shards[1].count_build(true);
        shards[1].built(true, 289);
        shards[0].count_build(false);
        shards[0].built(false, 289);
        let s = tier_stats(Tier::Fine, Some(3), 100, shards.iter());
        assert_eq!((s.lookups, s.hits, s.misses, s.cold_tessellations), (4, 3, 1, 1));
        assert_eq!(s.hit_rate, 0.75);
        assert_eq!((s.cold_vertices, s.recomputed_vertices, s.peak_bytes), (289, 289, 100));
        assert_eq!((s.name, s.verts_per_side, s.capacity_entries), ("fine", 17, Some(3)));
    }
}
