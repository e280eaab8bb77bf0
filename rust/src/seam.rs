//! Seams between subpatches tessellated at different rates: closing the cracks of the paper's
//! §7.1 ("geometric inconsistency ... cracks in the geometry due to T-vertices").
//!
//! Each ray chooses a rate per subpatch, so two neighbours can be tested at different rates by
//! the same ray: the shared edge is then a polyline of r₁ chords on one side and r₂ on the
//! other, and rays slip through the sliver between them. Adaptive patches of different sizes
//! and split children make the same T-junctions even at equal rates.
//!
//! The fix here needs no adjacency and keeps every tessellation a function of (subpatch, tier)
//! alone, so the cache modes still give identical pixels. Each boundary chord of a grid (at the
//! stride the ray reads it) carries a **seam box**: a box around the chord, oriented along it,
//! whose half-width `R` covers how far the limit surface's edge curve strays from that chord
//! ([`Tessellation::seam_radius`], measured when tessellating) plus a floating-point margin.
//! Both neighbours' boxes contain the same edge curve, so in every cross-section of the edge the
//! two boxes' outlines enclose a common point, and with the two tessellated sides they form a
//! connected curve from one side to the other: no ray crosses the surface between them. A ray
//! that passes through a seam box without hitting any grid triangle inside it hits the box
//! where it leaves it (so grid hits inside the box always win); a ray that starts inside a box
//! ignores it (rays leaving a surface near a seam do not hit their own seam).
//!
//! What it costs: three point evaluations per boundary chord when tessellating (12 for a coarse
//! grid, 48 medium, 192 fine), one float per cache entry, and a few slab tests for rays that pass
//! within `R` of a subpatch's edge. What it changes: near seams a ray may stop up to about `R`
//! (the tessellation's own chord error at that rate, below the ray's beam width) before the
//! tessellated surface; flat patches have `R` at the rounding level only.

use glam::Vec3A;

use crate::intersect::{intersect_tessellation, GridHit, WatertightRay};
use crate::patch::{LimitSurface, UvRect};
use crate::tessellate::{GridDomain, Tessellation};

/// Probes per boundary chord, at t = ¼, ½, ¾ of it: three catch S-shaped chords (an edge curve
/// with an inflection in the chord's middle crosses it there).
pub const SEAM_PROBES: usize = 3;

/// The largest deviation of an edge curve from its chord is taken as this many times the
/// largest deviation at the probes (the maximum of a smooth arc lies within a quarter chord of a
/// probe, where it exceeds the probe's by a small fraction).
pub const SEAM_SAFETY: f32 = 1.25;

/// The floating-point margin of a seam box, relative to the largest coordinate of its grid: two
/// patches evaluating the same edge point agree to within 2.8ε of the coordinates' magnitude
/// (the largest over OpenSubdiv's regression corpus, `loop_tetrahedron`: see
/// `mipray-subdiv-compare`'s `max_edge_mismatch_over_margin`); this is about twice that. It is
/// also how far seams can thicken a silhouette: nothing near the origin, a few ulps of the
/// position far from it.
pub const SEAM_MARGIN_REL: f32 = 6.0 * f32::EPSILON;

/// Square grid edges, in the order of [`SeamEdges`]' bits: v = 0, u = 1, v = 1, u = 0.
pub const EDGE_COUNT: usize = 4;

/// The diagonal u + v = 1 of a triangle patch's grid, from (1, 0) to (0, 1): edge index 4.
pub const DIAGONAL: usize = 4;

/// Which edges of a grid lie on its root subpatch's boundary (bit e for edge e: 0 is v = 0,
/// 1 is u = 1, 2 is v = 1, 3 is u = 0, 4 the diagonal of a triangle patch). Interior edges of
/// split children are shared with siblings evaluated on the same patch at the same (u, v), so
/// they need no seam.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SeamEdges(pub u8);

impl SeamEdges {
    pub const ALL: SeamEdges = SeamEdges(0b1111);
    pub const NONE: SeamEdges = SeamEdges(0);

    /// The root-boundary edges of split child (i, j) of a 2^depth × 2^depth split.
    pub fn of_child(depth: u8, i: u32, j: u32) -> SeamEdges {
        let last = (1u32 << depth) - 1;
        SeamEdges(u8::from(j == 0) | u8::from(i == last) << 1 | u8::from(j == last) << 2 | u8::from(i == 0) << 3)
    }

    pub fn contains(self, edge: usize) -> bool {
        self.0 >> edge & 1 == 1
    }

    /// The edges that bound the surface of a grid with `domain`: a triangle's are v = 0, u = 0
    /// and its diagonal (u = 1 and v = 1 only touch it at a corner).
    pub fn within(self, domain: GridDomain) -> SeamEdges {
        match domain {
            GridDomain::Square => self,
            GridDomain::LowerTriangle => SeamEdges((self.0 & 0b1001) | 1 << DIAGONAL),
            GridDomain::Empty => SeamEdges::NONE,
        }
    }
}

/// Grid index (i, j) of vertex `k` along edge `e` of an n×n grid, edges running with u (edges 0
/// and 2), with v (edges 1 and 3), or from (1, 0) to (0, 1) ([`DIAGONAL`]).
#[inline]
pub fn edge_vertex(e: usize, k: usize, n: usize) -> (usize, usize) {
    match e {
        0 => (k, 0),
        1 => (n - 1, k),
        2 => (k, n - 1),
        3 => (0, k),
        _ => (n - 1 - k, k),
    }
}

/// The grid-local (u, v) in [0, 1]² of the point at parameter `t` ∈ [0, 1] along edge `e`.
#[inline]
pub fn edge_uv(e: usize, t: f32) -> (f32, f32) {
    match e {
        0 => (t, 0.0),
        1 => (1.0, t),
        2 => (t, 1.0),
        3 => (0.0, t),
        _ => (1.0 - t, t),
    }
}

/// Distance from `p` to the segment [a, b] (object units).
#[inline]
pub fn point_segment_distance(p: Vec3A, a: Vec3A, b: Vec3A) -> f32 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 { ((p - a).dot(ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p - (a + ab * t)).length()
}

/// The floating-point margin for a grid whose largest coordinate magnitude is `max_abs`.
#[inline]
pub fn seam_margin(max_abs: f32) -> f32 {
    SEAM_MARGIN_REL * max_abs
}

/// The seam radius of an n×n grid `verts` (undisplaced, u fastest) over `rect` of `patch`:
/// [`SEAM_SAFETY`] times the largest distance between the limit surface at [`SEAM_PROBES`]
/// points inside a boundary chord (at stride 1) and that chord, plus [`seam_margin`]. Object
/// units. Non-finite distances (a degenerate patch) are left out.
pub fn seam_radius(surface: &dyn LimitSurface, patch: usize, rect: UvRect, verts: &[[f32; 3]], n: usize) -> f32 {
    if n < 2 || verts.len() < n * n {
        return 0.0;
    }
    let at = |i: usize, j: usize| Vec3A::from(verts[j * n + i]);
    let max_abs = verts.iter().fold(0.0f32, |m, v| m.max(v[0].abs()).max(v[1].abs()).max(v[2].abs()));
    let q = (n - 1) as f32;
    let mut dev: f32 = 0.0;
    let edges = SeamEdges::ALL.within(GridDomain::of(surface.patch_param(patch).kind, &rect));
    for e in (0..=DIAGONAL).filter(|&e| edges.contains(e)) {
        for k in 0..n - 1 {
            let (ia, ja) = edge_vertex(e, k, n);
            let (ib, jb) = edge_vertex(e, k + 1, n);
            for probe in 1..=SEAM_PROBES {
                let t = (k as f32 + probe as f32 / (SEAM_PROBES + 1) as f32) / q;
                let (lu, lv) = edge_uv(e, t);
                let u = rect.u0 + (rect.u1 - rect.u0) * lu;
                let v = rect.v0 + (rect.v1 - rect.v0) * lv;
                let c = surface.evaluate(patch, u, v).p;
                let d = point_segment_distance(c, at(ia, ja), at(ib, jb));
                if d.is_finite() {
                    dev = dev.max(d);
                }
            }
        }
    }
    SEAM_SAFETY * dev + seam_margin(max_abs)
}

/// A seam box: around the chord from `a` to `b`, `r` on every side (an oriented box, length
/// |b − a| + 2r, cross-section 2r × 2r).
#[derive(Clone, Copy, Debug)]
struct SeamBox {
    a: Vec3A,
    axis: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
    len: f32,
    r: f32,
}

impl SeamBox {
    fn new(a: Vec3A, b: Vec3A, r: f32) -> Option<SeamBox> {
        let ab = b - a;
        let len = ab.length();
        if !(len > 0.0 && len.is_finite() && r.is_finite()) {
            return None;
        }
        let axis = ab / len;
        let (e1, e2) = axis.any_orthonormal_pair();
        Some(SeamBox { a, axis, e1, e2, len, r })
    }

    /// The ray's entry and exit distances, or `None` when it misses. `grow` enlarges the box.
    #[inline]
    fn slabs(&self, o: Vec3A, d: Vec3A, grow: f32) -> Option<(f32, f32)> {
        let rel = o - self.a;
        let (r, len) = (self.r + grow, self.len);
        let mut near = f32::NEG_INFINITY;
        let mut far = f32::INFINITY;
        for (axis, lo, hi) in [(self.axis, -r, len + r), (self.e1, -r, r), (self.e2, -r, r)] {
            let (oc, dc) = (rel.dot(axis), d.dot(axis));
            if dc == 0.0 {
                if oc < lo || oc > hi {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / dc;
            let (t0, t1) = ((lo - oc) * inv, (hi - oc) * inv);
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
        (near <= far).then_some((near, far))
    }

    /// Whether `p` lies inside the box grown by `grow`.
    #[inline]
    fn contains(&self, p: Vec3A, grow: f32) -> bool {
        let rel = p - self.a;
        let r = self.r + grow;
        let x = rel.dot(self.axis);
        x >= -r && x <= self.len + r && rel.dot(self.e1).abs() <= r && rel.dot(self.e2).abs() <= r
    }
}

/// The closest seam-box hit of `ray` on the `edges` of `tess` read at vertex `stride`, in
/// (`t_min`, `t_max`): where the ray leaves the first box it passes through from outside. The
/// hit's (u, v) is the nearest point of the chord, in the grid's [0, 1]²; its normal is the
/// boundary quad's (the winding of [`crate::intersect`]'s triangles).
pub fn intersect_seams(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    edges: SeamEdges,
    t_min: f32,
    t_max: f32,
) -> Option<GridHit> {
    let n = tess.n;
    if n < 2 || stride == 0 || (n - 1) % stride != 0 || edges == SeamEdges::NONE {
        return None;
    }
    let q = (n - 1) / stride;
    // Grids are at most 17×17 (16 chords a side): the radii fit a fixed array.
    if q > 16 {
        return None;
    }
    let edges = edges.within(tess.domain);
    let base = tess.seam_radius;
    if !(base >= 0.0 && base.is_finite()) {
        return None;
    }
    let mut best: Option<GridHit> = None;
    let mut t_best = t_max;
    for e in (0..=DIAGONAL).filter(|&e| edges.contains(e)) {
        let vert = |k: usize| {
            let (i, j) = edge_vertex(e, k, n);
            tess.vert(i, j)
        };
        // Radius per chord: the stride-1 radius, plus how far the skipped vertex (merged
        // rates) lies from the longer chord.
        let mut radius = [0.0f32; 16];
        let mut edge_box = crate::bounds::Bounds3::EMPTY;
        for (k, r) in radius.iter_mut().enumerate().take(q) {
            let (a, b) = (vert(k * stride), vert((k + 1) * stride));
            let mut extra: f32 = 0.0;
            for m in 1..stride {
                extra = extra.max(point_segment_distance(vert(k * stride + m), a, b));
            }
            *r = base + extra;
            edge_box.grow(a);
            edge_box.grow(b);
        }
        let r_max = radius.iter().take(q).fold(0.0f32, |m, &r| m.max(r));
        // √3·r bounds how far a box reaches from its chord in any axis direction.
        if ray.hit_box(&edge_box.expanded(1.8 * r_max), t_min, t_best).is_none() {
            continue;
        }
        for (k, &r) in radius.iter().enumerate().take(q) {
            let Some(sb) = SeamBox::new(vert(k * stride), vert((k + 1) * stride), r) else { continue };
            // A ray that starts in (or on) the box leaves a surface near this seam: skip it.
            let start_grow = 1e-3 * r + seam_margin(ray.o.abs().max_element());
            if sb.contains(ray.o, start_grow) {
                continue;
            }
            let Some((near, far)) = sb.slabs(ray.o, ray.d, 0.0) else { continue };
            if !(near > t_min && far < t_best && far > near) {
                continue;
            }
            let p = ray.o + ray.d * far;
            let lambda = ((p - sb.a).dot(sb.axis) / sb.len).clamp(0.0, 1.0);
            let (u, v) = edge_uv(e, (k as f32 + lambda) / q as f32);
            // The boundary quad at this chord, as intersect's hit_quads winds it (on the
            // diagonal, its lower-left half).
            let (qi, qj) = match e {
                0 => (k, 0),
                1 => (q - 1, k),
                2 => (k, q - 1),
                3 => (0, k),
                _ => (q - 1 - k, k),
            };
            let p00 = tess.vert(qi * stride, qj * stride);
            let p10 = tess.vert((qi + 1) * stride, qj * stride);
            let far_corner =
                if e == DIAGONAL { tess.vert(qi * stride, (qj + 1) * stride) } else { tess.vert((qi + 1) * stride, (qj + 1) * stride) };
            t_best = far;
            best = Some(GridHit { t: far, u, v, ng: (p10 - p00).cross(far_corner - p00) });
        }
    }
    best
}

/// The closest hit of `ray` with the grid `tess` read at `stride` and with the seam boxes of
/// its `edges` ([`SeamEdges::NONE`]: the grid alone, as without seams), in (`t_min`, `t_max`).
pub fn intersect_with_seams(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    edges: SeamEdges,
    t_min: f32,
    t_max: f32,
) -> Option<GridHit> {
    let grid = intersect_tessellation(ray, tess, stride, t_min, t_max);
    let limit = grid.map_or(t_max, |h| h.t);
    intersect_seams(ray, tess, stride, edges, t_min, limit).or(grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, f: impl Fn(f32, f32) -> [f32; 3], seam_radius: f32) -> Tessellation {
        let mut verts = Vec::new();
        for j in 0..n {
            for i in 0..n {
                verts.push(f(i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32));
            }
        }
        Tessellation { n, verts: verts.into(), sub_boxes: Default::default(), chord_error: 0.0, seam_radius, domain: GridDomain::Square }
    }

    #[test]
    fn child_edges_are_the_ones_on_the_root_boundary() {
        assert_eq!(SeamEdges::of_child(0, 0, 0), SeamEdges::ALL);
        assert_eq!(SeamEdges::of_child(2, 1, 2), SeamEdges::NONE);
        assert_eq!(SeamEdges::of_child(1, 0, 0), SeamEdges(0b1001));
        assert_eq!(SeamEdges::of_child(1, 1, 1), SeamEdges(0b0110));
    }

    #[test]
    fn a_ray_through_the_gap_beside_a_grid_hits_its_seam_and_one_far_away_does_not() {
        let t = grid(5, |u, v| [u, v, 0.0], 0.01);
        // Parallel to the plane's normal just outside the u = 1 edge, within the radius.
        let down = |x: f32| WatertightRay::new(Vec3A::new(x, 0.5, 1.0), Vec3A::NEG_Z);
        let h = intersect_seams(&down(1.005), &t, 1, SeamEdges::ALL, 0.0, f32::INFINITY).expect("inside the seam box");
        assert!(h.t > 1.0 && h.t <= 1.0 + 0.01 * 1.5, "leaves the box below the plane: {h:?}");
        assert!((h.u - 1.0).abs() < 1e-6 && (h.v - 0.5).abs() < 1e-3);
        assert!(h.ng.z > 0.0);
        assert!(intersect_seams(&down(1.02), &t, 1, SeamEdges::ALL, 0.0, f32::INFINITY).is_none());
        // Edge 1 left out: no seam there.
        assert!(intersect_seams(&down(1.005), &t, 1, SeamEdges(0b1101), 0.0, f32::INFINITY).is_none());
        // A grid hit closer than the box exit wins (t_max is the grid's hit).
        assert!(intersect_seams(&down(0.995), &t, 1, SeamEdges::ALL, 0.0, 1.0).is_none());
    }

    #[test]
    fn triangle_grids_have_seams_on_their_diagonal_not_on_the_far_edges() {
        let mut t = grid(5, |u, v| [u, v, 0.0], 0.01);
        t.domain = GridDomain::LowerTriangle;
        let down = |x: f32, y: f32| WatertightRay::new(Vec3A::new(x, y, 1.0), Vec3A::NEG_Z);
        // Just beyond the diagonal, next to it: the diagonal's seam box.
        let h = intersect_seams(&down(0.505, 0.505), &t, 1, SeamEdges::ALL, 0.0, f32::INFINITY).expect("diagonal seam");
        assert!((h.u + h.v - 1.0).abs() < 1e-5 && h.ng.z > 0.0, "{h:?}");
        // Just beyond u = 1 at v = 0.5: outside the triangle, no seam there.
        assert!(intersect_seams(&down(1.005, 0.5), &t, 1, SeamEdges::ALL, 0.0, f32::INFINITY).is_none());
        assert!(intersect_seams(&down(0.5, -0.005), &t, 2, SeamEdges::ALL, 0.0, f32::INFINITY).is_some());
    }

    #[test]
    fn rays_starting_inside_a_seam_box_ignore_it() {
        let t = grid(2, |u, v| [u, v, 0.0], 0.01);
        let r = WatertightRay::new(Vec3A::new(1.0, 0.5, 0.0), Vec3A::new(1.0, 0.0, 0.01).normalize());
        assert!(intersect_seams(&r, &t, 1, SeamEdges::ALL, 0.0, f32::INFINITY).is_none());
    }

    #[test]
    fn merged_rates_grow_the_radius_by_the_skipped_vertex() {
        // A roof: the middle vertex of each u-edge is 0.1 above the chord of stride 2.
        let t = grid(3, |u, v| [u, v, 0.2 * (0.5 - (u - 0.5).abs())], 0.0);
        let r = WatertightRay::new(Vec3A::new(0.5, -0.05, 1.0), Vec3A::NEG_Z);
        assert!(intersect_seams(&r, &t, 2, SeamEdges(1), 0.0, f32::INFINITY).is_some(), "within 0.1 of the stride-2 chord");
        assert!(intersect_seams(&r, &t, 1, SeamEdges(1), 0.0, f32::INFINITY).is_none(), "stride 1 has radius 0");
    }
}
