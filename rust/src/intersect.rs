//! Ray–tessellation intersection: the watertight ray–triangle test of Woop, Benthin and Wald
//! (JCGT 2013), two triangles per quad, on a subpatch's grid at an effective rate; fine grids are
//! entered through their 4×4 sub-boxes (the paper's §5.2).
//!
//! Watertight means a ray through a shared edge or vertex hits at least one of the triangles
//! that share it, so rays never slip between quads of one grid. All of it runs in object space:
//! the ray is not renormalised, so t means the same thing as in render space.

use glam::{Vec3A, Vec4, Vec4Swizzles};

use crate::bounds::Bounds3;
use crate::tessellate::{GridDomain, Tessellation};

/// A ray prepared for slab tests against boxes: the part of [`WatertightRay`] a box test needs,
/// made alone where most rays test boxes and few go on to triangles (a ray entering an
/// instance's subpatch BVH; the watertight frame costs ~60 instructions more).
#[derive(Clone, Copy, Debug)]
pub struct BoxRay {
    pub o: Vec3A,
    inv_d: Vec3A,
}

impl BoxRay {
    #[inline]
    pub fn new(o: Vec3A, d: Vec3A) -> Self {
        BoxRay { o, inv_d: d.recip() }
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
}

/// A ray prepared for the watertight test: the axis permutation and shear of Woop et al.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    pub o: Vec3A,
    pub d: Vec3A,
    slab: BoxRay,
    /// `d` normalised (zero for a zero direction) and its length: for distances from the
    /// ray's line.
    d_unit: Vec3A,
    d_len: f32,
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
        WatertightRay {
            o,
            d,
            slab: BoxRay::new(o, d),
            d_unit: d.normalize_or_zero(),
            d_len: d.length(),
            kx,
            ky,
            kz,
            sx: d[kx] * sz,
            sy: d[ky] * sz,
            sz,
        }
    }

    /// Whether the ray, between `t_min` and `t_max`, may pass within `reach` of the segment
    /// [a, b]: false only when, computed with a margin for rounding, its line passes farther
    /// than `reach` from the segment, or the segment's points lie more than `reach` before
    /// `t_min` or beyond `t_max` along it. Object units. A cull for the thin boxes around grid
    /// chords, much tighter than their axis-aligned boxes when a chord runs diagonally.
    #[inline]
    pub fn may_pass_near_segment(&self, a: Vec3A, b: Vec3A, reach: f32, t_min: f32, t_max: f32) -> bool {
        let w = a - self.o;
        let u = b - a;
        // Each product below is within a few ulps of its operands' magnitudes, and d̂'s length
        // within 2ε of 1; a wrong s from rounding only raises the distance to second order.
        let margin = 32.0 * f32::EPSILON * (w.abs().max_element() + u.abs().max_element());
        // How far along the ray (length units) the segment's ends lie.
        let (ta, tb) = (w.dot(self.d_unit), (w + u).dot(self.d_unit));
        let len = self.d_len;
        if ta.max(tb) + reach + margin < t_min * len || ta.min(tb) - reach - margin > t_max * len {
            return false;
        }
        // |(a + s·u − o) × d̂| is the distance of the segment's point s from the line: |A + s·B|.
        let big_a = w.cross(self.d_unit);
        let big_b = u.cross(self.d_unit);
        let bb = big_b.length_squared();
        let s = if bb > 0.0 { (-big_a.dot(big_b) / bb).clamp(0.0, 1.0) } else { 0.0 };
        let dist = (big_a + big_b * s).length();
        // NaN (a degenerate ray or chord) is never culled.
        !(dist > reach + margin)
    }

    /// Slab test against a box ([`BoxRay::hit_box`]).
    #[inline]
    pub fn hit_box(&self, b: &Bounds3, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        self.slab.hit_box(b, t_min, t_max)
    }

    /// Watertight ray–triangle test. Returns (t, b0, b1, b2) with barycentrics of a, b, c.
    #[inline]
    pub fn hit_triangle(&self, a: Vec3A, b: Vec3A, c: Vec3A, t_max: f32) -> Option<(f32, f32, f32, f32)> {
        let (a, b, c) = (self.shear(a.as_ref()), self.shear(b.as_ref()), self.shear(c.as_ref()));
        self.finish_triangle(a, b, c, edge(c, b), edge(a, c), edge(b, a), t_max)
    }

    /// `p` in the ray's sheared frame: relative to the origin, permuted so the ray runs along
    /// z, sheared so it is the z axis, z scaled so the ray's t is z.
    #[inline]
    fn shear(&self, p: &[f32; 3]) -> Sheared {
        let o: &[f32; 3] = self.o.as_ref();
        let az = p[self.kz] - o[self.kz];
        Sheared { x: (p[self.kx] - o[self.kx]) - self.sx * az, y: (p[self.ky] - o[self.ky]) - self.sy * az, z: self.sz * az }
    }

    /// [`Self::shear`] of four points, one a lane: the same operations in each lane, so the
    /// same bits. Returns the sheared x, y and z.
    #[inline(always)]
    fn shear4(&self, p: [&[f32; 3]; 4]) -> (Vec4, Vec4, Vec4) {
        let o: &[f32; 3] = self.o.as_ref();
        let axis = |k: usize| Vec4::new(p[0][k], p[1][k], p[2][k], p[3][k]) - Vec4::splat(o[k]);
        let az = axis(self.kz);
        (axis(self.kx) - Vec4::splat(self.sx) * az, axis(self.ky) - Vec4::splat(self.sy) * az, Vec4::splat(self.sz) * az)
    }

    /// The rest of the watertight test for sheared `a`, `b`, `c` whose edge functions
    /// `u = edge(c, b)`, `v = edge(a, c)`, `w = edge(b, a)` the caller computed (a grid computes
    /// each of its edges' once and shares it, negated, with the neighbouring triangle: the same
    /// bits as computing it again, since `edge(q, p) = −edge(p, q)` exactly in IEEE arithmetic).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn finish_triangle(&self, a: Sheared, b: Sheared, c: Sheared, u: f32, v: f32, w: f32, t_max: f32) -> Option<(f32, f32, f32, f32)> {
        let (mut u, mut v, mut w) = (u, v, w);
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // Fall back to double precision on edges so shared edges are decided consistently.
            u = (c.x as f64 * b.y as f64 - c.y as f64 * b.x as f64) as f32;
            v = (a.x as f64 * c.y as f64 - a.y as f64 * c.x as f64) as f32;
            w = (b.x as f64 * a.y as f64 - b.y as f64 * a.x as f64) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t_scaled = u * a.z + v * b.z + w * c.z;
        // t = t_scaled / det must lie in (0, t_max]; compare without dividing, by the sign of det.
        if (det < 0.0 && (t_scaled >= 0.0 || t_scaled < t_max * det)) || (det > 0.0 && (t_scaled <= 0.0 || t_scaled > t_max * det)) {
            return None;
        }
        let inv = 1.0 / det;
        Some((t_scaled * inv, u * inv, v * inv, w * inv))
    }
}

/// A vertex in a ray's sheared frame (see [`WatertightRay::shear`]).
#[derive(Clone, Copy, Debug, Default)]
struct Sheared {
    x: f32,
    y: f32,
    z: f32,
}

/// The edge function of Woop et al. for the edge from `q` to `p`, as their test computes it.
#[inline]
fn edge(p: Sheared, q: Sheared) -> f32 {
    p.x * q.y - p.y * q.x
}

/// Where a ray hit a tessellation: distance, the subpatch-local (u, v) in [0, 1]², and the
/// geometric normal of the hit triangle (object space, unnormalised, from the winding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub ng: Vec3A,
    /// Found on a seam box (`seam.rs`), not a triangle: `ng` is then the boundary quad's, and
    /// the hit is where the ray leaves the box, not a crossing of the surface.
    pub seam: bool,
}

/// Most vertices a grid row has (a fine grid's 17).
const MAX_ROW: usize = 17;

/// Tests quads `[i0, i1) × [j0, j1)` (in stride units) of `tess` read with vertex `stride`.
///
/// Each vertex is sheared into the ray's frame once per call (not once per triangle that uses
/// it) and the diagonal's edge function is shared by a quad's two triangles: the arithmetic of
/// every triangle is what [`WatertightRay::hit_triangle`] does, so the hits are the same bits.
/// Four quads are tested at once ([`candidates`]) for the sign test that rejects nearly all of
/// them; the few that pass go on, one at a time, to the rest of the scalar test.
#[allow(clippy::too_many_arguments)]
fn hit_quads<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    range: (usize, usize, usize, usize),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let (i0, i1, j0, j1) = range;
    if i1 <= i0 || j1 <= j0 {
        return;
    }
    // Row buffers sized to the rows tested: most calls test a 1-quad coarse grid, a 2×2 (a
    // medium grid at stride 2) or a 4×4 sub-box, and filling two 17-vertex buffers for them was
    // over a third of the call's instructions (callgrind: docs/throughput-callgrind.md). Rows of
    // one or two quads are tested two rows at a time, so that a 2×2 fills the four lanes; a
    // lone quad has its own lane layout.
    if i1 - i0 == 1 && j1 - j0 == 1 {
        return hit_one_quad(ray, tess, stride, i0, j0, t_min, best, t_max, accept);
    }
    // Nearly all other calls read rows of five vertices: a medium grid (or a fine grid's
    // sub-box) as 4×4 quads at stride 1 or 2×2 at stride 2. Their rows are taken as
    // fixed-size arrays and kept in registers (the general path below indexes the grid per
    // lane and goes through row buffers on the stack).
    if (i1 - i0) * stride == 4 {
        match (stride, j1 - j0) {
            (1, _) => return hit_quads_span5(ray, tess, range, t_min, best, t_max, accept),
            (2, 2) => return hit_2x2_span5(ray, tess, range, t_min, best, t_max, accept),
            _ => {}
        }
    }
    match i1 - i0 + 1 {
        0..=3 => hit_quad_pairs(ray, tess, stride, range, t_min, best, t_max, accept),
        4..=5 => hit_quads_rows::<5, 8, A>(ray, tess, stride, range, t_min, best, t_max, accept),
        6..=9 => hit_quads_rows::<9, 12, A>(ray, tess, stride, range, t_min, best, t_max, accept),
        10..=MAX_ROW => hit_quads_rows::<MAX_ROW, 20, A>(ray, tess, stride, range, t_min, best, t_max, accept),
        _ => {
            // Wider than any tier's grid: test it in column strips.
            let mid = i0 + (MAX_ROW - 1);
            hit_quads(ray, tess, stride, (i0, mid, j0, j1), t_min, best, t_max, accept);
            hit_quads(ray, tess, stride, (mid, i1, j0, j1), t_min, best, t_max, accept);
        }
    }
}

/// A row of vertices in a ray's sheared frame, coordinates apart (so four quads' corners load
/// as the lanes of a [`Vec4`]); `P` holds the row and the lanes read past its last quad.
#[derive(Clone, Copy)]
struct ShearedRow<const P: usize> {
    x: [f32; P],
    y: [f32; P],
    z: [f32; P],
}

impl<const P: usize> ShearedRow<P> {
    const ZERO: Self = ShearedRow { x: [0.0; P], y: [0.0; P], z: [0.0; P] };

    /// Vertices `i0, i0 + 1, …` (`width` of them, stride units) of grid row `j`, four at a time
    /// (lanes past the row repeat its last vertex; `P` is a multiple of 4).
    #[inline(always)]
    fn fill(&mut self, ray: &WatertightRay, tess: &Tessellation, stride: usize, i0: usize, j: usize, width: usize) {
        let base = j * stride * tess.n + i0 * stride;
        let verts: &[[f32; 3]] = &tess.verts;
        let last = width - 1;
        for k in (0..width).step_by(4) {
            let at = |l: usize| &verts[base + (k + l).min(last) * stride];
            let (x, y, z) = ray.shear4([at(0), at(1), at(2), at(3)]);
            x.write_to_slice(&mut self.x[k..k + 4]);
            y.write_to_slice(&mut self.y[k..k + 4]);
            z.write_to_slice(&mut self.z[k..k + 4]);
        }
    }

    #[inline(always)]
    fn get(&self, k: usize) -> Sheared {
        Sheared { x: self.x[k], y: self.y[k], z: self.z[k] }
    }

    /// Vertices `k..k + 4` as lanes.
    #[inline(always)]
    fn lanes(&self, k: usize) -> Lanes {
        let four = |a: &[f32; P]| Vec4::from_array(a[k..k + 4].try_into().unwrap());
        Lanes { x: four(&self.x), y: four(&self.y) }
    }

    /// Vertices `k, k + 1` of this row and of `next` as lanes (two quads of two rows).
    #[inline(always)]
    fn lanes_with(&self, next: &Self, k: usize) -> Lanes {
        let two = |a: &[f32; P], b: &[f32; P]| Vec4::new(a[k], a[k + 1], b[k], b[k + 1]);
        Lanes { x: two(&self.x, &next.x), y: two(&self.y, &next.y) }
    }
}

/// Four sheared vertices' x and y, one a lane.
#[derive(Clone, Copy)]
struct Lanes {
    x: Vec4,
    y: Vec4,
}

/// [`edge`] in each lane: the same IEEE operations in the same order, so the same bits.
#[inline(always)]
fn edge4(p: Lanes, q: Lanes) -> Vec4 {
    p.x * q.y - p.y * q.x
}

/// The lanes (bits 0–3) where the triangle with edge functions `u`, `v`, `w` may be hit: those
/// [`WatertightRay::finish_triangle`] does not reject by the signs alone. An edge function of
/// exactly 0 (either sign) makes a lane a candidate, since the scalar test then recomputes all
/// three in double precision; elsewhere the signs must agree. A NaN edge function can never
/// make a hit (its t is NaN), so how its sign bit classifies it does not matter.
#[inline(always)]
fn sign_passes(u: Vec4, v: Vec4, w: Vec4) -> u32 {
    let zero = (u.cmpeq(Vec4::ZERO) | v.cmpeq(Vec4::ZERO) | w.cmpeq(Vec4::ZERO)).bitmask();
    let (nu, nv, nw) = (u.is_negative_bitmask(), v.is_negative_bitmask(), w.is_negative_bitmask());
    zero | (!((nu ^ nv) | (nu ^ nw)) & 0xf)
}

/// Which of four quads (corners as lanes) may be hit: bit `l` of the first mask for the
/// triangle (p00, p10, p11) of lane `l`, of the second for (p00, p11, p01), of the third for
/// the diagonal half (p00, p10, p01) of a triangle patch (computed only when `half`).
#[inline(always)]
fn candidates(s00: Lanes, s10: Lanes, s01: Lanes, s11: Lanes, half: bool) -> (u32, u32, u32) {
    let (bottom, left) = (edge4(s10, s00), edge4(s00, s01));
    let diagonal = edge4(s00, s11);
    let a = sign_passes(edge4(s11, s10), diagonal, bottom);
    let b = sign_passes(edge4(s01, s11), left, -diagonal);
    let d = if half { sign_passes(edge4(s01, s10), left, bottom) } else { 0 };
    (a, b, d)
}

/// The quads of the lanes `full` (both triangles) and `half` (a triangle patch's diagonal
/// half), masked to those [`candidates`] passes, through the scalar test in lane order, which
/// is the order of the quads: `corners(l)` gives lane `l`'s quad (i, j) and its sheared corners
/// s00, s10, s01, s11.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn finish_lanes<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    (full, half): (u32, u32),
    (s00, s10, s01, s11): (Lanes, Lanes, Lanes, Lanes),
    corners: impl Fn(usize) -> (usize, usize, [Sheared; 4]),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let (a, b, d) = candidates(s00, s10, s01, s11, half != 0);
    let (a, b, d) = (a & full, b & full, d & half);
    let mut lanes = a | b | d;
    while lanes != 0 {
        let l = lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        let (i, j, s) = corners(l);
        finish_quad(ray, tess, stride, i, j, s, (a >> l & 1 != 0, b >> l & 1 != 0, d >> l & 1 != 0), t_min, best, t_max, accept);
    }
}

/// The scalar test of quad (i, j)'s triangles that `tris` names: (p00, p10, p11),
/// (p00, p11, p01), and the diagonal half (p00, p10, p01), with sheared corners
/// `[s00, s10, s01, s11]`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn finish_quad<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    i: usize,
    j: usize,
    [s00, s10, s01, s11]: [Sheared; 4],
    tris: (bool, bool, bool),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let q = (tess.n - 1) / stride;
    let inv_q = 1.0 / q as f32;
    let n = tess.n;
    let verts: &[[f32; 3]] = &tess.verts;
    let corner = |di: usize, dj: usize| Vec3A::from(verts[(j + dj) * stride * n + (i + di) * stride]);
    if tris.2 {
        // On the diagonal: the half (p00, p10, p01), corners (0,0), (1,0), (0,1).
        if let Some((t, _b0, b1, b2)) = ray.finish_triangle(s00, s10, s01, edge(s01, s10), edge(s00, s01), edge(s10, s00), *t_max) {
            if t > t_min {
                let (p00, p10, p01) = (corner(0, 0), corner(1, 0), corner(0, 1));
                let ng = (p10 - p00).cross(p01 - p00);
                if accept(t, ng) {
                    *t_max = t;
                    *best = Some(GridHit { t, u: (i as f32 + b1) * inv_q, v: (j as f32 + b2) * inv_q, ng, seam: false });
                }
            }
        }
        return;
    }
    // Triangles (p00, p10, p11) and (p00, p11, p01): in (u, v) the corners are
    // (0,0), (1,0), (1,1) and (0,0), (1,1), (0,1). They share the diagonal's edge.
    let diagonal = edge(s00, s11);
    if tris.0 {
        if let Some((t, _b0, b1, b2)) = ray.finish_triangle(s00, s10, s11, edge(s11, s10), diagonal, edge(s10, s00), *t_max) {
            if t > t_min {
                let (lu, lv) = (b1 + b2, b2);
                let (p00, p10, p11) = (corner(0, 0), corner(1, 0), corner(1, 1));
                let ng = (p10 - p00).cross(p11 - p00);
                if accept(t, ng) {
                    *t_max = t;
                    *best = Some(GridHit { t, u: (i as f32 + lu) * inv_q, v: (j as f32 + lv) * inv_q, ng, seam: false });
                }
            }
        }
    }
    if tris.1 {
        if let Some((t, _b0, b1, b2)) = ray.finish_triangle(s00, s11, s01, edge(s01, s11), edge(s00, s01), -diagonal, *t_max) {
            if t > t_min {
                let (lu, lv) = (b1, b1 + b2);
                let (p00, p11, p01) = (corner(0, 0), corner(1, 1), corner(0, 1));
                let ng = (p11 - p00).cross(p01 - p00);
                if accept(t, ng) {
                    *t_max = t;
                    *best = Some(GridHit { t, u: (i as f32 + lu) * inv_q, v: (j as f32 + lv) * inv_q, ng, seam: false });
                }
            }
        }
    }
}

/// Lane masks (bits 0–3) of quads `(i + l, j)`, `l < count`, on a grid of `q` quads a side:
/// those wholly surface, and the one on a triangle patch's diagonal (beyond it the basis only
/// extrapolates, and such quads are in neither mask).
#[inline(always)]
fn row_masks(triangle: bool, q: usize, i: usize, j: usize, count: usize) -> (u32, u32) {
    let valid = (1u32 << count.min(4)) - 1;
    if !triangle {
        return (valid, 0);
    }
    // Quads with i + l + j + 1 < q are whole; the one with = q is the diagonal's.
    let whole = (q as isize - (i + j + 1) as isize).clamp(0, 4) as u32;
    let full = valid & ((1u32 << whole) - 1);
    let half = if whole < 4 && i + whole as usize + j < q { valid & (1 << whole) } else { 0 };
    (full, half)
}

/// [`hit_quads`] for rows of at most `W` vertices (`4 ≤ i1 − i0 + 1 ≤ W`, checked by the
/// caller), held in `P` floats (`W` rounded up to a multiple of 4): four quads of a row at a time.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn hit_quads_rows<const W: usize, const P: usize, A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    range: (usize, usize, usize, usize),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let q = (tess.n - 1) / stride;
    let (i0, i1, j0, j1) = range;
    let triangle = tess.domain == GridDomain::LowerTriangle;
    let width = i1 - i0 + 1;
    // A lane group starts at a multiple of 4 below the last quad (≤ W − 2) and reads 5
    // vertices, so W (5, 9 or 17) holds them; rows are filled four vertices at a time.
    debug_assert!((4..=W).contains(&width) && W % 4 == 1 && P % 4 == 0 && P >= W);
    // Rows j and j + 1 alternate between the two buffers (swapping them copied both).
    let mut rows = [ShearedRow::<P>::ZERO; 2];
    rows[0].fill(ray, tess, stride, i0, j0, width);
    for j in j0..j1 {
        let next = (j + 1 - j0) & 1;
        rows[next].fill(ray, tess, stride, i0, j + 1, width);
        let (lo, hi) = (&rows[next ^ 1], &rows[next]);
        for k in (0..width - 1).step_by(4) {
            let masks = row_masks(triangle, q, i0 + k, j, width - 1 - k);
            let lanes = (lo.lanes(k), lo.lanes(k + 1), hi.lanes(k), hi.lanes(k + 1));
            let corners = |l: usize| (i0 + k + l, j, [lo.get(k + l), lo.get(k + l + 1), hi.get(k + l), hi.get(k + l + 1)]);
            finish_lanes(ray, tess, stride, masks, lanes, corners, t_min, best, t_max, accept);
        }
    }
}

/// [`hit_quads`] for the one quad (i, j) (a coarse grid's: most calls): its corners sheared as
/// the four lanes of one vector, its four sides' edge functions as those of another.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn hit_one_quad<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    i: usize,
    j: usize,
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let q = (tess.n - 1) / stride;
    let triangle = tess.domain == GridDomain::LowerTriangle;
    if triangle && i + j + 1 > q {
        // Beyond a triangle patch's diagonal its basis only extrapolates.
        return;
    }
    let verts: &[[f32; 3]] = &tess.verts;
    let (x, y, z) = match <&[[f32; 3]; 4]>::try_from(verts) {
        // A coarse grid (the most calls): its four vertices are the quad's, no indexing.
        Ok(v) => ray.shear4([&v[0], &v[1], &v[2], &v[3]]),
        Err(_) => {
            let (row, base) = (stride * tess.n, (j * tess.n + i) * stride);
            ray.shear4([&verts[base], &verts[base + stride], &verts[base + row], &verts[base + row + stride]])
        }
    };
    let (xs, ys, zs) = (x.to_array(), y.to_array(), z.to_array());
    let corners = [0, 1, 2, 3].map(|k| Sheared { x: xs[k], y: ys[k], z: zs[k] });
    if triangle && i + j + 1 == q {
        // The diagonal half alone: rare (coarse grids of triangle patches), tested scalar.
        return finish_quad(ray, tess, stride, i, j, corners, (false, false, true), t_min, best, t_max, accept);
    }
    // Lanes (s11, s10, s01, s00) against (s10, s00, s11, s01): the sides edge(s11, s10),
    // edge(s10, s00), edge(s01, s11) and edge(s00, s01), each as `edge` computes it.
    let sides = edge4(Lanes { x: x.wyzx(), y: y.wyzx() }, Lanes { x: x.yxwz(), y: y.yxwz() });
    let (negative, zero) = (sides.is_negative_bitmask(), sides.cmpeq(Vec4::ZERO).bitmask());
    let diagonal = edge(corners[0], corners[3]);
    let (d_negative, d_zero) = (u32::from(diagonal.is_sign_negative()), diagonal == 0.0);
    // As `sign_passes`: (right, diagonal, bottom) and (top, left, −diagonal).
    let a = d_zero || zero & 0b0011 != 0 || (negative & 1 == d_negative && negative >> 1 & 1 == d_negative);
    let b = d_zero || zero & 0b1100 != 0 || (negative >> 2 & 1 != d_negative && negative >> 3 & 1 != d_negative);
    if a || b {
        finish_quad(ray, tess, stride, i, j, corners, (a, b, false), t_min, best, t_max, accept);
    }
}

/// [`hit_quads`] for rows of one or two quads (a medium grid or a fine grid's sub-box at stride
/// 2): two rows at a time, lanes (i0, j), (i0 + 1, j), (i0, j + 1), (i0 + 1, j + 1).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn hit_quad_pairs<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    range: (usize, usize, usize, usize),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let q = (tess.n - 1) / stride;
    let (i0, i1, j0, j1) = range;
    let triangle = tess.domain == GridDomain::LowerTriangle;
    let width = i1 - i0 + 1;
    debug_assert!((2..=3).contains(&width));
    // Four floats a row: the lanes read vertices 0..=2, and a row loads as one vector.
    let mut rows = [ShearedRow::<4>::ZERO; 3];
    rows[0].fill(ray, tess, stride, i0, j0, width);
    let mut j = j0;
    while j < j1 {
        let two = j + 1 < j1;
        rows[1].fill(ray, tess, stride, i0, j + 1, width);
        if two {
            rows[2].fill(ray, tess, stride, i0, j + 2, width);
        }
        let (full0, half0) = row_masks(triangle, q, i0, j, width - 1);
        let (full1, half1) = if two { row_masks(triangle, q, i0, j + 1, width - 1) } else { (0, 0) };
        let masks = (full0 | full1 << 2, half0 | half1 << 2);
        let [r0, r1, r2] = &rows;
        let lanes = (r0.lanes_with(r1, 0), r0.lanes_with(r1, 1), r1.lanes_with(r2, 0), r1.lanes_with(r2, 1));
        let corners = |l: usize| {
            let (c, r) = (l & 1, l >> 1);
            let (lo, hi) = (&rows[r], &rows[r + 1]);
            (i0 + c, j + r, [lo.get(c), lo.get(c + 1), hi.get(c), hi.get(c + 1)])
        };
        finish_lanes(ray, tess, stride, masks, lanes, corners, t_min, best, t_max, accept);
        rows[0] = rows[2];
        j += 2;
    }
}

/// Vertices `start..start + 5` of `tess` (a row of five), as an array: one bounds check for
/// the row instead of one per lane.
#[inline(always)]
fn row5(tess: &Tessellation, start: usize) -> &[[f32; 3]; 5] {
    tess.verts[start..].first_chunk::<5>().expect("a grid row of five vertices")
}

/// Five vertices of a row in the ray's sheared frame: the first four as lanes, the fifth apart.
#[derive(Clone, Copy)]
struct Sheared5 {
    x: Vec4,
    y: Vec4,
    z: Vec4,
    last: Sheared,
}

impl Sheared5 {
    /// `r` sheared: lanes by [`WatertightRay::shear4`], the fifth by [`WatertightRay::shear`]
    /// (the same operations, so the same bits as shearing each vertex alone).
    #[inline(always)]
    fn new(ray: &WatertightRay, r: &[[f32; 3]; 5]) -> Self {
        let (x, y, z) = ray.shear4([&r[0], &r[1], &r[2], &r[3]]);
        Sheared5 { x, y, z, last: ray.shear(&r[4]) }
    }

    /// Vertices 0–3 as lanes.
    #[inline(always)]
    fn lanes(&self) -> Lanes {
        Lanes { x: self.x, y: self.y }
    }

    /// Vertices 1–4 as lanes.
    #[inline(always)]
    fn lanes_shifted(&self) -> Lanes {
        let shift = |v: Vec4, e: f32| Vec4::new(v.y, v.z, v.w, e);
        Lanes { x: shift(self.x, self.last.x), y: shift(self.y, self.last.y) }
    }

    /// Vertex `k` (0–4). Only for the few quads the lanes pass: it goes through memory.
    #[inline(always)]
    fn get(&self, k: usize) -> Sheared {
        if k < 4 {
            Sheared { x: self.x[k], y: self.y[k], z: self.z[k] }
        } else {
            self.last
        }
    }
}

/// [`hit_quads`] at stride 1 on rows of five vertices (`i1 − i0 = 4`: a medium grid's 4×4
/// quads, a fine grid's sub-box): each row sheared once, as [`Sheared5`], the four quads of a
/// row pair tested as four lanes.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn hit_quads_span5<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    (i0, _, j0, j1): (usize, usize, usize, usize),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let n = tess.n;
    let q = n - 1;
    let triangle = tess.domain == GridDomain::LowerTriangle;
    let mut lo = Sheared5::new(ray, row5(tess, j0 * n + i0));
    for j in j0..j1 {
        let hi = Sheared5::new(ray, row5(tess, (j + 1) * n + i0));
        let masks = row_masks(triangle, q, i0, j, 4);
        let lanes = (lo.lanes(), lo.lanes_shifted(), hi.lanes(), hi.lanes_shifted());
        let corners = |l: usize| (i0 + l, j, [lo.get(l), lo.get(l + 1), hi.get(l), hi.get(l + 1)]);
        finish_lanes(ray, tess, 1, masks, lanes, corners, t_min, best, t_max, accept);
        lo = hi;
    }
}

/// [`hit_quads`] at stride 2 for 2×2 quads on rows of five vertices (a medium grid at rate 2,
/// a fine grid's sub-box at rate 8): the three rows' vertices 0, 2, 4 sheared as lanes (the
/// fourth repeats the third), the four quads as the lanes (i0, j0), (i0 + 1, j0), (i0, j0 + 1),
/// (i0 + 1, j0 + 1), as [`hit_quad_pairs`] orders them.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn hit_2x2_span5<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    (i0, _, j0, _): (usize, usize, usize, usize),
    t_min: f32,
    best: &mut Option<GridHit>,
    t_max: &mut f32,
    accept: &A,
) {
    let n = tess.n;
    let q = (n - 1) / 2;
    let triangle = tess.domain == GridDomain::LowerTriangle;
    let row = |j: usize| {
        let r = row5(tess, 2 * (j * n + i0));
        ray.shear4([&r[0], &r[2], &r[4], &r[4]])
    };
    let rows = [row(j0), row(j0 + 1), row(j0 + 2)];
    // Lanes k, k + 1 of row r and of row r + 1.
    let pair = |r: usize, k: usize| {
        let two = |a: Vec4, b: Vec4| if k == 0 { Vec4::new(a.x, a.y, b.x, b.y) } else { Vec4::new(a.y, a.z, b.y, b.z) };
        Lanes { x: two(rows[r].0, rows[r + 1].0), y: two(rows[r].1, rows[r + 1].1) }
    };
    let (full0, half0) = row_masks(triangle, q, i0, j0, 2);
    let (full1, half1) = row_masks(triangle, q, i0, j0 + 1, 2);
    let masks = (full0 | full1 << 2, half0 | half1 << 2);
    let lanes = (pair(0, 0), pair(0, 1), pair(1, 0), pair(1, 1));
    let corners = |l: usize| {
        let (c, r) = (l & 1, l >> 1);
        let at = |r: usize, k: usize| Sheared { x: rows[r].0[k], y: rows[r].1[k], z: rows[r].2[k] };
        (i0 + c, j0 + r, [at(r, c), at(r, c + 1), at(r + 1, c), at(r + 1, c + 1)])
    };
    finish_lanes(ray, tess, 2, masks, lanes, corners, t_min, best, t_max, accept);
}

/// Takes every hit: the `accept` of [`intersect_tessellation`] and the seam tests for callers
/// that pass none over.
#[inline(always)]
pub fn every_hit(_t: f32, _ng: Vec3A) -> bool {
    true
}

/// The closest hit of `ray` with `tess` read at vertex `stride` (1, or 2 for merged quads), in
/// (`t_min`, `t_max`), among those `accept(t, ng)` takes ([`every_hit`]: all; `ng` the hit
/// triangle's unnormalised normal). Fine grids are entered through their sub-boxes. The filter
/// runs inside the one pass: a caller passing hits over would otherwise search the grid again
/// from each (a ray leaving a displaced surface passed several of its own grids' hits).
pub fn intersect_tessellation<A: Fn(f32, Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    t_min: f32,
    t_max: f32,
    accept: &A,
) -> Option<GridHit> {
    if tess.domain == GridDomain::Empty {
        return None;
    }
    let mut best = None;
    let mut t_best = t_max;
    let sub_boxes = tess.boxes.sub_boxes();
    if sub_boxes.len() == 16 {
        // Each sub-box covers 4×4 quads at stride 1, i.e. (4 / stride)² quads at this stride.
        let per = 4 / stride;
        for (b, bb) in sub_boxes.iter().enumerate() {
            if ray.hit_box(bb, t_min, t_best).is_some() {
                let (bi, bj) = (b % 4 * per, b / 4 * per);
                hit_quads(ray, tess, stride, (bi, bi + per, bj, bj + per), t_min, &mut best, &mut t_best, accept);
            }
        }
    } else {
        let q = (tess.n - 1) / stride;
        hit_quads(ray, tess, stride, (0, q, 0, q), t_min, &mut best, &mut t_best, accept);
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
            boxes: Default::default(),
            chord_error: 0.0,
            seam_radius: 0.0,
            seam_normal: Default::default(),
            domain: GridDomain::Square,
        }
    }

    #[test]
    fn an_accepting_search_finds_what_searching_again_past_each_refused_hit_finds() {
        // A folded grid (a wave standing up out of its plane), crossed by rays that meet it
        // several times: refusing hits by distance and facing, one pass must give the hit that
        // the search-again loop the tracer used gives.
        let n = 17;
        let mut t = flat_grid(n);
        let verts: Vec<[f32; 3]> = t.verts.iter().map(|p| [p[0], p[1], 0.3 * (p[0] * 19.0).sin()]).collect();
        t.verts = verts.into();
        let mut seed = 3u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let (mut refused_some, mut found) = (0, 0);
        for r in 0..400 {
            let o = Vec3A::new(-0.2, next(), next() * 0.4 - 0.2);
            let d = Vec3A::new(1.0, next() * 0.2 - 0.1, next() * 0.1 - 0.05);
            let ray = WatertightRay::new(o, d);
            let window = next() * 0.8;
            let facing = if r % 2 == 0 { 1.0 } else { -1.0 };
            let accept = |t: f32, ng: Vec3A| !(t < window && facing * d.dot(ng) > 0.0);
            for stride in [1, 2] {
                let one_pass = intersect_tessellation(&ray, &t, stride, 0.0, f32::INFINITY, &accept);
                let mut t_from = 0.0;
                let again = loop {
                    match intersect_tessellation(&ray, &t, stride, t_from, f32::INFINITY, &every_hit) {
                        Some(h) if !accept(h.t, h.ng) => {
                            refused_some += 1;
                            t_from = crate::ray::next_up(h.t);
                        }
                        h => break h,
                    }
                };
                assert_eq!(one_pass, again, "ray {r}, stride {stride}");
                found += usize::from(one_pass.is_some());
            }
        }
        assert!(refused_some > 100 && found > 100, "{refused_some} refused, {found} found");
    }

    #[test]
    fn hit_maps_back_to_the_subpatch_uv() {
        let t = flat_grid(5);
        for &(x, y) in &[(0.1f32, 0.2f32), (0.9, 0.05), (0.5, 0.5), (0.33, 0.77)] {
            let r = WatertightRay::new(Vec3A::new(x, y, 1.0), Vec3A::NEG_Z);
            for stride in [1, 2] {
                let h = intersect_tessellation(&r, &t, stride, 0.0, f32::INFINITY, &every_hit).unwrap();
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
                let h = intersect_tessellation(&r, &t, 1, 0.0, f32::INFINITY, &every_hit);
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
                let h = intersect_tessellation(&r, &t, stride, 0.0, f32::INFINITY, &every_hit);
                assert_eq!(h.is_some(), inside, "({x}, {y}) at stride {stride}");
                if let Some(h) = h {
                    assert!((h.u - x).abs() < 1e-5 && (h.v - y).abs() < 1e-5 && h.ng.z > 0.0, "{h:?}");
                }
            }
        }
        t.domain = GridDomain::Empty;
        assert!(intersect_tessellation(
            &WatertightRay::new(Vec3A::new(0.1, 0.1, 1.0), Vec3A::NEG_Z),
            &t,
            1,
            0.0,
            f32::INFINITY,
            &every_hit
        )
        .is_none());
    }

    /// The grid test as it was before it shared sheared vertices and edges: every quad's two
    /// triangles through [`WatertightRay::hit_triangle`], vertex by vertex ([`per_triangle_in`]
    /// over the whole grid, every hit taken).
    fn per_triangle(ray: &WatertightRay, tess: &Tessellation, stride: usize, t_max: f32) -> Option<GridHit> {
        let q = (tess.n - 1) / stride;
        per_triangle_in(ray, tess, stride, (0, q, 0, q), 0.0, t_max, &every_hit, &mut 0)
    }

    #[test]
    fn the_grid_test_gives_the_same_bits_as_testing_each_triangle_alone() {
        // Bumpy grids of every tier's size, rays from everywhere, through vertices and edges too.
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rand = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut compared = 0;
        let mut hits = 0;
        for n in [2usize, 5, 17] {
            for domain in [GridDomain::Square, GridDomain::LowerTriangle] {
                let mut t = flat_grid(n);
                t.domain = domain;
                let bumps: Vec<[f32; 3]> = t.verts.iter().map(|p| [p[0], p[1], 0.2 * (rand() - 0.5)]).collect();
                t.verts = bumps.into();
                for _ in 0..400 {
                    // Aim at a grid vertex or edge midpoint half the time: the shared-edge cases.
                    let halves = (n - 1) as f32 * 2.0;
                    let (x, y, snap_x, snap_y) = (rand(), rand(), rand() < 0.5, rand() < 0.5);
                    let snap = |x: f32, on: bool| if on { (x * halves).round() / halves } else { x };
                    let target = Vec3A::new(snap(x, snap_x), snap(y, snap_y), 0.0);
                    let (ox, oy, oz, below) = (rand() * 4.0 - 2.0, rand() * 4.0 - 2.0, 0.5 + rand() * 2.0, rand() < 0.3);
                    let o = Vec3A::new(ox, oy, if below { -oz } else { oz });
                    let r = WatertightRay::new(o, target - o);
                    for stride in [1usize, 2].into_iter().filter(|s| (n - 1) % s == 0) {
                        let got = intersect_tessellation(&r, &t, stride, 0.0, f32::INFINITY, &every_hit);
                        let want = per_triangle(&r, &t, stride, f32::INFINITY);
                        assert_eq!(
                            got.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits())),
                            want.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits())),
                            "n {n} {domain:?} stride {stride} o {o} target {target}"
                        );
                        compared += 1;
                        hits += usize::from(got.is_some());
                    }
                }
            }
        }
        assert!(hits > compared / 3, "most rays should hit: {hits} of {compared}");
    }

    /// The closest accepted hit among quads `[i0, i1) × [j0, j1)` (stride units), triangle by
    /// triangle through [`WatertightRay::hit_triangle`] in the grid test's order (row by row,
    /// each quad's triangles in turn), each hit in (`t_min`, current best] offered to `accept`.
    /// Also counts the triangles whose single-precision edge functions include an exact 0 (the
    /// double-precision fallback).
    #[allow(clippy::too_many_arguments)]
    fn per_triangle_in(
        ray: &WatertightRay,
        tess: &Tessellation,
        stride: usize,
        (i0, i1, j0, j1): (usize, usize, usize, usize),
        t_min: f32,
        t_max: f32,
        accept: &dyn Fn(f32, Vec3A) -> bool,
        zero_edges: &mut usize,
    ) -> Option<GridHit> {
        let q = (tess.n - 1) / stride;
        let inv_q = 1.0 / q as f32;
        let (mut best, mut t_best) = (None, t_max);
        let triangle = tess.domain == GridDomain::LowerTriangle;
        for j in j0..j1 {
            for i in i0..i1 {
                if triangle && i + j + 1 > q {
                    continue;
                }
                let v = |di: usize, dj: usize| tess.vert((i + di) * stride, (j + dj) * stride);
                let (p00, p10, p11, p01) = (v(0, 0), v(1, 0), v(1, 1), v(0, 1));
                let tris = if triangle && i + j + 1 == q { vec![(p00, p10, p01, 2)] } else { vec![(p00, p10, p11, 0), (p00, p11, p01, 1)] };
                for (a, b, c, which) in tris {
                    let (sa, sb, sc) = (ray.shear(a.as_ref()), ray.shear(b.as_ref()), ray.shear(c.as_ref()));
                    if edge(sc, sb) == 0.0 || edge(sa, sc) == 0.0 || edge(sb, sa) == 0.0 {
                        *zero_edges += 1;
                    }
                    if let Some((t, _, b1, b2)) = ray.hit_triangle(a, b, c, t_best) {
                        let ng = (b - a).cross(c - a);
                        if t > t_min && accept(t, ng) {
                            t_best = t;
                            let (lu, lv) = match which {
                                0 => (b1 + b2, b2),
                                1 => (b1, b1 + b2),
                                _ => (b1, b2),
                            };
                            best = Some(GridHit { t, u: (i as f32 + lu) * inv_q, v: (j as f32 + lv) * inv_q, ng, seam: false });
                        }
                    }
                }
            }
        }
        best
    }

    #[test]
    fn quads_tested_four_at_once_give_the_same_bits_as_each_triangle_alone() {
        // Grids of every width the lane layouts take (1 or 2 quads a row in pairs of rows, 3–16
        // a row in fours), whole and in sub-ranges (a fine grid's sub-boxes), square and
        // triangle domains, bumpy and exactly flat (there rays through vertices and edges make
        // edge functions of exactly 0: the double-precision fallback), at scales where the
        // products underflow or overflow; rays aimed at vertices and edge midpoints, grazing
        // ones in the grid's plane, and accept filters that refuse hits by distance and facing,
        // so that a farther hit is taken instead.
        let mut seed = 0x853c_49e6_748f_ea9bu64;
        let mut rand = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut compared, mut hits, mut refused, mut zero_edges, mut rows_of_five) = (0, 0, 0, 0, 0);
        for case in 0..600 {
            let n = [2usize, 3, 5, 9, 17][case % 5];
            let mut t = flat_grid(n);
            t.domain = if case / 5 % 2 == 0 { GridDomain::Square } else { GridDomain::LowerTriangle };
            let flat = case / 10 % 3 == 0;
            let scale = [1.0f32, 1.0, 1.0, 1.0, 1e-21, 3e18][case / 30 % 6];
            let verts: Vec<[f32; 3]> = t
                .verts
                .iter()
                .map(|p| {
                    let z = if flat { 0.0 } else { 0.3 * (rand() - 0.5) };
                    [p[0] * scale, p[1] * scale, z * scale]
                })
                .collect();
            t.verts = verts.into();
            for _ in 0..40 {
                let halves = (n - 1) as f32 * 2.0;
                let snap = |x: f32, on: bool| if on { (x * halves).round() / halves } else { x };
                let (x, y, snap_x, snap_y) = (rand() * 1.2 - 0.1, rand() * 1.2 - 0.1, rand() < 0.6, rand() < 0.6);
                let target = Vec3A::new(snap(x, snap_x), snap(y, snap_y), 0.0) * scale;
                let kind = rand();
                let o = if kind < 0.15 {
                    // In the grid's plane: grazing, along or across its rows and columns.
                    let (dx, dy) = ([1.0f32, 0.0, 1.0, 1.0, -0.5][(rand() * 5.0) as usize % 5], rand() - 0.5);
                    target - Vec3A::new(dx, dy, 0.0) * 2.0 * scale
                } else if kind < 0.5 {
                    // Straight down through a vertex or edge: along the sheared frame's axis.
                    target + Vec3A::new(0.0, 0.0, 1.0 + rand()) * scale
                } else {
                    Vec3A::new(rand() * 4.0 - 2.0, rand() * 4.0 - 2.0, (0.5 + rand() * 2.0) * if rand() < 0.3 { -1.0 } else { 1.0 }) * scale
                };
                let d = target - o;
                let ray = WatertightRay::new(o, d);
                let window = rand() * 1.5;
                let facing = [1.0f32, -1.0, 0.0][(rand() * 3.0) as usize % 3];
                let accept = |t: f32, ng: Vec3A| !(t < window && facing * d.dot(ng) >= 0.0);
                let t_min = if rand() < 0.2 { rand() * 0.9 } else { 0.0 };
                let t_max = if rand() < 0.2 { 0.5 + rand() } else { f32::INFINITY };
                for stride in [1usize, 2].into_iter().filter(|s| (n - 1) % s == 0) {
                    let q = (n - 1) / stride;
                    // The whole grid, a random sub-range, and each 4×4 (stride units 4 / stride)
                    // block a fine grid's sub-boxes give.
                    let (a, b) = ((rand() * q as f32) as usize, (rand() * q as f32) as usize);
                    let (c, e) = ((rand() * q as f32) as usize, (rand() * q as f32) as usize);
                    let mut ranges = vec![(0, q, 0, q), (a.min(b), a.max(b) + 1, c.min(e), c.max(e) + 1)];
                    if n == 17 {
                        let per = 4 / stride;
                        ranges.extend((0..16).map(|k| (k % 4 * per, k % 4 * per + per, k / 4 * per, k / 4 * per + per)));
                    }
                    for range in ranges {
                        // Every hit offered to the filter, in order: the lanes must offer the
                        // same hits in the same order as the triangle-by-triangle walk.
                        let (offered_lanes, offered_walk) = (std::cell::RefCell::new(Vec::new()), std::cell::RefCell::new(Vec::new()));
                        let logged = |log: &std::cell::RefCell<Vec<(u32, [u32; 3])>>, t: f32, ng: Vec3A| {
                            log.borrow_mut().push((t.to_bits(), ng.to_array().map(f32::to_bits)));
                            accept(t, ng)
                        };
                        let mut got = None;
                        let mut t_got = t_max;
                        hit_quads(&ray, &t, stride, range, t_min, &mut got, &mut t_got, &|t, ng| logged(&offered_lanes, t, ng));
                        let refusing = std::cell::Cell::new(0);
                        let counting = |t: f32, ng: Vec3A| {
                            let ok = logged(&offered_walk, t, ng);
                            refusing.set(refusing.get() + usize::from(!ok));
                            ok
                        };
                        let want = per_triangle_in(&ray, &t, stride, range, t_min, t_max, &counting, &mut zero_edges);
                        assert_eq!(offered_lanes.take(), offered_walk.take(), "case {case} n {n} stride {stride} range {range:?}");
                        let (quads_i, quads_j) = (range.1 - range.0, range.3 - range.2);
                        if quads_i * stride == 4 && (stride == 1 || quads_j == 2) {
                            rows_of_five += 1;
                        }
                        let bits = |h: Option<GridHit>| {
                            h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.ng.to_array().map(f32::to_bits)))
                        };
                        assert_eq!(bits(got), bits(want), "case {case} n {n} stride {stride} range {range:?} o {o} d {d}");
                        assert_eq!(t_got.to_bits(), want.map_or(t_max, |h| h.t).to_bits());
                        compared += 1;
                        hits += usize::from(got.is_some());
                        refused += refusing.get();
                    }
                }
            }
        }
        // The cases the lanes must get right all occur, many times over.
        assert!(hits > compared / 10, "{hits} hits of {compared}");
        assert!(refused > 1000 && zero_edges > 1000, "{refused} refused hits, {zero_edges} triangles with a zero edge function");
        // The rows-of-five layouts (4×4 quads at stride 1, 2×2 at stride 2) are most of them.
        assert!(rows_of_five > compared / 3, "{rows_of_five} ranges with rows of five of {compared}");
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

    #[test]
    fn the_segment_cull_keeps_every_segment_the_ray_passes_within_reach_of() {
        // Against the distance measured by brute force: 4,097 points along the segment, each
        // point's exact distance from the line and position along it. The cull may keep more
        // than it must (its margin), never fewer.
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rand = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let v = |rand: &mut dyn FnMut() -> f32| Vec3A::new(rand() - 0.5, rand() - 0.5, rand() - 0.5);
        let (mut kept, mut culled) = (0, 0);
        for case in 0..4000 {
            let scale = [1.0f32, 1e-3, 1e3][case % 3];
            let (o, d) = (v(&mut rand) * 4.0 * scale, v(&mut rand) * [1.0f32, 0.01, 100.0][case / 3 % 3]);
            let (a, b) = (v(&mut rand) * scale, v(&mut rand) * scale);
            let (t_min, t_max) = if case % 2 == 0 { (0.0, f32::INFINITY) } else { (0.5, 1.0 + 4.0 * rand()) };
            let ray = WatertightRay::new(o, d);
            let (du, dl) = (d.as_dvec3().normalize(), d.as_dvec3().length());
            // The nearest point of the segment within the t range, by brute force (f64).
            let mut nearest = f64::INFINITY;
            for k in 0..=4096 {
                let p = (a + (b - a) * (k as f32 / 4096.0)).as_dvec3() - o.as_dvec3();
                let along = p.dot(du);
                let t = along / dl;
                // Beyond the range: how far from its nearer end, in length units.
                let off = if t < t_min as f64 {
                    (t_min as f64 - t) * dl
                } else if t > t_max as f64 {
                    (t - t_max as f64) * dl
                } else {
                    0.0
                };
                nearest = nearest.min((p - du * along).length().max(off));
            }
            let step = (b - a).length() as f64 / 4096.0;
            for reach in [nearest * 1.001 + step, nearest * 2.0 + step] {
                assert!(
                    ray.may_pass_near_segment(a, b, reach as f32, t_min, t_max),
                    "case {case}: culled a segment {nearest} away at reach {reach}"
                );
            }
            if ray.may_pass_near_segment(a, b, (nearest * 0.5) as f32, t_min, t_max) {
                kept += 1;
            } else {
                culled += 1;
            }
        }
        // The cull does cull: most segments beyond twice the reach are dropped.
        assert!(culled > 3 * kept, "culled {culled}, kept {kept} of those twice the reach away");
    }
}
