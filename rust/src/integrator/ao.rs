//! The ambient-occlusion integrator (issue 7's integrator (b), `integrator = ao`): every
//! surface lit by a uniform white sky of radiance `aoIntensity`, occluded within `aoDistance`.
//!
//! Colour = unoccluded fraction × diffuse albedo × `aoIntensity`, plus the surface's emission:
//! what the surface's diffuse lobe reflects toward the camera under that sky, with the light
//! other surfaces would bounce ignored. No lights, shadows, reflections or indirect light; the
//! hemisphere rays are §4.6's wide ones ([`Hemisphere::occlusion`]), interpolated from the
//! occlusion cache when `irradianceCache` is on. The AOVs: `ao` the fraction, `albedo` the
//! diffuse albedo toward the camera, `indirectDiffuse` the sky's light, `emission` the rest.

use crate::effects::{enabled, Effect};
use crate::error::RenderError;
use crate::options::RenderOptions;
use crate::progress::Progress;
use crate::ray::Ray;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::{TraceCounters, Tracer};

use super::hemisphere::{visible, Hemisphere};
use super::{tessellation_error, Integrator, SampleValue};

/// Ambient occlusion only. Construct with [`AmbientOcclusion::new`].
pub struct AmbientOcclusion<'a> {
    pub tracer: &'a Tracer<'a>,
    pub scene: &'a Scene,
    /// Camera rays through a thin lens (the scene's camera has an f-stop).
    pub depth_of_field: bool,
    ao: Hemisphere,
    /// The sky's radiance.
    intensity: f32,
    /// The `tessError` AOV was asked for.
    tess_error: bool,
}

impl<'a> AmbientOcclusion<'a> {
    /// An AO integrator with `options.ao_samples` hemisphere rays per camera hit.
    pub fn new(tracer: &'a Tracer<'a>, scene: &'a Scene, effects: &[Effect], options: &RenderOptions) -> Self {
        AmbientOcclusion {
            tracer,
            scene,
            depth_of_field: enabled(effects, "depth_of_field"),
            ao: Hemisphere::new(options.ao_samples, options),
            intensity: options.ao_intensity,
            tess_error: options.aovs.contains(&crate::aov::Aov::TessError),
        }
    }

    /// Radiance and AOV values along a camera ray.
    pub fn sample(&self, camera_ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        let mut out = SampleValue::miss(self.scene.camera.clipping_range.1);
        // The surface the camera ray sees, past opacity cut-outs.
        if let Some(v) = visible(self.tracer, self.scene, *camera_ray, None, counters) {
            let (ray, hit) = (&v.ray, &v.hit);
            out.set_hit(self.scene, hit, v.sp.ns);
            out.albedo = v.diffuse_albedo();
            out.ao = self.ao.occlusion(self.tracer, &v.sp, hit, &v.footprint, sampler, counters);
            out.indirect_diffuse = out.albedo * (self.intensity * out.ao);
            out.emission = v.surface.inputs.emissive_color;
            out.beam_width = ray.beam_width(hit.t);
            out.tess_rate = hit.quads as f32;
            if self.tess_error {
                let err = tessellation_error(self.tracer, self.scene, ray, hit);
                let width = ray.beam_width(hit.t);
                out.tess_error = [err, if width > 0.0 { err / width } else { 0.0 }];
            }
        }
        out.set_color_from_parts();
        out
    }
}

impl Integrator for AmbientOcclusion<'_> {
    fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        AmbientOcclusion::sample(self, ray, sampler, counters)
    }

    fn depth_of_field(&self) -> bool {
        self.depth_of_field
    }

    fn scene(&self) -> &Scene {
        self.scene
    }

    /// The occlusion cache, when `irradianceCache` is on.
    fn prepass(&self, options: &RenderOptions, progress: &dyn Progress) -> Result<TraceCounters, RenderError> {
        self.ao.prepass(self.tracer, self.scene, options, progress)
    }

    fn cache_stats(&self) -> Option<serde_json::Value> {
        self.ao.cache_stats()
    }
}
