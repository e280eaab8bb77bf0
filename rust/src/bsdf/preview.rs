//! UsdPreviewSurface's BSDF (<https://openusd.org/release/spec_usdpreviewsurface.html>, with
//! hdStorm's `previewSurface.glslfx` as the reference for what the inputs mean).
//!
//! **The model.** A mixture of three bases under an optional clearcoat:
//!
//! - *metal*, weight `metallic` (metallic workflow only): a GGX reflector whose Fresnel has
//!   `F0 = diffuseColor`;
//! - *plastic*, weight `(1 − metallic) · opacity`: a GGX reflector with the dielectric Fresnel
//!   (`F0 = ((1 − ior)/(1 + ior))²` in the metallic workflow, `specularColor` in the specular
//!   workflow) over a lambertian base of `diffuseColor`;
//! - *glass*, weight `(1 − metallic) · (1 − opacity)` when `opacityThreshold` is 0: a dielectric
//!   interface of index `ior` that reflects with the same Fresnel (total internal reflection
//!   included) and refracts the rest (Walter et al. 2007's microfacet BTDF).
//!
//! Because Schlick's Fresnel is linear in `F0`, the three reflections share one GGX lobe whose
//! Fresnel is the weighted sum: outside a transmitting surface it is exactly the specification's
//! `F0 = lerp(((1 − ior)/(1 + ior))², diffuseColor, metallic)`, and the diffuse is scaled by
//! `(1 − metallic)` as the specification says (and by `opacity`, as Storm premultiplies it).
//!
//! **Fresnel.** Schlick's, from `F0` to `F90` at grazing, where `F90 = clamp(50 · max(F0), 0, 1)`:
//! white for any real dielectric or metal (`F0 ≥ 0.02`, e.g. 0.04 for ior 1.5), but 0 for a
//! specular colour of 0. That rule (Unreal Engine's, for "pre-baked specular occlusion") is the
//! one departure from "Schlick to white at grazing": without it a specular-workflow surface with
//! `specularColor = 0` — [`crate::material::Material::lambertian`], every display-colour mesh —
//! would grow a grazing highlight, and `ior = 1` would still reflect.
//!
//! **Microfacets.** GGX with `α = roughness²`, Smith's height-correlated `G2`, directions
//! sampled from the distribution of visible normals (Heitz 2018); see [`super::microfacet`].
//! Below `roughness` [`DELTA_ROUGHNESS`] a lobe is a delta: the specular lobe the mirror, the
//! glass the smooth dielectric (reflection and refraction chosen by Fresnel), and the coat a
//! mirror coat. A glass of `ior` ≈ 1 is a delta pass-through at any roughness (a rough
//! interface between equal indices bends nothing).
//!
//! **Energy conservation (directional albedo ≤ 1 for every input).** Each base conserves energy
//! on its own, so their convex mixture does:
//! - the GGX lobes are single-scattering microfacet BRDFs (∫ f cos ≤ 1). A rough white metal
//!   loses what multiple scattering between microfacets would return: 1 % at roughness 0.25,
//!   8 % at 0.5, 37 % at 0.75 and 69 % at 1 at normal incidence. Storm's, pbrt's and Mitsuba 3's
//!   `roughconductor` / `roughdielectric` lose the same, which keeps the Mitsuba comparison
//!   like for like;
//! - the plastic's lambertian base is scaled by the energy its specular layer leaves, in the
//!   symmetric form of Kelemen and Szirmay-Kalos (2001) / Kulla and Conty (2017):
//!   `f_d = ρ/π · (1 − E(μo)) (1 − E(μi)) / (1 − E_avg)`, with `E(μ)` the specular layer's
//!   directional albedo (tabulated, [`AlbedoTable`]) and `E_avg` its cosine-weighted average.
//!   Then ∫ f_d cos = ρ (1 − E(μo)) exactly, so specular + diffuse = `E + ρ(1 − E)` ≤ 1, and
//!   unlike the glslfx's `(1 − F(h))` factor (which can exceed 1 in total for rough surfaces and
//!   is not reciprocal) the form is reciprocal. We chose it over the glslfx's form for those two
//!   reasons; at roughness 0 it is still the familiar `(1 − F(μo))(1 − F(μi))`;
//! - the glass reflects `F` and refracts `1 − F` of each microfacet's light;
//! - the clearcoat (white dielectric, `F0 = 0.04` for ior 1.5, its own roughness) reflects
//!   `c · E_c(μ)` and everything below it is scaled by `(1 − c E_c(μo)) (1 − c E_c(μi))`: the
//!   light crossing the coat on the way in and on the way out, each time losing what the coat
//!   reflects. Reciprocal, and base + coat ≤ `c E_c + (1 − c E_c)` ≤ 1.
//!
//! Refraction values are for *radiance* (light travelling against the camera rays), so they
//! include the `1/η²` factor of radiance compression (pbrt-v4's and Mitsuba 3's convention):
//! entering glass, `T/η²`; leaving, `T·η²`. The energy statements above hold for flux, i.e.
//! for the transmitted part before that factor.
//!
//! **Frames.** Every direction is a world-space unit vector; `wo` points toward the viewer.
//! The shading normal `n` and the geometric normal `ng` both face `wo`'s side. Light may arrive
//! only on `wo`'s side of `ng` (reflection) or on the far side (refraction, glass only), never
//! where the shading and geometric normals disagree, so nothing leaks through a surface. Where a
//! bent shading normal (normal mapping, smoothed normals) puts `wo` below it, the normal is
//! tilted toward `wo` just enough to see it, so such pixels are not black.

use glam::Vec3A;

use super::microfacet::{ggx_d, ggx_g1, ggx_g2, ggx_sample_vndf, ggx_vndf_pdf, refract, schlick, schlick_dielectric, AlbedoTable};
use super::{BsdfEval, BsdfSample, Lobe, Scattering};
use crate::sampling::{cosine_hemisphere, frame};

/// Roughness below which a lobe is a delta (mirror, smooth glass, mirror coat). Roughness
/// 1e-3 is GGX α = 1e-6, a lobe a few microradians wide: a glossy estimate there is the mirror
/// (tested), so the switch is continuous.
pub const DELTA_ROUGHNESS: f32 = 1e-3;

/// Normal-incidence reflectance of the clearcoat: a white dielectric of ior 1.5.
pub const CLEARCOAT_F0: f32 = 0.04;

/// Smallest `cos θo` against the shading normal: below it the normal is tilted toward `wo`.
const MIN_COS_O: f32 = 1e-4;

const COAT: usize = 0;
const SPEC: usize = 1;
const DIFF: usize = 2;
const TRANS: usize = 3;

/// UsdPreviewSurface's scattering at one shading point. See the module doc for the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewSurfaceBsdf {
    /// Shading normal (world, unit), in `ng`'s hemisphere, on the side `wo` comes from.
    pub n: Vec3A,
    /// Geometric normal (world, unit), on the side `wo` comes from.
    pub ng: Vec3A,
    /// `diffuseColor`: the lambertian base's reflectance and the metal's `F0`.
    rho: Vec3A,
    w_metal: f32,
    w_plastic: f32,
    w_glass: f32,
    f0_metal: Vec3A,
    f90_metal: f32,
    /// The dielectric's (plastic's and glass's) Fresnel.
    f0_diel: Vec3A,
    f90_diel: f32,
    /// Roughness for the albedo tables: 0 for the delta lobe.
    roughness: f32,
    /// GGX α; 0 for the delta lobe.
    alpha: f32,
    coat: f32,
    coat_roughness: f32,
    coat_alpha: f32,
    /// Index beyond the surface over the index on `wo`'s side.
    eta: f32,
    /// The glass refracts as a delta (smooth, or ior ≈ 1).
    trans_delta: bool,
}

/// A sample of the rough, non-diffuse lobes, with the half-angle of the lobe it came from: the
/// glossy ray's differential spreads over it (the paper's §4.4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlossySample {
    pub sample: BsdfSample,
    /// Radians: about twice the GGX lobe's microfacet spread, `2 atan α`.
    pub lobe_half_angle_rad: f32,
}

/// The shading frame at one `wo`.
struct Frame {
    n: Vec3A,
    t: Vec3A,
    b: Vec3A,
    /// `wo` in the frame.
    lo: Vec3A,
}

impl Frame {
    fn to_local(&self, w: Vec3A) -> Vec3A {
        Vec3A::new(self.t.dot(w), self.b.dot(w), self.n.dot(w))
    }
    fn to_world(&self, l: Vec3A) -> Vec3A {
        self.t * l.x + self.b * l.y + self.n * l.z
    }
}

fn mean(v: Vec3A) -> f32 {
    (v.x + v.y + v.z) * (1.0 / 3.0)
}

/// Schlick's `F90` for a given `F0`: white from `F0` ≥ 2 %, fading to 0 with it.
fn f90_of(f0: Vec3A) -> f32 {
    (50.0 * f0.max_element()).clamp(0.0, 1.0)
}

impl PreviewSurfaceBsdf {
    /// The BSDF of the (already clamped, textures applied) inputs `s` around shading normal `n`
    /// and geometric normal `ng` (world, unit, both facing the viewer). `front`: the viewer is on
    /// the side the surface's normal points to (outside a closed transmitting object), so light
    /// going through enters a medium of index `ior`; otherwise it leaves one. A positive
    /// `opacityThreshold` makes opacity a cutout mask, which the integrator applies: the surface
    /// here is then opaque.
    pub fn new(s: &PreviewSurface, n: Vec3A, ng: Vec3A, front: bool) -> Self {
        let ior = if s.ior.is_finite() && s.ior > 0.0 { s.ior } else { 1.0 };
        let unit = |x: f32| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
        let opacity = if s.opacity_threshold > 0.0 { 1.0 } else { unit(s.opacity) };
        let w_metal = if s.use_specular_workflow { 0.0 } else { unit(s.metallic) };
        let r = (1.0 - ior) / (1.0 + ior);
        let f0_diel = if s.use_specular_workflow { clamp_color(s.specular_color) } else { Vec3A::splat(r * r) };
        let rho = clamp_color(s.diffuse_color);
        let rough = unit(s.roughness);
        let (roughness, alpha) = if rough < DELTA_ROUGHNESS { (0.0, 0.0) } else { (rough, rough * rough) };
        let cr = unit(s.clearcoat_roughness);
        let (coat_roughness, coat_alpha) = if cr < DELTA_ROUGHNESS { (0.0, 0.0) } else { (cr, cr * cr) };
        let n = if n.is_finite() && n.length_squared() > 0.0 { n.normalize() } else { ng };
        PreviewSurfaceBsdf {
            n,
            ng,
            rho,
            w_metal,
            w_plastic: (1.0 - w_metal) * opacity,
            w_glass: (1.0 - w_metal) * (1.0 - opacity),
            f0_metal: rho,
            f90_metal: f90_of(rho),
            f0_diel,
            f90_diel: f90_of(f0_diel),
            roughness,
            alpha,
            coat: unit(s.clearcoat),
            coat_roughness,
            coat_alpha,
            eta: if front { ior } else { 1.0 / ior },
            trans_delta: alpha == 0.0 || (ior - 1.0).abs() < 1e-3,
        }
    }

    /// Some light goes through the surface (opacity < 1 with no cutout threshold, not a metal).
    pub fn transmits(&self) -> bool {
        self.w_glass > 0.0
    }

    /// The index beyond the surface over the index on the viewer's side.
    pub fn eta(&self) -> f32 {
        self.eta
    }

    /// The specular (GGX or mirror) lobe reflects anything.
    fn spec_nonzero(&self) -> bool {
        let m = self.w_metal * self.f0_metal.max_element().max(self.f90_metal);
        let d = (self.w_plastic + self.w_glass) * self.f0_diel.max_element().max(self.f90_diel);
        m + d > 0.0
    }

    /// Some lobe is rough and not lambertian: glossy reflection (specular lobe or coat) or rough
    /// refraction. What glossy rays sample.
    pub fn has_glossy(&self) -> bool {
        (self.alpha > 0.0 && self.spec_nonzero()) || (self.coat > 0.0 && self.coat_alpha > 0.0) || (self.w_glass > 0.0 && !self.trans_delta)
    }

    /// The shading frame for `wo`, or `None` when `wo` is below the geometric normal.
    fn frame(&self, wo: Vec3A) -> Option<Frame> {
        if !(self.ng.dot(wo) > 0.0) {
            return None;
        }
        let mut n = self.n;
        let c = n.dot(wo);
        if c < MIN_COS_O {
            // Tilt toward wo: (n + k wo)·wo = c + k before normalising, which keeps the sign.
            n = (n + wo * (2.0 * MIN_COS_O - c)).normalize_or(self.ng);
        }
        let (t, b) = frame(n);
        let lo = Vec3A::new(t.dot(wo), b.dot(wo), n.dot(wo).max(MIN_COS_O));
        Some(Frame { n, t, b, lo })
    }

    /// `1 − c E_c(μ)`: what the clearcoat lets through at `μ`.
    fn coat_k(&self, mu: f32) -> f32 {
        if self.coat <= 0.0 {
            return 1.0;
        }
        let e = AlbedoTable::get().albedo(mu, self.coat_roughness, Vec3A::splat(CLEARCOAT_F0), 1.0).x;
        (1.0 - self.coat * e).clamp(0.0, 1.0)
    }

    fn coat_fresnel(&self, cos: f32) -> f32 {
        schlick(cos, Vec3A::splat(CLEARCOAT_F0), 1.0).x
    }

    /// The dielectric's Fresnel across the interface (glass: total internal reflection leaving).
    fn fresnel_glass(&self, cos: f32) -> Vec3A {
        schlick_dielectric(cos, self.f0_diel, self.f90_diel, self.eta)
    }

    /// The shared specular lobe's Fresnel: metal + plastic + glass reflection.
    fn fresnel_spec(&self, cos: f32) -> Vec3A {
        let mut f = Vec3A::ZERO;
        if self.w_metal > 0.0 {
            f += self.w_metal * schlick(cos, self.f0_metal, self.f90_metal);
        }
        if self.w_plastic > 0.0 {
            f += self.w_plastic * schlick(cos, self.f0_diel, self.f90_diel);
        }
        if self.w_glass > 0.0 {
            f += self.w_glass * self.fresnel_glass(cos);
        }
        f
    }

    /// The plastic specular layer's directional albedo `E(μ)` per channel.
    fn e_diel(&self, mu: f32) -> Vec3A {
        AlbedoTable::get().albedo(mu, self.roughness, self.f0_diel, self.f90_diel)
    }

    /// Lobe pick probabilities at `μo` ∝ each lobe's estimated albedo (coat, specular, diffuse,
    /// transmission), not normalised.
    fn lobe_albedos(&self, mu_o: f32) -> [f32; 4] {
        let t = AlbedoTable::get();
        let ko = self.coat_k(mu_o);
        let mut a = [0.0f32; 4];
        if self.coat > 0.0 {
            a[COAT] = self.coat * t.albedo(mu_o, self.coat_roughness, Vec3A::splat(CLEARCOAT_F0), 1.0).x;
        }
        let e_d = self.e_diel(mu_o);
        let mut spec = Vec3A::ZERO;
        if self.w_metal > 0.0 {
            spec += self.w_metal * t.albedo(mu_o, self.roughness, self.f0_metal, self.f90_metal);
        }
        if self.w_plastic > 0.0 {
            spec += self.w_plastic * e_d;
            a[DIFF] = ko * self.w_plastic * mean(self.rho * (Vec3A::ONE - e_d));
        }
        if self.w_glass > 0.0 {
            let f = self.fresnel_glass(mu_o);
            spec += self.w_glass * f;
            let mut t = mean(Vec3A::ONE - f);
            if !self.trans_delta {
                // Rough microfacets refract even where the mean surface reflects totally: the
                // lobe must keep a share, or its light would have no density to be sampled by.
                t = t.max(0.2 * mean(Vec3A::ONE - self.f0_diel));
            }
            a[TRANS] = ko * self.w_glass * t;
        }
        a[SPEC] = ko * mean(spec);
        a
    }

    fn lobe_is_delta(&self, k: usize) -> bool {
        match k {
            COAT => self.coat_alpha == 0.0,
            SPEC => self.alpha == 0.0,
            DIFF => false,
            _ => self.trans_delta,
        }
    }

    /// The non-delta lobes' `f · |cos θi|`, split diffuse / other, and each lobe's own density
    /// of sampling `wi` (before the pick probabilities).
    fn eval_local(&self, f: &Frame, li: Vec3A, wi: Vec3A) -> (Vec3A, Vec3A, [f32; 4]) {
        let lo = f.lo;
        let mu_o = lo.z;
        let ng_i = self.ng.dot(wi);
        let (mut diffuse, mut spec, mut pdf) = (Vec3A::ZERO, Vec3A::ZERO, [0.0f32; 4]);
        if li.z > 0.0 && ng_i > 0.0 {
            let mu_i = li.z;
            let kk = self.coat_k(mu_o) * self.coat_k(mu_i);
            if self.w_plastic > 0.0 {
                let table = AlbedoTable::get();
                let avg = table.average_albedo(self.roughness, self.f0_diel, self.f90_diel);
                let left = Vec3A::ONE - avg;
                // (1 − E_avg) → 0 only when E → 1 everywhere (a perfect white mirror): no diffuse.
                let inv = Vec3A::select(left.cmpgt(Vec3A::splat(1e-6)), left.recip(), Vec3A::ZERO);
                let scale = (Vec3A::ONE - self.e_diel(mu_o)) * (Vec3A::ONE - self.e_diel(mu_i)) * inv;
                diffuse = self.w_plastic * self.rho * scale * (kk * mu_i * std::f32::consts::FRAC_1_PI);
                pdf[DIFF] = mu_i * std::f32::consts::FRAC_1_PI;
            }
            let h = (lo + li).normalize_or_zero();
            if h.z > 0.0 {
                let cos_h = lo.dot(h).max(0.0);
                if self.alpha > 0.0 {
                    let d = ggx_d(h, self.alpha);
                    let g2 = ggx_g2(lo, li, self.alpha);
                    spec += self.fresnel_spec(cos_h) * (d * g2 / (4.0 * mu_o) * kk);
                    pdf[SPEC] = ggx_g1(lo, self.alpha) * d / (4.0 * mu_o);
                }
                if self.coat > 0.0 && self.coat_alpha > 0.0 {
                    let d = ggx_d(h, self.coat_alpha);
                    let g2 = ggx_g2(lo, li, self.coat_alpha);
                    spec += Vec3A::splat(self.coat * self.coat_fresnel(cos_h) * d * g2 / (4.0 * mu_o));
                    pdf[COAT] = ggx_g1(lo, self.coat_alpha) * d / (4.0 * mu_o);
                }
            }
        } else if li.z < 0.0 && ng_i < 0.0 && self.w_glass > 0.0 && !self.trans_delta {
            let etap = self.eta;
            let mut h = (lo + li * etap).normalize_or_zero();
            if h.z < 0.0 {
                h = -h;
            }
            let (cos_o, cos_i) = (lo.dot(h), li.dot(h));
            if h != Vec3A::ZERO && cos_o > 0.0 && cos_i < 0.0 {
                let denom = (cos_i + cos_o / etap) * (cos_i + cos_o / etap);
                let d = ggx_d(h, self.alpha);
                let g2 = ggx_g2(lo, li, self.alpha);
                let t = self.w_glass * (Vec3A::ONE - self.fresnel_glass(cos_o));
                let kk = self.coat_k(mu_o) * self.coat_k(-li.z);
                let v = d * g2 * (cos_i * cos_o).abs() / (mu_o * denom) / (etap * etap) * kk;
                let p = ggx_vndf_pdf(lo, h, self.alpha) * cos_i.abs() / denom;
                if v.is_finite() && p.is_finite() {
                    spec = t * v;
                    pdf[TRANS] = p;
                }
            }
        }
        (diffuse, spec, pdf)
    }

    /// Samples a lobe among those `allowed` (indexed COAT, SPEC, DIFF, TRANS) with probability
    /// ∝ its albedo estimate. `split`: the weight counts only the non-diffuse value.
    fn sample_lobes(&self, wo: Vec3A, u: [f32; 3], allowed: [bool; 4], split: bool) -> Option<(BsdfSample, usize)> {
        let f = self.frame(wo)?;
        let lo = f.lo;
        let mu_o = lo.z;
        let mut p = self.lobe_albedos(mu_o);
        for k in 0..4 {
            if !allowed[k] || !(p[k] > 0.0) {
                p[k] = 0.0;
            }
        }
        let sum: f32 = p.iter().sum();
        if !(sum > 0.0) {
            return None;
        }
        p.iter_mut().for_each(|x| *x /= sum);
        let mut k = 0;
        let mut acc = 0.0;
        let u0 = u[0].clamp(0.0, 1.0);
        for (i, &pi) in p.iter().enumerate() {
            if pi > 0.0 {
                k = i;
                acc += pi;
                if u0 < acc {
                    break;
                }
            }
        }
        let (u1, u2) = (u[1], u[2]);
        let mirror = Vec3A::new(-lo.x, -lo.y, lo.z);
        if self.lobe_is_delta(k) {
            let ko = self.coat_k(mu_o);
            let (li, weight, lobe, eta) = match k {
                COAT => (mirror, Vec3A::splat(self.coat * self.coat_fresnel(mu_o)), Lobe::Specular, 1.0),
                SPEC => (mirror, self.fresnel_spec(mu_o) * ko * ko, Lobe::Specular, 1.0),
                _ => {
                    let lt = refract(lo, Vec3A::Z, self.eta)?;
                    let t = self.w_glass * (Vec3A::ONE - self.fresnel_glass(mu_o));
                    (lt, t * (ko * self.coat_k(-lt.z) / (self.eta * self.eta)), Lobe::Transmission, 1.0 / self.eta)
                }
            };
            let wi = f.to_world(li);
            let side = self.ng.dot(wi);
            if (lobe == Lobe::Transmission && !(side < 0.0)) || (lobe != Lobe::Transmission && !(side > 0.0)) {
                return None;
            }
            let weight = weight / p[k];
            return weight.is_finite().then_some((BsdfSample { wi, weight, pdf: p[k], lobe, delta: true, eta }, k));
        }
        let (li, lobe) = match k {
            COAT | SPEC => {
                let alpha = if k == COAT { self.coat_alpha } else { self.alpha };
                let h = ggx_sample_vndf(lo, alpha, u1, u2);
                (2.0 * lo.dot(h) * h - lo, Lobe::Glossy)
            }
            DIFF => (cosine_hemisphere(u1, u2).0, Lobe::Diffuse),
            _ => {
                let h = ggx_sample_vndf(lo, self.alpha, u1, u2);
                (refract(lo, h, self.eta)?, Lobe::Transmission)
            }
        };
        let wi = f.to_world(li);
        // A reflection lobe's direction below the surface, or a refraction's above it, is
        // absorbed: the lobe's density counts only where its value does.
        let below = li.z < 0.0 && self.ng.dot(wi) < 0.0;
        let above = li.z > 0.0 && self.ng.dot(wi) > 0.0;
        if (lobe == Lobe::Transmission && !below) || (lobe != Lobe::Transmission && !above) {
            return None;
        }
        let (d, s, pdfs) = self.eval_local(&f, li, wi);
        let pdf: f32 = (0..4).filter(|&j| !self.lobe_is_delta(j)).map(|j| p[j] * pdfs[j]).sum();
        let value = if split { s } else { d + s };
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        let weight = value / pdf;
        if !weight.is_finite() || weight.max_element() <= 0.0 {
            return None;
        }
        let eta = if lobe == Lobe::Transmission { 1.0 / self.eta } else { 1.0 };
        Some((BsdfSample { wi, weight, pdf, lobe, delta: false, eta }, k))
    }

    /// A direction from the rough non-diffuse lobes only (glossy reflection and rough
    /// refraction), chosen by their albedos; its weight is their `f · |cos θi|` over the density
    /// of this sampling. What the classic integrator's glossy rays use, while direct and ambient
    /// light cover the diffuse lobe. `None` if there is no such lobe or the sample is absorbed.
    pub fn sample_glossy(&self, wo: Vec3A, u: [f32; 3]) -> Option<GlossySample> {
        let allowed = [self.coat > 0.0 && self.coat_alpha > 0.0, self.alpha > 0.0, false, !self.trans_delta];
        let (sample, k) = self.sample_lobes(wo, u, allowed, true)?;
        let alpha = if k == COAT { self.coat_alpha } else { self.alpha };
        Some(GlossySample { sample, lobe_half_angle_rad: (2.0 * alpha.atan()).min(std::f32::consts::FRAC_PI_2) })
    }

    /// Every delta lobe's direction with its full weight (`∫ f cos` over the delta, not divided
    /// by any pick probability): the mirror reflection (specular and coat lobes together, they
    /// share it) and the smooth refraction. A Whitted-style integrator traces all of them.
    pub fn delta_lobes(&self, wo: Vec3A) -> [Option<BsdfSample>; 2] {
        let mut out = [None, None];
        let Some(f) = self.frame(wo) else { return out };
        let lo = f.lo;
        let mu_o = lo.z;
        let ko = self.coat_k(mu_o);
        let mut w = Vec3A::ZERO;
        if self.alpha == 0.0 {
            w += self.fresnel_spec(mu_o) * ko * ko;
        }
        if self.coat > 0.0 && self.coat_alpha == 0.0 {
            w += Vec3A::splat(self.coat * self.coat_fresnel(mu_o));
        }
        let wr = f.to_world(Vec3A::new(-lo.x, -lo.y, lo.z));
        if w.max_element() > 0.0 && self.ng.dot(wr) > 0.0 {
            out[0] = Some(BsdfSample { wi: wr, weight: w, pdf: 1.0, lobe: Lobe::Specular, delta: true, eta: 1.0 });
        }
        if self.w_glass > 0.0 && self.trans_delta {
            if let Some(lt) = refract(lo, Vec3A::Z, self.eta) {
                let wt = f.to_world(lt);
                let t = self.w_glass * (Vec3A::ONE - self.fresnel_glass(mu_o)) * (ko * self.coat_k(-lt.z) / (self.eta * self.eta));
                if t.max_element() > 0.0 && self.ng.dot(wt) < 0.0 {
                    out[1] = Some(BsdfSample { wi: wt, weight: t, pdf: 1.0, lobe: Lobe::Transmission, delta: true, eta: 1.0 / self.eta });
                }
            }
        }
        out
    }

    /// The diffuse lobe's directional albedo seen from `wo` (what an irradiance is multiplied
    /// by, over π): `(1 − c E_c(μo)) (1 − c E_c,avg) · w ρ (1 − E(μo))`. The coat's second
    /// factor is its average where the exact value would be an integral over `wi`.
    fn diffuse_albedo_at(&self, wo: Vec3A) -> Vec3A {
        let Some(f) = self.frame(wo) else { return Vec3A::ZERO };
        if self.w_plastic <= 0.0 {
            return Vec3A::ZERO;
        }
        let mu_o = f.lo.z;
        self.w_plastic * self.rho * (Vec3A::ONE - self.e_diel(mu_o)) * (self.coat_k(mu_o) * self.coat_k_avg())
    }

    fn coat_k_avg(&self) -> f32 {
        if self.coat <= 0.0 {
            return 1.0;
        }
        let e = AlbedoTable::get().average_albedo(self.coat_roughness, Vec3A::splat(CLEARCOAT_F0), 1.0).x;
        (1.0 - self.coat * e).clamp(0.0, 1.0)
    }
}

impl Scattering for PreviewSurfaceBsdf {
    fn eval(&self, wo: Vec3A, wi: Vec3A) -> BsdfEval {
        let Some(f) = self.frame(wo) else { return BsdfEval::default() };
        let li = f.to_local(wi);
        let (diffuse, specular, pdfs) = self.eval_local(&f, li, wi);
        let mut p = self.lobe_albedos(f.lo.z);
        let sum: f32 = p.iter().sum();
        if !(sum > 0.0) {
            return BsdfEval::default();
        }
        p.iter_mut().for_each(|x| *x /= sum);
        let pdf = (0..4).filter(|&j| !self.lobe_is_delta(j)).map(|j| p[j] * pdfs[j]).sum();
        BsdfEval { diffuse, specular, pdf }
    }

    fn sample(&self, wo: Vec3A, u: [f32; 3]) -> Option<BsdfSample> {
        self.sample_lobes(wo, u, [true; 4], false).map(|(s, _)| s)
    }

    /// The diffuse lobe's hemispherical (cosine-weighted average) albedo:
    /// `w ρ (1 − E_avg) (1 − c E_c,avg)²`, independent of the view. Exactly `diffuseColor` for
    /// a pure lambertian surface (specular 0, opaque, no coat).
    fn diffuse_reflectance(&self) -> Vec3A {
        if self.w_plastic <= 0.0 {
            return Vec3A::ZERO;
        }
        let avg = AlbedoTable::get().average_albedo(self.roughness, self.f0_diel, self.f90_diel);
        let k = self.coat_k_avg();
        self.w_plastic * self.rho * (Vec3A::ONE - avg) * (k * k)
    }

    fn diffuse_albedo(&self, wo: Vec3A) -> Vec3A {
        self.diffuse_albedo_at(wo)
    }

    fn has_delta(&self) -> bool {
        (self.alpha == 0.0 && self.spec_nonzero())
            || (self.coat > 0.0 && self.coat_alpha == 0.0)
            || (self.w_glass > 0.0 && self.trans_delta)
    }
}

/// UsdPreviewSurface's constant inputs, with its specification's names, meanings and fallbacks
/// (<https://openusd.org/release/spec_usdpreviewsurface.html>). Colours are linear RGB in
/// [0, 1]; every value is kept inside its valid range by [`PreviewSurface::clamped`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewSurface {
    /// Base colour: the diffuse reflectance, and a metal's specular colour. Fallback 0.18.
    pub diffuse_color: Vec3A,
    /// Emitted radiance (linear RGB, unbounded above). Fallback 0.
    pub emissive_color: Vec3A,
    /// Specular colour from `specular_color` (true) or from `metallic` and `ior` (false, the
    /// fallback).
    pub use_specular_workflow: bool,
    /// Normal-incidence specular reflectance in the specular workflow. Fallback 0.
    pub specular_color: Vec3A,
    /// 0 dielectric .. 1 metal (metallic workflow). Fallback 0.
    pub metallic: f32,
    /// Perceptual roughness in [0, 1] (GGX α = roughness²); 0 is the delta mirror or glass.
    /// Fallback 0.5.
    pub roughness: f32,
    /// Weight of a white dielectric (ior 1.5) coat over everything. Fallback 0.
    pub clearcoat: f32,
    /// The coat's roughness. Fallback 0.01.
    pub clearcoat_roughness: f32,
    /// 1 opaque; below 1 the surface transmits (glass, with `ior`) or, under
    /// `opacity_threshold`, is cut out. Fallback 1.
    pub opacity: f32,
    /// Above 0: opacity is a cutout mask (below the threshold: no surface). Fallback 0.
    pub opacity_threshold: f32,
    /// Index of refraction, > 0. Fallback 1.5.
    pub ior: f32,
}

impl Default for PreviewSurface {
    fn default() -> Self {
        PreviewSurface {
            diffuse_color: Vec3A::splat(0.18),
            emissive_color: Vec3A::ZERO,
            use_specular_workflow: false,
            specular_color: Vec3A::ZERO,
            metallic: 0.0,
            roughness: 0.5,
            clearcoat: 0.0,
            clearcoat_roughness: 0.01,
            opacity: 1.0,
            opacity_threshold: 0.0,
            ior: 1.5,
        }
    }
}

impl PreviewSurface {
    /// Every input inside its valid range (NaN to the fallback's side: 0 for colours); the
    /// names of the inputs that changed, so the caller can warn once naming the material.
    pub fn clamped(&self) -> (PreviewSurface, Vec<&'static str>) {
        let mut out = *self;
        let mut changed = Vec::new();
        let mut unit = |v: &mut f32, name: &'static str| {
            let c = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
            if c != *v {
                changed.push(name);
                *v = c;
            }
        };
        unit(&mut out.metallic, "metallic");
        unit(&mut out.roughness, "roughness");
        unit(&mut out.clearcoat, "clearcoat");
        unit(&mut out.clearcoat_roughness, "clearcoatRoughness");
        unit(&mut out.opacity, "opacity");
        unit(&mut out.opacity_threshold, "opacityThreshold");
        for (c, name) in [(&mut out.diffuse_color, "diffuseColor"), (&mut out.specular_color, "specularColor")] {
            let k = clamp_color(*c);
            if k != *c {
                changed.push(name);
                *c = k;
            }
        }
        let e = Vec3A::select(out.emissive_color.is_nan_mask(), Vec3A::ZERO, out.emissive_color).clamp(Vec3A::ZERO, Vec3A::splat(f32::MAX));
        if e != out.emissive_color {
            changed.push("emissiveColor");
            out.emissive_color = e;
        }
        if !(out.ior.is_finite() && out.ior > 0.0) {
            changed.push("ior");
            // ior ≤ 0 or NaN has no meaning; 1 (no refraction) is the nearest harmless value.
            out.ior = if out.ior.is_finite() && out.ior > 0.0 { out.ior } else { 1.0 };
        }
        (out, changed)
    }
}

/// NaN to 0, then into [0, 1].
pub fn clamp_color(c: Vec3A) -> Vec3A {
    Vec3A::select(c.is_nan_mask(), Vec3A::ZERO, c).clamp(Vec3A::ZERO, Vec3A::ONE)
}

#[cfg(test)]
mod tests;
