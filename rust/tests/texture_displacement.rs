//! Texture displacement at tessellation time reads the MIP level of its grid: a coarse tier's
//! lookups are as wide as its quads, so they read a coarse level (the paper's §2.6 applied to
//! displacement), and forcing the finest level ([`FilterMode::Finest`], the §6.3.3 experiment)
//! makes every tier read level 0.
//!
//! The sampler is the core's procedural [`CheckerSampler`] (1024² texels, 8×8 squares of 128
//! texels), which records the MIP level each lookup asks for. The surface is a 2×2-unit quad
//! with face-varying `st` spanning [0, 1]², so a grid of n vertices per side over the whole patch
//! has steps of 1024 / (n − 1) texels: level log₂(1024 / (n − 1)) exactly.

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;

use glam::Vec3A;
use mipray::displacement::{grid_spacing, Displacement, DisplacementShader, TextureDisplacement};
use mipray::geometry_cache::Tier;
use mipray::patch::{GridSamples, LimitSurface, UvRect};
use mipray::texture::{CheckerSampler, FilterMode, TextureSampler};

const RES: u32 = 1024;

mod common;

use common::st_quad::st_quad as quad;

fn displacement(filter: FilterMode) -> (Arc<CheckerSampler>, TextureDisplacement) {
    let checker = Arc::new(CheckerSampler::new("disp.tx", RES, 8, filter));
    let mut d = TextureDisplacement::new(checker.clone(), "disp.tx", 0).unwrap();
    d.scale = 0.2;
    d.bias = -0.1;
    (checker, d)
}

/// Offsets of one grid, and the histogram of MIP levels its lookups asked for.
fn grid(d: &TextureDisplacement, checker: &CheckerSampler, surface: &dyn LimitSurface, rect: UvRect, n: usize) -> (Vec<f32>, Vec<u64>) {
    checker.reset();
    let mut out = Vec::new();
    d.grid_offsets(surface, 0, rect, n, &mut out);
    assert_eq!(out.len(), n * n);
    (out, checker.level_histogram())
}

#[test]
fn coarse_tiers_read_coarser_mip_levels() {
    let surface = quad();
    let (checker, d) = displacement(FilterMode::Differentials);
    let half = UvRect { u0: 0.0, v0: 0.0, u1: 0.5, v1: 0.5 };
    // (tier, rect, expected level): 1024 texels over 1, 4, 16 quads, and 512 over 16 (a split child).
    let cases = [(Tier::Coarse, UvRect::UNIT, 10), (Tier::Medium, UvRect::UNIT, 8), (Tier::Fine, UvRect::UNIT, 6), (Tier::Fine, half, 5)];
    let mut summary = Vec::new();
    for (tier, rect, level) in cases {
        let n = tier.verts_per_side() as usize;
        let (offsets, hist) = grid(&d, &checker, &surface, rect, n);
        assert_eq!(hist[level], (n * n) as u64, "{tier:?} over {rect:?}: every lookup at level {level}, got {hist:?}");
        assert!((checker.mean_level() - level as f64).abs() < 1e-3, "{}", checker.mean_level());
        for o in &offsets {
            assert!(o.abs() <= d.bound() + 1e-6, "{o}");
        }
        summary.push(format!("{tier:?}/{n}: level {level}"));
    }
    println!("texture displacement levels: {}", summary.join(", "));
    // A coarse quad's lookups cover the whole checker: its average, 0.5 → 0.2·0.5 − 0.1 = 0.
    let (coarse, _) = grid(&d, &checker, &surface, UvRect::UNIT, 2);
    assert!(coarse.iter().all(|o| o.abs() < 1e-6), "{coarse:?}");
    // A fine grid resolves the squares (64 texels per step, half a square): offsets vary.
    let (fine, _) = grid(&d, &checker, &surface, UvRect::UNIT, 17);
    let (lo, hi) = fine.iter().fold((f32::MAX, f32::MIN), |(a, b), &o| (a.min(o), b.max(o)));
    assert!(hi - lo > 0.09, "fine offsets span {lo}..{hi}");
    assert_eq!(d.failed_lookups(), 0);
}

#[test]
fn finest_mode_reads_level_zero_at_every_tier() {
    let surface = quad();
    let (checker, d) = displacement(FilterMode::Finest);
    for tier in [Tier::Coarse, Tier::Medium, Tier::Fine] {
        let n = tier.verts_per_side() as usize;
        let (_, hist) = grid(&d, &checker, &surface, UvRect::UNIT, n);
        assert_eq!(hist[0], (n * n) as u64, "{tier:?}: {hist:?}");
    }
    assert_eq!(checker.stats()["filter_mode"], "finest");
}

#[test]
fn shader_enum_keeps_the_procedural_path_and_bounds() {
    let surface = quad();
    let fbm = Displacement { amplitude: 0.1, frequency: 1.5, octaves: 4, gain: 0.5 };
    let shader = DisplacementShader::from(fbm);
    let mut samples = GridSamples::default();
    surface.evaluate_grid(0, UvRect::UNIT, 17, false, &mut samples);
    let mut out = Vec::new();
    shader.grid_offsets(&surface, 0, UvRect::UNIT, &samples.p, 17, &mut out);
    // Bit for bit what tessellation computed before the shader enum: offset(p, grid spacing).
    let spacing = grid_spacing(&samples.p, 17);
    assert!((spacing - 0.125).abs() < 1e-6, "{spacing}");
    for (o, p) in out.iter().zip(&samples.p) {
        assert_eq!(*o, fbm.offset(Vec3A::from(*p), spacing));
    }
    assert_eq!(shader.bound(), fbm.bound());
    let (_, d) = displacement(FilterMode::Differentials);
    let tex = DisplacementShader::from(d);
    assert!((tex.bound() - 0.1).abs() < 1e-6);
    assert!(tex.validate().is_ok());
    tex.grid_offsets(&surface, 0, UvRect::UNIT, &samples.p, 17, &mut out);
    assert_eq!(out.len(), 17 * 17);
}

#[test]
fn missing_texture_names_its_path_and_missing_st_reads_the_fallback() {
    let checker: Arc<dyn TextureSampler> = Arc::new(CheckerSampler::new("disp.tx", RES, 8, FilterMode::Differentials));
    let err = TextureDisplacement::new(checker.clone(), "textures/missing.tx", 0).unwrap_err();
    assert!(err.to_string().contains("textures/missing.tx"), "{err}");
    // Channel 1 does not exist on the quad: every vertex reads st_fallback (0.06, 0.06), which
    // lies in the bottom-left (0) square, with zero widths: the finest level.
    let mut d = TextureDisplacement::new(checker, "disp.tx", 1).unwrap();
    d.st_fallback = [0.06, 0.06];
    d.bias = 0.25;
    let mut out = Vec::new();
    d.grid_offsets(&quad(), 0, UvRect::UNIT, 5, &mut out);
    assert!(out.iter().all(|&o| o == 0.25), "{out:?}");
    d.scale = f32::NAN;
    assert!(d.validate().unwrap_err().contains("scale"));
}

#[test]
fn pointwise_offsets_equal_the_grid_offsets_at_its_vertices() {
    // What shading at a hit uses (offset_at) agrees with what the tessellation stored.
    let surface = quad();
    let (_, d) = displacement(FilterMode::Differentials);
    let fbm = Displacement { amplitude: 0.1, frequency: 1.5, octaves: 4, gain: 0.5 };
    let mut samples = GridSamples::default();
    surface.evaluate_grid(0, UvRect::UNIT, 5, false, &mut samples);
    let spacing = grid_spacing(&samples.p, 5);
    for shader in [DisplacementShader::from(d), DisplacementShader::from(fbm)] {
        let mut grid = Vec::new();
        shader.grid_offsets(&surface, 0, UvRect::UNIT, &samples.p, 5, &mut grid);
        for j in 0..5 {
            for i in 0..5 {
                let (u, v) = UvRect::UNIT.grid_uv(i, j, 5);
                let p = Vec3A::from(samples.p[j * 5 + i]);
                let one = shader.offset_at(&surface, 0, (u, v), p, spacing, 0.25);
                assert_eq!(one, grid[j * 5 + i], "{shader:?} at ({u}, {v})");
            }
        }
    }
}
/// Wiring check (scratch copy only): tessellate() with a texture shader moves the fine tier's
/// vertices by the texture and the coarse tier's by its mean.
#[test]
fn tessellate_uses_the_texture_shader() {
    use mipray::subpatch::Subpatch;
    use mipray::tessellate::{tessellate, DisplaceParams};
    let surface = quad();
    let (checker, d) = displacement(FilterMode::Differentials);
    let params = DisplaceParams { displacement: DisplacementShader::from(d), normal_sign: 1.0, bound: 0.1, texture_edges_alike: false };
    let sub = Subpatch { patch: 0, rect: UvRect::UNIT, bounds: surface.patch_bounds(0), affine: false };
    let mut scratch = GridSamples::default();
    let (coarse, _) = tessellate(&surface, &sub, Tier::Coarse, Some(&params), &mut scratch);
    assert!(coarse.verts.iter().all(|v| v[2].abs() < 1e-6), "{:?}", coarse.verts);
    checker.reset();
    let (fine, _) = tessellate(&surface, &sub, Tier::Fine, Some(&params), &mut scratch);
    assert_eq!(checker.level_histogram()[6], 289);
    let zs: Vec<f32> = fine.verts.iter().map(|v| v[2]).collect();
    assert!(zs.iter().any(|&z| z > 0.09) && zs.iter().any(|&z| z < -0.09), "{zs:?}");
}
