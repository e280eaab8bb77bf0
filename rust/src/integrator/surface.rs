//! The surface at a ray hit: the exact limit surface evaluated at the hit's (u, v) (the paper:
//! intersect the tessellation, shade the surface), and how far the tessellation is from it.

use glam::Vec3A;

use crate::differential::{dndu_dndv, RayDifferential, UvDifferentials};
use crate::hit::Hit;
use crate::ray::Ray;
use crate::scene::Scene;
use crate::trace::Tracer;

pub use crate::hit::ShadingPoint;

/// Evaluates the exact limit surface at the hit's (u, v) for shading (the paper: intersect the
/// tessellation, shade the surface). The position stays the tessellation's hit point, so new
/// rays start where this ray stopped.
pub fn shading_point(tracer: &Tracer<'_>, scene: &Scene, ray: &Ray, hit: &Hit) -> ShadingPoint {
    let mesh = &scene.meshes[hit.mesh as usize];
    let s = mesh.surface.evaluate_at(hit.patch as usize, hit.u, hit.v, hit.time);
    let to_world = tracer.hit_render_from_object(hit);
    let nm = tracer.hit_normal_matrix(hit);
    let (mut odpdu, mut odpdv) = (s.dpdu, s.dpdv);
    if let Some(d) = &mesh.displacement {
        // Shade the displaced surface: its tangents by central differences over half the
        // hit's quad, displacement filtered at that quad's spacing as the tessellation was.
        let sign = if mesh.left_handed { -1.0 } else { 1.0 };
        let step = 0.5 / hit.quads.max(1) as f32;
        let spacing = s.dpdu.length().max(s.dpdv.length()) * 2.0 * step;
        let displaced = |u: f32, v: f32| {
            let e = mesh.surface.evaluate_at(hit.patch as usize, u.clamp(0.0, 1.0), v.clamp(0.0, 1.0), hit.time);
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
    let mut n_object = odpdu.cross(odpdv).normalize_or_zero();
    let mut ns = (nm * odpdu.cross(odpdv)).normalize_or_zero();
    if mesh.left_handed {
        ns = -ns;
        n_object = -n_object;
    }
    if mesh.surface.curves().is_some_and(|c| c.is_tube() && c.is_straight(hit.patch as usize)) {
        // A straight tube's pieces (a cylinder or frustum, and the spheres at its joints and
        // ends) are its exact surface: their normal is the true one. The tube's own
        // parameterization has no normal along its axis, so on a joint's sphere it would shade
        // the bend as if the cylinder went on.
        ns = hit.ng;
    }
    if ns == Vec3A::ZERO || !ns.is_finite() {
        // Degenerate derivatives (a collapsed edge, a pole): the triangle's normal is all we have.
        ns = hit.ng;
    }
    // The outward geometric normal: the triangle's, turned to the side of the outward shading
    // normal (the winding of a tessellated triangle says nothing of a left-handed mesh).
    let ng_out = if hit.ng.dot(ns) < 0.0 { -hit.ng } else { hit.ng };
    let front = ng_out.dot(ray.d) <= 0.0;
    // Face the viewer: both normals on the side the ray came from, shading normal kept in the
    // geometric normal's hemisphere.
    let ng = if front { ng_out } else { -ng_out };
    if ns.dot(ng) < 0.0 {
        ns = -ns;
    }
    let authored = authored_normal(mesh, hit);
    if let Some(n) = authored.map(|n| n.normalize_or_zero()).filter(|n| *n != Vec3A::ZERO && n.is_finite()) {
        // Outward as the surface's own normal is, as for the world-space one below.
        n_object = if n_object != Vec3A::ZERO && n.dot(n_object) < 0.0 { -n } else { n };
    }
    if let Some(n) = authored.map(|n| (nm * n).normalize_or_zero()).filter(|n| *n != Vec3A::ZERO && n.is_finite()) {
        // Authored normals say which way is out only up to their author's care: take the side
        // of the surface's own outward normal, then the viewer's, as for `ns` above.
        let n = if n.dot(ng_out) < 0.0 { -n } else { n };
        ns = tilt_above(if front { n } else { -n }, ng);
    }
    if !n_object.is_finite() {
        n_object = Vec3A::ZERO;
    }
    ShadingPoint { p: hit.p, ng, ns, dpdu, dpdv, front, mesh: Some(hit.mesh), time: hit.time, p_object: s.p, n_object }
}

/// The mesh's authored normal at the hit (object space, not normalized), if it has one.
fn authored_normal(mesh: &crate::scene::Mesh, hit: &Hit) -> Option<Vec3A> {
    let [c0, c1] = mesh.normals?;
    let (patch, u, v) = (hit.patch as usize, hit.u, hit.v);
    let (xy, _, _) = mesh.surface.face_varying(c0, patch, u, v)?;
    let (z, _, _) = mesh.surface.face_varying(c1, patch, u, v)?;
    Some(Vec3A::new(xy[0], xy[1], z[0]))
}

/// `n` kept in `ng`'s hemisphere, tilted back to just above its horizon at worst: an
/// interpolated normal near a silhouette may lean past the facet it shades.
fn tilt_above(n: Vec3A, ng: Vec3A) -> Vec3A {
    const MIN_COS: f32 = 0.01;
    let c = n.dot(ng);
    if c >= MIN_COS {
        n
    } else {
        (n + ng * (MIN_COS - c)).try_normalize().unwrap_or(ng)
    }
}

/// How far the tessellation hit is from the exact limit surface along the ray (world units):
/// Newton's method on S(u, v) = o + t·d from the hit's (u, v, t), with the displaced surface
/// where the mesh is displaced (unfiltered: the truth the tessellation approximates). Where
/// Newton leaves the patch (the ray meets the true surface on a neighbouring patch: near an edge
/// a coarse grid's chord cuts across it) or does not converge, the distance along the ray to the
/// tangent plane at the nearest point Newton reached on this patch stands in — exact for flat
/// surfaces, first-order otherwise — or, for a ray within 3° of that plane, the distance from
/// the hit point to S(u, v).
pub fn tessellation_error(tracer: &Tracer<'_>, scene: &Scene, ray: &Ray, hit: &Hit) -> f32 {
    let mesh = &scene.meshes[hit.mesh as usize];
    let m = tracer.hit_render_from_object(hit);
    let sign = if mesh.left_handed { -1.0 } else { 1.0 };
    let surf = |u: f32, v: f32| -> (Vec3A, Vec3A, Vec3A) {
        let e = mesh.surface.evaluate_at(hit.patch as usize, u, v, hit.time);
        match &mesh.displacement {
            None => (e.p, e.dpdu, e.dpdv),
            Some(d) => {
                let at = |u: f32, v: f32| {
                    let e = mesh.surface.evaluate_at(hit.patch as usize, u, v, hit.time);
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
    // Off the patch: along the ray to the tangent plane at the nearest point of the patch.
    let off_patch = |u: f32, v: f32| {
        let (p, du, dv) = surf(u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
        let (p, n) = (m.transform_point3a(p), m.transform_vector3a(du).cross(m.transform_vector3a(dv)).normalize_or_zero());
        let cos = ray.d.dot(n);
        let plane = ((p - hit.p).dot(n) / cos).abs();
        if cos.abs() > 0.05 && plane.is_finite() {
            plane
        } else {
            fallback
        }
    };
    let on_patch = |u: f32, v: f32| (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v);
    for _ in 0..8 {
        let (p, du, dv) = surf(u, v);
        let f = m.transform_point3a(p) - ray.at(t);
        let scale = hit.p.abs().max_element().max(1.0);
        if f.length() <= 4.0 * f32::EPSILON * scale {
            return if on_patch(u, v) { (t - hit.t).abs() } else { off_patch(u, v) };
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
    if on_patch(u, v) && f.length() < fallback {
        (t - hit.t).abs()
    } else {
        off_patch(u, v)
    }
}

/// dN/dx, dN/dy at the hit, render space, from the limit surface's second derivatives
/// (Weingarten) and the footprint: curved mirrors and lenses widen or narrow beams (§4.2). The
/// second derivatives go to render space with the instance's pose at the ray's time, as the
/// shading point's first derivatives do: a moving mirror curves beams as it is when hit.
pub fn normal_differentials(
    tracer: &Tracer<'_>,
    scene: &Scene,
    hit: &Hit,
    sp: &ShadingPoint,
    footprint: &RayDifferential,
) -> (Vec3A, Vec3A) {
    let mesh = &scene.meshes[hit.mesh as usize];
    let s = mesh.surface.evaluate_at(hit.patch as usize, hit.u, hit.v, hit.time);
    let m = tracer.hit_render_from_object(hit);
    let w = |v: Vec3A| m.transform_vector3a(v);
    let (mut dndu, mut dndv) = dndu_dndv(sp.dpdu, sp.dpdv, w(s.dpduu), w(s.dpduv), w(s.dpdvv));
    // dndu_dndv belongs to the normal dpdu × dpdv; the shading normal may be its negative.
    if sp.dpdu.cross(sp.dpdv).dot(sp.ns) < 0.0 {
        dndu = -dndu;
        dndv = -dndv;
    }
    UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv).chain(dndu, dndv)
}
