//! Integrators. For now the classic one: direct lighting of lambertian surfaces with ray-traced
//! shadows toward the lights that cast them. Distribution effects come with the light-transport
//! work; everything here already carries ray differentials so they can.

use glam::Vec3A;

use crate::differential::{dndu_dndv, reflect_direction, RayDifferential, UvDifferentials};
use crate::effects::{enabled, Effect};
use crate::options::RenderOptions;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::{cosine_hemisphere, frame, Sampler};
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

/// Everything one camera sample yields, one field per AOV.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleValue {
    /// Linear RGB radiance.
    pub color: Vec3A,
    /// 1 where a surface was hit.
    pub alpha: f32,
    /// Camera-space depth along the view axis, scene units (the far clip when nothing is hit).
    pub depth: f32,
    /// World-space unit shading normal, facing the camera.
    pub normal: Vec3A,
    /// Patch index within the mesh (−1 for none).
    pub prim_id: f32,
    pub instance_id: f32,
    /// World-space beam width at the hit that ends the camera ray's specular chain: the camera
    /// ray's own hit on a matte surface, the reflected ray's hit seen in a mirror (the paper's
    /// figure 2).
    pub beam_width: f32,
    /// `tessError`: distance along the camera ray between its hit on the tessellation and the
    /// exact (displaced) limit surface, world units; and the same over the beam width there.
    pub tess_error: [f32; 2],
    /// Unoccluded fraction of the hemisphere (the `ao` AOV; 0 when AO is off).
    pub ao: f32,
    /// Effective tessellation rate of that same hit, quads per side of its root subpatch: 1, 2,
    /// 4, 8, 16, or 16·2^depth where the subpatch was split.
    pub tess_rate: f32,
}

/// The surface at a hit, in render space, oriented toward the incoming ray.
#[derive(Clone, Copy, Debug)]
pub struct ShadingPoint {
    pub p: Vec3A,
    pub ng: Vec3A,
    pub ns: Vec3A,
    pub dpdu: Vec3A,
    pub dpdv: Vec3A,
}

/// Evaluates the exact limit surface at the hit's (u, v) for shading (the paper: intersect the
/// tessellation, shade the surface). The position stays the tessellation's hit point, so new
/// rays start where this ray stopped.
pub fn shading_point(tracer: &Tracer<'_>, scene: &Scene, ray: &Ray, hit: &Hit) -> ShadingPoint {
    let mesh = &scene.meshes[hit.mesh as usize];
    let s = mesh.surface.evaluate(hit.patch as usize, hit.u, hit.v);
    let to_world = tracer.render_from_object(hit.instance);
    let nm = tracer.normal_matrix(hit.instance);
    let (mut odpdu, mut odpdv) = (s.dpdu, s.dpdv);
    if let Some(d) = &mesh.displacement {
        // Shade the displaced surface: its tangents by central differences over half the
        // hit's quad, displacement filtered at that quad's spacing as the tessellation was.
        let sign = if mesh.left_handed { -1.0 } else { 1.0 };
        let step = 0.5 / hit.quads.max(1) as f32;
        let spacing = s.dpdu.length().max(s.dpdv.length()) * 2.0 * step;
        let displaced = |u: f32, v: f32| {
            let e = mesh.surface.evaluate(hit.patch as usize, u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
            e.p + e.dpdu.cross(e.dpdv).normalize_or_zero()
                * sign
                * d.offset_at(mesh.surface.as_ref(), hit.patch as usize, (u, v), e.p, spacing, 2.0 * step)
        };
        let (u0, u1) = ((hit.u - step).max(0.0), (hit.u + step).min(1.0));
        let (v0, v1) = ((hit.v - step).max(0.0), (hit.v + step).min(1.0));
        let du = (displaced(u1, hit.v) - displaced(u0, hit.v)) / (u1 - u0).max(f32::MIN_POSITIVE);
        let dv = (displaced(hit.u, v1) - displaced(hit.u, v0)) / (v1 - v0).max(f32::MIN_POSITIVE);
        if du.is_finite() && dv.is_finite() && du.cross(dv).length_squared() > 0.0 {
            (odpdu, odpdv) = (du, dv);
        }
    }
    let dpdu = to_world.transform_vector3a(odpdu);
    let dpdv = to_world.transform_vector3a(odpdv);
    let mut ns = (nm * odpdu.cross(odpdv)).normalize_or_zero();
    if mesh.left_handed {
        ns = -ns;
    }
    if ns == Vec3A::ZERO || !ns.is_finite() {
        // Degenerate derivatives (a collapsed edge, a pole): the triangle's normal is all we have.
        ns = hit.ng;
    }
    let mut ng = hit.ng;
    // Face the viewer: both normals on the side the ray came from, shading normal kept in the
    // geometric normal's hemisphere.
    if ng.dot(ray.d) > 0.0 {
        ng = -ng;
    }
    if ns.dot(ng) < 0.0 {
        ns = -ns;
    }
    ShadingPoint { p: hit.p, ng, ns, dpdu, dpdv }
}

/// How far the tessellation hit is from the exact limit surface along the ray (world units):
/// Newton's method on S(u, v) = o + t·d from the hit's (u, v, t), with the displaced surface
/// where the mesh is displaced (unfiltered: the truth the tessellation approximates). Where
/// Newton leaves the patch or does not converge, the distance from the hit point to S(u, v)
/// stands in (an upper bound of the same order).
pub fn tessellation_error(tracer: &Tracer<'_>, scene: &Scene, ray: &Ray, hit: &Hit) -> f32 {
    let mesh = &scene.meshes[hit.mesh as usize];
    let m = tracer.render_from_object(hit.instance);
    let sign = if mesh.left_handed { -1.0 } else { 1.0 };
    let surf = |u: f32, v: f32| -> (Vec3A, Vec3A, Vec3A) {
        let e = mesh.surface.evaluate(hit.patch as usize, u, v);
        match &mesh.displacement {
            None => (e.p, e.dpdu, e.dpdv),
            Some(d) => {
                let at = |u: f32, v: f32| {
                    let e = mesh.surface.evaluate(hit.patch as usize, u, v);
                    e.p + e.dpdu.cross(e.dpdv).normalize_or_zero()
                        * sign
                        * d.offset_at(mesh.surface.as_ref(), hit.patch as usize, (u, v), e.p, 0.0, 0.0)
                };
                let h = 1e-3;
                (at(u, v), (at(u + h, v) - at(u - h, v)) / (2.0 * h), (at(u, v + h) - at(u, v - h)) / (2.0 * h))
            }
        }
    };
    let (mut u, mut v, mut t) = (hit.u, hit.v, hit.t);
    let (p0, _, _) = surf(u, v);
    let fallback = (m.transform_point3a(p0) - hit.p).length();
    for _ in 0..8 {
        let (p, du, dv) = surf(u, v);
        let f = m.transform_point3a(p) - ray.at(t);
        let scale = hit.p.abs().max_element().max(1.0);
        if f.length() <= 4.0 * f32::EPSILON * scale {
            return if (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v) { (t - hit.t).abs() } else { fallback };
        }
        let j = glam::Mat3A::from_cols(m.transform_vector3a(du), m.transform_vector3a(dv), -ray.d);
        if j.determinant().abs() < 1e-20 {
            break;
        }
        let step = j.inverse() * -f;
        u += step.x;
        v += step.y;
        t += step.z;
        if !(u.is_finite() && v.is_finite() && t.is_finite()) || !(-0.25..=1.25).contains(&u) || !(-0.25..=1.25).contains(&v) {
            break;
        }
    }
    let (p, _, _) = surf(u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
    let f = m.transform_point3a(p) - ray.at(t);
    if (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v) && f.length() < fallback {
        (t - hit.t).abs()
    } else {
        fallback
    }
}

/// The classic distribution ray tracer: direct light with ray-traced shadows, perfect mirror
/// reflection to a maximum depth, and ambient occlusion by hemisphere rays. Every new ray gets
/// its differential from the paper's §4 rules, so its tessellation rate follows its width.
pub struct DirectLighting<'a> {
    pub tracer: &'a Tracer<'a>,
    pub scene: &'a Scene,
    /// Camera rays through a thin lens (the scene's camera has an f-stop).
    pub depth_of_field: bool,
    shadows: bool,
    reflection: bool,
    ao_samples: u32,
    ao_distance: f32,
    ao_intensity: f32,
    max_depth: u32,
    /// Shadow rays per shading point toward each wide light.
    shadow_samples: u32,
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
            shadows: enabled(effects, "shadows"),
            reflection: enabled(effects, "reflection"),
            ao_samples: if enabled(effects, "ao") { options.ao_samples } else { 0 },
            ao_distance: options.ao_distance,
            ao_intensity: options.ao_intensity,
            max_depth: options.max_depth,
            shadow_samples: options.shadow_samples,
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
        let albedo = match &material.diffuse_texture {
            None => material.diffuse_color,
            Some(tex) => self.texture_color(tex, hit, &sp, &footprint),
        };
        if albedo.max_element() > 0.0 {
            color += albedo * self.direct(&sp, hit, &footprint, sampler, counters);
            if self.ao_samples > 0 {
                ao = self.occlusion(&sp, hit, &footprint, sampler, counters);
                color += albedo * (self.ao_intensity * ao);
            }
        }
        if self.reflection && material.mirror.max_element() > 0.0 && depth < self.max_depth {
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
                };
                if let Some(reflected) = self.radiance(&r, hit, depth + 1, sampler, counters) {
                    color += material.mirror * reflected.color;
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
        let m = self.tracer.render_from_object(hit.instance);
        let w = |v: Vec3A| m.transform_vector3a(v);
        let (mut dndu, mut dndv) = dndu_dndv(sp.dpdu, sp.dpdv, w(s.dpduu), w(s.dpduv), w(s.dpdvv));
        // dndu_dndv belongs to the normal dpdu × dpdv; the shading normal may be its negative.
        if sp.dpdu.cross(sp.dpdv).dot(sp.ns) < 0.0 {
            dndu = -dndu;
            dndv = -dndv;
        }
        UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv).chain(dndu, dndv)
    }

    /// Light from every light (irradiance-weighted, over π for the lambertian BRDF), with shadow
    /// rays toward those that cast them. A point-like light takes one ray; area and dome lights
    /// and distant lights with an angle take `shadow_samples`, each with the §4.5 spread.
    fn direct(
        &self,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> Vec3A {
        let mut sum = Vec3A::ZERO;
        for light in &self.scene.lights {
            let n = if light.is_delta() { 1 } else { self.shadow_samples.max(1) };
            let mut acc = Vec3A::ZERO;
            for _ in 0..n {
                let (u1, u2) = if light.is_delta() { (0.5, 0.5) } else { (sampler.next_f32(), sampler.next_f32()) };
                let Some(ls) = light.sample(sp.p, sp.ns, u1, u2) else { continue };
                let cos_s = sp.ns.dot(ls.wi);
                if cos_s <= 0.0 || sp.ng.dot(ls.wi) <= 0.0 {
                    continue;
                }
                if self.shadows && light.casts_shadows {
                    // Point-like lights: parallel shadow rays, the footprint as origin
                    // differential (§4.3: narrow and coherent). Wide lights: the light's
                    // solid angle over the number of rays (§4.5: wide and incoherent).
                    let diff = if light.is_delta() {
                        RayDifferential::new(footprint.dpdx, footprint.dpdy, Vec3A::ZERO, Vec3A::ZERO)
                    } else {
                        let (d, clamped) = footprint.area_light_shadow_checked(ls.wi, ls.solid_angle_sr, n);
                        counters.differential_clamps += u64::from(clamped);
                        d
                    };
                    let o = offset_origin(sp.p, hit.p_error, sp.ng, ls.wi);
                    // Stop short of an area light's own surface (it is not geometry here, but a
                    // mesh can coincide with it).
                    let t_max = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) } else { f32::INFINITY };
                    let shadow = Ray { o, d: ls.wi, t_min: 0.0, t_max, diff, kind: RayKind::Shadow };
                    if self.tracer.occluded_from(&shadow, hit, counters) {
                        continue;
                    }
                }
                acc += ls.weight * (cos_s * std::f32::consts::FRAC_1_PI);
            }
            sum += acc / n as f32;
        }
        sum
    }

    /// The unoccluded fraction of the cosine-weighted hemisphere within `ao_distance`, from
    /// `ao_samples` rays whose spread is √(1/(N·p(ω))) (the paper's §4.6): wide near the
    /// horizon, narrower at the pole.
    fn occlusion(
        &self,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> f32 {
        let (t, b) = frame(sp.ns);
        let n = self.ao_samples;
        let mut open = 0u32;
        for _ in 0..n {
            let (local, pdf) = cosine_hemisphere(sampler.next_f32(), sampler.next_f32());
            let d = t * local.x + b * local.y + sp.ns * local.z;
            if d.dot(sp.ng) <= 0.0 {
                continue;
            }
            let (diff, clamped) = footprint.hemisphere_checked(d, pdf, n);
            counters.differential_clamps += u64::from(clamped);
            let r = Ray { o: offset_origin(sp.p, hit.p_error, sp.ng, d), d, t_min: 0.0, t_max: self.ao_distance, diff, kind: RayKind::Ao };
            if !self.tracer.occluded_from(&r, hit, counters) {
                open += 1;
            }
        }
        open as f32 / n as f32
    }
}
