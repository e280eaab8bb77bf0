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
use crate::ray::{offset_origin, Ray};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::{TraceCounters, Tracer};

use super::hemisphere::Hemisphere;
use super::{shading_point, tessellation_error, Integrator, SampleValue, ShadingPoint};

/// Cutout surfaces a camera ray passes through before it gives up (a bound, not physics).
const MAX_CUTOUTS: u32 = 64;

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
            tess_error: options.aovs.iter().any(|a| a == "tessError"),
        }
    }

    /// Radiance and AOV values along a camera ray.
    pub fn sample(&self, camera_ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        let mut out = SampleValue::miss(self.scene.camera.clipping_range.1);
        let mut ray = *camera_ray;
        let mut from = None;
        for _ in 0..=MAX_CUTOUTS {
            let hit = match &from {
                None => self.tracer.intersect(&ray, counters),
                Some(f) => self.tracer.intersect_from(&ray, f, counters),
            };
            let Some(hit) = hit else { break };
            let sp = shading_point(self.tracer, self.scene, &ray, &hit);
            let (footprint, clamped) = ray.diff.transfer_checked(ray.d, hit.t, sp.ng);
            counters.differential_clamps += u64::from(clamped);
            let mesh = &self.scene.meshes[hit.mesh as usize];
            let material = self.scene.material_at(hit.mesh as usize, hit.patch as usize);
            let surface = material.resolve(mesh.surface.as_ref(), &hit, &sp, &footprint);
            if surface.cut_out() {
                // No surface here: the same ray goes on from the hit, its beam as it arrived.
                let o = offset_origin(sp.p, hit.p_error, sp.ng, ray.d);
                ray = Ray { o, t_min: 0.0, t_max: ray.t_max - hit.t, diff: footprint, ..ray };
                from = Some(hit);
                continue;
            }
            let sp = ShadingPoint { ns: surface.ns, ..sp };
            out.set_hit(self.scene, &hit, sp.ns);
            out.albedo = crate::bsdf::Scattering::diffuse_albedo(&surface.bsdf(&sp), -ray.d);
            out.ao = self.ao.occlusion(self.tracer, &sp, &hit, &footprint, sampler, counters);
            out.indirect_diffuse = out.albedo * (self.intensity * out.ao);
            out.emission = surface.inputs.emissive_color;
            out.beam_width = ray.beam_width(hit.t);
            out.tess_rate = hit.quads as f32;
            if self.tess_error {
                let err = tessellation_error(self.tracer, self.scene, &ray, &hit);
                let width = ray.beam_width(hit.t);
                out.tess_error = [err, if width > 0.0 { err / width } else { 0.0 }];
            }
            break;
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
