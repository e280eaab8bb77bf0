//! Implicit surfaces — USD's `Sphere`, `Cube`, `Cylinder`, `Cylinder_1`, `Cone`, `Capsule`,
//! `Capsule_1` and `Plane` gprims — and `Points` as spheres, intersected exactly: closed-form
//! ray–quadric, ray–disk and ray–rectangle tests, not a tessellation.
//!
//! Each shape is a few analytic *pieces* (a sphere zone, a frustum's side, a disk, a rectangle),
//! and each piece is one patch of a [`LimitSurface`]: its own (u, v) in [0, 1]², position and
//! first and second derivatives in closed form. Shading, ray differentials (dP/du, dP/dv and,
//! through the second derivatives, dN/du, dN/dv), texture filtering, instancing and motion blur
//! therefore see them exactly as they see a subdivision surface; only the ray test differs
//! ([`ExactSurface`], which the tracer asks for through [`LimitSurface::exact`]).
//!
//! # Parameterisation (RenderMan's quadrics; `st` = (u, v))
//! In the shape's *canonical frame* the spine is +z; `axis` maps it to object space by a cyclic
//! permutation (X: canonical (a, b, c) → object (c, a, b), i.e. a→y, b→z, c→x; Y: a→z, b→x,
//! c→y), which keeps handedness, so dP/du × dP/dv is the outward normal on every piece.
//! - sphere zone (sphere, capsule caps, points): u = φ / 2π with φ the longitude from +a
//!   toward +b, v = (θ − θ₀) / (θ₁ − θ₀) with θ the latitude (−π/2 at the −c pole);
//! - frustum side (cylinder, cone, `_1` forms, capsule body): u = φ / 2π, v = (z − z₀) / (z₁ − z₀)
//!   from the bottom rim (a cone's apex is at v = 1);
//! - disk cap: u = φ / 2π (the top cap's φ runs from +a toward +b, the bottom cap's from +a
//!   toward −b, so each faces outward), v = 1 − ρ / radius (RenderMan's disk: the rim at v = 0);
//! - cube face: u and v along the next two canonical axes in cyclic order (a: b, c; b: c, a;
//!   c: a, b) for the + face, swapped for the − face, each from the face's low corner;
//! - plane: u along the canonical a axis (width for axis Z, length for X and Y), v along b.
//!
//! Patch order (the `elementId` AOV reports it): sphere 0; cube +a, −a, +b, −b, +c, −c;
//! cylinder and cone side, bottom cap, top cap (caps of radius 0 are left out); capsule side,
//! bottom cap, top cap; plane 0; points: the point's index.
//!
//! Capsules follow Storm (GeomUtil's capsule generator): the body is the frustum from
//! `radiusBottom` at −height/2 to `radiusTop` at +height/2, capped by hemispheres of those
//! radii centred at the rims.
//!
//! Numerics: the tests run in f64 on the f32 object-space ray (robust quadratic roots, the
//! discriminant of the sphere from the ray's distance to the centre as pbrt-v4 does), so grazing
//! rays and radii from 1e-6 to 1e6 resolve to the f32 answer. Every hit reports a bound on its
//! own floating-point error ([`ExactHit::error`]); the tracer uses it as the hit's chord error,
//! so a secondary ray leaving the surface ignores the surface it stands on within that bound
//! (the project's self-intersection rule, [`crate::trace::Tracer::intersect_from`]).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use glam::{DVec3, Vec3A};

use crate::bounds::Bounds3;
use crate::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};
use crate::ray::gamma;

/// The axis a shape's spine (or a plane's normal) runs along, USD's `axis` token.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Axis {
    X,
    Y,
    #[default]
    Z,
}

impl Axis {
    /// USD's `axis` token ("X", "Y" or "Z").
    pub fn from_usd(token: &str) -> Option<Axis> {
        match token {
            "X" => Some(Axis::X),
            "Y" => Some(Axis::Y),
            "Z" => Some(Axis::Z),
            _ => None,
        }
    }

    /// Object space from the canonical frame (spine +z): a cyclic permutation.
    fn to_object(self, v: DVec3) -> DVec3 {
        match self {
            Axis::Z => v,
            Axis::X => DVec3::new(v.z, v.x, v.y),
            Axis::Y => DVec3::new(v.y, v.z, v.x),
        }
    }

    /// The canonical frame from object space (the inverse of [`Axis::to_object`]).
    fn to_canonical(self, v: DVec3) -> DVec3 {
        match self {
            Axis::Z => v,
            Axis::X => DVec3::new(v.y, v.z, v.x),
            Axis::Y => DVec3::new(v.z, v.x, v.y),
        }
    }
}

/// An implicit gprim with its schema attributes. Object units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// `Sphere`: centred at the origin.
    Sphere { radius: f32 },
    /// `Cube`: edge length `size`, centred at the origin.
    Cube { size: f32 },
    /// `Cylinder` (both radii `radius`), `Cylinder_1`, and `Cone` (`radius_top` 0, the apex at
    /// +height/2): a closed frustum centred at the origin.
    Cylinder { radius_bottom: f32, radius_top: f32, height: f32, axis: Axis },
    /// `Capsule` and `Capsule_1`: the frustum of [`Shape::Cylinder`] (`height` excludes the caps)
    /// with hemispherical caps of its rims' radii.
    Capsule { radius_bottom: f32, radius_top: f32, height: f32, axis: Axis },
    /// `Plane`: a `width` × `length` rectangle through the origin facing +axis.
    Plane { width: f32, length: f32, axis: Axis },
}

impl Shape {
    /// The USD prim type's name, for messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            Shape::Sphere { .. } => "Sphere",
            Shape::Cube { .. } => "Cube",
            Shape::Cylinder { radius_top, .. } if *radius_top == 0.0 => "Cone",
            Shape::Cylinder { .. } => "Cylinder",
            Shape::Capsule { .. } => "Capsule",
            Shape::Plane { .. } => "Plane",
        }
    }

    /// Refuses sizes that leave nothing to render or cannot be traced: the message names the
    /// attribute and its value.
    ///
    /// # Errors
    /// A size that is not finite, is negative, or is zero where it must not be (a cylinder may
    /// have one radius 0, a cone's top radius is 0; every other size must be positive).
    pub fn validate(&self) -> Result<(), String> {
        let positive = |name: &str, v: f32| {
            if v.is_finite() && v > 0.0 && v <= crate::bounds::MAX_COORDINATE {
                Ok(())
            } else {
                Err(format!("{name} = {v} must be a positive number (up to {:e})", crate::bounds::MAX_COORDINATE))
            }
        };
        let radii = |bottom: f32, top: f32| {
            for (name, r) in [("radiusBottom", bottom), ("radiusTop", top)] {
                if !(r.is_finite() && (0.0..=crate::bounds::MAX_COORDINATE).contains(&r)) {
                    return Err(format!("{name} = {r} must be a non-negative number"));
                }
            }
            if bottom == 0.0 && top == 0.0 {
                return Err("radius = 0: nothing to render".to_string());
            }
            Ok(())
        };
        match *self {
            Shape::Sphere { radius } => positive("radius", radius),
            Shape::Cube { size } => positive("size", size),
            Shape::Cylinder { radius_bottom, radius_top, height, .. } | Shape::Capsule { radius_bottom, radius_top, height, .. } => {
                radii(radius_bottom, radius_top)?;
                match self {
                    // A capsule of height 0 is a sphere (or two): still something to render.
                    Shape::Capsule { .. } if height == 0.0 => Ok(()),
                    _ => positive("height", height),
                }
            }
            Shape::Plane { width, length, .. } => positive("width", width).and(positive("length", length)),
        }
    }
}

/// One analytic piece of a shape, in the shape's canonical frame (spine +z).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Piece {
    /// The zone of the sphere of `radius` about (0, 0, `z`) between latitudes θ₀ < θ₁ (radians).
    Zone { z: f64, radius: f64, theta0: f64, theta1: f64 },
    /// The side of the frustum from radius `r0` at height `z0` to `r1` at `z1` (z0 < z1).
    Side { z0: f64, z1: f64, r0: f64, r1: f64 },
    /// The disk of `radius` at height `z`, facing +z when `up`, else −z.
    Disk { z: f64, radius: f64, up: bool },
    /// The parallelogram `origin + u·eu + v·ev`, facing eu × ev.
    Rect { origin: DVec3, eu: DVec3, ev: DVec3 },
}

/// A ray's hit on one patch of an [`ExactSurface`]. Object space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExactHit {
    /// The ray parameter (the object-space ray is the render-space one transformed, so this is
    /// the render-space t too).
    pub t: f32,
    /// The patch's own parameters at the hit.
    pub u: f32,
    pub v: f32,
    /// Unit outward normal of the surface at the hit (dP/du × dP/dv's direction; where that
    /// vanishes — a pole, a cone's apex — the limit of the normals around it).
    pub n: Vec3A,
    /// Bound on the hit point's distance from the surface from floating-point error, object
    /// units.
    pub error: f32,
}

/// Surfaces the tracer intersects in closed form instead of tessellating.
pub trait ExactSurface: Send + Sync {
    /// The nearest hit of the object-space ray `o + t·d` on patch `patch` with t in
    /// (t_min, t_max), or `None`.
    fn intersect(&self, patch: usize, o: Vec3A, d: Vec3A, t_min: f32, t_max: f32) -> Option<ExactHit>;

    /// [`ExactSurface::intersect`] at shutter time `time` (0 = open, 1 = close, as
    /// [`crate::ray::Ray::time`]): the same for a surface that keeps its shape — the default —
    /// and the surface of that time for one that deforms (moving points).
    fn intersect_at(&self, patch: usize, o: Vec3A, d: Vec3A, t_min: f32, t_max: f32, _time: f32) -> Option<ExactHit> {
        self.intersect(patch, o, d, t_min, t_max)
    }
}

/// A root in (t_min, t_max) of `a t² + 2 b t + c`, nearest first, that `accept` takes.
/// Computed as `q = −(b + sign(b)·√disc)`, roots q/a and c/q, so neither root loses digits to
/// cancellation (and a = 0, a ray along a ruling of the quadric, leaves the linear root c/q).
fn quadratic_roots(a: f64, b: f64, c: f64, disc: f64, t_min: f64, t_max: f64, mut accept: impl FnMut(f64) -> bool) -> Option<f64> {
    if !(disc >= 0.0) {
        return None;
    }
    let q = -(b + disc.sqrt().copysign(b));
    let (mut t0, mut t1) = (q / a, c / q);
    if !(t0 <= t1) {
        std::mem::swap(&mut t0, &mut t1);
    }
    [t0, t1].into_iter().find(|&t| t.is_finite() && t > t_min && t < t_max && accept(t))
}

/// The longitude of (x, y) as a fraction of a turn, in [0, 1).
fn turn(x: f64, y: f64) -> f64 {
    let u = y.atan2(x) / TAU;
    if u < 0.0 {
        (u + 1.0).min(1.0 - f64::EPSILON)
    } else {
        u
    }
}

fn v3(v: DVec3) -> Vec3A {
    Vec3A::new(v.x as f32, v.y as f32, v.z as f32)
}

fn d3(v: Vec3A) -> DVec3 {
    DVec3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

/// The hit's floating-point error bound: a few ulps (f32: the ray and the result are f32) of
/// the magnitudes involved.
fn error_bound(o: DVec3, d: DVec3, t: f64, p: DVec3) -> f32 {
    (f64::from(gamma(16)) * (o.abs().max_element() + (t * d).abs().max_element() + p.abs().max_element())) as f32
}

impl Piece {
    /// Closed-form hit in the canonical frame: (t, u, v, unit outward normal).
    fn intersect(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<(f64, f64, f64, DVec3)> {
        match *self {
            Piece::Zone { z, radius, theta0, theta1 } => {
                let c = DVec3::new(0.0, 0.0, z);
                let (t, p) = sphere_hit(c, radius, o, d, t_min, t_max, |p| {
                    let s = ((p.z - z) / radius).clamp(-1.0, 1.0);
                    s >= theta0.sin() && s <= theta1.sin()
                })?;
                let n = (p - c) / radius;
                let theta = n.z.clamp(-1.0, 1.0).asin();
                Some((t, turn(n.x, n.y), ((theta - theta0) / (theta1 - theta0)).clamp(0.0, 1.0), n.normalize_or(DVec3::Z)))
            }
            Piece::Side { z0, z1, r0, r1 } => {
                // x² + y² = (k z + m)², the radius linear in z.
                let k = (r1 - r0) / (z1 - z0);
                let m = r0 - k * z0;
                let (ro, rd) = (k * o.z + m, k * d.z);
                let a = d.x * d.x + d.y * d.y - rd * rd;
                let b = o.x * d.x + o.y * d.y - ro * rd;
                let c = o.x * o.x + o.y * o.y - ro * ro;
                // b² − a c without cancellation for the cylinder (k = 0, pbrt-v4's form):
                // a (r² − |o⊥ − (o⊥·d⊥ / |d⊥|²) d⊥|²), the squared distance of the axis from the ray.
                let disc = if k == 0.0 && a > 0.0 {
                    let f = DVec3::new(o.x, o.y, 0.0) - DVec3::new(d.x, d.y, 0.0) * (b / a);
                    a * (r0 * r0 - f.length_squared())
                } else {
                    b * b - a * c
                };
                let t = quadratic_roots(a, b, c, disc, t_min, t_max, |t| {
                    let pz = o.z + t * d.z;
                    pz >= z0 && pz <= z1
                })?;
                let p = o + t * d;
                let rho = k * p.z + m;
                let n = DVec3::new(p.x, p.y, -k * rho).normalize_or(DVec3::Z.copysign(DVec3::splat(r0 - r1)));
                Some((t, turn(p.x, p.y), ((p.z - z0) / (z1 - z0)).clamp(0.0, 1.0), n))
            }
            Piece::Disk { z, radius, up } => {
                let t = (z - o.z) / d.z;
                if !(t.is_finite() && t > t_min && t < t_max) {
                    return None;
                }
                let p = o + t * d;
                let rho2 = p.x * p.x + p.y * p.y;
                if rho2 > radius * radius {
                    return None;
                }
                let s = if up { 1.0 } else { -1.0 };
                Some((t, turn(p.x, s * p.y), (1.0 - rho2.sqrt() / radius).clamp(0.0, 1.0), DVec3::new(0.0, 0.0, s)))
            }
            Piece::Rect { origin, eu, ev } => {
                let n = eu.cross(ev).normalize();
                let t = (origin - o).dot(n) / d.dot(n);
                if !(t.is_finite() && t > t_min && t < t_max) {
                    return None;
                }
                let q = o + t * d - origin;
                let (u, v) = (q.dot(eu) / eu.length_squared(), q.dot(ev) / ev.length_squared());
                // Shared edges (a cube's) hit on at least one side despite rounding.
                const SLACK: f64 = 1e-12;
                if !((-SLACK..=1.0 + SLACK).contains(&u) && (-SLACK..=1.0 + SLACK).contains(&v)) {
                    return None;
                }
                Some((t, u.clamp(0.0, 1.0), v.clamp(0.0, 1.0), n))
            }
        }
    }

    /// Position and derivatives at (u, v), canonical frame.
    fn evaluate(&self, u: f64, v: f64) -> [DVec3; 6] {
        let phi = TAU * u;
        let (sp, cp) = phi.sin_cos();
        match *self {
            Piece::Zone { z, radius, theta0, theta1 } => sphere_eval(DVec3::new(0.0, 0.0, z), radius, theta0, theta1, u, v),
            Piece::Side { z0, z1, r0, r1 } => {
                let (dr, dz) = (r1 - r0, z1 - z0);
                let rho = r0 + v * dr;
                [
                    DVec3::new(rho * cp, rho * sp, z0 + v * dz),
                    TAU * rho * DVec3::new(-sp, cp, 0.0),
                    DVec3::new(dr * cp, dr * sp, dz),
                    -TAU * TAU * rho * DVec3::new(cp, sp, 0.0),
                    TAU * dr * DVec3::new(-sp, cp, 0.0),
                    DVec3::ZERO,
                ]
            }
            Piece::Disk { z, radius, up } => {
                // The bottom cap mirrors y so that dP/du × dP/dv faces −z.
                let s = if up { 1.0 } else { -1.0 };
                let rho = radius * (1.0 - v);
                [
                    DVec3::new(rho * cp, s * rho * sp, z),
                    TAU * rho * DVec3::new(-sp, s * cp, 0.0),
                    -radius * DVec3::new(cp, s * sp, 0.0),
                    -TAU * TAU * rho * DVec3::new(cp, s * sp, 0.0),
                    -TAU * radius * DVec3::new(-sp, s * cp, 0.0),
                    DVec3::ZERO,
                ]
            }
            Piece::Rect { origin, eu, ev } => [origin + u * eu + v * ev, eu, ev, DVec3::ZERO, DVec3::ZERO, DVec3::ZERO],
        }
    }

    /// Canonical-frame bounds.
    fn bounds(&self) -> (DVec3, DVec3) {
        match *self {
            Piece::Zone { z, radius, theta0, theta1 } => {
                let (lo, hi) = (z + radius * theta0.sin(), z + radius * theta1.sin());
                // The widest circle of the zone: the equator if the zone spans it.
                let w = if theta0 <= 0.0 && theta1 >= 0.0 { radius } else { radius * theta0.cos().max(theta1.cos()) };
                (DVec3::new(-w, -w, lo), DVec3::new(w, w, hi))
            }
            Piece::Side { z0, z1, r0, r1 } => {
                let r = r0.max(r1);
                (DVec3::new(-r, -r, z0), DVec3::new(r, r, z1))
            }
            Piece::Disk { z, radius, .. } => (DVec3::new(-radius, -radius, z), DVec3::new(radius, radius, z)),
            Piece::Rect { origin, eu, ev } => {
                let corners = [origin, origin + eu, origin + ev, origin + eu + ev];
                corners.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), c| (lo.min(*c), hi.max(*c)))
            }
        }
    }
}

/// The nearest hit in (t_min, t_max) on the sphere of `radius` about `c` whose point `accept`
/// takes: (t, point). The discriminant is taken from the ray's distance to the centre
/// (pbrt-v4), exact to rounding for grazing rays where b² − a c cancels.
fn sphere_hit(
    c: DVec3,
    radius: f64,
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
    mut accept: impl FnMut(DVec3) -> bool,
) -> Option<(f64, DVec3)> {
    let f = o - c;
    let a = d.length_squared();
    if !(a > 0.0) {
        return None;
    }
    let b = f.dot(d);
    let cc = f.length_squared() - radius * radius;
    let perp = f - d * (b / a);
    let disc = a * (radius * radius - perp.length_squared());
    let t = quadratic_roots(a, b, cc, disc, t_min, t_max, |t| accept(o + t * d))?;
    // Re-project onto the sphere: the point is then exact to rounding whatever t's error.
    let p = o + t * d;
    let r = p - c;
    let len = r.length();
    Some((t, if len > 0.0 { c + r * (radius / len) } else { p }))
}

/// Position and derivatives of the sphere zone θ ∈ [θ₀, θ₁] about `c` at (u, v).
fn sphere_eval(c: DVec3, radius: f64, theta0: f64, theta1: f64, u: f64, v: f64) -> [DVec3; 6] {
    let (sp, cp) = (TAU * u).sin_cos();
    let dt = theta1 - theta0;
    let (st, ct) = (theta0 + v * dt).sin_cos();
    let radial = DVec3::new(ct * cp, ct * sp, st);
    [
        c + radius * radial,
        TAU * radius * ct * DVec3::new(-sp, cp, 0.0),
        dt * radius * DVec3::new(-st * cp, -st * sp, ct),
        -TAU * TAU * radius * ct * DVec3::new(cp, sp, 0.0),
        TAU * dt * radius * st * DVec3::new(sp, -cp, 0.0),
        -dt * dt * radius * radial,
    ]
}

/// The pieces of a shape (see the module's patch order).
fn pieces(shape: &Shape) -> Vec<Piece> {
    match *shape {
        Shape::Sphere { radius } => vec![Piece::Zone { z: 0.0, radius: f64::from(radius), theta0: -FRAC_PI_2, theta1: FRAC_PI_2 }],
        Shape::Cube { size } => {
            let s = f64::from(size);
            let h = 0.5 * s;
            let e = [DVec3::X, DVec3::Y, DVec3::Z];
            let mut out = Vec::with_capacity(6);
            for k in 0..3 {
                let (a, b, c) = (e[k], e[(k + 1) % 3], e[(k + 2) % 3]);
                let low = -h * (b + c);
                out.push(Piece::Rect { origin: h * a + low, eu: s * b, ev: s * c });
                out.push(Piece::Rect { origin: -h * a + low, eu: s * c, ev: s * b });
            }
            out
        }
        Shape::Cylinder { radius_bottom, radius_top, height, .. } => {
            let (r0, r1, h) = (f64::from(radius_bottom), f64::from(radius_top), 0.5 * f64::from(height));
            let mut out = vec![Piece::Side { z0: -h, z1: h, r0, r1 }];
            if r0 > 0.0 {
                out.push(Piece::Disk { z: -h, radius: r0, up: false });
            }
            if r1 > 0.0 {
                out.push(Piece::Disk { z: h, radius: r1, up: true });
            }
            out
        }
        Shape::Capsule { radius_bottom, radius_top, height, .. } => {
            let (r0, r1, h) = (f64::from(radius_bottom), f64::from(radius_top), 0.5 * f64::from(height));
            let mut out = Vec::with_capacity(3);
            if height > 0.0 {
                out.push(Piece::Side { z0: -h, z1: h, r0, r1 });
            }
            if r0 > 0.0 {
                out.push(Piece::Zone { z: -h, radius: r0, theta0: -FRAC_PI_2, theta1: 0.0 });
            }
            if r1 > 0.0 {
                out.push(Piece::Zone { z: h, radius: r1, theta0: 0.0, theta1: FRAC_PI_2 });
            }
            out
        }
        Shape::Plane { width, length, axis } => {
            // Width runs along object x for axes Z and Y, along z for X; length along y for Z
            // and X, along z for Y: in the canonical frame, width on a for Z, on b otherwise.
            let (w, l) = (f64::from(width), f64::from(length));
            let (ea, eb) = if axis == Axis::Z { (w, l) } else { (l, w) };
            vec![Piece::Rect { origin: DVec3::new(-0.5 * ea, -0.5 * eb, 0.0), eu: DVec3::new(ea, 0.0, 0.0), ev: DVec3::new(0.0, eb, 0.0) }]
        }
    }
}

fn shape_axis(shape: &Shape) -> Axis {
    match *shape {
        Shape::Sphere { .. } | Shape::Cube { .. } => Axis::Z,
        Shape::Cylinder { axis, .. } | Shape::Capsule { axis, .. } | Shape::Plane { axis, .. } => axis,
    }
}

fn surface_point(axis: Axis, e: [DVec3; 6]) -> SurfacePoint {
    let w = |v: DVec3| v3(axis.to_object(v));
    SurfacePoint { p: w(e[0]), dpdu: w(e[1]), dpdv: w(e[2]), dpduu: w(e[3]), dpduv: w(e[4]), dpdvv: w(e[5]) }
}

/// Object-space bounds from canonical ones, grown by a few ulps so the BVH never clips a hit.
fn object_bounds(axis: Axis, (lo, hi): (DVec3, DVec3)) -> Bounds3 {
    let (a, b) = (axis.to_object(lo), axis.to_object(hi));
    let pad = f64::from(gamma(8)) * a.abs().max(b.abs()).max_element();
    Bounds3 { min: v3(a.min(b) - DVec3::splat(pad)), max: v3(a.max(b) + DVec3::splat(pad)) }
}

/// `st` is the patch's (u, v) (RenderMan's convention for quadrics): the value and its
/// derivatives, for [`LimitSurface::face_varying`]'s channel 0.
fn st_of_uv(channel: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
    (channel == 0).then_some(([u, v], [1.0, 0.0], [0.0, 1.0]))
}

/// An implicit gprim as a limit surface of analytic patches, intersected exactly.
///
/// A shape whose sizes (radius, height, size, ...) change within the shutter holds its pieces
/// at each sample ([`ImplicitSurface::deforming`]): every piece's parameters are linear in the
/// shape's sizes, so the pieces blended between two samples are the pieces of the blended
/// shape, and a ray at shutter time t meets them exactly ([`ExactSurface::intersect_at`]) and
/// is shaded on them ([`LimitSurface::evaluate_at`]). A piece's box is the union of its boxes
/// at the samples, which holds every blend (each box's corners are linear in the sizes too).
#[derive(Clone, Debug)]
pub struct ImplicitSurface {
    shape: Shape,
    axis: Axis,
    /// The pieces (of the first sample, for a shape that changes within the shutter).
    pieces: Vec<Piece>,
    /// The samples' shutter times (0 = open, 1 = close), strictly increasing; empty for a
    /// shape that keeps still.
    times: Vec<f32>,
    /// Every sample's pieces, as many and of the same kinds as `pieces`; empty for a shape
    /// that keeps still.
    samples: Vec<Vec<Piece>>,
}

impl ImplicitSurface {
    /// # Errors
    /// The shape's sizes are refused by [`Shape::validate`].
    pub fn new(shape: Shape) -> Result<Self, String> {
        shape.validate()?;
        Ok(ImplicitSurface { shape, axis: shape_axis(&shape), pieces: pieces(&shape), times: Vec::new(), samples: Vec::new() })
    }

    /// A shape whose sizes change within the shutter: `samples` (shutter time, the shape
    /// then), all of one type and axis.
    ///
    /// # Errors
    /// One line: fewer than 2 or more than [`crate::deform::MAX_SAMPLES`] samples, times not
    /// finite and strictly increasing, a sample [`Shape::validate`] refuses, of another type
    /// or axis than the first, or with other pieces (a cylinder's radius or a capsule's height
    /// reaching 0 adds or drops a cap or the body).
    pub fn deforming(samples: Vec<(f32, Shape)>) -> Result<Self, String> {
        let times: Vec<f32> = samples.iter().map(|s| s.0).collect();
        crate::deform::check_times(&times)?;
        let first = samples[0].1;
        let mut out = ImplicitSurface::new(first)?;
        for &(t, shape) in &samples {
            shape.validate().map_err(|e| format!("{e} at shutter time {t}"))?;
            if std::mem::discriminant(&shape) != std::mem::discriminant(&first) || shape_axis(&shape) != out.axis {
                return Err(format!("the {} at shutter time {t} is of another type or axis than the first sample's", first.type_name()));
            }
            let p = pieces(&shape);
            let same = p.len() == out.pieces.len() && p.iter().zip(&out.pieces).all(|(a, b)| Piece::lerp(a, b, 0.5).is_some());
            if !same {
                return Err(format!(
                    "the {} at shutter time {t} has other pieces than the first sample's (a size reaching 0)",
                    first.type_name()
                ));
            }
            out.samples.push(p);
        }
        out.times = times;
        Ok(out)
    }

    /// The shape (of the first sample, for a shape that changes within the shutter).
    pub fn shape(&self) -> &Shape {
        &self.shape
    }

    /// The samples' shutter times; empty for a shape that keeps still.
    pub fn times(&self) -> &[f32] {
        &self.times
    }

    /// Piece `patch` at shutter time `time`: blended between the bracketing samples' (a
    /// sample's own at its time).
    fn piece_at(&self, patch: usize, time: f32) -> Option<Piece> {
        if self.times.is_empty() {
            return self.pieces.get(patch).copied();
        }
        let (i, j, f) = crate::deform::bracket(&self.times, time);
        let (a, b) = (self.samples[i].get(patch)?, self.samples[j].get(patch)?);
        match f {
            f if f <= 0.0 => Some(*a),
            f if f >= 1.0 => Some(*b),
            f => Piece::lerp(a, b, f64::from(f)),
        }
    }
}

impl Piece {
    /// The piece `f` of the way from `a` to `b` (two samples of one piece of a shape; its
    /// parameters are linear in the shape's sizes), or `None` for pieces of different kinds.
    fn lerp(a: &Piece, b: &Piece, f: f64) -> Option<Piece> {
        let l = |x: f64, y: f64| x * (1.0 - f) + y * f;
        let lv = |x: DVec3, y: DVec3| x * (1.0 - f) + y * f;
        Some(match (*a, *b) {
            (Piece::Zone { z, radius, theta0, theta1 }, Piece::Zone { z: z1, radius: r1, theta0: a0, theta1: a1 })
                if theta0 == a0 && theta1 == a1 =>
            {
                Piece::Zone { z: l(z, z1), radius: l(radius, r1), theta0, theta1 }
            }
            (Piece::Side { z0, z1, r0, r1 }, Piece::Side { z0: w0, z1: w1, r0: s0, r1: s1 }) => {
                Piece::Side { z0: l(z0, w0), z1: l(z1, w1), r0: l(r0, s0), r1: l(r1, s1) }
            }
            (Piece::Disk { z, radius, up }, Piece::Disk { z: z1, radius: r1, up: up1 }) if up == up1 => {
                Piece::Disk { z: l(z, z1), radius: l(radius, r1), up }
            }
            (Piece::Rect { origin, eu, ev }, Piece::Rect { origin: o1, eu: u1, ev: v1 }) => {
                Piece::Rect { origin: lv(origin, o1), eu: lv(eu, u1), ev: lv(ev, v1) }
            }
            _ => return None,
        })
    }
}

impl LimitSurface for ImplicitSurface {
    fn patch_count(&self) -> usize {
        self.pieces.len()
    }

    fn patch_param(&self, patch: usize) -> PatchParam {
        PatchParam::root(patch as u32, patch as u32, PatchKind::Other)
    }

    /// The union over the samples, for a shape that changes within the shutter.
    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        if self.times.is_empty() {
            return self.pieces.get(patch).map_or(Bounds3::EMPTY, |p| object_bounds(self.axis, p.bounds()));
        }
        self.samples.iter().filter_map(|s| s.get(patch)).fold(Bounds3::EMPTY, |b, p| b.union(&object_bounds(self.axis, p.bounds())))
    }

    /// At shutter open for a shape that changes within the shutter;
    /// [`LimitSurface::evaluate_at`] for a ray's time.
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        self.evaluate_at(patch, u, v, 0.0)
    }

    fn evaluate_at(&self, patch: usize, u: f32, v: f32, time: f32) -> SurfacePoint {
        self.piece_at(patch, time).map_or_else(SurfacePoint::default, |p| surface_point(self.axis, p.evaluate(f64::from(u), f64::from(v))))
    }

    fn deforms(&self) -> bool {
        !self.times.is_empty()
    }

    fn control_face_count(&self) -> usize {
        self.pieces.len()
    }

    fn patch_is_affine(&self, patch: usize) -> bool {
        matches!(self.pieces.get(patch), Some(Piece::Rect { .. }))
    }

    fn face_varying(&self, channel: usize, _patch: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        st_of_uv(channel, u, v)
    }

    fn exact(&self) -> Option<&dyn ExactSurface> {
        Some(self)
    }
}

impl ExactSurface for ImplicitSurface {
    fn intersect(&self, patch: usize, o: Vec3A, d: Vec3A, t_min: f32, t_max: f32) -> Option<ExactHit> {
        self.intersect_at(patch, o, d, t_min, t_max, 0.0)
    }

    fn intersect_at(&self, patch: usize, o: Vec3A, d: Vec3A, t_min: f32, t_max: f32, time: f32) -> Option<ExactHit> {
        let piece = self.piece_at(patch, time)?;
        let (oc, dc) = (self.axis.to_canonical(d3(o)), self.axis.to_canonical(d3(d)));
        let (t, u, v, n) = piece.intersect(oc, dc, f64::from(t_min), f64::from(t_max))?;
        let tf = t as f32;
        // The f32 t may round onto the interval's ends: the interval is open.
        if !(tf > t_min && tf < t_max) {
            return None;
        }
        let p = piece.evaluate(u, v)[0];
        Some(ExactHit { t: tf, u: u as f32, v: v as f32, n: v3(self.axis.to_object(n)), error: error_bound(oc, dc, t, p) })
    }
}

/// `Points`: a sphere per point (centre, radius = width / 2), one patch each, so the mesh's
/// bottom-level BVH is a BVH over the points. Object units.
///
/// Points that move within the shutter (sparks, rain, spray: `points` sampled inside it, or
/// moved by `velocities`) hold their centres and radii at each sample
/// ([`PointsSurface::deforming`]): a ray at shutter time t meets each sphere at its centre and
/// radius blended between the bracketing samples ([`crate::deform::bracket`]), exactly — the
/// spheres are never tessellated — and is shaded on that sphere
/// ([`LimitSurface::evaluate_at`]). A point's box is the union of its spheres' boxes at the
/// samples, which holds every blend (a blend of two balls lies in the hull of both).
#[derive(Clone, Debug)]
pub struct PointsSurface {
    /// Centres of each sample, sample-major: sample k's point i at k·n + i.
    centers: Vec<[f32; 3]>,
    /// Radii, laid out as `centers`.
    radii: Vec<f32>,
    /// The samples' shutter times (0 = open, 1 = close), strictly increasing; empty for points
    /// that keep still (one sample).
    times: Vec<f32>,
    /// Points per sample.
    n: usize,
}

impl PointsSurface {
    /// Spheres at `points` with diameters `widths`: one width for all (USD's constant
    /// interpolation; empty means USD's default width, 1) or one per point (vertex or
    /// varying).
    ///
    /// # Errors
    /// A point or width is not finite, a width is negative, or `widths` has neither 0, 1 nor
    /// `points.len()` entries: the message names the attribute and index.
    pub fn new(points: Vec<[f32; 3]>, widths: &[f32]) -> Result<Self, String> {
        Self::check(&points, widths)?;
        let radii = Self::radii_of(points.len(), widths);
        Ok(PointsSurface { n: points.len(), centers: points, radii, times: Vec::new() })
    }

    /// Points moving within the shutter: `samples` (shutter time, the points then; each as
    /// many), with `widths` the diameters at every sample (one list for all samples, as
    /// [`PointsSurface::new`] takes it) or at each (one list per sample, each of 0, 1 or one
    /// per point values).
    ///
    /// # Errors
    /// One line: fewer than 2 or more than [`crate::deform::MAX_SAMPLES`] samples, times not
    /// finite and strictly increasing, samples of another point count than the first, widths
    /// neither one list nor one per sample, or a sample [`PointsSurface::check`] refuses (the
    /// message names its shutter time).
    pub fn deforming(samples: Vec<(f32, Vec<[f32; 3]>)>, widths: &[Vec<f32>]) -> Result<Self, String> {
        let times: Vec<f32> = samples.iter().map(|s| s.0).collect();
        crate::deform::check_times(&times)?;
        if !(widths.len() == 1 || widths.len() == samples.len()) {
            return Err(format!("{} widths samples for {} points samples (want 1 or one per sample)", widths.len(), samples.len()));
        }
        let n = samples[0].1.len();
        let (mut centers, mut radii) = (Vec::with_capacity(n * samples.len()), Vec::with_capacity(n * samples.len()));
        for (k, (t, points)) in samples.into_iter().enumerate() {
            if points.len() != n {
                return Err(format!("the points at shutter time {t} are {} (the first sample has {n})", points.len()));
            }
            let w = &widths[k.min(widths.len() - 1)];
            Self::check(&points, w).map_err(|e| format!("{e} at shutter time {t}"))?;
            radii.extend(Self::radii_of(n, w));
            centers.extend(points);
        }
        Ok(PointsSurface { centers, radii, times, n })
    }

    fn radii_of(n: usize, widths: &[f32]) -> Vec<f32> {
        match widths.len() {
            0 => vec![0.5; n],
            1 => vec![0.5 * widths[0]; n],
            _ => widths.iter().map(|w| 0.5 * w).collect(),
        }
    }

    /// What [`PointsSurface::new`] refuses, without building anything.
    ///
    /// # Errors
    /// As [`PointsSurface::new`].
    pub fn check(points: &[[f32; 3]], widths: &[f32]) -> Result<(), String> {
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(format!("points[{i}] = {:?} is not finite", points[i]));
        }
        if let Some(i) = widths.iter().position(|w| !(w.is_finite() && *w >= 0.0)) {
            return Err(format!("widths[{i}] = {} must be a non-negative number", widths[i]));
        }
        match widths.len() {
            0 | 1 => Ok(()),
            n if n == points.len() => Ok(()),
            n => Err(format!("widths has {n} values for {} points (want 1 or one per point)", points.len())),
        }
    }

    /// The samples' shutter times; empty for points that keep still.
    pub fn times(&self) -> &[f32] {
        &self.times
    }

    /// Point `patch`'s sphere in sample `k`: (centre, radius).
    fn sample_sphere(&self, patch: usize, k: usize) -> (DVec3, f64) {
        let i = k * self.n + patch;
        (d3(Vec3A::from(self.centers[i])), f64::from(self.radii[i]))
    }

    /// Point `patch`'s sphere at shutter time `time`: (centre, radius), blended in f64 between
    /// the bracketing samples (exactly a sample's at its own time).
    fn sphere_at(&self, patch: usize, time: f32) -> Option<(DVec3, f64)> {
        if patch >= self.n {
            return None;
        }
        if self.times.is_empty() {
            return Some(self.sample_sphere(patch, 0));
        }
        let (i, j, f) = crate::deform::bracket(&self.times, time);
        let ((ca, ra), (cb, rb)) = (self.sample_sphere(patch, i), self.sample_sphere(patch, j));
        Some(match f {
            f if f <= 0.0 => (ca, ra),
            f if f >= 1.0 => (cb, rb),
            f => {
                let f = f64::from(f);
                (ca * (1.0 - f) + cb * f, ra * (1.0 - f) + rb * f)
            }
        })
    }
}

impl LimitSurface for PointsSurface {
    fn patch_count(&self) -> usize {
        self.n
    }

    fn patch_param(&self, patch: usize) -> PatchParam {
        PatchParam::root(patch as u32, patch as u32, PatchKind::Other)
    }

    /// The union over the samples of the sphere's box (a sample of width 0 adds its centre,
    /// which the blends toward it approach).
    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        if patch >= self.n {
            return Bounds3::EMPTY;
        }
        let samples = self.times.len().max(1);
        // A point of width 0 throughout is nothing to hit: no subpatch, no BVH leaf.
        if (0..samples).all(|k| !(self.radii[k * self.n + patch] > 0.0)) {
            return Bounds3::EMPTY;
        }
        (0..samples).fold(Bounds3::EMPTY, |b, k| {
            let (c, r) = self.sample_sphere(patch, k);
            b.union(&object_bounds(Axis::Z, (c - DVec3::splat(r), c + DVec3::splat(r))))
        })
    }

    /// At shutter open (the first sample) for moving points; [`LimitSurface::evaluate_at`] for
    /// a ray's time.
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        self.evaluate_at(patch, u, v, 0.0)
    }

    fn evaluate_at(&self, patch: usize, u: f32, v: f32, time: f32) -> SurfacePoint {
        self.sphere_at(patch, time).map_or_else(SurfacePoint::default, |(c, r)| {
            surface_point(Axis::Z, sphere_eval(c, r, -FRAC_PI_2, FRAC_PI_2, f64::from(u), f64::from(v)))
        })
    }

    fn deforms(&self) -> bool {
        !self.times.is_empty()
    }

    fn control_face_count(&self) -> usize {
        self.n
    }

    fn face_varying(&self, channel: usize, _patch: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        st_of_uv(channel, u, v)
    }

    fn exact(&self) -> Option<&dyn ExactSurface> {
        Some(self)
    }
}

impl ExactSurface for PointsSurface {
    fn intersect(&self, patch: usize, o: Vec3A, d: Vec3A, t_min: f32, t_max: f32) -> Option<ExactHit> {
        self.intersect_at(patch, o, d, t_min, t_max, 0.0)
    }

    fn intersect_at(&self, patch: usize, o: Vec3A, d: Vec3A, t_min: f32, t_max: f32, time: f32) -> Option<ExactHit> {
        let (c, r) = self.sphere_at(patch, time)?;
        if !(r > 0.0) {
            return None;
        }
        let (od, dd) = (d3(o), d3(d));
        let (t, p) = sphere_hit(c, r, od, dd, f64::from(t_min), f64::from(t_max), |_| true)?;
        let tf = t as f32;
        if !(tf > t_min && tf < t_max) {
            return None;
        }
        let n = ((p - c) / r).normalize_or(DVec3::Z);
        let v = (n.z.clamp(-1.0, 1.0).asin() + FRAC_PI_2) / PI;
        Some(ExactHit { t: tf, u: turn(n.x, n.y) as f32, v: v as f32, n: v3(n), error: error_bound(od, dd, t, p) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of `evaluate` against its analytic derivatives, on every patch.
    fn check_derivatives(s: &dyn LimitSurface) {
        let h = 1e-3_f32;
        for patch in 0..s.patch_count() {
            for &(u, v) in &[(0.3_f32, 0.4_f32), (0.71, 0.55), (0.12, 0.83)] {
                let e = s.evaluate(patch, u, v);
                let du = (s.evaluate(patch, u + h, v).p - s.evaluate(patch, u - h, v).p) / (2.0 * h);
                let dv = (s.evaluate(patch, u, v + h).p - s.evaluate(patch, u, v - h).p) / (2.0 * h);
                let duu = (s.evaluate(patch, u + h, v).dpdu - s.evaluate(patch, u - h, v).dpdu) / (2.0 * h);
                let duv = (s.evaluate(patch, u, v + h).dpdu - s.evaluate(patch, u, v - h).dpdu) / (2.0 * h);
                let dvv = (s.evaluate(patch, u, v + h).dpdv - s.evaluate(patch, u, v - h).dpdv) / (2.0 * h);
                let scale = e.dpdu.length().max(e.dpdv.length()).max(1.0);
                for (name, fd, exact) in
                    [("dpdu", du, e.dpdu), ("dpdv", dv, e.dpdv), ("dpduu", duu, e.dpduu), ("dpduv", duv, e.dpduv), ("dpdvv", dvv, e.dpdvv)]
                {
                    let tol = 2e-3 * scale * if name.len() > 4 { 40.0 } else { 1.0 };
                    assert!((fd - exact).length() < tol, "patch {patch} ({u}, {v}) {name}: finite {fd} vs analytic {exact}");
                }
                // The patch's own (u, v) → point → the hit's (u, v) and normal agree.
                let n = e.dpdu.cross(e.dpdv).normalize();
                let from = e.p + n * 3.0;
                let hit = s.exact().unwrap().intersect(patch, from, -n, 0.0, f32::INFINITY).expect("a ray down the normal hits");
                assert!((hit.t - 3.0).abs() < 1e-4, "patch {patch}: t {}", hit.t);
                assert!((hit.u - u).abs() < 1e-4 && (hit.v - v).abs() < 1e-4, "patch {patch}: uv ({}, {}) vs ({u}, {v})", hit.u, hit.v);
                assert!(hit.n.dot(n) > 1.0 - 1e-5, "patch {patch}: normal {} vs dP/du × dP/dv {n}", hit.n);
            }
        }
    }

    #[test]
    fn every_shape_and_axis_matches_its_derivatives_and_its_ray_test() {
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            let shapes = [
                Shape::Sphere { radius: 1.5 },
                Shape::Cube { size: 2.0 },
                Shape::Cylinder { radius_bottom: 1.0, radius_top: 1.0, height: 2.0, axis },
                Shape::Cylinder { radius_bottom: 1.0, radius_top: 0.0, height: 2.0, axis },
                Shape::Cylinder { radius_bottom: 0.5, radius_top: 1.2, height: 3.0, axis },
                Shape::Capsule { radius_bottom: 0.5, radius_top: 0.5, height: 1.0, axis },
                Shape::Capsule { radius_bottom: 0.7, radius_top: 0.3, height: 1.0, axis },
                Shape::Plane { width: 2.0, length: 3.0, axis },
            ];
            for shape in shapes {
                check_derivatives(&ImplicitSurface::new(shape).unwrap());
            }
        }
        check_derivatives(&PointsSurface::new(vec![[1.0, 2.0, 3.0], [-4.0, 0.5, 0.0]], &[0.5, 2.0]).unwrap());
    }

    #[test]
    fn axes_and_plane_sizes_follow_usd() {
        // A cylinder along X reaches ±height/2 on x and ±radius on y, z.
        let c = ImplicitSurface::new(Shape::Cylinder { radius_bottom: 1.0, radius_top: 1.0, height: 4.0, axis: Axis::X }).unwrap();
        let b = (0..c.patch_count()).fold(Bounds3::EMPTY, |b, i| b.union(&c.patch_bounds(i)));
        assert!((b.max - Vec3A::new(2.0, 1.0, 1.0)).abs().max_element() < 1e-5, "{b:?}");
        // A cone's apex points along +axis.
        let cone = ImplicitSurface::new(Shape::Cylinder { radius_bottom: 1.0, radius_top: 0.0, height: 2.0, axis: Axis::Y }).unwrap();
        assert!((cone.evaluate(0, 0.3, 1.0).p - Vec3A::new(0.0, 1.0, 0.0)).length() < 1e-6);
        // Plane: width on x and length on y (axis Z); width on z, length on y (X); width on x,
        // length on z (Y); facing +axis.
        for (axis, extent, normal) in [
            (Axis::Z, Vec3A::new(1.0, 1.5, 0.0), Vec3A::Z),
            (Axis::X, Vec3A::new(0.0, 1.5, 1.0), Vec3A::X),
            (Axis::Y, Vec3A::new(1.0, 0.0, 1.5), Vec3A::Y),
        ] {
            let p = ImplicitSurface::new(Shape::Plane { width: 2.0, length: 3.0, axis }).unwrap();
            assert!((p.patch_bounds(0).max - extent).abs().max_element() < 1e-5, "{axis:?}: {:?}", p.patch_bounds(0));
            let e = p.evaluate(0, 0.5, 0.5);
            assert!((e.dpdu.cross(e.dpdv).normalize() - normal).length() < 1e-6, "{axis:?}");
        }
    }

    #[test]
    fn zero_and_bad_sizes_are_refused_by_name() {
        assert!(ImplicitSurface::new(Shape::Sphere { radius: 0.0 }).unwrap_err().contains("radius = 0"));
        assert!(ImplicitSurface::new(Shape::Cube { size: f32::NAN }).unwrap_err().contains("size = NaN"));
        let e = ImplicitSurface::new(Shape::Cylinder { radius_bottom: 1.0, radius_top: 1.0, height: 0.0, axis: Axis::Z }).unwrap_err();
        assert!(e.contains("height = 0"), "{e}");
        assert!(ImplicitSurface::new(Shape::Plane { width: 1.0, length: -1.0, axis: Axis::Z }).unwrap_err().contains("length = -1"));
        assert!(PointsSurface::new(vec![[0.0; 3]; 3], &[1.0, 2.0]).unwrap_err().contains("widths has 2 values for 3 points"));
        assert!(PointsSurface::new(vec![[0.0; 3]], &[-1.0]).unwrap_err().contains("widths[0] = -1"));
    }

    #[test]
    fn moving_points_blend_their_spheres_and_refuse_bad_samples_by_name() {
        let p = PointsSurface::deforming(vec![(0.0, vec![[0.0; 3]]), (1.0, vec![[2.0, 0.0, 0.0]])], &[vec![1.0], vec![3.0]]).unwrap();
        assert!(p.deforms());
        // At t = 0.25 the centre is (0.5, 0, 0) and the radius 0.5 + 0.25 · 1 = 0.75.
        let hit = p.intersect_at(0, Vec3A::new(0.5, 0.0, 5.0), Vec3A::NEG_Z, 0.0, f32::INFINITY, 0.25).unwrap();
        assert!((hit.t - 4.25).abs() < 1e-5, "t {}", hit.t);
        assert!((p.evaluate_at(0, 0.0, 0.5, 0.25).p - Vec3A::new(1.25, 0.0, 0.0)).length() < 1e-5);
        let b = p.patch_bounds(0);
        assert!(b.contains(Vec3A::new(-0.5, 0.0, 0.0)) && b.contains(Vec3A::new(3.5, 1.5, 0.0)), "{b:?}");
        let e = PointsSurface::deforming(vec![(0.0, vec![[0.0; 3]]), (1.0, vec![[0.0; 3]; 2])], &[vec![]]).unwrap_err();
        assert!(e.contains("the points at shutter time 1 are 2 (the first sample has 1)"), "{e}");
        let e = PointsSurface::deforming(vec![(0.0, vec![[0.0; 3]]), (1.0, vec![[0.0; 3]])], &[vec![], vec![], vec![]]).unwrap_err();
        assert!(e.contains("3 widths samples for 2 points samples"), "{e}");
        let e = PointsSurface::deforming(vec![(0.0, vec![[0.0; 3]]), (1.0, vec![[0.0; 3]])], &[vec![1.0], vec![-1.0]]).unwrap_err();
        assert!(e.contains("widths[0] = -1 must be a non-negative number at shutter time 1"), "{e}");
        assert!(PointsSurface::deforming(vec![(0.5, vec![[0.0; 3]]), (0.5, vec![[0.0; 3]])], &[vec![]]).is_err());
    }

    #[test]
    fn a_shape_whose_sizes_change_is_the_blended_shape_and_refuses_other_pieces() {
        let cyl = |r: f32, h: f32| Shape::Cylinder { radius_bottom: r, radius_top: r, height: h, axis: Axis::X };
        let s = ImplicitSurface::deforming(vec![(0.0, cyl(1.0, 2.0)), (0.5, cyl(2.0, 2.0)), (1.0, cyl(2.0, 4.0))]).unwrap();
        assert!(s.deforms());
        // At t = 0.75: radius 2, height 3, its pieces exactly those of that cylinder.
        let mid = ImplicitSurface::new(cyl(2.0, 3.0)).unwrap();
        for patch in 0..3 {
            let (a, b) = (s.evaluate_at(patch, 0.3, 0.4, 0.75), mid.evaluate(patch, 0.3, 0.4));
            assert!((a.p - b.p).length() < 1e-6 && (a.dpdu - b.dpdu).length() < 1e-5, "patch {patch}");
            let hit = s.intersect_at(patch, a.p + Vec3A::X * 5.0 + Vec3A::Y * 0.01, Vec3A::NEG_X, 0.0, f32::INFINITY, 0.75);
            let want = mid.intersect(patch, a.p + Vec3A::X * 5.0 + Vec3A::Y * 0.01, Vec3A::NEG_X, 0.0, f32::INFINITY);
            assert_eq!(hit, want, "patch {patch}");
            assert!(s.patch_bounds(patch).contains(ImplicitSurface::new(cyl(2.0, 4.0)).unwrap().evaluate(patch, 0.1, 0.0).p));
        }
        let cone = Shape::Cylinder { radius_bottom: 1.0, radius_top: 0.0, height: 2.0, axis: Axis::X };
        let e = ImplicitSurface::deforming(vec![(0.0, cyl(1.0, 2.0)), (1.0, cone)]).unwrap_err();
        assert!(e.contains("other pieces"), "{e}");
        let e = ImplicitSurface::deforming(vec![(0.0, cyl(1.0, 2.0)), (1.0, Shape::Sphere { radius: 1.0 })]).unwrap_err();
        assert!(e.contains("another type or axis"), "{e}");
        let e = ImplicitSurface::deforming(vec![(0.0, cyl(1.0, 2.0)), (1.0, cyl(-1.0, 2.0))]).unwrap_err();
        assert!(e.contains("at shutter time 1"), "{e}");
    }

    #[test]
    fn grazing_and_extreme_radii_hit_where_the_closed_form_says() {
        for radius in [1e-6_f32, 1e-3, 1.0, 1e3, 1e6] {
            let s = ImplicitSurface::new(Shape::Sphere { radius }).unwrap();
            // A ray passing at distance b from the centre enters at t = D − √(r² − b²).
            for frac in [0.0_f32, 0.5, 0.999, 0.999_999] {
                let b = frac * radius;
                let dist = 10.0 * radius;
                let o = Vec3A::new(-dist, b, 0.0);
                let hit = s.intersect(0, o, Vec3A::X, 0.0, f32::INFINITY).expect("hits");
                let want = f64::from(dist) - (f64::from(radius).powi(2) - f64::from(b).powi(2)).sqrt();
                assert!(
                    (f64::from(hit.t) - want).abs() <= 4.0 * f64::from(f32::EPSILON) * f64::from(dist),
                    "r {radius} b {b}: t {} vs {want}",
                    hit.t
                );
            }
            // Just outside the silhouette: no hit.
            let o = Vec3A::new(-10.0 * radius, radius * 1.000_01, 0.0);
            assert!(s.intersect(0, o, Vec3A::X, 0.0, f32::INFINITY).is_none(), "r {radius}");
        }
    }

    #[test]
    fn a_ray_leaving_the_surface_does_not_find_it_again_and_refraction_finds_the_far_side() {
        let s = ImplicitSurface::new(Shape::Sphere { radius: 2.0 }).unwrap();
        let mut rng = 1u64;
        let mut next = || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((rng >> 40) as f32) / (1u64 << 24) as f32
        };
        for _ in 0..2000 {
            let (u, v) = (next(), 0.02 + 0.96 * next());
            let e = s.evaluate(0, u, v);
            let n = e.dpdu.cross(e.dpdv).normalize();
            // Leaving outward at any angle, from the surface point offset by its error bound.
            let t = e.dpdu.normalize();
            let d = (n * (0.001 + next()) + t * (next() - 0.5)).normalize();
            let o = e.p + n * (gamma(16) * 8.0);
            assert!(s.intersect(0, o, d, 0.0, f32::INFINITY).is_none(), "self-hit at {u}, {v}");
            // Entering: the far side, at the chord's length.
            let din = -d;
            let o_in = e.p - n * (gamma(16) * 8.0);
            let h = s.intersect(0, o_in, din, 0.0, f32::INFINITY).expect("far side");
            // The far root from the actual origin, in f64 (textbook form).
            let (of, df) = (d3(o_in), d3(din));
            let (b, c) = (of.dot(df), of.length_squared() - 4.0);
            let a = df.length_squared();
            let chord = (-b + (b * b - a * c).sqrt()) / a;
            assert!((f64::from(h.t) - chord).abs() < 1e-6, "chord {chord} vs t {}", h.t);
        }
    }
}
