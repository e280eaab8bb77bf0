//! Tests of the cache as a whole: LRU order, byte accounting, capacities against the paper's,
//! sharding, single-flight builds under threads, the four modes, invalidation, and the stats
//! JSON.

use std::collections::{HashSet, VecDeque};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering::SeqCst};
use std::sync::{mpsc, Arc, Barrier};
use std::time::Duration;

use super::tier_cache::{NodeKey, Resident};
use super::*;

/// A stand-in tessellation: an id to check which build a caller got, and sizes. Held by value,
/// as a small tessellation is (`Arc<Grid>` where a test needs to see which allocation a caller
/// got).
#[derive(Clone, Debug)]
struct Grid {
    id: u64,
    bytes: usize,
    verts: usize,
}

impl CacheEntry for Grid {
    type Stored = Grid;
    fn byte_size(&self) -> usize {
        self.bytes
    }
    fn vertex_count(&self) -> usize {
        self.verts
    }
    fn to_stored(&self) -> Grid {
        self.clone()
    }
    fn from_stored(stored: &Grid) -> Grid {
        stored.clone()
    }
}

/// A grid of `tier`'s nominal size.
fn grid(tier: Tier, id: u64) -> Grid {
    Grid { id, bytes: tier.vertex_bytes(), verts: tier.vertex_count() as usize }
}

fn key(mesh: u32, subpatch: u32, tier: Tier) -> CacheKey {
    CacheKey::new(mesh, 0, subpatch, tier)
}

/// A multires config with the given per-tier budgets.
fn budgets(coarse: usize, medium: usize, fine: usize) -> CacheConfig {
    CacheConfig { budget_bytes: [coarse, medium, fine], ..CacheConfig::multires(0) }
}

fn check_invariant(stats: &CacheStats) {
    for t in &stats.tiers {
        assert_eq!(t.lookups, t.hits + t.misses + t.cold_tessellations, "tier {}: {t:?}", t.name);
    }
}

#[test]
fn lru_evicts_the_least_recently_used_and_a_get_refreshes_it() {
    let f = Tier::Fine;
    let cache = GeometryCache::new(budgets(0, 0, 3 * f.vertex_bytes()));
    assert_eq!(cache.shard_count(f), 1, "a small tier is one exact LRU");
    for s in 0..3 {
        cache.get_or_build(key(0, s, f), || grid(f, s.into())); // recency, newest first: 2 1 0
    }
    // A hit on 0 makes it the most recent: 0 2 1.
    assert_eq!(cache.get_or_build(key(0, 0, f), || grid(f, 99)).id, 0);
    cache.get_or_build(key(0, 3, f), || grid(f, 3)); // evicts 1, not 0: 3 0 2
    assert!(!cache.contains(key(0, 1, f)));
    assert!([0, 2, 3].iter().all(|&s| cache.contains(key(0, s, f))));
    cache.get_or_build(key(0, 4, f), || grid(f, 4)); // evicts 2: 4 3 0
    assert!(!cache.contains(key(0, 2, f)));
    assert!([0, 3, 4].iter().all(|&s| cache.contains(key(0, s, f))));
    // 1 was built before: a miss, which evicts 0 (now the least recent).
    assert_eq!(cache.get_or_build(key(0, 1, f), || grid(f, 11)).id, 11);
    assert!(!cache.contains(key(0, 0, f)));
    let s = cache.stats();
    let fine = s.tier(f);
    assert_eq!((fine.lookups, fine.hits, fine.misses, fine.cold_tessellations), (7, 1, 1, 5));
    assert_eq!(fine.recomputed_vertices, 289);
    assert_eq!(s.cold_vertices, 5 * 289);
    assert_eq!(cache.resident_entries(f), 3);
    check_invariant(&s);
}

#[test]
fn contains_neither_counts_nor_refreshes() {
    let c = Tier::Coarse;
    let cache = GeometryCache::new(budgets(2 * c.vertex_bytes(), 0, 0));
    cache.get_or_build(key(0, 0, c), || grid(c, 0));
    cache.get_or_build(key(0, 1, c), || grid(c, 1));
    assert!(cache.contains(key(0, 0, c)));
    cache.get_or_build(key(0, 2, c), || grid(c, 2));
    assert!(!cache.contains(key(0, 0, c)), "contains() must not refresh recency");
    assert_eq!(cache.stats().tier(c).lookups, 3);
}

#[test]
fn bytes_are_accounted_per_tier_and_eviction_frees_exactly_the_entry() {
    let m = Tier::Medium;
    let budget = 1000;
    let cache = GeometryCache::new(budgets(500, budget, 500));
    // A reference LRU: (subpatch, bytes), most recent first.
    let mut model: VecDeque<(u32, usize)> = VecDeque::new();
    let mut peak = 0;
    let sizes = [300, 400, 250, 500, 100, 999, 1000, 1, 7, 640, 360, 2];
    for (s, &bytes) in sizes.iter().enumerate() {
        let s = s as u32;
        let before = cache.resident_bytes(m);
        cache.get_or_build(key(0, s, m), || Grid { id: s.into(), bytes, verts: 25 });
        let mut evicted = 0;
        while model.iter().map(|e| e.1).sum::<usize>() + bytes > budget {
            evicted += model.pop_back().map_or(0, |e| e.1);
        }
        model.push_front((s, bytes));
        let expected: usize = model.iter().map(|e| e.1).sum();
        peak = peak.max(expected);
        let now = cache.resident_bytes(m);
        assert_eq!(now, expected, "after storing {bytes} bytes");
        assert_eq!(now, before + bytes - evicted, "eviction must free exactly the evicted bytes");
        assert!(now <= budget);
        assert_eq!(cache.stats().tier(m).peak_bytes, peak as u64);
        assert!(model.iter().all(|&(k, _)| cache.contains(key(0, k, m))));
        assert_eq!(cache.resident_entries(m), model.len());
    }
    // The other tiers saw nothing.
    assert_eq!(cache.resident_bytes(Tier::Coarse) + cache.resident_bytes(Tier::Fine), 0);
    let s = cache.stats();
    assert_eq!(s.tier(Tier::Coarse).peak_bytes + s.tier(Tier::Fine).peak_bytes, 0);
    assert_eq!(s.tier(m).peak_bytes, 1000);
}

#[test]
fn capacity_entries_at_the_default_budget_match_the_paper() {
    let default = CacheConfig::default();
    assert_eq!(default, CacheConfig::DEFAULT);
    assert_eq!(default.mode, CacheMode::Multires);
    assert_eq!(default.budget_bytes, [10_000_000; 3]);
    let caps = Tier::ALL.map(|t| default.capacity_entries(t));
    assert_eq!(caps, [Some(208_333), Some(33_333), Some(2_883)]);
    let stats = GeometryCache::<Grid>::new(default).stats();
    assert_eq!(stats.tiers.clone().map(|t| t.capacity_entries), [Some(208_333), Some(33_333), Some(2_883)]);
    assert_eq!(stats.budget_bytes, Some(30_000_000));

    // The paper's figures (§5.2) are for binary megabytes: within 1% at 10 MiB and 30 MiB.
    let mib = 1 << 20;
    let near = |got: Option<usize>, paper: f64| {
        let got = got.unwrap_or(0) as f64;
        assert!((got - paper).abs() / paper < 0.01, "{got} vs the paper's {paper}");
    };
    let per_mib = CacheConfig::multires(30 * mib);
    near(per_mib.capacity_entries(Tier::Coarse), 220_000.0);
    near(per_mib.capacity_entries(Tier::Medium), 35_000.0);
    near(per_mib.capacity_entries(Tier::Fine), 3_000.0);
    near(CacheConfig::single(30 * mib).capacity_entries(Tier::Fine), 9_100.0);
    // The dragon table's single-resolution rows (§6.3.2): 100 MB → 30k, 1 MB → 300.
    near(CacheConfig::single(100 * mib).capacity_entries(Tier::Fine), 30_000.0 * 1.0079);
    near(CacheConfig::single(mib).capacity_entries(Tier::Fine), 300.0 * 1.0067);

    // Counting the fine tier's 16 sub-bounding boxes (24 bytes each) lowers its capacity.
    let with_boxes = default.with_entry_bytes([48, 300, 3468 + 16 * 24]);
    assert_eq!(with_boxes.capacity_entries(Tier::Fine), Some(2_596));
    assert_eq!(with_boxes.capacity_entries(Tier::Coarse), Some(208_333));
}

#[test]
fn capacity_entries_follow_the_real_entry_size() {
    let f = Tier::Fine;
    let cache = GeometryCache::new(CacheConfig::default());
    assert_eq!(cache.capacity_entries(f), Some(2_883));
    // A fine tessellation that also holds 16 sub-boxes (two `Vec3A`, 32 bytes, each) and a
    // 4-byte chord error: 3,984 bytes.
    cache.get_or_build(key(0, 0, f), || Grid { id: 0, bytes: 3468 + 16 * 32 + 4, verts: 289 });
    assert_eq!(cache.capacity_entries(f), Some(2_510));
    assert_eq!(cache.stats().tier(f).capacity_entries, Some(2_510));
    assert_eq!(cache.capacity_entries(Tier::Coarse), Some(208_333), "other tiers keep theirs");
    // Building does not give a budget to tiers without one.
    let none = GeometryCache::new(CacheConfig::none());
    none.get_or_build(key(0, 0, f), || grid(f, 0));
    assert_eq!(none.capacity_entries(f), Some(0));
    let unbounded = GeometryCache::new(CacheConfig::unbounded());
    unbounded.get_or_build(key(0, 0, f), || grid(f, 0));
    assert_eq!(unbounded.capacity_entries(f), None);
}

#[test]
fn shard_counts_are_chosen_so_each_shard_keeps_hundreds_of_entries() {
    let shards = |c: CacheConfig| Tier::ALL.map(|t| c.shard_count(t));
    // 208,333 / 16, 33,333 / 16 and 2,883 / 8 entries per shard.
    assert_eq!(shards(CacheConfig::DEFAULT), [16, 16, 8]);
    // 722 coarse entries: 2 shards of 361 (4 would leave 180); 115 medium, 10 fine: 1.
    assert_eq!(shards(CacheConfig::multires(3 * 10 * 3468)), [2, 1, 1]);
    assert_eq!(shards(CacheConfig::single(30_000_000)), [1, 1, 16]);
    assert_eq!(shards(CacheConfig::unbounded()), [16; 3]);
    assert_eq!(shards(CacheConfig::none()), [16; 3]);
    assert_eq!(shards(CacheConfig::DEFAULT.with_shards(3)), [4; 3]);
    assert_eq!(shards(CacheConfig::DEFAULT.with_shards(1000)), [64; 3]);
    assert_eq!(shards(CacheConfig::DEFAULT.with_shards(5).with_shards(0)), [16, 16, 8]);
    let cache = GeometryCache::<Grid>::new(CacheConfig::DEFAULT);
    assert_eq!(Tier::ALL.map(|t| cache.shard_count(t)), [16, 16, 8]);
}

#[test]
fn shards_spread_many_meshes_and_many_subpatches() {
    let f = Tier::Fine;
    // 8 fine shards of 360 entries each. 2,000 one-subpatch meshes fit only if they spread
    // (every mesh's subpatch 0 in one shard would keep 360).
    let cache = GeometryCache::new(CacheConfig::DEFAULT);
    for mesh in 0..2000 {
        cache.get_or_build(key(mesh, 0, f), || grid(f, mesh.into()));
    }
    assert_eq!(cache.resident_entries(f), 2000);
    let cache = GeometryCache::new(CacheConfig::DEFAULT);
    for s in 0..2000 {
        cache.get_or_build(key(7, s, f), || grid(f, s.into()));
    }
    assert_eq!(cache.resident_entries(f), 2000);
    assert_eq!(cache.stats().tier(f).misses, 0);
}

#[test]
fn sharded_tiers_account_bytes_and_peak_over_all_shards() {
    let m = Tier::Medium;
    let budget = 4 * 1000;
    let cache = GeometryCache::new(budgets(0, budget, 0).with_shards(4));
    assert_eq!(cache.shard_count(m), 4);
    let mut peak = 0;
    let mut total_built = 0;
    for s in 0..200u32 {
        let bytes = 100 + (s as usize * 37) % 300;
        total_built += bytes;
        cache.get_or_build(key(s % 3, s, m), || Grid { id: 0, bytes, verts: 25 });
        let now = cache.resident_bytes(m);
        assert!(now <= budget, "{now} > {budget}");
        peak = peak.max(now);
        assert_eq!(cache.stats().tier(m).peak_bytes, peak as u64);
    }
    assert!(peak > budget / 2 && total_built > budget);
    cache.invalidate_mesh(0);
    cache.invalidate_mesh(1);
    cache.invalidate_mesh(2);
    assert_eq!((cache.resident_bytes(m), cache.resident_entries(m)), (0, 0));
}

#[test]
fn config_constructors() {
    assert_eq!(CacheConfig::multires(10).budget_bytes, [3, 3, 4]);
    assert_eq!(CacheConfig::multires(10).total_budget_bytes(), Some(10));
    assert_eq!(CacheConfig::single(7).budget_bytes, [0, 0, 7]);
    assert_eq!(CacheConfig::single(7).total_budget_bytes(), Some(7));
    assert_eq!(CacheConfig::unbounded().total_budget_bytes(), None);
    assert_eq!(CacheConfig::unbounded().capacity_entries(Tier::Fine), None);
    assert_eq!(CacheConfig::none().total_budget_bytes(), Some(0));
    assert_eq!(CacheConfig::none().capacity_entries(Tier::Coarse), Some(0));
    for mode in CacheMode::ALL {
        assert_eq!(CacheConfig::for_mode(mode, 99).mode, mode);
    }
    assert_eq!(CacheConfig::for_mode(CacheMode::Single, 99), CacheConfig::single(99));
    // Single ignores coarse and medium budgets even if someone sets them.
    let odd = CacheConfig { budget_bytes: [5, 5, 5], ..CacheConfig::single(0) };
    assert_eq!(odd.tier_budget_bytes(Tier::Coarse), Some(0));
    assert_eq!(odd.total_budget_bytes(), Some(5));
    assert_eq!(CacheConfig::DEFAULT.with_entry_bytes([0, 1, 2]).entry_bytes, [1, 1, 2]);
}

#[test]
fn mode_names_round_trip_and_unknown_names_list_the_valid_ones() {
    for mode in CacheMode::ALL {
        assert_eq!(mode.to_string().parse::<CacheMode>(), Ok(mode));
        assert_eq!(serde_json::to_string(&mode).ok(), Some(format!("\"{mode}\"")));
    }
    assert_eq!(CacheMode::ALL.map(CacheMode::name), ["multires", "single", "unbounded", "none"]);
    assert_eq!(CacheMode::default(), CacheMode::Multires);
    let err = "lru".parse::<CacheMode>().err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("\"lru\""), "{err}");
    for name in ["multires", "single", "unbounded", "none"] {
        assert!(err.contains(name), "{err} should list {name}");
    }
}

#[test]
fn concurrent_lookups_build_each_key_exactly_once() {
    const THREADS: usize = 8;
    const ROUNDS: usize = 4;
    let keys = [key(0, 0, Tier::Fine), key(0, 1, Tier::Fine), key(1, 0, Tier::Medium)];
    let builds: [AtomicUsize; 3] = Default::default();
    let cache = GeometryCache::new(CacheConfig::default());
    let start = Barrier::new(THREADS);
    // Shared entries: every caller must get the very allocation of the one build.
    let cache: GeometryCache<Arc<Grid>> = cache;
    let got: Vec<Vec<Arc<Grid>>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..THREADS)
            .map(|_| {
                s.spawn(|| {
                    start.wait();
                    let mut got = Vec::new();
                    for _ in 0..ROUNDS {
                        for (i, &k) in keys.iter().enumerate() {
                            got.push(cache.get_or_build(k, || {
                                std::thread::sleep(Duration::from_millis(20));
                                let n = builds[i].fetch_add(1, SeqCst);
                                Arc::new(Grid { id: (i * 1000 + n) as u64, ..grid(k.tier, 0) })
                            }));
                        }
                    }
                    got
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap_or_default()).collect()
    });
    assert_eq!(builds.each_ref().map(|b| b.load(SeqCst)), [1, 1, 1]);
    // Every caller got the one build of its key.
    for per_thread in &got {
        assert_eq!(per_thread.len(), ROUNDS * keys.len());
        for (j, e) in per_thread.iter().enumerate() {
            assert_eq!(e.id, (j % keys.len() * 1000) as u64);
            assert!(Arc::ptr_eq(e, &got[0][j % keys.len()]));
        }
    }
    let s = cache.stats();
    check_invariant(&s);
    let fine = s.tier(Tier::Fine);
    let medium = s.tier(Tier::Medium);
    assert_eq!((fine.lookups, fine.cold_tessellations, fine.misses), (2 * (THREADS * ROUNDS) as u64, 2, 0));
    assert_eq!((medium.lookups, medium.cold_tessellations, medium.misses), ((THREADS * ROUNDS) as u64, 1, 0));
    assert_eq!(s.recomputed_vertices, 0);
}

#[test]
fn concurrent_lookups_rebuild_once_per_residency() {
    const THREADS: usize = 8;
    let f = Tier::Fine;
    let cache = GeometryCache::new(budgets(0, 0, f.vertex_bytes())); // room for one fine entry
    let builds = AtomicUsize::new(0);
    let hammer = |cache: &GeometryCache<Grid>| {
        let start = Barrier::new(THREADS);
        std::thread::scope(|s| {
            for _ in 0..THREADS {
                s.spawn(|| {
                    start.wait();
                    cache.get_or_build(key(0, 0, f), || {
                        std::thread::sleep(Duration::from_millis(20));
                        grid(f, builds.fetch_add(1, SeqCst) as u64)
                    });
                });
            }
        });
    };
    hammer(&cache);
    assert_eq!(builds.load(SeqCst), 1);
    cache.get_or_build(key(0, 1, f), || grid(f, 100)); // evicts key 0
    assert!(!cache.contains(key(0, 0, f)));
    hammer(&cache);
    assert_eq!(builds.load(SeqCst), 2, "one rebuild for the second residency");
    let s = cache.stats();
    check_invariant(&s);
    let fine = s.tier(f);
    assert_eq!((fine.cold_tessellations, fine.misses, fine.hits), (2, 1, 2 * THREADS as u64 - 2));
    assert_eq!(fine.recomputed_vertices, 289);
}

/// Four threads, pseudo-random keys over all tiers, small budgets: every lookup is classified
/// once, and the builds match the cold tessellations and misses.
#[test]
fn lookups_are_hits_plus_misses_plus_cold_in_every_mode() {
    const THREADS: u64 = 4;
    const LOOKUPS: u64 = 1500;
    const SUBPATCHES: u64 = 40;
    for config in [
        budgets(10 * 48, 10 * 300, 10 * 3468),
        budgets(40 * 48, 40 * 300, 40 * 3468).with_shards(4),
        CacheConfig::single(10 * 3468),
        CacheConfig::unbounded(),
        CacheConfig::none(),
    ] {
        let cache = GeometryCache::new(config);
        let builds: [AtomicUsize; 3] = Default::default();
        std::thread::scope(|s| {
            for t in 0..THREADS {
                let (cache, builds) = (&cache, &builds);
                s.spawn(move || {
                    let mut x = 0x9e37_79b9_7f4a_7c15_u64.wrapping_mul(t + 1);
                    for _ in 0..LOOKUPS {
                        x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                        let tier = if config.mode == CacheMode::Single { Tier::Fine } else { Tier::ALL[(x >> 60) as usize % 3] };
                        let k = key((x >> 40) as u32 % 2, ((x >> 20) % SUBPATCHES) as u32, tier);
                        let e = cache.get_or_build(k, || {
                            builds[tier.index()].fetch_add(1, SeqCst);
                            grid(tier, u64::from(k.subpatch))
                        });
                        assert_eq!(e.id, u64::from(k.subpatch));
                    }
                });
            }
        });
        let s = cache.stats();
        check_invariant(&s);
        assert_eq!(s.tiers.iter().map(|t| t.lookups).sum::<u64>(), THREADS * LOOKUPS, "{}", config.mode);
        for t in Tier::ALL {
            let ts = s.tier(t);
            let verts = u64::from(t.vertex_count());
            assert_eq!(builds[t.index()].load(SeqCst) as u64, ts.cold_tessellations + ts.misses, "{} {t}", config.mode);
            assert!(ts.cold_tessellations <= 2 * SUBPATCHES);
            assert_eq!(ts.recomputed_vertices, ts.misses * verts);
            assert!(cache.resident_bytes(t) <= config.tier_budget_bytes(t).unwrap_or(usize::MAX));
            if config.mode != CacheMode::None && ts.lookups > 0 {
                // Every key is built cold once; with 2 × 40 keys and 6,000 lookups all appear.
                assert_eq!(ts.cold_tessellations, 2 * SUBPATCHES, "{} {t}", config.mode);
            }
        }
        let cold: u64 = Tier::ALL.iter().map(|t| s.tier(*t).cold_tessellations * u64::from(t.vertex_count())).sum();
        assert_eq!(s.cold_vertices, cold);
        match config.mode {
            CacheMode::Unbounded => assert_eq!(s.recomputed_vertices, 0),
            CacheMode::None => assert!(s.tiers.iter().all(|t| t.hits == 0)),
            _ => assert!(s.recomputed_vertices > 0, "budgets this small must thrash"),
        }
    }
}

#[test]
fn unbounded_never_evicts() {
    let f = Tier::Fine;
    let cache = GeometryCache::new(CacheConfig::unbounded());
    for s in 0..2000 {
        cache.get_or_build(key(s % 7, s, f), || grid(f, s.into()));
    }
    for s in 0..2000 {
        assert_eq!(cache.get_or_build(key(s % 7, s, f), || grid(f, 0)).id, u64::from(s));
    }
    assert_eq!(cache.resident_entries(f), 2000);
    assert_eq!(cache.resident_bytes(f), 2000 * 3468);
    let s = cache.stats();
    let fine = s.tier(f);
    assert_eq!((fine.cold_tessellations, fine.hits, fine.misses), (2000, 2000, 0));
    assert_eq!(fine.peak_bytes, 2000 * 3468);
    assert_eq!((s.budget_bytes, fine.capacity_entries), (None, None));
}

#[test]
fn none_never_stores_and_reports_recomputation() {
    let m = Tier::Medium;
    let cache = GeometryCache::new(CacheConfig::none());
    let builds = AtomicUsize::new(0);
    for _ in 0..3 {
        let e = cache.get_or_build(key(0, 5, m), || grid(m, builds.fetch_add(1, SeqCst) as u64));
        assert!(!cache.contains(key(0, 5, m)));
        assert_eq!(e.id as usize + 1, builds.load(SeqCst));
    }
    cache.get_or_build(key(0, 6, m), || grid(m, 0));
    assert_eq!(builds.load(SeqCst), 3);
    assert_eq!(cache.resident_bytes(m), 0);
    let s = cache.stats();
    let med = s.tier(m);
    assert_eq!((med.lookups, med.cold_tessellations, med.misses, med.hits), (4, 2, 2, 0));
    assert_eq!((med.recomputed_vertices, s.cold_vertices, med.peak_bytes), (50, 50, 0));
    assert_eq!((s.budget_bytes, med.capacity_entries), (Some(0), Some(0)));
    check_invariant(&s);
}

#[test]
fn single_stores_only_fine() {
    let cache = GeometryCache::new(CacheConfig::single(10 * 3468));
    let fine = key(0, 0, Tier::Fine);
    cache.get_or_build(fine, || grid(Tier::Fine, 1));
    assert!(cache.contains(fine));
    assert_eq!(cache.get_or_build(fine, || grid(Tier::Fine, 2)).id, 1);
    // A coarse lookup is served but not stored: its tier has no budget.
    let coarse = key(0, 0, Tier::Coarse);
    assert_eq!(cache.get_or_build(coarse, || grid(Tier::Coarse, 3)).id, 3);
    assert_eq!(cache.get_or_build(coarse, || grid(Tier::Coarse, 4)).id, 4);
    assert!(!cache.contains(coarse));
    assert_eq!(cache.resident_bytes(Tier::Coarse), 0);
    let s = cache.stats();
    assert_eq!(s.tiers.clone().map(|t| t.capacity_entries), [Some(0), Some(0), Some(10)]);
    assert_eq!(s.budget_bytes, Some(10 * 3468));
    assert_eq!((s.tier(Tier::Coarse).misses, s.tier(Tier::Fine).hits), (1, 1));
    assert!(!s.table().contains("medium"), "an unused tier is left out of the table");
}

#[test]
fn invalidate_mesh_removes_only_that_mesh_and_frees_its_bytes() {
    let cache = GeometryCache::new(CacheConfig::default());
    for mesh in [1, 2] {
        for t in Tier::ALL {
            for s in 0..5 {
                cache.get_or_build(key(mesh, s, t), || Grid { id: s.into(), bytes: 100 * mesh as usize + 1, verts: 4 });
            }
        }
    }
    let before = cache.stats();
    cache.invalidate_mesh(1);
    for t in Tier::ALL {
        assert_eq!(cache.resident_bytes(t), 5 * 201, "mesh 2's bytes stay, mesh 1's are freed");
        assert_eq!(cache.resident_entries(t), 5);
        for s in 0..5 {
            assert!(!cache.contains(key(1, s, t)));
            assert!(cache.contains(key(2, s, t)));
        }
    }
    assert_eq!(cache.stats(), before, "invalidation alone changes no counter");
    // Mesh 2 still hits; mesh 1's next build is of new geometry, so it is cold, not a miss.
    assert_eq!(cache.get_or_build(key(2, 0, Tier::Fine), || grid(Tier::Fine, 9)).id, 0);
    cache.get_or_build(key(1, 0, Tier::Fine), || grid(Tier::Fine, 9));
    let fine = cache.stats().tier(Tier::Fine).clone();
    assert_eq!((fine.hits, fine.misses, fine.cold_tessellations), (1, 0, 11));
    cache.invalidate_mesh(3); // an unknown mesh: nothing happens
    assert_eq!(cache.resident_entries(Tier::Fine), 6);
}

#[test]
fn a_build_in_flight_when_its_mesh_is_invalidated_is_returned_but_not_stored() {
    let f = Tier::Fine;
    let cache = GeometryCache::new(CacheConfig::default());
    let (started_tx, started_rx) = mpsc::channel();
    let (go_tx, go_rx) = mpsc::channel::<()>();
    let cache_ref = &cache;
    std::thread::scope(|s| {
        let builder = s.spawn(move || {
            cache_ref.get_or_build(key(1, 0, f), || {
                let _ = started_tx.send(());
                let _ = go_rx.recv();
                grid(f, 42)
            })
        });
        let _ = started_rx.recv();
        cache.invalidate_mesh(1);
        let _ = go_tx.send(());
        assert_eq!(builder.join().map(|e| e.id).ok(), Some(42));
    });
    assert!(!cache.contains(key(1, 0, f)));
    assert_eq!(cache.resident_bytes(f), 0);
}

#[test]
fn generation_is_part_of_the_key() {
    let c = Tier::Coarse;
    let cache = GeometryCache::new(CacheConfig::default());
    cache.get_or_build(CacheKey::new(4, 0, 1, c), || grid(c, 0));
    assert_eq!(cache.get_or_build(CacheKey::new(4, 1, 1, c), || grid(c, 1)).id, 1);
    assert!(cache.contains(CacheKey::new(4, 0, 1, c)));
    assert_eq!(cache.stats().tier(c).cold_tessellations, 2);
}

#[test]
fn an_oversized_entry_is_returned_but_not_stored() {
    let m = Tier::Medium;
    let cache = GeometryCache::new(budgets(0, 1000, 0));
    cache.get_or_build(key(0, 0, m), || Grid { id: 0, bytes: 300, verts: 25 });
    let big = cache.get_or_build(key(0, 1, m), || Grid { id: 1, bytes: 1001, verts: 25 });
    assert_eq!(big.id, 1);
    assert!(!cache.contains(key(0, 1, m)));
    assert!(cache.contains(key(0, 0, m)), "an oversized entry evicts nothing");
    assert_eq!(cache.resident_bytes(m), 300);
    assert_eq!(cache.get_or_build(key(0, 1, m), || Grid { id: 2, bytes: 1001, verts: 25 }).id, 2);
    let s = cache.stats();
    let med = s.tier(m);
    assert_eq!((med.peak_bytes, med.cold_tessellations, med.misses, med.recomputed_vertices), (300, 2, 1, 25));
    // Exactly the budget still fits.
    cache.get_or_build(key(0, 2, m), || Grid { id: 3, bytes: 1000, verts: 25 });
    assert!(cache.contains(key(0, 2, m)));
    assert_eq!(cache.resident_bytes(m), 1000);
}

#[test]
fn a_panicking_build_leaves_the_key_buildable() {
    let c = Tier::Coarse;
    let cache = GeometryCache::new(CacheConfig::default());
    let k = key(0, 0, c);
    let (started_tx, started_rx) = mpsc::channel();
    let (go_tx, go_rx) = mpsc::channel::<()>();
    let cache_ref = &cache;
    std::thread::scope(|s| {
        let panicker = s.spawn(move || {
            catch_unwind(AssertUnwindSafe(|| {
                cache_ref.get_or_build(k, || -> Grid {
                    let _ = started_tx.send(());
                    let _ = go_rx.recv();
                    panic!("tessellation failed (on purpose)")
                })
            }))
            .is_err()
        });
        let _ = started_rx.recv();
        // This thread finds the build in flight and waits; when it is abandoned, it builds.
        let waiter = s.spawn(|| cache.get_or_build(k, || grid(c, 7)).id);
        std::thread::sleep(Duration::from_millis(20));
        let _ = go_tx.send(());
        assert_eq!(panicker.join().ok(), Some(true));
        assert_eq!(waiter.join().ok(), Some(7));
    });
    assert!(cache.contains(k));
    let s = cache.stats();
    check_invariant(&s);
    assert_eq!(s.tier(c).lookups, 2);
}

#[test]
fn a_build_that_looks_up_its_own_key_panics_instead_of_deadlocking() {
    let c = Tier::Coarse;
    let cache = GeometryCache::new(CacheConfig::default());
    let k = key(0, 0, c);
    let result = catch_unwind(AssertUnwindSafe(|| {
        cache.get_or_build(k, || {
            let _inner = cache.get_or_build(k, || grid(c, 1));
            grid(c, 2)
        })
    }));
    let message = result.err().and_then(|p| p.downcast_ref::<String>().cloned()).unwrap_or_default();
    assert!(message.contains("wait for itself"), "{message}");
    // The outer build was abandoned, so the key can still be built.
    assert_eq!(cache.get_or_build(k, || grid(c, 3)).id, 3);
}

#[test]
fn stats_json_has_every_named_field() {
    let cache = GeometryCache::new(CacheConfig::default());
    cache.get_or_build(key(0, 0, Tier::Fine), || grid(Tier::Fine, 0));
    let json = serde_json::to_value(cache.stats()).unwrap_or_default();
    let keys = |v: &serde_json::Value| -> HashSet<String> { v.as_object().map(|o| o.keys().cloned().collect()).unwrap_or_default() };
    let top: HashSet<String> = ["mode", "budget_bytes", "tiers", "cold_vertices", "recomputed_vertices"].map(String::from).into();
    assert_eq!(keys(&json), top);
    let tier_fields: HashSet<String> = [
        "name",
        "verts_per_side",
        "capacity_entries",
        "cold_tessellations",
        "lookups",
        "hits",
        "misses",
        "hit_rate",
        "recomputed_vertices",
        "peak_bytes",
    ]
    .map(String::from)
    .into();
    let tiers = json["tiers"].as_array().cloned().unwrap_or_default();
    assert_eq!(tiers.len(), 3);
    for (t, v) in Tier::ALL.iter().zip(&tiers) {
        assert_eq!(keys(v), tier_fields);
        assert_eq!(v["name"], t.name());
        assert_eq!(v["verts_per_side"], t.verts_per_side());
    }
    assert_eq!(json["mode"], "multires");
    assert_eq!(json["budget_bytes"], 30_000_000);
    assert_eq!(json["cold_vertices"], 289);
    assert_eq!(tiers[2]["lookups"], 1);
    assert_eq!(tiers[2]["peak_bytes"], 3468);
    assert_eq!(tiers[2]["capacity_entries"], 2883);
    assert!(tiers[2]["hit_rate"].is_f64());
    // Unbounded has no budget and no capacity: null, not a huge number.
    let unbounded = serde_json::to_value(GeometryCache::<Grid>::new(CacheConfig::unbounded()).stats()).unwrap_or_default();
    assert!(unbounded["budget_bytes"].is_null() && unbounded["tiers"][0]["capacity_entries"].is_null());
    assert_eq!(unbounded["mode"], "unbounded");
}

#[test]
fn table_reads_like_the_papers() {
    let cache = GeometryCache::new(CacheConfig::default());
    let c = Tier::Coarse;
    for _ in 0..4 {
        cache.get_or_build(key(0, 0, c), || grid(c, 0));
    }
    let table = cache.table();
    assert_eq!(table, cache.stats().to_string());
    let lines: Vec<&str> = table.lines().collect();
    assert!(lines[0].contains("multires") && lines[0].contains("30.0 MB"), "{table}");
    let coarse = lines.iter().find(|l| l.starts_with("coarse")).copied().unwrap_or_default();
    assert!(coarse.contains("2x2") && coarse.contains("208333") && coarse.contains("100.00%"), "{coarse}");
    assert!(lines.iter().any(|l| l.starts_with("medium")) && lines.iter().any(|l| l.starts_with("fine")));
    assert!(table.contains("recomputed vertices (cache cost) 0"));
    let unbounded = GeometryCache::<Grid>::new(CacheConfig::unbounded()).table();
    assert!(unbounded.contains("no budget") && unbounded.contains("unbounded"), "{unbounded}");
}

#[test]
fn vertex_vectors_are_entries() {
    let cache: GeometryCache<Vec<[f32; 3]>> = GeometryCache::new(CacheConfig::default());
    let e = cache.get_or_build(key(0, 0, Tier::Medium), || vec![[1.0, 2.0, 3.0]; 25]);
    assert_eq!((e.byte_size(), e.vertex_count()), (300, 25));
    assert_eq!(cache.resident_bytes(Tier::Medium), 300);
}

/// A coarse tessellation as the renderer caches it (4 vertices inline).
fn coarse_tessellation(x: f32) -> crate::tessellate::Tessellation {
    use crate::tessellate::{GridBoxes, GridDomain, Tessellation};
    Tessellation {
        n: 2,
        verts: vec![[x, 0.0, 0.0]; 4].into(),
        boxes: GridBoxes::NONE,
        chord_error: 0.0,
        seam_radius: 0.0,
        seam_normal: Default::default(),
        domain: GridDomain::Square,
    }
}

/// The bookkeeping sizes the module docs quote: a resident coarse tessellation is an 88-byte
/// LRU node (the 64-byte stored entry, its 12-byte key, its size and two links) and an 8-byte
/// index bucket at a load of 37.5–75%; nothing else is allocated for it.
#[test]
fn bookkeeping_is_as_documented() {
    use crate::tessellate::Tessellation;
    assert_eq!(std::mem::size_of::<CacheKey>(), 16);
    assert_eq!(std::mem::size_of::<NodeKey>(), 12);
    assert_eq!(std::mem::size_of::<Option<Resident<Tessellation>>>(), 80);
    let cache: GeometryCache<Tessellation> = GeometryCache::new(CacheConfig::default().with_shards(1));
    let n = 12_000;
    for s in 0..n {
        let e = cache.get_or_build(key(0, s, Tier::Coarse), || coarse_tessellation(s as f32));
        assert_eq!(e.verts[0][0], s as f32);
    }
    assert_eq!(cache.resident_entries(Tier::Coarse), n as usize);
    assert_eq!(cache.resident_bytes(Tier::Coarse), n as usize * 56);
    // 12,000 entries: 16,384 buckets (73% full) of 8 bytes; the slab's amortised growth
    // reserves up to 16,384 nodes, of which only the 12,000 written are ever touched.
    let table = cache.table_bytes(Tier::Coarse);
    let (lo, hi) = (n as usize * 88 + 16_384 * 8, 16_384 * (88 + 8));
    assert!((lo..=hi).contains(&table), "{table} bytes for {n} entries");
    // Hits return the stored grid.
    assert_eq!(cache.get_or_build(key(0, 7, Tier::Coarse), || unreachable!("resident")).verts[3][0], 7.0);
    // 12,000 ids: 1,500 bytes of bitset, rounded up by amortised growth.
    assert!(cache.seen_set_bytes(Tier::Coarse) < 4096, "{}", cache.seen_set_bytes(Tier::Coarse));
}

#[test]
fn builds_get_evicted_entries_to_reuse() {
    let f = Tier::Fine;
    let cache: GeometryCache<Arc<Grid>> = GeometryCache::new(budgets(0, 0, 2 * f.vertex_bytes()));
    let mut spares = Vec::new();
    for s in 0..8u32 {
        cache.get_or_build_reusing(key(0, s, f), |spare| {
            spares.push(spare.map(|g| g.id));
            Arc::new(grid(f, s.into()))
        });
    }
    // Two fit; from the third build on, each evicts the least recent one, which the next build
    // of the shard gets.
    assert_eq!(spares, [None, None, None, Some(0), Some(1), Some(2), Some(3), Some(4)]);
    // Hits and plain builds do not take spares; waiting is the same as before.
    assert_eq!(cache.get_or_build(key(0, 7, f), || unreachable!("resident")).id, 7);
    assert_eq!(cache.resident_entries(f), 2);
    // No more than `MAX_SPARES` are kept: a tier of 1-entry shards that evicts 8 at once.
    let m = Tier::Medium;
    let cache: GeometryCache<Arc<Grid>> = GeometryCache::new(budgets(0, 8, 0));
    for s in 0..8u32 {
        cache.get_or_build(key(0, s, m), || Arc::new(Grid { id: s.into(), bytes: 1, verts: 1 }));
    }
    let big = cache.get_or_build(key(0, 8, m), || Arc::new(Grid { id: 8, bytes: 8, verts: 1 }));
    assert_eq!(Arc::strong_count(&big), 2);
    let mut kept = Vec::new();
    for s in 9..20u32 {
        cache.get_or_build_reusing(key(0, s, m), |spare| {
            kept.extend(spare.map(|g| g.id));
            Arc::new(Grid { id: s.into(), bytes: 8, verts: 1 })
        });
    }
    // Of the 8 evicted at once, the first 4 (0–3) were kept, the rest dropped; the next build
    // got the newest kept one, and every later build the entry the one before it evicted.
    assert_eq!(super::tier_cache::MAX_SPARES, 4);
    assert_eq!(kept, [3, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17]);
    check_invariant(&cache.stats());
}

/// Threads asking for the same split children in different orders get one id per child, dense
/// after the roots, and the same ids from every handle to the table of that mesh generation.
#[test]
fn split_ids_are_dense_and_the_same_for_every_thread_and_render() {
    let cache: GeometryCache<Grid> = GeometryCache::new(CacheConfig::default());
    let children: Vec<u64> = (0..500u64).map(|c| c * 7919 + (c << 40)).collect();
    let per_thread: Vec<Vec<u32>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..4)
            .map(|t| {
                let (cache, children) = (&cache, &children);
                s.spawn(move || {
                    let ids = cache.split_ids(3, 2, 40);
                    // Each thread walks the children from another start, both ways.
                    let order: Vec<usize> = (0..children.len()).map(|k| (k * (2 * t + 1) + 97 * t) % children.len()).collect();
                    for &k in order.iter().rev() {
                        ids.id(children[k]);
                    }
                    children.iter().map(|&c| ids.id(c)).collect()
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(per_thread.windows(2).all(|w| w[0] == w[1]), "every thread sees the same ids");
    let mut ids = per_thread[0].clone();
    ids.sort_unstable();
    assert_eq!(ids, (40..540).collect::<Vec<u32>>(), "one id per child, dense after the 40 roots");
    // A later render's handle answers the same; another mesh's table is its own.
    let later = cache.split_ids(3, 2, 40);
    assert_eq!(children.iter().map(|&c| later.id(c)).collect::<Vec<_>>(), per_thread[0]);
    assert_eq!(cache.split_ids(4, 2, 40).id(children[0]), 40);
    assert!(cache.split_id_bytes() >= 500 * 12, "{}", cache.split_id_bytes());
}

#[test]
fn a_tier_too_small_for_the_working_set_is_reported_with_a_budget_that_fits() {
    // 10 fine grids of 100 bytes in a 500-byte fine tier, swept in order three times: LRU evicts
    // each just before it is needed again (the cliff), so every lookup after the first sweep
    // rebuilds. A brute-force truth: 10 distinct, 20 rebuilt, 1000 bytes would hold them.
    let cache: GeometryCache<Grid> = GeometryCache::new(budgets(0, 0, 500).with_entry_bytes([1, 1, 100]));
    let before = cache.stats();
    let mut built = 0u64;
    for _ in 0..3 {
        for s in 0..10 {
            cache.get_or_build(key(0, s, Tier::Fine), || {
                built += 1;
                Grid { id: u64::from(s), bytes: 100, verts: 1 }
            });
        }
    }
    assert_eq!(built, 30, "LRU thrashes: every lookup builds");
    let report = cache.too_small(&before);
    let expected = TooSmall { tier: "fine", budget_bytes: 500, distinct: 10, rebuilt: 20, fits_bytes: 1000, total_mb: 1 };
    assert_eq!(report, vec![expected]);

    // A budget below one entry stores nothing: every lookup after the first sweep rebuilds.
    let none_fit: GeometryCache<Grid> = GeometryCache::new(budgets(0, 0, 50).with_entry_bytes([1, 1, 100]));
    let before = none_fit.stats();
    for _ in 0..3 {
        for s in 0..10 {
            none_fit.get_or_build(key(0, s, Tier::Fine), || Grid { id: u64::from(s), bytes: 100, verts: 1 });
        }
    }
    let expected = TooSmall { tier: "fine", budget_bytes: 50, distinct: 10, rebuilt: 20, fits_bytes: 1000, total_mb: 1 };
    assert_eq!(none_fit.too_small(&before), vec![expected]);
    assert!(none_fit.too_small(&before).len() == 1, "reported every render (warned once)");

    // With that budget the same sweeps rebuild nothing and nothing is reported.
    let fits: GeometryCache<Grid> = GeometryCache::new(budgets(0, 0, 1000).with_entry_bytes([1, 1, 100]));
    let before = fits.stats();
    for _ in 0..3 {
        for s in 0..10 {
            fits.get_or_build(key(0, s, Tier::Fine), || Grid { id: u64::from(s), bytes: 100, verts: 1 });
        }
    }
    assert_eq!(fits.stats().since(&before).tiers[Tier::Fine.index()].misses, 0);
    assert!(fits.too_small(&before).is_empty());
}
