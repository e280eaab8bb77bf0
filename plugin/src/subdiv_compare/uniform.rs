//! OpenSubdiv's uniform refinement against our limit surface: how far the points of the mesh
//! refined uniformly to level k lie from the limit surface the renderer evaluates. Catmull-Clark
//! and Loop points converge to the limit as k grows (about 4× closer per level); bilinear points
//! lie on it at every level.
//!
//! The distance of a point is found by a nearest-triangle search over a medium (5×5) tessellation
//! of every patch, then Gauss–Newton steps on the patches of the nearest triangles, so it is the
//! distance to the limit surface itself, not to its tessellation.

use std::collections::HashMap;

use glam::Vec3A;
use mipray::error::MeshError;
use mipray::geometry_cache::Tier;
use mipray::patch::{GridSamples, LimitSurface, UvRect};
use mipray::subpatch::Subpatch;
use mipray::tessellate::tessellate;
use mipray_bridge::OsdSurface;
use serde::Serialize;

use super::spread;

/// Distances relative to the bounding-box diagonal.
#[derive(Clone, Debug, Serialize)]
pub struct UniformReport {
    pub level: u32,
    /// Refined faces (holes left out) and the points they use.
    pub faces: usize,
    pub points: usize,
    pub points_measured: usize,
    pub max_rel_distance: f64,
    pub rms_rel_distance: f64,
}

/// One triangle of the search tessellation: corners, and their patch (u, v).
struct Tri {
    p: [Vec3A; 3],
    uv: [(f32, f32); 3],
    patch: u32,
}

/// The closest point of triangle `p` to `x` as barycentric weights (Ericson, *Real-Time
/// Collision Detection*, §5.1.5); for a degenerate triangle, its nearest corner.
fn closest_barycentric(x: Vec3A, p: &[Vec3A; 3]) -> [f32; 3] {
    let w = closest_barycentric_raw(x, p);
    if w.iter().all(|c| c.is_finite()) {
        return w;
    }
    let d: [f32; 3] = p.map(|q| (q - x).length_squared());
    let k = if d[0] <= d[1] && d[0] <= d[2] {
        0
    } else if d[1] <= d[2] {
        1
    } else {
        2
    };
    let mut w = [0.0; 3];
    w[k] = 1.0;
    w
}

fn closest_barycentric_raw(x: Vec3A, p: &[Vec3A; 3]) -> [f32; 3] {
    let (a, b, c) = (p[0], p[1], p[2]);
    let (ab, ac, ap) = (b - a, c - a, x - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = x - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = x - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    if !(v.is_finite() && w.is_finite()) {
        return [1.0, 0.0, 0.0];
    }
    [1.0 - v - w, v, w]
}

/// A uniform grid of cells over triangles, for nearest-triangle queries.
struct TriGrid {
    tris: Vec<Tri>,
    cells: HashMap<(i64, i64, i64), Vec<u32>>,
    size: f32,
}

impl TriGrid {
    fn new(tris: Vec<Tri>) -> Self {
        let mean: f32 =
            tris.iter().map(|t| (t.p[1] - t.p[0]).length().max((t.p[2] - t.p[0]).length())).sum::<f32>() / tris.len().max(1) as f32;
        let size = if mean.is_finite() && mean > 0.0 { mean } else { 1.0 };
        let mut cells: HashMap<(i64, i64, i64), Vec<u32>> = HashMap::new();
        for (k, t) in tris.iter().enumerate() {
            let lo = t.p[0].min(t.p[1]).min(t.p[2]);
            let hi = t.p[0].max(t.p[1]).max(t.p[2]);
            let (a, b) = (Self::key(lo, size), Self::key(hi, size));
            for x in a.0..=b.0 {
                for y in a.1..=b.1 {
                    for z in a.2..=b.2 {
                        cells.entry((x, y, z)).or_default().push(k as u32);
                    }
                }
            }
        }
        TriGrid { tris, cells, size }
    }

    fn key(p: Vec3A, size: f32) -> (i64, i64, i64) {
        ((p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64)
    }

    /// Up to `k` nearest triangles' (distance, patch, u, v) at their closest points.
    fn nearest(&self, x: Vec3A, k: usize) -> Vec<(f32, u32, f32, f32)> {
        let c = Self::key(x, self.size);
        let mut found: Vec<(f32, u32, f32, f32)> = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for ring in 0i64..64 {
            for dx in -ring..=ring {
                for dy in -ring..=ring {
                    for dz in -ring..=ring {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                            continue;
                        }
                        let Some(list) = self.cells.get(&(c.0 + dx, c.1 + dy, c.2 + dz)) else { continue };
                        for &t in list {
                            if !seen.insert(t) {
                                continue;
                            }
                            let tri = &self.tris[t as usize];
                            let w = closest_barycentric(x, &tri.p);
                            let q = tri.p[0] * w[0] + tri.p[1] * w[1] + tri.p[2] * w[2];
                            let u = tri.uv[0].0 * w[0] + tri.uv[1].0 * w[1] + tri.uv[2].0 * w[2];
                            let v = tri.uv[0].1 * w[0] + tri.uv[1].1 * w[1] + tri.uv[2].1 * w[2];
                            found.push(((q - x).length(), tri.patch, u, v));
                        }
                    }
                }
            }
            found.sort_by(|a, b| a.0.total_cmp(&b.0));
            found.truncate(k);
            // Every unvisited triangle is at least `ring` cells away.
            if found.len() >= k.min(self.tris.len()) && found.last().is_some_and(|f| f.0 <= ring as f32 * self.size) {
                return found;
            }
        }
        // Far from everything (a refined point with no patch near it): look at every triangle.
        for (t, tri) in self.tris.iter().enumerate() {
            if seen.contains(&(t as u32)) {
                continue;
            }
            let w = closest_barycentric(x, &tri.p);
            let q = tri.p[0] * w[0] + tri.p[1] * w[1] + tri.p[2] * w[2];
            found.push((
                (q - x).length(),
                tri.patch,
                tri.uv[0].0 * w[0] + tri.uv[1].0 * w[1] + tri.uv[2].0 * w[2],
                tri.uv[0].1 * w[0] + tri.uv[1].1 * w[1] + tri.uv[2].1 * w[2],
            ));
        }
        found.sort_by(|a, b| a.0.total_cmp(&b.0));
        found.truncate(k);
        found
    }
}

/// Distance from `x` to the patch's limit surface near (u, v): Gauss–Newton steps, (u, v) kept in
/// the patch's domain.
fn refine(surface: &dyn LimitSurface, patch: usize, mut u: f32, mut v: f32, x: Vec3A) -> f32 {
    let tri = surface.patch_param(patch).kind.is_triangle();
    let mut best = f32::INFINITY;
    for _ in 0..8 {
        let s = surface.evaluate(patch, u, v);
        let r = x - s.p;
        best = best.min(r.length());
        let (a, b, c) = (s.dpdu.dot(s.dpdu), s.dpdu.dot(s.dpdv), s.dpdv.dot(s.dpdv));
        let det = a * c - b * b;
        if !(det.abs() > 1e-30) {
            break;
        }
        let (gu, gv) = (s.dpdu.dot(r), s.dpdv.dot(r));
        u = (u + (c * gu - b * gv) / det).clamp(0.0, 1.0);
        v = (v + (a * gv - b * gu) / det).clamp(0.0, 1.0);
        if tri && u + v > 1.0 {
            let k = 1.0 / (u + v);
            (u, v) = (u * k, v * k);
        }
    }
    best
}

/// Compares level `level` of OpenSubdiv's uniform refinement with `surface`'s limit surface, at
/// up to `max_points` points (0: all).
///
/// # Errors
/// OpenSubdiv's uniform refinement failed.
pub fn measure(surface: &OsdSurface, level: u32, max_points: usize, diag: f32) -> Result<UniformReport, MeshError> {
    let (points, faces) = surface.uniform_refinement(level)?;
    let mut used = vec![false; points.len()];
    for f in &faces {
        for &i in f {
            if let Some(u) = used.get_mut(i as usize) {
                *u = true;
            }
        }
    }
    let used: Vec<usize> = (0..points.len()).filter(|&i| used[i]).collect();
    let mut tris = Vec::new();
    let mut scratch = GridSamples::default();
    for patch in 0..surface.patch_count() {
        let pp = surface.patch_param(patch);
        let sub = Subpatch { patch: patch as u32, rect: UvRect::UNIT, bounds: surface.patch_bounds(patch), affine: false };
        let (t, _) = tessellate(surface, &sub, Tier::Medium, None, &mut scratch);
        let q = t.n - 1;
        let uv = |i: usize, j: usize| (i as f32 / q as f32, j as f32 / q as f32);
        for j in 0..q {
            for i in 0..q {
                for tri in [[(i, j), (i + 1, j), (i + 1, j + 1)], [(i, j), (i + 1, j + 1), (i, j + 1)]] {
                    let uvs = tri.map(|(a, b)| uv(a, b));
                    if pp.kind.is_triangle() && uvs.iter().all(|&(u, v)| u + v > 1.0 + 1e-6) {
                        continue;
                    }
                    tris.push(Tri { p: tri.map(|(a, b)| t.vert(a, b)), uv: uvs, patch: patch as u32 });
                }
            }
        }
    }
    let grid = TriGrid::new(tris);
    let measured = spread(used.len(), max_points);
    let (mut max_d, mut sum2) = (0.0f64, 0.0f64);
    for &k in &measured {
        let x = Vec3A::from(points[used[k]]);
        let mut d = f32::INFINITY;
        for (_, patch, u, v) in grid.nearest(x, 4) {
            d = d.min(refine(surface, patch as usize, u, v, x));
        }
        let d = f64::from(d);
        max_d = max_d.max(d);
        sum2 += d * d;
    }
    let n = measured.len().max(1) as f64;
    let dg = f64::from(diag);
    Ok(UniformReport {
        level,
        faces: faces.len(),
        points: used.len(),
        points_measured: measured.len(),
        max_rel_distance: max_d / dg,
        rms_rel_distance: (sum2 / n).sqrt() / dg,
    })
}
