//! USD `BasisCurves` (and, through the Python front end, `NurbsCurves` converted to Bézier
//! segments) ray traced as curves: each cubic segment is tessellated on demand into linear
//! pieces at the rate the ray's beam width asks for, and those pieces are kept in the same
//! three-tier geometry cache as subpatch grids (the paper's method, applied to curves).
//!
//! # Segments
//! Every curve becomes cubic Bézier segments at build time: `bezier` as authored, `bspline` and
//! `catmullRom` by their basis-change matrices, `linear` as Bézier segments with their inner
//! control points at the thirds (straight, so one piece represents them exactly). Wrap follows
//! UsdGeomBasisCurves: `nonperiodic` (bezier: (n − 4)/3 + 1 segments, bspline/catmullRom: n − 3,
//! linear: n − 1), `periodic` (bezier: n/3, the others n; the last segment wraps to the first
//! vertex) and `pinned` (bspline and catmullRom get a phantom vertex 2P₀ − P₁ at each end, so
//! the curve ends at its end vertices: n − 1 segments; bezier and linear as nonperiodic).
//! Widths and normals are converted alike: `vertex` values by the same basis as the points,
//! `varying` values linearly between a segment's ends, `uniform` one per curve, `constant` one.
//!
//! Each segment is a patch of a [`LimitSurface`] (so the tracer's bottom-level BVH is over the
//! segments, never over the pieces: a million hair segments cost one root subpatch each and
//! their tessellations live in the cache's budget). Its box is its control hull grown by its
//! largest half width. The patch's own u runs along the segment (the Bézier parameter), v
//! around the tube (a turn) or across the ribbon (0 → 1).
//!
//! # Shapes
//! - `tube` (USD `type` unset or `tube`): a round tube of diameter `widths`. A piece is the
//!   frustum between its two end circles plus a sphere at each piece vertex, so consecutive
//!   pieces meet without gaps and curve ends are round.
//! - `ribbon` with authored `normals`: a flat strip of width `widths` through the curve, facing
//!   the normals (dP/du × dP/dv points along them).
//! - `ribbon` without normals: a flat strip facing each ray (as Storm draws camera-facing
//!   ribbons), intersected where the ray passes within half the width of the centreline. Its
//!   shading surface is the tube's, at the point whose normal faces the ray.
//!
//! # Derivatives
//! Positions and first derivatives along the curve are the Bézier's, in closed form; the frame
//! around the curve (N(u) = T × a for a fixed axis a per segment, B = N × T) is differentiated
//! by central differences in f64, and the second derivatives of the surface likewise; around
//! the tube (v) all derivatives are closed form. Ray differentials, shading normals and texture
//! filters therefore see a curve as any other surface.

use glam::{DVec3, Vec3A};

use crate::bounds::Bounds3;
use crate::geometry_cache::Tier;
use crate::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};
use crate::ray::gamma;
use crate::tessellate::{GridBoxes, GridDomain, Tessellation};

/// USD's `type`: straight segments between vertices, or cubic segments of a basis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CurveType {
    Linear,
    Cubic,
}

/// USD's `basis` for cubic curves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Basis {
    Bezier,
    Bspline,
    CatmullRom,
}

/// USD's `wrap`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Wrap {
    Nonperiodic,
    Periodic,
    Pinned,
}

/// A primvar's interpolation, as USD names it (`faceVarying` is `varying` on curves).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Interpolation {
    Constant,
    Uniform,
    Vertex,
    Varying,
}

/// What a curve looks like across: a round tube, or a flat ribbon.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Style {
    Tube,
    Ribbon,
}

impl CurveType {
    pub fn from_usd(token: &str) -> Option<Self> {
        match token {
            "linear" => Some(CurveType::Linear),
            "cubic" => Some(CurveType::Cubic),
            _ => None,
        }
    }
}

impl Basis {
    pub fn from_usd(token: &str) -> Option<Self> {
        match token {
            "bezier" => Some(Basis::Bezier),
            "bspline" => Some(Basis::Bspline),
            "catmullRom" => Some(Basis::CatmullRom),
            _ => None,
        }
    }
}

impl Wrap {
    pub fn from_usd(token: &str) -> Option<Self> {
        match token {
            "nonperiodic" => Some(Wrap::Nonperiodic),
            "periodic" => Some(Wrap::Periodic),
            "pinned" => Some(Wrap::Pinned),
            _ => None,
        }
    }
}

impl Interpolation {
    /// USD's interpolation token; `faceVarying` reads as `varying` (curves have no faces).
    pub fn from_usd(token: &str) -> Option<Self> {
        match token {
            "constant" => Some(Interpolation::Constant),
            "uniform" => Some(Interpolation::Uniform),
            "vertex" => Some(Interpolation::Vertex),
            "varying" | "faceVarying" => Some(Interpolation::Varying),
            _ => None,
        }
    }
}

impl Style {
    /// The `primvars:mipray:curveStyle` token (`tube`, `ribbon`); the
    /// empty token is a tube.
    pub fn from_usd(token: &str) -> Option<Self> {
        match token {
            "" | "tube" => Some(Style::Tube),
            "ribbon" => Some(Style::Ribbon),
            _ => None,
        }
    }
}

/// A `BasisCurves` prim's data, as authored. Object space, object units.
#[derive(Clone, Debug)]
pub struct CurvesDesc<'a> {
    pub points: &'a [[f32; 3]],
    /// `curveVertexCounts`.
    pub counts: &'a [i32],
    pub curve_type: CurveType,
    pub basis: Basis,
    pub wrap: Wrap,
    /// Diameters; empty means USD's fallback width, 1.
    pub widths: &'a [f32],
    pub widths_interpolation: Interpolation,
    /// Ribbon orientation; empty for none.
    pub normals: &'a [[f32; 3]],
    pub normals_interpolation: Interpolation,
    pub style: Style,
}

/// A curve's surface: its Bézier segments, each a patch. Object units.
#[derive(Clone, Debug)]
pub struct CurvesSurface {
    /// Control points of each segment's cubic Bézier; of every sample's segments for curves
    /// that move within the shutter, sample-major (sample k's segment s at k · segments + s).
    cps: Vec<[[f32; 3]; 4]>,
    /// Half widths of each segment as a cubic Bézier in u, laid out as `cps`.
    half_widths: Vec<[f32; 4]>,
    /// Ribbon normals per segment as a cubic Bézier in u (oriented ribbons only; the frame's,
    /// the same at every sample).
    normals: Vec<[[f32; 3]; 4]>,
    /// The samples' shutter times (0 = open, 1 = close), strictly increasing, for curves whose
    /// control points or widths move within the shutter ([`CurvesSurface::deforming`]); empty
    /// for curves that keep still.
    times: Vec<f32>,
    /// The curve each segment belongs to.
    curve: Vec<u32>,
    /// Straight segments (linear curves): one piece is exact.
    straight: Vec<bool>,
    style: Style,
    curve_count: usize,
    /// Curves drawn other than as authored, named for the warning and the stats (see
    /// [`CurvesSurface::new`]); `None` when every curve is drawn as authored.
    fallbacks: Option<String>,
}

/// Bézier control points of a window of 4 (cubic) or 2 (linear) values.
fn to_bezier<const D: usize>(curve_type: CurveType, basis: Basis, w: &[[f64; D]]) -> [[f64; D]; 4] {
    let m: [[f64; 4]; 4] = match (curve_type, basis) {
        (CurveType::Linear, _) => {
            let mut out = [[0.0; D]; 4];
            for k in 0..D {
                out[0][k] = w[0][k];
                out[1][k] = (2.0 * w[0][k] + w[1][k]) / 3.0;
                out[2][k] = (w[0][k] + 2.0 * w[1][k]) / 3.0;
                out[3][k] = w[1][k];
            }
            return out;
        }
        (CurveType::Cubic, Basis::Bezier) => [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
        (CurveType::Cubic, Basis::Bspline) => {
            let s = 1.0 / 6.0;
            [[s, 4.0 * s, s, 0.0], [0.0, 4.0 * s, 2.0 * s, 0.0], [0.0, 2.0 * s, 4.0 * s, 0.0], [0.0, s, 4.0 * s, s]]
        }
        (CurveType::Cubic, Basis::CatmullRom) => {
            let s = 1.0 / 6.0;
            [[0.0, 1.0, 0.0, 0.0], [-s, 1.0, s, 0.0], [0.0, s, 1.0, -s], [0.0, 0.0, 1.0, 0.0]]
        }
    };
    let mut out = [[0.0; D]; 4];
    for (row, o) in m.iter().zip(out.iter_mut()) {
        for (c, x) in row.iter().zip(w) {
            for k in 0..D {
                o[k] += c * x[k];
            }
        }
    }
    out
}

/// A linear ramp from `a` to `b` as a cubic Bézier.
fn ramp<const D: usize>(a: [f64; D], b: [f64; D]) -> [[f64; D]; 4] {
    let mut out = [[0.0; D]; 4];
    for k in 0..D {
        out[0][k] = a[k];
        out[1][k] = (2.0 * a[k] + b[k]) / 3.0;
        out[2][k] = (a[k] + 2.0 * b[k]) / 3.0;
        out[3][k] = b[k];
    }
    out
}

/// How the vertices of one curve of `n` vertices make segments: the window size, the vertex
/// index of each window's start (indices run past n − 1 for periodic curves and wrap, and are
/// −1 / n for pinned curves' phantom vertices), and the number of `varying` values.
struct Windows {
    size: usize,
    starts: Vec<i64>,
    varying: usize,
}

fn windows(curve_type: CurveType, basis: Basis, wrap: Wrap, n: usize) -> Result<Windows, String> {
    let n_i = n as i64;
    match curve_type {
        CurveType::Linear => {
            let (segs, min) = if wrap == Wrap::Periodic { (n, 3) } else { (n.saturating_sub(1), 2) };
            if n < min {
                return Err(format!("has {n} vertices; a linear {} curve needs at least {min}", wrap_name(wrap)));
            }
            Ok(Windows { size: 2, starts: (0..segs as i64).collect(), varying: n })
        }
        CurveType::Cubic => {
            let (size, starts, varying): (usize, Vec<i64>, usize) = match (basis, wrap) {
                (Basis::Bezier, Wrap::Periodic) => {
                    if n < 3 || n % 3 != 0 {
                        return Err(format!("has {n} vertices; a periodic bezier curve needs a multiple of 3"));
                    }
                    (4, (0..n_i / 3).map(|i| 3 * i).collect(), n / 3)
                }
                (Basis::Bezier, _) => {
                    if n < 4 || (n - 4) % 3 != 0 {
                        return Err(format!("has {n} vertices; a bezier curve needs 4 + 3k"));
                    }
                    let segs = (n - 4) / 3 + 1;
                    (4, (0..segs as i64).map(|i| 3 * i).collect(), segs + 1)
                }
                (_, Wrap::Periodic) => {
                    if n < 3 {
                        return Err(format!("has {n} vertices; a periodic cubic curve needs at least 3"));
                    }
                    (4, (0..n_i).collect(), n)
                }
                (_, Wrap::Nonperiodic) => {
                    if n < 4 {
                        return Err(format!("has {n} vertices; a nonperiodic cubic curve needs at least 4"));
                    }
                    (4, (0..n_i - 3).collect(), n - 2)
                }
                (_, Wrap::Pinned) => {
                    if n < 2 {
                        return Err(format!("has {n} vertices; a pinned cubic curve needs at least 2"));
                    }
                    (4, (-1..n_i - 2).collect(), n)
                }
            };
            Ok(Windows { size, starts, varying })
        }
    }
}

fn wrap_name(wrap: Wrap) -> &'static str {
    match wrap {
        Wrap::Nonperiodic => "nonperiodic",
        Wrap::Periodic => "periodic",
        Wrap::Pinned => "pinned",
    }
}

/// Value `i` of a curve's vertex values `v` (its own slice), wrapping for periodic curves and
/// reflecting for pinned curves' phantom vertices (2P₀ − P₁, 2Pₙ₋₁ − Pₙ₋₂).
fn vertex_value<const D: usize>(v: &[[f64; D]], i: i64, pinned: bool) -> [f64; D] {
    let n = v.len() as i64;
    let reflect = |a: [f64; D], b: [f64; D]| {
        let mut out = [0.0; D];
        for k in 0..D {
            out[k] = 2.0 * a[k] - b[k];
        }
        out
    };
    if pinned && i < 0 && n >= 2 {
        reflect(v[0], v[1])
    } else if pinned && i == n && n >= 2 {
        reflect(v[(n - 1) as usize], v[(n - 2) as usize])
    } else {
        v[i.rem_euclid(n) as usize]
    }
}

/// A primvar spread over the curves: each segment's cubic Bézier of it.
#[allow(clippy::too_many_arguments)]
fn primvar_segments<const D: usize>(
    name: &str,
    values: &[[f64; D]],
    interp: Interpolation,
    desc: &CurvesDesc<'_>,
    wins: &[Windows],
    n_vertices: usize,
    n_varying: usize,
) -> Result<Vec<[[f64; D]; 4]>, String> {
    let curves = desc.counts.len();
    let want = match interp {
        Interpolation::Constant => 1,
        Interpolation::Uniform => curves,
        Interpolation::Vertex => n_vertices,
        Interpolation::Varying => n_varying,
    };
    if values.len() != want {
        let what = match interp {
            Interpolation::Constant => "constant: want 1".to_string(),
            Interpolation::Uniform => format!("uniform: want one per curve, {curves}"),
            Interpolation::Vertex => format!("vertex: want one per vertex, {n_vertices}"),
            Interpolation::Varying => format!("varying: want one per segment end, {n_varying}"),
        };
        return Err(format!("{name} has {} values ({what})", values.len()));
    }
    let pinned = desc.wrap == Wrap::Pinned && desc.curve_type == CurveType::Cubic && desc.basis != Basis::Bezier;
    let mut out = Vec::new();
    // A window of two is a straight piece: a linear curve's, or a cubic curve's drawn as its
    // control polygon (see `CurvesSurface::new`).
    let window_type = |w: &Windows| if w.size == 2 { CurveType::Linear } else { desc.curve_type };
    let (mut vertex0, mut varying0) = (0usize, 0usize);
    for (c, (w, &count)) in wins.iter().zip(desc.counts).enumerate() {
        let n = count as usize;
        for (s, &start) in w.starts.iter().enumerate() {
            out.push(match interp {
                Interpolation::Constant => [values[0]; 4],
                Interpolation::Uniform => [values[c]; 4],
                Interpolation::Vertex => {
                    let own = &values[vertex0..vertex0 + n];
                    let window: Vec<[f64; D]> = (0..w.size as i64).map(|k| vertex_value(own, start + k, pinned)).collect();
                    to_bezier(window_type(w), desc.basis, &window)
                }
                Interpolation::Varying => {
                    let own = &values[varying0..varying0 + w.varying];
                    ramp(own[s % own.len()], own[(s + 1) % own.len()])
                }
            });
        }
        vertex0 += n;
        varying0 += w.varying;
    }
    Ok(out)
}

fn f32x3(v: [f64; 3]) -> [f32; 3] {
    [v[0] as f32, v[1] as f32, v[2] as f32]
}

fn dv(v: [f32; 3]) -> DVec3 {
    DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
}

fn va(v: DVec3) -> Vec3A {
    Vec3A::new(v.x as f32, v.y as f32, v.z as f32)
}

/// A cubic Bézier's value, first and second derivatives at t.
fn bezier3(c: &[DVec3; 4], t: f64) -> (DVec3, DVec3, DVec3) {
    let s = 1.0 - t;
    let p = c[0] * (s * s * s) + c[1] * (3.0 * s * s * t) + c[2] * (3.0 * s * t * t) + c[3] * (t * t * t);
    let d = (c[1] - c[0]) * (3.0 * s * s) + (c[2] - c[1]) * (6.0 * s * t) + (c[3] - c[2]) * (3.0 * t * t);
    let dd = (c[2] - c[1] * 2.0 + c[0]) * (6.0 * s) + (c[3] - c[2] * 2.0 + c[1]) * (6.0 * t);
    (p, d, dd)
}

fn bezier1(c: &[f32; 4], t: f64) -> (f64, f64) {
    let c = c.map(f64::from);
    let s = 1.0 - t;
    let p = c[0] * s * s * s + c[1] * 3.0 * s * s * t + c[2] * 3.0 * s * t * t + c[3] * t * t * t;
    let d = (c[1] - c[0]) * 3.0 * s * s + (c[2] - c[1]) * 6.0 * s * t + (c[3] - c[2]) * 3.0 * t * t;
    (p, d)
}

/// Pieces per tier: one (coarse), 4 (medium; read at stride 2 for 2) and 16 (fine; stride 2
/// for 8), the rates 1, 2, 4, 8, 16 of a subpatch's quads per side.
pub const fn tier_pieces(tier: Tier) -> usize {
    match tier {
        Tier::Coarse => 1,
        Tier::Medium => 4,
        Tier::Fine => 16,
    }
}

/// A hit on a curve's tessellation: the ray's t, the segment's (u, v), and the object-space
/// normal of the piece hit (pointing toward the ray's side for camera-facing ribbons).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurveHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub n: Vec3A,
    /// Camera-facing ribbons: a hit of a ray leaving the curve near its origin is the same
    /// ribbon turned toward the new ray, passed over either way within the own-surface window.
    pub facing: bool,
    /// How far the surface hit may lie from where another ray finds it (object units): 0 for
    /// tubes and oriented ribbons, whose surface is fixed; a camera-facing ribbon turns to
    /// face each ray, so a ray leaving it meets it again anywhere within its half width.
    pub uncertainty: f32,
}

impl CurvesSurface {
    /// Builds the segments of `desc`'s curves.
    ///
    /// # Errors
    /// A curve with a vertex count its type, basis and wrap cannot make segments of, counts
    /// that do not add up to the points, non-finite points, widths or normals, negative widths,
    /// or a primvar with the wrong number of values for its interpolation: the message names the
    /// attribute (`curveVertexCounts`, `points`, `widths`, `normals`).
    pub fn new(desc: &CurvesDesc<'_>) -> Result<Self, String> {
        if let Some(i) = desc.points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(format!("points[{i}] = {:?} is not finite", desc.points[i]));
        }
        if let Some(i) = desc.widths.iter().position(|w| !(w.is_finite() && *w >= 0.0)) {
            return Err(format!("widths[{i}] = {} must be a non-negative number", desc.widths[i]));
        }
        if let Some(i) = desc.normals.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(format!("normals[{i}] = {:?} is not finite", desc.normals[i]));
        }
        let mut total = 0usize;
        let mut wins = Vec::with_capacity(desc.counts.len());
        // One curve whose count its basis cannot make segments of does not take the others
        // with it: it is drawn as its control polygon (as Storm draws it), or left out when it
        // has fewer than two vertices, and named.
        let (mut as_polygon, mut left_out) = (Vec::new(), Vec::new());
        for (c, &count) in desc.counts.iter().enumerate() {
            if count < 0 {
                return Err(format!("curveVertexCounts[{c}] = {count} is negative"));
            }
            let n = count as usize;
            wins.push(match windows(desc.curve_type, desc.basis, desc.wrap, n) {
                Ok(w) => w,
                Err(e) => {
                    let wrap = if desc.wrap == Wrap::Periodic && n >= 3 { Wrap::Periodic } else { Wrap::Nonperiodic };
                    match windows(CurveType::Linear, desc.basis, wrap, n) {
                        Ok(w) => {
                            as_polygon.push(format!("curve {c} {e}"));
                            w
                        }
                        Err(_) => {
                            left_out.push(format!("curve {c} {e}"));
                            Windows { size: 2, starts: Vec::new(), varying: n }
                        }
                    }
                }
            });
            total += n;
        }
        let fallbacks = Self::describe_fallbacks(&as_polygon, &left_out);
        if total != desc.points.len() {
            return Err(format!("curveVertexCounts add up to {total} vertices but points has {}", desc.points.len()));
        }
        let n_varying: usize = wins.iter().map(|w| w.varying).sum();
        let points: Vec<[f64; 3]> = desc.points.iter().map(|p| p.map(f64::from)).collect();
        let cps = primvar_segments("points", &points, Interpolation::Vertex, desc, &wins, total, n_varying)?;
        let widths: Vec<[f64; 1]> =
            if desc.widths.is_empty() { vec![[1.0]] } else { desc.widths.iter().map(|w| [f64::from(*w)]).collect() };
        let w_interp = if desc.widths.is_empty() { Interpolation::Constant } else { desc.widths_interpolation };
        let widths = primvar_segments("widths", &widths, w_interp, desc, &wins, total, n_varying)?;
        let normals = if desc.style == Style::Ribbon && !desc.normals.is_empty() {
            let n: Vec<[f64; 3]> = desc.normals.iter().map(|p| p.map(f64::from)).collect();
            primvar_segments("normals", &n, desc.normals_interpolation, desc, &wins, total, n_varying)?
        } else {
            Vec::new()
        };
        let curve: Vec<u32> = wins.iter().enumerate().flat_map(|(c, w)| std::iter::repeat_n(c as u32, w.starts.len())).collect();
        Ok(CurvesSurface {
            cps: cps.iter().map(|s| s.map(f32x3)).collect(),
            // A negative half width can only come from a basis overshooting between vertex
            // widths: clamp it (nothing to hit there).
            half_widths: widths.iter().map(|s| s.map(|w| (0.5 * w[0]).max(0.0) as f32)).collect(),
            normals: normals.iter().map(|s| s.map(f32x3)).collect(),
            straight: wins.iter().flat_map(|w| std::iter::repeat_n(w.size == 2, w.starts.len())).collect(),
            times: Vec::new(),
            curve,
            style: desc.style,
            curve_count: desc.counts.len(),
            fallbacks,
        })
    }

    /// One line naming the curves drawn as control polygons and those left out, the first
    /// few of each with the reason (`curveVertexCounts[i]`), or `None`.
    fn describe_fallbacks(as_polygon: &[String], left_out: &[String]) -> Option<String> {
        const SHOWN: usize = 3;
        let list = |v: &[String]| {
            let more = v.len().saturating_sub(SHOWN);
            let mut s = v.iter().take(SHOWN).cloned().collect::<Vec<_>>().join("; ");
            if more > 0 {
                s.push_str(&format!("; and {more} more"));
            }
            s
        };
        let mut parts = Vec::new();
        if !as_polygon.is_empty() {
            parts.push(format!("{} curve(s) drawn as their control polygons (curveVertexCounts: {})", as_polygon.len(), list(as_polygon)));
        }
        if !left_out.is_empty() {
            parts.push(format!("{} curve(s) left out (curveVertexCounts: {})", left_out.len(), list(left_out)));
        }
        (!parts.is_empty()).then(|| parts.join("; "))
    }

    /// Curves drawn other than as authored (control polygons for counts their basis cannot
    /// use, curves of fewer than two vertices left out): one line for a warning, or `None`.
    pub fn fallbacks(&self) -> Option<&str> {
        self.fallbacks.as_deref()
    }

    /// Curves moving within the shutter: `samples` (shutter time, the curves then: the same
    /// prim's curves built from that time's points and widths). A ray at shutter time t meets
    /// the curves of control points and widths blended between the bracketing samples; every
    /// basis is linear in its control points (the Bézier conversion too), so that is the curve
    /// of the blended authored points. Ribbon normals are the first sample's (USD's `normals`
    /// of the frame).
    ///
    /// Tessellated pieces are cached per sample (under [`crate::deform::sample_generation`],
    /// as a deforming mesh's grids are) and blended per ray ([`crate::deform::blend`]), not
    /// tessellated per ray from blended control points: a segment's pieces are evaluated
    /// once per sample and tier, and a ray pays one lerp of at most 34 vertices — the cache
    /// keeps serving hair that moves. The blend of two samples' pieces is the blended curve's
    /// polyline at the same parameters (positions and half widths are linear in the control
    /// points); an oriented ribbon's across vectors blend as vectors, within the chord error
    /// of the blended ribbon's for the small turns a shutter sees.
    ///
    /// # Errors
    /// One line: fewer than 2 or more than [`crate::deform::MAX_SAMPLES`] samples, times not
    /// finite and strictly increasing, or a sample whose segments differ from the first's in
    /// count, curves, straightness or style (another topology).
    pub fn deforming(samples: Vec<(f32, CurvesSurface)>) -> Result<Self, String> {
        let times: Vec<f32> = samples.iter().map(|s| s.0).collect();
        crate::deform::check_times(&times)?;
        let mut iter = samples.into_iter();
        let Some((_, mut out)) = iter.next() else { return Err("no deformation samples".into()) };
        if !out.times.is_empty() {
            return Err("a deforming curves sample is itself deforming".into());
        }
        for (t, s) in iter {
            let same = s.curve == out.curve && s.straight == out.straight && s.style == out.style && s.times.is_empty();
            if !same {
                return Err(format!("the curves at shutter time {t} have other segments than the first sample's"));
            }
            out.cps.extend(s.cps);
            out.half_widths.extend(s.half_widths);
        }
        out.times = times;
        Ok(out)
    }

    /// The samples' shutter times; empty for curves that keep still.
    pub fn times(&self) -> &[f32] {
        &self.times
    }

    /// Segments (patches).
    pub fn segment_count(&self) -> usize {
        self.curve.len()
    }

    /// Sample `k`'s segment `seg`.
    fn sample_segment(&self, seg: usize, k: usize) -> Segment {
        let i = k * self.curve.len() + seg;
        Segment { cps: self.cps[i].map(dv), half_widths: self.half_widths[i], normals: self.normals.get(seg).map(|n| n.map(dv)) }
    }

    /// Segment `seg` at shutter time `time`: its control points and half widths blended
    /// between the bracketing samples (a sample's own at its time; curves that keep still
    /// are the same at every time).
    fn segment(&self, seg: usize, time: f32) -> Segment {
        if self.times.is_empty() {
            return self.sample_segment(seg, 0);
        }
        let (i, j, f) = crate::deform::bracket(&self.times, time);
        match f {
            f if f <= 0.0 => self.sample_segment(seg, i),
            f if f >= 1.0 => self.sample_segment(seg, j),
            f => {
                let (a, b) = (self.sample_segment(seg, i), self.sample_segment(seg, j));
                let fd = f64::from(f);
                Segment {
                    cps: std::array::from_fn(|k| a.cps[k] * (1.0 - fd) + b.cps[k] * fd),
                    half_widths: std::array::from_fn(|k| a.half_widths[k] * (1.0 - f) + b.half_widths[k] * f),
                    normals: a.normals,
                }
            }
        }
    }

    /// Segment `seg`'s centre, tangent derivative and frame at u (the first sample's).
    #[cfg(test)]
    fn frame(&self, seg: usize, u: f64) -> (DVec3, DVec3, DVec3, DVec3, DVec3) {
        self.sample_segment(seg, 0).frame(u)
    }

    /// Segment `seg`'s surface point and first derivatives at (u, v) (the first sample's).
    #[cfg(test)]
    fn first(&self, seg: usize, u: f64, v: f64) -> (DVec3, DVec3, DVec3) {
        self.sample_segment(seg, 0).first(u, v)
    }

    /// The segment's Bézier control points (object space; the first sample's when the curves
    /// move).
    pub fn control_points(&self, seg: usize) -> [Vec3A; 4] {
        self.cps[seg].map(Vec3A::from)
    }

    /// The segment's half width at u (object units; the first sample's when the curves move).
    pub fn half_width(&self, seg: usize, u: f32) -> f32 {
        bezier1(&self.half_widths[seg], f64::from(u)).0 as f32
    }

    /// Straight segments are tested at one piece whatever the beam.
    pub fn is_straight(&self, seg: usize) -> bool {
        self.straight.get(seg).copied().unwrap_or(false)
    }

    pub fn style(&self) -> Style {
        self.style
    }

    /// True for round tubes (neither ribbon).
    pub fn is_tube(&self) -> bool {
        !self.faces_ray() && self.normals.is_empty()
    }

    /// True for ribbons without authored normals, which face each ray.
    pub fn faces_ray(&self) -> bool {
        self.style == Style::Ribbon && self.normals.is_empty()
    }

    /// How far one straight piece may stray from the segment (object units): ⅛ of the bound
    /// on the Bézier's second derivative (6 × its control points' largest second difference)
    /// plus the half width's; n pieces stray 1/n² of it. The tracer chooses the rate from
    /// it — as many pieces as keep that sag within the ray's beam — so a straight hair
    /// segment takes one piece whatever its length and only bends are refined. Of curves that
    /// move, the largest over the samples, which bounds every blend's (a blend's second
    /// differences are the blend of the samples'), so the rate does not depend on the time.
    pub fn sag_of_one_piece(&self, seg: usize) -> f32 {
        (0..self.times.len().max(1)).map(|k| self.sample_segment(seg, k).sag_of_one_piece()).fold(0.0, f32::max)
    }

    /// The segment's centreline point at u, and the turn v around the tube at which its
    /// surface normal points along `dir` (object space), at shutter open.
    pub fn v_facing(&self, seg: usize, u: f32, dir: Vec3A) -> f32 {
        self.segment(seg, 0.0).v_facing(u, dir)
    }

    /// The piece vertices of a segment tessellated into `pieces` linear pieces, as a cache
    /// entry: `n` = pieces + 1, `verts` holds the n centreline points, then n entries of
    /// (half width, 0, 0) for tubes and camera-facing ribbons or the half-width vector across an
    /// oriented ribbon. `chord_error` bounds how far the curve strays from the polyline
    /// (object units: [`CurvesSurface::sag_of_one_piece`] over pieces², plus rounding). Of
    /// curves that move, the first sample's ([`CurvesSurface::tessellate_sample`]).
    pub fn tessellate(&self, seg: usize, pieces: usize) -> Tessellation {
        self.tessellate_sample(seg, 0, pieces)
    }

    /// [`CurvesSurface::tessellate`] of sample `k` (0 for curves that keep still).
    pub fn tessellate_sample(&self, seg: usize, k: usize, pieces: usize) -> Tessellation {
        let s = self.sample_segment(seg, k);
        let n = pieces + 1;
        let mut verts = Vec::with_capacity(2 * n);
        let mut across = Vec::with_capacity(n);
        for i in 0..n {
            let u = i as f64 / pieces as f64;
            let (p, _, _, w, _) = s.frame(u);
            let (r, _) = bezier1(&s.half_widths, u);
            verts.push(f32x3(p.to_array()));
            across.push(if s.normals.is_none() { [r as f32, 0.0, 0.0] } else { f32x3((w * r).to_array()) });
        }
        verts.extend(across);
        let scale = s.cps.iter().map(|p| p.abs().max_element()).fold(0.0, f64::max);
        let chord_error = self.sag_of_one_piece(seg) / (pieces * pieces) as f32 + gamma(8) * scale as f32;
        Tessellation {
            n,
            verts: verts.into(),
            boxes: GridBoxes::NONE,
            chord_error,
            seam_radius: 0.0,
            seam_normal: Default::default(),
            domain: GridDomain::Square,
        }
    }

    /// The nearest hit of the object-space ray `o + t·d`, t in (t_min, t_max), on segment
    /// `seg`'s tessellation `tess` read at vertex stride `stride` (2: pieces merged in pairs):
    /// [`CurvesSurface::intersect_at`] at shutter open.
    #[allow(clippy::too_many_arguments)]
    pub fn intersect(
        &self,
        seg: usize,
        tess: &Tessellation,
        stride: usize,
        o: Vec3A,
        d: Vec3A,
        t_min: f32,
        t_max: f32,
    ) -> Option<CurveHit> {
        self.intersect_at(seg, tess, stride, o, d, t_min, t_max, 0.0)
    }

    /// [`CurvesSurface::intersect`] at shutter time `time`: the hit's v is read on the
    /// segment of that time, and `tess` is the segment's tessellation at that time (the
    /// samples' blended, [`crate::deform::blend`], for curves that move).
    #[allow(clippy::too_many_arguments)]
    pub fn intersect_at(
        &self,
        seg: usize,
        tess: &Tessellation,
        stride: usize,
        o: Vec3A,
        d: Vec3A,
        t_min: f32,
        t_max: f32,
        time: f32,
    ) -> Option<CurveHit> {
        let n = tess.n;
        let verts = tess.verts.as_slice();
        let (centres, across) = verts.split_at(n);
        let stride = stride.max(1);
        let pieces = (n - 1) / stride;
        let (od, dd) = (dv(o.into()), dv(d.into()));
        let (tmin, tmax) = (f64::from(t_min), f64::from(t_max));
        let mut best: Option<(f64, f64, DVec3)> = None; // (t, u along the segment, normal)
        let mut t_best = tmax;
        for k in 0..pieces {
            let (i0, i1) = (k * stride, (k + 1) * stride);
            let (a, b) = (dv(centres[i0]), dv(centres[i1]));
            let (u0, u1) = (k as f64 / pieces as f64, (k + 1) as f64 / pieces as f64);
            let found = if self.faces_ray() {
                facing_piece(od, dd, a, b, f64::from(across[i0][0]), f64::from(across[i1][0]), tmin, t_best)
            } else if self.normals.is_empty() {
                tube_piece(od, dd, a, b, f64::from(across[i0][0]), f64::from(across[i1][0]), k + 1 == pieces, tmin, t_best)
            } else {
                ribbon_piece(od, dd, a, b, dv(across[i0]), dv(across[i1]), tmin, t_best)
            };
            if let Some((t, s, nrm)) = found {
                t_best = t;
                best = Some((t, u0 + (u1 - u0) * s, nrm));
            }
        }
        let (t, u, nrm) = best?;
        let tf = t as f32;
        if !(tf > t_min && tf < t_max) {
            return None;
        }
        let u = u.clamp(0.0, 1.0);
        let nv = va(nrm);
        let s = self.segment(seg, time);
        let v = if self.normals.is_empty() {
            // Around the tube: where its normal points the way the piece's does.
            s.v_facing(u as f32, nv)
        } else {
            // Across the ribbon: the hit's offset along W over the full width.
            let p = od + dd * t;
            let (c, _, _, w, _) = s.frame(u);
            let r = bezier1(&s.half_widths, u).0.max(f64::MIN_POSITIVE);
            ((p - c).dot(w) / r * 0.5 + 0.5).clamp(0.0, 1.0) as f32
        };
        let uncertainty = if self.faces_ray() { bezier1(&s.half_widths, u).0 as f32 } else { 0.0 };
        Some(CurveHit { t: tf, u: u as f32, v, n: nv, facing: self.faces_ray(), uncertainty })
    }
}

/// One segment's data at one time: its Bézier control points and half widths (a sample's, or
/// blended between two), and its ribbon normals. Every per-segment evaluation reads this.
#[derive(Clone, Copy, Debug)]
struct Segment {
    cps: [DVec3; 4],
    half_widths: [f32; 4],
    /// Oriented ribbons only.
    normals: Option<[DVec3; 4]>,
}

impl Segment {
    /// See [`CurvesSurface::sag_of_one_piece`].
    fn sag_of_one_piece(&self) -> f32 {
        let c = &self.cps;
        let second = 6.0 * (c[2] - c[1] * 2.0 + c[0]).length().max((c[3] - c[2] * 2.0 + c[1]).length());
        let w = self.half_widths.map(f64::from);
        let second_w = 6.0 * (w[2] - 2.0 * w[1] + w[0]).abs().max((w[3] - 2.0 * w[2] + w[1]).abs());
        ((second + second_w) / 8.0) as f32
    }

    /// The fixed axis the frame around the segment is built from: the coordinate axis least
    /// aligned with its chord.
    fn frame_axis(&self) -> DVec3 {
        let c = &self.cps;
        let mut chord = c[3] - c[0];
        if chord.length_squared() == 0.0 {
            chord = c[1] - c[0] + (c[2] - c[1]);
        }
        let a = chord.abs();
        if a.x <= a.y && a.x <= a.z {
            DVec3::X
        } else if a.y <= a.z {
            DVec3::Y
        } else {
            DVec3::Z
        }
    }

    /// Centre, tangent derivative and frame (unit T, N, B with B = N × T) at u.
    fn frame(&self, u: f64) -> (DVec3, DVec3, DVec3, DVec3, DVec3) {
        let c = &self.cps;
        let (p, d, _) = bezier3(c, u);
        let mut t = d.normalize_or_zero();
        if t == DVec3::ZERO {
            t = (c[3] - c[0]).normalize_or(DVec3::Z);
        }
        let (n, b) = match &self.normals {
            None => {
                let n = t.cross(self.frame_axis()).normalize_or(t.any_orthonormal_vector());
                (n, n.cross(t))
            }
            Some(normals) => {
                // Ribbons: v runs across W = normal × T; the surface normal is the authored
                // one's part perpendicular to T.
                let (nn, _, _) = bezier3(normals, u);
                let w = nn.cross(t).normalize_or(t.any_orthonormal_vector());
                (w, w.cross(t))
            }
        };
        (p, d, t, n, b)
    }

    /// The surface point and its first derivatives at (u, v), f64.
    fn first(&self, u: f64, v: f64) -> (DVec3, DVec3, DVec3) {
        let (p, d, _, n, b) = self.frame(u);
        let (r, dr) = bezier1(&self.half_widths, u);
        let h = 1e-5;
        let (ua, ub) = ((u - h).max(0.0), (u + h).min(1.0));
        let (_, _, _, na, ba) = self.frame(ua);
        let (_, _, _, nb, bb) = self.frame(ub);
        let (dn, db) = ((nb - na) / (ub - ua), (bb - ba) / (ub - ua));
        if self.normals.is_some() {
            // Ribbon: P = C + (2v − 1)·r·W, W = n here.
            let s = 2.0 * v - 1.0;
            return (p + n * (s * r), d + n * (s * dr) + dn * (s * r), n * (2.0 * r));
        }
        let th = std::f64::consts::TAU * v;
        let (cs, sn) = (th.cos(), th.sin());
        let radial = n * cs + b * sn;
        let dpdu = d + radial * dr + (dn * cs + db * sn) * r;
        let dpdv = (b * cs - n * sn) * (std::f64::consts::TAU * r);
        (p + radial * r, dpdu, dpdv)
    }

    /// The turn v around the tube at u at which its surface normal points along `dir`.
    fn v_facing(&self, u: f32, dir: Vec3A) -> f32 {
        let (_, _, _, n, b) = self.frame(f64::from(u));
        let dir = DVec3::new(f64::from(dir.x), f64::from(dir.y), f64::from(dir.z));
        let v = dir.dot(b).atan2(dir.dot(n)) / std::f64::consts::TAU;
        (if v < 0.0 { v + 1.0 } else { v }).clamp(0.0, 1.0) as f32
    }

    /// The surface point and its derivatives at (u, v): closed form along the tube, central
    /// differences in f64 for the frame's and the second derivatives along u.
    fn evaluate(&self, u: f32, v: f32) -> SurfacePoint {
        let (u, v) = (f64::from(u).clamp(0.0, 1.0), f64::from(v));
        let (p, dpdu, dpdv) = self.first(u, v);
        let h = 1e-4;
        let (ua, ub) = ((u - h).max(0.0), (u + h).min(1.0));
        let (_, du_a, dv_a) = self.first(ua, v);
        let (_, du_b, dv_b) = self.first(ub, v);
        let (_, _, dv_c) = self.first(u, v + h);
        let (_, _, dv_d) = self.first(u, v - h);
        SurfacePoint {
            p: va(p),
            dpdu: va(dpdu),
            dpdv: va(dpdv),
            dpduu: va((du_b - du_a) / (ub - ua)),
            dpduv: va((dv_b - dv_a) / (ub - ua)),
            dpdvv: va((dv_c - dv_d) / (2.0 * h)),
        }
    }

    /// The control hull grown by the largest half width (and rounding); empty for a segment
    /// of width 0 throughout.
    fn bounds(&self) -> Bounds3 {
        let r = self.half_widths.iter().copied().fold(0.0f32, f32::max);
        if !(r > 0.0) {
            return Bounds3::EMPTY;
        }
        let mut b = Bounds3::EMPTY;
        for p in &self.cps {
            b.grow(va(*p));
        }
        let pad = r + gamma(8) * b.max_abs();
        b.expanded(pad)
    }
}

/// Orthonormal (x, y) with z the unit `z`.
fn basis_of(z: DVec3) -> (DVec3, DVec3) {
    let x = z.any_orthonormal_vector();
    (x, z.cross(x))
}

/// Nearest t in (t_min, t_max) where the ray meets the sphere (c, r), entering or leaving, with
/// the outward normal.
fn sphere(o: DVec3, d: DVec3, c: DVec3, r: f64, t_min: f64, t_max: f64) -> Option<(f64, DVec3)> {
    if !(r > 0.0) {
        return None;
    }
    let a = d.length_squared();
    let f = o - c;
    let b = f.dot(d);
    // The discriminant from the ray's distance to the centre (pbrt-v4), robust when far away.
    let perp = f - d * (b / a);
    let disc = a * (r * r - perp.length_squared());
    if !(disc >= 0.0) {
        return None;
    }
    let q = -(b + disc.sqrt().copysign(b));
    let cc = f.length_squared() - r * r;
    let (mut t0, mut t1) = (q / a, cc / q);
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    let t = [t0, t1].into_iter().find(|&t| t.is_finite() && t > t_min && t < t_max)?;
    Some((t, (o + d * t - c) / r))
}

/// A tube piece: the frustum from circle (a, ra) to (b, rb), and the sphere at a (and at b
/// when `last`). Returns (t, s along the piece, outward normal).
#[allow(clippy::too_many_arguments)]
fn tube_piece(o: DVec3, d: DVec3, a: DVec3, b: DVec3, ra: f64, rb: f64, last: bool, t_min: f64, t_max: f64) -> Option<(f64, f64, DVec3)> {
    let mut best: Option<(f64, f64, DVec3)> = None;
    let mut t_hi = t_max;
    if let Some((t, n)) = sphere(o, d, a, ra, t_min, t_hi) {
        t_hi = t;
        best = Some((t, 0.0, n));
    }
    if last {
        if let Some((t, n)) = sphere(o, d, b, rb, t_min, t_hi) {
            t_hi = t;
            best = Some((t, 1.0, n));
        }
    }
    let axis = b - a;
    let len = axis.length();
    if len > 0.0 {
        let z = axis / len;
        let (x, y) = basis_of(z);
        let lo = o - a;
        let (ox, oy, oz) = (lo.dot(x), lo.dot(y), lo.dot(z));
        let (dx, dy, dz) = (d.dot(x), d.dot(y), d.dot(z));
        // x² + y² = (k z + ra)², z in [0, len].
        let k = (rb - ra) / len;
        let (ro, rd) = (k * oz + ra, k * dz);
        let qa = dx * dx + dy * dy - rd * rd;
        let qb = ox * dx + oy * dy - ro * rd;
        let qc = ox * ox + oy * oy - ro * ro;
        let disc = qb * qb - qa * qc;
        if disc >= 0.0 && qa != 0.0 {
            let q = -(qb + disc.sqrt().copysign(qb));
            let (mut t0, mut t1) = (q / qa, qc / q);
            if !(t0 <= t1) {
                std::mem::swap(&mut t0, &mut t1);
            }
            for t in [t0, t1] {
                if !(t.is_finite() && t > t_min && t < t_hi) {
                    continue;
                }
                let zz = oz + t * dz;
                if !(0.0..=len).contains(&zz) || k * zz + ra < 0.0 {
                    continue;
                }
                let (px, py) = (ox + t * dx, oy + t * dy);
                let n = (x * px + y * py - z * ((k * zz + ra) * k)).normalize_or(x);
                best = Some((t, zz / len, n));
                break;
            }
        }
    }
    best
}

/// An oriented ribbon piece: the quad a − wa, b − wb, b + wb, a + wa (two triangles).
#[allow(clippy::too_many_arguments)]
fn ribbon_piece(o: DVec3, d: DVec3, a: DVec3, b: DVec3, wa: DVec3, wb: DVec3, t_min: f64, t_max: f64) -> Option<(f64, f64, DVec3)> {
    let (p00, p10, p11, p01) = (a - wa, b - wb, b + wb, a + wa);
    let mut best = None;
    let mut t_hi = t_max;
    // Triangles (p00, p10, p11) and (p00, p11, p01); s along the piece from barycentrics.
    for (q0, q1, q2, s1, s2) in [(p00, p10, p11, 1.0, 1.0), (p00, p11, p01, 1.0, 0.0)] {
        let (e1, e2) = (q1 - q0, q2 - q0);
        let pv = d.cross(e2);
        let det = e1.dot(pv);
        if det.abs() < 1e-300 {
            continue;
        }
        let inv = 1.0 / det;
        let tv = o - q0;
        let bu = tv.dot(pv) * inv;
        if !(0.0..=1.0).contains(&bu) {
            continue;
        }
        let qv = tv.cross(e1);
        let bv = d.dot(qv) * inv;
        if bv < 0.0 || bu + bv > 1.0 {
            continue;
        }
        let t = e2.dot(qv) * inv;
        if t > t_min && t < t_hi {
            t_hi = t;
            let n = (b - a).cross(wa + wb).normalize_or(e1.cross(e2).normalize_or(DVec3::Z));
            best = Some((t, (bu * s1 + bv * s2).clamp(0.0, 1.0), n));
        }
    }
    best
}

/// A camera-facing ribbon piece: the ray passes within the half width (interpolated along the
/// piece) of the segment a → b. t is where it passes closest (on the ribbon's plane, which
/// contains the segment and faces the ray); the normal faces back along the ray.
#[allow(clippy::too_many_arguments)]
fn facing_piece(o: DVec3, d: DVec3, a: DVec3, b: DVec3, ra: f64, rb: f64, t_min: f64, t_max: f64) -> Option<(f64, f64, DVec3)> {
    let e = b - a;
    let (dd, ee, de) = (d.dot(d), e.dot(e), d.dot(e));
    let w = o - a;
    let (dw, ew) = (d.dot(w), e.dot(w));
    let den = dd * ee - de * de;
    let s = if den > 1e-12 * dd * ee { ((dd * ew - de * dw) / den).clamp(0.0, 1.0) } else { 0.0 };
    let q = a + e * s;
    let t = (q - o).dot(d) / dd;
    if !(t > t_min && t < t_max) {
        return None;
    }
    let dist = (o + d * t - q).length();
    let r = ra + (rb - ra) * s;
    if !(dist <= r) || r <= 0.0 {
        return None;
    }
    let tang = if ee > 0.0 { e / ee.sqrt() } else { DVec3::ZERO };
    let back = -d / dd.sqrt();
    let n = (back - tang * back.dot(tang)).normalize_or(back);
    Some((t, s, n))
}

impl LimitSurface for CurvesSurface {
    fn patch_count(&self) -> usize {
        self.curve.len()
    }

    fn patch_param(&self, patch: usize) -> PatchParam {
        // The base face is the curve, so per-curve (uniform) materials index it.
        let curve = self.curve.get(patch).copied().unwrap_or(0);
        PatchParam::root(curve, curve, PatchKind::Other)
    }

    /// The control hull grown by the half width; of curves that move, the union over the
    /// samples, which holds every blend (a blended point lies in the hull of the samples'
    /// control points, its half width at most the larger of theirs there).
    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        if patch >= self.curve.len() {
            return Bounds3::EMPTY;
        }
        (0..self.times.len().max(1)).fold(Bounds3::EMPTY, |b, k| b.union(&self.sample_segment(patch, k).bounds()))
    }

    /// At shutter open for curves that move; [`LimitSurface::evaluate_at`] for a ray's time.
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        self.evaluate_at(patch, u, v, 0.0)
    }

    fn evaluate_at(&self, patch: usize, u: f32, v: f32, time: f32) -> SurfacePoint {
        if patch >= self.curve.len() {
            return SurfacePoint::default();
        }
        self.segment(patch, time).evaluate(u, v)
    }

    fn deforms(&self) -> bool {
        !self.times.is_empty()
    }

    fn control_face_count(&self) -> usize {
        self.curve_count
    }

    fn face_varying(&self, channel: usize, _patch: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        (channel == 0).then_some(([u, v], [1.0, 0.0], [0.0, 1.0]))
    }

    fn curves(&self) -> Option<&CurvesSurface> {
        Some(self)
    }

    fn simplified(&self) -> Option<&str> {
        self.fallbacks()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn desc<'a>(points: &'a [[f32; 3]], counts: &'a [i32], curve_type: CurveType, basis: Basis, wrap: Wrap) -> CurvesDesc<'a> {
        CurvesDesc {
            points,
            counts,
            curve_type,
            basis,
            wrap,
            widths: &[],
            widths_interpolation: Interpolation::Constant,
            normals: &[],
            normals_interpolation: Interpolation::Vertex,
            style: Style::Tube,
        }
    }

    /// B-spline basis functions evaluated directly (the textbook uniform cubic B-spline).
    fn bspline_point(p: &[[f32; 3]], i: usize, t: f64) -> DVec3 {
        let b = [
            (1.0 - t).powi(3) / 6.0,
            (3.0 * t.powi(3) - 6.0 * t * t + 4.0) / 6.0,
            (-3.0 * t.powi(3) + 3.0 * t * t + 3.0 * t + 1.0) / 6.0,
            t.powi(3) / 6.0,
        ];
        (0..4).map(|k| dv(p[i + k]) * b[k]).sum()
    }

    fn catmull_rom_point(p: [DVec3; 4], t: f64) -> DVec3 {
        // 0.5 · [ 2P1 + (−P0 + P2) t + (2P0 − 5P1 + 4P2 − P3) t² + (−P0 + 3P1 − 3P2 + P3) t³ ]
        (p[1] * 2.0
            + (p[2] - p[0]) * t
            + (p[0] * 2.0 - p[1] * 5.0 + p[2] * 4.0 - p[3]) * t * t
            + (p[1] * 3.0 - p[0] - p[2] * 3.0 + p[3]) * t * t * t)
            * 0.5
    }

    const PTS: [[f32; 3]; 7] =
        [[0.0, 0.0, 0.0], [1.0, 2.0, 0.0], [2.0, -1.0, 1.0], [3.0, 0.5, 0.0], [4.0, 1.0, -1.0], [5.0, 0.0, 0.0], [6.0, 2.0, 1.0]];

    /// Moving curves: a blend of two samples' pieces is the tessellation of the curve of
    /// blended control points; bounds hold every sample; other segments are refused by name.
    #[test]
    fn moving_curves_blend_as_their_blended_control_points() {
        let counts = [7];
        let shifted = |dy: f32| PTS.map(|p| [p[0], p[1] + dy * p[0], p[2]]);
        let at = |dy: f32| CurvesSurface::new(&desc(&shifted(dy), &counts, CurveType::Cubic, Basis::Bspline, Wrap::Nonperiodic)).unwrap();
        let moving = CurvesSurface::deforming(vec![(0.0, at(0.0)), (1.0, at(1.0))]).unwrap();
        assert!(moving.deforms());
        let mid = at(0.25);
        for seg in 0..moving.segment_count() {
            let blended = crate::deform::blend(&moving.tessellate_sample(seg, 0, 16), &moving.tessellate_sample(seg, 1, 16), 0.25);
            for (p, q) in blended.verts.iter().zip(mid.tessellate(seg, 16).verts.iter()) {
                assert!((Vec3A::from(*p) - Vec3A::from(*q)).length() < 1e-5, "segment {seg}: {p:?} vs {q:?}");
            }
            let (a, b) = (moving.evaluate_at(seg, 0.3, 0.2, 0.25), mid.evaluate(seg, 0.3, 0.2));
            assert!((a.p - b.p).length() < 1e-5 && (a.dpdu - b.dpdu).length() < 1e-4, "segment {seg}");
            let bb = moving.patch_bounds(seg);
            assert!(bb.contains(at(1.0).evaluate(seg, 0.5, 0.0).p) && bb.contains(at(0.0).evaluate(seg, 0.5, 0.5).p));
        }
        let fewer = CurvesSurface::new(&desc(&PTS[..6], &[6], CurveType::Cubic, Basis::Bspline, Wrap::Nonperiodic)).unwrap();
        let e = CurvesSurface::deforming(vec![(0.0, at(0.0)), (1.0, fewer)]).unwrap_err();
        assert!(e.contains("the curves at shutter time 1 have other segments"), "{e}");
        assert!(CurvesSurface::deforming(vec![(0.0, at(0.0))]).unwrap_err().contains("1 deformation samples"));
    }

    #[test]
    fn segments_follow_usd_bases_and_wraps() {
        let counts = [7];
        let s = CurvesSurface::new(&desc(&PTS, &counts, CurveType::Cubic, Basis::Bspline, Wrap::Nonperiodic)).unwrap();
        assert_eq!(s.segment_count(), 4);
        for seg in 0..4 {
            for t in [0.0, 0.3, 0.8, 1.0] {
                let got = s.first(seg, t, 0.0);
                let (c, ..) = s.frame(seg, t);
                let want = bspline_point(&PTS, seg, t);
                assert!((c - want).length() < 1e-5, "bspline seg {seg} t {t}: {c} vs {want}");
                let _ = got;
            }
        }
        let s = CurvesSurface::new(&desc(&PTS, &counts, CurveType::Cubic, Basis::CatmullRom, Wrap::Nonperiodic)).unwrap();
        for seg in 0..4 {
            for t in [0.0, 0.45, 1.0] {
                let (c, ..) = s.frame(seg, t);
                let w = [PTS[seg], PTS[seg + 1], PTS[seg + 2], PTS[seg + 3]].map(dv);
                assert!((c - catmull_rom_point(w, t)).length() < 1e-5, "catmullRom seg {seg} t {t}");
            }
        }
        // Pinned: n − 1 segments, through the end vertices.
        let s = CurvesSurface::new(&desc(&PTS, &counts, CurveType::Cubic, Basis::Bspline, Wrap::Pinned)).unwrap();
        assert_eq!(s.segment_count(), 6);
        assert!((s.frame(0, 0.0).0 - dv(PTS[0])).length() < 1e-6);
        assert!((s.frame(5, 1.0).0 - dv(PTS[6])).length() < 1e-6);
        // Periodic: n segments, closed.
        let s = CurvesSurface::new(&desc(&PTS, &counts, CurveType::Cubic, Basis::Bspline, Wrap::Periodic)).unwrap();
        assert_eq!(s.segment_count(), 7);
        assert!((s.frame(6, 1.0).0 - s.frame(0, 0.0).0).length() < 1e-6);
        // Bezier: 4 + 3k, through every third vertex.
        let s = CurvesSurface::new(&desc(&PTS, &counts, CurveType::Cubic, Basis::Bezier, Wrap::Nonperiodic)).unwrap();
        assert_eq!(s.segment_count(), 2);
        assert!((s.frame(1, 0.0).0 - dv(PTS[3])).length() < 1e-6);
        // Linear: n − 1 or n.
        assert_eq!(
            CurvesSurface::new(&desc(&PTS, &counts, CurveType::Linear, Basis::Bezier, Wrap::Nonperiodic)).unwrap().segment_count(),
            6
        );
        assert_eq!(CurvesSurface::new(&desc(&PTS, &counts, CurveType::Linear, Basis::Bezier, Wrap::Periodic)).unwrap().segment_count(), 7);
    }

    #[test]
    fn bad_counts_and_widths_are_named() {
        // A count its basis cannot use no longer refuses the prim: the curve is drawn as its
        // control polygon and named (`a_curve_its_basis_cannot_use_is_drawn_as_its_polygon`).
        let s = CurvesSurface::new(&desc(&PTS[..5], &[5], CurveType::Cubic, Basis::Bezier, Wrap::Nonperiodic)).unwrap();
        let e = s.fallbacks().unwrap();
        assert!(e.contains("curve 0 has 5 vertices; a bezier curve needs 4 + 3k"), "{e}");
        let e = CurvesSurface::new(&desc(&PTS, &[4, 4], CurveType::Cubic, Basis::Bezier, Wrap::Nonperiodic)).unwrap_err();
        assert!(e.contains("add up to 8") && e.contains("points has 7"), "{e}");
        let mut d = desc(&PTS, &[7], CurveType::Cubic, Basis::Bspline, Wrap::Nonperiodic);
        d.widths = &[0.1, 0.2];
        d.widths_interpolation = Interpolation::Vertex;
        let e = CurvesSurface::new(&d).unwrap_err();
        assert!(e.contains("widths has 2 values") && e.contains("want one per vertex, 7"), "{e}");
        d.widths = &[0.1; 5];
        d.widths_interpolation = Interpolation::Varying;
        assert!(CurvesSurface::new(&d).is_ok(), "varying: segments + 1 = 5");
    }

    /// As Storm draws them (OpenUSD's testUsdImagingGLBasisCurvesVaryingTopology and
    /// testUsdImagingGLCurves/pinnedCurves): a bezier curve of 7 + 1 vertices is its control
    /// polygon, a pinned cubic curve of one vertex is left out, and the other curves of the prim
    /// are drawn as they would be alone.
    #[test]
    fn a_curve_its_basis_cannot_use_is_drawn_as_its_polygon() {
        let mut pts = PTS.to_vec();
        pts.push([7.0, 0.0, 1.0]);
        let s = CurvesSurface::new(&desc(&pts, &[8], CurveType::Cubic, Basis::Bezier, Wrap::Nonperiodic)).unwrap();
        assert_eq!(s.segment_count(), 7, "one straight piece per pair of vertices");
        for seg in 0..7 {
            assert!(s.is_straight(seg));
            let c = s.control_points(seg);
            assert_eq!(c[0], Vec3A::from(pts[seg]));
            assert_eq!(c[3], Vec3A::from(pts[seg + 1]));
        }
        let note = s.fallbacks().unwrap();
        assert!(note.contains("1 curve(s) drawn as their control polygons") && note.contains("curve 0 has 8 vertices"), "{note}");
        assert_eq!(LimitSurface::simplified(&s), Some(note), "listed in the stats' scene.simplified");

        // Pinned B-spline curves of 3, 2, 1 vertices: the last is left out, the others are
        // the same segments as the first two curves alone.
        let d = desc(&PTS[..6], &[3, 2, 1], CurveType::Cubic, Basis::Bspline, Wrap::Pinned);
        let s = CurvesSurface::new(&d).unwrap();
        let alone = CurvesSurface::new(&desc(&PTS[..5], &[3, 2], CurveType::Cubic, Basis::Bspline, Wrap::Pinned)).unwrap();
        assert!(alone.fallbacks().is_none());
        assert_eq!(s.segment_count(), alone.segment_count());
        for seg in 0..s.segment_count() {
            assert_eq!(s.control_points(seg), alone.control_points(seg));
            assert!(!s.is_straight(seg));
        }
        let note = s.fallbacks().unwrap();
        assert!(note.contains("1 curve(s) left out") && note.contains("curve 2 has 1 vertices"), "{note}");
        // Uniform values still index curves as authored.
        assert_eq!(s.curve_count, 3);
    }

    #[test]
    fn derivatives_match_finite_differences_and_normals_point_out() {
        let mut d = desc(&PTS, &[7], CurveType::Cubic, Basis::CatmullRom, Wrap::Nonperiodic);
        let widths = [0.2, 0.3, 0.25, 0.4, 0.2, 0.3, 0.1];
        d.widths = &widths;
        d.widths_interpolation = Interpolation::Vertex;
        let s = CurvesSurface::new(&d).unwrap();
        for seg in 0..s.segment_count() {
            for (u, v) in [(0.3, 0.1), (0.6, 0.7)] {
                let e = s.evaluate(seg, u, v);
                let h = 1e-3;
                let du = (s.evaluate(seg, u + h, v).p - s.evaluate(seg, u - h, v).p) / (2.0 * h);
                let dvv = (s.evaluate(seg, u, v + h).p - s.evaluate(seg, u, v - h).p) / (2.0 * h);
                assert!((du - e.dpdu).length() < 2e-3 * e.dpdu.length().max(1.0), "seg {seg}: dpdu {} vs {du}", e.dpdu);
                assert!((dvv - e.dpdv).length() < 2e-3 * e.dpdv.length().max(1.0), "seg {seg}: dpdv {} vs {dvv}", e.dpdv);
                let (c, ..) = s.frame(seg, f64::from(u));
                let out = e.p - va(c);
                assert!(e.dpdu.cross(e.dpdv).dot(out) > 0.0, "seg {seg}: normal points inward");
                assert!((out.length() - s.half_width(seg, u)).abs() < 1e-5);
            }
        }
    }
}
