//! What a ray found: the hit on the tessellation ([`Hit`]) and the surface there as shading sees
//! it ([`ShadingPoint`]). Their own module so that what reads them (materials, integrators,
//! lights) need not depend on what makes them (the tracer, the shading-point evaluation).

use glam::Vec3A;

/// A ray's closest hit. Render space unless stated.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    /// Index into the tracer's instances (for [`crate::trace::Tracer::hit_render_from_object`]).
    pub instance: u32,
    /// The scene's instance id (the `instanceId` AOV).
    pub instance_id: u32,
    pub mesh: u32,
    pub patch: u32,
    /// The patch's own (u, v) at the hit: shading evaluates the exact limit surface there.
    pub u: f32,
    pub v: f32,
    /// The hit point on the tessellation.
    pub p: Vec3A,
    /// Conservative per-axis floating-point error of `p`, for offsetting new rays.
    pub p_error: Vec3A,
    /// Unit geometric normal of the hit triangle, from its winding (front faces wind counter-
    /// clockwise, as USD's rightHanded orientation).
    pub ng: Vec3A,
    /// The effective rate the hit was found at, in quads per side of the root subpatch: 1, 2, 4,
    /// 8, 16, or 16·2^depth after splitting; 0 on a surface intersected exactly ([`crate::implicit`]).
    pub quads: u32,
    /// The root subpatch hit (index in its mesh's subpatches).
    pub subpatch: u32,
    /// How far the tessellation that was hit may stray from the surface (render units): new rays
    /// from this hit ignore their own subpatch closer than this plus the error of whatever
    /// tessellation of it they test (see [`crate::trace::Tracer::intersect_from`]).
    pub chord_error: f32,
    /// The ray's shutter time (see [`crate::ray::Ray::time`]): rays leaving this hit inherit it.
    pub time: f32,
}

/// The surface at a hit, in render space, oriented toward the incoming ray.
#[derive(Clone, Copy, Debug)]
pub struct ShadingPoint {
    pub p: Vec3A,
    /// Unit geometric normal, facing the incoming ray.
    pub ng: Vec3A,
    /// Unit shading normal (the limit surface's), in `ng`'s hemisphere.
    pub ns: Vec3A,
    pub dpdu: Vec3A,
    pub dpdv: Vec3A,
    /// The ray arrived on the side the surface's normal points to (its outside: dP/du × dP/dv,
    /// negated for a left-handed mesh). Refraction enters the material from the front and
    /// leaves it from the back.
    pub front: bool,
    /// The mesh shaded (index into the scene's meshes; `None` at the camera): which lights
    /// reach it (light linking).
    pub mesh: Option<u32>,
    /// The shutter time of the ray that found it (0 to 1): moving lights are posed at it.
    pub time: f32,
    /// The point on the limit surface, in the gprim's object space (MaterialX `Pobject`; zero
    /// at the camera).
    pub p_object: Vec3A,
    /// The surface's unit outward normal in object space (its authored normal where it has
    /// one; MaterialX `Nobject`); zero where it has none.
    pub n_object: Vec3A,
}

impl ShadingPoint {
    /// The camera ray's origin as a "shading point", for [`crate::light`]'s emission seen
    /// directly (which reads where a ray starts, not a BSDF): lights in front of the camera are
    /// seen with full weight, and a dome is the background.
    pub fn at_camera(ray: &crate::ray::Ray) -> ShadingPoint {
        ShadingPoint {
            p: ray.o,
            ng: ray.d,
            ns: ray.d,
            dpdu: Vec3A::ZERO,
            dpdv: Vec3A::ZERO,
            front: true,
            mesh: None,
            time: ray.time,
            p_object: Vec3A::ZERO,
            n_object: Vec3A::ZERO,
        }
    }
}
