//! NURBS trim curves (UsdGeomNurbsPatch `trimCurve:*`, RenderMan's `RiTrimCurve`): closed
//! loops of rational B-spline curves in a patch's (u, v) parameter space that cut regions out
//! of the surface.
//!
//! The sense is RenderMan's odd rule, as Aqsis implements it (`CqTrimLoopArray::TrimPoint`):
//! a parameter point is kept when it lies inside an odd number of loops (a ray from it crosses
//! the loops an odd number of times), and passed over otherwise; the loops' orientation plays
//! no part. Maya's USD reader reads the loops the same way (the first loop the outer boundary,
//! holes inside it), so a surface with a hole carries an outer loop and the hole's loop, and a
//! single loop keeps its inside.
//!
//! Each loop is flattened at sync into one closed polyline whose chord error is below
//! [`TOLERANCE`] of the loops' extent (far below a texel of the patch's parameters), kept in
//! bands along v so a test reads only the edges at its v.

use std::sync::Arc;

/// The flattened polylines stray from the curves by at most this fraction of the largest side
/// of the loops' bounding box in (u, v).
pub const TOLERANCE: f64 = 1e-6;

/// The highest trim curve order accepted (degree 15).
pub const MAX_ORDER: usize = 16;

/// Trim curves as USD gives them; each slice is one `trimCurve:*` attribute.
#[derive(Clone, Copy, Debug, Default)]
pub struct TrimDesc<'a> {
    /// `trimCurve:counts`: curves per loop.
    pub counts: &'a [i64],
    /// `trimCurve:orders`: one per curve.
    pub orders: &'a [i64],
    /// `trimCurve:vertexCounts`: control points per curve.
    pub vertex_counts: &'a [i64],
    /// `trimCurve:knots`: `vertexCount + order` per curve, one curve after another.
    pub knots: &'a [f64],
    /// `trimCurve:ranges`: the parameter interval of each curve used; empty for each curve's
    /// whole domain.
    pub ranges: &'a [[f64; 2]],
    /// `trimCurve:points`: homogeneous `(u w, v w, w)`, one curve after another.
    pub points: &'a [[f64; 3]],
}

/// One curve's slices, checked.
struct Curve<'a> {
    order: usize,
    knots: &'a [f64],
    points: &'a [[f64; 3]],
    range: [f64; 2],
}

fn count(name: &str, i: usize, v: i64) -> Result<usize, String> {
    usize::try_from(v).map_err(|_| format!("trimCurve:{name}[{i}] = {v} is negative"))
}

impl TrimDesc<'_> {
    /// Every check [`TrimRegion::new`] makes, without flattening anything.
    ///
    /// # Errors
    /// As [`TrimRegion::new`].
    pub fn check(&self) -> Result<(), String> {
        self.loops().map(|_| ())
    }

    /// The curves of each loop, checked: every count matching, orders from 2 to
    /// [`MAX_ORDER`] and at most the curve's vertex count, knots finite and non-decreasing,
    /// ranges inside their curve's domain, points finite with positive weights.
    fn loops(&self) -> Result<Vec<Vec<Curve<'_>>>, String> {
        let n_curves = self.counts.iter().enumerate().try_fold(0usize, |sum, (i, &c)| {
            let c = count("counts", i, c)?;
            if c == 0 {
                return Err(format!("trimCurve:counts[{i}] = 0: a loop needs a curve"));
            }
            Ok(sum + c)
        })?;
        for (name, len) in [("orders", self.orders.len()), ("vertexCounts", self.vertex_counts.len())] {
            if len != n_curves {
                return Err(format!("trimCurve:{name} has {len} values for the {n_curves} curves of trimCurve:counts"));
            }
        }
        if !self.ranges.is_empty() && self.ranges.len() != n_curves {
            return Err(format!("trimCurve:ranges has {} values for the {n_curves} curves of trimCurve:counts", self.ranges.len()));
        }
        let mut n_points = 0usize;
        let mut n_knots = 0usize;
        for i in 0..n_curves {
            let order = count("orders", i, self.orders[i])?;
            let n = count("vertexCounts", i, self.vertex_counts[i])?;
            if !(2..=MAX_ORDER).contains(&order) {
                return Err(format!("trimCurve:orders[{i}] = {order} is not between 2 and {MAX_ORDER}"));
            }
            if n < order {
                return Err(format!("trimCurve:orders[{i}] = {order} is more than trimCurve:vertexCounts[{i}] = {n}"));
            }
            n_points += n;
            n_knots += n + order;
        }
        if self.points.len() != n_points {
            return Err(format!("trimCurve:points has {} values but trimCurve:vertexCounts sums to {n_points}", self.points.len()));
        }
        if self.knots.len() != n_knots {
            return Err(format!(
                "trimCurve:knots has {} values but trimCurve:vertexCounts and trimCurve:orders sum to {n_knots}",
                self.knots.len()
            ));
        }
        if let Some(i) = self.points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(format!("trimCurve:points[{i}] is not finite"));
        }
        if let Some(i) = self.points.iter().position(|p| p[2] <= 0.0) {
            return Err(format!("trimCurve:points[{i}] has weight w = {} (it must be positive)", self.points[i][2]));
        }
        if let Some(i) = self.knots.iter().position(|k| !k.is_finite()) {
            return Err(format!("trimCurve:knots[{i}] is not finite"));
        }
        let (mut at_point, mut at_knot, mut curve) = (0, 0, 0);
        let mut loops = Vec::with_capacity(self.counts.len());
        for &c in self.counts {
            let mut curves = Vec::new();
            for _ in 0..c {
                let order = self.orders[curve] as usize;
                let n = self.vertex_counts[curve] as usize;
                let knots = &self.knots[at_knot..at_knot + n + order];
                if let Some(k) = knots.windows(2).position(|w| w[1] < w[0]) {
                    return Err(format!("trimCurve:knots decrease at trimCurve:knots[{}] (curve {curve})", at_knot + k + 1));
                }
                let domain = [knots[order - 1], knots[n]];
                if !(domain[0] < domain[1]) {
                    return Err(format!("trimCurve:knots of curve {curve} span no parameter range"));
                }
                let range = match self.ranges.get(curve) {
                    None => domain,
                    Some(&[a, b]) => {
                        // Rounding in an exporter can put a range end a hair past the domain.
                        let slack = 1e-9 * (domain[1] - domain[0]);
                        if !(a.is_finite() && b.is_finite() && a < b && a >= domain[0] - slack && b <= domain[1] + slack) {
                            return Err(format!(
                                "trimCurve:ranges[{curve}] = ({a}, {b}) is not an increasing pair inside the curve's domain [{}, {}]",
                                domain[0], domain[1]
                            ));
                        }
                        [a.max(domain[0]), b.min(domain[1])]
                    }
                };
                curves.push(Curve { order, knots, points: &self.points[at_point..at_point + n], range });
                at_point += n;
                at_knot += n + order;
                curve += 1;
            }
            loops.push(curves);
        }
        Ok(loops)
    }
}

impl Curve<'_> {
    /// The curve's point at `t` (de Boor in homogeneous coordinates, then projected).
    fn at(&self, t: f64) -> [f64; 2] {
        let p = self.order - 1;
        let n = self.points.len();
        // The span k (p ≤ k < n) with knots[k] ≤ t < knots[k + 1], the last non-empty one at
        // the domain's end.
        let mut k = p;
        while k + 1 < n && self.knots[k + 1] <= t {
            k += 1;
        }
        let mut d = [[0.0f64; 3]; MAX_ORDER];
        d[..=p].copy_from_slice(&self.points[k - p..=k]);
        for r in 1..=p {
            for j in (r..=p).rev() {
                let i = k - p + j;
                let den = self.knots[i + p + 1 - r] - self.knots[i];
                let a = if den > 0.0 { (t - self.knots[i]) / den } else { 0.0 };
                let prev = d[j - 1];
                for (x, y) in d[j].iter_mut().zip(prev) {
                    *x = (1.0 - a) * y + a * *x;
                }
            }
        }
        [d[p][0] / d[p][2], d[p][1] / d[p][2]]
    }

    /// Appends the curve from its range's start (inclusive) to its end (exclusive: the next
    /// curve of the loop starts there), within `tol` of it.
    fn flatten(&self, tol: f64, out: &mut Vec<[f64; 2]>) {
        let [a, b] = self.range;
        // Each non-empty knot span inside the range is smooth: split it at its knots.
        let mut cuts = vec![a];
        cuts.extend(self.knots.iter().copied().filter(|&k| k > a && k < b));
        cuts.push(b);
        cuts.dedup();
        for w in cuts.windows(2) {
            let (t0, t1) = (w[0], w[1]);
            subdivide(self, t0, t1, self.at(t0), self.at(t1), tol, 0, out);
        }
    }
}

/// Pushes `p0` and the points between it and `p1` (exclusive) that bring the polyline within
/// `tol` of the curve over [t0, t1]: at least 8 pieces a span, so a span's wiggles are seen.
#[allow(clippy::too_many_arguments)]
fn subdivide(c: &Curve<'_>, t0: f64, t1: f64, p0: [f64; 2], p1: [f64; 2], tol: f64, depth: u32, out: &mut Vec<[f64; 2]>) {
    let tm = 0.5 * (t0 + t1);
    let pm = c.at(tm);
    let dev = distance_to_segment(pm, p0, p1);
    if depth < 3 || (dev > tol && depth < 16) {
        subdivide(c, t0, tm, p0, pm, tol, depth + 1, out);
        subdivide(c, tm, t1, pm, p1, tol, depth + 1, out);
    } else {
        out.push(p0);
    }
}

fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let s = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let (ex, ey) = (p[0] - a[0] - s * dx, p[1] - a[1] - s * dy);
    (ex * ex + ey * ey).sqrt()
}

/// Flattened trim loops, with the test of a parameter point. NURBS parameter space (the
/// knots' units).
#[derive(Clone, Debug)]
pub struct TrimRegion {
    /// Every loop's edges `(u0, v0, u1, v1)`, with v0 ≠ v1 (edges along u cross no ray along u).
    edges: Vec<[f64; 4]>,
    /// Bands along v: `band_start[b]..band_start[b + 1]` indexes `band_edges`, the edges whose
    /// v extent meets band b.
    band_start: Vec<u32>,
    band_edges: Vec<u32>,
    v0: f64,
    inv_band: f64,
    /// Vertices of the flattened loops, for the stats and tests.
    vertices: usize,
    tolerance: f64,
}

impl TrimRegion {
    /// Checks and flattens the trim curves.
    ///
    /// # Errors
    /// One line naming the `trimCurve:*` attribute that does not fit (counts that do not
    /// match, an order above the vertex count or out of 2..=16, knots decreasing or not
    /// finite, a range outside its curve, non-finite points, weights not positive).
    pub fn new(d: &TrimDesc<'_>) -> Result<TrimRegion, String> {
        let loops = d.loops()?;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in d.points {
            for c in 0..2 {
                lo[c] = lo[c].min(p[c] / p[2]);
                hi[c] = hi[c].max(p[c] / p[2]);
            }
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        if !extent.is_finite() {
            return Err("trimCurve:points are too large to trim with".into());
        }
        let tolerance = TOLERANCE * extent.max(f64::MIN_POSITIVE);
        let mut edges = Vec::new();
        let mut vertices = 0;
        let (mut v_lo, mut v_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for curves in &loops {
            let mut poly = Vec::new();
            for c in curves {
                c.flatten(tolerance, &mut poly);
            }
            vertices += poly.len();
            // Closed: the last vertex joins the first (the loop is explicitly closed in USD;
            // the closing edge spans any gap an exporter left).
            for (i, &a) in poly.iter().enumerate() {
                let b = poly[(i + 1) % poly.len()];
                if a[1] != b[1] {
                    v_lo = v_lo.min(a[1].min(b[1]));
                    v_hi = v_hi.max(a[1].max(b[1]));
                    edges.push([a[0], a[1], b[0], b[1]]);
                }
            }
        }
        let bands = (edges.len() / 4).clamp(1, 4096);
        let span = (v_hi - v_lo).max(f64::MIN_POSITIVE);
        let inv_band = bands as f64 / span;
        let band_of = |v: f64| (((v - v_lo) * inv_band).floor().max(0.0) as usize).min(bands - 1);
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); bands];
        for (i, e) in edges.iter().enumerate() {
            let (b0, b1) = (band_of(e[1].min(e[3])), band_of(e[1].max(e[3])));
            for l in &mut lists[b0..=b1] {
                l.push(i as u32);
            }
        }
        let mut band_start = Vec::with_capacity(bands + 1);
        let mut band_edges = Vec::new();
        for l in lists {
            band_start.push(band_edges.len() as u32);
            band_edges.extend(l);
        }
        band_start.push(band_edges.len() as u32);
        let v0 = if v_lo.is_finite() { v_lo } else { 0.0 };
        Ok(TrimRegion { edges, band_start, band_edges, v0, inv_band, vertices, tolerance })
    }

    /// Whether the surface at NURBS parameters (u, v) is kept: inside an odd number of loops.
    pub fn keeps(&self, u: f64, v: f64) -> bool {
        let bands = self.band_start.len() - 1;
        let b = (v - self.v0) * self.inv_band;
        if !(b >= 0.0 && b < bands as f64 + 1.0) || self.edges.is_empty() {
            return false;
        }
        let b = (b as usize).min(bands - 1);
        let mut inside = false;
        for &e in &self.band_edges[self.band_start[b] as usize..self.band_start[b + 1] as usize] {
            let [u0, v0, u1, v1] = self.edges[e as usize];
            // Half-open in v, so a vertex on the ray's line counts once.
            if (v0 <= v) != (v1 <= v) {
                let x = u0 + (v - v0) / (v1 - v0) * (u1 - u0);
                if x > u {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// Vertices of the flattened loops.
    pub fn vertex_count(&self) -> usize {
        self.vertices
    }

    /// How far (parameter units) the flattened loops may stray from the curves.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }
}

/// A trimmed surface's trim, read per patch: each patch's NURBS parameter rectangle maps its
/// own (u, v) to the trim's space.
#[derive(Debug)]
pub struct PatchTrim {
    pub region: TrimRegion,
    /// Per patch `[u0, v0, u1, v1]`, NURBS parameters.
    pub rects: Vec<[f64; 4]>,
}

impl PatchTrim {
    /// Whether the surface at patch `patch`'s own (u, v) is kept.
    #[inline]
    pub fn keeps(&self, patch: u32, u: f32, v: f32) -> bool {
        let Some(&[u0, v0, u1, v1]) = self.rects.get(patch as usize) else { return true };
        self.region.keeps(u0 + (u1 - u0) * f64::from(u), v0 + (v1 - v0) * f64::from(v))
    }
}

/// What a surface gives the tracer when it is trimmed.
pub type SharedTrim = Arc<PatchTrim>;

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed polyline loop (order 2) through `pts`, repeated first point at the end.
    fn polyline(pts: &[[f64; 2]]) -> (Vec<[f64; 3]>, Vec<f64>) {
        let mut p: Vec<[f64; 3]> = pts.iter().map(|q| [q[0], q[1], 1.0]).collect();
        p.push(p[0]);
        let n = p.len();
        let mut k = vec![0.0];
        k.extend((0..n).map(|i| i as f64));
        k.push((n - 1) as f64);
        (p, k)
    }

    /// The exact circle of radius `r` about `c` as a rational quadratic (nine points, weights
    /// 1 and √½; the points pre-weighted, homogeneous).
    pub(crate) fn circle(c: [f64; 2], r: f64) -> (Vec<[f64; 3]>, Vec<f64>) {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let unit = [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (-1.0, 1.0), (-1.0, 0.0), (-1.0, -1.0), (0.0, -1.0), (1.0, -1.0), (1.0, 0.0)];
        let p = unit
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| {
                let w = if i % 2 == 1 { h } else { 1.0 };
                [(c[0] + r * x) * w, (c[1] + r * y) * w, w]
            })
            .collect();
        (p, vec![0.0, 0.0, 0.0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1.0, 1.0, 1.0])
    }

    fn square_with_hole() -> (Vec<[f64; 3]>, Vec<f64>) {
        let (mut p, mut k) = polyline(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        let (cp, ck) = circle([0.5, 0.5], 0.3);
        p.extend(cp);
        k.extend(ck);
        (p, k)
    }

    #[test]
    fn a_square_with_a_circular_hole_keeps_the_ring_only() {
        let (p, k) = square_with_hole();
        let d = TrimDesc { counts: &[1, 1], orders: &[2, 3], vertex_counts: &[5, 9], knots: &k, ranges: &[], points: &p };
        let t = TrimRegion::new(&d).unwrap();
        let tol = t.tolerance();
        assert!(tol < 1e-5, "{tol}");
        let mut checked = 0;
        for j in 0..203 {
            for i in 0..197 {
                let (u, v) = ((i as f64 + 0.31) / 197.0, (j as f64 + 0.57) / 203.0);
                let r = ((u - 0.5).powi(2) + (v - 0.5).powi(2)).sqrt();
                // Within the tolerance of the circle either answer is right.
                if (r - 0.3).abs() <= 2.0 * tol {
                    continue;
                }
                assert_eq!(t.keeps(u, v), r > 0.3, "({u}, {v}) at radius {r}");
                checked += 1;
            }
        }
        assert!(checked > 39_000);
        // Outside every loop: passed over.
        assert!(!t.keeps(1.5, 0.5) && !t.keeps(0.5, -0.1));
        // The circle's polyline is within the tolerance of the circle, and fine enough
        // that points a little more than the tolerance inside the circle are trimmed.
        for a in 0..3600 {
            let th = a as f64 / 3600.0 * std::f64::consts::TAU;
            let (c, s) = (th.cos(), th.sin());
            assert!(!t.keeps(0.5 + (0.3 - 2.0 * tol) * c, 0.5 + (0.3 - 2.0 * tol) * s), "angle {th}");
            assert!(t.keeps(0.5 + (0.3 + 2.0 * tol) * c, 0.5 + (0.3 + 2.0 * tol) * s), "angle {th}");
        }
    }

    #[test]
    fn one_loop_keeps_its_inside_and_orientation_plays_no_part() {
        let (p, k) = circle([2.0, 3.0], 1.0);
        let mut rev: Vec<[f64; 3]> = p.clone();
        rev.reverse();
        for pts in [&p, &rev] {
            let d = TrimDesc { counts: &[1], orders: &[3], vertex_counts: &[9], knots: &k, ranges: &[], points: pts };
            let t = TrimRegion::new(&d).unwrap();
            assert!(t.keeps(2.0, 3.0) && t.keeps(2.9, 3.0));
            assert!(!t.keeps(3.1, 3.0) && !t.keeps(0.0, 0.0));
        }
    }

    #[test]
    fn a_loop_of_several_curves_and_ranges() {
        // The unit square as four linear curves, one with a range covering half its domain
        // (that curve's knots run to 2 and its points double back along the edge).
        let pts = [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0],
            [0.0, 5.0, 1.0],
        ];
        let knots = [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 2.0, 2.0];
        let ranges = [[0.0, 1.0], [0.0, 1.0], [0.0, 1.0], [0.0, 1.0]];
        let d =
            TrimDesc { counts: &[4], orders: &[2, 2, 2, 2], vertex_counts: &[2, 2, 2, 3], knots: &knots, ranges: &ranges, points: &pts };
        let t = TrimRegion::new(&d).unwrap();
        assert!(t.keeps(0.5, 0.5) && t.keeps(0.01, 0.99));
        assert!(!t.keeps(-0.01, 0.5) && !t.keeps(0.5, 1.01));
    }

    #[test]
    fn bad_trim_data_names_the_attribute() {
        let (p, k) = square_with_hole();
        let good = TrimDesc { counts: &[1, 1], orders: &[2, 3], vertex_counts: &[5, 9], knots: &k, ranges: &[], points: &p };
        TrimRegion::new(&good).unwrap();
        let err = |d: TrimDesc<'_>| TrimRegion::new(&d).unwrap_err();
        assert!(err(TrimDesc { counts: &[2, 1], ..good }).starts_with("trimCurve:orders has 2 values for the 3 curves"));
        assert!(err(TrimDesc { counts: &[1, -1], ..good }).starts_with("trimCurve:counts[1] = -1"));
        assert!(
            err(TrimDesc { orders: &[2, 10], ..good }).starts_with("trimCurve:orders[1] = 10 is more than trimCurve:vertexCounts[1] = 9")
        );
        assert!(err(TrimDesc { orders: &[1, 3], ..good }).starts_with("trimCurve:orders[0] = 1"));
        assert!(err(TrimDesc { points: &p[1..], ..good }).starts_with("trimCurve:points has 13 values"));
        assert!(err(TrimDesc { knots: &k[1..], ..good }).starts_with("trimCurve:knots has 18 values"));
        assert!(err(TrimDesc { ranges: &[[0.0, 4.0]], ..good }).starts_with("trimCurve:ranges has 1 values"));
        assert!(err(TrimDesc { ranges: &[[0.0, 5.0], [0.0, 1.0]], ..good }).starts_with("trimCurve:ranges[0] = (0, 5)"));
        let mut nan = p.clone();
        nan[7][1] = f64::NAN;
        assert!(err(TrimDesc { points: &nan, ..good }).starts_with("trimCurve:points[7] is not finite"));
        let mut zero_w = p.clone();
        zero_w[6][2] = 0.0;
        assert!(err(TrimDesc { points: &zero_w, ..good }).starts_with("trimCurve:points[6] has weight"));
        let mut dec = k.clone();
        dec[2] = 5.0;
        assert!(err(TrimDesc { knots: &dec, ..good }).starts_with("trimCurve:knots decrease"));
    }
}
