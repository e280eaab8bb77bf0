//! The classic distribution ray tracer: direct light with ray-traced shadows, mirror reflection
//! to a maximum depth, and ambient occlusion by hemisphere rays.

use glam::Vec3A;

use crate::differential::{dndu_dndv, reflect_direction, RayDifferential, UvDifferentials};
use crate::effects::{enabled, Effect};
use crate::material::Input;
use crate::options::RenderOptions;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

use super::direct::DirectLight;
use super::hemisphere::Hemisphere;
use super::{shading_point, tessellation_error, Integrator, SampleValue, ShadingPoint};

/// The classic distribution ray tracer: direct light with ray-traced shadows, perfect mirror
/// reflection to a maximum depth, and ambient occlusion by hemisphere rays. Every new ray gets
/// its differential from the paper's §4 rules, so its tessellation rate follows its width.
pub struct DirectLighting<'a> {
    pub tracer: &'a Tracer<'a>,
    pub scene: &'a Scene,
    /// Camera rays through a thin lens (the scene's camera has an f-stop).
    pub depth_of_field: bool,
    reflection: bool,
    direct: DirectLight,
    /// Ambient occlusion, when its effect is enabled (`samples` 0: off).
    ao: Hemisphere,
    ao_intensity: f32,
    max_depth: u32,
    /// The `tessError` AOV was asked for.
    tess_error: bool,
}

/// Radiance along a ray, the AO fraction at its hit, and the beam width and rate at the end of
/// its specular chain (the debug AOVs follow mirrors, as the paper's figure 2 does).
struct Shade {
    color: Vec3A,
    ao: f32,
    /// The shading normal at the ray's own hit (render space, facing the ray).
    normal: Vec3A,
    beam_width: f32,
    quads: u32,
}

impl<'a> DirectLighting<'a> {
    /// An integrator tracing only the `effects` the scene called for.
    pub fn new(tracer: &'a Tracer<'a>, scene: &'a Scene, effects: &[Effect], options: &RenderOptions) -> Self {
        DirectLighting {
            tracer,
            scene,
            depth_of_field: enabled(effects, "depth_of_field"),
            reflection: enabled(effects, "reflection"),
            direct: DirectLight { shadows: enabled(effects, "shadows"), shadow_samples: options.shadow_samples },
            ao: Hemisphere { samples: if enabled(effects, "ao") { options.ao_samples } else { 0 }, distance: options.ao_distance },
            ao_intensity: options.ao_intensity,
            max_depth: options.max_depth,
            tess_error: options.aovs.iter().any(|a| a == "tessError"),
        }
    }

    /// Radiance and AOV values along a camera ray.
    pub fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue {
        let far = self.scene.camera.clipping_range.1;
        let mut out = SampleValue { depth: far, prim_id: -1.0, instance_id: -1.0, ..Default::default() };
        let Some(hit) = self.tracer.intersect(ray, counters) else {
            return out;
        };
        let shade = self.shade(ray, &hit, 0, sampler, counters);
        out.color = shade.color;
        out.ao = shade.ao;
        out.alpha = 1.0;
        out.depth = self.scene.camera.depth(hit.p);
        out.normal = shade.normal;
        out.prim_id = hit.patch as f32;
        out.instance_id = hit.instance_id as f32;
        out.beam_width = shade.beam_width;
        out.tess_rate = shade.quads as f32;
        if self.tess_error {
            // Newton's method on the limit surface: a few evaluations per pixel, only when asked.
            let err = tessellation_error(self.tracer, self.scene, ray, &hit);
            let width = ray.beam_width(hit.t);
            out.tess_error = [err, if width > 0.0 { err / width } else { 0.0 }];
        }
        out
    }

    fn radiance(&self, ray: &Ray, from: &Hit, depth: u32, sampler: &mut Sampler, counters: &mut TraceCounters) -> Option<Shade> {
        let hit = self.tracer.intersect_from(ray, from, counters)?;
        Some(self.shade(ray, &hit, depth, sampler, counters))
    }

    fn shade(&self, ray: &Ray, hit: &Hit, depth: u32, sampler: &mut Sampler, counters: &mut TraceCounters) -> Shade {
        let sp = shading_point(self.tracer, self.scene, ray, hit);
        let material = self.scene.material_at(hit.mesh as usize, hit.patch as usize);
        let (footprint, clamped) = ray.diff.transfer_checked(ray.d, hit.t, sp.ng);
        counters.differential_clamps += u64::from(clamped);
        let mut color = Vec3A::ZERO;
        let mut ao = 0.0;
        let (mut beam_width, mut quads) = (ray.beam_width(hit.t), hit.quads);
        let albedo = match material.texture(Input::DiffuseColor) {
            None => material.surface.diffuse_color,
            Some(tex) => self.texture_color(tex, hit, &sp, &footprint),
        };
        // Until the BSDF lands: a smooth specular layer is a mirror of its normal-incidence colour.
        let s = &material.surface;
        let mirror = if s.roughness > 0.0 {
            Vec3A::ZERO
        } else if s.use_specular_workflow {
            s.specular_color
        } else {
            s.diffuse_color * s.metallic
        };
        if albedo.max_element() > 0.0 {
            color += albedo * self.direct.estimate(self.tracer, self.scene, &sp, hit, &footprint, sampler, counters);
            if self.ao.samples > 0 {
                ao = self.ao.occlusion(self.tracer, &sp, hit, &footprint, sampler, counters);
                color += albedo * (self.ao_intensity * ao);
            }
        }
        if self.reflection && mirror.max_element() > 0.0 && depth < self.max_depth {
            let (dndx, dndy) = self.normal_differentials(hit, &sp, &footprint);
            let wr = reflect_direction(ray.d, sp.ns);
            if wr.dot(sp.ng) > 0.0 {
                let (diff, clamped) = footprint.reflect_checked(ray.d, sp.ns, dndx, dndy);
                counters.differential_clamps += u64::from(clamped);
                let r = Ray {
                    o: offset_origin(sp.p, hit.p_error, sp.ng, wr),
                    d: wr,
                    t_min: 0.0,
                    t_max: f32::INFINITY,
                    diff,
                    kind: RayKind::Reflection,
                    time: ray.time,
                };
                if let Some(reflected) = self.radiance(&r, hit, depth + 1, sampler, counters) {
                    color += mirror * reflected.color;
                    (beam_width, quads) = (reflected.beam_width, reflected.quads);
                }
            }
        }
        Shade { color, ao, normal: sp.ns, beam_width, quads }
    }

    /// A textured colour at the hit, filtered over the footprint the ray differential gives:
    /// (du, dv)/(dx, dy) by least squares on the tangent plane, chained through the surface's
    /// d(st)/du, d(st)/dv (the paper's §2.6 and §6.3.3: wide rays read coarse MIP levels).
    fn texture_color(&self, tex: &crate::material::TexturedColor, hit: &Hit, sp: &ShadingPoint, footprint: &RayDifferential) -> Vec3A {
        let mesh = &self.scene.meshes[hit.mesh as usize];
        let Some((st, dst_du, dst_dv)) = mesh.surface.face_varying(tex.st_channel, hit.patch as usize, hit.u, hit.v) else {
            return tex.eval(None, [0.0; 2], [0.0; 2]);
        };
        let uv = UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv);
        let dx = [dst_du[0] * uv.dudx + dst_dv[0] * uv.dvdx, dst_du[1] * uv.dudx + dst_dv[1] * uv.dvdx];
        let dy = [dst_du[0] * uv.dudy + dst_dv[0] * uv.dvdy, dst_du[1] * uv.dudy + dst_dv[1] * uv.dvdy];
        tex.eval(Some(st), dx, dy)
    }

    /// dN/dx, dN/dy at the hit from the limit surface's second derivatives (Weingarten) and
    /// the footprint: what makes convex mirrors widen beams (the paper's §4.2).
    fn normal_differentials(&self, hit: &Hit, sp: &ShadingPoint, footprint: &RayDifferential) -> (Vec3A, Vec3A) {
        let mesh = &self.scene.meshes[hit.mesh as usize];
        let s = mesh.surface.evaluate(hit.patch as usize, hit.u, hit.v);
        let m = self.tracer.hit_render_from_object(hit);
        let w = |v: Vec3A| m.transform_vector3a(v);
        let (mut dndu, mut dndv) = dndu_dndv(sp.dpdu, sp.dpdv, w(s.dpduu), w(s.dpduv), w(s.dpdvv));
        // dndu_dndv belongs to the normal dpdu × dpdv; the shading normal may be its negative.
        if sp.dpdu.cross(sp.dpdv).dot(sp.ns) < 0.0 {
            dndu = -dndu;
            dndv = -dndv;
        }
        UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv).chain(dndu, dndv)
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
}
