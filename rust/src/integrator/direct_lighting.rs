//! The classic distribution ray tracer on UsdPreviewSurface's BSDF: direct light with ray-traced
//! shadows through every non-delta lobe, emission, mirror and glass recursion to a maximum
//! depth, glossy reflection and rough refraction by sampled rays, opacity cutouts, and ambient
//! occlusion by hemisphere rays.
//!
//! At a shading point (the camera ray's hit, or a secondary ray's):
//!
//! - **emission**: the material's `emissiveColor`, wherever a camera, mirror, glass or glossy
//!   ray hits it; lights themselves (area lights, a dome as the background) are seen by camera
//!   and delta rays through [`DirectLight::emitted`];
//! - **direct light** ([`DirectLight::estimate`]): light and BSDF samples with multiple importance
//!   sampling, through every non-delta lobe — the lambertian part is `directDiffuse`, the glossy
//!   highlight `specular`. Glossy rays therefore never add a light themselves (that light is
//!   already counted), only what surfaces send;
//! - **ambient occlusion**: the unoccluded fraction of the hemisphere times the diffuse albedo
//!   and `aoIntensity`, the light of a uniform white sky: `indirectDiffuse`. Taken on the camera
//!   ray's specular chain only (the hit it sees directly or through mirrors and glass), not at
//!   the end of glossy rays, whose blur would hide it at `aoSamples` times the cost;
//! - **delta lobes** (mirror, smooth glass, smooth clearcoat), while the depth is below
//!   `maxDepth`: every delta direction is traced — reflection and refraction both, Whitted's
//!   deterministic splitting — weighted by its Fresnel term, with Igehy's reflected or refracted
//!   differential (`reflection` / `refraction` rays);
//! - **rough non-diffuse lobes** (glossy reflection, rough refraction), while the depth is below
//!   `maxDepth`: `glossySamples` rays sampled from those lobes at the first non-mirror hit of a
//!   camera ray (its hit or one seen through mirrors and glass), 1 at hits further along a glossy
//!   path; each a `glossy` (or `refraction`) ray whose differential spreads over the lobe (the
//!   paper's §4.4) so it reads coarse tessellations. Only for materials whose rough specular is
//!   significant ([`crate::material::SurfaceCalls::glossy`]).
//!
//! **Opacity cutouts** (`opacityThreshold` > 0, opacity below it): there is no surface; every ray
//! continues through (keeping its kind and its differential), up to [`MAX_CUTOUTS`] surfaces.
//! Shadow and ambient-occlusion rays pass through too ([`super::visibility`]): a leaf card
//! shadows only where its mask leaves a leaf. Glass (`opacity` < 1 with no threshold) is a
//! surface to them: it blocks shadow rays, as refracting glass does in a classic ray tracer.

use glam::Vec3A;

use crate::bsdf::{BsdfSample, Lobe, PreviewSurfaceBsdf, Scattering};
use crate::differential::RayDifferential;
use crate::effects::{enabled, Effect};
use crate::options::RenderOptions;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

use super::direct_light::DirectLight;
use super::hemisphere::{self, Hemisphere, Visible};
pub use super::visibility::MAX_CUTOUTS;
use super::{normal_differentials, tessellation_error, Integrator, SampleValue, ShadingPoint};

/// A delta branch weaker than this (all channels) is not traced: it could not change a pixel
/// by more than that fraction of what it sees.
const MIN_DELTA_WEIGHT: f32 = 1e-4;

/// The classic distribution ray tracer (see the module doc). Every new ray gets its
/// differential from the paper's §4 rules, so its tessellation rate follows its width.
pub struct DirectLighting<'a> {
    pub tracer: &'a Tracer<'a>,
    pub scene: &'a Scene,
    /// Camera rays through a thin lens (the scene's camera has an f-stop).
    pub depth_of_field: bool,
    reflection: bool,
    refraction: bool,
    glossy: bool,
    direct: DirectLight,
    /// Ambient occlusion, when its effect is enabled (`samples` 0: off).
    ao: Hemisphere,
    ao_intensity: f32,
    max_depth: u32,
    glossy_samples: u32,
    /// The `tessError` AOV was asked for.
    tess_error: bool,
}

/// Radiance split the way the AOVs report it.
#[derive(Clone, Copy, Debug, Default)]
struct Light {
    emission: Vec3A,
    direct_diffuse: Vec3A,
    indirect_diffuse: Vec3A,
    specular: Vec3A,
}

impl Light {
    fn total(&self) -> Vec3A {
        self.emission + self.direct_diffuse + self.indirect_diffuse + self.specular
    }
}

/// Radiance along a ray with its parts, the AO fraction and diffuse albedo at its hit, and the
/// beam width and rate at the end of its specular chain (the debug AOVs follow mirrors, as the
/// paper's figure 2 does).
struct Shade {
    light: Light,
    ao: f32,
    albedo: Vec3A,
    /// The shading normal at the ray's own hit (render space, facing the ray; normal-mapped).
    normal: Vec3A,
    beam_width: f32,
    quads: u32,
}

/// How a ray came to a surface, which decides what is gathered there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Path {
    /// The camera ray, or one continuing it through mirrors and glass only.
    Specular,
    /// After a glossy bounce.
    Glossy,
}

impl<'a> DirectLighting<'a> {
    /// An integrator tracing only the `effects` the scene called for.
    pub fn new(tracer: &'a Tracer<'a>, scene: &'a Scene, effects: &[Effect], options: &RenderOptions) -> Self {
        DirectLighting {
            tracer,
            scene,
            depth_of_field: enabled(effects, "depth_of_field"),
            reflection: enabled(effects, "reflection"),
            refraction: enabled(effects, "refraction"),
            glossy: enabled(effects, "glossy"),
            direct: DirectLight::for_render(scene, effects, options),
            ao: Hemisphere::new(if enabled(effects, "ao") { options.ao_samples } else { 0 }, options),
            ao_intensity: options.ao_intensity,
            max_depth: options.max_depth,
            glossy_samples: options.glossy_samples.max(1),
            tess_error: options.aovs.contains(&crate::aov::Aov::TessError),
        }
    }

    /// Radiance and AOV values along a camera ray.
    pub fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        let far = self.scene.camera.clipping_range.1;
        let mut out = SampleValue::miss(far);
        let eye = ShadingPoint::at_camera(ray);
        let Some(v) = self.visible(*ray, None, counters) else {
            // Lights the camera looks at directly: a dome is the background.
            out.emission = self.direct.seen_by_camera(self.scene, &eye, ray.d, f32::INFINITY);
            out.set_color_from_parts();
            return out;
        };
        let shade = self.shade(&v, 0, Path::Specular, sampler, counters);
        let seen = self.direct.seen_by_camera(self.scene, &eye, ray.d, (v.hit.p - ray.o).length());
        out.set_hit(self.scene, &v.hit, shade.normal);
        out.emission = shade.light.emission + seen;
        out.direct_diffuse = shade.light.direct_diffuse;
        out.indirect_diffuse = shade.light.indirect_diffuse;
        out.specular = shade.light.specular;
        out.set_color_from_parts();
        out.ao = shade.ao;
        out.albedo = shade.albedo;
        out.beam_width = shade.beam_width;
        out.tess_rate = shade.quads as f32;
        if self.tess_error {
            // Newton's method on the limit surface: a few evaluations per pixel, only when asked.
            let err = tessellation_error(self.tracer, self.scene, &v.ray, &v.hit);
            let width = v.ray.beam_width(v.hit.t);
            out.tess_error = [err, if width > 0.0 { err / width } else { 0.0 }];
        }
        out
    }

    /// The first surface along `ray` that is not cut out, from hit `from` (secondary rays) or
    /// from the camera ([`hemisphere::visible`]).
    fn visible(&self, ray: Ray, from: Option<Hit>, counters: &mut TraceCounters) -> Option<Visible> {
        hemisphere::visible(self.tracer, self.scene, ray, from, counters)
    }

    fn shade(&self, v: &Visible, depth: u32, path: Path, sampler: &mut Sampler, counters: &mut TraceCounters) -> Shade {
        let (ray, hit) = (&v.ray, &v.hit);
        let wo = -ray.d;
        let bsdf = v.surface.bsdf(&v.sp);
        // The light sampler and shadow rays see the normal-mapped shading normal.
        let sp = ShadingPoint { ns: v.surface.ns, ..v.sp };
        let mut light = Light { emission: v.surface.inputs.emissive_color, ..Light::default() };
        let albedo = bsdf.diffuse_albedo(wo);
        if albedo.max_element() > 0.0 || bsdf.has_glossy() {
            let d = self.direct.estimate(self.tracer, self.scene, &sp, hit, &v.footprint, &bsdf, wo, sampler, counters);
            light.direct_diffuse = d.diffuse;
            light.specular = d.specular;
        }
        let mut ao = 0.0;
        if self.ao.samples > 0 && path == Path::Specular && albedo.max_element() > 0.0 {
            ao = self.ao.occlusion(self.tracer, &sp, hit, &v.footprint, sampler, counters);
            light.indirect_diffuse = albedo * (self.ao_intensity * ao);
        }
        let (mut beam_width, mut quads) = (ray.beam_width(hit.t), hit.quads);
        if depth < self.max_depth {
            let calls = v.surface.inputs.calls(&|_| false);
            let (dndx, dndy) = normal_differentials(self.tracer, self.scene, hit, &sp, &v.footprint);
            // Delta lobes: trace every one (reflection and refraction), strongest chain's
            // beam width reported.
            let mut strongest = 0.0;
            for lobe in bsdf.delta_lobes(wo).into_iter().flatten() {
                let refracts = lobe.lobe == Lobe::Transmission;
                if (refracts && !self.refraction) || (!refracts && !self.reflection) || lobe.weight.max_element() < MIN_DELTA_WEIGHT {
                    continue;
                }
                let r = self.delta_ray(ray, hit, &sp, &v.footprint, &lobe, &bsdf, dndx, dndy, counters);
                match self.visible(r, Some(*hit), counters) {
                    Some(next) => {
                        let s = self.shade(&next, depth + 1, path, sampler, counters);
                        let lit = s.light.total() + self.direct.emitted(self.scene, &sp, r.d, (next.hit.p - r.o).length(), None);
                        light.specular += lobe.weight * lit;
                        let w = lobe.weight.max_element();
                        if w > strongest {
                            strongest = w;
                            (beam_width, quads) = (s.beam_width, s.quads);
                        }
                    }
                    None => light.specular += lobe.weight * self.direct.emitted(self.scene, &sp, r.d, f32::INFINITY, None),
                }
            }
            // Rough non-diffuse lobes: glossy rays.
            if self.glossy && calls.glossy && bsdf.has_glossy() {
                let n = if path == Path::Specular { self.glossy_samples } else { 1 };
                let mut sum = Vec3A::ZERO;
                for _ in 0..n {
                    let u = [sampler.next_f32(), sampler.next_f32(), sampler.next_f32()];
                    let Some(g) = bsdf.sample_glossy(wo, u) else { continue };
                    let specular_diff = self.delta_differential(ray, &sp, &v.footprint, &g.sample, &bsdf, dndx, dndy, counters);
                    let (diff, clamped) = specular_diff.glossy_checked(g.sample.wi, g.lobe_half_angle_rad, n);
                    counters.differential_clamps += u64::from(clamped);
                    let kind = if g.sample.lobe == Lobe::Transmission { RayKind::Refraction } else { RayKind::Glossy };
                    let r = self.spawn(hit, &sp, g.sample.wi, diff, kind, ray.time);
                    // Lights are not added: direct light's BSDF samples count them (MIS).
                    if let Some(next) = self.visible(r, Some(*hit), counters) {
                        sum += g.sample.weight * self.shade(&next, depth + 1, Path::Glossy, sampler, counters).light.total();
                    }
                }
                light.specular += sum / n as f32;
            }
        }
        Shade { light, ao, albedo, normal: sp.ns, beam_width, quads }
    }

    /// A new ray from the shading point toward `wi`, offset off the surface on `wi`'s side.
    fn spawn(&self, hit: &Hit, sp: &ShadingPoint, wi: Vec3A, diff: RayDifferential, kind: RayKind, time: f32) -> Ray {
        Ray { o: offset_origin(sp.p, hit.p_error, sp.ng, wi), d: wi, t_min: 0.0, t_max: f32::INFINITY, diff, kind, time }
    }

    /// The ray of a delta lobe: `reflection` with Igehy's reflected differential, or
    /// `refraction` with the refracted one.
    #[allow(clippy::too_many_arguments)]
    fn delta_ray(
        &self,
        ray: &Ray,
        hit: &Hit,
        sp: &ShadingPoint,
        footprint: &RayDifferential,
        lobe: &BsdfSample,
        bsdf: &PreviewSurfaceBsdf,
        dndx: Vec3A,
        dndy: Vec3A,
        counters: &mut TraceCounters,
    ) -> Ray {
        let diff = self.delta_differential(ray, sp, footprint, lobe, bsdf, dndx, dndy, counters);
        let kind = if lobe.lobe == Lobe::Transmission { RayKind::Refraction } else { RayKind::Reflection };
        self.spawn(hit, sp, lobe.wi, diff, kind, ray.time)
    }

    /// The specular differential of a scattered direction: Igehy's reflection, or refraction
    /// for a transmitted one (reflection where the mean surface would reflect totally).
    #[allow(clippy::too_many_arguments)]
    fn delta_differential(
        &self,
        ray: &Ray,
        sp: &ShadingPoint,
        footprint: &RayDifferential,
        lobe: &BsdfSample,
        bsdf: &PreviewSurfaceBsdf,
        dndx: Vec3A,
        dndy: Vec3A,
        counters: &mut TraceCounters,
    ) -> RayDifferential {
        if lobe.lobe == Lobe::Transmission {
            // The normal faces the incident ray, so the index ratio is far over near: the BSDF's η.
            if let Some((diff, clamped)) = footprint.refract_checked(ray.d, sp.ns, dndx, dndy, bsdf.eta()) {
                counters.differential_clamps += u64::from(clamped);
                return diff;
            }
        }
        let (diff, clamped) = footprint.reflect_checked(ray.d, sp.ns, dndx, dndy);
        counters.differential_clamps += u64::from(clamped);
        diff
    }
}

impl Integrator for DirectLighting<'_> {
    fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        DirectLighting::sample(self, ray, sampler, counters)
    }

    fn depth_of_field(&self) -> bool {
        self.depth_of_field
    }

    fn scene(&self) -> &Scene {
        self.scene
    }

    /// The ambient-occlusion cache's records, when `irradianceCache` is on.
    fn prepass(
        &self,
        options: &RenderOptions,
        progress: &dyn crate::progress::Progress,
    ) -> Result<TraceCounters, crate::error::RenderError> {
        self.ao.prepass(self.tracer, self.scene, options, progress)
    }

    fn cache_stats(&self) -> Option<serde_json::Value> {
        self.ao.cache_stats()
    }
}
