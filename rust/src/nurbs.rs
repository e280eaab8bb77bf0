//! USD `NurbsPatch` surfaces as rational Bézier patches, tessellated on demand like any other
//! limit surface.
//!
//! A NURBS surface is cut into Bézier patches by knot insertion (Boehm's algorithm, in f64):
//! every distinct knot inside the evaluated range, and the range's ends, are raised to
//! multiplicity `order − 1` in each direction, after which each non-empty knot span in u times
//! each in v is a tensor-product Bézier patch of the surface's degrees. The weights ride along
//! as the fourth homogeneous coordinate, so rational surfaces (conics, cylinders, spheres) are
//! exact. Each Bézier patch is one root patch of a [`LimitSurface`]: the tracer bounds it by
//! the hull of its control points, splits and tessellates it at the rate the ray's beam width
//! asks for and caches the grids in the geometry cache's tiers, as it does OpenSubdiv's
//! patches (the paper's §5). Positions and their first and second derivatives are evaluated
//! exactly (Bernstein polynomials, then the quotient rule for the weights), for shading, ray
//! differentials and the tessellation-error estimate.
//!
//! Conventions: `points` are USD's, u fastest (`points[v * u_count + u]`, UsdGeomNurbsPatch's
//! "row-major with U considered rows", as RiNuPatch); a patch's own (u, v) in [0, 1]² runs
//! along the NURBS parameters of its span. Object space throughout. Trim curves
//! ([`crate::trim`]) are attached with [`NurbsSurface::with_trim`]; the tracer reads them per
//! hit through [`LimitSurface::trim`].

use glam::{DVec3, Vec3A};

use crate::bounds::Bounds3;
use crate::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};

/// The highest order (degree + 1) rendered in either direction; evaluation keeps a patch's
/// rows on the stack.
pub const MAX_ORDER: usize = 8;

/// A NurbsPatch as USD gives it (UsdGeomNurbsPatch's attributes). Object space.
#[derive(Clone, Copy, Debug)]
pub struct NurbsDesc<'a> {
    /// Control points, `u_count × v_count`, u fastest.
    pub points: &'a [[f32; 3]],
    /// `pointWeights`: one per point, or empty for a polynomial surface.
    pub weights: &'a [f64],
    pub u_count: usize,
    pub v_count: usize,
    pub u_order: usize,
    pub v_order: usize,
    /// `u_count + u_order` values, non-decreasing.
    pub u_knots: &'a [f64],
    pub v_knots: &'a [f64],
    /// `uRange` / `vRange`: the parameter interval rendered; `None` for the whole domain
    /// `[knots[order − 1], knots[count]]`.
    pub u_range: Option<[f64; 2]>,
    pub v_range: Option<[f64; 2]>,
}

impl<'a> NurbsDesc<'a> {
    /// A patch rendered over its whole domain (no `uRange`/`vRange`): `counts` and `orders` are
    /// (u, v).
    pub fn whole(
        points: &'a [[f32; 3]],
        weights: &'a [f64],
        counts: (usize, usize),
        orders: (usize, usize),
        u_knots: &'a [f64],
        v_knots: &'a [f64],
    ) -> Self {
        let ((u_count, v_count), (u_order, v_order)) = (counts, orders);
        NurbsDesc { points, weights, u_count, v_count, u_order, v_order, u_knots, v_knots, u_range: None, v_range: None }
    }
}

/// A NurbsPatch's Bézier patches. Object space.
#[derive(Clone, Debug)]
pub struct NurbsSurface {
    /// Degrees in u and v (order − 1).
    p: usize,
    q: usize,
    /// Homogeneous control points `(x w, y w, z w, w)`, `(p + 1)(q + 1)` per patch, u fastest.
    cps: Vec<[f64; 4]>,
    /// Each patch's hull of its projected control points.
    bounds: Vec<Bounds3>,
    affine: Vec<bool>,
    /// Each patch's NURBS parameter interval, normalized to the rendered range: its `st`.
    st: Vec<[f64; 4]>,
    rational: bool,
    /// The rendered parameter ranges `[u0, u1, v0, v1]` (the knots' units): `st` is relative
    /// to them.
    range: [f64; 4],
    trim: Option<crate::trim::SharedTrim>,
}

/// One direction's knots after insertion, and the control net along it.
struct Spans {
    /// `(first control point, st start, st end)` of each non-empty span in the range.
    spans: Vec<(usize, f64, f64)>,
    /// The net, `count' × width` values, after insertion.
    net: Vec<f64>,
}

/// Checks one direction's counts and knots; names the USD attributes.
fn check_direction(dir: char, count: usize, order: usize, knots: &[f64], range: Option<[f64; 2]>) -> Result<[f64; 2], String> {
    if order < 2 {
        return Err(format!("{dir}Order = {order} must be at least 2"));
    }
    if order > MAX_ORDER {
        return Err(format!("{dir}Order = {order}: orders above {MAX_ORDER} are not rendered"));
    }
    if count < order {
        return Err(format!("{dir}VertexCount = {count} is less than {dir}Order = {order}"));
    }
    if knots.len() != count + order {
        return Err(format!(
            "{dir}Knots has {} values for {dir}VertexCount {count} and {dir}Order {order} (want {})",
            knots.len(),
            count + order
        ));
    }
    if let Some(i) = knots.iter().position(|k| !k.is_finite()) {
        return Err(format!("{dir}Knots[{i}] is not finite"));
    }
    if let Some(i) = knots.windows(2).position(|w| w[1] < w[0]) {
        return Err(format!("{dir}Knots decrease at {dir}Knots[{}]", i + 1));
    }
    let domain = [knots[order - 1], knots[count]];
    if !(domain[0] < domain[1]) {
        return Err(format!("{dir}Knots span no parameter range: nothing to render"));
    }
    let Some([a, b]) = range else { return Ok(domain) };
    if !(a.is_finite() && b.is_finite() && a < b) {
        return Err(format!("{dir}Range = ({a}, {b}) is not an increasing pair of numbers"));
    }
    // USD's range lies within the knots' domain; one outside renders the domain's part.
    let (a, b) = (a.max(domain[0]), b.min(domain[1]));
    if !(a < b) {
        return Err(format!("{dir}Range lies outside the knots' domain [{}, {}]", domain[0], domain[1]));
    }
    Ok([a, b])
}

/// Inserts knot `t` once into `knots` (degree `p`) and the net of `width`-wide points
/// (Boehm's algorithm; The NURBS Book, A5.1 with r = 1).
fn insert_knot(p: usize, knots: &mut Vec<f64>, net: &mut Vec<f64>, width: usize, t: f64) {
    // k: the span holding t (knots[k] <= t < knots[k + 1]); s: t's multiplicity.
    let k = knots.iter().rposition(|&x| x <= t).expect("t lies within the knots");
    let s = knots.iter().filter(|&&x| x == t).count();
    let n = net.len() / width;
    let mut out = Vec::with_capacity(net.len() + width);
    for i in 0..=n {
        if i + p <= k {
            out.extend_from_slice(&net[i * width..(i + 1) * width]);
        } else if i + s <= k {
            let a = (t - knots[i]) / (knots[i + p] - knots[i]);
            for c in 0..width {
                out.push(a * net[i * width + c] + (1.0 - a) * net[(i - 1) * width + c]);
            }
        } else {
            out.extend_from_slice(&net[(i - 1) * width..i * width]);
        }
    }
    knots.insert(k + 1, t);
    *net = out;
}

/// The Bézier segments of each non-empty knot span inside `range` (clipped to it), one after
/// another in the returned net. `net` holds `knots.len() − p − 1` points of `width` values.
///
/// Each span is cut out on its own: its p + 1 control points and 2p + 2 knots are a B-spline
/// whose domain is the span, and raising the span's ends to multiplicity p there makes its
/// net the Bézier one. The work is O(p² · width) a span, where inserting into the whole
/// knot vector would copy the whole net for each knot.
fn bezier_spans(p: usize, knots: &[f64], net: &[f64], width: usize, range: [f64; 2]) -> Spans {
    let n = net.len() / width;
    let len = range[1] - range[0];
    let mut spans = Vec::new();
    let mut out = Vec::new();
    for i in p..n {
        let (a, b) = (knots[i].max(range[0]), knots[i + 1].min(range[1]));
        if !(a < b) {
            continue;
        }
        let mut local_knots = knots[i - p..=i + p + 1].to_vec();
        let mut local = net[(i - p) * width..(i + 1) * width].to_vec();
        for t in [a, b] {
            let s = local_knots.iter().filter(|&&x| x == t).count();
            for _ in s..p {
                insert_knot(p, &mut local_knots, &mut local, width, t);
            }
        }
        // The span [a, b] is now a Bézier segment: the p + 1 points before its end knot.
        let Some(j) = (p..local_knots.len() - p - 1).find(|&j| local_knots[j] == a && local_knots[j + 1] == b) else {
            continue;
        };
        spans.push((out.len() / width, (a - range[0]) / len, (b - range[0]) / len));
        out.extend_from_slice(&local[(j - p) * width..(j + 1) * width]);
    }
    Spans { spans, net: out }
}

impl NurbsSurface {
    /// Every check [`NurbsSurface::new`] makes, without building anything: the rendered
    /// ranges in u and v.
    ///
    /// # Errors
    /// As [`NurbsSurface::new`].
    pub fn check(d: &NurbsDesc<'_>) -> Result<([f64; 2], [f64; 2]), String> {
        let (nu, nv) = (d.u_count, d.v_count);
        if nu.checked_mul(nv) != Some(d.points.len()) {
            return Err(format!("points has {} values but uVertexCount × vVertexCount = {nu} × {nv}", d.points.len()));
        }
        let u_range = check_direction('u', nu, d.u_order, d.u_knots, d.u_range)?;
        let v_range = check_direction('v', nv, d.v_order, d.v_knots, d.v_range)?;
        if let Some(i) = d.points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(format!("points[{i}] is not finite"));
        }
        if !d.weights.is_empty() && d.weights.len() != d.points.len() {
            return Err(format!("pointWeights has {} values for {} points", d.weights.len(), d.points.len()));
        }
        // Positive weights keep the surface inside its control points' hull, which bounds it.
        if let Some(i) = d.weights.iter().position(|w| !(w.is_finite() && *w > 0.0)) {
            return Err(format!("pointWeights[{i}] = {} must be a positive number", d.weights[i]));
        }
        Ok((u_range, v_range))
    }

    /// Cuts the NURBS surface into Bézier patches.
    ///
    /// # Errors
    /// One line naming the USD attribute: counts that do not match the points, orders below 2
    /// or above [`MAX_ORDER`], knots of the wrong length, decreasing or spanning nothing, a
    /// range outside the knots, non-finite points, weights that are not positive and finite.
    pub fn new(d: &NurbsDesc<'_>) -> Result<NurbsSurface, String> {
        let (u_range, v_range) = Self::check(d)?;
        let (nu, nv) = (d.u_count, d.v_count);
        let (p, q) = (d.u_order - 1, d.v_order - 1);
        let weight = |i: usize| d.weights.get(i).copied().unwrap_or(1.0);
        let rational = d.weights.windows(2).any(|w| w[0] != w[1]);
        // Along u first, with u the outer index (net[u][v][4]): each "point" of the insertion
        // is a whole column of homogeneous points.
        let mut net = Vec::with_capacity(nu * nv * 4);
        for u in 0..nu {
            for v in 0..nv {
                let i = v * nu + u;
                let w = weight(i);
                let [x, y, z] = d.points[i].map(f64::from);
                net.extend([x * w, y * w, z * w, w]);
            }
        }
        let us = bezier_spans(p, d.u_knots, &net, nv * 4, u_range);
        let nu2 = us.net.len() / (nv * 4);
        // Then along v, with v the outer index (net[v][u'][4]).
        let mut net = Vec::with_capacity(us.net.len());
        for v in 0..nv {
            for u in 0..nu2 {
                net.extend_from_slice(&us.net[(u * nv + v) * 4..(u * nv + v + 1) * 4]);
            }
        }
        let vs = bezier_spans(q, d.v_knots, &net, nu2 * 4, v_range);
        let mut s = NurbsSurface {
            p,
            q,
            cps: Vec::new(),
            bounds: Vec::new(),
            affine: Vec::new(),
            st: Vec::new(),
            rational,
            range: [u_range[0], u_range[1], v_range[0], v_range[1]],
            trim: None,
        };
        for &(v0, t0, t1) in &vs.spans {
            for &(u0, s0, s1) in &us.spans {
                let start = s.cps.len();
                for j in 0..=q {
                    for i in 0..=p {
                        let at = ((v0 + j) * nu2 + u0 + i) * 4;
                        let c = &vs.net[at..at + 4];
                        s.cps.push([c[0], c[1], c[2], c[3]]);
                    }
                }
                let patch = &s.cps[start..];
                s.bounds.push(Bounds3::from_points(patch.iter().map(|c| project(c).as_vec3().into())));
                s.affine.push(affine(patch, p, q));
                s.st.push([s0, t0, s1, t1]);
            }
        }
        if s.bounds.is_empty() {
            return Err("the knots leave no span inside uRange and vRange: nothing to render".into());
        }
        Ok(s)
    }

    /// The surface trimmed by `region` (NURBS parameters, the knots' units): each patch's
    /// parameter rectangle is kept with it, so a hit's patch (u, v) reads the region.
    pub fn with_trim(mut self, region: crate::trim::TrimRegion) -> Self {
        let [u0, u1, v0, v1] = self.range;
        let rects = self
            .st
            .iter()
            .map(|&[s0, t0, s1, t1]| [u0 + (u1 - u0) * s0, v0 + (v1 - v0) * t0, u0 + (u1 - u0) * s1, v0 + (v1 - v0) * t1])
            .collect();
        self.trim = Some(std::sync::Arc::new(crate::trim::PatchTrim { region, rects }));
        self
    }

    /// Degrees in u and v.
    pub fn degrees(&self) -> (usize, usize) {
        (self.p, self.q)
    }

    /// Whether any weight differs from the others (a rational surface).
    pub fn is_rational(&self) -> bool {
        self.rational
    }

    fn patch_cps(&self, patch: usize) -> &[[f64; 4]] {
        let n = (self.p + 1) * (self.q + 1);
        &self.cps[patch * n..(patch + 1) * n]
    }

    /// The surface and its derivatives at the patch's own (u, v), in f64.
    pub fn evaluate_f64(&self, patch: usize, u: f64, v: f64) -> [DVec3; 6] {
        let (p, q) = (self.p, self.q);
        let cps = self.patch_cps(patch);
        let bu = bernstein(p, u);
        let bv = bernstein(q, v);
        // Homogeneous sums: value, d/du, d/dv, d²/du², d²/dudv, d²/dv².
        let mut h = [[0.0f64; 4]; 6];
        for j in 0..=q {
            for i in 0..=p {
                let c = &cps[j * (p + 1) + i];
                let ws = [
                    bu[0][i] * bv[0][j],
                    bu[1][i] * bv[0][j],
                    bu[0][i] * bv[1][j],
                    bu[2][i] * bv[0][j],
                    bu[1][i] * bv[1][j],
                    bu[0][i] * bv[2][j],
                ];
                for (hk, wk) in h.iter_mut().zip(ws) {
                    for c4 in 0..4 {
                        hk[c4] += wk * c[c4];
                    }
                }
            }
        }
        let a = |k: usize| DVec3::new(h[k][0], h[k][1], h[k][2]);
        let w = |k: usize| h[k][3];
        // The quotient rule for S = A / w.
        let s = a(0) / w(0);
        let su = (a(1) - w(1) * s) / w(0);
        let sv = (a(2) - w(2) * s) / w(0);
        let suu = (a(3) - 2.0 * w(1) * su - w(3) * s) / w(0);
        let suv = (a(4) - w(1) * sv - w(2) * su - w(4) * s) / w(0);
        let svv = (a(5) - 2.0 * w(2) * sv - w(5) * s) / w(0);
        [s, su, sv, suu, suv, svv]
    }
}

fn project(c: &[f64; 4]) -> DVec3 {
    DVec3::new(c[0], c[1], c[2]) / c[3]
}

/// Whether a Bézier patch is an affine image of the unit square: equal weights and control
/// points evenly spaced along two edge vectors (a flat parallelogram, linearly parameterized).
fn affine(cps: &[[f64; 4]], p: usize, q: usize) -> bool {
    let w = cps[0][3];
    if cps.iter().any(|c| c[3] != w) {
        return false;
    }
    let at = |i: usize, j: usize| project(&cps[j * (p + 1) + i]);
    let (o, eu, ev) = (at(0, 0), at(p, 0) - at(0, 0), at(0, q) - at(0, 0));
    let scale = cps.iter().map(|c| project(c).abs().max_element()).fold(f64::MIN_POSITIVE, f64::max);
    (0..=q).all(|j| {
        (0..=p).all(|i| {
            let want = o + eu * (i as f64 / p as f64) + ev * (j as f64 / q as f64);
            (at(i, j) - want).abs().max_element() <= 4.0 * f64::from(f32::EPSILON) * scale
        })
    })
}

/// Bernstein polynomials of degree `n` at `t` and their first and second derivatives.
fn bernstein(n: usize, t: f64) -> [[f64; MAX_ORDER]; 3] {
    // rows[k][i] = B(i, k)(t), built up by de Casteljau's triangle; the derivatives are
    // differences of degrees n − 1 and n − 2.
    let mut rows = [[0.0; MAX_ORDER]; MAX_ORDER];
    rows[0][0] = 1.0;
    for k in 1..=n {
        for i in 0..=k {
            let left = if i < k { (1.0 - t) * rows[k - 1][i] } else { 0.0 };
            let right = if i > 0 { t * rows[k - 1][i - 1] } else { 0.0 };
            rows[k][i] = left + right;
        }
    }
    let at = |k: usize, i: usize, back: usize| -> f64 {
        // B(i − back, k), zero outside 0..=k.
        match i.checked_sub(back) {
            Some(i) if i <= k => rows[k][i],
            _ => 0.0,
        }
    };
    let mut out = [[0.0; MAX_ORDER]; 3];
    for i in 0..=n {
        out[0][i] = rows[n][i];
        if n >= 1 {
            out[1][i] = n as f64 * (at(n - 1, i, 1) - at(n - 1, i, 0));
        }
        if n >= 2 {
            out[2][i] = (n * (n - 1)) as f64 * (at(n - 2, i, 2) - 2.0 * at(n - 2, i, 1) + at(n - 2, i, 0));
        }
    }
    out
}

fn va(v: DVec3) -> Vec3A {
    Vec3A::new(v.x as f32, v.y as f32, v.z as f32)
}

impl LimitSurface for NurbsSurface {
    fn patch_count(&self) -> usize {
        self.bounds.len()
    }

    fn patch_param(&self, patch: usize) -> PatchParam {
        PatchParam::root(patch as u32, patch as u32, PatchKind::Other)
    }

    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        let Some(b) = self.bounds.get(patch) else { return Bounds3::EMPTY };
        // The control points were rounded to f32 after insertion (and evaluation rounds too).
        b.expanded(crate::ray::gamma(8) * b.max_abs())
    }

    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        if patch >= self.bounds.len() {
            return SurfacePoint::default();
        }
        let [p, dpdu, dpdv, dpduu, dpduv, dpdvv] = self.evaluate_f64(patch, f64::from(u), f64::from(v));
        SurfacePoint { p: va(p), dpdu: va(dpdu), dpdv: va(dpdv), dpduu: va(dpduu), dpduv: va(dpduv), dpdvv: va(dpdvv) }
    }

    fn control_face_count(&self) -> usize {
        self.bounds.len()
    }

    fn patch_is_affine(&self, patch: usize) -> bool {
        self.affine.get(patch).copied().unwrap_or(false)
    }

    fn trim(&self) -> Option<crate::trim::SharedTrim> {
        self.trim.clone()
    }

    /// Channel 0 is the surface's own `st`: the NURBS parameters, normalized over the rendered
    /// range (RenderMan's default for a NuPatch).
    fn face_varying(&self, channel: usize, patch: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        let [s0, t0, s1, t1] = self.st.get(patch).filter(|_| channel == 0)?.map(|x| x as f32);
        Some(([s0 + (s1 - s0) * u, t0 + (t1 - t0) * v], [s1 - s0, 0.0], [0.0, t1 - t0]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Cox–de Boor: the B-spline basis N(i, p) at t (half-open spans, 0/0 = 0).
    fn basis(knots: &[f64], i: usize, p: usize, t: f64) -> f64 {
        if p == 0 {
            return if knots[i] <= t && t < knots[i + 1] { 1.0 } else { 0.0 };
        }
        let mut out = 0.0;
        let d0 = knots[i + p] - knots[i];
        if d0 > 0.0 {
            out += (t - knots[i]) / d0 * basis(knots, i, p - 1, t);
        }
        let d1 = knots[i + p + 1] - knots[i + 1];
        if d1 > 0.0 {
            out += (knots[i + p + 1] - t) / d1 * basis(knots, i + 1, p - 1, t);
        }
        out
    }

    /// The NURBS surface at (s, t) straight from its definition.
    fn brute(d: &NurbsDesc<'_>, s: f64, t: f64) -> DVec3 {
        let (mut a, mut w) = (DVec3::ZERO, 0.0);
        for v in 0..d.v_count {
            for u in 0..d.u_count {
                let i = v * d.u_count + u;
                let b = basis(d.u_knots, u, d.u_order - 1, s)
                    * basis(d.v_knots, v, d.v_order - 1, t)
                    * d.weights.get(i).copied().unwrap_or(1.0);
                a += b * DVec3::from(d.points[i].map(f64::from));
                w += b;
            }
        }
        a / w
    }

    /// A deterministic wavy net of `nu × nv` points, with weights in [0.5, 2].
    fn net(nu: usize, nv: usize) -> (Vec<[f32; 3]>, Vec<f64>) {
        let mut pts = Vec::new();
        let mut ws = Vec::new();
        for v in 0..nv {
            for u in 0..nu {
                let (x, y) = (u as f32, v as f32);
                pts.push([x + 0.3 * (y * 1.7).sin(), y + 0.2 * (x * 2.3).cos(), (x * 0.9 + y * 1.3).sin()]);
                ws.push(0.5 + 1.5 * (0.5 + 0.5 * ((u * 7 + v * 3) as f64).sin()));
            }
        }
        (pts, ws)
    }

    /// Where (s, t) of the NURBS falls: the patch and its own (u, v), by the patches' `st`.
    fn locate(surface: &NurbsSurface, d: &NurbsDesc<'_>, s: f64, t: f64) -> (usize, f64, f64) {
        let [ua, ub] = d.u_range.unwrap_or([d.u_knots[d.u_order - 1], d.u_knots[d.u_count]]);
        let [va_, vb] = d.v_range.unwrap_or([d.v_knots[d.v_order - 1], d.v_knots[d.v_count]]);
        let (sn, tn) = ((s - ua) / (ub - ua), (t - va_) / (vb - va_));
        for (k, st) in surface.st.iter().enumerate() {
            let [s0, t0, s1, t1] = *st;
            if s0 <= sn && sn < s1 && t0 <= tn && tn < t1 {
                return (k, (sn - s0) / (s1 - s0), (tn - t0) / (t1 - t0));
            }
        }
        panic!("({s}, {t}) is in no patch");
    }

    fn check_against_brute(d: &NurbsDesc<'_>) {
        let surface = NurbsSurface::new(d).unwrap();
        let [ua, ub] = d.u_range.unwrap_or([d.u_knots[d.u_order - 1], d.u_knots[d.u_count]]);
        let [va_, vb] = d.v_range.unwrap_or([d.v_knots[d.v_order - 1], d.v_knots[d.v_count]]);
        for a in 0..23 {
            for b in 0..19 {
                let s = ua + (ub - ua) * (a as f64 + 0.37) / 23.0;
                let t = va_ + (vb - va_) * (b as f64 + 0.61) / 19.0;
                let want = brute(d, s, t);
                let (k, u, v) = locate(&surface, d, s, t);
                let got = surface.evaluate_f64(k, u, v)[0];
                assert!((got - want).length() < 1e-9, "({s}, {t}): {got} vs {want}");
                assert!(surface.patch_bounds(k).contains(va(got)), "({s}, {t}) outside patch {k}'s bounds");
            }
        }
    }

    #[test]
    fn rational_non_uniform_patches_match_cox_de_boor() {
        let (pts, ws) = net(7, 6);
        // Cubic in u with a double interior knot and unclamped ends, quadratic in v clamped
        // with a triple (C⁻¹... here C⁰ at degree 2: multiplicity 2) knot.
        let uk = [0.0, 0.5, 1.0, 2.0, 3.0, 3.0, 4.5, 5.0, 6.0, 6.5, 7.0];
        let vk = [0.0, 0.0, 0.0, 1.0, 2.0, 2.0, 3.0, 3.0, 3.0];
        let mut d = NurbsDesc::whole(&pts, &ws, (7, 6), (4, 3), &uk, &vk);
        check_against_brute(&d);
        let surface = NurbsSurface::new(&d).unwrap();
        // u spans [2, 3], [3, 4.5], [4.5, 5] of the domain [2, 5]; v spans [0, 1], [1, 2], [2, 3].
        assert_eq!(surface.patch_count(), 9);
        assert!(surface.is_rational());
        // A range inside one span and across a knot.
        d.u_range = Some([2.25, 4.0]);
        d.v_range = Some([0.5, 2.5]);
        check_against_brute(&d);
        assert_eq!(NurbsSurface::new(&d).unwrap().patch_count(), 2 * 3);
        // A range inside one span: one patch across u.
        d.u_range = Some([3.2, 3.9]);
        check_against_brute(&d);
        assert_eq!(NurbsSurface::new(&d).unwrap().patch_count(), 3);
        // Polynomial: no weights.
        d.weights = &[];
        check_against_brute(&d);
        // A larger net of many spans, with knots of every multiplicity up to the order.
        let (pts, ws) = net(40, 30);
        let uk: Vec<f64> = (0..44).map(|i| f64::from((i / 2) as u32) + if i % 7 == 0 { 0.25 } else { 0.0 }).collect();
        let mut uk = uk;
        uk.sort_by(f64::total_cmp);
        let vk: Vec<f64> = (0_i32..33).map(|i| f64::from((i - 2).clamp(0, 28) / 3)).collect();
        let big = NurbsDesc::whole(&pts, &ws, (40, 30), (4, 3), &uk, &vk);
        check_against_brute(&big);
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let (pts, ws) = net(5, 5);
        let uk = [0.0, 0.0, 0.0, 0.0, 0.4, 1.0, 1.0, 1.0, 1.0];
        let vk = [0.0, 0.0, 0.0, 0.3, 0.7, 1.0, 1.0, 1.0];
        let d = NurbsDesc::whole(&pts, &ws, (5, 5), (4, 3), &uk, &vk);
        let s = NurbsSurface::new(&d).unwrap();
        let h = 1e-5;
        for k in 0..s.patch_count() {
            for (u, v) in [(0.3, 0.6), (0.9, 0.1), (0.5, 0.5)] {
                let e = s.evaluate_f64(k, u, v);
                let f = |u: f64, v: f64| s.evaluate_f64(k, u, v);
                let du = (f(u + h, v)[0] - f(u - h, v)[0]) / (2.0 * h);
                let dv = (f(u, v + h)[0] - f(u, v - h)[0]) / (2.0 * h);
                let duu = (f(u + h, v)[1] - f(u - h, v)[1]) / (2.0 * h);
                let duv = (f(u, v + h)[1] - f(u, v - h)[1]) / (2.0 * h);
                let dvv = (f(u, v + h)[2] - f(u, v - h)[2]) / (2.0 * h);
                for (got, want, name) in
                    [(e[1], du, "dpdu"), (e[2], dv, "dpdv"), (e[3], duu, "dpduu"), (e[4], duv, "dpduv"), (e[5], dvv, "dpdvv")]
                {
                    assert!((got - want).length() < 1e-5 * want.length().max(1.0), "patch {k} ({u}, {v}) {name}: {got} vs {want}");
                }
            }
        }
    }

    /// A quarter of the unit cylinder about z, exact as a rational quadratic in u, linear in v.
    pub(crate) fn quarter_cylinder() -> (Vec<[f32; 3]>, Vec<f64>) {
        let w = std::f64::consts::FRAC_1_SQRT_2;
        let pts = vec![[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 2.0], [1.0, 1.0, 2.0], [0.0, 1.0, 2.0]];
        (pts, vec![1.0, w, 1.0, 1.0, w, 1.0])
    }

    #[test]
    fn a_rational_quarter_cylinder_is_exact() {
        let (pts, ws) = quarter_cylinder();
        let (uk, vk) = ([0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0]);
        let d = NurbsDesc::whole(&pts, &ws, (3, 2), (3, 2), &uk, &vk);
        let s = NurbsSurface::new(&d).unwrap();
        assert_eq!(s.patch_count(), 1);
        assert!(!s.patch_is_affine(0));
        for a in 0..=10 {
            for b in 0..=4 {
                let (u, v) = (a as f32 / 10.0, b as f32 / 4.0);
                let e = s.evaluate(0, u, v);
                let r = (e.p.x * e.p.x + e.p.y * e.p.y).sqrt();
                assert!((r - 1.0).abs() < 1e-6, "({u}, {v}): radius {r}");
                assert!((e.p.z - 2.0 * v).abs() < 1e-6);
                // The normal dpdu × dpdv is radial.
                let n = e.dpdu.cross(e.dpdv).normalize();
                let radial = Vec3A::new(e.p.x, e.p.y, 0.0).normalize();
                assert!(n.dot(radial).abs() > 1.0 - 1e-6, "({u}, {v}): normal {n}");
            }
        }
    }

    #[test]
    fn an_evenly_spaced_bicubic_plane_is_affine_and_a_bent_one_is_not() {
        let mut pts = Vec::new();
        for v in 0..4 {
            for u in 0..4 {
                pts.push([u as f32 * 2.0 + v as f32 * 0.5, v as f32, 0.0]);
            }
        }
        let k = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        let d = NurbsDesc::whole(&pts, &[], (4, 4), (4, 4), &k, &k);
        assert!(NurbsSurface::new(&d).unwrap().patch_is_affine(0));
        let mut bent = pts.clone();
        bent[5][2] = 0.1;
        let d = NurbsDesc { points: &bent, ..d };
        assert!(!NurbsSurface::new(&d).unwrap().patch_is_affine(0));
    }

    #[test]
    fn bad_input_is_refused_naming_the_attribute() {
        let (pts, ws) = net(4, 4);
        let k = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        let good = NurbsDesc::whole(&pts, &ws, (4, 4), (4, 4), &k, &k);
        NurbsSurface::new(&good).unwrap();
        let err = |d: NurbsDesc<'_>| NurbsSurface::new(&d).unwrap_err();
        assert!(
            err(NurbsDesc { u_knots: &k[1..], ..good }).starts_with("uKnots has 7 values"),
            "{}",
            err(NurbsDesc { u_knots: &k[1..], ..good })
        );
        assert!(err(NurbsDesc { points: &pts[1..], ..good }).starts_with("points has 15 values"));
        assert!(err(NurbsDesc { v_order: 1, ..good }).starts_with("vOrder = 1"));
        assert!(err(NurbsDesc { v_order: 9, ..good }).starts_with("vOrder = 9"));
        let mut bad_w = ws.clone();
        bad_w[3] = -1.0;
        assert!(err(NurbsDesc { weights: &bad_w, ..good }).starts_with("pointWeights[3] = -1"));
        assert!(err(NurbsDesc { weights: &ws[1..], ..good }).starts_with("pointWeights has 15 values"));
        let dec = [0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 1.0, 1.0];
        assert!(err(NurbsDesc { v_knots: &dec, ..good }).starts_with("vKnots decrease"));
        assert!(err(NurbsDesc { u_range: Some([2.0, 3.0]), ..good }).starts_with("uRange lies outside"));
        let mut nan = pts.clone();
        nan[2][1] = f32::NAN;
        assert!(err(NurbsDesc { points: &nan, ..good }).starts_with("points[2]"));
    }
}
