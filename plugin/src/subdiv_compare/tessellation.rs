//! How far the renderer's tessellations stray from the limit surface: per tier, per effective
//! rate, and for split children.
//!
//! The error at a probe is the distance between the limit surface at a patch (u, v) and the point
//! of the renderer's two triangles per quad (`(p00, p10, p11)` and `(p00, p11, p01)`, as
//! [`mipray::intersect`] splits them) at the same (u, v): what a hit's position and its shading
//! point can differ by. It bounds the geometric (closest-point) distance from above. Probes sit
//! at every quad's centre and edge midpoints, where a bilinear chord strays most.

use std::collections::BTreeMap;

use glam::Vec3A;
use mipray::geometry_cache::Tier;
use mipray::patch::{GridSamples, LimitSurface, PatchKind, UvRect};
use mipray::subpatch::{ChildCell, Subpatch};
use mipray::tessellate::{tessellate, GridDomain, Tessellation};

use super::{in_domain, spread, CompareOptions};

/// Largest errors in object units, by tier name, by rate (quads a side) and by split depth.
#[derive(Clone, Debug, Default)]
pub struct TessellationErrors {
    pub by_tier: BTreeMap<String, f64>,
    pub by_rate: BTreeMap<String, f64>,
    pub after_split: BTreeMap<String, f64>,
    pub patches: usize,
}

/// The renderer's triangle interpolation of quad (p00, p10, p11, p01) at quad-local (lu, lv);
/// `diagonal`: the quad is on a triangle patch's diagonal, where only (p00, p10, p01) is drawn.
pub fn triangle_point(p00: Vec3A, p10: Vec3A, p11: Vec3A, p01: Vec3A, lu: f32, lv: f32, diagonal: bool) -> Vec3A {
    if diagonal {
        p00 + (p10 - p00) * lu + (p01 - p00) * lv
    } else if lu >= lv {
        p00 * (1.0 - lu) + p10 * (lu - lv) + p11 * lv
    } else {
        p00 * (1.0 - lv) + p11 * lu + p01 * (lv - lu)
    }
}

/// The largest error (object units) of `tess`, a grid over `rect` of `patch`, read at vertex
/// `stride`; `each(qi, qj, error)` sees every probe's error with its quad (in stride units).
pub fn grid_error(
    surface: &dyn LimitSurface,
    patch: usize,
    kind: PatchKind,
    rect: UvRect,
    tess: &Tessellation,
    stride: usize,
    mut each: impl FnMut(usize, usize, f64),
) -> f64 {
    let q = (tess.n - 1) / stride;
    let mut worst = 0.0f64;
    let triangle = tess.domain == GridDomain::LowerTriangle;
    if tess.domain == GridDomain::Empty {
        return 0.0;
    }
    for qj in 0..q {
        for qi in 0..q {
            if triangle && qi + qj + 1 > q {
                continue;
            }
            let diagonal = triangle && qi + qj + 1 == q;
            let p00 = tess.vert(qi * stride, qj * stride);
            let p10 = tess.vert((qi + 1) * stride, qj * stride);
            let p11 = tess.vert((qi + 1) * stride, (qj + 1) * stride);
            let p01 = tess.vert(qi * stride, (qj + 1) * stride);
            let mut probes = vec![(0.5, 0.5), (0.5, 0.0), (0.0, 0.5)];
            if qi + 1 == q {
                probes.push((1.0, 0.5));
            }
            if qj + 1 == q {
                probes.push((0.5, 1.0));
            }
            for (lu, lv) in probes {
                let (gu, gv) = ((qi as f32 + lu) / q as f32, (qj as f32 + lv) / q as f32);
                let u = rect.u0 + (rect.u1 - rect.u0) * gu;
                let v = rect.v0 + (rect.v1 - rect.v0) * gv;
                if !in_domain(kind, u, v) {
                    continue;
                }
                let s = surface.evaluate(patch, u, v).p;
                let e = f64::from((s - triangle_point(p00, p10, p11, p01, lu, lv, diagonal)).length());
                let e = if e.is_nan() { f64::INFINITY } else { e };
                each(qi, qj, e);
                worst = worst.max(e);
            }
        }
    }
    worst
}

fn tier_name(t: Tier) -> &'static str {
    t.name()
}

/// Measures the patches [`CompareOptions::tessellation_patches`] picks.
pub fn measure(surface: &dyn LimitSurface, options: &CompareOptions) -> TessellationErrors {
    let mut out = TessellationErrors::default();
    let mut scratch = GridSamples::default();
    let bump = |m: &mut BTreeMap<String, f64>, k: String, e: f64| {
        let slot = m.entry(k).or_insert(0.0);
        *slot = slot.max(e);
    };
    let patches = spread(surface.patch_count(), options.tessellation_patches);
    out.patches = patches.len();
    for &patch in &patches {
        let kind = surface.patch_param(patch).kind;
        let bounds = surface.patch_bounds(patch);
        for tier in Tier::ALL {
            let sub = Subpatch { patch: patch as u32, rect: UvRect::UNIT, bounds, affine: false };
            let (t, _) = tessellate(surface, &sub, tier, None, &mut scratch);
            for stride in [1usize, 2] {
                if (t.n - 1) % stride != 0 || (t.n - 1) / stride < 1 || (tier == Tier::Coarse && stride == 2) {
                    continue;
                }
                let e = grid_error(surface, patch, kind, UvRect::UNIT, &t, stride, |_, _, _| {});
                bump(&mut out.by_rate, ((t.n - 1) / stride).to_string(), e);
                if stride == 1 {
                    bump(&mut out.by_tier, tier_name(tier).to_string(), e);
                }
            }
        }
    }
    let split_patches = spread(surface.patch_count(), options.split_patches);
    for depth in 1..=options.split_depth.min(mipray::tessellate::MAX_SPLIT_DEPTH) {
        for &patch in &split_patches {
            let kind = surface.patch_param(patch).kind;
            let bounds = surface.patch_bounds(patch);
            let cells = 1u32 << depth;
            for j in 0..cells {
                for i in 0..cells {
                    let rect = ChildCell { root: 0, depth: depth as u8, i, j }.rect(&UvRect::UNIT);
                    let sub = Subpatch { patch: patch as u32, rect, bounds, affine: false };
                    let (t, _) = tessellate(surface, &sub, Tier::Fine, None, &mut scratch);
                    let e = grid_error(surface, patch, kind, rect, &t, 1, |_, _, _| {});
                    bump(&mut out.after_split, depth.to_string(), e);
                }
            }
        }
    }
    out
}
