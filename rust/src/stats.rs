//! Render statistics, as the paper reports them, under the stable names of DESIGN.md
//! ("Statistics and stats JSON"): nested JSON objects whose dotted paths are the names.

use serde_json::{json, Value};

use crate::effects::Effect;
use crate::ray::RayKind;
use crate::tessellate::Rate;
use crate::trace::{TraceCounters, Tracer};

/// Peak resident set size of this process in bytes (Linux `VmHWM`), or 0 where unknown.
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1).and_then(|kb| kb.parse::<u64>().ok()))
        })
        .map_or(0, |kb| kb * 1024)
}

/// What the render measured beyond the tracer's own counters.
pub struct RenderFigures {
    pub wall_s: f64,
    pub threads: usize,
    pub dropped_samples: u64,
    pub width: usize,
    pub height: usize,
    pub samples: u32,
}

/// Builds the stats JSON of one render. `cache_before` is the cache's statistics when the
/// render started (a delegate's cache lives across renders): the JSON reports this render's
/// lookups, misses and vertices only.
pub fn collect(
    tracer: &Tracer<'_>,
    counters: &TraceCounters,
    effects: &[Effect],
    figures: &RenderFigures,
    control_faces: usize,
    instances: usize,
    cache_before: &crate::geometry_cache::CacheStats,
) -> Value {
    let mut geometry_cache = serde_json::to_value(tracer.cache.stats().since(cache_before)).unwrap_or(Value::Null);
    if let Value::Object(g) = &mut geometry_cache {
        // Tiers whose budget this render outgrew (warned once per cache).
        g.insert("too_small".into(), serde_json::to_value(tracer.cache.too_small(cache_before)).unwrap_or(Value::Null));
    }
    let rays: serde_json::Map<String, Value> =
        RayKind::ALL.iter().enumerate().map(|(i, k)| (k.name().to_string(), json!(counters.rays[i]))).collect();
    let rates: serde_json::Map<String, Value> =
        Rate::ALL.iter().map(|r| (r.quads().to_string(), json!(counters.rate_tests[*r as usize]))).collect();
    let by_kind: serde_json::Map<String, Value> = RayKind::ALL
        .iter()
        .enumerate()
        .map(|(i, k)| {
            let h = counters.rate_tests_by_kind[i];
            (k.name().to_string(), json!({"1": h[0], "2": h[1], "4": h[2], "8": h[3], "16": h[4], "split": h[5]}))
        })
        .collect();
    let subpatches = tracer.subpatch_count() as u64;
    // Patches intersected exactly (implicit gprims, points) are never tessellated.
    let exact_patches = tracer.exact_patch_count() as u64;
    // Curve segments' finest tessellation is 17 centreline points and their widths.
    let curve_segments = tracer.curve_segment_count() as u64;
    let full_verts = (subpatches - exact_patches - curve_segments) * 17 * 17 + curve_segments * 17 * 2;
    json!({
        "render": {
            "wall_s": figures.wall_s,
            "threads": figures.threads,
            "resolution": [figures.width, figures.height],
            "samples": figures.samples,
            "rays": rays,
            "ray_subpatch_tests": counters.ray_subpatch_tests,
            "rate_tests": rates,
            "rate_tests_by_ray": by_kind,
            "finer_than_fine_tests": counters.finer_than_fine,
            "differential_clamps": counters.differential_clamps,
            "cutout_passes": counters.cutout_passes,
            "cutout_limit_rays": counters.cutout_limit,
            "dropped_samples": figures.dropped_samples,
        },
        "geometry_cache": geometry_cache,
        "scene": {
            "control_faces": control_faces,
            "subpatches": subpatches,
            "exact_patches": exact_patches,
            "curve_segments": curve_segments,
            "instances": instances,
            "full_tessellation_vertices": full_verts,
            "full_tessellation_bytes": full_verts * 12,
            "bvh_bytes": tracer.bvh_bytes(),
            "subpatch_bytes": tracer.subpatch_bytes(),
            "split_subpatches": tracer.mesh_geometry().map(|m| m.child_ids.len()).sum::<usize>(),
            // Meshes whose patches are built on first use: how many rays reached (their
            // subpatches are counted above), how many none did (never built), and how many of
            // their grids left the bounds they were placed by (rays may have missed those).
            "meshes_built_on_first_use": tracer.lazy_meshes_built(),
            "meshes_not_reached": tracer.meshes_not_reached(),
            "lazy_bounds_escaped": tracer.lazy_bounds_escaped.load(std::sync::atomic::Ordering::Relaxed),
            "displaced_vertices_outside_bounds": tracer.displaced_outside.load(std::sync::atomic::Ordering::Relaxed),
            "lights": tracer.scene().lights.iter().map(|l| l.describe(&|m| tracer.scene().mesh_name(m))).collect::<Vec<Value>>(),
            // Surfaces made cheaper than exact to bound their work, each naming its prim.
            "simplified": tracer.scene().meshes.iter().filter_map(|m| m.surface.simplified().map(|s| format!("{}: {s}", m.name))).collect::<Vec<String>>(),
        },
        // The geometry memory budget (`geometryMemoryMb`), when one is set.
        "geometry_budget": tracer.budget().map_or(Value::Null, crate::geometry_budget::Budget::stats),
        "texture_cache": tracer.scene().textures.as_ref().map_or(Value::Null, |t| t.stats()),
        // The displacement texture store's own memory (its texels are not in texture_cache).
        "displacement_textures": crate::displacement_texture::stats(tracer.scene().meshes.iter().filter_map(|m| match &m.displacement {
            Some(crate::displacement::DisplacementShader::Texture(t)) => Some(t.store()),
            _ => None,
        })),
        "memory": { "peak_rss_bytes": peak_rss_bytes() },
        "effects": { "enabled": effects },
    })
}
