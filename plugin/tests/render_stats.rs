//! The stats JSON of real renders through the delegate: every name DESIGN.md lists ("Statistics
//! and stats JSON") is there, and the figures agree with each other and with the render, for a
//! first render (cold cache) and a second one on the delegate's warm cache (each render reports
//! its own lookups).

#![allow(clippy::unwrap_used)]

mod common;

use glam::{Mat4, Vec3};
use hd_mipray::material::{SurfaceInputs, TextureInput};
use hd_mipray::mesh::MeshData;
use hd_mipray::{RenderDelegate, RenderPass, RenderSettings};
use mipray::aov::Aov;
use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo};
use mipray::material::Input;
use mipray::progress::NoProgress;
use mipray::texture::{Interpolation, Primvar2, Wrap};
use mipray_bridge::OiioImageIo;
use serde_json::Value;

const WIDTH: usize = 20;
const HEIGHT: usize = 16;
const SAMPLES: u32 = 2;

/// A subdivision cube and, beside it, a quad with a diffuse texture (so the texture system is
/// used and reports), under the shadow-casting sun of `delegate_with_camera`.
fn delegate(texture_file: &str) -> RenderDelegate {
    let mut d = common::delegate_with_camera(Vec3::new(1.0, -3.0, 4.0), Vec3::ZERO, true);
    d.set_mesh("/cube", common::grey_mesh("/cube", common::cube(), 0.6));
    let (mut topology, points) = mipray::bilinear::grid_mesh(1.0, 1, 0.0);
    topology.scheme = mipray::topology::Scheme::None;
    let st = Primvar2 {
        name: "st".into(),
        interpolation: Interpolation::FaceVarying,
        values: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        indices: Vec::new(),
    };
    let diffuse = TextureInput {
        file: texture_file.into(),
        scale: [1.0; 4],
        bias: [0.0; 4],
        fallback: [0.5; 4],
        wrap_s: Wrap::Clamp,
        wrap_t: Wrap::Clamp,
        channel: 0,
        color_space: mipray::texture::SourceColorSpace::Auto,
        udim_tiles: Vec::new(),
    };
    d.set_mesh(
        "/quad",
        MeshData {
            topology,
            points,
            transform: Mat4::from_translation(Vec3::new(2.0, 0.0, 0.0)),
            st: Some(st),
            material: Some(SurfaceInputs {
                textures: vec![(Input::DiffuseColor, diffuse)],
                ..SurfaceInputs::lambertian("/quad", [0.18; 3])
            }),
            ..Default::default()
        },
    );
    d
}

/// `value` at a dotted path, which must exist.
fn at<'a>(stats: &'a Value, path: &str) -> &'a Value {
    path.split('.').fold(stats, |v, key| v.get(key).unwrap_or_else(|| panic!("stats lack {path} (at {key})")))
}

fn u(stats: &Value, path: &str) -> u64 {
    at(stats, path).as_u64().unwrap_or_else(|| panic!("{path} is not a count: {}", at(stats, path)))
}

/// Checks one render's stats against each other and the render (a geometry cache of
/// `budget` bytes in all); returns each tier's (lookups, cold tessellations, misses).
fn check(stats: &Value, render: &str, budget: u64) -> [(u64, u64, u64); 3] {
    // render.*
    assert!(at(stats, "render.wall_s").as_f64().unwrap() > 0.0, "{render}");
    for kind in ["camera", "shadow", "reflection", "refraction", "glossy", "diffuse", "ao"] {
        u(stats, &format!("render.rays.{kind}"));
    }
    assert_eq!(u(stats, "render.rays.camera"), (WIDTH * HEIGHT) as u64 * u64::from(SAMPLES), "{render}: one camera ray a sample");
    assert!(u(stats, "render.rays.shadow") > 0, "{render}: the sun casts shadows");
    // Every ray–subpatch test is at one of the five rates or split.
    let tests = u(stats, "render.ray_subpatch_tests");
    let rates: u64 = at(stats, "render.rate_tests").as_object().unwrap().values().map(|v| v.as_u64().unwrap()).sum();
    assert_eq!(rates + u(stats, "render.finer_than_fine_tests"), tests, "{render}");
    assert!(tests > 0, "{render}");

    // geometry_cache.*
    let cache = at(stats, "geometry_cache");
    assert_eq!(at(cache, "mode"), "multires");
    assert_eq!(u(cache, "budget_bytes"), budget, "{render}: the total budget");
    let tiers = at(cache, "tiers").as_array().unwrap();
    assert_eq!(tiers.len(), 3);
    let mut out = [(0, 0, 0); 3];
    let (mut cold_vertices, mut recomputed_vertices, mut lookups) = (0, 0, 0);
    for (t, (name, side)) in [("coarse", 2u64), ("medium", 5), ("fine", 17)].into_iter().enumerate() {
        let tier = &tiers[t];
        assert_eq!((at(tier, "name").as_str().unwrap(), u(tier, "verts_per_side")), (name, side));
        let (l, h, m, c) = (u(tier, "lookups"), u(tier, "hits"), u(tier, "misses"), u(tier, "cold_tessellations"));
        assert_eq!(l, h + m + c, "{render}, {name}: lookups = hits + misses + cold tessellations");
        // The documented hit rate (geometry_cache::TierStats): hits / (hits + misses); 1 when
        // every lookup was cold, 0 with no lookups.
        let rate = at(tier, "hit_rate").as_f64().unwrap();
        let expected = if h + m > 0 {
            h as f64 / (h + m) as f64
        } else if l > 0 {
            1.0
        } else {
            0.0
        };
        assert_eq!(rate, expected, "{render}, {name}: hit rate");
        // One tier is one grid: what a tessellation builds and what the budget holds follow.
        let verts = side * side;
        assert_eq!(u(tier, "recomputed_vertices"), m * verts, "{render}, {name}: misses rebuild whole grids");
        let capacity = u(tier, "capacity_entries");
        let tier_budget = budget / 3;
        assert!(capacity * verts * 12 <= tier_budget && capacity > 0, "{render}, {name}: {capacity} entries of {verts} vertices");
        assert!(u(tier, "peak_bytes") <= tier_budget, "{render}, {name}");
        cold_vertices += c * verts;
        recomputed_vertices += m * verts;
        lookups += l;
        out[t] = (l, c, m);
    }
    assert_eq!(u(cache, "cold_vertices"), cold_vertices, "{render}: cold vertices, all tiers");
    assert_eq!(u(cache, "recomputed_vertices"), recomputed_vertices, "{render}: recomputed vertices, all tiers");
    // Without splits, each ray–subpatch test looks up exactly one tessellation.
    assert_eq!(u(stats, "render.finer_than_fine_tests"), 0, "{render}: nothing here needs more than 16×16 quads");
    assert_eq!(lookups, tests, "{render}: one lookup a test");

    // scene.*
    assert_eq!(u(stats, "scene.control_faces"), 6 + 1, "{render}: the cube's faces and the quad");
    let subpatches = u(stats, "scene.subpatches");
    assert!(subpatches >= 7, "{render}: at least a patch a face, got {subpatches}");
    assert_eq!(u(stats, "scene.full_tessellation_vertices"), subpatches * 17 * 17, "{render}");
    assert_eq!(u(stats, "scene.full_tessellation_bytes"), subpatches * 17 * 17 * 12, "{render}");

    // texture_cache.*: OpenImageIO's, with the one texture the quad reads.
    let tex = at(stats, "texture_cache");
    assert_eq!(at(tex, "kind"), "oiio", "{render}");
    assert_eq!(u(tex, "textures"), 1, "{render}");
    assert!(u(tex, "lookups") > 0, "{render}");

    // memory.peak_rss_bytes: this process holds at least its own binary's pages.
    assert!(u(stats, "memory.peak_rss_bytes") > 1 << 20, "{render}");

    // effects.enabled[]{name,why}
    let effects = at(stats, "effects.enabled").as_array().unwrap();
    for e in effects {
        assert!(!at(e, "name").as_str().unwrap().is_empty() && !at(e, "why").as_str().unwrap().is_empty(), "{render}: {e}");
    }
    let names: Vec<&str> = effects.iter().map(|e| at(e, "name").as_str().unwrap()).collect();
    assert!(names.contains(&"camera") && names.contains(&"shadows"), "{render}: {names:?}");
    out
}

#[test]
fn each_render_s_stats_have_every_named_field_and_agree() {
    let dir = std::env::temp_dir().join(format!("mipray-render-stats-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("checker.exr");
    let pixels: Vec<f32> = (0..16).flat_map(|i| [if (i + i / 4) % 2 == 0 { 0.9 } else { 0.1 }; 3]).collect();
    let image = ImageBuf { width: 4, height: 4, channels: ["R", "G", "B"].map(String::from).to_vec(), pixels, metadata: Vec::new() };
    OiioImageIo.write(&file, &image, &[ChannelFormat::Float], &[]).unwrap();
    // The default 30 MB holds every tessellation; 60 kB (20 kB a tier: 5 fine and 64 medium
    // entries) evicts, so the second render on it misses too.
    for mb in [30.0, 0.06] {
        let budget = (mb * 1e6) as u64;
        let mut d = delegate(file.to_str().unwrap());
        let pass = RenderPass {
            camera: "/cam".into(),
            width: WIDTH,
            height: HEIGHT,
            aovs: vec![Aov::Color],
            // tessFactor 0.25: quads a quarter of the beam wide, so camera rays reach the fine
            // tier at this small size (at the default, rates sized by the patches' own extent
            // stay in the coarse and medium tiers here) and 60 kB evicts fine entries too.
            settings: RenderSettings {
                samples: SAMPLES,
                threads: 1,
                geometry_cache_mb: mb,
                tess_factor: 0.25,
                ..RenderSettings::default()
            },
        };
        let first = pass.execute(&mut d, &NoProgress).unwrap();
        let second = pass.execute(&mut d, &NoProgress).unwrap();
        assert!(first.prim_errors.is_empty(), "{:?}", first.prim_errors);
        let cold = check(&first.stats, &format!("first render, {mb} MB"), budget);
        let warm = check(&second.stats, &format!("second render, {mb} MB"), budget);
        // The same render looks up the same tessellations; the first built each one cold,
        // the second none (the cache remembers what it ever built, evicted or not).
        for t in 0..3 {
            assert_eq!(warm[t].0, cold[t].0, "{mb} MB, tier {t}: the same lookups");
            assert_eq!(warm[t].1, 0, "{mb} MB, tier {t}: nothing cold on a warm cache");
        }
        assert!(cold.iter().map(|c| c.1).sum::<u64>() > 0, "{mb} MB: the first render tessellated");
        let misses: u64 = warm.iter().map(|c| c.2).sum();
        if mb == 30.0 {
            assert_eq!(misses, 0, "30 MB holds everything: the second render only hits");
        } else {
            assert!(misses > 0 && cold[2].2 > 0, "60 kB evicts, in both renders");
        }
        assert_eq!(first.buffers, second.buffers, "{mb} MB: the warm cache changes the cost, never the answer");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
