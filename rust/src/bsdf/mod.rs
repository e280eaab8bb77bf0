//! Scattering at a shading point: the interface every integrator uses, and the BSDFs behind it.
//!
//! Conventions: all directions are unit vectors in render (world) space; `wo` points from the
//! surface toward where the light goes (the viewer, −ray.d), `wi` toward where it comes from.
//! Values are `f(wo, wi) · |cos θi|` with θi measured from the shading normal, so an estimator
//! needs no extra cosine; densities are per unit solid angle.

use glam::Vec3A;

use crate::sampling::{cosine_hemisphere, frame};

mod albedo_table_data;
pub mod microfacet;
pub mod preview;

pub use preview::{GlossySample, PreviewSurfaceBsdf};

/// Which part of the BSDF a sample came from: it decides the ray's kind (and so its
/// differential and tessellation rate) and which AOV its light goes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lobe {
    /// Lambertian reflection (the `directDiffuse` / `indirectDiffuse` AOVs; hemisphere rays).
    Diffuse,
    /// Rough (microfacet) reflection: glossy rays.
    Glossy,
    /// Delta reflection (roughness 0): mirror rays.
    Specular,
    /// Refraction through the surface, delta or rough: refraction rays.
    Transmission,
}

/// A non-delta evaluation, split so the AOVs can tell diffuse from specular light.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BsdfEval {
    /// Lambertian part of `f · |cos θi|`.
    pub diffuse: Vec3A,
    /// Everything else (glossy reflection and rough transmission) of `f · |cos θi|`.
    pub specular: Vec3A,
    /// Density with which [`Scattering::sample`] picks `wi` (solid angle; 0 where it never does).
    pub pdf: f32,
}

impl BsdfEval {
    /// `f · |cos θi|` of every lobe.
    pub fn total(&self) -> Vec3A {
        self.diffuse + self.specular
    }
}

/// One sampled direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    pub wi: Vec3A,
    /// `f · |cos θi| / pdf`: what the incoming radiance is multiplied by. Finite, non-negative.
    pub weight: Vec3A,
    /// Solid-angle density of `wi`; for a delta lobe, the discrete probability of picking it.
    pub pdf: f32,
    pub lobe: Lobe,
    /// The direction is a delta (mirror or smooth glass): no light sample can find it, so
    /// multiple importance sampling gives it full weight.
    pub delta: bool,
    /// For refraction: the relative index of refraction η = η_incident / η_transmitted the
    /// refracted ray's differential needs (1 otherwise).
    pub eta: f32,
}

/// What an integrator asks of a surface's scattering.
pub trait Scattering {
    /// `f(wo, wi) · |cos θi|` of the non-delta lobes and the density of sampling `wi`.
    fn eval(&self, wo: Vec3A, wi: Vec3A) -> BsdfEval;

    /// A direction by importance, from three uniform numbers in [0, 1); `None` when the sample
    /// is absorbed or falls where the BSDF is zero.
    fn sample(&self, wo: Vec3A, u: [f32; 3]) -> Option<BsdfSample>;

    /// The hemispherical-directional reflectance of the diffuse part: the `albedo` AOV, and what
    /// hemisphere integrals (ambient occlusion, irradiance) are multiplied by.
    fn diffuse_reflectance(&self) -> Vec3A;

    /// Some lobe is a delta (mirror or smooth glass).
    fn has_delta(&self) -> bool;

    /// The diffuse part's directional albedo seen from `wo`: what an irradiance estimate
    /// (ambient occlusion, an irradiance cache, one-bounce color bleeding) is multiplied by, over
    /// π, to give the diffuse radiance toward `wo`. A specular layer over the diffuse makes it
    /// depend on `wo`; by default, [`Scattering::diffuse_reflectance`].
    fn diffuse_albedo(&self, wo: Vec3A) -> Vec3A {
        let _ = wo;
        self.diffuse_reflectance()
    }
}

/// A lambertian reflector of reflectance `r` around shading normal `n` (geometric normal `ng`
/// bounds the hemisphere light may arrive from).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lambertian {
    pub r: Vec3A,
    pub n: Vec3A,
    pub ng: Vec3A,
}

impl Scattering for Lambertian {
    fn eval(&self, wo: Vec3A, wi: Vec3A) -> BsdfEval {
        let cos = self.n.dot(wi);
        if cos <= 0.0 || self.ng.dot(wi) <= 0.0 || self.ng.dot(wo) <= 0.0 {
            return BsdfEval::default();
        }
        BsdfEval { diffuse: self.r * (cos * std::f32::consts::FRAC_1_PI), specular: Vec3A::ZERO, pdf: cos * std::f32::consts::FRAC_1_PI }
    }

    fn sample(&self, wo: Vec3A, u: [f32; 3]) -> Option<BsdfSample> {
        let (t, b) = frame(self.n);
        let (local, pdf) = cosine_hemisphere(u[0], u[1]);
        let wi = t * local.x + b * local.y + self.n * local.z;
        if pdf <= 0.0 || self.ng.dot(wi) <= 0.0 || self.ng.dot(wo) <= 0.0 {
            return None;
        }
        Some(BsdfSample { wi, weight: self.r, pdf, lobe: Lobe::Diffuse, delta: false, eta: 1.0 })
    }

    fn diffuse_reflectance(&self) -> Vec3A {
        self.r
    }

    fn has_delta(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sampled weight is eval/pdf, and the estimator of reflectance under uniform white
    /// light (the white furnace) converges to r.
    #[test]
    fn lambertian_white_furnace_and_sample_consistency() {
        let n = Vec3A::new(0.3, -0.2, 0.9).normalize();
        let l = Lambertian { r: Vec3A::splat(1.0), n, ng: n };
        let wo = (n + Vec3A::X * 0.5).normalize();
        let mut sum = Vec3A::ZERO;
        let k = 64;
        for i in 0..k {
            for j in 0..k {
                let u = [(i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32, 0.5];
                let s = l.sample(wo, u).expect("a direction above the surface");
                let e = l.eval(wo, s.wi);
                assert!((e.pdf - s.pdf).abs() <= 1e-5 * s.pdf.max(1.0));
                assert!((e.total() / e.pdf - s.weight).abs().max_element() < 1e-4);
                sum += s.weight;
            }
        }
        let mean = sum / (k * k) as f32;
        assert!((mean - Vec3A::ONE).abs().max_element() < 1e-5, "{mean}");
    }
}
