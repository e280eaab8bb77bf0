//! Ray–tessellation intersection: the watertight ray–triangle test of Woop, Benthin and Wald
//! (JCGT 2013), two triangles per quad, on a subpatch's grid at an effective rate; fine grids are
//! entered through their 4×4 sub-boxes (the paper's §5.2).
//!
//! Watertight means a ray through a shared edge or vertex hits at least one of the triangles
//! that share it, so rays never slip between quads of one grid. All of it runs in object space:
//! the ray is not renormalised, so t means the same thing as in render space.

use glam::Vec3A;

use crate::bounds::Bounds3;
use crate::tessellate::{GridDomain, Tessellation};

/// A ray prepared for the watertight test: the axis permutation and shear of Woop et al.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    pub o: Vec3A,
    pub d: Vec3A,
    inv_d: Vec3A,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl WatertightRay {
    pub fn new(o: Vec3A, d: Vec3A) -> Self {
        let a = d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z {
                0
            } else {
                2
            }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / d[kz];
        WatertightRay { o, d, inv_d: d.recip(), kx, ky, kz, sx: d[kx] * sz, sy: d[ky] * sz, sz }
    }

    /// Slab test against a box; returns the entry and exit distances clipped to [t_min, t_max].
    #[inline]
    pub fn hit_box(&self, b: &Bounds3, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        let t0 = (b.min - self.o) * self.inv_d;
        let t1 = (b.max - self.o) * self.inv_d;
        // A ray parallel to a slab and exactly in its plane makes 0·∞ = NaN there. SIMD min and
        // max do not prefer the number (they return the second operand), so the NaN would pick
        // an arbitrary side: a ray along an edge two boxes share (a camera centred on it) then
        // missed both. The closed slab holds the ray for all t.
        let t0 = Vec3A::select(t0.is_nan_mask(), Vec3A::NEG_INFINITY, t0);
        let t1 = Vec3A::select(t1.is_nan_mask(), Vec3A::INFINITY, t1);
        let near = t0.min(t1).max_element().max(t_min);
        // Robust slab exit: scale by 1 + 2γ(3) so grazing hits at box faces are kept (Ize 2013).
        let far = t0.max(t1).min_element() * (1.0 + 2.0 * crate::ray::gamma(3));
        let far = far.min(t_max);
        (near <= far).then_some((near, far))
    }

    /// Watertight ray–triangle test. Returns (t, b0, b1, b2) with barycentrics of a, b, c.
    #[inline]
    pub fn hit_triangle(&self, a: Vec3A, b: Vec3A, c: Vec3A, t_max: f32) -> Option<(f32, f32, f32, f32)> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = a - self.o;
        let b = b - self.o;
        let c = c - self.o;
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // Fall back to double precision on edges so shared edges are decided consistently.
            u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
            v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
            w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        // t = t_scaled / det must lie in (0, t_max]; compare without dividing, by the sign of det.
        if (det < 0.0 && (t_scaled >= 0.0 || t_scaled < t_max * det)) || (det > 0.0 && (t_scaled <= 0.0 || t_scaled > t_max * det)) {
            return None;
        }
        let inv = 1.0 / det;
        Some((t_scaled * inv, u * inv, v * inv, w * inv))
    }
}

/// Where a ray hit a tessellation: distance, the subpatch-local (u, v) in [0, 1]², and the
/// geometric normal of the hit triangle (object space, unnormalised, from the winding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub ng: Vec3A,
}

/// Tests quads `[i0, i1) × [j0, j1)` (in stride units) of `tess` read with vertex `stride`.
fn hit_quads(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    range: (usize, usize, usize, usize),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
) {
    let q = (tess.n - 1) / stride;
    let inv_q = 1.0 / q as f32;
    let (i0, i1, j0, j1) = range;
    let triangle = tess.domain == GridDomain::LowerTriangle;
    for j in j0..j1 {
        for i in i0..i1 {
            if triangle && i + j + 1 > q {
                // Beyond a triangle patch's diagonal its basis only extrapolates.
                continue;
            }
            let p00 = tess.vert(i * stride, j * stride);
            let p10 = tess.vert((i + 1) * stride, j * stride);
            let p11 = tess.vert((i + 1) * stride, (j + 1) * stride);
            let p01 = tess.vert(i * stride, (j + 1) * stride);
            if triangle && i + j + 1 == q {
                // On the diagonal: the half (p00, p10, p01), corners (0,0), (1,0), (0,1).
                if let Some((t, _b0, b1, b2)) = ray.hit_triangle(p00, p10, p01, *t_max) {
                    if t > t_min {
                        *t_max = t;
                        *best =
                            Some(GridHit { t, u: (i as f32 + b1) * inv_q, v: (j as f32 + b2) * inv_q, ng: (p10 - p00).cross(p01 - p00) });
                    }
                }
                continue;
            }
            // Triangles (p00, p10, p11) and (p00, p11, p01): in (u, v) the corners are
            // (0,0), (1,0), (1,1) and (0,0), (1,1), (0,1).
            if let Some((t, _b0, b1, b2)) = ray.hit_triangle(p00, p10, p11, *t_max) {
                if t > t_min {
                    *t_max = t;
                    let (lu, lv) = (b1 + b2, b2);
                    *best = Some(GridHit { t, u: (i as f32 + lu) * inv_q, v: (j as f32 + lv) * inv_q, ng: (p10 - p00).cross(p11 - p00) });
                }
            }
            if let Some((t, _b0, b1, b2)) = ray.hit_triangle(p00, p11, p01, *t_max) {
                if t > t_min {
                    *t_max = t;
                    let (lu, lv) = (b1, b1 + b2);
                    *best = Some(GridHit { t, u: (i as f32 + lu) * inv_q, v: (j as f32 + lv) * inv_q, ng: (p11 - p00).cross(p01 - p00) });
                }
            }
        }
    }
}

/// The closest hit of `ray` with `tess` read at vertex `stride` (1, or 2 for merged quads), in
/// (`t_min`, `t_max`). Fine grids are entered through their sub-boxes.
pub fn intersect_tessellation(ray: &WatertightRay, tess: &Tessellation, stride: usize, t_min: f32, t_max: f32) -> Option<GridHit> {
    if tess.domain == GridDomain::Empty {
        return None;
    }
    let mut best = None;
    let mut t_best = t_max;
    if tess.sub_boxes.len() == 16 {
        // Each sub-box covers 4×4 quads at stride 1, i.e. (4 / stride)² quads at this stride.
        let per = 4 / stride;
        for (b, bb) in tess.sub_boxes.iter().enumerate() {
            if ray.hit_box(bb, t_min, t_best).is_some() {
                let (bi, bj) = (b % 4 * per, b / 4 * per);
                hit_quads(ray, tess, stride, (bi, bi + per, bj, bj + per), t_min, &mut best, &mut t_best);
            }
        }
    } else {
        let q = (tess.n - 1) / stride;
        hit_quads(ray, tess, stride, (0, q, 0, q), t_min, &mut best, &mut t_best);
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_grid(n: usize) -> Tessellation {
        let mut verts = Vec::new();
        for j in 0..n {
            for i in 0..n {
                verts.push([i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32, 0.0]);
            }
        }
        Tessellation {
            n,
            verts: verts.into(),
            sub_boxes: Default::default(),
            chord_error: 0.0,
            seam_radius: 0.0,
            seam_normal: Default::default(),
            domain: GridDomain::Square,
        }
    }

    #[test]
    fn hit_maps_back_to_the_subpatch_uv() {
        let t = flat_grid(5);
        for &(x, y) in &[(0.1f32, 0.2f32), (0.9, 0.05), (0.5, 0.5), (0.33, 0.77)] {
            let r = WatertightRay::new(Vec3A::new(x, y, 1.0), Vec3A::NEG_Z);
            for stride in [1, 2] {
                let h = intersect_tessellation(&r, &t, stride, 0.0, f32::INFINITY).unwrap();
                assert!((h.t - 1.0).abs() < 1e-6 && (h.u - x).abs() < 1e-5 && (h.v - y).abs() < 1e-5, "{h:?}");
                assert!(h.ng.z > 0.0, "counter-clockwise grid faces +z");
            }
        }
    }

    #[test]
    fn rays_through_shared_edges_and_vertices_never_slip_through() {
        let t = flat_grid(5);
        // Every grid line and every vertex of a 4×4 grid, from a slanted direction.
        for j in 0..=8 {
            for i in 0..=8 {
                let (x, y) = (i as f32 / 8.0, j as f32 / 8.0);
                let d = Vec3A::new(0.3, -0.2, -1.0);
                let r = WatertightRay::new(Vec3A::new(x, y, 0.0) - d * 2.0, d);
                let h = intersect_tessellation(&r, &t, 1, 0.0, f32::INFINITY);
                let inside = (0.0..=1.0).contains(&x) && (0.0..=1.0).contains(&y);
                assert_eq!(h.is_some(), inside, "({x}, {y})");
            }
        }
    }

    #[test]
    fn triangle_domains_are_hit_below_their_diagonal_only() {
        let mut t = flat_grid(5);
        t.domain = GridDomain::LowerTriangle;
        for &(x, y, inside) in
            &[(0.1f32, 0.2f32, true), (0.45, 0.45, true), (0.2, 0.77, true), (0.55, 0.5, false), (0.9, 0.9, false), (0.3, 0.74, false)]
        {
            for stride in [1, 2] {
                let r = WatertightRay::new(Vec3A::new(x, y, 1.0), Vec3A::NEG_Z);
                let h = intersect_tessellation(&r, &t, stride, 0.0, f32::INFINITY);
                assert_eq!(h.is_some(), inside, "({x}, {y}) at stride {stride}");
                if let Some(h) = h {
                    assert!((h.u - x).abs() < 1e-5 && (h.v - y).abs() < 1e-5 && h.ng.z > 0.0, "{h:?}");
                }
            }
        }
        t.domain = GridDomain::Empty;
        assert!(intersect_tessellation(&WatertightRay::new(Vec3A::new(0.1, 0.1, 1.0), Vec3A::NEG_Z), &t, 1, 0.0, f32::INFINITY).is_none());
    }

    #[test]
    fn box_test_keeps_grazing_hits_and_rejects_misses() {
        let b = Bounds3 { min: Vec3A::ZERO, max: Vec3A::ONE };
        let r = WatertightRay::new(Vec3A::new(-1.0, 0.5, 0.5), Vec3A::X);
        assert_eq!(r.hit_box(&b, 0.0, 10.0), Some((1.0, 2.0 * (1.0 + 2.0 * crate::ray::gamma(3)))));
        let grazing = WatertightRay::new(Vec3A::new(-1.0, 1.0, 0.5), Vec3A::X);
        assert!(grazing.hit_box(&b, 0.0, 10.0).is_some());
        let miss = WatertightRay::new(Vec3A::new(-1.0, 1.5, 0.5), Vec3A::X);
        assert!(miss.hit_box(&b, 0.0, 10.0).is_none());
    }

    #[test]
    fn a_ray_in_a_face_plane_of_a_box_hits_it_on_either_side() {
        // Parallel to the box's min and max planes of every axis and lying in one: 0·∞ = NaN in
        // that slab, which must count as inside (two boxes sharing the plane both hold the ray).
        let b = Bounds3 { min: Vec3A::ZERO, max: Vec3A::ONE };
        for axis in 0..3 {
            for plane in [0.0, 1.0] {
                for d in [Vec3A::X, Vec3A::Y, Vec3A::Z, -Vec3A::X, -Vec3A::Y, -Vec3A::Z] {
                    if d[axis] != 0.0 {
                        continue;
                    }
                    let mut o = Vec3A::splat(0.5) - d * 2.0;
                    o[axis] = plane;
                    let r = WatertightRay::new(o, d + Vec3A::ZERO);
                    assert!(r.hit_box(&b, 0.0, 10.0).is_some(), "axis {axis} plane {plane} d {d}");
                }
            }
        }
    }
}
