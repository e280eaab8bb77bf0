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

/// The live counters of one tier.
#[derive(Default, Debug)]
pub(crate) struct TierCounters {
    pub(crate) lookups: AtomicU64,
    pub(crate) hits: AtomicU64,
    pub(crate) misses: AtomicU64,
    pub(crate) cold_tessellations: AtomicU64,
    pub(crate) cold_vertices: AtomicU64,
    pub(crate) recomputed_vertices: AtomicU64,
    pub(crate) peak_bytes: AtomicU64,
    /// The largest `byte_size` of any entry built in this tier, for `capacity_entries`.
    pub(crate) largest_entry_bytes: AtomicU64,
}

impl TierCounters {
    #[inline]
    pub(crate) fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Relaxed);
    }

    /// Records a finished build of `bytes` and `vertices`: cold vertices for a first build,
    /// recomputed ones (the cache cost) for a rebuild.
    #[inline]
    pub(crate) fn built(&self, cold: bool, vertices: usize, bytes: usize) {
        let counter = if cold {
            &self.cold_vertices
        } else {
            &self.recomputed_vertices
        };
        Self::add(counter, vertices as u64);
        self.largest_entry_bytes.fetch_max(bytes as u64, Relaxed);
    }

    #[inline]
    pub(crate) fn raise_peak(&self, resident_bytes: usize) {
        self.peak_bytes.fetch_max(resident_bytes as u64, Relaxed);
    }

    pub(crate) fn snapshot(&self, tier: Tier, capacity_entries: Option<u64>) -> TierStats {
        let lookups = self.lookups.load(Relaxed);
        let hits = self.hits.load(Relaxed);
        TierStats {
            name: tier.name(),
            verts_per_side: tier.verts_per_side(),
            capacity_entries,
            cold_tessellations: self.cold_tessellations.load(Relaxed),
            lookups,
            hits,
            misses: self.misses.load(Relaxed),
            hit_rate: if lookups == 0 {
                0.0
            } else {
                hits as f64 / lookups as f64
            },
            recomputed_vertices: self.recomputed_vertices.load(Relaxed),
            peak_bytes: self.peak_bytes.load(Relaxed),
            cold_vertices: self.cold_vertices.load(Relaxed),
        }
    }
}

/// One tier's figures, one row of the paper's tables.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TierStats {
    /// "coarse", "medium" or "fine".
    pub name: &'static str,
    /// 2, 5 or 17.
    pub verts_per_side: u32,
    /// Entries of this tier's nominal size the budget holds; `null` (None) when unbounded, 0
    /// when the tier stores nothing (`none` mode; coarse and medium in `single` mode). See
    /// [`CacheConfig::capacity_entries`](super::CacheConfig::capacity_entries).
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
    /// `hits / lookups`, in [0, 1]; 0 when there were no lookups.
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
            "tier",
            "grid",
            "capacity",
            "cold tess",
            "lookups",
            "hits",
            "misses",
            "hit rate",
            "recomp verts",
            "cold verts",
            "peak bytes"
        );
        for t in &self.tiers {
            if t.capacity_entries == Some(0) && t.lookups == 0 {
                continue;
            }
            let capacity = t
                .capacity_entries
                .map_or_else(|| "unbounded".to_owned(), |c| c.to_string());
            let hit_rate = if t.lookups == 0 {
                "-".to_owned()
            } else {
                format!("{:.2}%", 100.0 * t.hit_rate)
            };
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
        let _ = writeln!(
            s,
            "cold vertices {}, recomputed vertices (cache cost) {}",
            self.cold_vertices, self.recomputed_vertices
        );
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
        .map_or_else(
            || format!("{b} B"),
            |&(unit, scale)| format!("{:.1} {unit}", b as f64 / scale),
        )
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
    fn snapshot_computes_hit_rate() {
        let c = TierCounters::default();
        assert_eq!(c.snapshot(Tier::Fine, Some(3)).hit_rate, 0.0);
        TierCounters::add(&c.lookups, 4);
        TierCounters::add(&c.hits, 3);
        TierCounters::add(&c.cold_tessellations, 1);
        c.built(true, 289, 3468);
        c.raise_peak(100);
        c.raise_peak(50);
        let s = c.snapshot(Tier::Fine, Some(3));
        assert_eq!(s.hit_rate, 0.75);
        assert_eq!(
            (s.cold_vertices, s.recomputed_vertices, s.peak_bytes),
            (289, 0, 100)
        );
        assert_eq!(
            (s.name, s.verts_per_side, s.capacity_entries),
            ("fine", 17, Some(3))
        );
    }
}
