//! Integrators: what radiance a camera ray brings back. Each is chosen by the `integrator`
//! render setting (default: what the scene calls for) and traces only the effects
//! [`crate::effects::analyze`] enabled. Every new ray gets its differential from the paper's §4
//! rules, so its tessellation rate follows its width.
//!
//! - [`classic`]: direct light with shadows, specular and glossy reflection and refraction to a
//!   maximum depth, ambient occlusion (the paper's classic plus distribution ray tracing);
//! - [`surface`]: the shading point at a hit (exact limit surface), shared by all;
//! - [`direct`]: light from the scene's lights at a shading point;
//! - [`hemisphere`]: hemisphere integrals (ambient occlusion) at a shading point.

use glam::Vec3A;

use crate::ray::Ray;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::TraceCounters;

pub mod classic;
pub mod direct;
pub mod hemisphere;
pub mod surface;

pub use classic::DirectLighting;
pub use surface::{shading_point, tessellation_error, ShadingPoint};

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


/// What the render loop asks of an integrator: one camera sample's values, from any thread.
pub trait Integrator: Sync {
    /// Radiance and AOV values along camera ray `ray`; `sampler` is this pixel sample's stream.
    fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue;
    /// Camera rays go through a thin lens (the scene's camera has an f-stop).
    fn depth_of_field(&self) -> bool;
    /// The scene rendered.
    fn scene(&self) -> &Scene;
}
