//! One-bounce color bleeding (issue 7's integrator (c), `integrator = colorBleeding`): direct
//! light plus one diffuse bounce of `indirectSamples` hemisphere rays (the paper's §4.6 names it
//! among the distribution effects its wide rays make cheap).
//!
//! At the surface a camera ray sees (past cut-outs), radiance = emission + direct light through
//! the material's BSDF ([`DirectLight::estimate`]: every lobe, light and BSDF samples with MIS) +
//! the BSDF's diffuse albedo × `E/π`, where `E` is the irradiance the hemisphere rays find. Each
//! hemisphere ray is shaded where it lands with emission and direct light only (through that
//! surface's BSDF, toward the ray) — one bounce, no recursion. Lights are not geometry and escaped
//! rays bring nothing back, so a light (dome or area) is counted once, by the direct term;
//! emissive surfaces (`emissiveColor`) are not lights, so the bounce is what carries their light
//! onto other surfaces. Mirror, glass and glossy chains are the classic integrator's and the path
//! tracer's: here a delta lobe reflects nothing but what direct light's MIS gives it.
//!
//! The hemisphere rays are cosine-weighted and stratified ([`Strata::for_rays`]: M × N ≈
//! `indirectSamples`), of kind [`RayKind::Diffuse`], each with §4.6's differential
//! (`hemisphere_checked`): they are wide, so they read coarse tessellations and, at their hits,
//! coarse texture MIP levels. Direct light where a hemisphere ray lands takes one light sample
//! (and one BSDF sample): each ray is already one sample of an `indirectSamples`-sample integral.
//!
//! With `irradianceCache` on, `E/π` comes from an irradiance cache with gradients
//! ([`crate::irradiance_cache`]) made by [`Integrator::prepass`] at the surfaces the pixel
//! centres see — the same rays, gathered once per record and interpolated between records — and
//! is sampled directly only where no record is valid. The `ao` AOV is filled when `aoSamples` > 0
//! ([`Hemisphere::occlusion`], cached too); it does not light the colour here. The AOVs split the
//! colour as the classic integrator does: `emission`, `directDiffuse`, `indirectDiffuse` (the
//! bounce), `specular` (direct light through the glossy lobes).

use std::sync::OnceLock;

use glam::Vec3A;
use serde_json::Value;

use crate::bsdf::Scattering;
use crate::effects::{enabled, Effect};
use crate::error::RenderError;
use crate::irradiance_cache::{estimate, stats_object, HemisphereEstimate, HemisphereRay, IrradianceCache, Quantity, Strata};
use crate::options::RenderOptions;
use crate::progress::Progress;
use crate::ray::{Ray, RayKind};
use crate::sampling::{frame, Sampler};
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

use super::direct_light::DirectLight;
use super::hemisphere::{gather, prepass_build, visible, visible_at, Hemisphere, Visible, RECORD_STREAM};
use super::{tessellation_error, Integrator, SampleValue, ShadingPoint};

/// Direct light plus one diffuse bounce. Construct with [`ColorBleeding::new`].
pub struct ColorBleeding<'a> {
    pub tracer: &'a Tracer<'a>,
    pub scene: &'a Scene,
    /// Camera rays through a thin lens (the scene's camera has an f-stop).
    pub depth_of_field: bool,
    /// Direct light where the camera ray lands: `shadowSamples` light and BSDF samples.
    direct: DirectLight,
    /// Direct light where a hemisphere ray lands: one of each.
    bounce_direct: DirectLight,
    /// Hemisphere rays per camera hit (0: no bounce — the `indirect_diffuse` effect was not
    /// enabled).
    indirect_samples: u32,
    /// The irradiance cache's error bound, when caching.
    cache_error: Option<f32>,
    cache: OnceLock<IrradianceCache>,
    /// The `ao` AOV, when `aoSamples` > 0.
    ao: Hemisphere,
    /// The `tessError` AOV was asked for.
    tess_error: bool,
}

impl<'a> ColorBleeding<'a> {
    /// A color-bleeding integrator over `tracer`'s scene, tracing the `effects` the scene and
    /// settings called for (shadow rays only toward lights that cast shadows; hemisphere rays
    /// when `indirect_diffuse` is enabled; the `ao` AOV when `ao` is).
    pub fn new(tracer: &'a Tracer<'a>, scene: &'a Scene, effects: &[Effect], options: &RenderOptions) -> Self {
        let direct = DirectLight::for_render(scene, effects, options);
        let mut bounce_direct = direct.clone();
        bounce_direct.shadow_samples = 1;
        let indirect_samples = if enabled(effects, "indirect_diffuse") { options.indirect_samples } else { 0 };
        ColorBleeding {
            tracer,
            scene,
            depth_of_field: enabled(effects, "depth_of_field"),
            direct,
            bounce_direct,
            indirect_samples,
            cache_error: (options.irradiance_cache && indirect_samples > 0).then_some(options.irradiance_cache_error),
            cache: OnceLock::new(),
            ao: Hemisphere::new(if enabled(effects, "ao") { options.ao_samples } else { 0 }, options),
            tess_error: options.aovs.contains(&crate::aov::Aov::TessError),
        }
    }

    /// The irradiance cache, once the pre-pass has made it.
    pub fn cache(&self) -> Option<&IrradianceCache> {
        self.cache.get()
    }

    /// Radiance a hemisphere ray brings back from `hit`: emission plus direct light reflected
    /// toward the ray by the surface there (past cut-outs), its textures read at the wide ray's
    /// footprint.
    fn bounce_radiance(&self, ray: &Ray, hit: &Hit, sampler: &mut Sampler, counters: &mut TraceCounters) -> Vec3A {
        let Some(v) = visible_at(self.tracer, self.scene, *ray, *hit, counters) else { return Vec3A::ZERO };
        let wo = -v.ray.d;
        let bsdf = v.surface.bsdf(&v.sp);
        let mut l = v.surface.inputs.emissive_color;
        if bsdf.diffuse_albedo(wo).max_element() > 0.0 || bsdf.has_glossy() {
            l += self.bounce_direct.estimate(self.tracer, self.scene, &v.sp, &v.hit, &v.footprint, &bsdf, wo, sampler, counters).total();
        }
        l
    }

    /// The bounce's rays above the surface `v`.
    fn gather(&self, v: &Visible, sampler: &mut Sampler, counters: &mut TraceCounters) -> Vec<HemisphereRay> {
        let strata = Strata::for_rays(self.indirect_samples);
        gather(self.tracer, &v.sp, &v.hit, &v.footprint, strata, f32::INFINITY, RayKind::Diffuse, sampler, counters, |found, ray, s, c| {
            found.map_or(Vec3A::ZERO, |h| self.bounce_radiance(ray, h, s, c))
        })
    }

    /// The one-bounce integral at the surface `v` with its gradients: `E/π` from the stratified
    /// hemisphere rays (an irradiance record).
    pub fn irradiance_estimate(&self, v: &Visible, sampler: &mut Sampler, counters: &mut TraceCounters) -> HemisphereEstimate {
        let rays = self.gather(v, sampler, counters);
        let (t, b) = frame(v.sp.ns);
        estimate(Strata::for_rays(self.indirect_samples), &rays, t, b, v.sp.ns)
    }

    /// `E/π` at the surface `v`: interpolated from the cache where a record is valid, otherwise
    /// the mean of the hemisphere rays.
    fn indirect(&self, v: &Visible, sampler: &mut Sampler, counters: &mut TraceCounters) -> Vec3A {
        if let Some(e) = self.cache.get().and_then(|c| c.interpolate(v.sp.p, v.sp.ns)) {
            return e;
        }
        let rays = self.gather(v, sampler, counters);
        rays.iter().map(|r| r.value).sum::<Vec3A>() / rays.len().max(1) as f32
    }

    /// Radiance and AOV values along a camera ray.
    pub fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        let mut out = SampleValue::miss(self.scene.camera.clipping_range.1);
        // The camera as a "shading point" for lights seen directly (a dome is the background).
        let eye = ShadingPoint::at_camera(ray);
        let Some(v) = visible(self.tracer, self.scene, *ray, None, counters) else {
            out.emission = self.direct.seen_by_camera(self.scene, &eye, ray.d, f32::INFINITY);
            out.set_color_from_parts();
            return out;
        };
        let wo = -v.ray.d;
        let bsdf = v.surface.bsdf(&v.sp);
        let albedo = bsdf.diffuse_albedo(wo);
        out.set_hit(self.scene, &v.hit, v.sp.ns);
        out.albedo = albedo;
        out.emission = v.surface.inputs.emissive_color + self.direct.seen_by_camera(self.scene, &eye, ray.d, (v.hit.p - ray.o).length());
        if albedo.max_element() > 0.0 || bsdf.has_glossy() {
            let d = self.direct.estimate(self.tracer, self.scene, &v.sp, &v.hit, &v.footprint, &bsdf, wo, sampler, counters);
            out.direct_diffuse = d.diffuse;
            out.specular = d.specular;
        }
        if self.indirect_samples > 0 && albedo.max_element() > 0.0 {
            out.indirect_diffuse = albedo * self.indirect(&v, sampler, counters);
        }
        if self.ao.samples > 0 {
            out.ao = self.ao.occlusion(self.tracer, &v.sp, &v.hit, &v.footprint, sampler, counters);
        }
        out.set_color_from_parts();
        out.beam_width = v.ray.beam_width(v.hit.t);
        out.tess_rate = v.hit.quads as f32;
        if self.tess_error {
            let err = tessellation_error(self.tracer, self.scene, &v.ray, &v.hit);
            let width = v.ray.beam_width(v.hit.t);
            out.tess_error = [err, if width > 0.0 { err / width } else { 0.0 }];
        }
        out
    }
}

impl Integrator for ColorBleeding<'_> {
    fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        ColorBleeding::sample(self, ray, sampler, counters)
    }

    fn depth_of_field(&self) -> bool {
        self.depth_of_field
    }

    fn scene(&self) -> &Scene {
        self.scene
    }

    /// Makes the irradiance cache (and the occlusion cache of the `ao` AOV) when caching, at the
    /// surfaces with a diffuse albedo the pixel centres see.
    fn prepass(&self, options: &RenderOptions, progress: &dyn Progress) -> Result<TraceCounters, RenderError> {
        let needs = |v: &Visible| v.diffuse_albedo().max_element() > 0.0;
        let mut counters = self.ao.prepass_where(self.tracer, self.scene, options, progress, &needs)?;
        if let (Some(error), None) = (self.cache_error, self.cache.get()) {
            let mut cache = IrradianceCache::new(Quantity::Irradiance, error);
            let c = prepass_build(&mut cache, self.tracer, self.scene, options, progress, &needs, |pt, pixel, counters| {
                // Another stream than the occlusion records' of the same pixel.
                let mut sampler = Sampler::new(options.seed ^ RECORD_STREAM, pixel, 1);
                Some(self.irradiance_estimate(&pt.ctx, &mut sampler, counters))
            })?;
            counters.add(&c);
            let _ = self.cache.set(cache);
        }
        Ok(counters)
    }

    fn cache_stats(&self) -> Option<Value> {
        stats_object(&[self.ao.cache(), self.cache.get()])
    }
}
