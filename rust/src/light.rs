//! Lights (UsdLux): distant, sphere, rect, disk, cylinder, dome and emissive meshes (`MeshLightAPI`:
//! [`TriangleLight`], sampled uniformly by area); `ShapingAPI` on sphere, rect and disk
//! lights ([`Shaping`]); light and shadow linking ([`Light::illuminates`],
//! [`Light::shadowed_by`]: what the direct-lighting estimator and shadow rays honour).
//!
//! **Units** (UsdLux's `LightAPI`): a light's scalar emission is `intensity · 2^exposure`, times
//! `color` (and the blackbody colour of `colorTemperature`, which the USD front end folds into
//! `color`). Sphere, rect, disk and dome lights emit that as **radiance**; with `normalize` an
//! area light's radiance is divided by its world-space surface area, so its power does not
//! change with its size (a dome ignores `normalize`). A distant light's emission is the radiance
//! of a disk of angular diameter `angle`; with `normalize` it is divided by UsdLux's
//! `sizeFactor` (π sin²θmax for θmax ≤ π/2, θmax = angle/2), which makes `intensity` the
//! **irradiance** on a surface facing the light whatever its angle. A distant light of angle 0
//! is a point at infinity (a delta light) whose emission is that irradiance. So a white
//! lambertian surface facing a normalized distant light of intensity 1 has radiance 1/π.
//!
//! **Sampling** (what [`crate::integrator::direct_light`] and the light sampler build on): every
//! light samples a direction toward it from a shading point with a solid-angle density
//! ([`Light::sample`], [`Light::pdf`]): a sphere uniformly over the cone it subtends, a rect or
//! disk uniformly over its area, a distant light uniformly over its cone, a textured dome by its
//! importance table ([`EnvTexture`]) and a uniform dome cosine-weighted about the normal; a dome
//! with `PortalLight`s mostly through them ([`Portal`]: a mixture that keeps what it delivers). Rays
//! found by BSDF sampling meet area lights through [`Light::intersect`] (lights are not geometry
//! in the BVH) and, when they escape, dome and distant lights through [`Light::environment`] /
//! [`crate::scene::Scene::environment`], so the two strategies can be weighted by multiple importance
//! sampling. Shadow rays get the paper's differentials: narrow toward point-like lights (§4.3),
//! spread over the light's solid angle divided among the rays toward wide ones (§4.5).

use std::f32::consts::PI;

use glam::{Mat4, Vec3A};

use crate::sampling::{cosine_hemisphere, frame};

mod env;
mod ies;
mod mesh;
mod portal;

pub use ies::{IesProfile, Photometry, Tilt};
pub use portal::{Portal, PORTAL_FRACTION};

pub use env::{latlong_direction, latlong_st, luminance, Distribution1D, Distribution2D, EnvDistribution, EnvTexture, TABLE_MAX_WIDTH};
pub use mesh::{Emitter, MeshEmission, TriangleHit, TriangleLight, TrianglePoint};

#[derive(Clone, Debug, PartialEq)]
pub enum LightShape {
    /// Light arriving from direction −`direction`; `direction` is where it travels (render space,
    /// unit length): a UsdLux.DistantLight emits along its local −Z. `angle_deg` is the angular
    /// diameter of the source, in [0, 360) (0: a point at infinity).
    Distant { direction: Vec3A, angle_deg: f32 },
    /// A sphere of `radius` (render units) around `center`, emitting outward.
    Sphere { center: Vec3A, radius: f32 },
    /// A parallelogram `center ± u ± v` (half-extent vectors), emitting along its `normal`
    /// (UsdLux: the light's −Z).
    Rect { center: Vec3A, u: Vec3A, v: Vec3A, normal: Vec3A },
    /// An ellipse `center + a·u + b·v`, a² + b² ≤ 1, emitting along `normal`.
    Disk { center: Vec3A, u: Vec3A, v: Vec3A, normal: Vec3A },
    /// A tube without end caps (UsdLux.CylinderLight): `center + t·axis + radius·(cos φ e1 +
    /// sin φ e2)`, t ∈ [−1, 1], where e1, e2 are unit and orthogonal to each other and to
    /// `axis` (the half-length vector: the light's local X). It emits outward only.
    Cylinder { center: Vec3A, axis: Vec3A, radius: f32, e1: Vec3A, e2: Vec3A },
    /// Radiance from every direction: uniform, or a latlong environment texture.
    Dome(Option<EnvTexture>),
    /// An emissive mesh (UsdLux `MeshLightAPI`, `GeometryLight`) as tessellated for lighting,
    /// emitting from its triangles' front sides (both with `two_sided`).
    Mesh(std::sync::Arc<TriangleLight>),
}

impl PartialEq for TriangleLight {
    /// The same mesh light (its triangles are not compared).
    fn eq(&self, o: &Self) -> bool {
        std::ptr::eq(self, o)
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// Prim path, for messages and stats.
    pub name: String,
    pub shape: LightShape,
    /// Linear RGB: the emitted radiance (a dome's multiplies its texture), except for a distant
    /// light of angle 0, where it is the irradiance on a surface facing the light.
    pub radiance_scale: Vec3A,
    pub casts_shadows: bool,
    /// UsdLux `ShapingAPI` (sphere, rect and disk lights): the emission's cone and focus.
    pub shaping: Option<Shaping>,
    /// UsdLux light linking: the meshes this light illuminates.
    pub illuminates: MeshFilter,
    /// A rect light's `texture:file`, multiplying its radiance over the rect.
    pub texture: Option<RectTexture>,
    /// UsdLux shadow linking: the meshes that block this light's shadow rays.
    pub shadowed_by: MeshFilter,
    /// A dome's `PortalLight`s, which guide its light sampling (see [`Portal`]); empty for
    /// every other light.
    pub portals: std::sync::Arc<[Portal]>,
    /// An IES-shaped sphere, rect, disk or cylinder light draws its directions by its profile
    /// toward the shaded point (a guide over its shape's sampling numbers) rather than by its
    /// shape alone (USD: `bool mipray:iesProfileSampling` on the light). Off by
    /// default: on a 2 × 2 panel with a 20° beam 0.5 above a floor it lowers the mean squared
    /// error per sample 1.5× but costs 2.3× the render time (release build,
    /// `scripts/ies_profile_sampling_noise.py`), a net loss until the guide is cheaper.
    pub profile_sampling: bool,
}

/// A set of the scene's meshes (indices into [`crate::scene::Scene::meshes`]) given by those it leaves out:
/// the default holds every mesh. What a light or shadow linking collection resolves to.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MeshFilter {
    /// Sorted, without duplicates.
    excluded: std::sync::Arc<[u32]>,
}

impl MeshFilter {
    /// Every mesh but `excluded`.
    pub fn excluding(mut excluded: Vec<u32>) -> Self {
        excluded.sort_unstable();
        excluded.dedup();
        MeshFilter { excluded: excluded.into() }
    }

    /// Whether mesh `mesh` is in the set.
    pub fn contains(&self, mesh: u32) -> bool {
        self.excluded.binary_search(&mesh).is_err()
    }

    /// True for the set of every mesh (no linking).
    pub fn is_all(&self) -> bool {
        self.excluded.is_empty()
    }

    /// The meshes left out.
    pub fn excluded(&self) -> &[u32] {
        &self.excluded
    }
}

/// A rect light's texture (`texture:file`), laid over the rect as Hydra's hdEmbree lays it: `s`
/// along the light's +X from its −X edge, `t` along +Y from its −Y edge (USD's `st`, `t` up the
/// image).
#[derive(Clone)]
pub struct RectTexture {
    pub sampler: std::sync::Arc<dyn crate::texture::TextureSampler>,
    pub texture: crate::texture::TextureHandle,
}

impl std::fmt::Debug for RectTexture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RectTexture").field("texture", &self.texture).finish_non_exhaustive()
    }
}

impl PartialEq for RectTexture {
    fn eq(&self, o: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.sampler, &o.sampler) && self.texture == o.texture
    }
}

impl RectTexture {
    /// The texture's colour at `st` (a texel's worth of filtering); white where it cannot be
    /// read, black for non-finite or negative texels.
    pub fn radiance(&self, st: [f32; 2]) -> Vec3A {
        // One texel of the finer axis both ways: a coarser MIP level would bleed colour across
        // the rect.
        let [w, h] = self.sampler.resolution(self.texture).unwrap_or([1024, 1024]);
        let texel = 1.0 / w.max(h).max(1) as f32;
        let lookup =
            crate::texture::Lookup { wrap_s: crate::texture::Wrap::Clamp, wrap_t: crate::texture::Wrap::Clamp, ..Default::default() };
        let mut rgb = [0.0f32; 3];
        if !self.sampler.sample(self.texture, st, [texel, 0.0], [0.0, texel], &lookup, &mut rgb) {
            return Vec3A::ONE;
        }
        let c = Vec3A::from(rgb);
        if c.is_finite() {
            c.max(Vec3A::ZERO)
        } else {
            Vec3A::ZERO
        }
    }
}

/// UsdLux's `ShapingAPI` on an area light, as Hydra's reference path tracer (hdEmbree) applies
/// it: emitted radiance along a direction ω (from the light toward the lit point) at angle
/// θ = ∠(axis, ω) off the light's axis (its local −Z) is multiplied by
///
/// - focus: `lerp(|cos θ|^focus, focusTint, 1)` when `focus` > 0 (the tint colours what the
///   focus takes away; black by default);
/// - cone: `1 − smoothstep(θ; θsoft, θcone)` with θcone = `cone:angle` and
///   θsoft = θcone · (1 − `cone:softness`): full inside θsoft, zero beyond θcone (softness 0:
///   a hard edge at θcone).
///
/// The factor depends only on ω, so a spot of cone angle α pointing down from height h lights a
/// floor inside radius h·tan α and nothing outside (for a small light).
#[derive(Clone, Debug, PartialEq)]
pub struct Shaping {
    /// Unit, render space: where the light points (its local −Z).
    pub axis: Vec3A,
    /// `cone:angle`, radians, in [0, π].
    pub cone: f32,
    /// `cone:softness`, in [0, 1].
    pub softness: f32,
    /// `focus`, ≥ 0.
    pub focus: f32,
    /// `focusTint`, linear RGB.
    pub focus_tint: Vec3A,
    /// `ies:file`, `ies:angleScale`, `ies:normalize` ([`IesShaping`]).
    pub ies: Option<std::sync::Arc<IesShaping>>,
}

/// An IES profile on a light (UsdLux `ShapingAPI`'s `ies:*` inputs), evaluated as
/// [`IesProfile`] documents: the candela toward the emission direction (times the tilt
/// table's factor at the light's tilt), divided by the profile's mean with `normalize`.
#[derive(Clone, Debug, PartialEq)]
pub struct IesShaping {
    pub profile: IesProfile,
    /// The file, for stats and messages.
    pub file: String,
    /// `ies:angleScale`, > −1 (type C profiles only).
    pub angle_scale: f32,
    pub normalize: bool,
    /// The light's local +X and +Y in render space (unit): the azimuth's frame.
    pub x: Vec3A,
    pub y: Vec3A,
    /// The luminaire's tilt, radians, at which a tilt table is read ([`Tilt::tilt_angle`]: by
    /// the table's lamp-to-luminaire geometry; 0 without one).
    pub tilt: f32,
}

impl IesShaping {
    /// What radiance emitted along unit `w` (away from the light, whose −Z is `axis`) is
    /// multiplied by.
    pub fn factor(&self, axis: Vec3A, w: Vec3A) -> f32 {
        use std::f32::consts::PI;
        let c = match self.profile.kind {
            ies::Photometry::C => {
                let theta = axis.dot(w).clamp(-1.0, 1.0).acos();
                // hdEmbree's azimuth: of the direction toward the light, in the light's XY plane.
                let phi = (-w.dot(self.y)).atan2(-w.dot(self.x));
                let scale = 1.0 + self.angle_scale;
                let theta = if scale > 0.0 { ((theta - PI) / scale + PI).clamp(0.0, PI) } else { theta };
                self.profile.candela(theta, phi)
            }
            _ => self.profile.candela_local(Vec3A::new(w.dot(self.x), w.dot(self.y), -w.dot(axis))),
        } * self.tilt_factor();
        if self.normalize {
            let m = self.profile.mean();
            if m > 0.0 {
                c / m
            } else {
                0.0
            }
        } else {
            c
        }
    }

    /// An upper bound of [`IesShaping::factor`] over the directions whose angle off the axis
    /// lies in [`lo`, `hi`] (radians): type C's largest candela over those vertical angles
    /// (every azimuth); types A and B their peak.
    pub fn bound_between(&self, lo: f32, hi: f32) -> f32 {
        let c = match self.profile.kind {
            ies::Photometry::C => {
                let scale = 1.0 + self.angle_scale;
                // The angle scale's map is increasing: the interval's ends bound it.
                let map = |t: f32| if scale > 0.0 { ((t - PI) / scale + PI).clamp(0.0, PI) } else { t };
                self.profile.max_between(map(lo), map(hi))
            }
            _ => self.profile.peak(),
        } * self.tilt_factor();
        match (self.normalize, self.profile.mean() > 0.0) {
            (true, true) => c / self.profile.mean(),
            (true, false) => 0.0,
            _ => c,
        }
    }

    /// The tilt table's factor at the light's tilt (1 without a table).
    pub fn tilt_factor(&self) -> f32 {
        self.profile.tilt.as_ref().map_or(1.0, |t| t.factor(self.tilt))
    }

    /// The largest [`IesShaping::factor`] (an upper bound for the light tree's importance).
    pub fn peak(&self) -> f32 {
        let m = self.profile.mean();
        let peak = self.profile.peak() * self.tilt_factor();
        match (self.normalize, m > 0.0) {
            (true, true) => peak / m,
            (true, false) => 0.0,
            _ => peak,
        }
    }
}

impl Shaping {
    /// From UsdLux's inputs (`cone_deg` in degrees); values out of range are clamped (NaN: the
    /// input's fallback). `None` when the inputs shape nothing (a cone of 180° or more, no focus).
    pub fn new(axis: Vec3A, cone_deg: f32, softness: f32, focus: f32, focus_tint: Vec3A) -> Option<Shaping> {
        let finite = |x: f32, fallback: f32| if x.is_finite() { x } else { fallback };
        let cone = finite(cone_deg, 180.0).clamp(0.0, 180.0).to_radians();
        let focus = finite(focus, 0.0).max(0.0);
        let s = Shaping {
            axis: axis.normalize_or(Vec3A::NEG_Z),
            cone,
            softness: finite(softness, 0.0).clamp(0.0, 1.0),
            focus,
            focus_tint: if focus_tint.is_finite() { focus_tint.max(Vec3A::ZERO) } else { Vec3A::ZERO },
            ies: None,
        };
        (cone < PI || focus > 0.0).then_some(s)
    }

    /// `shaping` (or, if `None`, no cone or focus about `axis`) with the IES profile `ies`.
    pub fn with_ies(shaping: Option<Shaping>, axis: Vec3A, ies: IesShaping) -> Shaping {
        let base = shaping.unwrap_or(Shaping {
            axis: axis.normalize_or(Vec3A::NEG_Z),
            cone: PI,
            softness: 0.0,
            focus: 0.0,
            focus_tint: Vec3A::ZERO,
            ies: None,
        });
        Shaping { ies: Some(std::sync::Arc::new(ies)), ..base }
    }

    /// What radiance emitted along unit `w` (away from the light) is multiplied by (RGB).
    pub fn factor(&self, w: Vec3A) -> Vec3A {
        let cos_off = self.axis.dot(w).clamp(-1.0, 1.0);
        let mut f = Vec3A::ONE;
        if self.focus > 0.0 {
            let ff = cos_off.abs().powf(self.focus);
            f = self.focus_tint + (Vec3A::ONE - self.focus_tint) * ff;
        }
        if let Some(ies) = &self.ies {
            f *= ies.factor(self.axis, w);
        }
        if self.cone < PI {
            let theta = cos_off.acos();
            let soft = self.cone * (1.0 - self.softness);
            let step = if theta <= soft {
                0.0
            } else if theta >= self.cone {
                1.0
            } else {
                let t = (theta - soft) / (self.cone - soft);
                t * t * (3.0 - 2.0 * t)
            };
            f *= 1.0 - step;
        }
        f
    }

    /// An upper bound of [`Shaping::factor`]'s largest channel over the directions whose angle
    /// off the axis lies in [`lo`, `hi`] (radians, within [0, π]): focus and cone at the angle
    /// nearest their peak, the profile by [`IesShaping::bound_between`].
    pub fn bound_between(&self, lo: f32, hi: f32) -> f32 {
        let mut f = 1.0;
        if self.focus > 0.0 {
            // |cos| is largest at an end of the interval.
            let ff = lo.cos().abs().max(hi.cos().abs()).powf(self.focus);
            f = (self.focus_tint + (Vec3A::ONE - self.focus_tint) * ff).max_element();
        }
        if let Some(ies) = &self.ies {
            f *= ies.bound_between(lo, hi);
        }
        if self.cone < PI {
            let soft = self.cone * (1.0 - self.softness);
            let step = if lo <= soft {
                0.0
            } else if lo >= self.cone {
                1.0
            } else {
                let t = (lo - soft) / (self.cone - soft);
                t * t * (3.0 - 2.0 * t)
            };
            f *= 1.0 - step;
        }
        f
    }

    /// Cosine of the widest angle off the axis the light emits at (−1: every direction).
    pub fn cos_max(&self) -> f32 {
        if self.cone < PI {
            self.cone.cos()
        } else {
            -1.0
        }
    }
}

/// One sample of a light as seen from a point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the point toward the light (render space).
    pub wi: Vec3A,
    /// Distance to the sampled point on the light (render units; infinite for distant and dome
    /// lights).
    pub distance: f32,
    /// Radiance arriving along `wi` (for a delta light: the irradiance it delivers).
    pub radiance: Vec3A,
    /// Solid-angle density of `wi` (per steradian); 1 for a delta light.
    pub pdf: f32,
    /// A point at infinity: one sample is the light's whole contribution.
    pub delta: bool,
}

impl LightSample {
    /// Radiance over density: what the integrator multiplies by `f · |cos θ|`.
    pub fn weight(&self) -> Vec3A {
        if self.pdf > 0.0 {
            self.radiance / self.pdf
        } else {
            Vec3A::ZERO
        }
    }
}

/// Where a ray meets an area light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightHit {
    /// Distance along the (unit) ray, render units.
    pub t: f32,
    /// Radiance the light sends back along the ray.
    pub radiance: Vec3A,
    /// The solid-angle density with which [`Light::sample`] from the ray's origin picks this
    /// direction (for multiple importance sampling).
    pub pdf: f32,
}

/// UsdLux's `sizeFactor` of a normalized distant light of half-angle `theta_max` (radians,
/// clamped to [0, π]): 1 for a point, π sin²θmax up to π/2, (2 − sin²θmax)·π beyond. Up to π/2
/// it is the irradiance a cone of unit radiance delivers to a surface facing it.
pub fn distant_size_factor(theta_max: f32) -> f32 {
    let t = theta_max.clamp(0.0, PI);
    if t <= 0.0 {
        1.0
    } else if t <= PI / 2.0 {
        PI * t.sin().powi(2)
    } else {
        (2.0 - t.sin().powi(2)) * PI
    }
}

/// 1 − cos θ without cancellation for small θ (radians).
fn one_minus_cos(theta: f32) -> f32 {
    2.0 * (0.5 * theta).sin().powi(2)
}

impl Light {
    /// A point at infinity travelling along `direction` with irradiance `irradiance` (RGB).
    pub fn distant(name: impl Into<String>, direction: Vec3A, irradiance: Vec3A) -> Self {
        Light {
            name: name.into(),
            shape: LightShape::Distant { direction: direction.normalize_or(Vec3A::NEG_Z), angle_deg: 0.0 },
            radiance_scale: irradiance,
            casts_shadows: true,
            shaping: None,
            illuminates: MeshFilter::default(),
            shadowed_by: MeshFilter::default(),
            texture: None,
            portals: Vec::new().into(),
            profile_sampling: false,
        }
    }

    /// A UsdLux.DistantLight from its world transform and inputs (see the module doc for what
    /// `normalize` does). `angle_deg` is clipped to [0, 360), as UsdLux says.
    pub fn usd_distant(
        name: impl Into<String>,
        render_from_light: &Mat4,
        intensity: f32,
        exposure: f32,
        color: Vec3A,
        angle_deg: f32,
        normalize: bool,
    ) -> Self {
        let dir = render_from_light.transform_vector3a(Vec3A::NEG_Z);
        let angle = if angle_deg.is_finite() { angle_deg.clamp(0.0, 360.0 - 1e-3) } else { 0.0 };
        let mut emission = color * intensity * exposure.exp2();
        if normalize {
            emission /= distant_size_factor((0.5 * angle).to_radians());
        }
        let mut l = Light::distant(name, dir, emission);
        l.shape = LightShape::Distant { direction: dir.normalize_or(Vec3A::NEG_Z), angle_deg: angle };
        l
    }

    /// An area or dome light from its UsdLux inputs: `shape` already in render space. With
    /// `normalize`, an area light's radiance is divided by its area (a dome's is not).
    pub fn usd_area(name: impl Into<String>, shape: LightShape, intensity: f32, exposure: f32, color: Vec3A, normalize: bool) -> Self {
        let mut radiance = color * intensity * exposure.exp2();
        if normalize {
            let area = shape_area(&shape);
            if area > 0.0 {
                radiance /= area;
            }
        }
        Light {
            name: name.into(),
            shape,
            radiance_scale: radiance,
            casts_shadows: true,
            shaping: None,
            illuminates: MeshFilter::default(),
            shadowed_by: MeshFilter::default(),
            texture: None,
            portals: Vec::new().into(),
            profile_sampling: false,
        }
    }

    /// True when one sample represents the light exactly (a point at infinity).
    pub fn is_delta(&self) -> bool {
        matches!(self.shape, LightShape::Distant { angle_deg, .. } if angle_deg <= 0.0)
    }

    /// Distant and dome lights: at infinity, met by rays that escape the scene.
    pub fn is_infinite(&self) -> bool {
        matches!(self.shape, LightShape::Distant { .. } | LightShape::Dome(_))
    }

    /// Irradiance (RGB) a distant light delivers to a surface facing it; zero for other lights.
    pub fn distant_irradiance(&self) -> Vec3A {
        match self.shape {
            LightShape::Distant { angle_deg, .. } => self.radiance_scale * distant_size_factor((0.5 * angle_deg).to_radians()),
            _ => Vec3A::ZERO,
        }
    }

    /// The solid angle (steradians) the light subtends from `p`: exact for spheres, distant
    /// lights and domes; for rects and disks the area × cosine / distance² of their centre
    /// (an estimate, used only for ray spreads). 0 for a delta light.
    pub fn solid_angle(&self, p: Vec3A) -> f32 {
        match &self.shape {
            LightShape::Distant { angle_deg, .. } => 2.0 * PI * one_minus_cos((0.5 * angle_deg).to_radians()),
            LightShape::Dome(_) => 4.0 * PI,
            LightShape::Sphere { center, radius } => {
                let d2 = (*center - p).length_squared();
                if d2 <= radius * radius {
                    return 4.0 * PI;
                }
                let sin2 = radius * radius / d2;
                2.0 * PI * sin2 / (1.0 + (1.0 - sin2).max(0.0).sqrt())
            }
            shape @ (LightShape::Rect { center, normal, .. } | LightShape::Disk { center, normal, .. }) => {
                let d = *center - p;
                let d2 = d.length_squared();
                if !(d2 > 0.0) {
                    return 2.0 * PI;
                }
                (shape_area(shape) * normal.dot(d).abs() / (d2 * d2.sqrt())).min(2.0 * PI)
            }
            LightShape::Mesh(m) => {
                // Its area over the distance² to its bounds' centre: an estimate, as for rects.
                let d2 = (m.bounds().center() - p).length_squared();
                if !(d2 > 0.0) {
                    return 4.0 * PI;
                }
                (m.area() / d2).min(4.0 * PI)
            }
            LightShape::Cylinder { center, axis, radius, .. } => {
                // Its largest projected area over the distance²: an estimate, as for rects.
                let d2 = (*center - p).length_squared();
                if !(d2 > 0.0) {
                    return 4.0 * PI;
                }
                (4.0 * radius * axis.length() / d2).min(4.0 * PI)
            }
        }
    }

    /// Samples a direction toward the light from point `p` with shading normal `n` (only a
    /// uniform dome uses `n`: it is cosine-sampled about it), with two uniform numbers. `None`
    /// when the sample cannot light `p` (behind a one-sided light, inside a sphere light). A
    /// moving light is taken at the shutter's open ([`Light::sample_at`] for a ray's time).
    pub fn sample(&self, p: Vec3A, n: Vec3A, u1: f32, u2: f32) -> Option<LightSample> {
        self.sample_at(p, n, u1, u2, 0.0)
    }

    /// As [`Light::sample`], a moving light (a mesh light under transform motion blur) posed at
    /// shutter time `time` (the ray's [`crate::ray::Ray::time`]; other lights ignore it).
    pub fn sample_at(&self, p: Vec3A, n: Vec3A, u1: f32, u2: f32, time: f32) -> Option<LightSample> {
        // An IES light seen wide enough for its profile to vary across it: the shape's own
        // numbers drawn by the profile toward `p` ([`ProfileGuide`]), its density scaled.
        let guide = self.profile_guide(p);
        let (u1, u2, guided) = match &guide {
            Some(g) => g.remap(u1, u2),
            None => (u1, u2, 1.0),
        };
        let mut sample = self.sample_shape(p, n, u1, u2, time)?;
        sample.pdf *= guided;
        (sample.pdf.is_finite() && sample.pdf > 0.0).then_some(sample)
    }

    fn sample_shape(&self, p: Vec3A, n: Vec3A, u1: f32, u2: f32, time: f32) -> Option<LightSample> {
        let sample = match &self.shape {
            LightShape::Distant { direction, angle_deg } => {
                let toward = -*direction;
                if *angle_deg <= 0.0 {
                    return Some(LightSample { wi: toward, distance: f32::INFINITY, radiance: self.radiance_scale, pdf: 1.0, delta: true });
                }
                let omc_max = one_minus_cos((0.5 * angle_deg).to_radians());
                let wi = cone_direction(toward, omc_max, u1, u2);
                LightSample { wi, distance: f32::INFINITY, radiance: self.radiance_scale, pdf: 1.0 / (2.0 * PI * omc_max), delta: false }
            }
            LightShape::Dome(env) => {
                let (wi, pdf) = self.sample_dome(env.as_ref(), p, n, u1, u2)?;
                let radiance = self.radiance_scale * env.as_ref().map_or(Vec3A::ONE, |e| e.radiance(wi));
                LightSample { wi, distance: f32::INFINITY, radiance, pdf, delta: false }
            }
            LightShape::Sphere { center, radius } => {
                let to_c = *center - p;
                let dc2 = to_c.length_squared();
                let r2 = radius * radius;
                if !(dc2 > r2) {
                    // Inside (or on) the sphere: an outward-emitting sphere lights nothing there.
                    return None;
                }
                let dc = dc2.sqrt();
                let sin2_max = r2 / dc2;
                let omc_max = sin2_max / (1.0 + (1.0 - sin2_max).max(0.0).sqrt());
                let wi = cone_direction(to_c / dc, omc_max, u1, u2);
                // Distance to the near intersection with the sphere along wi.
                let b = wi.dot(to_c);
                let disc = (r2 - (dc2 - b * b)).max(0.0);
                let distance = (b - disc.sqrt()).max(0.0);
                LightSample { wi, distance, radiance: self.radiance_scale, pdf: 1.0 / (2.0 * PI * omc_max), delta: false }
            }
            shape @ (LightShape::Rect { .. } | LightShape::Disk { .. } | LightShape::Cylinder { .. } | LightShape::Mesh(_)) => {
                let (y, ny, area, emission) = sample_planar(shape, u1, u2, time)?;
                let d = y - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0 && dist2.is_finite()) {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos_l = match shape {
                    LightShape::Mesh(m) if m.two_sided => ny.dot(wi).abs(),
                    _ => -ny.dot(wi),
                };
                if !(cos_l > 0.0) {
                    return None;
                }
                if let LightShape::Mesh(m) = shape {
                    // A nearer part of the mesh in front of the sampled point hides it: the
                    // directions kept are those whose nearest emitting crossing is the sample,
                    // so the density is that crossing's, as `intersect` finds it.
                    if m.intersect_at(p, wi, dist * (1.0 - 1e-3), time).is_some() {
                        return None;
                    }
                }
                let mut radiance = self.radiance_scale * emission;
                if let (Some(tex), LightShape::Rect { .. }) = (&self.texture, shape) {
                    radiance *= tex.radiance([u1, u2]);
                }
                // Area sampling: density in solid angle = dist² / (cos_l · area).
                LightSample { wi, distance: dist, radiance, pdf: dist2 / (cos_l * area), delta: false }
            }
        };
        let mut sample = sample;
        if let Some(shaping) = &self.shaping {
            sample.radiance *= shaping.factor(-sample.wi);
            if sample.radiance.max_element() <= 0.0 {
                // Outside the cone: no shadow ray for nothing.
                return None;
            }
        }
        // A non-finite radiance (a broken light) is passed on: the render loop drops and counts
        // such samples.
        (sample.pdf.is_finite() && sample.pdf > 0.0 && sample.wi.is_finite()).then_some(sample)
    }

    /// The solid-angle density with which [`Light::sample`] from `p` (normal `n`) picks
    /// direction `wi` (unit): 0 where it never does, and for a delta light.
    pub fn pdf(&self, p: Vec3A, n: Vec3A, wi: Vec3A) -> f32 {
        self.pdf_at(p, n, wi, 0.0)
    }

    /// As [`Light::pdf`] for [`Light::sample_at`] at shutter time `time`.
    pub fn pdf_at(&self, p: Vec3A, n: Vec3A, wi: Vec3A, time: f32) -> f32 {
        let pdf = self.pdf_shape(p, n, wi, time);
        match self.profile_guide(p) {
            Some(g) if pdf > 0.0 => self.shape_numbers(p, wi).map_or(0.0, |u| pdf * g.density(u)),
            _ => pdf,
        }
    }

    fn pdf_shape(&self, p: Vec3A, n: Vec3A, wi: Vec3A, time: f32) -> f32 {
        match &self.shape {
            LightShape::Distant { direction, angle_deg } => {
                if *angle_deg <= 0.0 {
                    return 0.0;
                }
                let omc_max = one_minus_cos((0.5 * angle_deg).to_radians());
                if 1.0 - wi.dot(-*direction) <= omc_max {
                    1.0 / (2.0 * PI * omc_max)
                } else {
                    0.0
                }
            }
            LightShape::Dome(env) => {
                if self.portals.is_empty() {
                    return dome_pdf(env.as_ref(), n, wi);
                }
                let choice = portal::PortalChoice::at(&self.portals, p);
                let q = choice.fraction();
                let through = if q > 0.0 { choice.pdf(wi) } else { 0.0 };
                q * through + (1.0 - q) * dome_pdf(env.as_ref(), n, wi)
            }
            LightShape::Sphere { center, radius } => {
                let to_c = *center - p;
                let dc2 = to_c.length_squared();
                let r2 = radius * radius;
                if !(dc2 > r2) {
                    return 0.0;
                }
                let sin2_max = r2 / dc2;
                let omc_max = sin2_max / (1.0 + (1.0 - sin2_max).max(0.0).sqrt());
                if 1.0 - wi.dot(to_c / dc2.sqrt()) <= omc_max {
                    1.0 / (2.0 * PI * omc_max)
                } else {
                    0.0
                }
            }
            LightShape::Rect { .. } | LightShape::Disk { .. } => self.intersect_planar(p, wi, f32::INFINITY).map_or(0.0, |h| h.pdf),
            LightShape::Cylinder { .. } => self.intersect_cylinder(p, wi, f32::INFINITY).map_or(0.0, |h| h.pdf),
            LightShape::Mesh(_) => self.intersect_mesh(p, wi, f32::INFINITY, time).map_or(0.0, |h| h.pdf),
        }
    }

    /// Where the ray from `o` along unit `d` meets this area light's emitting side before
    /// `t_max` (sphere, rect, disk; `None` for distant and dome lights, which rays meet only by
    /// escaping: [`Light::environment`]).
    pub fn intersect(&self, o: Vec3A, d: Vec3A, t_max: f32) -> Option<LightHit> {
        self.intersect_at(o, d, t_max, 0.0)
    }

    /// As [`Light::intersect`], a moving light posed at shutter time `time`.
    pub fn intersect_at(&self, o: Vec3A, d: Vec3A, t_max: f32, time: f32) -> Option<LightHit> {
        let mut hit = self.intersect_shape(o, d, t_max, time)?;
        if let Some(shaping) = &self.shaping {
            hit.radiance *= shaping.factor(-d);
        }
        if let Some(g) = self.profile_guide(o) {
            hit.pdf *= self.shape_numbers(o, d).map_or(0.0, |u| g.density(u));
        }
        Some(hit)
    }

    /// The guide drawing this light's shape numbers by its IES profile (and cone and focus)
    /// toward `p`: `None` without a profile, for a shape it does not apply to, or where the
    /// light looks too small from `p` for the profile to vary across it.
    fn profile_guide(&self, p: Vec3A) -> Option<ProfileGuide> {
        if !self.profile_sampling {
            return None;
        }
        let ies = self.shaping.as_ref().and_then(|s| s.ies.as_ref())?;
        // One shading point asks for the same light's guide for its light sample, its BSDF
        // sample's density and the ray meeting the light: the last one is kept per thread.
        let centre = match &self.shape {
            LightShape::Sphere { center, .. }
            | LightShape::Rect { center, .. }
            | LightShape::Disk { center, .. }
            | LightShape::Cylinder { center, .. } => *center,
            _ => return None,
        };
        let key = (std::sync::Arc::as_ptr(ies) as usize, p.to_array().map(f32::to_bits), centre.to_array().map(f32::to_bits));
        GUIDE_CACHE.with(|c| {
            let mut c = c.borrow_mut();
            if let Some((k, g)) = c.as_ref() {
                if *k == key {
                    return g.clone();
                }
            }
            let g = self.build_profile_guide(p);
            *c = Some((key, g.clone()));
            g
        })
    }

    fn build_profile_guide(&self, p: Vec3A) -> Option<ProfileGuide> {
        let shaping = self.shaping.as_ref().filter(|s| s.ies.is_some())?;
        let (center, reach) = match &self.shape {
            LightShape::Sphere { center, radius } => (*center, *radius),
            LightShape::Rect { center, u, v, .. } | LightShape::Disk { center, u, v, .. } => {
                (*center, (*u + *v).length().max((*u - *v).length()))
            }
            LightShape::Cylinder { center, axis, radius, .. } => (*center, axis.length() + radius),
            _ => return None,
        };
        let dist = (center - p).length();
        if !(reach > GUIDE_MIN_SPREAD * dist) {
            return None;
        }
        // The direction the light emits toward p from the point shape numbers `u` pick.
        let toward_p = |u: [f32; 2]| -> Option<Vec3A> {
            Some(match &self.shape {
                LightShape::Sphere { center, radius } => {
                    let to_c = *center - p;
                    let dc2 = to_c.length_squared();
                    if !(dc2 > radius * radius) {
                        return None;
                    }
                    let sin2_max = radius * radius / dc2;
                    let omc_max = sin2_max / (1.0 + (1.0 - sin2_max).max(0.0).sqrt());
                    -cone_direction(to_c / dc2.sqrt(), omc_max, u[0], u[1])
                }
                shape => {
                    let (y, ..) = sample_planar(shape, u[0], u[1], 0.0)?;
                    (p - y).try_normalize()?
                }
            })
        };
        // Emission directions at the cells' corners and centres. A cell weighs the most the
        // shaping can send within the cone about its centre's direction that holds its corners'
        // (widened by half: its edges may bulge beyond its corners' cone), so a beam narrower
        // than a cell is not missed.
        const G: usize = GUIDE_CELLS;
        const N: usize = G + 1;
        let g = G as f32;
        let mut corners = [Vec3A::ZERO; N * N];
        for (k, d) in corners.iter_mut().enumerate() {
            let u = |x: usize| (x as f32 / g).min(1.0 - f32::EPSILON);
            *d = toward_p([u(k % N), u(k / N)])?;
        }
        let mut w = [0.0f32; G * G];
        for (k, w) in w.iter_mut().enumerate() {
            let (i, j) = (k % G, k / G);
            let centre = toward_p([(i as f32 + 0.5) / g, (j as f32 + 0.5) / g])?;
            // Two arc cosines a cell: the angle off the axis, and the cone's.
            let cos_delta = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .iter()
                .map(|&(di, dj)| centre.dot(corners[(i + di) + N * (j + dj)]))
                .fold(1.0f32, f32::min);
            let delta = 1.5 * cos_delta.clamp(-1.0, 1.0).acos();
            let theta = shaping.axis.dot(centre).clamp(-1.0, 1.0).acos();
            *w = shaping.bound_between((theta - delta).max(0.0), (theta + delta).min(PI));
        }
        ProfileGuide::new(w)
    }

    /// The shape numbers (u1, u2) with which [`Light::sample_shape`] from `p` picks direction
    /// `wi` (the inverse of its map; `None` where it never does).
    fn shape_numbers(&self, p: Vec3A, wi: Vec3A) -> Option<[f32; 2]> {
        let turn = |x: f32, y: f32| (y.atan2(x) / (2.0 * PI)).rem_euclid(1.0);
        match &self.shape {
            LightShape::Sphere { center, radius } => {
                let to_c = *center - p;
                let dc2 = to_c.length_squared();
                let sin2_max = radius * radius / dc2;
                let omc_max = sin2_max / (1.0 + (1.0 - sin2_max).max(0.0).sqrt());
                let axis = to_c / dc2.sqrt();
                let (t, b) = frame(axis);
                // 1 − cos θ without cancellation: |wi − axis|² / 2.
                let omc = 0.5 * (wi - axis).length_squared();
                Some([(omc / omc_max).clamp(0.0, 1.0), turn(wi.dot(t), wi.dot(b))])
            }
            LightShape::Rect { center, u, v, normal } | LightShape::Disk { center, u, v, normal } => {
                let cos_l = -normal.dot(wi);
                let t = normal.dot(p - *center) / cos_l;
                if !(t > 0.0 && t.is_finite()) {
                    return None;
                }
                let q = p + wi * t - *center;
                let (uu, uv, vv) = (u.dot(*u), u.dot(*v), v.dot(*v));
                let det = uu * vv - uv * uv;
                let (qu, qv) = (q.dot(*u), q.dot(*v));
                let a = (qu * vv - qv * uv) / det;
                let b = (qv * uu - qu * uv) / det;
                Some(match self.shape {
                    LightShape::Rect { .. } => [(0.5 * (a + 1.0)).clamp(0.0, 1.0), (0.5 * (b + 1.0)).clamp(0.0, 1.0)],
                    _ => [(a * a + b * b).clamp(0.0, 1.0), turn(a, b)],
                })
            }
            LightShape::Cylinder { center, axis, e1, e2, .. } => {
                let hit = self.intersect_cylinder(p, wi, f32::INFINITY)?;
                let q = p + wi * hit.t - *center;
                let half2 = axis.length_squared();
                let along = q.dot(*axis) / half2;
                let radial = q - *axis * along;
                Some([(0.5 * (along + 1.0)).clamp(0.0, 1.0), turn(radial.dot(*e1), radial.dot(*e2))])
            }
            _ => None,
        }
    }

    fn intersect_shape(&self, o: Vec3A, d: Vec3A, t_max: f32, time: f32) -> Option<LightHit> {
        match &self.shape {
            LightShape::Sphere { center, radius } => {
                let to_c = *center - o;
                let dc2 = to_c.length_squared();
                let r2 = radius * radius;
                if !(dc2 > r2) {
                    return None;
                }
                let b = d.dot(to_c);
                let h2 = dc2 - b * b;
                if b <= 0.0 || h2 > r2 {
                    return None;
                }
                let t = b - (r2 - h2).max(0.0).sqrt();
                let sin2_max = r2 / dc2;
                let omc_max = sin2_max / (1.0 + (1.0 - sin2_max).max(0.0).sqrt());
                (t > 0.0 && t < t_max).then(|| LightHit { t, radiance: self.radiance_scale, pdf: 1.0 / (2.0 * PI * omc_max) })
            }
            LightShape::Rect { .. } | LightShape::Disk { .. } => self.intersect_planar(o, d, t_max),
            LightShape::Cylinder { .. } => self.intersect_cylinder(o, d, t_max),
            LightShape::Mesh(_) => self.intersect_mesh(o, d, t_max, time),
            _ => None,
        }
    }

    /// The tube's outer wall where the ray from `o` along unit `d` first meets it, from outside:
    /// a ray entering through an open end sees only the inner side, which emits nothing. As the
    /// solid cylinder is convex, these are exactly the wall points [`Light::sample`] keeps.
    fn intersect_cylinder(&self, o: Vec3A, d: Vec3A, t_max: f32) -> Option<LightHit> {
        let LightShape::Cylinder { center, axis, radius, .. } = &self.shape else { return None };
        let half = axis.length();
        let a_hat = *axis / half;
        let oc = o - *center;
        let op = oc - a_hat * oc.dot(a_hat);
        let dp = d - a_hat * d.dot(a_hat);
        let a = dp.length_squared();
        let c = op.length_squared() - radius * radius;
        if !(a > 0.0 && c > 0.0 && half > 0.0) {
            return None;
        }
        let b = op.dot(dp);
        let disc = b * b - a * c;
        if !(disc >= 0.0) {
            return None;
        }
        // The near root, without cancellation.
        let t = c / (-b + disc.sqrt());
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        if (oc + d * t).dot(a_hat).abs() > half {
            return None;
        }
        let n = (op + dp * t) / *radius;
        let cos_l = -n.dot(d);
        if !(cos_l > 0.0) {
            return None;
        }
        Some(LightHit { t, radiance: self.radiance_scale, pdf: t * t / (cos_l * shape_area(&self.shape)) })
    }

    /// The mesh's nearest emitting side along the ray at shutter time `time`
    /// ([`TriangleLight::intersect_at`]), with the density of area sampling there.
    fn intersect_mesh(&self, o: Vec3A, d: Vec3A, t_max: f32, time: f32) -> Option<LightHit> {
        let LightShape::Mesh(m) = &self.shape else { return None };
        let h = m.intersect_at(o, d, t_max, time)?;
        Some(LightHit { t: h.t, radiance: self.radiance_scale * h.emission, pdf: h.t * h.t / (h.cos * h.area) })
    }

    fn intersect_planar(&self, o: Vec3A, d: Vec3A, t_max: f32) -> Option<LightHit> {
        let (LightShape::Rect { center, u, v, normal } | LightShape::Disk { center, u, v, normal }) = &self.shape else {
            return None;
        };
        let cos_l = -normal.dot(d);
        // Only the emitting side (the ray travels against the normal) sends light back.
        if !(cos_l > 0.0) {
            return None;
        }
        let t = normal.dot(o - *center) / cos_l;
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        let q = o + d * t - *center;
        // q = a·u + b·v in the light's plane (u and v need not be orthogonal).
        let (uu, uv, vv) = (u.dot(*u), u.dot(*v), v.dot(*v));
        let det = uu * vv - uv * uv;
        if !(det > 0.0) {
            return None;
        }
        let (qu, qv) = (q.dot(*u), q.dot(*v));
        let a = (qu * vv - qv * uv) / det;
        let b = (qv * uu - qu * uv) / det;
        let inside = match self.shape {
            LightShape::Rect { .. } => a.abs() <= 1.0 && b.abs() <= 1.0,
            _ => a * a + b * b <= 1.0,
        };
        if !inside {
            return None;
        }
        let area = shape_area(&self.shape);
        let mut radiance = self.radiance_scale;
        if let (Some(tex), LightShape::Rect { .. }) = (&self.texture, &self.shape) {
            radiance *= tex.radiance([0.5 * (a + 1.0), 0.5 * (b + 1.0)]);
        }
        Some(LightHit { t, radiance, pdf: t * t / (cos_l * area) })
    }

    /// Radiance arriving along unit `wi` from this light when a ray escapes the scene: a dome's,
    /// or a distant light's inside its cone; zero otherwise (a delta light is never met).
    pub fn environment(&self, wi: Vec3A) -> Vec3A {
        match &self.shape {
            LightShape::Dome(env) => self.radiance_scale * env.as_ref().map_or(Vec3A::ONE, |e| e.radiance(wi)),
            LightShape::Distant { direction, angle_deg } if *angle_deg > 0.0 => {
                if 1.0 - wi.dot(-*direction) <= one_minus_cos((0.5 * angle_deg).to_radians()) {
                    self.radiance_scale
                } else {
                    Vec3A::ZERO
                }
            }
            _ => Vec3A::ZERO,
        }
    }
}

impl Light {
    /// A dome's direction and its full density ([`Light::pdf`]): through a portal with
    /// probability Q, else by the dome's own strategy (see [`Portal`] for the mixture).
    fn sample_dome(&self, env: Option<&EnvTexture>, p: Vec3A, n: Vec3A, u1: f32, u2: f32) -> Option<(Vec3A, f32)> {
        if self.portals.is_empty() {
            return dome_sample(env, n, u1, u2);
        }
        let choice = portal::PortalChoice::at(&self.portals, p);
        let q = choice.fraction();
        let wi = if u1 < q {
            choice.sample(u1 / q, u2)?
        } else {
            // u1 rescaled over the dome's share; the portal branch may have q = 0.
            dome_sample(env, n, ((u1 - q) / (1.0 - q)).clamp(0.0, 1.0 - f32::EPSILON), u2)?.0
        };
        let pdf = self.pdf(p, n, wi);
        (pdf > 0.0).then_some((wi, pdf))
    }
}

/// A dome's own strategy: its importance table, or (uniform, or no table) cosine-weighted
/// about `n`. (direction, solid-angle density).
fn dome_sample(env: Option<&EnvTexture>, n: Vec3A, u1: f32, u2: f32) -> Option<(Vec3A, f32)> {
    if let Some(s) = env.and_then(|e| e.sample([u1, u2])) {
        return Some(s);
    }
    let (local, pdf) = cosine_hemisphere(u1, u2);
    let (t, b) = frame(n);
    Some((t * local.x + b * local.y + n * local.z, pdf))
}

/// The density of [`dome_sample`].
fn dome_pdf(env: Option<&EnvTexture>, n: Vec3A, wi: Vec3A) -> f32 {
    match env.filter(|e| e.distribution.is_some()) {
        Some(e) => e.pdf(wi),
        None => n.dot(wi).max(0.0) * std::f32::consts::FRAC_1_PI,
    }
}

impl Light {
    /// What the stats say of this light (`scene.lights`): its name, kind, whether it casts
    /// shadows, its shaping, and the meshes its light and shadow linking leave out, by the names
    /// `mesh_name` gives their indices (the scene's: [`crate::scene::Scene::meshes`]).
    pub fn describe<'a>(&self, mesh_name: &dyn Fn(u32) -> Option<&'a str>) -> serde_json::Value {
        let kind = match &self.shape {
            LightShape::Distant { .. } => "distant",
            LightShape::Sphere { .. } => "sphere",
            LightShape::Rect { .. } => "rect",
            LightShape::Disk { .. } => "disk",
            LightShape::Cylinder { .. } => "cylinder",
            LightShape::Dome(_) => "dome",
            LightShape::Mesh(_) => "mesh",
        };
        let names = |f: &MeshFilter| -> Vec<&str> { f.excluded().iter().filter_map(|&m| mesh_name(m)).collect() };
        let mut out = serde_json::json!({ "name": self.name, "kind": kind, "casts_shadows": self.casts_shadows });
        if !self.portals.is_empty() {
            out["portals"] = self
                .portals
                .iter()
                .map(|q| serde_json::json!({ "name": q.name, "area": q.area(), "normal": [q.normal.x, q.normal.y, q.normal.z] }))
                .collect();
            out["portal_fraction"] = serde_json::json!(PORTAL_FRACTION);
        }
        if let LightShape::Mesh(m) = &self.shape {
            out["triangles"] = serde_json::json!(m.len());
            out["area"] = serde_json::json!(m.area());
            out["two_sided"] = serde_json::json!(m.two_sided);
            out["moving"] = serde_json::json!(m.is_moving());
            // What it emits, a bound material's tint included (per face: its mean over the mesh).
            let r = self.radiance_scale * m.mean_emission();
            out["radiance"] = serde_json::json!([r.x, r.y, r.z]);
            out["per_face_emission"] = serde_json::json!(m.has_emission());
        }
        if let Some(s) = &self.shaping {
            out["shaping"] = serde_json::json!({
                "cone_angle_deg": s.cone.to_degrees(),
                "cone_softness": s.softness,
                "focus": s.focus,
                "focus_tint": [s.focus_tint.x, s.focus_tint.y, s.focus_tint.z],
            });
            if let Some(ies) = &s.ies {
                out["shaping"]["ies"] = serde_json::json!({
                    "file": ies.file,
                    "photometric_type": format!("{:?}", ies.profile.kind),
                    "angle_scale": ies.angle_scale,
                    "normalize": ies.normalize,
                    "mean_candela": ies.profile.mean(),
                    "profile_sampling": self.profile_sampling,
                    "peak_candela": ies.profile.peak(),
                });
                if let Some(t) = &ies.profile.tilt {
                    out["shaping"]["ies"]["tilt"] = serde_json::json!({
                        "geometry": t.geometry,
                        "angle_deg": ies.tilt.to_degrees(),
                        "factor": ies.tilt_factor(),
                    });
                }
            }
        }
        if !self.illuminates.is_all() {
            out["not_illuminating"] = serde_json::json!(names(&self.illuminates));
        }
        if !self.shadowed_by.is_all() {
            out["not_shadowed_by"] = serde_json::json!(names(&self.shadowed_by));
        }
        out
    }

    /// What a camera or mirror ray escaping along unit `wi` sees of this light, its
    /// directional spread (from its differential) `spread_rad`: a dome's texture filtered over
    /// that angle rather than over the importance table's texel ([`Light::environment`]), a
    /// distant light's disk. For rays no light sample could have found (no multiple importance
    /// sampling involved).
    pub fn seen(&self, wi: Vec3A, spread_rad: f32) -> Vec3A {
        match &self.shape {
            LightShape::Dome(Some(env)) => self.radiance_scale * env.radiance_filtered(wi, spread_rad),
            _ => self.environment(wi),
        }
    }
}

/// A guide's key: the light's profile (its address), the shaded point and the light's centre.
type GuideKey = (usize, [u32; 3], [u32; 3]);

thread_local! {
    /// The last [`ProfileGuide`] built on this thread, by its key.
    static GUIDE_CACHE: std::cell::RefCell<Option<(GuideKey, Option<ProfileGuide>)>> = const { std::cell::RefCell::new(None) };
}

/// Cells per side of a [`ProfileGuide`]'s grid.
const GUIDE_CELLS: usize = 4;

/// A light whose bounding radius is under this fraction of its distance from the shaded point
/// (about 1.7°) is sampled by shape alone: its profile hardly varies across it.
const GUIDE_MIN_SPREAD: f32 = 0.03;

/// The share of a [`ProfileGuide`]'s samples drawn uniformly (the shape's own density): a
/// defensive mixture, so the profile's directions are never much noisier than the shape's
/// (at most 1 / this times the variance) where the cells' weights misjudge a beam, and every
/// point stays choosable (no bias).
const GUIDE_UNIFORM: f32 = 0.2;

/// A piecewise-constant density over a light's two shape numbers (the unit square its own
/// sampling maps to points: area for rects, disks and cylinders, the subtended cone for
/// spheres), by what its IES profile (with cone and focus) sends toward the shaded point from
/// each cell's centre: the shape's numbers are drawn from it, and the shape's density is
/// multiplied by its density there, so directions the profile favours get more samples.
#[derive(Clone, Debug)]
struct ProfileGuide {
    /// Cumulative cell weights, row-major (i + GUIDE_CELLS · j), the last being the total.
    cdf: [f32; GUIDE_CELLS * GUIDE_CELLS],
    w: [f32; GUIDE_CELLS * GUIDE_CELLS],
}

impl ProfileGuide {
    /// `None` when the profile sends nothing from any cell centre, or the same from all (the
    /// shape's own density is then as good).
    fn new(mut w: [f32; GUIDE_CELLS * GUIDE_CELLS]) -> Option<ProfileGuide> {
        let n = w.len() as f32;
        let mean = w.iter().sum::<f32>() / n;
        let top = w.iter().copied().fold(0.0f32, f32::max);
        if !(mean > 0.0 && mean.is_finite()) || top <= 1.05 * w.iter().copied().fold(f32::INFINITY, f32::min) {
            return None;
        }
        for x in &mut w {
            *x = (1.0 - GUIDE_UNIFORM) * *x / mean + GUIDE_UNIFORM;
        }
        let mut cdf = w;
        for k in 1..cdf.len() {
            cdf[k] += cdf[k - 1];
        }
        Some(ProfileGuide { cdf, w })
    }

    /// The shape numbers for uniform (u1, u2), and the guide's density there.
    fn remap(&self, u1: f32, u2: f32) -> (f32, f32, f32) {
        let total = self.cdf[self.cdf.len() - 1];
        let x = u1 * total;
        let k = self.cdf.partition_point(|&c| c <= x).min(self.cdf.len() - 1);
        let before = if k == 0 { 0.0 } else { self.cdf[k - 1] };
        let frac = ((x - before) / self.w[k]).clamp(0.0, 1.0 - f32::EPSILON);
        let (i, j) = (k % GUIDE_CELLS, k / GUIDE_CELLS);
        let g = GUIDE_CELLS as f32;
        ((i as f32 + frac) / g, (j as f32 + u2) / g, self.w[k] * self.w.len() as f32 / total)
    }

    /// The density (relative to uniform) of shape numbers `u`.
    fn density(&self, u: [f32; 2]) -> f32 {
        let cell = |x: f32| ((x * GUIDE_CELLS as f32) as usize).min(GUIDE_CELLS - 1);
        let total = self.cdf[self.cdf.len() - 1];
        self.w[cell(u[0]) + GUIDE_CELLS * cell(u[1])] * self.w.len() as f32 / total
    }
}

/// A direction uniformly distributed over the cone around unit `axis` with 1 − cos(half-angle)
/// = `omc_max`, from two uniform numbers.
fn cone_direction(axis: Vec3A, omc_max: f32, u1: f32, u2: f32) -> Vec3A {
    // 1 − cos θ uniform in [0, omc_max]; sin θ from it without cancellation.
    let omc = u1 * omc_max;
    let cos_t = 1.0 - omc;
    let sin_t = (omc * (2.0 - omc)).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    let (t, b) = frame(axis);
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize()
}

/// Area of an area light's surface (render units²); 0 for distant and dome lights.
pub fn shape_area(shape: &LightShape) -> f32 {
    match shape {
        LightShape::Sphere { radius, .. } => 4.0 * PI * radius * radius,
        LightShape::Rect { u, v, .. } => 4.0 * u.cross(*v).length(),
        LightShape::Disk { u, v, .. } => PI * u.cross(*v).length(),
        LightShape::Cylinder { axis, radius, .. } => 2.0 * PI * radius * 2.0 * axis.length(),
        LightShape::Mesh(m) => m.area(),
        _ => 0.0,
    }
}

/// A uniformly distributed point on a rect, disk, cylinder or mesh light (a moving mesh posed at
/// shutter time `time`; a mesh whose triangles emit their own colours chooses them by power):
/// (point, emitting normal, area whose reciprocal is the point's density per unit area, what
/// the point emits as a factor of the light's radiance).
fn sample_planar(shape: &LightShape, u1: f32, u2: f32, time: f32) -> Option<(Vec3A, Vec3A, f32, Vec3A)> {
    let area = shape_area(shape);
    if !(area > 0.0) {
        return None;
    }
    match shape {
        LightShape::Rect { center, u, v, normal } => {
            Some((*center + *u * (2.0 * u1 - 1.0) + *v * (2.0 * u2 - 1.0), *normal, area, Vec3A::ONE))
        }
        LightShape::Cylinder { center, axis, radius, e1, e2 } => {
            let phi = 2.0 * PI * u2;
            let n = *e1 * phi.cos() + *e2 * phi.sin();
            Some((*center + *axis * (2.0 * u1 - 1.0) + n * *radius, n, area, Vec3A::ONE))
        }
        LightShape::Disk { center, u, v, normal } => {
            let r = u1.sqrt();
            let phi = 2.0 * PI * u2;
            Some((*center + *u * (r * phi.cos()) + *v * (r * phi.sin()), *normal, area, Vec3A::ONE))
        }
        LightShape::Mesh(m) => {
            let s = m.sample_at(u1, u2, time);
            Some((s.p, s.normal, s.area, s.emission))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    /// Monte Carlo irradiance at `p` (normal `n`) from `light`, no occlusion.
    fn irradiance(light: &Light, p: Vec3A, n: Vec3A, samples: u32) -> f32 {
        let mut s = Sampler::new(1, 2, 3);
        let mut e = 0.0f64;
        for _ in 0..samples {
            if let Some(ls) = light.sample(p, n, s.next_f32(), s.next_f32()) {
                e += f64::from(ls.weight().x * ls.wi.dot(n).max(0.0));
            }
        }
        (e / f64::from(samples)) as f32
    }

    #[test]
    fn sphere_light_irradiance_is_analytic() {
        // A sphere of radiance L, radius r, at distance d on the normal: E = π L (r/d)².
        let light =
            Light::usd_area("/s", LightShape::Sphere { center: Vec3A::new(0.0, 0.0, 4.0), radius: 0.5 }, 1.0, 0.0, Vec3A::ONE, false);
        let e = irradiance(&light, Vec3A::ZERO, Vec3A::Z, 200_000);
        let expected = PI * (0.5f32 / 4.0).powi(2);
        assert!((e - expected).abs() < 0.01 * expected, "{e} vs {expected}");
    }

    #[test]
    fn disk_light_irradiance_is_analytic_and_normalize_divides_by_area() {
        // A disk of radius r facing the point from height h: E = π L r² / (h² + r²).
        let down = Vec3A::NEG_Z;
        let shape = LightShape::Disk { center: Vec3A::new(0.0, 0.0, 2.0), u: Vec3A::X, v: Vec3A::Y, normal: down };
        let light = Light::usd_area("/d", shape.clone(), 1.0, 0.0, Vec3A::ONE, false);
        let e = irradiance(&light, Vec3A::ZERO, Vec3A::Z, 200_000);
        let expected = PI / (4.0 + 1.0);
        assert!((e - expected).abs() < 0.02 * expected, "{e} vs {expected}");
        let normalized = Light::usd_area("/d", shape, 1.0, 0.0, Vec3A::ONE, true);
        assert!((normalized.radiance_scale.x - 1.0 / PI).abs() < 1e-6);
        // Behind the disk nothing arrives.
        assert_eq!(irradiance(&light, Vec3A::new(0.0, 0.0, 4.0), Vec3A::NEG_Z, 1000), 0.0);
    }

    /// Lambert's exact irradiance at `p` (normal `n`) from a polygon of uniform radiance 1
    /// (vertices in order): E = ½ Σ θᵢ (n · γᵢ), θᵢ the angle each edge subtends, γᵢ the unit
    /// normal of the plane through p and the edge.
    fn lambert_polygon(poly: &[Vec3A], p: Vec3A, n: Vec3A) -> f32 {
        let mut e = 0.0f64;
        for i in 0..poly.len() {
            let (a, b) = ((poly[i] - p).normalize(), (poly[(i + 1) % poly.len()] - p).normalize());
            let theta = f64::from(a.dot(b).clamp(-1.0, 1.0)).acos();
            e += theta * f64::from(n.dot(a.cross(b).normalize()));
        }
        (0.5 * e).abs() as f32
    }

    #[test]
    fn a_moving_mesh_light_gives_the_time_average_of_lamberts_irradiance() {
        use crate::motion::{MotionKey, MotionTransform};
        // A unit square facing down (its object-space normal −Z), carried from x = −1.5 at
        // height 2 to x = +1 at height 2.5 and grown to 1.6 × 0.7 over the shutter: translation,
        // and a scale that deforms it unevenly in x and y (the density then follows the pose).
        let square = [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)].map(|(x, y)| Vec3A::new(x, y, 0.0));
        // Clockwise seen from +Z: the right-hand normal is −Z.
        let tris = vec![[square[0], square[2], square[1]], [square[0], square[3], square[2]]];
        let key = |t: f32, x: f32, z: f32, s: glam::Vec3| MotionKey {
            time: t,
            render_from_object: Mat4::from_translation(glam::Vec3::new(x, 0.0, z)) * Mat4::from_scale(s),
        };
        let motion =
            MotionTransform::new(vec![key(0.0, -1.5, 2.0, glam::Vec3::ONE), key(1.0, 1.0, 2.5, glam::Vec3::new(1.6, 0.7, 1.0))]).unwrap();
        let mesh = TriangleLight::moving(tris, false, motion.clone()).unwrap();
        assert!((mesh.area() - 1.0).abs() < 1e-5 && (mesh.max_area() - 1.12).abs() < 1e-4);
        let b = mesh.bounds();
        assert!(b.min.x <= -2.0 + 1e-4 && b.max.x >= 1.8 - 1e-4 && b.min.z <= 2.0 && b.max.z >= 2.5);
        let light = Light::usd_area("/m", LightShape::Mesh(mesh), 1.0, 0.0, Vec3A::ONE, false);
        let (p, n) = (Vec3A::new(0.2, 0.1, 0.0), Vec3A::Z);
        // Truth: Lambert's formula at each pose, averaged over the shutter (midpoint rule).
        let steps = 2000;
        let truth = (0..steps)
            .map(|k| {
                let x = motion.at((k as f32 + 0.5) / steps as f32);
                let outline: Vec<Vec3A> = [square[0], square[3], square[2], square[1]].iter().map(|&q| x.transform_point3a(q)).collect();
                f64::from(lambert_polygon(&outline, p, n))
            })
            .sum::<f64>() as f32
            / steps as f32;
        // Monte Carlo with a shutter time per sample, as the render loop gives rays.
        let mut s = Sampler::new(5, 6, 7);
        let (mut e, samples) = (0.0f64, 400_000);
        for _ in 0..samples {
            let time = s.next_f32();
            if let Some(ls) = light.sample_at(p, n, s.next_f32(), s.next_f32(), time) {
                e += f64::from(ls.weight().x * ls.wi.dot(n).max(0.0));
                // BSDF sampling's rays meet the posed light with the same density and distance.
                let pdf = light.pdf_at(p, n, ls.wi, time);
                assert!((pdf - ls.pdf).abs() < 1e-3 * ls.pdf, "{pdf} vs {}", ls.pdf);
                let hit = light.intersect_at(p, ls.wi, f32::INFINITY, time).unwrap();
                assert!((hit.t - ls.distance).abs() < 1e-4 * ls.distance, "{} vs {}", hit.t, ls.distance);
            }
        }
        let e = (e / f64::from(samples)) as f32;
        assert!((e - truth).abs() < 0.01 * truth, "{e} vs {truth}");
        // Not the light frozen at the shutter's open: the test can tell.
        let frozen = irradiance(&light, p, n, 100_000);
        assert!((frozen - truth).abs() > 0.1 * truth, "{frozen} vs {truth}");
        // A mirroring pose keeps the emitting side: the square still lights the floor below.
        let mirror = MotionTransform::new(vec![
            MotionKey {
                time: 0.0,
                render_from_object: Mat4::from_translation(glam::Vec3::new(0.0, 0.0, 2.0))
                    * Mat4::from_scale(glam::Vec3::new(-1.0, 1.0, 1.0)),
            },
            MotionKey {
                time: 1.0,
                render_from_object: Mat4::from_translation(glam::Vec3::new(0.0, 0.1, 2.0))
                    * Mat4::from_scale(glam::Vec3::new(-1.0, 1.0, 1.0)),
            },
        ])
        .unwrap();
        let tris = vec![[square[0], square[2], square[1]], [square[0], square[3], square[2]]];
        let mirrored =
            Light::usd_area("/m", LightShape::Mesh(TriangleLight::moving(tris, false, mirror).unwrap()), 1.0, 0.0, Vec3A::ONE, false);
        let ls = mirrored.sample_at(Vec3A::ZERO, Vec3A::Z, 0.3, 0.6, 0.5).unwrap();
        assert!(ls.wi.z > 0.0 && mirrored.intersect_at(Vec3A::ZERO, Vec3A::Z, f32::INFINITY, 0.5).is_some());
        assert!(mirrored.intersect_at(Vec3A::new(0.0, 0.0, 4.0), Vec3A::NEG_Z, f32::INFINITY, 0.5).is_none());
    }

    #[test]
    fn mesh_light_irradiance_is_lamberts_and_its_density_is_consistent() {
        // A non-convex L-shaped polygon, tilted, facing the origin, fan-triangulated from a
        // vertex of the concave corner's neighbour so every triangle lies inside it.
        let tilt = Mat4::from_rotation_x(0.4) * Mat4::from_translation(glam::Vec3::new(0.3, -0.2, 2.0));
        let outline: Vec<Vec3A> = [(0.0, 0.0), (0.0, 2.0), (1.0, 2.0), (1.0, 1.0), (2.0, 1.0), (2.0, 0.0)]
            .iter()
            .map(|&(x, y)| tilt.transform_point3a(Vec3A::new(x - 1.0, y - 1.0, 0.0)))
            .collect();
        // Triangles (0,1,2), (0,2,3), (0,3,4), (0,4,5) cover the L; the outline runs clockwise
        // seen from +Z, so they face −Z's image, toward the origin.
        let tris: Vec<[Vec3A; 3]> = (1..5).map(|i| [outline[0], outline[i], outline[i + 1]]).collect();
        let mesh = TriangleLight::new(tris, false).unwrap();
        assert!((mesh.area() - 3.0).abs() < 1e-5);
        let light = Light::usd_area("/m", LightShape::Mesh(mesh.clone()), 1.0, 0.0, Vec3A::ONE, false);
        for (p, n) in [(Vec3A::ZERO, Vec3A::Z), (Vec3A::new(0.5, 0.3, 0.2), Vec3A::new(0.3, 0.1, 1.0).normalize())] {
            let e = irradiance(&light, p, n, 400_000);
            let expected = lambert_polygon(&outline, p, n);
            assert!((e - expected).abs() < 0.01 * expected, "{e} vs {expected} at {p}");
        }
        // What light sampling picks, BSDF sampling's rays meet with the same density.
        let mut s = Sampler::new(3, 1, 4);
        for _ in 0..200 {
            let ls = light.sample(Vec3A::ZERO, Vec3A::Z, s.next_f32(), s.next_f32()).unwrap();
            let pdf = light.pdf(Vec3A::ZERO, Vec3A::Z, ls.wi);
            assert!((pdf - ls.pdf).abs() < 1e-3 * ls.pdf, "{pdf} vs {}", ls.pdf);
            let hit = light.intersect(Vec3A::ZERO, ls.wi, f32::INFINITY).unwrap();
            assert!((hit.t - ls.distance).abs() < 1e-4 && hit.radiance == ls.radiance);
        }
        // Behind it nothing arrives; normalize divides by the area.
        assert_eq!(irradiance(&light, Vec3A::new(0.0, 0.0, 6.0), Vec3A::NEG_Z, 1000), 0.0);
        let normalized = Light::usd_area("/m", LightShape::Mesh(mesh), 1.0, 0.0, Vec3A::ONE, true);
        assert!((normalized.radiance_scale.x - 1.0 / 3.0).abs() < 1e-6);
    }

    /// Monte Carlo RGB irradiance at `p` (normal `n`) from `light`, no occlusion; also checks
    /// that every sample's direction is met by BSDF rays with the same density and radiance.
    fn irradiance_rgb(light: &Light, p: Vec3A, n: Vec3A, samples: u32, time: f32) -> Vec3A {
        let mut s = Sampler::new(11, 2, 9);
        let mut e = [0.0f64; 3];
        for k in 0..samples {
            if let Some(ls) = light.sample_at(p, n, s.next_f32(), s.next_f32(), time) {
                let w = ls.weight() * ls.wi.dot(n).max(0.0);
                for c in 0..3 {
                    e[c] += f64::from(w[c]);
                }
                if k % 64 == 0 {
                    let pdf = light.pdf_at(p, n, ls.wi, time);
                    assert!((pdf - ls.pdf).abs() < 1e-3 * ls.pdf, "{pdf} vs {}", ls.pdf);
                    let hit = light.intersect_at(p, ls.wi, f32::INFINITY, time).unwrap();
                    assert!((hit.radiance - ls.radiance).abs().max_element() <= 1e-5 * ls.radiance.max_element().max(1.0));
                }
            }
        }
        Vec3A::from(e.map(|x| (x / f64::from(samples)) as f32))
    }

    /// The square [−1, 1]² at height 2 facing down, as two triangles per half (x < 0, x > 0),
    /// and its halves' outlines (for Lambert's formula).
    fn halved_square() -> (Vec<[Vec3A; 3]>, [[Vec3A; 4]; 2]) {
        let p = |x: f32, y: f32| Vec3A::new(x, y, 2.0);
        let half = |x0: f32, x1: f32| [p(x0, -1.0), p(x1, -1.0), p(x1, 1.0), p(x0, 1.0)];
        let (l, r) = (half(-1.0, 0.0), half(0.0, 1.0));
        // Clockwise seen from +Z: the right-hand normal is −Z, toward the floor.
        let tris = [l, r].iter().flat_map(|q| [[q[0], q[2], q[1]], [q[0], q[3], q[2]]]).collect();
        (tris, [l, r])
    }

    #[test]
    fn a_mesh_lights_faces_emit_their_own_materials_colours() {
        // GeomSubsets: the left half emits (1, 0.2, 0), the right (0, 0.5, 2); the estimate at
        // points mostly under one half is the exact sum of each half's Lambert irradiance times
        // its colour, channel by channel.
        let (tris, halves) = halved_square();
        let (cl, cr) = (Vec3A::new(1.0, 0.2, 0.0), Vec3A::new(0.0, 0.5, 2.0));
        let emission =
            MeshEmission { emitters: vec![Emitter::Color(cl), Emitter::Color(cr)], per_triangle: vec![0, 0, 1, 1], st: Vec::new() };
        let mesh = TriangleLight::with_emission(tris.clone(), false, None, emission.clone()).unwrap();
        assert!((mesh.mean_emission() - 0.5 * (cl + cr)).length() < 1e-6);
        let light = Light::usd_area("/m", LightShape::Mesh(mesh.clone()), 1.5, 0.0, Vec3A::ONE, false);
        for p in [Vec3A::new(-0.7, 0.2, 0.0), Vec3A::new(0.8, -0.3, 0.0)] {
            let exact = (cl * lambert_polygon(&halves[0], p, Vec3A::Z) + cr * lambert_polygon(&halves[1], p, Vec3A::Z)) * 1.5;
            let e = irradiance_rgb(&light, p, Vec3A::Z, 400_000, 0.0);
            for c in 0..3 {
                assert!((e[c] - exact[c]).abs() <= 0.01 * exact.max_element(), "channel {c}: {e} vs {exact} at {p}");
            }
            // Not the mesh's one colour (their mean) everywhere: the test can tell.
            let mean = 0.5 * (cl + cr) * (lambert_polygon(&halves[0], p, Vec3A::Z) + lambert_polygon(&halves[1], p, Vec3A::Z)) * 1.5;
            assert!((mean - exact).abs().max_element() > 0.1 * exact.max_element());
        }
        // Chosen by power: the right half (channel mean 5/6 against 2/5) gets 25/37 of samples;
        // a face that emits nothing gets none.
        let right = (0..10_000).filter(|k| mesh.sample(((*k as f32) + 0.5) / 1e4, 0.5).0.x > 0.0).count();
        assert!((right as f32 / 1e4 - 25.0 / 37.0).abs() < 2e-3, "{right}");
        let dark = MeshEmission { emitters: vec![Emitter::Color(cl), Emitter::Color(Vec3A::ZERO)], ..emission.clone() };
        let dark = TriangleLight::with_emission(tris.clone(), false, None, dark).unwrap();
        assert!((0..1000).all(|k| dark.sample((k as f32 + 0.5) / 1e3, 0.3).0.x < 0.0));
        // Moving: the same per-face densities, posed.
        use crate::motion::{MotionKey, MotionTransform};
        let key = |t: f32, x: f32| MotionKey { time: t, render_from_object: Mat4::from_translation(glam::Vec3::new(x, 0.0, 0.0)) };
        let motion = MotionTransform::new(vec![key(0.0, 0.0), key(1.0, 1.0)]).unwrap();
        let moving = TriangleLight::with_emission(tris, false, Some(motion), emission).unwrap();
        let light = Light::usd_area("/m", LightShape::Mesh(moving), 1.5, 0.0, Vec3A::ONE, false);
        let p = Vec3A::new(0.3, 0.2, 0.0);
        let shifted = halves.map(|q| q.map(|v| v + Vec3A::new(0.5, 0.0, 0.0)));
        let exact = (cl * lambert_polygon(&shifted[0], p, Vec3A::Z) + cr * lambert_polygon(&shifted[1], p, Vec3A::Z)) * 1.5;
        let e = irradiance_rgb(&light, p, Vec3A::Z, 200_000, 0.5);
        assert!((e - exact).abs().max_element() <= 0.01 * exact.max_element(), "{e} vs {exact}");
    }

    /// A texture whose texels are `left` where s < 0.5 and `right` elsewhere; a footprint of
    /// the whole image reads their mean.
    struct Split {
        left: [f32; 3],
        right: [f32; 3],
    }

    impl crate::texture::TextureSampler for Split {
        fn handle(&self, _path: &str) -> Result<crate::texture::TextureHandle, crate::texture::TextureError> {
            Ok(crate::texture::TextureHandle::new(0))
        }
        fn sample(
            &self,
            _h: crate::texture::TextureHandle,
            st: [f32; 2],
            dx: [f32; 2],
            _dy: [f32; 2],
            _lookup: &crate::texture::Lookup,
            out: &mut [f32],
        ) -> bool {
            for (c, o) in out.iter_mut().enumerate() {
                *o = if dx[0] >= 1.0 {
                    0.5 * (self.left[c] + self.right[c])
                } else if st[0] < 0.5 {
                    self.left[c]
                } else {
                    self.right[c]
                };
            }
            true
        }
        fn resolution(&self, _h: crate::texture::TextureHandle) -> Option<[u32; 2]> {
            Some([64, 64])
        }
        fn filter_mode(&self) -> crate::texture::FilterMode {
            crate::texture::FilterMode::Differentials
        }
        fn stats(&self) -> serde_json::Value {
            serde_json::json!({})
        }
    }

    #[test]
    fn a_textured_mesh_light_emits_its_texture_at_each_points_st() {
        // One emissiveColor texture over the whole square (s = (x + 1)/2): (1, 0.2, 0) where
        // x < 0, (0, 0.3, 1) where x > 0, times scale 2 plus bias 0.1. The texture's edge
        // crosses no triangle here, so also try a mesh whose two triangles it cuts diagonally.
        let (left, right) = ([1.0, 0.2, 0.0], [0.0, 0.3, 1.0]);
        let tex = crate::material::TexturedColor {
            sampler: std::sync::Arc::new(Split { left, right }),
            texture: crate::texture::TextureHandle::new(0),
            path: "split.png".into(),
            lookup: crate::texture::Lookup::DEFAULT,
            scale: Vec3A::splat(2.0),
            bias: Vec3A::splat(0.1),
            fallback: Vec3A::ZERO,
            st_channel: 0,
        };
        let (cl, cr) = (Vec3A::from(left) * 2.0 + 0.1, Vec3A::from(right) * 2.0 + 0.1);
        let (halved, halves) = halved_square();
        let p = |x: f32, y: f32| Vec3A::new(x, y, 2.0);
        let whole = vec![[p(-1.0, -1.0), p(1.0, 1.0), p(1.0, -1.0)], [p(-1.0, -1.0), p(-1.0, 1.0), p(1.0, 1.0)]];
        let st_of = |t: &[Vec3A; 3]| t.map(|v| [0.5 * (v.x + 1.0), 0.5 * (v.y + 1.0)]);
        for tris in [halved, whole] {
            let emission = MeshEmission {
                emitters: vec![Emitter::Texture(tex.clone())],
                per_triangle: vec![0; tris.len()],
                st: tris.iter().map(st_of).collect(),
            };
            let mesh = TriangleLight::with_emission(tris, false, None, emission).unwrap();
            assert!((mesh.mean_emission() - 0.5 * (cl + cr)).length() < 1e-5);
            let light = Light::usd_area("/t", LightShape::Mesh(mesh), 1.0, 0.0, Vec3A::ONE, false);
            for q in [Vec3A::new(-0.6, 0.1, 0.0), Vec3A::new(0.7, -0.4, 0.0)] {
                let exact = cl * lambert_polygon(&halves[0], q, Vec3A::Z) + cr * lambert_polygon(&halves[1], q, Vec3A::Z);
                let e = irradiance_rgb(&light, q, Vec3A::Z, 400_000, 0.0);
                assert!((e - exact).abs().max_element() <= 0.01 * exact.max_element(), "{e} vs {exact} at {q}");
            }
        }
    }

    /// A type C beam about the light's −Z: 100 cd to 10° off the axis, falling linearly to 0
    /// at 20°, nothing beyond.
    fn beam_shaping(axis: Vec3A) -> Shaping {
        let text = "TILT=NONE\n1 -1 1 10 1 1 2 0 0 0\n1 1 10\n0 10 20 30 40 50 60 70 80 90\n0\n100 100 0 0 0 0 0 0 0 0\n";
        let profile = IesProfile::parse(text).unwrap();
        let ies = IesShaping { profile, file: "beam.ies".into(), angle_scale: 0.0, normalize: false, x: Vec3A::X, y: Vec3A::Y, tilt: 0.0 };
        Shaping::with_ies(None, axis, ies)
    }

    #[test]
    fn an_ies_lights_directions_follow_its_profile_same_mean_less_noise() {
        // A 2 × 2 rect 0.5 above the floor, facing down, with a 10–20° beam: from a floor point
        // only the patch of rect within ~20° of straight up sends light, a small part of it.
        let rect = LightShape::Rect { center: Vec3A::new(0.0, 0.0, 0.5), u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z };
        let mut light = Light::usd_area("/beam", rect, 1.0, 0.0, Vec3A::ONE, false);
        light.shaping = Some(beam_shaping(Vec3A::NEG_Z));
        light.profile_sampling = true;
        let shaping = light.shaping.clone().unwrap();
        for p in [Vec3A::new(0.3, 0.2, 0.0), Vec3A::new(-0.85, 0.6, 0.0)] {
            let n = Vec3A::Z;
            // Truth by quadrature over the rect: ∫ f(ω) cos θl cos θp / d² dA.
            let m = 1000;
            let mut truth = 0.0f64;
            for i in 0..m {
                for j in 0..m {
                    let y = Vec3A::new(-1.0 + 2.0 * (i as f32 + 0.5) / m as f32, -1.0 + 2.0 * (j as f32 + 0.5) / m as f32, 0.5);
                    let d = p - y;
                    let d2 = d.length_squared();
                    let w = d / d2.sqrt();
                    truth += f64::from(shaping.factor(w).x * w.z * w.z / d2);
                }
            }
            let truth = truth * 4.0 / f64::from(m * m);
            // The estimate and its variance, by the profile's directions and by area alone.
            let samples = 500_000;
            let mut s = Sampler::new(4, 4, 2);
            let (mut sum, mut sum2, mut area_sum, mut area_sum2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for k in 0..samples {
                let (u1, u2) = (s.next_f32(), s.next_f32());
                if let Some(ls) = light.sample(p, n, u1, u2) {
                    let e = f64::from(ls.weight().x * ls.wi.dot(n).max(0.0));
                    sum += e;
                    sum2 += e * e;
                    if k % 97 == 0 {
                        let pdf = light.pdf(p, n, ls.wi);
                        assert!((pdf - ls.pdf).abs() < 1e-3 * ls.pdf, "{pdf} vs {}", ls.pdf);
                        let hit = light.intersect(p, ls.wi, f32::INFINITY).unwrap();
                        assert!((hit.pdf - ls.pdf).abs() < 1e-3 * ls.pdf, "{} vs {}", hit.pdf, ls.pdf);
                    }
                }
                // What mipray did before: the rect by area.
                let y = Vec3A::new(2.0 * u1 - 1.0, 2.0 * u2 - 1.0, 0.5);
                let d = p - y;
                let d2 = d.length_squared();
                let w = d / d2.sqrt();
                let e = f64::from(shaping.factor(w).x * w.z * w.z / d2 * 4.0);
                area_sum += e;
                area_sum2 += e * e;
            }
            let n_s = f64::from(samples);
            let (mean, var) = (sum / n_s, sum2 / n_s - (sum / n_s).powi(2));
            let (area_mean, area_var) = (area_sum / n_s, area_sum2 / n_s - (area_sum / n_s).powi(2));
            // Each within four standard errors (plus the quadrature's own 0.2%).
            for (m, v) in [(mean, var), (area_mean, area_var)] {
                let tol = 4.0 * (v / n_s).sqrt() + 0.002 * truth;
                assert!(
                    (m - truth).abs() < tol,
                    "{m} vs quadrature {truth} at {p} (guided {mean} var {var}, area {area_mean} var {area_var})"
                );
            }
            // Measured: 3.1× and 2.3× less variance at these two points.
            assert!(var < 0.5 * area_var, "variance {var} by profile, {area_var} by area at {p}");
        }
        // Every guided shape: what sampling picks, pdf and BSDF rays give the same density.
        let shapes = [
            LightShape::Sphere { center: Vec3A::new(0.2, 0.0, 0.6), radius: 0.4 },
            LightShape::Disk { center: Vec3A::new(0.0, 0.1, 0.5), u: Vec3A::X, v: Vec3A::Y * 0.7, normal: Vec3A::NEG_Z },
            LightShape::Cylinder { center: Vec3A::new(0.0, 0.0, 0.6), axis: Vec3A::X, radius: 0.3, e1: Vec3A::Y, e2: Vec3A::Z },
        ];
        for shape in shapes {
            let mut light = Light::usd_area("/g", shape.clone(), 1.0, 0.0, Vec3A::ONE, false);
            light.shaping = Some(beam_shaping(Vec3A::NEG_Z));
            light.profile_sampling = true;
            // A point the profile's guide applies at (under the disk's centre every cell can
            // send the beam's peak: no guide).
            let p = [Vec3A::new(0.1, 0.05, 0.0), Vec3A::new(0.7, 0.3, 0.0), Vec3A::new(-0.5, -0.6, 0.0)]
                .into_iter()
                .find(|&p| light.profile_guide(p).is_some())
                .unwrap_or_else(|| panic!("no guide for {shape:?}"));
            let mut s = Sampler::new(8, 1, 1);
            let mut met = 0;
            for _ in 0..4000 {
                let Some(ls) = light.sample(p, Vec3A::Z, s.next_f32(), s.next_f32()) else { continue };
                let pdf = light.pdf(p, Vec3A::Z, ls.wi);
                assert!((pdf - ls.pdf).abs() < 2e-3 * ls.pdf, "{pdf} vs {} for {shape:?}", ls.pdf);
                if let Some(hit) = light.intersect(p, ls.wi, f32::INFINITY) {
                    assert!((hit.pdf - ls.pdf).abs() < 2e-3 * ls.pdf, "{} vs {} for {shape:?}", hit.pdf, ls.pdf);
                    met += 1;
                }
            }
            assert!(met > 50, "{met} for {shape:?}");
        }
    }

    /// A uniform dome guided by a portal over a window in the ceiling of a closed room: (mean,
    /// variance) of the one-sample irradiance estimate at `p` (normal +Z) of the light
    /// arriving through the window (every other direction is blocked by the room).
    fn window_irradiance(dome: &Light, window: &Portal, p: Vec3A, samples: u32) -> (f64, f64) {
        let mut s = Sampler::new(7, 5, 3);
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..samples {
            let mut e = 0.0f64;
            if let Some(ls) = dome.sample(p, Vec3A::Z, s.next_f32(), s.next_f32()) {
                // What the estimator reports must be what `pdf` says of the same direction.
                let pdf = dome.pdf(p, Vec3A::Z, ls.wi);
                assert!((pdf - ls.pdf).abs() <= 1e-4 * ls.pdf, "{pdf} vs {}", ls.pdf);
                if window.pdf(p, ls.wi) > 0.0 {
                    e = f64::from(ls.weight().x * ls.wi.dot(Vec3A::Z).max(0.0));
                }
            }
            sum += e;
            sum2 += e * e;
        }
        let n = f64::from(samples);
        (sum / n, sum2 / n - (sum / n).powi(2))
    }

    #[test]
    fn portals_guide_a_dome_without_changing_what_it_delivers() {
        // A 1 × 0.6 window in a ceiling at height 2, light passing down (−Z) into the room.
        let window = Portal {
            name: "/Window".into(),
            center: Vec3A::new(0.3, -0.2, 2.0),
            u: Vec3A::new(0.5, 0.0, 0.0),
            v: Vec3A::new(0.0, 0.3, 0.0),
            normal: Vec3A::NEG_Z,
        };
        let plain = Light::usd_area("/Sky", LightShape::Dome(None), 1.0, 0.0, Vec3A::ONE, false);
        let mut guided = plain.clone();
        guided.portals = vec![window.clone()].into();
        let p = Vec3A::new(-0.4, 0.5, 0.0);
        let c = window.center;
        let (u, v) = (window.u, window.v);
        let exact = f64::from(lambert_polygon(&[c - u - v, c + u - v, c + u + v, c - u + v], p, Vec3A::Z));
        let (plain_mean, plain_var) = window_irradiance(&plain, &window, p, 400_000);
        let (mean, var) = window_irradiance(&guided, &window, p, 400_000);
        for m in [plain_mean, mean] {
            assert!((m - exact).abs() < 0.02 * exact, "{m} vs Lambert's {exact}");
        }
        // Most samples now pass through the window: far less noise for the same count.
        assert!(var < 0.2 * plain_var, "variance {var} with the portal, {plain_var} without");
        // Unoccluded, the dome still delivers π: the mixture keeps every direction.
        let e = irradiance(&guided, p, Vec3A::Z, 400_000);
        assert!((e - PI).abs() < 0.01 * PI, "{e}");
        // Above the window (behind the portal) the dome is sampled as without one.
        let above = Vec3A::new(0.0, 0.0, 3.0);
        assert_eq!(guided.pdf(above, Vec3A::Z, Vec3A::Z), plain.pdf(above, Vec3A::Z, Vec3A::Z));
        assert_eq!(guided.describe(&|_| None)["portals"][0]["name"], "/Window");
        // Two portals, a wall window (passing light along +X) overlapping the ceiling one's
        // directions from some points and facing away from others: chosen by weight, their
        // densities add, and the estimate stays Lambert's and the dome's.
        let side = Portal {
            name: "/Side".into(),
            center: Vec3A::new(-1.5, 0.0, 1.5),
            u: Vec3A::new(0.0, 0.6, 0.0),
            v: Vec3A::new(0.0, 0.0, 0.8),
            normal: Vec3A::X,
        };
        let mut both = plain.clone();
        both.portals = vec![window.clone(), side].into();
        for q in [p, Vec3A::new(-2.0, 0.0, 0.5)] {
            let exact = f64::from(lambert_polygon(&[c - u - v, c + u - v, c + u + v, c - u + v], q, Vec3A::Z));
            let (m, _) = window_irradiance(&both, &window, q, 400_000);
            assert!((m - exact).abs() < 0.02 * exact, "{m} vs Lambert's {exact} at {q}");
            let e = irradiance(&both, q, Vec3A::Z, 400_000);
            assert!((e - PI).abs() < 0.01 * PI, "{e} at {q}");
        }
    }

    #[test]
    fn dome_and_distant_cone_deliver_their_irradiance() {
        let dome = Light::usd_area("/dome", LightShape::Dome(None), 1.0, 0.0, Vec3A::ONE, false);
        let e = irradiance(&dome, Vec3A::ZERO, Vec3A::Z, 100_000);
        assert!((e - PI).abs() < 1e-4, "{e}");
        // Normalized: the intensity is the irradiance facing the light, whatever the angle.
        let sun = Light::usd_distant("/sun", &Mat4::IDENTITY, 2.0, 0.0, Vec3A::ONE, 10.0, true);
        let e = irradiance(&sun, Vec3A::ZERO, Vec3A::Z, 100_000);
        assert!((e - 2.0).abs() < 2e-3, "{e}");
        assert!((sun.distant_irradiance().x - 2.0).abs() < 1e-5);
        // Not normalized: the intensity is the disk's radiance, E = L π sin²(5°).
        let raw = Light::usd_distant("/sun", &Mat4::IDENTITY, 2.0, 0.0, Vec3A::ONE, 10.0, false);
        let e = irradiance(&raw, Vec3A::ZERO, Vec3A::Z, 100_000);
        let expected = 2.0 * PI * 5f32.to_radians().sin().powi(2);
        assert!((e - expected).abs() < 1e-3 * expected, "{e} vs {expected}");
        assert!(!sun.is_delta() && Light::distant("/p", Vec3A::NEG_Z, Vec3A::ONE).is_delta());
        // A point at infinity: the intensity is the irradiance, normalized or not.
        let point = Light::usd_distant("/pt", &Mat4::IDENTITY, 3.0, 1.0, Vec3A::ONE, 0.0, false);
        assert!(point.is_delta() && (point.radiance_scale.x - 6.0).abs() < 1e-6);
    }
}
