//! Light arriving at a shading point straight from the scene's lights, scattered by the surface's
//! BSDF toward the viewer: the direct-lighting estimator every integrator uses.
//!
//! **Estimator.** `shadow_samples` = N light samples and N BSDF samples per shading point,
//! combined by multiple importance sampling with Veach's power heuristic (β = 2):
//!
//! - a light sample chooses a light by importance ([`crate::light_sampler`]: probability P_j
//!   ∝ an estimate of its unoccluded irradiance at the point, so the shadow rays go where the
//!   light is — the paper's §4.3) and a direction on it with the light's own density p_j(ω)
//!   ([`crate::light::Light::sample`]); its density is p_L = P_j · p_j(ω);
//! - a BSDF sample draws a direction with the BSDF's density p_B(ω) and collects every light that
//!   direction crosses before the first occluder ([`Light::intersect`] for area lights, through
//!   the light tree's boxes; [`Light::environment`] for dome and distant lights when the ray
//!   escapes). Lights are not geometry, so a ray sees all the lights along it, exactly as light
//!   sampling does.
//!
//! Each sample is weighted w = (n_s p_s)² / ((N p_L)² + (n_B p_B)²) for its strategy s, where n_B
//! is the number of BSDF samples. A glossy surface reflecting a small bright light is lit mostly
//! by its BSDF samples, a diffuse one by its light samples, and neither is noisy. Delta lights
//! (a distant light of angle 0) are found only by light sampling and need no weight; delta BSDF
//! lobes (mirror, smooth glass) are not estimated here at all: no light sample can find their
//! direction, so the integrator's specular ray adds whatever light it meets, in full
//! ([`DirectLight::seen`], or [`DirectLight::emitted`] with no weight). The N light choices are
//! stratified (one random offset, N equal strata: systematic sampling), so a light chosen with
//! probability ≥ 1/N is visited at every shading point; a delta light chosen several times
//! traces its (identical) shadow ray once. A light of non-finite radiance gives a non-finite
//! estimate, which the render loop drops and counts.
//!
//! **Shadow rays** (`render.rays.shadow`) toward lights that cast shadows, with the paper's
//! differentials: a delta light's is narrow and parallel, the footprint as origin differential
//! (§4.3); a light sample of a wide light spreads over the solid angle it stands for,
//! 1 / (P_j p_j), shared by the N rays (§4.5: "the relative size of the light divided by the
//! number of shadow rays"); a BSDF sample's over 1 / (n_B p_B) (§4.6's rule for importance-sampled
//! rays). Shadow rays pass through opacity cut-outs (`opacityThreshold`) and are blocked by
//! everything else, glass of `opacity` < 1 without a threshold included (see
//! [`super::visibility`]).

use std::sync::Arc;

use glam::Vec3A;

use crate::bsdf::Scattering;
use crate::differential::RayDifferential;
use crate::effects::{enabled, Effect};
use crate::light::{Light, LightShape};
use crate::light_sampler::LightSampler;
use crate::options::RenderOptions;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

use super::{visibility, ShadingPoint};

/// Direct light at a point, split as the AOVs need it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LightEstimate {
    /// Through the BSDF's lambertian part (`directDiffuse`).
    pub diffuse: Vec3A,
    /// Through everything else: glossy reflection, rough transmission (`specular`).
    pub specular: Vec3A,
}

impl LightEstimate {
    /// Outgoing radiance of both parts.
    pub fn total(&self) -> Vec3A {
        self.diffuse + self.specular
    }
}

/// How direct light is gathered: built once per render from the scene's lights, the effects and
/// the settings ([`DirectLight::new`]).
#[derive(Clone, Debug)]
pub struct DirectLight {
    /// Shadow rays are traced (the scene has lights that cast shadows).
    pub shadows: bool,
    /// Light samples (and BSDF samples) per shading point: `shadowSamples`.
    pub shadow_samples: u32,
    /// Camera rays see dome lights ([`crate::options::RenderOptions::dome_light_camera_visibility`]).
    pub camera_sees_dome: bool,
    lights: Arc<LightSampler>,
}

/// A light a BSDF-sampled ray meets: (light index, distance, radiance, light-sampling density).
type Crossed = (usize, f32, Vec3A, f32);

/// Veach's power heuristic (β = 2) for a sample of effective density `a` against `b`.
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2.is_infinite() {
        return 1.0;
    }
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

impl DirectLight {
    /// The scene's lights organised for sampling ([`LightSampler`]); `shadows`: trace shadow
    /// rays (toward lights that cast them); `shadow_samples`: light samples per shading point.
    pub fn new(scene: &Scene, shadows: bool, shadow_samples: u32) -> Self {
        DirectLight {
            shadows,
            shadow_samples: shadow_samples.max(1),
            camera_sees_dome: true,
            lights: Arc::new(LightSampler::new(&scene.lights)),
        }
    }

    /// What a render's integrators use: shadows when the scene calls for them (the `shadows`
    /// effect), `shadowSamples`, and camera rays seeing domes as `domeLightCameraVisibility` says.
    pub fn for_render(scene: &Scene, effects: &[Effect], options: &RenderOptions) -> Self {
        DirectLight {
            camera_sees_dome: options.dome_light_camera_visibility,
            ..DirectLight::new(scene, enabled(effects, "shadows"), options.shadow_samples)
        }
    }

    /// The light sampler (for probabilities of choosing a light at a point).
    pub fn light_sampler(&self) -> &LightSampler {
        &self.lights
    }

    /// Direct light scattered toward `wo` (unit, render space, pointing away from the surface)
    /// by `bsdf` at shading point `sp` of `hit`: N light samples and N BSDF samples with
    /// multiple importance sampling (see the module doc). `footprint` is the incoming ray's
    /// differential transferred to the hit (the origin of the shadow rays' differentials).
    /// Radiance, linear RGB.
    #[allow(clippy::too_many_arguments)]
    pub fn estimate(
        &self,
        tracer: &Tracer<'_>,
        scene: &Scene,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        bsdf: &dyn Scattering,
        wo: Vec3A,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> LightEstimate {
        let n_bsdf = if self.lights.has_wide_lights() { self.shadow_samples } else { 0 };
        self.gather(tracer, scene, sp, hit, footprint, bsdf, wo, n_bsdf, n_bsdf, sampler, counters)
    }

    /// Next-event estimation for a path tracer that continues each path with one BSDF-sampled
    /// ray: N light samples only, weighted by multiple importance sampling against that one
    /// BSDF sample, whose light the path tracer adds with [`DirectLight::emitted`] (with its
    /// BSDF density). Same arguments as [`DirectLight::estimate`].
    #[allow(clippy::too_many_arguments)]
    pub fn estimate_lights(
        &self,
        tracer: &Tracer<'_>,
        scene: &Scene,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        bsdf: &dyn Scattering,
        wo: Vec3A,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> LightEstimate {
        self.gather(tracer, scene, sp, hit, footprint, bsdf, wo, 0, 1, sampler, counters)
    }

    /// Radiance (RGB) that the scene's lights send back along a ray leaving shading point
    /// `from` in unit direction `wi` whose first surface hit is at distance `t_hit` (infinite
    /// when it escapes): every area light crossed before it, and dome and distant lights if it
    /// escaped. With `bsdf_pdf = None` (camera rays, delta bounces: directions no light sample
    /// finds) the light counts in full; with `Some(p)` — `wi` was drawn from the BSDF with
    /// density p, after [`DirectLight::estimate_lights`] at `from` — each light is weighted by
    /// the power heuristic against light sampling, and lights that cast no shadows count even
    /// behind `t_hit`, as light sampling counts them.
    pub fn emitted(&self, scene: &Scene, from: &ShadingPoint, wi: Vec3A, t_hit: f32, bsdf_pdf: Option<f32>) -> Vec3A {
        self.emitted_where(scene, from, wi, t_hit, bsdf_pdf, true)
    }

    /// As [`DirectLight::emitted`] along a camera ray from `eye`: a dome only when the camera
    /// sees domes ([`DirectLight::camera_sees_dome`]).
    pub fn seen_by_camera(&self, scene: &Scene, eye: &ShadingPoint, wi: Vec3A, t_hit: f32) -> Vec3A {
        self.emitted_where(scene, eye, wi, t_hit, None, self.camera_sees_dome)
    }

    fn emitted_where(&self, scene: &Scene, from: &ShadingPoint, wi: Vec3A, t_hit: f32, bsdf_pdf: Option<f32>, domes: bool) -> Vec3A {
        let mis = bsdf_pdf.filter(|p| p.is_finite() && *p > 0.0);
        let at = mis.map(|_| self.lights.at(from.p, from.ns));
        let mut sum = Vec3A::ZERO;
        for (j, t, radiance, pdf) in self.crossed(scene, from, wi) {
            let light = &scene.lights[j];
            if !domes && matches!(light.shape, LightShape::Dome(_)) {
                continue;
            }
            if from.mesh.is_some_and(|m| !light.illuminates.contains(m)) {
                continue;
            }
            if mis.is_some() && !light.shadowed_by.is_all() {
                // Found by light sampling alone (see `gather`).
                continue;
            }
            let through = mis.is_some() && !(self.shadows && light.casts_shadows);
            // An escaping ray (t_hit infinite) sees the lights at infinity too.
            if !(t < t_hit || t_hit == f32::INFINITY || through) {
                continue;
            }
            let w = match (mis, &at) {
                (Some(pb), Some(at)) => power_heuristic(pb, self.shadow_samples as f32 * at.pmf(j) * pdf),
                _ => 1.0,
            };
            sum += radiance * w;
        }
        sum
    }

    /// Radiance (RGB) the lights send along a camera ray or a delta (mirror, glass) bounce
    /// `ray` whose first surface hit is at distance `t_hit` (infinite when it escapes): every
    /// area light it crosses before, and when it escapes the background ([`Scene::background`]:
    /// a dome filtered over the ray's own directional spread, as sharp as its pixel, rather
    /// than the lighting filter [`DirectLight::emitted`] uses). Full weight: no light sample
    /// can find these directions.
    pub fn seen(&self, scene: &Scene, ray: &Ray, t_hit: f32) -> Vec3A {
        let mut sum = Vec3A::ZERO;
        self.lights.for_each_crossed(&scene.lights, ray.o, ray.d, t_hit, ray.time, |_, h| sum += h.radiance);
        if t_hit == f32::INFINITY {
            sum += scene.background(ray.d, ray.diff.directional_spread_rad());
        }
        sum
    }

    /// Every light the ray from `from.p` along `wi` meets, ignoring occlusion.
    fn crossed(&self, scene: &Scene, from: &ShadingPoint, wi: Vec3A) -> Vec<Crossed> {
        let mut out: Vec<Crossed> = Vec::new();
        self.lights.for_each_crossed(&scene.lights, from.p, wi, f32::INFINITY, from.time, |j, h| out.push((j, h.t, h.radiance, h.pdf)));
        for (j, light) in scene.lights.iter().enumerate() {
            if light.is_infinite() && !light.is_delta() {
                let radiance = light.environment(wi);
                if radiance.max_element() > 0.0 {
                    out.push((j, f32::INFINITY, radiance, light.pdf_at(from.p, from.ns, wi, from.time)));
                }
            }
        }
        out
    }

    #[allow(clippy::too_many_arguments)]
    fn gather(
        &self,
        tracer: &Tracer<'_>,
        scene: &Scene,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        bsdf: &dyn Scattering,
        wo: Vec3A,
        n_bsdf: u32,
        n_bsdf_weight: u32,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> LightEstimate {
        let mut out = LightEstimate::default();
        if self.lights.is_empty() {
            return out;
        }
        let n = self.shadow_samples.max(1);
        let (nf, nbf) = (n as f32, n_bsdf_weight as f32);
        // The lights weighed once at this point: every choice and probability below reads it.
        let at = self.lights.at(sp.p, sp.ns);
        // Light samples: N stratified choices of a light, each with its own direction.
        let offset = sampler.next_f32();
        let mut delta_visibility: Vec<(usize, bool)> = Vec::new();
        for k in 0..n {
            let u_choice = (k as f32 + offset) / nf;
            let (u1, u2) = (sampler.next_f32(), sampler.next_f32());
            let Some((j, prob)) = at.sample(u_choice) else { continue };
            let light = &scene.lights[j];
            if !light.illuminates.contains(hit.mesh) {
                continue;
            }
            let Some(ls) = light.sample_at(sp.p, sp.ns, u1, u2, hit.time) else { continue };
            let f = bsdf.eval(wo, ls.wi);
            if f.total().max_element() <= 0.0 {
                continue;
            }
            let p_light = prob * ls.pdf;
            // A shadow-linked light is found by light sampling alone: which surfaces block it
            // depends on the light, so the BSDF samples' shared occlusion ray cannot answer.
            let light_only = ls.delta || !light.shadowed_by.is_all();
            let w = if light_only { 1.0 } else { power_heuristic(nf * p_light, nbf * f.pdf) };
            let scale = w / (nf * p_light);
            if !(scale > 0.0 && scale.is_finite()) {
                continue;
            }
            if self.shadows && light.casts_shadows {
                let visible = if ls.delta {
                    match delta_visibility.iter().find(|(d, _)| *d == j) {
                        Some(&(_, v)) => v,
                        None => {
                            let v = !self.occluded(tracer, sp, hit, footprint, light, ls.wi, ls.distance, None, counters);
                            delta_visibility.push((j, v));
                            v
                        }
                    }
                } else {
                    !self.occluded(tracer, sp, hit, footprint, light, ls.wi, ls.distance, Some((1.0 / p_light, n)), counters)
                };
                if !visible {
                    continue;
                }
            }
            out.diffuse += ls.radiance * f.diffuse * scale;
            out.specular += ls.radiance * f.specular * scale;
        }
        // BSDF samples: directions by the BSDF, weighted against light sampling.
        for _ in 0..n_bsdf {
            let u = [sampler.next_f32(), sampler.next_f32(), sampler.next_f32()];
            let Some(s) = bsdf.sample(wo, u) else { continue };
            if s.delta {
                continue;
            }
            let f = bsdf.eval(wo, s.wi);
            if !(f.pdf > 0.0) || f.total().max_element() <= 0.0 {
                continue;
            }
            let mut crossed = self.crossed(scene, sp, s.wi);
            crossed.retain(|c| {
                let light = &scene.lights[c.0];
                light.illuminates.contains(hit.mesh) && light.shadowed_by.is_all()
            });
            if crossed.is_empty() {
                continue;
            }
            let t_geometry = self.first_occluder(tracer, sp, hit, footprint, scene, &crossed, s.wi, f.pdf, n_bsdf, counters);
            for (j, t, radiance, pdf) in crossed {
                let light = &scene.lights[j];
                // Blocked when a surface is nearer than the light (a finite distance: a light at
                // infinity is blocked by any surface).
                if self.shadows && light.casts_shadows && t_geometry.is_finite() && t >= t_geometry {
                    continue;
                }
                let w = power_heuristic(nbf * f.pdf, nf * at.pmf(j) * pdf);
                let scale = w / (nbf * f.pdf);
                out.diffuse += radiance * f.diffuse * scale;
                out.specular += radiance * f.specular * scale;
            }
        }
        // Not finite only for a light of non-finite radiance: returned as it is, so the render
        // loop drops the sample and counts it.
        out
    }

    /// True when the shadow ray from the surface toward `light` along `wi` is blocked before
    /// `distance`. `spread`: the solid angle the ray stands for and the ray count (a wide
    /// light's §4.5 differential); `None`: a point-like light's narrow one (§4.3).
    #[allow(clippy::too_many_arguments)]
    fn occluded(
        &self,
        tracer: &Tracer<'_>,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        light: &Light,
        wi: Vec3A,
        distance: f32,
        spread: Option<(f32, u32)>,
        counters: &mut TraceCounters,
    ) -> bool {
        let diff = match spread {
            // Parallel shadow rays, the footprint as origin differential (§4.3: narrow and
            // coherent).
            None => RayDifferential::new(footprint.dpdx, footprint.dpdy, Vec3A::ZERO, Vec3A::ZERO),
            Some((solid_angle, n)) => {
                let (d, clamped) = footprint.area_light_shadow_checked(wi, solid_angle, n);
                counters.differential_clamps += u64::from(clamped);
                d
            }
        };
        // Through opacity cut-outs: a leaf card shadows only where its mask leaves a leaf.
        let ray = self.shadow_ray(sp, hit, wi, distance, diff);
        if light.shadowed_by.is_all() {
            visibility::occluded_from(tracer, &ray, hit, counters)
        } else {
            visibility::occluded_by(tracer, &ray, hit, &light.shadowed_by, counters)
        }
    }

    /// A shadow ray toward a light at `distance`, stopping just short of it (a light is not
    /// geometry here, but a mesh can coincide with it).
    fn shadow_ray(&self, sp: &ShadingPoint, hit: &Hit, wi: Vec3A, distance: f32, diff: RayDifferential) -> Ray {
        let o = offset_origin(sp.p, hit.p_error, sp.ng, wi);
        let t_max = if distance.is_finite() { distance * (1.0 - 1e-4) } else { f32::INFINITY };
        Ray { o, d: wi, t_min: 0.0, t_max, diff, kind: RayKind::Shadow, time: hit.time }
    }

    /// Distance to the first surface along a BSDF-sampled direction, as far as the lights it
    /// crosses need (infinite when nothing blocks them): one any-hit ray when a single
    /// shadow-casting light is crossed, else one closest-hit ray.
    #[allow(clippy::too_many_arguments)]
    fn first_occluder(
        &self,
        tracer: &Tracer<'_>,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        scene: &Scene,
        crossed: &[Crossed],
        wi: Vec3A,
        pdf: f32,
        n: u32,
        counters: &mut TraceCounters,
    ) -> f32 {
        if !self.shadows {
            return f32::INFINITY;
        }
        let casting: Vec<f32> = crossed.iter().filter(|c| scene.lights[c.0].casts_shadows).map(|c| c.1).collect();
        let Some(far) = casting.iter().copied().reduce(f32::max) else { return f32::INFINITY };
        // Importance-sampled rays spread over the solid angle each stands for (§4.6).
        let (diff, clamped) = footprint.hemisphere_checked(wi, pdf, n.max(1));
        counters.differential_clamps += u64::from(clamped);
        let ray = self.shadow_ray(sp, hit, wi, far, diff);
        // Both through opacity cut-outs, as light samples' shadow rays.
        if casting.len() == 1 {
            if visibility::occluded_from(tracer, &ray, hit, counters) {
                0.0
            } else {
                f32::INFINITY
            }
        } else {
            visibility::first_opaque_from(tracer, &ray, hit, counters).map_or(f32::INFINITY, |b| (b.hit.p - sp.p).length())
        }
    }
}
