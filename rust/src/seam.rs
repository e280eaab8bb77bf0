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

use glam::{Vec3A, Vec4};

use crate::intersect::{intersect_tessellation, GridHit, WatertightRay};
use crate::patch::{EdgeKnots, LimitSurface, UvRect};
use crate::tessellate::{GridDomain, Tessellation};

/// Probes per boundary chord, at t = ¼, ½, ¾ of it: three catch S-shaped chords (an edge curve
/// with an inflection in the chord's middle crosses it there).
pub const SEAM_PROBES: usize = 3;

/// The largest deviation of an edge curve from its chord is taken as this many times the largest
/// deviation of the curve the probes determine (see [`seam_extent`]): exact for the polynomial
/// edges of every OpenSubdiv patch (cubic, quartic for Loop), so the factor only covers rounding
/// and surfaces whose edges are not polynomials of degree ≤ 4 (an analytic sphere's arcs, whose
/// deviation is a quadratic times t(1 − t) to within a fraction of a percent at chord angles
/// under a radian), plus the sampling of the fitted curve ([`FIT_STEPS`]). It was 1.25 times the
/// probes' own largest deviation, which stood boxes higher than needed on most chords (their
/// image cost is in docs/cracks.md) and short of it on S-shaped quartic (Loop) edges, whose
/// maximum can reach 1.8 times the probes'.
pub const SEAM_SAFETY: f32 = 1.1;

/// Each side of a seam box along its chord's normal reaches at least this fraction of the other
/// side's measured extent: a cubic edge curve whose sign change hides between a chord's end and
/// its first probe dips to the other side by at most 1/6.7 of its height on the first ([`SeamNormal`]).
pub const SEAM_NORMAL_FLOOR: f32 = 0.25;

/// The floating-point margin of a seam box, relative to the largest coordinate of its grid: two
/// patches evaluating the same edge point agree to within 2.8ε of the coordinates' magnitude
/// (the largest over OpenSubdiv's regression corpus, `loop_tetrahedron`: see
/// `mipray-subdiv-compare`'s `max_edge_mismatch_over_margin`); this is about twice that. It is
/// also how far seams can thicken a silhouette: nothing near the origin, a few ulps of the
/// position far from it.
pub const SEAM_MARGIN_REL: f32 = 6.0 * f32::EPSILON;

/// √3, rounded up: how far a seam box reaches from its chord, in units of its radius.
const SQRT_3_UP: f32 = 1.732_051;

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

/// Where edge `e`'s vertices lie in an n×n grid's row-major vertex array: vertex `k` of the
/// edge ([`edge_vertex`]) is at `start + k * step`. Read in the seam tests' inner loops, where a
/// match per vertex cost a displaced AO ray ~150 instructions.
#[inline]
pub fn edge_line(e: usize, n: usize) -> (usize, usize) {
    match e {
        0 => (0, 1),
        1 => (n - 1, n),
        2 => ((n - 1) * n, 1),
        3 => (0, n),
        _ => (n - 1, n - 1),
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

/// The boundary quad of chord `k` of edge `e` of a grid with `q` quads a side, as (i, j) in
/// quads: the quad whose side the chord is, as [`crate::intersect`] winds it (on the diagonal,
/// its lower-left half).
#[inline]
fn chord_quad(e: usize, k: usize, q: usize) -> (usize, usize) {
    match e {
        0 => (k, 0),
        1 => (q - 1, k),
        2 => (k, q - 1),
        3 => (0, k),
        _ => (q - 1 - k, k),
    }
}

/// The frame of chord `k` of edge `e` of an `n × n` grid read at `stride` (`vert(i, j)` gives
/// the vertices): the chord's ends, its unit axis and length, and `e1` the normal of its
/// boundary quad made perpendicular to the axis (the side the quad's triangles face), `e2`
/// completing the frame across the chord. `None` for a chord of zero or non-finite length.
/// Computed the same way when tessellating and when intersecting, from the same vertices, so
/// the extents measured in it are the ones the box is built with.
fn chord_frame(vert: impl Fn(usize, usize) -> Vec3A, e: usize, k: usize, n: usize, stride: usize, triangle: bool) -> Option<ChordFrame> {
    let q = (n - 1) / stride;
    let at = |m: usize| {
        let (i, j) = edge_vertex(e, m, n);
        vert(i, j)
    };
    let (a, b) = (at(k * stride), at((k + 1) * stride));
    let ab = b - a;
    let len = ab.length();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let axis = ab / len;
    let (qi, qj) = chord_quad(e, k, q);
    let p00 = vert(qi * stride, qj * stride);
    let p10 = vert((qi + 1) * stride, qj * stride);
    // A triangle grid's quad on the diagonal is its lower-left half alone (its (1, 1) corner is
    // the basis extrapolated beyond the patch): the far corner of edges 0 and 3's last chords
    // there, as of the diagonal's, is (0, 1). With (1, 1) those chords' frames, so their boxes
    // and seam hits' normals, could face the wrong side (issue 23).
    let far = if e == DIAGONAL || (triangle && qi + qj + 1 == q) {
        vert(qi * stride, (qj + 1) * stride)
    } else {
        vert((qi + 1) * stride, (qj + 1) * stride)
    };
    let ng = (p10 - p00).cross(far - p00);
    let e1 = (ng - axis * ng.dot(axis)).normalize_or_zero();
    let (e1, e2) = if e1 != Vec3A::ZERO && e1.is_finite() { (e1, axis.cross(e1)) } else { axis.any_orthonormal_pair() };
    Some(ChordFrame { a, b, axis, len, e1, e2, ng })
}

/// See [`chord_frame`].
#[derive(Clone, Copy, Debug)]
struct ChordFrame {
    a: Vec3A,
    b: Vec3A,
    axis: Vec3A,
    len: f32,
    e1: Vec3A,
    e2: Vec3A,
    /// The boundary quad's (unnormalised) normal.
    ng: Vec3A,
}

/// How far the limit surface's edge curves stray from a grid's boundary chords along each
/// chord's normal (`e1` of its frame: the boundary quad's side), below and above, as fractions
/// of the [seam radius](Tessellation::seam_radius). The radius bounds the curve's distance from
/// the chord in any direction; these two bound it along the normal, so a seam box need stand
/// off the surface only as far as the curve does: a flat patch's edge curves stray from their
/// chords only within its plane, and a convex surface's only outward. Without them a box is
/// the radius thick on both sides of the surface, which thickens silhouettes and shadows rays
/// leaving the surface near a seam by up to the chord error.
///
/// Two bytes, inside the padding of a cache entry: each fraction is `2^(−code/8)` (code 0 is
/// the whole radius, as [`SeamNormal::ISOTROPIC`]; code 255 is 2.5·10⁻¹⁰ of it), rounded up,
/// so the decoded extent is never smaller than the measured one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SeamNormal {
    below: u8,
    above: u8,
}

impl SeamNormal {
    /// The radius on both sides: what a grid whose chords' normals mean nothing gets (a
    /// displaced grid, sized on the undisplaced surface; a degenerate one).
    pub const ISOTROPIC: SeamNormal = SeamNormal { below: 0, above: 0 };

    /// From extents `below` (≥ 0, toward −e1) and `above` (≥ 0, toward +e1) for a radius `r`.
    pub fn encode(below: f32, above: f32, r: f32) -> SeamNormal {
        let code = |x: f32| -> u8 {
            if !(r > 0.0 && r.is_finite() && x.is_finite()) || x >= r {
                return 0;
            }
            if x <= 0.0 {
                return 255;
            }
            // The largest code whose fraction 2^(−code/8) is still ≥ x / r.
            let c = (-8.0 * (x / r).log2()).floor().clamp(0.0, 255.0) as u8;
            // log2 rounds: step back while the decoded fraction falls short.
            (0..=c).rev().find(|&c| Self::fraction(c) * r >= x).unwrap_or(0)
        };
        SeamNormal { below: code(below), above: code(above) }
    }

    #[inline]
    fn fraction(code: u8) -> f32 {
        (-(code as f32) / 8.0).exp2()
    }

    /// The extents along the normal for radius `r`: (below, above), each at most `r`.
    #[inline]
    pub fn extents(self, r: f32) -> (f32, f32) {
        (r * Self::fraction(self.below), r * Self::fraction(self.above))
    }
}

/// The seam radius of an n×n grid `verts` (undisplaced, u fastest) over `rect` of `patch`, and
/// how far along the chords' normals it reaches ([`SeamNormal`]): [`SEAM_SAFETY`] times the
/// largest distance (and the largest distance below and above along the normal) between the
/// limit surface at [`SEAM_PROBES`] points inside a boundary chord (at stride 1) and that chord,
/// plus [`seam_margin`]. Object units. Non-finite distances (a degenerate patch) are left out.
pub fn seam_extent(surface: &dyn LimitSurface, patch: usize, rect: UvRect, verts: &[[f32; 3]], n: usize) -> (f32, SeamNormal) {
    seam_extent_with(surface, patch, rect, verts, n, true)
}

/// [`seam_extent`]; with `normals` false only the radius is measured, and the extents along
/// the normals are [`SeamNormal::ISOTROPIC`]: what a displaced grid uses (its chords are not
/// the ones measured), which saves measuring what it would throw away. The radius is
/// the same bits either way.
pub fn seam_extent_with(
    surface: &dyn LimitSurface,
    patch: usize,
    rect: UvRect,
    verts: &[[f32; 3]],
    n: usize,
    normals: bool,
) -> (f32, SeamNormal) {
    if n < 2 || verts.len() < n * n {
        return (0.0, SeamNormal::ISOTROPIC);
    }
    let at = |i: usize, j: usize| Vec3A::from(verts[j * n + i]);
    let max_abs = verts.iter().fold(0.0f32, |m, v| m.max(v[0].abs()).max(v[1].abs()).max(v[2].abs()));
    let q = (n - 1) as f32;
    let (mut dev_sq, mut below, mut above): (f32, f32, f32) = (0.0, 0.0, 0.0);
    let domain = GridDomain::of(surface.patch_param(patch).kind, &rect);
    let triangle = domain == GridDomain::LowerTriangle;
    let edges = SeamEdges::ALL.within(domain);
    // The chords (e, k): edges in order, k along each. Plain loops over them, not a chained
    // iterator: collected through `flat_map`, the probes' (u, v) grew their vector a push at a
    // time and each probe went through a call: ~3 k instructions a grid built, most of what
    // the surface evaluations cost (callgrind, displaced AO render).
    let edge_list = (0..=DIAGONAL).filter(|&e| edges.contains(e));
    let chord_count = edge_list.clone().count() * (n - 1);
    let tau = |p: usize| (p + 1) as f32 / (SEAM_PROBES + 1) as f32;
    let to_patch = |lu: f32, lv: f32| [rect.u0 + (rect.u1 - rect.u0) * lu, rect.v0 + (rect.v1 - rect.v0) * lv];
    // Every probe of every chord in one evaluation: positions only.
    let mut uv: Vec<[f32; 2]> = Vec::with_capacity(chord_count * SEAM_PROBES);
    for e in edge_list.clone() {
        for k in 0..n - 1 {
            for p in 0..SEAM_PROBES {
                let (lu, lv) = edge_uv(e, (k as f32 + tau(p)) / q);
                uv.push(to_patch(lu, lv));
            }
        }
    }
    let mut probes = Vec::with_capacity(uv.len());
    surface.evaluate_points(patch, &uv, &mut probes);
    let knots = surface.edge_knots(patch);
    let mut curves = probes.chunks_exact(SEAM_PROBES);
    'chords: for e in edge_list {
        for k in 0..n - 1 {
            let Some(curve) = curves.next() else { break 'chords };
            let frame = if normals { chord_frame(at, e, k, n, 1, triangle) } else { None };
            let (ia, ja) = edge_vertex(e, k, n);
            let (ib, jb) = edge_vertex(e, k + 1, n);
            let (a, b) = (at(ia, ja), at(ib, jb));
            let side = frame.map(|f| f.e1);
            // A chord across a knot of a piecewise polynomial edge (a single-crease patch's) is
            // fitted piece by piece; every other chord at once.
            let (ua, ub) = (edge_uv(e, k as f32 / q), edge_uv(e, (k + 1) as f32 / q));
            let (pa, pb) = (to_patch(ua.0, ua.1), to_patch(ub.0, ub.1));
            let fitted = match chord_knots(&knots, pa, pb) {
                Some(cuts) => piecewise_chord(surface, patch, a, b, pa, pb, &cuts, side),
                None => fit_chord(a, b, curve, side),
            };
            let Some((chord_sq, low, high)) = fitted else { continue };
            dev_sq = dev_sq.max(chord_sq);
            if !normals {
                continue;
            }
            match side {
                Some(_) => (below, above) = (below.max(-low), above.max(high)),
                None => (below, above) = (below.max(chord_sq.sqrt()), above.max(chord_sq.sqrt())),
            }
        }
    }
    let dev = dev_sq.sqrt();
    let margin = seam_margin(max_abs);
    let r = SEAM_SAFETY * dev + margin;
    if !normals {
        return (r, SeamNormal::ISOTROPIC);
    }
    // The probes can miss a shallow dip to the side the curve barely crosses to (near a chord's
    // end, beyond the outer probes); each side gets at least a fraction of the other's.
    let floor = SEAM_NORMAL_FLOOR * below.max(above);
    (r, SeamNormal::encode(SEAM_SAFETY * below.max(floor) + margin, SEAM_SAFETY * above.max(floor) + margin, r))
}

/// The deviation of an edge curve from its chord a → b, from the curve at the chord's
/// [`SEAM_PROBES`] probes: (the largest |D|², the lowest and highest D along `side`, each 0 at
/// worst), `None` when not finite. D(τ) = c(τ) − (a + (b − a)τ) over the chord's own parameter
/// τ ∈ [0, 1] vanishes at both ends: D = τ(1 − τ)·G(τ). For a polynomial edge of degree ≤ 4 G
/// is a quadratic, which the three probes determine; its extremes bound the curve's, including
/// where the probes miss (a maximum between them, a dip near an end).
fn fit_chord(a: Vec3A, b: Vec3A, curve: &[[f32; 3]], side: Option<Vec3A>) -> Option<(f32, f32, f32)> {
    let tau = |p: usize| (p + 1) as f32 / (SEAM_PROBES + 1) as f32;
    let mut g = [Vec3A::ZERO; SEAM_PROBES];
    for (p, (gp, c)) in g.iter_mut().zip(curve).enumerate() {
        let tau = tau(p);
        let d = Vec3A::from(*c) - (a + (b - a) * tau);
        if !d.is_finite() {
            return None;
        }
        *gp = d / (tau * (1.0 - tau));
    }
    // Without a side (a displaced grid's chords, a degenerate frame) the samples' heights are
    // not needed: a loop of its own, the same operations for |D|².
    let (chord_sq, low, high) = match side {
        Some(e1) => fit_samples::<true>(&g, e1),
        None => fit_samples::<false>(&g, Vec3A::ZERO),
    };
    Some((chord_sq.max_element(), low.min_element(), high.max_element()))
}

/// [`fit_chord`]'s samples of the fitted deviation D = Σ_p g_p · weight: the largest |D|² and,
/// with `SIDE`, the lowest and highest D along `e1` (zero lanes without), four samples a lane.
#[inline(always)]
fn fit_samples<const SIDE: bool>(g: &[Vec3A; SEAM_PROBES], e1: Vec3A) -> (Vec4, Vec4, Vec4) {
    // The fitted deviation at every sample, four samples a lane (x, y, z apart): a grid's
    // seam extent was measured one sample at a time, and at 31 samples per chord that was
    // most of what making a coarse grid cost.
    let (mut chord_sq, mut low, mut high) = (Vec4::ZERO, Vec4::ZERO, Vec4::ZERO);
    let [p0, p1, p2] = &FIT_WEIGHTS;
    for ((w0, w1), w2) in p0.iter().zip(p1).zip(p2) {
        let (w0, w1, w2) = (Vec4::from_array(*w0), Vec4::from_array(*w1), Vec4::from_array(*w2));
        let dx = w0 * g[0].x + w1 * g[1].x + w2 * g[2].x;
        let dy = w0 * g[0].y + w1 * g[1].y + w2 * g[2].y;
        let dz = w0 * g[0].z + w1 * g[1].z + w2 * g[2].z;
        chord_sq = chord_sq.max(dx * dx + dy * dy + dz * dz);
        // Along the normal, from the chord's line: a box spans the chord's length (and `r`
        // beyond its ends) whatever the curve's position along it.
        if SIDE {
            let h = dx * e1.x + dy * e1.y + dz * e1.z;
            low = low.min(h);
            high = high.max(h);
        }
    }
    (chord_sq, low, high)
}

/// Where the knots of `knots` cut the chord from patch (u, v) `pa` to `pb` (an edge runs along
/// u or along v): the fractions of the chord, in order, strictly inside (0, 1); `None` when no
/// knot falls inside.
fn chord_knots(knots: &EdgeKnots, pa: [f32; 2], pb: [f32; 2]) -> Option<[f32; 2]> {
    let (axis, along) = if pa[0] != pb[0] { (0, &knots.u) } else { (1, &knots.v) };
    let (x0, x1) = (pa[axis], pb[axis]);
    let mut cuts = [f32::NAN; 2];
    let mut n = 0;
    for &x in along {
        let f = (x - x0) / (x1 - x0);
        if f > 0.0 && f < 1.0 {
            cuts[n] = f;
            n += 1;
        }
    }
    if n == 2 && cuts[1] < cuts[0] {
        cuts.swap(0, 1);
    }
    (n > 0).then_some(cuts)
}

/// [`fit_chord`] for a chord a → b (patch (u, v) `pa` → `pb`) whose edge curve changes
/// polynomial at the fractions `cuts` of it (NaN: none): each piece fitted against its own
/// chord between the curve's points at the cuts, plus how far that piece's chord strays from
/// the whole chord (linear along it, so at most at its ends). Exact up to that triangle
/// inequality, which only errs large.
#[allow(clippy::too_many_arguments)]
fn piecewise_chord(
    surface: &dyn LimitSurface,
    patch: usize,
    a: Vec3A,
    b: Vec3A,
    pa: [f32; 2],
    pb: [f32; 2],
    cuts: &[f32; 2],
    side: Option<Vec3A>,
) -> Option<(f32, f32, f32)> {
    let mut ends = vec![0.0f32];
    ends.extend(cuts.iter().copied().filter(|f| f.is_finite()));
    ends.push(1.0);
    let at = |f: f32| [pa[0] + (pb[0] - pa[0]) * f, pa[1] + (pb[1] - pa[1]) * f];
    let tau = |p: usize| (p + 1) as f32 / (SEAM_PROBES + 1) as f32;
    // The curve at the inner cuts, then each piece's probes.
    let mut uv: Vec<[f32; 2]> = ends[1..ends.len() - 1].iter().map(|&f| at(f)).collect();
    for w in ends.windows(2) {
        uv.extend((0..SEAM_PROBES).map(|p| at(w[0] + (w[1] - w[0]) * tau(p))));
    }
    let mut points = Vec::with_capacity(uv.len());
    surface.evaluate_points(patch, &uv, &mut points);
    let inner = ends.len() - 2;
    let point = |i: usize| {
        if i == 0 {
            a
        } else if i == ends.len() - 1 {
            b
        } else {
            Vec3A::from(points[i - 1])
        }
    };
    let (mut dev, mut low, mut high) = (0.0f32, 0.0f32, 0.0f32);
    for (piece, w) in ends.windows(2).enumerate() {
        let (pa, pb) = (point(piece), point(piece + 1));
        let probes = &points[inner + piece * SEAM_PROBES..inner + (piece + 1) * SEAM_PROBES];
        let (sq, lo, hi) = fit_chord(pa, pb, probes, side)?;
        // The piece's chord against the whole chord's at the same parameter, at its two ends.
        let (da, db) = (pa - (a + (b - a) * w[0]), pb - (a + (b - a) * w[1]));
        if !(da.is_finite() && db.is_finite()) {
            return None;
        }
        dev = dev.max(sq.sqrt() + da.length().max(db.length()));
        if let Some(e1) = side {
            let (ha, hb) = (da.dot(e1), db.dot(e1));
            low = low.min(lo + ha.min(hb));
            high = high.max(hi + ha.max(hb));
        }
    }
    Some((dev * dev, low, high))
}

/// Points at which the fitted deviation is sampled for its extremes. A quadratic times τ(1 − τ)
/// is a quartic, whose second derivative on [0, 1] is at most 320 times its largest magnitude
/// (Markov's inequality), so between samples 1/32 apart it exceeds the sampled maximum by at
/// most 4 % of it: [`SEAM_SAFETY`] covers that.
const FIT_STEPS: usize = 32;

/// Lanes of four samples in [`FIT_WEIGHTS`].
const FIT_LANES: usize = FIT_STEPS / 4;

/// For each probe p and inner sample τ = step / [`FIT_STEPS`] (the ends, where the deviation is
/// zero, left out): the Lagrange weight of probe p in the quadratic through τ = ¼, ½, ¾, times
/// τ(1 − τ); the deviation at the sample is Σ_p g_p · weight. Four samples a lane, sample
/// `step` at `[p][(step − 1) / 4][(step − 1) % 4]`; the last lane's fourth entry (τ = 1) is 0.
/// The same for every chord of every grid, so made once, at compile time.
const FIT_WEIGHTS: [[[f32; 4]; FIT_LANES]; SEAM_PROBES] = {
    let (x0, x1, x2) = (0.25f32, 0.5f32, 0.75f32);
    let mut table = [[[0.0f32; 4]; FIT_LANES]; SEAM_PROBES];
    let mut step = 1;
    while step < FIT_STEPS {
        let tau = step as f32 / FIT_STEPS as f32;
        let bump = tau * (1.0 - tau);
        let (lane, k) = ((step - 1) / 4, (step - 1) % 4);
        table[0][lane][k] = (tau - x1) * (tau - x2) / ((x0 - x1) * (x0 - x2)) * bump;
        table[1][lane][k] = (tau - x0) * (tau - x2) / ((x1 - x0) * (x1 - x2)) * bump;
        table[2][lane][k] = (tau - x0) * (tau - x1) / ((x2 - x0) * (x2 - x1)) * bump;
        step += 1;
    }
    table
};

/// A seam box: around the chord from `a` to `b`, oriented along it, `r` beyond its ends and on
/// either side across it (`e2`), and from `below` under it to `above` over it along its normal
/// (`e1`).
#[derive(Clone, Copy, Debug)]
pub struct SeamBox {
    a: Vec3A,
    axis: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
    len: f32,
    r: f32,
    below: f32,
    above: f32,
}

impl SeamBox {
    /// The slabs: (direction, low, high) relative to `a`, grown by `grow`.
    #[inline]
    fn slabs_of(&self, grow: f32) -> [(Vec3A, f32, f32); 3] {
        let r = self.r + grow;
        [(self.axis, -r, self.len + r), (self.e1, -self.below - grow, self.above + grow), (self.e2, -r, r)]
    }

    /// The ray's entry and exit distances, or `None` when it misses.
    #[inline]
    fn slabs(&self, o: Vec3A, d: Vec3A) -> Option<(f32, f32)> {
        let rel = o - self.a;
        let mut near = f32::NEG_INFINITY;
        let mut far = f32::INFINITY;
        for (axis, lo, hi) in self.slabs_of(0.0) {
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
    pub fn contains(&self, p: Vec3A, grow: f32) -> bool {
        self.coverage(p, grow) <= 1.0
    }

    /// How far into the box `p` grown by `grow` on every side reaches, as the largest of: its
    /// offset from the middle of the box's normal and cross slabs, plus `grow`, over the slab's
    /// half-width; and how far beyond the chord's ends it lies, plus `grow`, over how far the box
    /// reaches beyond them. At most 1 when that grown point lies inside.
    pub fn coverage(&self, p: Vec3A, grow: f32) -> f32 {
        let rel = p - self.a;
        let ratio = |x: f32| if x.is_nan() { f32::INFINITY } else { x };
        let along = rel.dot(self.axis);
        let beyond = (-along).max(along - self.len).max(0.0);
        let mut m = ratio((beyond + grow) / self.r.max(f32::MIN_POSITIVE));
        for &(axis, lo, hi) in &self.slabs_of(0.0)[1..] {
            let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
            m = m.max(ratio(((rel.dot(axis) - mid).abs() + grow) / half.max(f32::MIN_POSITIVE)));
        }
        m
    }
}

/// The seam box the renderer tests for chord `k` of edge `e` of `tess` read at `stride`, and
/// its chord's frame (for the hit's normal). At stride 1 the box is the measured one: the seam
/// radius across and beyond the chord, [`Tessellation::seam_normal`]'s extents along its normal.
/// At a merged stride the long chord skips vertices, and its frame turns from its short chords'
/// (by at most `dθ`, measured): the box then also holds the skipped vertices' polyline
/// (`extra`, their largest distance from the long chord, across; their own height along its
/// normal) and the short chords' measured extents turned into its frame (`r·|e1' − e1|` more
/// either way along the normal), which for a flat grid leaves it as thin as at stride 1.
pub fn seam_box(tess: &Tessellation, e: usize, k: usize, stride: usize) -> Option<(SeamBox, Vec3A)> {
    let n = tess.n;
    let vert = |i: usize, j: usize| tess.vert(i, j);
    let triangle = tess.domain == GridDomain::LowerTriangle;
    let f = chord_frame(vert, e, k, n, stride, triangle)?;
    let base = tess.seam_radius;
    let (mut below, mut above) = tess.seam_normal.extents(base);
    let mut extra: f32 = 0.0;
    if stride > 1 {
        let at = |m: usize| {
            let (i, j) = edge_vertex(e, m, n);
            tess.vert(i, j)
        };
        let (mut skipped_lo, mut skipped_hi, mut turn): (f32, f32, f32) = (0.0, 0.0, 0.0);
        for m in 1..stride {
            let p = at(k * stride + m);
            extra = extra.max(point_segment_distance(p, f.a, f.b));
            let h = (p - f.a).dot(f.e1);
            (skipped_lo, skipped_hi) = (skipped_lo.min(h), skipped_hi.max(h));
        }
        for s in 0..stride {
            match chord_frame(vert, e, k * stride + s, n, 1, triangle) {
                Some(short) => turn = turn.max((short.e1 - f.e1).length()),
                None => turn = 2.0,
            }
        }
        let turned = base * turn;
        below = (below + turned - skipped_lo).min(base + extra);
        above = (above + turned + skipped_hi).min(base + extra);
        if !(turned.is_finite() && below.is_finite() && above.is_finite()) {
            (below, above) = (base + extra, base + extra);
        }
    }
    let r = base + extra;
    Some((SeamBox { a: f.a, axis: f.axis, e1: f.e1, e2: f.e2, len: f.len, r, below, above }, f.ng))
}

/// `intersect_seams`'s rule for rays starting inside a box: never stopped by it.
#[inline(always)]
pub fn never_from_inside(_ng: Vec3A) -> bool {
    false
}

/// The closest seam-box hit of `ray` on the `edges` of `tess` read at vertex `stride`, in
/// (`t_min`, `t_max`): where the ray leaves the first box it passes through from outside. The
/// hit's (u, v) is the nearest point of the chord, in the grid's [0, 1]²; its normal is the
/// boundary quad's (the winding of [`crate::intersect`]'s triangles).
/// Hits `accept(t, ng)` refuses are passed over inside the search (see
/// [`crate::intersect::intersect_tessellation`]).
///
/// A ray that starts inside (or on) a box leaves a surface near that seam and ignores the box,
/// unless `stops_inside(ng)` (the box's boundary-quad normal) says it heads through the surface
/// there: then it stops where it leaves the box, as a ray from outside does (the tracer's rule
/// 8 for displaced meshes, docs/cracks.md). [`never_from_inside`] keeps the plain rule.
#[allow(clippy::too_many_arguments)]
pub fn intersect_seams<A: Fn(f32, Vec3A) -> bool, S: Fn(Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    edges: SeamEdges,
    t_min: f32,
    t_max: f32,
    accept: &A,
    stops_inside: &S,
) -> Option<GridHit> {
    let n = tess.n;
    if n < 2 || stride == 0 || (n - 1) % stride != 0 || edges == SeamEdges::NONE {
        return None;
    }
    let q = (n - 1) / stride;
    let edges = edges.within(tess.domain);
    let base = tess.seam_radius;
    if !(base >= 0.0 && base.is_finite()) {
        return None;
    }
    let mut best: Option<GridHit> = None;
    let mut t_best = t_max;
    let verts: &[[f32; 3]] = &tess.verts;
    let origin_margin = seam_margin(ray.o.abs().max_element());
    for e in (0..=DIAGONAL).filter(|&e| edges.contains(e)) {
        let (start, step) = edge_line(e, n);
        let vert = |k: usize| Vec3A::from(verts[start + k * step]);
        // At most how far chord k's box reaches from the chord: the radius, plus (merged rates)
        // a bound on the skipped vertices' distance from the long chord — their L1 distance from
        // its middle, which costs no square root or division per vertex (the box itself, built
        // only for chords the cull lets through, measures the distance exactly).
        let reach = |k: usize, a: Vec3A, b: Vec3A| {
            let mid = (a + b) * 0.5;
            (1..stride).fold(base, |r, m| r.max(base + (vert(k * stride + m) - mid).abs().element_sum()))
        };
        // Cull the edge first, cheaply: every box lies within its chord's reach, and √3 times
        // that bounds how far it reaches from its chord in any axis direction. At stride 1 every
        // reach is the radius; merged, each chord's is computed again below where it is needed
        // (one skipped vertex at stride 2: cheaper than keeping them in an array per edge).
        // An edge of one or two chords is culled chord by chord: its box is made only for
        // longer edges (a merged 2×2 grid made it, and its chords' reaches, for nothing).
        if q > 2 {
            // Each vertex read once: a chord's end is the next one's start.
            let mut edge_box = crate::bounds::Bounds3::EMPTY;
            let mut r_max: f32 = base;
            let mut a = vert(0);
            edge_box.grow(a);
            for k in 0..q {
                let b = vert((k + 1) * stride);
                if stride > 1 {
                    r_max = r_max.max(reach(k, a, b));
                }
                edge_box.grow(b);
                a = b;
            }
            if ray.hit_box(&edge_box.expanded(1.8 * r_max), t_min, t_best).is_none() {
                continue;
            }
        }
        let mut b = vert(0);
        for k in 0..q {
            // Then each chord, before building its box: every point of the box lies within √3
            // times its reach of the chord (r beyond an end, and r across both ways), so a ray
            // that passes farther from the chord in (t_min, t_best) misses the box.
            // The axis-aligned test is the cheaper, the distance the tighter for chords running
            // diagonally to the axes: most rays fail the first, most of the rest the second.
            // (The chord's start is the previous one's end, read once.)
            let a = b;
            b = vert((k + 1) * stride);
            let r = if stride > 1 { reach(k, a, b) } else { base };
            let chord = crate::bounds::Bounds3 { min: a.min(b), max: a.max(b) };
            if ray.hit_box(&chord.expanded(1.8 * r), t_min, t_best).is_none()
                || !ray.may_pass_near_segment(a, b, SQRT_3_UP * r, t_min, t_best)
            {
                continue;
            }
            let Some((sb, ng)) = seam_box(tess, e, k, stride) else { continue };
            // A ray that starts in (or on) the box leaves a surface near this seam: skip it,
            // unless it heads through the surface there (`stops_inside`).
            let start_grow = 1e-3 * sb.r + origin_margin;
            let inside = sb.contains(ray.o, start_grow);
            if inside && !stops_inside(ng) {
                continue;
            }
            let Some((near, far)) = sb.slabs(ray.o, ray.d) else { continue };
            if !(far > t_min && far < t_best && (inside || (near > t_min && far > near))) {
                continue;
            }
            let p = ray.o + ray.d * far;
            let lambda = ((p - sb.a).dot(sb.axis) / sb.len).clamp(0.0, 1.0);
            let (u, v) = edge_uv(e, (k as f32 + lambda) / q as f32);
            if !inside && !accept(far, ng) {
                continue;
            }
            t_best = far;
            best = Some(GridHit { t: far, u, v, ng, seam: true });
        }
    }
    best
}

/// Whether `ray` may hit, in (`t_min`, `t_max`), the grid `tess` read at `stride` or a seam box
/// of its `edges`: false only when it misses one box holding all of them, the grid's vertices'
/// (a fine grid's: its sub-boxes') grown by the seam boxes' largest reach and a few ulps.
/// Most rays that reach a subpatch pass beside its grid: its box is the patch's hull (grown by
/// the displacement bound on displaced meshes), looser than the grid. One box test then
/// replaces a fine grid's sixteen sub-box tests, a coarse or medium grid's triangle tests and
/// every seam's edge and chord culls. Conservative: it holds every chord box the seams' own
/// culls test (so a seam box passing them passes this) and every sub-box.
fn may_hit_grid_or_seams(ray: &WatertightRay, tess: &Tessellation, stride: usize, edges: SeamEdges, t_min: f32, t_max: f32) -> bool {
    let n = tess.n;
    if n < 2 || stride == 0 || tess.domain == GridDomain::Empty {
        // Left to the tests themselves (which find nothing or refuse the same way).
        return true;
    }
    if let Some(cull) = tess.boxes.cull(stride) {
        return ray.hit_box(cull, t_min, t_max).is_some();
    }
    if (n - 1) % stride != 0 {
        return true;
    }
    ray.hit_box(&gathered_cull_box(tess, stride, edges), t_min, t_max).is_some()
}

/// The box a ray must meet to hit `tess` read at `stride`, or the seam boxes of its `edges`:
/// the vertices read at that stride, grown by the seams' largest reach from their chords (as
/// `intersect_seams` bounds it) and a triangle test's rounding slack.
fn gathered_cull_box(tess: &Tessellation, stride: usize, edges: SeamEdges) -> crate::bounds::Bounds3 {
    let n = tess.n;
    let verts: &[[f32; 3]] = &tess.verts;
    let mut bb = crate::bounds::Bounds3::EMPTY;
    if stride == 1 {
        // Coarse grids (4 vertices) come here at every test: no stepping.
        for v in verts {
            bb.grow(Vec3A::from(*v));
        }
    } else {
        for j in (0..n).step_by(stride) {
            for v in verts[j * n..(j + 1) * n].iter().step_by(stride) {
                bb.grow(Vec3A::from(*v));
            }
        }
    }
    let base = tess.seam_radius;
    let mut reach: f32 = 0.0;
    let edges = edges.within(tess.domain);
    if edges != SeamEdges::NONE && base >= 0.0 && base.is_finite() {
        reach = base;
        if stride > 1 {
            let q = (n - 1) / stride;
            for e in (0..=DIAGONAL).filter(|&e| edges.contains(e)) {
                let (start, step) = edge_line(e, n);
                let vert = |k: usize| Vec3A::from(verts[start + k * step]);
                for k in 0..q {
                    let mid = (vert(k * stride) + vert((k + 1) * stride)) * 0.5;
                    for m in 1..stride {
                        reach = reach.max(base + (vert(k * stride + m) - mid).abs().element_sum());
                    }
                }
            }
        }
    }
    // A triangle's hit is computed in the ray's sheared frame: a few ulps of slack so that
    // rounding never puts a grazing hit outside the box.
    let pad = 1.8 * reach + crate::ray::gamma(8) * bb.max_abs();
    bb.expanded(pad)
}

/// The cull box at `stride` stored with a medium or fine grid
/// ([`crate::tessellate::GridBoxes::cull`]): [`gathered_cull_box`] with every seam edge (the
/// diagonal too) the grid's domain has, so it holds the box any test of the grid at that stride
/// would gather, whichever edges that test's neighbours seam. Empty where the stride does not
/// divide the grid (such a test gathers nothing: it is left to the test itself).
pub(crate) fn cull_box(tess: &Tessellation, stride: usize) -> crate::bounds::Bounds3 {
    if tess.n >= 2 && (tess.n - 1) % stride == 0 {
        gathered_cull_box(tess, stride, SeamEdges(SeamEdges::ALL.0 | 1 << DIAGONAL))
    } else {
        crate::bounds::Bounds3::EMPTY
    }
}

/// The closest hit of `ray` with the grid `tess` read at `stride` and with the seam boxes of
/// its `edges` ([`SeamEdges::NONE`]: the grid alone, as without seams), in (`t_min`, `t_max`).
/// Hits `accept(t, ng)` refuses are passed over inside the one search (see
/// [`crate::intersect::intersect_tessellation`]).
#[allow(clippy::too_many_arguments)]
pub fn intersect_with_seams<A: Fn(f32, Vec3A) -> bool, S: Fn(Vec3A) -> bool>(
    ray: &WatertightRay,
    tess: &Tessellation,
    stride: usize,
    edges: SeamEdges,
    t_min: f32,
    t_max: f32,
    accept: &A,
    stops_inside: &S,
) -> Option<GridHit> {
    if !may_hit_grid_or_seams(ray, tess, stride, edges, t_min, t_max) {
        return None;
    }
    let grid = intersect_tessellation(ray, tess, stride, t_min, t_max, accept);
    let limit = grid.map_or(t_max, |h| h.t);
    intersect_seams(ray, tess, stride, edges, t_min, limit, accept, stops_inside).or(grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `intersect_seams` from t = 0 to `t_max`, every hit accepted, boxes the ray starts in
    /// ignored: what most tests here ask.
    fn seams(ray: &WatertightRay, t: &Tessellation, stride: usize, edges: SeamEdges, t_max: f32) -> Option<GridHit> {
        intersect_seams(ray, t, stride, edges, 0.0, t_max, &crate::intersect::every_hit, &never_from_inside)
    }
    use crate::tessellate::GridBoxes;

    fn grid(n: usize, f: impl Fn(f32, f32) -> [f32; 3], seam_radius: f32) -> Tessellation {
        let mut verts = Vec::new();
        for j in 0..n {
            for i in 0..n {
                verts.push(f(i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32));
            }
        }
        Tessellation {
            n,
            verts: verts.into(),
            boxes: Default::default(),
            chord_error: 0.0,
            seam_radius,
            seam_normal: Default::default(),
            domain: GridDomain::Square,
        }
    }

    /// The cull box kept with a grid is an early out only: searched with it or with the box
    /// gathered at each test, every ray finds the same hit, at either stride, with any seam
    /// edges, on square and triangle grids; and it holds the gathered box.
    #[test]
    fn a_stored_cull_box_changes_no_hit() {
        let mut state = 0x9e37_79b9_u32;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        let mut checked = 0;
        for (n, domain) in [(5, GridDomain::Square), (17, GridDomain::Square), (5, GridDomain::LowerTriangle)] {
            let bumps: Vec<f32> = (0..n * n).map(|_| 0.1 * (rnd() - 0.5)).collect();
            let at = |u: f32, v: f32| bumps[(v * (n - 1) as f32).round() as usize * n + (u * (n - 1) as f32).round() as usize];
            let mut bare = grid(n, |u, v| [u, v, 0.3 * u * v + at(u, v)], 0.02);
            bare.domain = domain;
            let mut kept = bare.clone();
            kept.boxes = GridBoxes::refill_for_test(std::array::from_fn(|s| cull_box(&bare, s + 1)));
            for stride in 1..=2 {
                for edges in [SeamEdges::ALL, SeamEdges::NONE, SeamEdges(0b0101), SeamEdges(0b1010)] {
                    let gathered = gathered_cull_box(&bare, stride, edges);
                    let cull = kept.boxes.cull(stride).expect("kept");
                    assert!(cull.min.cmple(gathered.min).all() && cull.max.cmpge(gathered.max).all(), "{cull:?} holds {gathered:?}");
                    for _ in 0..400 {
                        let o = Vec3A::new(1.4 * rnd() - 0.2, 1.4 * rnd() - 0.2, 1.0);
                        let target = Vec3A::new(1.4 * rnd() - 0.2, 1.4 * rnd() - 0.2, 0.2 * rnd() - 0.1);
                        let r = WatertightRay::new(o, (target - o).normalize());
                        let search = |t: &Tessellation| {
                            intersect_with_seams(&r, t, stride, edges, 0.0, f32::INFINITY, &crate::intersect::every_hit, &never_from_inside)
                        };
                        let (a, b) = (search(&bare), search(&kept));
                        assert_eq!(format!("{a:?}"), format!("{b:?}"));
                        checked += usize::from(a.is_some());
                    }
                }
            }
        }
        assert!(checked > 1000, "most rays aim at the grid: {checked}");
    }

    #[test]
    fn an_edge_s_line_indexes_its_vertices() {
        for n in [2, 5, 17] {
            for e in 0..=DIAGONAL {
                let (start, step) = edge_line(e, n);
                for k in 0..n {
                    let (i, j) = edge_vertex(e, k, n);
                    assert_eq!(start + k * step, j * n + i, "edge {e} vertex {k} of {n}");
                }
            }
        }
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
        let h = seams(&down(1.005), &t, 1, SeamEdges::ALL, f32::INFINITY).expect("inside the seam box");
        assert!(h.t > 1.0 && h.t <= 1.0 + 0.01 * 1.5, "leaves the box below the plane: {h:?}");
        assert!((h.u - 1.0).abs() < 1e-6 && (h.v - 0.5).abs() < 1e-3);
        assert!(h.ng.z > 0.0);
        assert!(seams(&down(1.02), &t, 1, SeamEdges::ALL, f32::INFINITY).is_none());
        // Edge 1 left out: no seam there.
        assert!(seams(&down(1.005), &t, 1, SeamEdges(0b1101), f32::INFINITY).is_none());
        // A grid hit closer than the box exit wins (t_max is the grid's hit).
        assert!(seams(&down(0.995), &t, 1, SeamEdges::ALL, 1.0).is_none());
    }

    #[test]
    fn triangle_grids_have_seams_on_their_diagonal_not_on_the_far_edges() {
        let mut t = grid(5, |u, v| [u, v, 0.0], 0.01);
        t.domain = GridDomain::LowerTriangle;
        let down = |x: f32, y: f32| WatertightRay::new(Vec3A::new(x, y, 1.0), Vec3A::NEG_Z);
        // Just beyond the diagonal, next to it: the diagonal's seam box.
        let h = seams(&down(0.505, 0.505), &t, 1, SeamEdges::ALL, f32::INFINITY).expect("diagonal seam");
        assert!((h.u + h.v - 1.0).abs() < 1e-5 && h.ng.z > 0.0, "{h:?}");
        // Just beyond u = 1 at v = 0.5: outside the triangle, no seam there.
        assert!(seams(&down(1.005, 0.5), &t, 1, SeamEdges::ALL, f32::INFINITY).is_none());
        assert!(seams(&down(0.5, -0.005), &t, 2, SeamEdges::ALL, f32::INFINITY).is_some());
    }

    #[test]
    fn rays_starting_inside_a_seam_box_ignore_it() {
        let t = grid(2, |u, v| [u, v, 0.0], 0.01);
        let r = WatertightRay::new(Vec3A::new(1.0, 0.5, 0.0), Vec3A::new(1.0, 0.0, 0.01).normalize());
        assert!(seams(&r, &t, 1, SeamEdges::ALL, f32::INFINITY).is_none());
    }

    #[test]
    fn merged_rates_grow_the_radius_by_the_skipped_vertex() {
        // A roof: the middle vertex of each u-edge is 0.1 above the chord of stride 2.
        let t = grid(3, |u, v| [u, v, 0.2 * (0.5 - (u - 0.5).abs())], 0.0);
        let r = WatertightRay::new(Vec3A::new(0.5, -0.05, 1.0), Vec3A::NEG_Z);
        assert!(seams(&r, &t, 2, SeamEdges(1), f32::INFINITY).is_some(), "within 0.1 of the stride-2 chord");
        assert!(seams(&r, &t, 1, SeamEdges(1), f32::INFINITY).is_none(), "stride 1 has radius 0");
    }

    /// One patch given by a function of (u, v), for measuring seams on known edge curves.
    struct FnSurface(fn(f32, f32) -> Vec3A);

    impl LimitSurface for FnSurface {
        fn patch_count(&self) -> usize {
            1
        }
        fn patch_param(&self, _patch: usize) -> crate::patch::PatchParam {
            crate::patch::PatchParam::root(0, 0, crate::patch::PatchKind::Other)
        }
        fn patch_bounds(&self, _patch: usize) -> crate::bounds::Bounds3 {
            crate::bounds::Bounds3::from_points((0..=8).flat_map(|j| (0..=8).map(move |i| (self.0)(i as f32 / 8.0, j as f32 / 8.0))))
        }
        fn evaluate(&self, _patch: usize, u: f32, v: f32) -> crate::patch::SurfacePoint {
            crate::patch::SurfacePoint { p: (self.0)(u, v), ..Default::default() }
        }
        fn control_face_count(&self) -> usize {
            1
        }
    }

    /// [`FnSurface`] whose edges along u change polynomial at `knots` ([`LimitSurface::edge_knots`]).
    struct KnotSurface(FnSurface, [f32; 2]);

    impl LimitSurface for KnotSurface {
        fn patch_count(&self) -> usize {
            1
        }
        fn patch_param(&self, patch: usize) -> crate::patch::PatchParam {
            self.0.patch_param(patch)
        }
        fn patch_bounds(&self, patch: usize) -> crate::bounds::Bounds3 {
            self.0.patch_bounds(patch)
        }
        fn evaluate(&self, patch: usize, u: f32, v: f32) -> crate::patch::SurfacePoint {
            self.0.evaluate(patch, u, v)
        }
        fn control_face_count(&self) -> usize {
            1
        }
        fn edge_knots(&self, _patch: usize) -> EdgeKnots {
            EdgeKnots { u: self.1, v: [f32::NAN; 2] }
        }
    }

    /// The n×n grid of `surface` over the unit square, with its measured seam, as the
    /// tessellator makes it.
    fn measured(surface: &FnSurface, n: usize) -> Tessellation {
        measured_with(surface, surface.0, n)
    }

    /// [`measured`] of any surface whose points are `f`.
    fn measured_with(surface: &dyn LimitSurface, f: fn(f32, f32) -> Vec3A, n: usize) -> Tessellation {
        let verts: Vec<[f32; 3]> = (0..n)
            .flat_map(|j| (0..n).map(move |i| (i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32)))
            .map(|(u, v)| f(u, v).into())
            .collect();
        let (seam_radius, seam_normal) = seam_extent(surface, 0, UvRect::UNIT, &verts, n);
        Tessellation {
            n,
            verts: verts.into(),
            boxes: Default::default(),
            chord_error: 0.0,
            seam_radius,
            seam_normal,
            domain: GridDomain::Square,
        }
    }

    #[test]
    fn normal_extents_round_up_and_stay_within_an_eighth_of_an_octave() {
        for r in [1e-6f32, 1.0, 3e4] {
            for k in 0..200 {
                let x = r * (-(k as f32) * 0.17).exp2();
                let (below, above) = SeamNormal::encode(x, 0.5 * x, r).extents(r);
                assert!(below >= x && above >= 0.5 * x, "r {r}: {x} -> {below}, {} -> {above}", 0.5 * x);
                assert!(below <= (x * 1.0906).max(2.6e-10 * r), "r {r}: {x} -> {below} is loose");
            }
            assert_eq!(SeamNormal::encode(2.0 * r, f32::NAN, r).extents(r), (r, r), "beyond the radius, or unknown: the radius");
        }
        assert_eq!(SeamNormal::ISOTROPIC.extents(0.25), (0.25, 0.25));
    }

    #[test]
    fn a_flat_patch_with_curved_edges_gets_seam_boxes_as_thin_as_rounding() {
        // In z = 0, but the edges bow within the plane: the chords miss the edge curves by up
        // to ~0.03 sideways and not at all along the normal.
        let flat = FnSurface(|u, v| Vec3A::new(u + 0.12 * v * (1.0 - v), v + 0.12 * u * (1.0 - u), 0.0));
        for n in [2usize, 5, 17] {
            let t = measured(&flat, n);
            let (below, above) = t.seam_normal.extents(t.seam_radius);
            // A chord of length L of a curve of curvature 0.24 misses it by 0.24 L²/8 sideways.
            let sag = 0.24 / (8 * (n - 1) * (n - 1)) as f32;
            assert!(t.seam_radius > sag, "n {n}: the edges bow: radius {} against the sag {sag}", t.seam_radius);
            assert!(below < 1e-6 && above < 1e-6, "n {n}: along the normal only rounding: {below}, {above}");
            // Straight down just outside the middle of the first v = 0 chord, within the radius
            // (where a coarser neighbour's crack would be): the box is hit where it leaves it,
            // on the plane.
            let (a, b) = (t.vert(0, 0), t.vert(1, 0));
            let c = (b - a).normalize();
            let p = (a + b) * 0.5 + Vec3A::new(c.y, -c.x, 0.0) * (0.5 * t.seam_radius);
            let down = WatertightRay::new(p + Vec3A::Z, Vec3A::NEG_Z);
            assert!(
                crate::intersect::intersect_tessellation(&down, &t, 1, 0.0, f32::INFINITY, &crate::intersect::every_hit).is_none(),
                "outside the grid"
            );
            let h =
                intersect_with_seams(&down, &t, 1, SeamEdges::ALL, 0.0, f32::INFINITY, &crate::intersect::every_hit, &never_from_inside)
                    .expect("inside the seam box");
            assert!((h.t - 1.0).abs() < 1e-6, "n {n}: hit {} off the plane", h.t - 1.0);
            for stride in [2usize, 4].into_iter().filter(|s| (n - 1) % s == 0) {
                let (sb, _) = seam_box(&t, 0, 0, stride).unwrap();
                assert!(sb.below < 1e-6 && sb.above < 1e-6, "n {n} stride {stride}: merged chords stay flat: {sb:?}");
            }
        }
    }

    #[test]
    fn a_convex_edge_gets_a_seam_box_mostly_on_its_outer_side() {
        // A roof bowed up along u: the v = 0 and v = 1 edges arc 0.1 above their coarse chord
        // (+z, the side the grid's triangles face).
        let dome = FnSurface(|u, v| Vec3A::new(u, v, 0.4 * u * (1.0 - u)));
        let t = measured(&dome, 2);
        let (below, above) = t.seam_normal.extents(t.seam_radius);
        assert!((0.1..=0.14).contains(&above), "above {above}");
        assert!(below <= 0.35 * above && below >= 0.25 * 0.1, "below {below} (the floor is a quarter of above)");
        let (sb, ng) = seam_box(&t, 0, 0, 1).unwrap();
        assert!(ng.z > 0.0 && sb.e1.z > 0.99, "{sb:?}");
        // The curve's apex is inside its box; a point as far below the chord is not.
        assert!(sb.contains(Vec3A::new(0.5, 0.0, 0.1), 0.0));
        assert!(!sb.contains(Vec3A::new(0.5, 0.0, -0.1), 0.0));
    }

    #[test]
    fn an_s_shaped_quartic_edge_stays_inside_its_box_where_the_probes_miss_its_peak() {
        // A Loop patch's edge is a quartic: here z = 10·u(1 − u)·g(u) with g a quadratic whose
        // roots (0.34, 0.67) make the curve rise near the ends, between an end and the first
        // probe, to 1.8 times anything the probes at ¼, ½, ¾ see. 1.25 times the probes' largest
        // deviation left the peak outside the box; the curve the probes determine does not.
        let w = FnSurface(|u, v| {
            let _ = v;
            Vec3A::new(u, v, 10.0 * u * (1.0 - u) * (0.995 * u * u - u + 0.225))
        });
        let curve = |u: f32| (w.0)(u, 0.0);
        let (peak_u, peak) =
            (0..=1000).map(|i| i as f32 / 1000.0).map(|u| (u, curve(u).z.abs())).fold((0.0, 0.0), |m, x| if x.1 > m.1 { x } else { m });
        let probes = [0.25f32, 0.5, 0.75].map(|u| curve(u).z.abs()).into_iter().fold(0.0f32, f32::max);
        assert!(peak > 1.7 * probes, "the peak {peak} at u = {peak_u} hides from the probes' {probes}");
        let t = measured(&w, 2);
        assert!(t.seam_radius >= peak && t.seam_radius <= 1.2 * peak, "radius {} for a peak of {peak}", t.seam_radius);
        let (sb, _) = seam_box(&t, 0, 0, 1).unwrap();
        for i in 0..=100 {
            let c = curve(i as f32 / 100.0);
            assert!(sb.contains(c, 0.0), "the edge curve at u = {} ({c}) is outside its box {sb:?}", i as f32 / 100.0);
        }
    }

    #[test]
    fn a_piecewise_edge_stays_inside_its_box_when_its_knots_are_known() {
        // A single-crease patch's edges across the crease (sharpness 4): flat up to u = 15/16,
        // then the crease's fillet, z = 200·(u − 15/16)³, C² at the knot. The probes at ¼, ½,
        // ¾ of the one coarse chord see only the flat piece's deviation from it, and the
        // quadratic they determine falls short near the end; fitted piece by piece at the
        // knot, the box holds the whole curve.
        fn kinked(u: f32, v: f32) -> Vec3A {
            let d = (u - 15.0 / 16.0).max(0.0);
            Vec3A::new(u, v, 200.0 * d * d * d)
        }
        let curve = |u: f32| kinked(u, 0.0);
        let outside = |t: &Tessellation| {
            let (sb, _) = seam_box(t, 0, 0, 1).unwrap();
            (0..=1000).map(|i| i as f32 / 1000.0).filter(|&u| !sb.contains(curve(u), 0.0)).count()
        };
        let blind = measured(&FnSurface(kinked), 2);
        assert!(outside(&blind) > 0, "without the knot the box should miss part of the fillet (radius {})", blind.seam_radius);
        for knots in [[15.0 / 16.0, f32::NAN], [f32::NAN, 15.0 / 16.0], [0.5, 15.0 / 16.0]] {
            let t = measured_with(&KnotSurface(FnSurface(kinked), knots), kinked, 2);
            assert_eq!(outside(&t), 0, "knots {knots:?}: part of the edge curve is outside its box (radius {})", t.seam_radius);
            // Not wildly larger than the curve's largest distance from the chord (~0.046).
            assert!(t.seam_radius < 0.1, "knots {knots:?}: radius {}", t.seam_radius);
        }
        // A knot on a chord's end (a finer grid's vertex) changes nothing.
        let fine = measured_with(&KnotSurface(FnSurface(kinked), [15.0 / 16.0, f32::NAN]), kinked, 17);
        let plain = measured(&FnSurface(kinked), 17);
        assert_eq!(fine.seam_radius.to_bits(), plain.seam_radius.to_bits());
    }
}
