//! Ray differentials: how wide a ray's beam is, and how the width changes as the ray travels,
//! hits a surface, reflects, refracts, or is replaced by a distribution of rays.
//!
//! The math under the paper's one idea (Christensen et al. 2003, §4: *coherent rays are narrow,
//! incoherent rays are wide*): the geometry cache tessellates a subpatch at the rate the beam
//! width of the ray testing it asks for, so every ray carries a differential.
//!
//! - Camera rays, exact (Igehy 1999): [`RayDifferential::from_pinhole`],
//!   [`RayDifferential::from_orthographic`].
//! - Transfer to a hit (Igehy 1999, eq. 10–11), the footprint on the tangent plane, and the beam
//!   width at a distance along the ray (§4.1): [`RayDifferential::transfer`],
//!   [`RayDifferential::beam_width_at`].
//! - Specular reflection and refraction (§4.2; Igehy 1999), with the normal's derivatives from
//!   the surface's curvature ([`dndu_dndv`], [`UvDifferentials`]): convex mirrors widen beams,
//!   concave ones narrow them up to the crossover and widen them after.
//! - Distribution rays (§4.4–§4.6; Suykens and Willems 2001): glossy, area-light shadow and
//!   hemisphere rays take the origin derivatives of the footprint and a directional spread of
//!   `sqrt(1 / (N p(ω)))` radians; one ray per bounce uses the path differential (§2.5).
//!
//! **Conventions.** `x` and `y` are image coordinates in pixels, so each derivative is *per
//! pixel step*: `dpdx` in world units per pixel, `dddx` in radians per pixel (the derivative of a
//! unit direction). Every vector is in world (render) space. A direction `d` is the unit
//! direction of travel: for an incident ray it points toward the surface (pbrt's `-wo`).
//!
//! **Robustness.** No public function returns NaN or infinity, whatever it is given. A vector
//! with a NaN becomes zero; an infinite one, or one longer than [`MAX_DIFFERENTIAL`], keeps its
//! direction at that length; a `|cos|` the equations divide by is held at least
//! [`GRAZING_COS_MIN`]; a spread is at most [`MAX_SPREAD_RAD`]. The `_checked` twins of the
//! per-hit operations also say whether a rule fired, for the render's stats.
//!
//! References: H. Igehy, *Tracing Ray Differentials*, SIGGRAPH 1999. F. Suykens and Y. D.
//! Willems, *Path Differentials and Applications*, EGWR 2001. P. H. Christensen et al., *Ray
//! Differentials and Multiresolution Geometry Caching for Distribution Ray Tracing in Complex
//! Scenes*, 2003, §2.5 and §4. The API follows pbrt-v4's `RayDifferential` and
//! `SurfaceInteraction::ComputeDifferentials`.

use glam::Vec3A;
use std::f32::consts::PI;

/// Longest differential vector kept, in world units (or radians) per pixel. pbrt-v4 drops
/// differentials whose squared length exceeds 1e16; we keep the direction and cap the length at
/// 1e8 instead, because a beam that wide is still wide: dropping it would make the ray look
/// infinitely narrow and ask the geometry cache for its finest tessellation.
pub const MAX_DIFFERENTIAL: f32 = 1e8;

/// Smallest `|cos|` between a ray and a normal that the transfer and refraction equations divide
/// by. Within 0.057° of grazing, the footprint on the surface is held at 1000 times the beam's
/// cross-section instead of growing as `1 / cos` without bound.
pub const GRAZING_COS_MIN: f32 = 1e-3;

/// Largest directional spread, in radians: `sqrt(4π)`, one ray standing for the whole sphere of
/// directions (a single uniform hemisphere ray gets `sqrt(2π)`, §4.6's worst case).
pub const MAX_SPREAD_RAD: f32 = 3.544_907_7;

/// The derivatives of a ray's origin `P` and unit direction `D` with respect to the image
/// coordinates `x` and `y` (one pixel step each), in world space.
///
/// pbrt stores two neighbour rays (`rxOrigin`, `rxDirection`, …); we store their derivatives,
/// because (1) a distribution ray (§4.4–§4.6) has a directional spread but no neighbour ray to
/// store; (2) the beam width at distance `t` is then `|dP + t dD|`, without subtracting nearly
/// equal positions far from the origin (which loses every digit of an `f32` there); (3) scaling
/// for several samples per pixel and the chain rule are linear in derivatives.
///
/// Clamps are reported, not stored: each operation a renderer runs per hit or per sampled ray
/// has a `_checked` twin returning `(result, clamped)`, `clamped` saying whether that step
/// fired a clamping rule (not whether its input had been clamped before), so counting it after
/// every step counts each clamp once. The struct stays the four derivatives.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RayDifferential {
    /// dP/dx: world units per pixel.
    pub dpdx: Vec3A,
    /// dP/dy: world units per pixel.
    pub dpdy: Vec3A,
    /// dD/dx of the unit direction: radians per pixel (perpendicular to `D` to first order).
    pub dddx: Vec3A,
    /// dD/dy of the unit direction: radians per pixel.
    pub dddy: Vec3A,
}

/// A vector with a NaN becomes zero; an infinite or too long one keeps its direction at
/// [`MAX_DIFFERENTIAL`]. Returns whether it changed.
fn sanitize(v: Vec3A) -> (Vec3A, bool) {
    // The common case first, in one comparison: a NaN or an infinite (or overflowing) length
    // compares false and goes on to the checks below.
    if v.length_squared() <= MAX_DIFFERENTIAL * MAX_DIFFERENTIAL {
        return (v, false);
    }
    if v.is_nan() {
        return (Vec3A::ZERO, true);
    }
    if !v.is_finite() {
        let dir = Vec3A::select(v.is_finite_mask(), Vec3A::ZERO, v.signum());
        return (dir.normalize() * MAX_DIFFERENTIAL, true);
    }
    // Divide by the largest component first: the squared length of a finite vector may overflow.
    let unit = (v / v.abs().max_element()).normalize();
    (unit * MAX_DIFFERENTIAL, true)
}

/// A ray parameter: NaN becomes 0, an infinity the largest finite value of its sign.
fn sanitize_t(t: f32) -> (f32, bool) {
    match t {
        _ if t.is_nan() => (0.0, true),
        _ if t.is_infinite() => (f32::MAX.copysign(t), true),
        _ => (t, false),
    }
}

/// A directional spread in radians: NaN becomes the widest, a negative one its magnitude, and
/// none exceeds [`MAX_SPREAD_RAD`].
fn sanitize_spread(s: f32) -> (f32, bool) {
    let m = if s.is_nan() { MAX_SPREAD_RAD } else { s.abs().min(MAX_SPREAD_RAD) };
    (m, m != s)
}

/// The refraction geometry shared by [`refract_direction`] and [`RayDifferential::refract`]:
/// `(n facing the incident d, c = d·n ≤ 0, η = incident over transmitted index, cos θt, flipped)`,
/// or `None` at total internal reflection.
fn refraction(d: Vec3A, n: Vec3A, eta: f32) -> Option<(Vec3A, f32, f32, f32, bool)> {
    let c = d.dot(n);
    let flip = c > 0.0; // leaving: the ray is on the side `n` points away from
    let (n, c, eta_rel) = if flip { (-n, -c, eta) } else { (n, c, 1.0 / eta) };
    let k = 1.0 - eta_rel * eta_rel * (1.0 - c * c);
    (k >= 0.0).then(|| (n, c, eta_rel, k.sqrt(), flip))
}

impl RayDifferential {
    /// No spread at all: a ray that stands for itself only.
    pub const ZERO: Self = Self { dpdx: Vec3A::ZERO, dpdy: Vec3A::ZERO, dddx: Vec3A::ZERO, dddy: Vec3A::ZERO };

    /// From the four derivatives (world units and radians per pixel), sanitized.
    pub fn new(dpdx: Vec3A, dpdy: Vec3A, dddx: Vec3A, dddy: Vec3A) -> Self {
        Self::new_checked(dpdx, dpdy, dddx, dddy).0
    }

    fn new_checked(dpdx: Vec3A, dpdy: Vec3A, dddx: Vec3A, dddy: Vec3A) -> (Self, bool) {
        let ((dpdx, a), (dpdy, b)) = (sanitize(dpdx), sanitize(dpdy));
        let ((dddx, c), (dddy, d)) = (sanitize(dddx), sanitize(dddy));
        (Self { dpdx, dpdy, dddx, dddy }, a | b | c | d)
    }

    /// `self` sanitized (the fields are public: anyone may have stored a NaN), and whether that
    /// changed anything.
    fn sanitized(&self) -> (Self, bool) {
        Self::new_checked(self.dpdx, self.dpdy, self.dddx, self.dddy)
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        [self.dpdx, self.dpdy, self.dddx, self.dddy].iter().all(|v| v.is_finite())
    }

    /// A pinhole camera ray, exactly: the origin is fixed (`dP = 0`) and `D = d / |d|` for the
    /// unnormalized world-space direction `d_unnorm` through the pixel, whose per-pixel
    /// derivatives are `dd_dx`, `dd_dy` (for `d = fwd + x·sx + y·sy`, they are `sx` and `sy`).
    ///
    /// Igehy's `dD = ((d·d) dd − (d·dd) d) / (d·d)^{3/2}`, computed in the equal form
    /// `(dd − D (D·dd)) / |d|`: one square root, no cubed length to overflow. A zero or
    /// non-finite `d_unnorm` gives [`RayDifferential::ZERO`].
    pub fn from_pinhole(d_unnorm: Vec3A, dd_dx: Vec3A, dd_dy: Vec3A) -> Self {
        let inv_len = d_unnorm.length_recip();
        if !(inv_len.is_finite() && inv_len > 0.0) {
            return Self::ZERO;
        }
        let d = d_unnorm * inv_len;
        let dddx = (dd_dx - d * d.dot(dd_dx)) * inv_len;
        let dddy = (dd_dy - d * d.dot(dd_dy)) * inv_len;
        Self::new(Vec3A::ZERO, Vec3A::ZERO, dddx, dddy)
    }

    /// An orthographic camera ray, exactly: the origin moves by the pixel spacing vectors
    /// `dp_dx`, `dp_dy` (world units per pixel); the direction does not change (`dD = 0`).
    pub fn from_orthographic(dp_dx: Vec3A, dp_dy: Vec3A) -> Self {
        Self::new(dp_dx, dp_dy, Vec3A::ZERO, Vec3A::ZERO)
    }

    /// A distribution ray: origin derivatives `dpdx`, `dpdy` (the footprint at the point it
    /// leaves) and an isotropic directional spread of `spread_rad` radians around the unit
    /// direction `dir`: `dddx`, `dddy` are two orthonormal vectors perpendicular to `dir` times
    /// the spread. Sampled rays have no image-space neighbours, so which perpendicular pair is
    /// arbitrary; only their lengths matter to the beam width.
    pub fn from_spread(dpdx: Vec3A, dpdy: Vec3A, dir: Vec3A, spread_rad: f32) -> Self {
        Self::from_spread_checked(dpdx, dpdy, dir, spread_rad).0
    }

    fn from_spread_checked(dpdx: Vec3A, dpdy: Vec3A, dir: Vec3A, spread: f32) -> (Self, bool) {
        let ((dpdx, a), (dpdy, b)) = (sanitize(dpdx), sanitize(dpdy));
        let (dddx, dddy, c) = spread_directions(dir, spread);
        (Self { dpdx, dpdy, dddx, dddy }, a | b | c)
    }

    /// The beam width at distance `t` along the ray, in world units per pixel step: the larger
    /// of `|dP/dx + t dD/dx|` and `|dP/dy + t dD/dy|`, the edges of the beam's parallelogram.
    ///
    /// The larger edge, not the area: quads about as wide as the beam's wider side are what the
    /// geometry cache needs (finer would resolve nothing the beam can see), pbrt's trilinear MIP
    /// filter likewise takes the major axis, and it stays non-zero when the parallelogram
    /// degenerates to a segment. Never NaN, at most [`MAX_DIFFERENTIAL`].
    pub fn beam_width_at(&self, t: f32) -> f32 {
        let (ax, ay, _) = self.cross_section(t);
        ax.length().max(ay.length()).min(MAX_DIFFERENTIAL)
    }

    /// The beam width at distance `t` as the square root of the parallelogram's area (world
    /// units per pixel step): the side of the square of equal area. Zero for a degenerate
    /// (segment-shaped) beam, which is why [`RayDifferential::beam_width_at`] is the default.
    pub fn beam_width_area_at(&self, t: f32) -> f32 {
        let (ax, ay, _) = self.cross_section(t);
        ax.cross(ay).length().sqrt().min(MAX_DIFFERENTIAL)
    }

    /// `(dP/dx + t dD/dx, dP/dy + t dD/dy)`, sanitized, and whether anything was clamped.
    fn cross_section(&self, t: f32) -> (Vec3A, Vec3A, bool) {
        let ((s, cs), (t, ct)) = (self.sanitized(), sanitize_t(t));
        let ((ax, cx), (ay, cy)) = (sanitize(s.dpdx + t * s.dddx), sanitize(s.dpdy + t * s.dddy));
        (ax, ay, cs | ct | cx | cy)
    }

    /// The directional spread, in radians per pixel: the larger of `|dD/dx|` and `|dD/dy|`.
    pub fn directional_spread_rad(&self) -> f32 {
        let s = self.sanitized().0;
        s.dddx.length().max(s.dddy.length())
    }

    /// Transfers the differential along the ray (unit direction `d`) to a hit at distance `t`
    /// on a surface with normal `n` (either orientation, any length). Igehy's eq. 10–11:
    /// `dP' = dP + t dD + dt D` with `dt = −((dP + t dD)·n) / (D·n)`, so `dP'` lies in the
    /// tangent plane (the footprint); `dD' = dD`.
    ///
    /// Clamps: `|D·n| < GRAZING_COS_MIN` is held at that value with its sign (the footprint
    /// then leaves the tangent plane slightly, but stays finite); a zero or non-finite `n` is
    /// replaced by `d`, giving the cross-section perpendicular to the ray; a zero or
    /// non-finite `d` leaves `dP + t dD` unprojected.
    pub fn transfer(&self, d: Vec3A, t: f32, n: Vec3A) -> Self {
        self.transfer_checked(d, t, n).0
    }

    /// [`RayDifferential::transfer`], and whether it clamped.
    pub fn transfer_checked(&self, d: Vec3A, t: f32, n: Vec3A) -> (Self, bool) {
        let s = self.sanitized().0;
        let (ax, ay, mut clamped) = self.cross_section(t);
        let (d, mut n) = (d.normalize_or_zero(), n.normalize_or_zero());
        if d == Vec3A::ZERO {
            return (Self::new(ax, ay, s.dddx, s.dddy), true);
        }
        if n == Vec3A::ZERO {
            (n, clamped) = (d, true);
        }
        let mut cos = d.dot(n);
        if cos.abs() < GRAZING_COS_MIN {
            (cos, clamped) = (GRAZING_COS_MIN.copysign(cos), true);
        }
        let (dtdx, dtdy) = (-ax.dot(n) / cos, -ay.dot(n) / cos);
        let (r, c) = Self::new_checked(ax + dtdx * d, ay + dtdy * d, s.dddx, s.dddy);
        (r, c | clamped)
    }

    /// Specular reflection at a hit. `self` must already be transferred there: its `dpdx`,
    /// `dpdy` (the footprint) become the reflected ray's origin derivatives. `d` is the incident
    /// unit direction, `n` the unit normal, and `dndx`, `dndy` its derivatives (from
    /// [`UvDifferentials::chain`] over [`dndu_dndv`]; zero on a plane), in either orientation
    /// as long as they agree. Igehy: `R = D − 2 (D·N) N`, so
    /// `dR = dD − 2 [(D·N) dN + d(D·N) N]` with `d(D·N) = dD·N + D·dN`. A degenerate `d` or
    /// `n` passes `self` through.
    pub fn reflect(&self, d: Vec3A, n: Vec3A, dndx: Vec3A, dndy: Vec3A) -> Self {
        self.reflect_checked(d, n, dndx, dndy).0
    }

    /// [`RayDifferential::reflect`], and whether it clamped.
    pub fn reflect_checked(&self, d: Vec3A, n: Vec3A, dndx: Vec3A, dndy: Vec3A) -> (Self, bool) {
        let (s, cs) = self.sanitized();
        let (d, n) = (d.normalize_or_zero(), n.normalize_or_zero());
        if d == Vec3A::ZERO || n == Vec3A::ZERO {
            return (s, true);
        }
        let ((dndx, cx), (dndy, cy)) = (sanitize(dndx), sanitize(dndy));
        let c = d.dot(n);
        let drdx = s.dddx - 2.0 * (c * dndx + (s.dddx.dot(n) + d.dot(dndx)) * n);
        let drdy = s.dddy - 2.0 * (c * dndy + (s.dddy.dot(n) + d.dot(dndy)) * n);
        let (r, cr) = Self::new_checked(s.dpdx, s.dpdy, drdx, drdy);
        (r, cr | cs | cx | cy)
    }

    /// Specular refraction at a hit (`self` transferred there, as for
    /// [`RayDifferential::reflect`]). `eta` is the index of refraction of the side `n` points
    /// away from over that of the side it points to (pbrt-v4's convention: 1.5 for glass with an
    /// outward normal); whether the ray enters or leaves is read from the sign of `d·n`.
    ///
    /// Igehy, with `η` the incident over the transmitted index and `N` facing the incident ray:
    /// `T = η D − μ N`, `μ = η (D·N) − T·N`, `T·N = −sqrt(1 − η² (1 − (D·N)²))`, so
    /// `dT = η dD − (μ dN + dμ N)` with `dμ = (η − η² (D·N) / (T·N)) d(D·N)`.
    ///
    /// `None` at total internal reflection: the caller reflects instead. Clamps: near the
    /// critical angle `|T·N|` is held at least [`GRAZING_COS_MIN`] where it divides; a
    /// non-finite or non-positive `eta` is taken as 1; a degenerate `d` or `n` passes `self`
    /// through.
    pub fn refract(&self, d: Vec3A, n: Vec3A, dndx: Vec3A, dndy: Vec3A, eta: f32) -> Option<Self> {
        self.refract_checked(d, n, dndx, dndy, eta).map(|r| r.0)
    }

    /// [`RayDifferential::refract`], and whether it clamped.
    pub fn refract_checked(&self, d: Vec3A, n: Vec3A, dndx: Vec3A, dndy: Vec3A, eta: f32) -> Option<(Self, bool)> {
        let (s, cs) = self.sanitized();
        let (eta, ce) = if eta.is_finite() && eta > 0.0 { (eta, false) } else { (1.0, true) };
        let (d, n) = (d.normalize_or_zero(), n.normalize_or_zero());
        if d == Vec3A::ZERO || n == Vec3A::ZERO {
            return Some((s, true));
        }
        let (n, c, eta_rel, cos_t, flip) = refraction(d, n, eta)?;
        let sign = if flip { -1.0 } else { 1.0 };
        let ((dndx, cx), (dndy, cy)) = (sanitize(sign * dndx), sanitize(sign * dndy));
        let mu = eta_rel * c + cos_t;
        let dmu_dc = eta_rel + eta_rel * eta_rel * c / cos_t.max(GRAZING_COS_MIN);
        let dtdx = eta_rel * s.dddx - (mu * dndx + dmu_dc * (s.dddx.dot(n) + d.dot(dndx)) * n);
        let dtdy = eta_rel * s.dddy - (mu * dndy + dmu_dc * (s.dddy.dot(n) + d.dot(dndy)) * n);
        let (r, cr) = Self::new_checked(s.dpdx, s.dpdy, dtdx, dtdy);
        Some((r, cr | cs | ce | cx | cy | (cos_t < GRAZING_COS_MIN)))
    }

    /// A glossy reflection or refraction ray (§4.4), one of `n_rays` sampled over a cone of
    /// half-angle `lobe_half_angle_rad`, leaving in unit direction `dir`. `self` is the
    /// *specular* differential at the same hit ([`RayDifferential::reflect`] or
    /// [`RayDifferential::refract`]), whose footprint becomes the origin derivatives.
    ///
    /// The spread is the larger of the glossy one ([`glossy_spread_rad`]) and the specular one
    /// ([`RayDifferential::directional_spread_rad`]): the paper's heuristic for curved surfaces.
    /// We take the max of the scalar spreads and spread isotropically around `dir`, since a
    /// glossy ray is not the mirror ray and the specular `dD` is not perpendicular to it. On a
    /// flat surface the specular spread is the camera ray's, so the glossy one wins, as the
    /// paper's flat case says.
    pub fn glossy(&self, dir: Vec3A, lobe_half_angle_rad: f32, n_rays: u32) -> Self {
        self.glossy_checked(dir, lobe_half_angle_rad, n_rays).0
    }

    /// [`RayDifferential::glossy`], and whether it clamped.
    pub fn glossy_checked(&self, dir: Vec3A, lobe_half_angle_rad: f32, n_rays: u32) -> (Self, bool) {
        let (sg, cg) = glossy_spread(lobe_half_angle_rad, n_rays);
        self.distribution(dir, sg.max(self.directional_spread_rad()), cg)
    }

    /// A shadow ray toward an area light (§4.5), one of `n_rays`, from the hit `self` was
    /// transferred to, in unit direction `dir`. The light subtends `light_solid_angle_sr`
    /// steradians there (`area · cos θ_light / distance²`); 0, a point light, gives a spread of
    /// 0 (§4.3). See [`area_light_spread_rad`].
    pub fn area_light_shadow(&self, dir: Vec3A, light_solid_angle_sr: f32, n_rays: u32) -> Self {
        self.area_light_shadow_checked(dir, light_solid_angle_sr, n_rays).0
    }

    /// [`RayDifferential::area_light_shadow`], and whether it clamped.
    pub fn area_light_shadow_checked(&self, dir: Vec3A, light_solid_angle_sr: f32, n_rays: u32) -> (Self, bool) {
        let (sp, c) = solid_angle_spread(light_solid_angle_sr, n_rays);
        self.distribution(dir, sp, c)
    }

    /// A hemisphere ray (diffuse, ambient occlusion, final gather; §4.6), one of `n_rays`
    /// importance-sampled with density `pdf_sr` (per steradian) for its direction `dir`, from
    /// the hit `self` was transferred to. Spread `sqrt(1 / (N p(ω)))`: [`spread_from_pdf_rad`].
    pub fn hemisphere(&self, dir: Vec3A, pdf_sr: f32, n_rays: u32) -> Self {
        self.hemisphere_checked(dir, pdf_sr, n_rays).0
    }

    /// [`RayDifferential::hemisphere`], and whether it clamped (e.g. `pdf_sr = 0` at the
    /// horizon of a cosine-weighted lobe).
    pub fn hemisphere_checked(&self, dir: Vec3A, pdf_sr: f32, n_rays: u32) -> (Self, bool) {
        let (sp, c) = pdf_spread(pdf_sr, n_rays);
        self.distribution(dir, sp, c)
    }

    /// [`RayDifferential::hemisphere_checked`] for the many rays of one footprint (ambient
    /// occlusion's, a final gather's): the footprint is sanitized once, not once a ray.
    pub fn hemisphere_fan(&self) -> HemisphereFan {
        let (s, cs) = self.sanitized();
        let ((dpdx, a), (dpdy, b)) = (sanitize(s.dpdx), sanitize(s.dpdy));
        HemisphereFan { dpdx, dpdy, clamped: cs | a | b }
    }

    /// A path-tracing ray, one sample per bounce (§2.5; §4.6's worst case), from the hit `self`
    /// was transferred to, sampled with density `pdf_sr` at path depth `depth` (1 for the first
    /// bounce), `n_paths` paths per pixel reaching that depth. Spread
    /// [`path_sample_spacing`] `· sqrt(1 / p(ω))`: the hemisphere spread at depth 1.
    pub fn path(&self, dir: Vec3A, pdf_sr: f32, depth: u32, n_paths: u32) -> Self {
        self.path_checked(dir, pdf_sr, depth, n_paths).0
    }

    /// [`RayDifferential::path`], and whether it clamped.
    pub fn path_checked(&self, dir: Vec3A, pdf_sr: f32, depth: u32, n_paths: u32) -> (Self, bool) {
        let (sp, c) = pdf_spread(pdf_sr, 1);
        self.distribution(dir, sp * path_sample_spacing(depth, n_paths), c)
    }

    fn distribution(&self, dir: Vec3A, spread_rad: f32, clamped: bool) -> (Self, bool) {
        let (s, cs) = self.sanitized();
        let (r, cr) = Self::from_spread_checked(s.dpdx, s.dpdy, dir, spread_rad);
        (r, cr | cs | clamped)
    }

    /// Scales all four derivatives by `s` (pbrt's `ScaleDifferentials`): with several samples
    /// per pixel, `s = 1 / sqrt(spp)` makes each sample's beam the width of its share of the
    /// pixel. For camera rays only: distribution spreads already count their rays. A non-finite
    /// `s` leaves `self` unscaled (but sanitized). Returns whether it clamped.
    pub fn scale(&mut self, s: f32) -> bool {
        let (r, c) = if s.is_finite() {
            Self::new_checked(self.dpdx * s, self.dpdy * s, self.dddx * s, self.dddy * s)
        } else {
            (self.sanitized().0, true)
        };
        *self = r;
        c
    }
}

/// A footprint prepared for hemisphere rays ([`RayDifferential::hemisphere_fan`]).
#[derive(Clone, Copy, Debug)]
pub struct HemisphereFan {
    /// The footprint's origin derivatives, sanitized (world units per pixel step).
    dpdx: Vec3A,
    dpdy: Vec3A,
    /// Whether sanitizing the footprint clamped anything.
    clamped: bool,
}

impl HemisphereFan {
    /// [`RayDifferential::hemisphere_checked`]`(dir, pdf_sr, n_rays)` of the footprint, bit for
    /// bit, and whether it clamped.
    pub fn ray(&self, dir: Vec3A, pdf_sr: f32, n_rays: u32) -> (RayDifferential, bool) {
        let (spread, c) = pdf_spread(pdf_sr, n_rays);
        let (dddx, dddy, cd) = spread_directions(dir, spread);
        (RayDifferential { dpdx: self.dpdx, dpdy: self.dpdy, dddx, dddy }, self.clamped | c | cd)
    }
}

/// The direction derivatives of an isotropic spread of `spread` radians around `dir` (two
/// orthonormal vectors perpendicular to it, times the spread), sanitized, and whether anything
/// was clamped (the spread, a zero direction, the vectors).
fn spread_directions(dir: Vec3A, spread: f32) -> (Vec3A, Vec3A, bool) {
    let (s, cs) = sanitize_spread(spread);
    let dir = dir.normalize_or_zero();
    let ((e1, e2), cd) = if dir == Vec3A::ZERO { ((Vec3A::X, Vec3A::Y), true) } else { (dir.any_orthonormal_pair(), false) };
    let ((dddx, cx), (dddy, cy)) = (sanitize(e1 * s), sanitize(e2 * s));
    (dddx, dddy, cs | cd | cx | cy)
}

/// The directional spread, in radians, of one of `n_rays` rays importance-sampled with density
/// `pdf_sr` (per steradian) at its direction: `sqrt(1 / (N p(ω)))`, the side of the solid angle
/// `1 / (N p)` the ray stands for (§4.6). Cosine-weighted sampling (`p = cos θ / π`) makes rays
/// near the pole narrower than near the horizon by `sqrt(cos θ_horizon / cos θ_pole)`. A
/// non-positive or NaN pdf gives the widest spread, [`MAX_SPREAD_RAD`]; an infinite pdf (a
/// delta lobe) gives 0; `n_rays = 0` is taken as 1.
pub fn spread_from_pdf_rad(pdf_sr: f32, n_rays: u32) -> f32 {
    pdf_spread(pdf_sr, n_rays).0
}

fn pdf_spread(pdf_sr: f32, n_rays: u32) -> (f32, bool) {
    let denom = n_rays.max(1) as f32 * pdf_sr;
    if denom.is_nan() || denom <= 0.0 {
        return (MAX_SPREAD_RAD, true);
    }
    let (s, c) = sanitize_spread(denom.recip().sqrt());
    (s, c | (n_rays == 0))
}

/// One of `n_rays` rays sharing a solid angle of `solid_angle_sr` steradians uniformly:
/// `sqrt(Ω / N)` radians, i.e. [`spread_from_pdf_rad`] with `p = 1 / Ω`.
fn solid_angle_spread(solid_angle_sr: f32, n_rays: u32) -> (f32, bool) {
    let omega = if solid_angle_sr.is_nan() { 4.0 * PI } else { solid_angle_sr.clamp(0.0, 4.0 * PI) };
    let (s, cs) = sanitize_spread((omega / n_rays.max(1) as f32).sqrt());
    (s, cs | (omega != solid_angle_sr) | (n_rays == 0))
}

/// The glossy spread (§4.4), in radians, of one of `n_rays` rays sampled over a cone of
/// half-angle `lobe_half_angle_rad` (clamped to `[0, π]`): each stands for `Ω / N` of the cone's
/// solid angle `Ω = 2π (1 − cos α)`, so the spread is `sqrt(Ω / N)`. The paper's "cone angle
/// divided by the number of rays" is its 2D figure 3; in 3D the rays divide a solid angle, so
/// the angle per ray goes as `1 / sqrt(N)`, as [`spread_from_pdf_rad`] gives for a uniform lobe.
pub fn glossy_spread_rad(lobe_half_angle_rad: f32, n_rays: u32) -> f32 {
    glossy_spread(lobe_half_angle_rad, n_rays).0
}

fn glossy_spread(lobe_half_angle_rad: f32, n_rays: u32) -> (f32, bool) {
    let a = if lobe_half_angle_rad.is_nan() { PI } else { lobe_half_angle_rad.clamp(0.0, PI) };
    // 2π (1 − cos α) = 4π sin²(α/2), without the cancellation of narrow lobes.
    let half_sin = (0.5 * a).sin();
    let (s, cs) = solid_angle_spread(4.0 * PI * half_sin * half_sin, n_rays);
    (s, cs | (a != lobe_half_angle_rad))
}

/// The spread of a shadow ray toward an area light (§4.5), in radians: "the relative size of
/// the light source divided by the number of shadow rays", read as the light's solid angle
/// `light_solid_angle_sr` shared by `n_rays` rays, `sqrt(Ω / N)`: its angular size over `√N`.
pub fn area_light_spread_rad(light_solid_angle_sr: f32, n_rays: u32) -> f32 {
    solid_angle_spread(light_solid_angle_sr, n_rays).0
}

/// Suykens and Willems' path differential as the paper quotes it (§2.5): the global sample
/// spacing `d / N^{1/(2d)}` at path depth `d` for `N` paths per pixel reaching that depth (0 is
/// taken as 1 for both), as a fraction of each bounce's unit sampling domain, capped at 1 (the
/// whole domain). Times `sqrt(1 / p(ω))` it is a spread in radians ([`RayDifferential::path`]).
pub fn path_sample_spacing(depth: u32, n_paths: u32) -> f32 {
    let (d, n) = (depth.max(1) as f32, n_paths.max(1) as f32);
    (d / n.powf(0.5 / d)).min(1.0)
}

/// The unit reflected direction `d − 2 (d·n) n` of the incident direction `d` (toward the
/// surface) about the normal `n` (either orientation). Zero if `d` or `n` is degenerate.
pub fn reflect_direction(d: Vec3A, n: Vec3A) -> Vec3A {
    let (d, n) = (d.normalize_or_zero(), n.normalize_or_zero());
    (d - 2.0 * d.dot(n) * n).normalize_or_zero()
}

/// The unit refracted direction of the incident direction `d` at a surface with normal `n` and
/// index ratio `eta`, in the convention of [`RayDifferential::refract`]; `None` at total
/// internal reflection, or when `d`, `n` or `eta` is degenerate.
pub fn refract_direction(d: Vec3A, n: Vec3A, eta: f32) -> Option<Vec3A> {
    let (d, n) = (d.normalize_or_zero(), n.normalize_or_zero());
    if d == Vec3A::ZERO || n == Vec3A::ZERO || !(eta.is_finite() && eta > 0.0) {
        return None;
    }
    let (n, c, eta_rel, cos_t, _) = refraction(d, n, eta)?;
    (eta_rel * d - (eta_rel * c + cos_t) * n).try_normalize()
}

/// The derivatives of the unit normal `N = normalize(dpdu × dpdv)` along the surface, from the
/// position's first and second derivatives (Weingarten equations, as pbrt): with
/// `E, F, G = dpdu·dpdu, dpdu·dpdv, dpdv·dpdv` and `e, f, g = N·dpduu, N·dpduv, N·dpdvv`,
/// `dN/du = ((fF − eG) dpdu + (eF − fE) dpdv) / (EG − F²)` and
/// `dN/dv = ((gF − fG) dpdu + (fF − gE) dpdv) / (EG − F²)`.
///
/// The results belong to that orientation of `N`: negate both if the renderer flips the normal.
/// Scale free: the inputs are first divided by the longer of `|dpdu|`, `|dpdv|` (the normal
/// field does not change), so `EG − F²` neither overflows nor underflows at huge or tiny scene
/// scales; and `EG − F²` is computed as `|dpdu × dpdv|²` (Lagrange's identity), which does not
/// cancel. A degenerate parameterization gives zeros (a flat surface).
pub fn dndu_dndv(dpdu: Vec3A, dpdv: Vec3A, dpduu: Vec3A, dpduv: Vec3A, dpdvv: Vec3A) -> (Vec3A, Vec3A) {
    let k = dpdu.length().max(dpdv.length()).recip();
    let (pu, pv) = (dpdu * k, dpdv * k);
    let cross = pu.cross(pv);
    let inv_det = cross.length_squared().recip();
    if !(k.is_finite() && k > 0.0 && inv_det.is_finite()) {
        return (Vec3A::ZERO, Vec3A::ZERO);
    }
    let n = cross * inv_det.sqrt();
    let (e_, f_, g_) = (pu.dot(pu), pu.dot(pv), pv.dot(pv));
    let (e, f, g) = (n.dot(dpduu * k), n.dot(dpduv * k), n.dot(dpdvv * k));
    let dndu = ((f * f_ - e * g_) * pu + (e * f_ - f * e_) * pv) * inv_det;
    let dndv = ((g * f_ - f * g_) * pu + (f * f_ - g * e_) * pv) * inv_det;
    (sanitize(dndu).0, sanitize(dndv).0)
}

/// The derivatives of the surface parameters `(u, v)` with respect to the image `x`, `y` at a
/// hit, per pixel step: texture filter widths, and the chain rule for the normal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UvDifferentials {
    /// du/dx, per pixel.
    pub dudx: f32,
    /// dv/dx, per pixel.
    pub dvdx: f32,
    /// du/dy, per pixel.
    pub dudy: f32,
    /// dv/dy, per pixel.
    pub dvdy: f32,
    /// Set when `dpdu`, `dpdv` were degenerate or a result was clamped to ±1e8 (pbrt's bound).
    pub clamped: bool,
}

impl UvDifferentials {
    /// From the footprint `dpdx`, `dpdy` at the hit ([`RayDifferential::transfer`]) and the
    /// surface's `dpdu`, `dpdv`: the least-squares solution of `dpdx ≈ dudx·dpdu + dvdx·dpdv`
    /// (and for `y`), as pbrt's `ComputeDifferentials`. No normal is needed: least squares over
    /// the three equations discards the component along `dpdu × dpdv` by itself.
    ///
    /// Computed as `dudx = ((dpdx × pv)·c) / (|c|² |dpdu|)`, `dvdx = ((pu × dpdx)·c) /
    /// (|c|² |dpdv|)` with `pu`, `pv` the unit `dpdu`, `dpdv` and `c = pu × pv`: the normal
    /// equations' solution, without their cancellation or overflow. Degenerate `dpdu`, `dpdv`
    /// give zeros; results are clamped to ±1e8 and NaN to 0 (pbrt). Both set `clamped`.
    pub fn from_footprint(dpdx: Vec3A, dpdy: Vec3A, dpdu: Vec3A, dpdv: Vec3A) -> Self {
        let ((dpdx, cx), (dpdy, cy)) = (sanitize(dpdx), sanitize(dpdy));
        let (inv_lu, inv_lv) = (dpdu.length_recip(), dpdv.length_recip());
        let (pu, pv) = (dpdu * inv_lu, dpdv * inv_lv);
        let c = pu.cross(pv);
        let inv_det = c.length_squared().recip();
        let ok = |x: f32| x.is_finite() && x > 0.0;
        if !(ok(inv_lu) && ok(inv_lv) && inv_det.is_finite()) {
            return Self { clamped: true, ..Self::default() };
        }
        let raw = |p: Vec3A| (p.cross(pv).dot(c) * inv_lu, pu.cross(p).dot(c) * inv_lv);
        let ((a, b), (e, f)) = (raw(dpdx), raw(dpdy));
        let fix = |x: f32| match x * inv_det {
            y if y.is_finite() => y.clamp(-1e8, 1e8),
            _ => 0.0,
        };
        let (dudx, dvdx, dudy, dvdy) = (fix(a), fix(b), fix(e), fix(f));
        let changed = [dudx, dvdx, dudy, dvdy] != [a, b, e, f].map(|x| x * inv_det);
        Self { dudx, dvdx, dudy, dvdy, clamped: cx | cy | changed }
    }

    /// The chain rule for a vector quantity `f(u, v)` on the surface: `(df/dx, df/dy)`
    /// `= (dfdu·dudx + dfdv·dvdx, dfdu·dudy + dfdv·dvdy)`. With `dndu`, `dndv` from
    /// [`dndu_dndv`] this gives the `dndx`, `dndy` of [`RayDifferential::reflect`]. Sanitized
    /// like a differential (NaN to 0, length capped), unflagged.
    pub fn chain(&self, dfdu: Vec3A, dfdv: Vec3A) -> (Vec3A, Vec3A) {
        let dfdx = dfdu * self.dudx + dfdv * self.dvdx;
        let dfdy = dfdu * self.dudy + dfdv * self.dvdy;
        (sanitize(dfdx).0, sanitize(dfdy).0)
    }
}

#[cfg(test)]
mod tests;
