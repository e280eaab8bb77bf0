//! Property tests: watertight ray–triangle and ray–quad intersection (random meshes, rays through
//! shared edges and vertices exactly), and the geometry cache's invariants (every lookup is a
//! hit, a miss or a cold tessellation; a tier never holds more than its budget).

#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use glam::Vec3A;
use mipray::geometry_cache::{CacheConfig, CacheKey, CacheMode, GeometryCache, Tier};
use mipray::intersect::{intersect_tessellation, WatertightRay};
use mipray::tessellate::{GridDomain, Tessellation};
use proptest::prelude::*;

fn v3() -> impl Strategy<Value = Vec3A> {
    (-10.0f32..10.0, -10.0f32..10.0, -10.0f32..10.0).prop_map(|(x, y, z)| Vec3A::new(x, y, z))
}

fn unit() -> impl Strategy<Value = Vec3A> {
    v3().prop_filter("a direction", |v| v.length() > 0.1).prop_map(|v| v.normalize())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// Two triangles sharing the edge (a, b), folded along it: a ray through any point of the
    /// edge hits one of them (unless it runs along a triangle's plane, where neither test can
    /// answer reliably and the ray does not cross the surface anyway).
    #[test]
    fn a_ray_through_a_shared_edge_hits_one_of_its_triangles(a in v3(), b in v3(), c in v3(), d in v3(), t in 0.02f32..0.98, dir in unit(), dist in 0.5f32..50.0) {
        let n1 = (b - a).cross(c - a);
        prop_assume!(n1.length() > 1e-2 && (b - a).length() > 1e-2);
        // c and d on opposite sides of the edge seen along the ray (d mirrored if not): the
        // ray then crosses the fold, as at every shared edge of a tessellated surface.
        let m = dir.cross(b - a);
        prop_assume!(m.length() > 1e-2);
        let side = |p: Vec3A| (p - a).dot(m);
        let d = if side(c) * side(d) > 0.0 { d - m * (2.0 * side(d) / m.length_squared()) } else { d };
        prop_assume!(side(c).abs() > 1e-3 && side(d).abs() > 1e-3);
        let n2 = (a - b).cross(d - b);
        prop_assume!(n2.length() > 1e-2);
        prop_assume!(n1.normalize().dot(dir).abs() > 1e-3 && n2.normalize().dot(dir).abs() > 1e-3);
        let p = a + (b - a) * t;
        let ray = WatertightRay::new(p - dir * dist, dir);
        let h1 = ray.hit_triangle(a, b, c, f32::INFINITY);
        let h2 = ray.hit_triangle(b, a, d, f32::INFINITY);
        prop_assert!(h1.is_some() || h2.is_some(), "slipped between the triangles at t = {t}");
    }

    /// A fan of triangles around a shared vertex, closed all the way round: a ray through the
    /// vertex itself hits at least one triangle. The ray's origin is rounded, so it passes
    /// within rounding of the vertex: the fan must cover the vertex's neighbourhood as the ray
    /// sees it, i.e. not fold over (a steep saddle seen from the side: some triangle then faces
    /// the ray the other way, and a ray just beside the vertex can pass between the layers;
    /// every failure seen of this test, 49 in 3 million fans, was such a fold).
    #[test]
    fn a_ray_through_a_shared_vertex_hits_its_fan(center in v3(), n in 3usize..12, radius in 0.5f32..5.0, lift in -1.0f32..1.0, dir_xy in (-0.5f32..0.5, -0.5f32..0.5), dist in 0.5f32..50.0) {
        let ring: Vec<Vec3A> = (0..n).map(|k| {
            let a = std::f32::consts::TAU * k as f32 / n as f32;
            center + Vec3A::new(radius * a.cos(), radius * a.sin(), lift * (k % 2) as f32)
        }).collect();
        let dir = Vec3A::new(dir_xy.0, dir_xy.1, -1.0).normalize();
        let facing: Vec<f32> = (0..n).map(|k| (ring[k] - center).cross(ring[(k + 1) % n] - center).dot(dir)).collect();
        prop_assume!(facing.iter().all(|f| *f < 0.0) || facing.iter().all(|f| *f > 0.0), "the fan folds over as the ray sees it");
        let ray = WatertightRay::new(center - dir * dist, dir);
        let hit = (0..n).any(|k| ray.hit_triangle(center, ring[k], ring[(k + 1) % n], f32::INFINITY).is_some());
        prop_assert!(hit, "slipped through the fan's centre");
    }

    /// A random height field on an n×n grid (any effective rate: stride 1 or 2; square or
    /// triangle domain): rays from above, steeper than any slope of the field (so they cross it
    /// once), through grid lines and grid vertices exactly always hit it.
    #[test]
    fn rays_through_grid_lines_and_vertices_always_hit_the_quads(heights in proptest::collection::vec(-0.1f32..0.1, 25), k in 1usize..4, s in 0.01f32..0.99, vertical in proptest::bool::ANY, tilt in (-0.6f32..0.6, -0.6f32..0.6), stride in 1usize..=2, triangle in proptest::bool::ANY) {
        let n = 5;
        let verts: Vec<[f32; 3]> = (0..n * n).map(|i| [(i % n) as f32 / 4.0, (i / n) as f32 / 4.0, heights[i]]).collect();
        let domain = if triangle { GridDomain::LowerTriangle } else { GridDomain::Square };
        let tess = Tessellation { n, verts: verts.into(), boxes: Default::default(), chord_error: 0.0, seam_radius: 0.0, seam_normal: Default::default(), domain };
        // A point on interior grid line k (at this stride's lines: 1, 2, 3 or just 2), at
        // parameter s along it; s on a vertex now and then.
        let line = (if stride == 2 { 2 } else { k }) as f32 / 4.0;
        let s = if (s * 100.0) as u32 % 5 == 0 { (s * 4.0).round().clamp(1.0, 3.0) / 4.0 } else { s };
        let (x, y) = if vertical { (line, s) } else { (s, line) };
        prop_assume!(!triangle || x + y < 0.999);
        let dir = Vec3A::new(tilt.0, tilt.1, -1.0).normalize();
        // Aim at the grid's own interpolation of that point (bilinear along the line is exact:
        // a grid line is one edge of two quads).
        let at = |i: usize, j: usize| Vec3A::from(tess.verts[j * n + i]);
        let z = if vertical {
            let i = (line * 4.0).round() as usize;
            let f = s * 4.0 / stride as f32;
            let j0 = ((f.floor() as usize).min(4 / stride - 1)) * stride;
            let w = (s * 4.0 - j0 as f32) / stride as f32;
            at(i, j0).z * (1.0 - w) + at(i, j0 + stride).z * w
        } else {
            let j = (line * 4.0).round() as usize;
            let f = s * 4.0 / stride as f32;
            let i0 = ((f.floor() as usize).min(4 / stride - 1)) * stride;
            let w = (s * 4.0 - i0 as f32) / stride as f32;
            at(i0, j).z * (1.0 - w) + at(i0 + stride, j).z * w
        };
        let target = Vec3A::new(x, y, z);
        let ray = WatertightRay::new(target - dir * 3.0, dir);
        prop_assert!(intersect_tessellation(&ray, &tess, stride, 0.0, f32::INFINITY, &mipray::intersect::every_hit).is_some(), "missed ({x}, {y}) at stride {stride}");
    }
}

/// One lookup: a tier and a subpatch id.
fn lookups() -> impl Strategy<Value = Vec<(usize, u32)>> {
    proptest::collection::vec((0usize..3, 0u32..60), 1..400)
}

fn entry(tier: Tier) -> Vec<[f32; 3]> {
    vec![[0.0; 3]; tier.vertex_count() as usize]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// For any sequence of lookups and any mode and budget: lookups = hits + misses + cold
    /// tessellations in every tier; resident and peak bytes never exceed a tier's budget; a
    /// resident key is served without building; `unbounded` never misses and `none` never hits.
    #[test]
    fn cache_counts_add_up_and_tiers_stay_within_budget(seq in lookups(), budget in 0usize..40_000, mode in 0usize..4, shards in 0usize..3) {
        let mode = [CacheMode::Multires, CacheMode::Single, CacheMode::Unbounded, CacheMode::None][mode];
        let config = CacheConfig::for_mode(mode, budget).with_shards([0, 1, 4][shards]);
        let cache: GeometryCache<Vec<[f32; 3]>> = GeometryCache::new(config);
        let mut builds = [0u64; 3];
        for &(t, id) in &seq {
            let tier = Tier::ALL[t];
            let key = CacheKey::new(1, 0, id, tier);
            let resident = cache.contains(key);
            let mut built = false;
            let e = cache.get_or_build(key, || {
                built = true;
                entry(tier)
            });
            prop_assert_eq!(e.len(), tier.vertex_count() as usize);
            prop_assert!(!(resident && built), "a resident entry was built again");
            builds[t] += u64::from(built);
            if let Some(b) = config.tier_budget_bytes(tier) {
                prop_assert!(cache.resident_bytes(tier) <= b, "{:?} holds {} > {b}", tier, cache.resident_bytes(tier));
            }
        }
        let stats = cache.stats();
        for tier in Tier::ALL {
            let s = stats.tier(tier);
            let n = seq.iter().filter(|(t, _)| Tier::ALL[*t] == tier).count() as u64;
            prop_assert_eq!(s.lookups, n);
            prop_assert_eq!(s.lookups, s.hits + s.misses + s.cold_tessellations, "{:?}", s);
            prop_assert_eq!(builds[tier.index()], s.misses + s.cold_tessellations);
            if let Some(b) = config.tier_budget_bytes(tier) {
                prop_assert!(s.peak_bytes <= b as u64, "{:?} peak {} > budget {b}", tier, s.peak_bytes);
            }
            match mode {
                CacheMode::Unbounded => prop_assert_eq!(s.misses, 0),
                CacheMode::None => prop_assert_eq!(s.hits, 0),
                _ => {}
            }
        }
    }
}

/// The cache's counts add up under threads too: 4 threads, overlapping keys.
#[test]
fn cache_counts_add_up_under_threads() {
    let cache: Arc<GeometryCache<Vec<[f32; 3]>>> = Arc::new(GeometryCache::new(CacheConfig::multires(20_000)));
    std::thread::scope(|s| {
        for th in 0..4u64 {
            let cache = cache.clone();
            s.spawn(move || {
                let mut x = th.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
                for _ in 0..5000 {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    let tier = Tier::ALL[(x % 3) as usize];
                    cache.get_or_build(CacheKey::new(0, 0, ((x >> 8) % 200) as u32, tier), || entry(tier));
                }
            });
        }
    });
    let stats = cache.stats();
    let total: u64 = Tier::ALL.iter().map(|t| stats.tier(*t).lookups).sum();
    assert_eq!(total, 20_000);
    for t in Tier::ALL {
        let s = stats.tier(t);
        assert_eq!(s.lookups, s.hits + s.misses + s.cold_tessellations, "{s:?}");
        assert!(s.peak_bytes <= cache.config().tier_budget_bytes(t).unwrap() as u64);
    }
}
