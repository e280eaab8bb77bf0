//! Integrators. For now the classic one: direct lighting of lambertian surfaces with ray-traced
//! shadows toward the lights that cast them. Distribution effects come with the light-transport
//! work; everything here already carries ray differentials so they can.

use glam::Vec3A;

use crate::differential::RayDifferential;
use crate::effects::{enabled, Effect};
use crate::light::LightShape;
use crate::ray::{offset_origin, Ray, RayKind};
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
    /// World-space beam width of the camera ray at its hit (the paper's figures 2 and 4).
    pub beam_width: f32,
    /// Effective tessellation rate of the hit, quads per side of its root subpatch: 1, 2, 4, 8,
    /// 16, or 16·2^depth where the subpatch was split.
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
            e.p + e.dpdu.cross(e.dpdv).normalize_or_zero() * sign * d.offset(e.p, spacing)
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

/// The direct-lighting integrator.
pub struct DirectLighting<'a> {
    pub tracer: &'a Tracer<'a>,
    pub scene: &'a Scene,
    pub effects: &'a [Effect],
}

impl DirectLighting<'_> {
    /// Radiance and AOV values along a camera ray.
    pub fn sample(&self, ray: &Ray, counters: &mut TraceCounters) -> SampleValue {
        let far = self.scene.camera.clipping_range.1;
        let mut out = SampleValue { depth: far, prim_id: -1.0, instance_id: -1.0, ..Default::default() };
        let Some(hit) = self.tracer.intersect(ray, counters) else {
            return out;
        };
        let sp = shading_point(self.tracer, self.scene, ray, &hit);
        let material = self.scene.material_of(hit.mesh as usize);
        let albedo = material.diffuse_color;
        let footprint = ray.diff.transfer(ray.d, hit.t, sp.ng);
        let shadows = enabled(self.effects, "shadows");
        let mut color = Vec3A::ZERO;
        for light in &self.scene.lights {
            let LightShape::Distant { direction, .. } = light.shape;
            let wi = -direction;
            let cos_s = sp.ns.dot(wi);
            if cos_s <= 0.0 || sp.ng.dot(wi) <= 0.0 {
                continue;
            }
            if shadows && light.casts_shadows {
                // Shadow rays to a distant light are parallel: no directional spread, the
                // footprint as the origin differential (the paper's §4.3: narrow and coherent).
                let shadow = Ray {
                    o: offset_origin(sp.p, hit.p_error, sp.ng, wi),
                    d: wi,
                    t_min: 0.0,
                    t_max: f32::INFINITY,
                    diff: RayDifferential { dpdx: footprint.dpdx, dpdy: footprint.dpdy, dddx: Vec3A::ZERO, dddy: Vec3A::ZERO },
                    kind: RayKind::Shadow,
                };
                if self.tracer.occluded(&shadow, counters) {
                    continue;
                }
            }
            color += albedo * light.radiance_scale * (cos_s * std::f32::consts::FRAC_1_PI);
        }
        out.color = color;
        out.alpha = 1.0;
        out.depth = self.scene.camera.depth(hit.p);
        out.normal = sp.ns;
        out.prim_id = hit.patch as f32;
        out.instance_id = hit.instance_id as f32;
        out.beam_width = ray.beam_width(hit.t);
        out.tess_rate = hit.quads as f32;
        out
    }
}
