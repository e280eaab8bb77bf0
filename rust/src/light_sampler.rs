//! Choosing which light a shadow ray goes to: many lights sampled by importance, not all traced
//! at every point (the paper's §4.3: "we only trace shadow rays to the lights that matter").
//!
//! **The rule.** At a shading point p with normal n, light j is chosen with probability
//! P_j(p, n) proportional to an upper-bound-flavoured estimate of the irradiance it can deliver,
//! without occlusion:
//!
//! - area lights (sphere, rect, disk, cylinder): `Φ · cos θ'_light · cos θ'_surface / d²`, where
//!   Φ is the light's luminance × area facing the point at best (a rect's or disk's area, a
//!   sphere's πr², a tube's 2rℓ + πr²: an intensity), d the distance from p to its bounds'
//!   centre (at least half their diagonal), θ'_light the smallest angle between the light's
//!   emission cone and the direction to p that the bounds allow (zero importance when p is
//!   behind a one-sided light) and θ'_surface the smallest angle between n and a direction into
//!   the bounds (zero below the horizon);
//! - distant lights: the irradiance facing the light × the cosine of the smallest angle between
//!   n and the light's cone (delta lights included: angle 0);
//! - dome lights: π × the dome's mean luminance (its irradiance on any surface, roughly).
//!
//! A light shaped by UsdLux's `ShapingAPI` emits only within its cone: its bounds say so
//! (emission spread θe = the cone angle), so points outside every cone get probability 0.
//!
//! Every quantity is an irradiance, so the three kinds compete on one scale. A light gets
//! probability 0 only where these bounds prove it cannot light p, so the estimator
//! Σ_k f(light j_k) / (N · P_{j_k}) over N choices is unbiased: its expectation is the sum over
//! all lights.
//!
//! **Cost.** Area lights sit in a light tree (Conty Estevez & Kulla 2018, *Importance Sampling
//! of Many Lights with Adaptive Tree Splitting*; the variant of PBRT 4th ed. §12.6.3): a binary
//! BVH over the lights' bounds, each node carrying the union of its lights' bounds, emission
//! cones (axis and spread θo, falloff θe) and power Φ, built with PBRT's surface-area-orientation
//! heuristic. The top of the tree is flattened into a *cut* of at most [`CUT_SIZE`] nodes that,
//! with the distant and dome lights, are weighed linearly once per shading point
//! ([`LightSampler::at`]) — a point inside a big cluster's box learns nothing from its bounds,
//! and errors there would compound down the tree (measured on `lights_many.rs`'s 100 lights:
//! the plain tree chose worse than uniformly, the cut far better). Below the cut a choice walks
//! down, picking a child with probability proportional to the two children's importance:
//! O(depth) evaluations, and the probability of a given light (for multiple importance sampling)
//! retraces its bit trail in the same time. So a shading point costs ≤ 64 + a few importance
//! evaluations, then O(log n) per choice, whatever the light count. Uniform numbers are remapped
//! at each step, so stratified numbers stay stratified: N stratified choices spread over the
//! lights like systematic sampling. The tree also answers "which lights does this ray cross"
//! ([`LightSampler::for_each_crossed`]) by box tests, for rays found by BSDF sampling. `cargo test
//! --release -p mipray --test lights_many -- --ignored --nocapture` measures the costs against a
//! linear CDF over every light (figures in `lights_many.rs`).

use std::f32::consts::PI;

use glam::Vec3A;

use crate::light::{luminance, Light, LightHit, LightShape};

/// A directional cone: unit `w`, half-angle cosine `cos_theta` (−1: every direction).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cone {
    w: Vec3A,
    cos_theta: f32,
}

impl Cone {
    /// The smallest cone holding both (PBRT's `DirectionCone::Union`).
    fn union(a: Cone, b: Cone) -> Cone {
        let all = Cone { w: a.w, cos_theta: -1.0 };
        let theta_a = a.cos_theta.clamp(-1.0, 1.0).acos();
        let theta_b = b.cos_theta.clamp(-1.0, 1.0).acos();
        let theta_d = a.w.dot(b.w).clamp(-1.0, 1.0).acos();
        if (theta_d + theta_b).min(PI) <= theta_a {
            return a;
        }
        if (theta_d + theta_a).min(PI) <= theta_b {
            return b;
        }
        let theta_o = (theta_a + theta_d + theta_b) / 2.0;
        if theta_o >= PI {
            return all;
        }
        let theta_r = theta_o - theta_a;
        let wr = a.w.cross(b.w);
        if wr.length_squared() < 1e-12 {
            return all;
        }
        let w = glam::Mat3A::from_axis_angle(wr.normalize().into(), theta_r) * a.w;
        Cone { w: w.normalize(), cos_theta: theta_o.cos() }
    }
}

/// What the tree knows about a set of lights: a box, a power, an emission cone.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LightBounds {
    lo: Vec3A,
    hi: Vec3A,
    /// Luminance × projected area (render units² · radiance): an intensity.
    phi: f32,
    /// Normals of the emitters lie within this cone …
    normals: Cone,
    /// … and each emits within θe of its normal (cos θe; 0: a hemisphere).
    cos_theta_e: f32,
}

fn cos_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        1.0
    } else {
        cos_a * cos_b + sin_a * sin_b
    }
}

fn sin_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        0.0
    } else {
        sin_a * cos_b - cos_a * sin_b
    }
}

fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

impl LightBounds {
    fn of(light: &Light) -> Option<LightBounds> {
        let lum = luminance(light.radiance_scale);
        let b = match &light.shape {
            LightShape::Sphere { center, radius } => LightBounds {
                lo: *center - Vec3A::splat(*radius),
                hi: *center + Vec3A::splat(*radius),
                phi: lum * PI * radius * radius,
                normals: Cone { w: Vec3A::Z, cos_theta: -1.0 },
                cos_theta_e: 0.0,
            },
            shape @ (LightShape::Rect { center, u, v, normal } | LightShape::Disk { center, u, v, normal }) => {
                let extent = if matches!(shape, LightShape::Rect { .. }) { u.abs() + v.abs() } else { (*u * *u + *v * *v).map(f32::sqrt) };
                LightBounds {
                    lo: *center - extent,
                    hi: *center + extent,
                    phi: lum * crate::light::shape_area(shape),
                    normals: Cone { w: normal.normalize_or(Vec3A::NEG_Z), cos_theta: 1.0 },
                    cos_theta_e: 0.0,
                }
            }
            LightShape::Cylinder { center, axis, radius, .. } => LightBounds {
                lo: *center - axis.abs() - Vec3A::splat(*radius),
                hi: *center + axis.abs() + Vec3A::splat(*radius),
                // Seen side-on it shows 2r × length; end-on, no more than its wall's πr².
                phi: lum * (4.0 * radius * axis.length() + PI * radius * radius),
                normals: Cone { w: Vec3A::Z, cos_theta: -1.0 },
                cos_theta_e: 0.0,
            },
            LightShape::Mesh(m) => LightBounds {
                lo: m.bounds().min,
                hi: m.bounds().max,
                // Its whole area facing the point at best (an upper bound, as the others'), at
                // its faces' mean emission.
                phi: luminance(light.radiance_scale * m.mean_emission()) * m.max_area(),
                normals: Cone { w: Vec3A::Z, cos_theta: -1.0 },
                cos_theta_e: 0.0,
            },
            _ => return None,
        };
        // A shaped light emits only within its cone about its axis (focus only dims it: the
        // bound stays an upper one), from any point of it.
        let b = match &light.shaping {
            Some(shaping) if shaping.cos_max() > -1.0 => match light.shape {
                LightShape::Sphere { .. } | LightShape::Cylinder { .. } => {
                    LightBounds { normals: Cone { w: shaping.axis, cos_theta: 1.0 }, cos_theta_e: shaping.cos_max(), ..b }
                }
                _ => LightBounds { cos_theta_e: b.cos_theta_e.max(shaping.cos_max()), ..b },
            },
            _ => b,
        };
        // A light of non-finite radiance stays in, with a nominal power: its samples carry the
        // non-finite value to the render loop, which drops them and counts them (no NaN reaches
        // the film, and the stats say a light is broken). Only lights that emit nothing leave.
        // An IES profile scales the emission by up to its peak (a candela value, or the peak
        // over the mean when normalized).
        let peak = light.shaping.as_ref().and_then(|s| s.ies.as_ref()).map_or(1.0, |ies| ies.peak());
        let phi = b.phi * peak;
        let phi = if phi.is_finite() { phi } else { 1.0 };
        (phi > 0.0 && b.lo.is_finite() && b.hi.is_finite()).then_some(LightBounds { phi, ..b })
    }

    fn union(a: &LightBounds, b: &LightBounds) -> LightBounds {
        LightBounds {
            lo: a.lo.min(b.lo),
            hi: a.hi.max(b.hi),
            phi: a.phi + b.phi,
            normals: Cone::union(a.normals, b.normals),
            cos_theta_e: a.cos_theta_e.min(b.cos_theta_e),
        }
    }

    fn centroid(&self) -> Vec3A {
        0.5 * (self.lo + self.hi)
    }

    /// PBRT's estimate of the irradiance the lights can send to p (normal n; zero n: no
    /// horizon), conservative in its zeros.
    fn importance(&self, p: Vec3A, n: Vec3A) -> f32 {
        let pc = self.centroid();
        let half_diag2 = (0.25 * (self.hi - self.lo).length_squared()).max(1e-12);
        let d2 = (p - pc).length_squared().max(half_diag2);
        let wi = (p - pc).normalize_or(Vec3A::Z);
        let cos_w = self.normals.w.dot(wi);
        let sin_w = safe_sqrt(1.0 - cos_w * cos_w);
        // The directions from p into the bounds: a cone of half-angle θb (its bounding sphere).
        let dist2 = (p - pc).length_squared();
        let (sin_b, cos_b) = if dist2 <= half_diag2 {
            (0.0, -1.0)
        } else {
            let sin2 = half_diag2 / dist2;
            (sin2.sqrt(), safe_sqrt(1.0 - sin2))
        };
        let cos_o = self.normals.cos_theta;
        let sin_o = safe_sqrt(1.0 - cos_o * cos_o);
        let cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, cos_o);
        let sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, cos_o);
        let cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
        if cos_p <= self.cos_theta_e {
            return 0.0;
        }
        let mut importance = self.phi * cos_p / d2;
        if n != Vec3A::ZERO {
            // One-sided: the surface faces −wi (toward the lights) or it cannot be lit from them.
            let cos_i = (-wi).dot(n);
            let sin_i = safe_sqrt(1.0 - cos_i * cos_i);
            importance *= cos_sub_clamped(sin_i, cos_i, sin_b, cos_b).max(0.0);
        }
        if importance.is_finite() {
            importance.max(0.0)
        } else {
            0.0
        }
    }

    /// PBRT's surface-area-orientation cost of a split candidate along axis `dim`.
    fn cost(&self, node: &LightBounds, dim: usize) -> f32 {
        let theta_o = self.normals.cos_theta.clamp(-1.0, 1.0).acos();
        let theta_e = self.cos_theta_e.clamp(-1.0, 1.0).acos();
        let theta_w = (theta_o + theta_e).min(PI);
        let sin_o = safe_sqrt(1.0 - self.normals.cos_theta.powi(2));
        let m_omega = 2.0 * PI * (1.0 - self.normals.cos_theta)
            + PI / 2.0 * (2.0 * theta_w * sin_o - (theta_o - 2.0 * theta_w).cos() - 2.0 * theta_o * sin_o + self.normals.cos_theta);
        let diag = node.hi - node.lo;
        let kr = if diag[dim] > 0.0 { diag.max_element() / diag[dim] } else { 1.0 };
        let d = self.hi - self.lo;
        let area = 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x);
        self.phi * m_omega * kr * area.max(1e-12)
    }
}

#[derive(Clone, Copy, Debug)]
enum NodeKind {
    /// A light (index into the scene's lights).
    Leaf(u32),
    /// Interior: the first child follows it, the second is at this index.
    Interior(u32),
}

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: LightBounds,
    kind: NodeKind,
    /// A leaf's exact shape, for tests the bounds are too loose for (a point beside a flat light
    /// is inside its box's bounding sphere).
    shape: Option<Exact>,
    /// A leaf light's IES profile, which scales its importance toward each point: an index
    /// into [`LightSampler::profiles`].
    profile: Option<u32>,
}

/// A light shaped by an IES profile, as its leaf weighs it: `bounds.phi` holds the profile's
/// peak, and the importance at p is scaled by the profile's largest value toward p over its
/// peak.
#[derive(Clone, Debug)]
struct Profiled {
    /// The light's bounding sphere, render space.
    center: Vec3A,
    radius: f32,
    /// Its axis (−Z) and profile.
    axis: Vec3A,
    ies: std::sync::Arc<crate::light::IesShaping>,
}

/// The least share of its peak a profiled light keeps in the tree's weights: a profile that is
/// zero toward the centre of a wide light may not be zero toward all of it, and a light never
/// chosen where it does reach would be lost (a bias); this keeps every light choosable.
const PROFILE_FLOOR: f32 = 1.0 / 256.0;

impl Profiled {
    fn of(light: &Light) -> Option<Profiled> {
        let shaping = light.shaping.as_ref()?;
        let ies = shaping.ies.clone()?;
        let (center, radius) = match light.shape {
            LightShape::Sphere { center, radius } => (center, radius),
            LightShape::Rect { center, u, v, .. } => (center, (u.abs() + v.abs()).length()),
            LightShape::Disk { center, u, v, .. } => (center, u.length().max(v.length())),
            LightShape::Cylinder { center, axis, radius, .. } => (center, axis.length() + radius),
            _ => return None,
        };
        Some(Profiled { center, radius, axis: shaping.axis, ies })
    }

    /// The profile's largest value toward p over its peak, in (0, 1]: the factor toward the
    /// light's centre and toward four points on its bounding sphere's rim as seen from p (the
    /// directions a finite light emits toward p span that cone), at least [`PROFILE_FLOOR`].
    fn share(&self, p: Vec3A) -> f32 {
        let peak = self.ies.peak();
        if !(peak > 0.0 && peak.is_finite()) {
            return 1.0;
        }
        let to_p = p - self.center;
        let d = to_p.length();
        if !(d > self.radius) {
            return 1.0;
        }
        let w = to_p / d;
        let mut best = self.ies.factor(self.axis, w);
        if self.radius > 0.0 {
            let (t, b) = crate::sampling::frame(w);
            let r = self.radius / d;
            for e in [t, -t, b, -b] {
                // From a rim point of the sphere toward p.
                best = best.max(self.ies.factor(self.axis, (w - e * r).normalize_or(w)));
            }
        }
        (best / peak).clamp(PROFILE_FLOOR, 1.0)
    }
}

/// What a single light's importance can test exactly.
#[derive(Clone, Copy, Debug)]
enum Exact {
    Sphere {
        center: Vec3A,
        radius: f32,
    },
    /// A one-sided rect or disk: emits along `normal` from the plane through `center`; the
    /// parallelogram `corners` holds it.
    Planar {
        center: Vec3A,
        normal: Vec3A,
        corners: [Vec3A; 4],
    },
}

impl Exact {
    fn of(light: &Light) -> Option<Exact> {
        match light.shape {
            LightShape::Sphere { center, radius } => Some(Exact::Sphere { center, radius }),
            LightShape::Rect { center, u, v, normal } | LightShape::Disk { center, u, v, normal } => {
                Some(Exact::Planar { center, normal, corners: [center + u + v, center + u - v, center - u - v, center - u + v] })
            }
            _ => None,
        }
    }

    /// False when the light certainly sends nothing to p (normal n; zero: any direction): p is
    /// behind a one-sided light, or the light is wholly below p's horizon.
    fn can_light(&self, p: Vec3A, n: Vec3A) -> bool {
        match *self {
            Exact::Sphere { center, radius } => n == Vec3A::ZERO || (center - p).dot(n) > -radius,
            Exact::Planar { center, normal, corners } => {
                (p - center).dot(normal) > 0.0 && (n == Vec3A::ZERO || corners.iter().any(|c| (*c - p).dot(n) > 0.0))
            }
        }
    }
}

impl Node {
    /// The bounds' importance, zero where a leaf's exact shape says it cannot light p.
    fn importance(&self, p: Vec3A, n: Vec3A, profiles: &[Profiled]) -> f32 {
        match self.shape {
            Some(e) if !e.can_light(p, n) => 0.0,
            _ => match self.profile.and_then(|i| profiles.get(i as usize)) {
                Some(profile) => self.bounds.importance(p, n) * profile.share(p),
                None => self.bounds.importance(p, n),
            },
        }
    }
}

/// What the top level knows about a distant or dome light.
#[derive(Clone, Debug)]
struct Infinite {
    light: u32,
    /// Irradiance luminance on a surface facing it (distant) or π × mean radiance (dome).
    irradiance: f32,
    /// Distant lights: toward the light, and the cone's half-angle; a dome has none.
    cone: Option<(Vec3A, f32, f32)>,
    /// A dome's PortalLights (empty for others): its importance is what comes through them.
    portals: std::sync::Arc<[crate::light::Portal]>,
}

/// The least share of its unportalled importance a dome with portals keeps: it still lights
/// every direction (the portals only guide its samples), so where no portal faces a point, or
/// the stage's portals miss an opening, it must stay choosable.
const PORTAL_IMPORTANCE_FLOOR: f32 = 1.0 / 32.0;

impl Infinite {
    /// At point p with normal n (zero: no horizon).
    fn importance(&self, p: Vec3A, n: Vec3A) -> f32 {
        match self.cone {
            Some((toward, sin_max, cos_max)) if n != Vec3A::ZERO => {
                let cos_n = n.dot(toward);
                let sin_n = safe_sqrt(1.0 - cos_n * cos_n);
                self.irradiance * cos_sub_clamped(sin_n, cos_n, sin_max, cos_max).max(0.0)
            }
            _ if !self.portals.is_empty() => self.irradiance * portal_share(&self.portals, p, n),
            _ => self.irradiance,
        }
    }
}

/// The share of a uniform dome's irradiance at p (normal n) that arrives through `portals`:
/// Σ solid angle × cosine to n over π (over 2π, the hemisphere, with no normal), each portal's
/// solid angle estimated from its centre ([`crate::light::Portal::weight`]), capped at 1 and at
/// least [`PORTAL_IMPORTANCE_FLOOR`].
fn portal_share(portals: &[crate::light::Portal], p: Vec3A, n: Vec3A) -> f32 {
    let through: f32 = portals
        .iter()
        .map(|q| {
            let w = q.weight(p);
            if w > 0.0 && n != Vec3A::ZERO {
                w * n.dot((q.center - p).normalize_or_zero()).max(0.0) / PI
            } else {
                w / (2.0 * PI)
            }
        })
        .sum();
    if through.is_finite() {
        through.clamp(PORTAL_IMPORTANCE_FLOOR, 1.0)
    } else {
        1.0
    }
}

/// Deepest tree level that may be split by the heuristic; deeper, splits halve the lights, so
/// bit trails (one bit per level) fit in 64 bits for any light count below 2³¹.
const MAX_HEURISTIC_DEPTH: u32 = 32;

/// Most tree nodes in the cut that is weighed linearly at every shading point (see
/// [`LightSampler`]): with this many or fewer area lights every light is weighed on its own.
pub const CUT_SIZE: usize = 64;

/// The scene's lights, organised for choosing one by importance at a shading point. Built once
/// per render from the scene's light list; indices are into that list.
///
/// A choice is made in two steps. First among the *cut* — at most [`CUT_SIZE`] tree nodes
/// covering every area light, the largest clusters (by the build's cost: power × orientation
/// spread × area) split first — and the infinite lights, all weighed at the point
/// ([`LightSampler::at`]): the top of a light tree is where its bounds are loosest (a shading
/// point inside a cluster's box learns nothing from it), so the top is flattened. Then down the
/// tree below the chosen cut node, child by child. With ≤ [`CUT_SIZE`] area lights the cut is the
/// leaves and the choice is a plain CDF over per-light importances.
#[derive(Clone, Debug, Default)]
pub struct LightSampler {
    infinite: Vec<Infinite>,
    nodes: Vec<Node>,
    /// Per light: its path from the root (bit k set: the second child at depth k), for lights
    /// in the tree.
    trails: Vec<Option<u64>>,
    /// The cut: node index and depth.
    cut: Vec<(u32, u32)>,
    /// Per light: its entry in the linear step (infinite lights first, then the cut nodes).
    entry: Vec<Option<u32>>,
    any_wide: bool,
    /// Per light: its exact shape (area lights), copied into its leaf.
    exact: Vec<Option<Exact>>,
    /// The IES-profiled lights' weighing, indexed by their leaves.
    profiles: Vec<Profiled>,
    /// Per light: its index in `profiles`, copied into its leaf.
    profiled: Vec<Option<u32>>,
}

/// The lights as weighed at one shading point: make once per point ([`LightSampler::at`]), then
/// choose and ask probabilities as often as needed.
#[derive(Clone, Debug)]
pub struct LightsAt<'a> {
    sampler: &'a LightSampler,
    p: Vec3A,
    n: Vec3A,
    /// Cumulative importance over the entries (infinite lights, then the cut).
    cdf: Vec<f32>,
}

impl LightSampler {
    /// Builds the tree over `lights` (area lights) and the list of infinite ones. Lights that
    /// emit nothing are left out: they are never chosen, and contribute nothing.
    pub fn new(lights: &[Light]) -> Self {
        let mut s = LightSampler { trails: vec![None; lights.len()], entry: vec![None; lights.len()], ..Default::default() };
        let mut items: Vec<(LightBounds, u32)> = Vec::new();
        s.exact = lights.iter().map(Exact::of).collect();
        for l in lights {
            let p = Profiled::of(l);
            s.profiled.push(p.is_some().then_some(s.profiles.len() as u32));
            s.profiles.extend(p);
        }
        for (i, l) in lights.iter().enumerate() {
            match &l.shape {
                LightShape::Distant { direction, angle_deg } => {
                    let irradiance = nominal(luminance(l.distant_irradiance()));
                    if irradiance > 0.0 {
                        let theta_max = (0.5 * angle_deg).to_radians().min(PI);
                        s.infinite.push(Infinite {
                            light: i as u32,
                            irradiance,
                            cone: Some((-*direction, theta_max.sin(), theta_max.cos())),
                            portals: Vec::new().into(),
                        });
                    }
                }
                LightShape::Dome(env) => {
                    let mean = env.as_ref().map_or(Vec3A::ONE, |e| e.mean());
                    let irradiance = nominal(PI * luminance(l.radiance_scale * mean));
                    if irradiance > 0.0 {
                        s.infinite.push(Infinite { light: i as u32, irradiance, cone: None, portals: l.portals.clone() });
                    }
                }
                _ => {
                    if let Some(b) = LightBounds::of(l) {
                        items.push((b, i as u32));
                    }
                }
            }
        }
        s.any_wide = s.infinite.iter().any(|inf| !lights[inf.light as usize].is_delta()) || !items.is_empty();
        for (k, inf) in s.infinite.iter().enumerate() {
            s.entry[inf.light as usize] = Some(k as u32);
        }
        if !items.is_empty() {
            s.build(&mut items, 0, 0);
            s.make_cut();
        }
        s
    }

    /// Lights that can be chosen.
    pub fn len(&self) -> usize {
        self.infinite.len() + self.trails.iter().flatten().count()
    }

    /// No light can be chosen.
    pub fn is_empty(&self) -> bool {
        self.infinite.is_empty() && self.nodes.is_empty()
    }

    /// Some light that can be chosen is not a delta light (so BSDF sampling can find it).
    pub fn has_wide_lights(&self) -> bool {
        self.any_wide
    }

    fn build(&mut self, items: &mut [(LightBounds, u32)], depth: u32, trail: u64) -> usize {
        let index = self.nodes.len();
        let total = items[1..].iter().fold(items[0].0, |acc, (b, _)| LightBounds::union(&acc, b));
        if items.len() == 1 {
            let shape = self.exact.get(items[0].1 as usize).copied().flatten();
            let profile = self.profiled.get(items[0].1 as usize).copied().flatten();
            self.nodes.push(Node { bounds: total, kind: NodeKind::Leaf(items[0].1), shape, profile });
            self.trails[items[0].1 as usize] = Some(trail);
            return index;
        }
        let mid = if depth < MAX_HEURISTIC_DEPTH { split_by_cost(items, &total) } else { None }.unwrap_or_else(|| {
            // Halve along the centroids' longest axis.
            let (clo, chi) =
                items.iter().fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), (b, _)| (lo.min(b.centroid()), hi.max(b.centroid())));
            let dim = (chi - clo).to_array().iter().enumerate().fold(0, |best, (k, e)| if *e > (chi - clo)[best] { k } else { best });
            items.sort_by(|a, b| a.0.centroid()[dim].total_cmp(&b.0.centroid()[dim]).then(a.1.cmp(&b.1)));
            items.len() / 2
        });
        self.nodes.push(Node { bounds: total, kind: NodeKind::Interior(0), shape: None, profile: None });
        let (left, right) = items.split_at_mut(mid);
        self.build(left, depth + 1, trail);
        let second = self.build(right, depth + 1, trail | (1u64 << depth.min(63)));
        self.nodes[index].kind = NodeKind::Interior(second as u32);
        index
    }

    /// The cut: from the root, split the costliest interior node until [`CUT_SIZE`] nodes (or
    /// only leaves) remain; then number every light by the cut node above it.
    fn make_cut(&mut self) {
        let mut cut: Vec<(u32, u32)> = vec![(0, 0)];
        loop {
            if cut.len() + 1 > CUT_SIZE {
                break;
            }
            let costliest = cut
                .iter()
                .enumerate()
                .filter(|(_, (node, _))| matches!(self.nodes[*node as usize].kind, NodeKind::Interior(_)))
                .map(|(k, (node, _))| (k, self.nodes[*node as usize].bounds.cost(&self.nodes[*node as usize].bounds, 0)))
                .fold(None, |best: Option<(usize, f32)>, (k, c)| if best.is_none_or(|(_, b)| c > b) { Some((k, c)) } else { best });
            let Some((k, _)) = costliest else { break };
            let (node, depth) = cut[k];
            let NodeKind::Interior(second) = self.nodes[node as usize].kind else { break };
            cut[k] = (node + 1, depth + 1);
            cut.insert(k + 1, (second, depth + 1));
        }
        let first = self.infinite.len() as u32;
        for (k, &(node, _)) in cut.iter().enumerate() {
            let mut stack = vec![node as usize];
            while let Some(i) = stack.pop() {
                match self.nodes[i].kind {
                    NodeKind::Leaf(light) => self.entry[light as usize] = Some(first + k as u32),
                    NodeKind::Interior(second) => stack.extend([i + 1, second as usize]),
                }
            }
        }
        self.cut = cut;
    }

    /// The lights weighed at shading point `p` with normal `n` (zero: no horizon).
    pub fn at(&self, p: Vec3A, n: Vec3A) -> LightsAt<'_> {
        let mut cdf = Vec::with_capacity(self.infinite.len() + self.cut.len());
        let mut total = 0.0f32;
        for i in &self.infinite {
            total += i.importance(p, n);
            cdf.push(total);
        }
        for &(node, _) in &self.cut {
            total += self.nodes[node as usize].importance(p, n, &self.profiles);
            cdf.push(total);
        }
        LightsAt { sampler: self, p, n, cdf }
    }

    /// [`LightsAt::sample`] at (p, n), for a single choice.
    pub fn sample(&self, p: Vec3A, n: Vec3A, u: f32) -> Option<(usize, f32)> {
        self.at(p, n).sample(u)
    }

    /// [`LightsAt::pmf`] at (p, n), for a single light.
    pub fn pmf(&self, p: Vec3A, n: Vec3A, light: usize) -> f32 {
        self.at(p, n).pmf(light)
    }

    /// Calls `f(light index, hit)` for every area light the ray from `o` along unit `d` meets
    /// (on its emitting side) before `t_max`, finding them by the tree's boxes; moving lights
    /// posed at shutter time `time` (the ray's).
    pub fn for_each_crossed(&self, lights: &[Light], o: Vec3A, d: Vec3A, t_max: f32, time: f32, mut f: impl FnMut(usize, LightHit)) {
        if self.nodes.is_empty() {
            return;
        }
        let inv = d.recip();
        // Depth-first; the tree is at most MAX_HEURISTIC_DEPTH + 32 deep, so the stack (two
        // entries per level at most) never overflows.
        let mut stack = [0usize; 2 * MAX_HEURISTIC_DEPTH as usize + 66];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let node = stack[top];
            let b = &self.nodes[node].bounds;
            if !ray_box(o, inv, b.lo, b.hi, t_max) {
                continue;
            }
            match self.nodes[node].kind {
                NodeKind::Leaf(light) => {
                    if let Some(hit) = lights.get(light as usize).and_then(|l| l.intersect_at(o, d, t_max, time)) {
                        f(light as usize, hit);
                    }
                }
                NodeKind::Interior(second) => {
                    stack[top] = second as usize;
                    stack[top + 1] = node + 1;
                    top += 2;
                }
            }
        }
    }
}

impl LightsAt<'_> {
    /// Chooses a light from uniform `u`: (light index, probability). `None` when no light can
    /// light the point. A stratified `u` gives stratified choices (the number is remapped at
    /// each step, never redrawn).
    pub fn sample(&self, u: f32) -> Option<(usize, f32)> {
        let total = *self.cdf.last()?;
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let target = (u * total).clamp(0.0, total * (1.0 - f32::EPSILON));
        let e = self.cdf.partition_point(|&c| c <= target).min(self.cdf.len() - 1);
        let start = if e == 0 { 0.0 } else { self.cdf[e - 1] };
        let weight = self.cdf[e] - start;
        if !(weight > 0.0) {
            return None;
        }
        let s = self.sampler;
        let mut prob = weight / total;
        if e < s.infinite.len() {
            return Some((s.infinite[e].light as usize, prob));
        }
        let mut u = ((target - start) / weight).clamp(0.0, 1.0 - f32::EPSILON);
        let mut node = s.cut[e - s.infinite.len()].0 as usize;
        loop {
            match s.nodes[node].kind {
                NodeKind::Leaf(light) => return Some((light as usize, prob)),
                NodeKind::Interior(second) => {
                    let (a, b) = (node + 1, second as usize);
                    let ia = s.nodes[a].importance(self.p, self.n, &s.profiles);
                    let ib = s.nodes[b].importance(self.p, self.n, &s.profiles);
                    if !(ia + ib > 0.0) {
                        return None;
                    }
                    let pa = ia / (ia + ib);
                    if u < pa {
                        u = (u / pa).min(1.0 - f32::EPSILON);
                        prob *= pa;
                        node = a;
                    } else {
                        u = ((u - pa) / (1.0 - pa)).clamp(0.0, 1.0 - f32::EPSILON);
                        prob *= 1.0 - pa;
                        node = b;
                    }
                }
            }
        }
    }

    /// The probability that [`LightsAt::sample`] chooses light `light`.
    pub fn pmf(&self, light: usize) -> f32 {
        let s = self.sampler;
        let Some(total) = self.cdf.last().copied().filter(|t| *t > 0.0 && t.is_finite()) else { return 0.0 };
        let Some(Some(e)) = s.entry.get(light).map(|e| e.map(|e| e as usize)) else { return 0.0 };
        let mut prob = (self.cdf[e] - if e == 0 { 0.0 } else { self.cdf[e - 1] }) / total;
        if e < s.infinite.len() {
            return prob;
        }
        let Some(Some(trail)) = s.trails.get(light) else { return 0.0 };
        let (cut_node, mut depth) = s.cut[e - s.infinite.len()];
        let mut node = cut_node as usize;
        loop {
            match s.nodes[node].kind {
                NodeKind::Leaf(_) => return prob,
                NodeKind::Interior(second) => {
                    let (a, b) = (node + 1, second as usize);
                    let ia = s.nodes[a].importance(self.p, self.n, &s.profiles);
                    let ib = s.nodes[b].importance(self.p, self.n, &s.profiles);
                    if !(ia + ib > 0.0) {
                        return 0.0;
                    }
                    if trail >> depth.min(63) & 1 == 0 {
                        prob *= ia / (ia + ib);
                        node = a;
                    } else {
                        prob *= ib / (ia + ib);
                        node = b;
                    }
                    depth += 1;
                }
            }
        }
    }
}

/// An importance that is not finite (a light of NaN or infinite radiance) becomes 1: see
/// [`LightBounds::of`].
fn nominal(importance: f32) -> f32 {
    if importance.is_finite() {
        importance
    } else {
        1.0
    }
}

/// Slab test of the ray against a box, conservative (padded) so a ray grazing a flat light's
/// box is not lost.
fn ray_box(o: Vec3A, inv_d: Vec3A, lo: Vec3A, hi: Vec3A, t_max: f32) -> bool {
    let pad = 1e-4 * (hi - lo).max_element().max(1e-6);
    let t0 = (lo - Vec3A::splat(pad) - o) * inv_d;
    let t1 = (hi + Vec3A::splat(pad) - o) * inv_d;
    // NaN (0 · ∞ on a slab edge) counts as inside: never lose a light.
    let near = t0.min(t1);
    let far = t0.max(t1);
    let tn = [near.x, near.y, near.z, 0.0].into_iter().filter(|x| !x.is_nan()).fold(f32::NEG_INFINITY, f32::max);
    let tf = [far.x, far.y, far.z, t_max].into_iter().filter(|x| !x.is_nan()).fold(f32::INFINITY, f32::min);
    tn <= tf
}

/// The split of `items` (sorted in place) with the least surface-area-orientation cost over 12
/// buckets per axis; `None` when every centroid coincides.
fn split_by_cost(items: &mut [(LightBounds, u32)], total: &LightBounds) -> Option<usize> {
    const BUCKETS: usize = 12;
    let (clo, chi) =
        items.iter().fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), (b, _)| (lo.min(b.centroid()), hi.max(b.centroid())));
    let mut best: Option<(f32, usize, usize)> = None;
    for dim in 0..3 {
        let extent = chi[dim] - clo[dim];
        if !(extent > 0.0) {
            continue;
        }
        let bucket_of = |b: &LightBounds| (((b.centroid()[dim] - clo[dim]) / extent * BUCKETS as f32) as usize).min(BUCKETS - 1);
        let mut buckets: [Option<LightBounds>; BUCKETS] = [None; BUCKETS];
        for (b, _) in items.iter() {
            let k = bucket_of(b);
            buckets[k] = Some(buckets[k].map_or(*b, |acc| LightBounds::union(&acc, b)));
        }
        for split in 0..BUCKETS - 1 {
            let side = |range: std::ops::Range<usize>| {
                buckets[range]
                    .iter()
                    .flatten()
                    .fold(None, |acc: Option<LightBounds>, b| Some(acc.map_or(*b, |a| LightBounds::union(&a, b))))
            };
            let (Some(l), Some(r)) = (side(0..split + 1), side(split + 1..BUCKETS)) else { continue };
            let cost = l.cost(total, dim) + r.cost(total, dim);
            if cost.is_finite() && best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, dim, split));
            }
        }
    }
    let (_, dim, split) = best?;
    let extent = chi[dim] - clo[dim];
    let left = |b: &LightBounds| (((b.centroid()[dim] - clo[dim]) / extent * BUCKETS as f32) as usize).min(BUCKETS - 1) <= split;
    // Stable partition, so the tree (and the image) does not depend on anything but the input.
    let (mut l, r): (Vec<_>, Vec<_>) = items.iter().copied().partition(|(b, _)| left(b));
    let mid = l.len();
    l.extend(r);
    items.copy_from_slice(&l);
    (mid > 0 && mid < items.len()).then_some(mid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    fn sphere(c: Vec3A, r: f32, l: f32) -> Light {
        Light::usd_area("/s", LightShape::Sphere { center: c, radius: r }, l, 0.0, Vec3A::ONE, false)
    }

    /// A small sphere at `c` shaped by a narrow type C beam (1000 cd within 10°, nothing past
    /// 15°) about `axis`.
    fn beam(c: Vec3A, axis: Vec3A) -> Light {
        let ies = crate::light::IesProfile::parse("TILT=NONE\n1 -1 1 3 1 1 2 0 0 0 1 1 10\n0 10 15\n0\n1000 1000 0\n").unwrap();
        let (x, y) = axis.any_orthonormal_pair();
        let shaping =
            crate::light::IesShaping { profile: ies, file: "beam.ies".into(), angle_scale: 0.0, normalize: false, x, y, tilt: 0.0 };
        let mut l = sphere(c, 0.01, 1.0);
        l.shaping = Some(crate::light::Shaping::with_ies(None, axis, shaping));
        l
    }

    #[test]
    fn an_ies_beam_weighs_its_light_by_the_profile_toward_the_point() {
        // Two equal beams at the same distance from p: one aimed at p, one away. Without the
        // profile in the weights each would be chosen half the time.
        let lights = vec![beam(Vec3A::new(-1.0, 0.0, 3.0), Vec3A::NEG_Z), beam(Vec3A::new(1.0, 0.0, 3.0), Vec3A::Z)];
        let s = LightSampler::new(&lights);
        let (p, n) = (Vec3A::new(-1.0, 0.0, 0.0), Vec3A::Z);
        let (aimed, away) = (s.pmf(p, n, 0), s.pmf(p, n, 1));
        assert!(aimed > 0.99 && away > 0.0 && (aimed + away - 1.0).abs() < 1e-5, "{aimed} {away}");
        // Still unbiased: the estimate with the tree's choices is the beam's I / d² (the other
        // sends nothing here), the small sphere's intensity being L · πr² · candela.
        let truth = 1000.0 * PI * 0.01 * 0.01 / 9.0;
        let mut rng = Sampler::new(4, 5, 6);
        let (mut e, trials) = (0.0f64, 100_000);
        for k in 0..trials {
            let (j, prob) = s.sample(p, n, (k as f32 + 0.5) / trials as f32).unwrap();
            if let Some(ls) = lights[j].sample(p, n, rng.next_f32(), rng.next_f32()) {
                e += f64::from(ls.weight().x * ls.wi.dot(n).max(0.0) / prob);
            }
        }
        let e = (e / f64::from(trials)) as f32;
        assert!((e - truth).abs() < 0.01 * truth, "{e} vs {truth}");
        // Off the beam of the first, inside neither: both kept at the floor, never dropped.
        let q = Vec3A::new(0.0, 5.0, 0.0);
        assert!(s.pmf(q, n, 0) > 0.0 && s.pmf(q, n, 1) > 0.0);
    }

    #[test]
    fn a_dome_with_portals_weighs_what_comes_through_them() {
        // A uniform dome beside a sphere light; a 4 × 4 window 4 above p, facing down.
        let dome = Light::usd_area("/sky", LightShape::Dome(None), 1.0, 0.0, Vec3A::ONE, false);
        let lamp = sphere(Vec3A::new(3.0, 0.0, 2.0), 0.2, 5.0);
        let window = crate::light::Portal {
            name: "/window".into(),
            center: Vec3A::new(0.0, 0.0, 4.0),
            u: Vec3A::X * 2.0,
            v: Vec3A::Y * 2.0,
            normal: Vec3A::NEG_Z,
        };
        let open = LightSampler::new(&[dome.clone(), lamp.clone()]);
        let mut guided = dome;
        guided.portals = vec![window].into();
        let portals = LightSampler::new(&[guided, lamp]);
        let (p, n) = (Vec3A::ZERO, Vec3A::Z);
        // The dome's weight relative to the lamp's, scaled by the window's share of the sky:
        // its solid angle 16 · 1 / 4² = 1 sr, at normal incidence, over π.
        let ratio = |s: &LightSampler| s.pmf(p, n, 0) / s.pmf(p, n, 1);
        let share = ratio(&portals) / ratio(&open);
        assert!((share - 1.0 / PI).abs() < 1e-4, "{share}");
        // Behind the window (no portal faces the point): the floor, never zero.
        let (behind, down) = (Vec3A::new(0.0, 0.0, 6.0), Vec3A::NEG_Z);
        let share = portals.pmf(behind, down, 0) / portals.pmf(behind, down, 1) / (open.pmf(behind, down, 0) / open.pmf(behind, down, 1));
        assert!((share - PORTAL_IMPORTANCE_FLOOR).abs() < 1e-5, "{share}");
    }

    #[test]
    fn pmf_matches_sampling_frequencies_and_sums_to_one() {
        let mut rng = Sampler::new(9, 9, 9);
        // More lights than the cut holds, so choices also walk down the tree.
        let mut lights: Vec<Light> = (0..300)
            .map(|_| {
                let c = Vec3A::new(rng.next_f32() * 10.0 - 5.0, rng.next_f32() * 10.0 - 5.0, rng.next_f32() * 4.0 + 0.5);
                sphere(c, 0.1 + 0.3 * rng.next_f32(), 1.0 + 5.0 * rng.next_f32())
            })
            .collect();
        lights.push(Light::distant("/sun", Vec3A::new(0.3, 0.1, -1.0), Vec3A::splat(2.0)));
        lights.push(Light::usd_area(
            "/rect",
            LightShape::Rect { center: Vec3A::Z * 3.0, u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z },
            3.0,
            0.0,
            Vec3A::ONE,
            false,
        ));
        let s = LightSampler::new(&lights);
        let (p, n) = (Vec3A::new(0.5, -0.3, 0.0), Vec3A::Z);
        let total: f32 = (0..lights.len()).map(|j| s.pmf(p, n, j)).sum();
        assert!((total - 1.0).abs() < 1e-4, "{total}");
        let trials = 200_000;
        let mut counts = vec![0u32; lights.len()];
        for k in 0..trials {
            let (j, prob) = s.sample(p, n, (k as f32 + 0.5) / trials as f32).expect("a light");
            assert!((prob - s.pmf(p, n, j)).abs() <= 1e-5 * prob.max(1e-3), "light {j}: {prob} vs {}", s.pmf(p, n, j));
            counts[j] += 1;
        }
        for (j, c) in counts.iter().enumerate() {
            let expected = s.pmf(p, n, j) * trials as f32;
            assert!((*c as f32 - expected).abs() <= 2.0 + 0.01 * expected, "light {j}: {c} vs {expected}");
        }
    }

    #[test]
    fn lights_that_cannot_light_a_point_are_never_chosen() {
        // A rect facing up, below the point: it lights nothing above it.
        let down_facing = Light::usd_area(
            "/r",
            LightShape::Rect { center: Vec3A::new(0.0, 0.0, -1.0), u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z },
            1.0,
            0.0,
            Vec3A::ONE,
            false,
        );
        let below = sphere(Vec3A::new(0.0, 0.0, -5.0), 0.5, 1.0);
        let s = LightSampler::new(&[down_facing, below]);
        assert_eq!(s.pmf(Vec3A::ZERO, Vec3A::Z, 0), 0.0);
        // The sphere is below the horizon of a surface facing up.
        assert!(s.sample(Vec3A::ZERO, Vec3A::Z, 0.5).is_none());
        assert!(s.pmf(Vec3A::ZERO, Vec3A::NEG_Z, 1) > 0.0);
    }

    #[test]
    fn rays_find_the_lights_they_cross() {
        let lights: Vec<Light> = (0..20).map(|i| sphere(Vec3A::new(i as f32 * 2.0, 0.0, 5.0), 0.5, 1.0)).collect();
        let s = LightSampler::new(&lights);
        let mut hits = Vec::new();
        s.for_each_crossed(&lights, Vec3A::new(14.0, 0.0, 0.0), Vec3A::Z, f32::INFINITY, 0.0, |j, h| hits.push((j, h.t)));
        assert_eq!(hits.len(), 1);
        assert_eq!(hits[0].0, 7);
        assert!((hits[0].1 - 4.5).abs() < 1e-5);
        let mut none = 0;
        s.for_each_crossed(&lights, Vec3A::new(15.0, 0.0, 0.0), Vec3A::Z, f32::INFINITY, 0.0, |_, _| none += 1);
        assert_eq!(none, 0);
    }
}
