//! Unidirectional path tracing (issue 7's integrator (d)): from each camera hit, one path of
//! BSDF-sampled bounces with next-event estimation at every vertex and Russian roulette.
//!
//! **The estimator.** Light reaches a path vertex from the scene's lights two ways, combined by
//! multiple importance sampling (Veach's power heuristic): `shadowSamples` light samples
//! ([`DirectLight::estimate_lights`], the paper's §4.3 light choice), and the one BSDF-sampled
//! ray that continues the path, which adds the lights it meets before its first hit
//! ([`DirectLight::emitted`], an area light crossed or a dome when it escapes), each weighted
//! against the light samples' density there. So no light is counted twice and neither strategy's
//! weak cases (a small light seen by a rough surface, a big light seen by a glossy one) are
//! noisy. Delta directions (mirror, smooth glass, the camera ray) cannot be found by a light
//! sample: lights they meet count in full. At the last vertex no ray follows, so it takes the
//! full estimator ([`DirectLight::estimate`], with its own BSDF samples). Emissive surfaces
//! (`emissiveColor`) are not lights: no light sample finds them, so every path that hits one
//! counts its emission in full, whatever bounce reached it.
//!
//! **Cut-outs** (`opacityThreshold`): a ray meeting a cut-out goes on through it as the same ray,
//! so the lights it meets are weighted from the vertex that sampled it, over its whole length;
//! next-event estimation's shadow rays pass the same cut-outs ([`super::visibility`]).
//!
//! **Length.** `max_depth` bounces after the camera hit, every vertex lit by next-event
//! estimation: `max_depth = 0` is direct lighting. After `russian_roulette_depth` bounces a
//! path continues with probability q = min(1, max component of its throughput) and is divided
//! by q: dim paths end early, the expectation is unchanged.
//!
//! **Differentials (the paper's §4).** A delta bounce gets the specular differential, narrow
//! and coherent (§4.2: Igehy's reflection and refraction with the surface's curvature); a
//! diffuse or glossy bounce gets the path differential of Suykens and Willems (§2.5,
//! [`crate::differential::RayDifferential::path`]): the hemisphere spread `sqrt(1 / p(ω))` of
//! the sampled density, times the sample spacing of the pixel's paths at that depth. At depth 1
//! that is §4.6's hemisphere spread for `samples` rays; deeper bounces are wider, so they read
//! coarse tessellations, which is the point of the multiresolution geometry cache. The spread
//! follows the density the direction was actually drawn with, so a glossy bounce from a narrow
//! GGX lobe (high density) is narrow and a diffuse one wide: §4.4's glossy rule (the lobe's
//! solid angle shared by its rays) for an importance-sampled lobe of any shape. Each ray is
//! counted by its kind (`render.rays.diffuse`, `glossy`, `reflection`, `refraction`), which
//! also sets its incoherent tessellation factor.

use glam::Vec3A;

use crate::bsdf::{BsdfSample, Lobe, Scattering};
use crate::differential::RayDifferential;
use crate::effects::{enabled, Effect};
use crate::error::RenderError;
use crate::options::RenderOptions;
use crate::progress::Progress;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

use super::direct_light::DirectLight;
use super::hemisphere::Hemisphere;
use super::visibility::MAX_CUTOUTS;
use super::{normal_differentials, shading_point, tessellation_error, Integrator, SampleValue, ShadingPoint};

/// The path tracer. Construct with [`PathTracer::new`]; chosen by `integrator = path`
/// ([`crate::integrator::select`]).
pub struct PathTracer<'a> {
    pub tracer: &'a Tracer<'a>,
    pub scene: &'a Scene,
    /// Camera rays through a thin lens (the scene's camera has an f-stop).
    pub depth_of_field: bool,
    direct: DirectLight,
    /// Bounces after the camera hit (`maxDepth`).
    pub max_depth: u32,
    /// Bounces before Russian roulette may end a path; `max_depth` or more: never.
    pub russian_roulette_depth: u32,
    /// Paths per pixel (`samples`): the path differential's sample count.
    samples: u32,
    /// Ambient occlusion for the `ao` AOV at the camera hit only (the colour is path traced).
    ao: Hemisphere,
    /// The `tessError` AOV was asked for.
    tess_error: bool,
}

/// Where a path is: the ray it travels, the surface it left, and what its light is worth.
struct Segment {
    /// The ray, or its part beyond the opacity cut-outs it has passed.
    ray: Ray,
    /// The hit and shading point the ray left (`None`: the camera ray).
    from: Option<(Hit, ShadingPoint)>,
    /// Where the ray started, for the lights it meets ([`DirectLight::emitted`]): the shading
    /// point it left, or the camera's position.
    eye: ShadingPoint,
    /// The last cut-out the ray passed, which `ray` leaves, and the distance along the ray
    /// from `eye` to it (render units): the ray goes on as one ray, so lights are weighted from
    /// where it was sampled, over its whole length.
    through: Option<(Hit, f32)>,
    /// The product of the BSDF weights `f·|cos|/pdf` and Russian-roulette factors so far.
    throughput: Vec3A,
    /// The BSDF density the ray's direction was drawn with, for the multiple-importance weight
    /// of the lights it meets; `None` (camera ray, delta bounce): no light sample could have
    /// found them, so they count in full.
    bsdf_pdf: Option<f32>,
    /// Every bounce so far was a delta one: the debug AOVs (beam width, rate) follow the ray.
    specular_chain: bool,
}

impl<'a> PathTracer<'a> {
    /// A path tracer over `tracer`'s scene, tracing the `effects` the scene and settings called
    /// for (shadow rays only toward lights that cast shadows; the `ao` AOV only with AO samples).
    pub fn new(tracer: &'a Tracer<'a>, scene: &'a Scene, effects: &[Effect], options: &RenderOptions) -> Self {
        PathTracer {
            tracer,
            scene,
            depth_of_field: enabled(effects, "depth_of_field"),
            direct: DirectLight::for_render(scene, effects, options),
            max_depth: options.max_depth,
            russian_roulette_depth: options.russian_roulette_depth,
            samples: options.samples,
            ao: Hemisphere::new(if enabled(effects, "ao") { options.ao_samples } else { 0 }, options),
            tess_error: options.aovs.contains(&crate::aov::Aov::TessError),
        }
    }

    /// Radiance and AOV values along a camera ray. The colour is the sum of its AOV parts:
    /// `emission` (emissive surfaces and lights the camera sees), `directDiffuse` (the lights'
    /// light through the camera hit's diffuse lobe: its light samples and its first BSDF ray's
    /// weighted light), `indirectDiffuse` (everything else arriving through a diffuse first
    /// bounce) and `specular` (everything through the other lobes).
    pub fn sample(&self, camera_ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        let far = self.scene.camera.clipping_range.1;
        let mut out = SampleValue::miss(far);
        let mut seg = Segment {
            ray: *camera_ray,
            from: None,
            eye: ShadingPoint::at_camera(camera_ray),
            through: None,
            throughput: Vec3A::ONE,
            bsdf_pdf: None,
            specular_chain: true,
        };
        // Where light found after the camera hit goes, by the lobe of the first bounce.
        let mut first_lobe: Option<Lobe> = None;
        let mut bounce = 0u32;
        let mut cutouts = 0u32;
        loop {
            let hit = match (&seg.through, &seg.from) {
                (Some((cut, _)), _) | (None, Some((cut, _))) => self.tracer.intersect_from(&seg.ray, cut, counters),
                (None, None) => self.tracer.intersect(&seg.ray, counters),
            };
            let ray = seg.ray;
            let passed = seg.through.map_or(0.0, |(_, t)| t);
            let mut found = None;
            if let Some(hit) = hit {
                let sp = shading_point(self.tracer, self.scene, &ray, &hit);
                let (footprint, clamped) = ray.diff.transfer_checked(ray.d, hit.t, sp.ng);
                counters.differential_clamps += u64::from(clamped);
                let mesh = &self.scene.meshes[hit.mesh as usize];
                let material = self.scene.material_at(hit.mesh as usize, hit.patch as usize);
                let surface = material.resolve(mesh.surface.as_ref(), &hit, &sp, &footprint);
                if surface.cut_out() {
                    // No surface here: the same ray goes on from the hit, its beam as it arrived.
                    cutouts += 1;
                    if cutouts > MAX_CUTOUTS {
                        counters.cutout_limit += 1;
                        break;
                    }
                    counters.cutout_passes += 1;
                    let o = offset_origin(sp.p, hit.p_error, sp.ng, ray.d);
                    seg.ray = Ray { o, t_min: 0.0, t_max: ray.t_max - hit.t, diff: footprint, ..ray };
                    seg.through = Some((hit, passed + hit.t));
                    continue;
                }
                found = Some((hit, sp, footprint, surface));
            }
            // The lights this ray meets before its hit: next-event estimation at the vertex it
            // left found them too, so they are weighted against it (or count in full from the
            // camera and after delta bounces). Measured from where the ray started, past any
            // cut-outs: one ray, one weight.
            let t_hit = found.as_ref().map_or(f32::INFINITY, |(h, ..)| passed + h.t);
            let lights = seg.throughput
                * if bounce == 0 {
                    self.direct.seen_by_camera(self.scene, &seg.eye, ray.d, t_hit)
                } else {
                    self.direct.emitted(self.scene, &seg.eye, ray.d, t_hit, seg.bsdf_pdf)
                };
            match first_lobe {
                None => out.emission += lights,
                // The first BSDF ray's share of the camera hit's direct light.
                Some(Lobe::Diffuse) if bounce == 1 => out.direct_diffuse += lights,
                Some(lobe) => *part(&mut out, lobe) += lights,
            }
            let Some((hit, sp, footprint, surface)) = found else { break };
            // Shade with the (normal-mapped) shading normal from here on.
            let sp = ShadingPoint { ns: surface.ns, ..sp };
            let bsdf = surface.bsdf(&sp);
            let wo = -ray.d;
            if bounce == 0 {
                self.camera_aovs(&mut out, &ray, &hit, &sp, &footprint, sampler, counters);
                out.albedo = bsdf.diffuse_albedo(wo);
            }
            if seg.specular_chain {
                out.beam_width = ray.beam_width(hit.t);
                out.tess_rate = hit.quads as f32;
            }
            // Emissive surfaces are not lights: only paths find them, so they count in full.
            let emitted = seg.throughput * surface.inputs.emissive_color;
            match first_lobe {
                None => out.emission += emitted,
                Some(lobe) => *part(&mut out, lobe) += emitted,
            }
            let last = bounce >= self.max_depth;
            let direct = if last {
                // No BSDF ray follows to find the lights' share that multiple importance
                // sampling gives it: take the full estimator.
                self.direct.estimate(self.tracer, self.scene, &sp, &hit, &footprint, &bsdf, wo, sampler, counters)
            } else {
                self.direct.estimate_lights(self.tracer, self.scene, &sp, &hit, &footprint, &bsdf, wo, sampler, counters)
            };
            match first_lobe {
                None => {
                    out.direct_diffuse += direct.diffuse;
                    out.specular += direct.specular;
                }
                Some(lobe) => *part(&mut out, lobe) += seg.throughput * direct.total(),
            }
            if last {
                break;
            }
            let u = [sampler.next_f32(), sampler.next_f32(), sampler.next_f32()];
            let Some(bs) = bsdf.sample(wo, u) else { break };
            if !(bs.weight.is_finite() && bs.weight.max_element() > 0.0) {
                break;
            }
            let mut throughput = seg.throughput * bs.weight;
            bounce += 1;
            if bounce > self.russian_roulette_depth {
                // Survive with q = min(1, max throughput), divide by q: unbiased, and a path
                // whose throughput fell to a few percent costs a few percent of a bounce.
                let q = throughput.max_element().min(1.0);
                if sampler.next_f32() >= q {
                    break;
                }
                throughput /= q;
            }
            let Some(next) = self.bounce_ray(&ray, &hit, &sp, &footprint, &bs, bounce, counters) else { break };
            first_lobe.get_or_insert(bs.lobe);
            seg = Segment {
                ray: next,
                from: Some((hit, sp)),
                eye: sp,
                through: None,
                throughput,
                bsdf_pdf: (!bs.delta).then_some(bs.pdf),
                specular_chain: seg.specular_chain && bs.delta,
            };
        }
        out.set_color_from_parts();
        out
    }

    /// The camera hit's AOVs (alpha, depth, position, normals, ids, `tessError`, `ao`).
    #[allow(clippy::too_many_arguments)]
    fn camera_aovs(
        &self,
        out: &mut SampleValue,
        ray: &Ray,
        hit: &Hit,
        sp: &ShadingPoint,
        footprint: &RayDifferential,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) {
        out.set_hit(self.scene, hit, sp.ns);
        if self.tess_error {
            let err = tessellation_error(self.tracer, self.scene, ray, hit);
            let width = ray.beam_width(hit.t);
            out.tess_error = [err, if width > 0.0 { err / width } else { 0.0 }];
        }
        if self.ao.samples > 0 {
            out.ao = self.ao.occlusion(self.tracer, sp, hit, footprint, sampler, counters);
        }
    }

    /// The next ray of the path, in the sampled direction, with its differential and kind.
    #[allow(clippy::too_many_arguments)]
    fn bounce_ray(
        &self,
        ray: &Ray,
        hit: &Hit,
        sp: &ShadingPoint,
        footprint: &RayDifferential,
        bs: &BsdfSample,
        depth: u32,
        counters: &mut TraceCounters,
    ) -> Option<Ray> {
        let kind = match bs.lobe {
            Lobe::Diffuse => RayKind::Diffuse,
            Lobe::Glossy => RayKind::Glossy,
            Lobe::Specular => RayKind::Reflection,
            Lobe::Transmission => RayKind::Refraction,
        };
        let (diff, clamped) = if bs.delta {
            let (dndx, dndy) = normal_differentials(self.tracer, self.scene, hit, sp, footprint);
            if bs.lobe == Lobe::Transmission {
                // `refract` takes the index of the side the normal points away from over the
                // side it points to; the shading normal faces the incident ray, so that is
                // η_transmitted / η_incident = 1 / bs.eta.
                footprint.refract_checked(ray.d, sp.ns, dndx, dndy, 1.0 / bs.eta)?
            } else {
                footprint.reflect_checked(ray.d, sp.ns, dndx, dndy)
            }
        } else {
            footprint.path_checked(bs.wi, bs.pdf, depth, self.samples)
        };
        counters.differential_clamps += u64::from(clamped);
        Some(Ray {
            o: offset_origin(sp.p, hit.p_error, sp.ng, bs.wi),
            d: bs.wi,
            t_min: 0.0,
            t_max: f32::INFINITY,
            diff,
            kind,
            time: ray.time,
        })
    }
}

/// The AOV that light arriving through a first bounce of `lobe` goes to (beyond the direct
/// light of a diffuse first bounce, which is `directDiffuse`).
fn part(out: &mut SampleValue, lobe: Lobe) -> &mut Vec3A {
    match lobe {
        Lobe::Diffuse => &mut out.indirect_diffuse,
        Lobe::Glossy | Lobe::Specular | Lobe::Transmission => &mut out.specular,
    }
}

impl Integrator for PathTracer<'_> {
    fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        PathTracer::sample(self, ray, sampler, counters)
    }

    fn depth_of_field(&self) -> bool {
        self.depth_of_field
    }

    fn scene(&self) -> &Scene {
        self.scene
    }

    /// The occlusion cache of the `ao` AOV, when `irradianceCache` is on.
    fn prepass(&self, options: &RenderOptions, progress: &dyn Progress) -> Result<TraceCounters, RenderError> {
        self.ao.prepass(self.tracer, self.scene, options, progress)
    }

    fn cache_stats(&self) -> Option<serde_json::Value> {
        self.ao.cache_stats()
    }
}
