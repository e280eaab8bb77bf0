//! Integrators: what radiance a camera ray brings back. Each is chosen by the `integrator`
//! render setting (default: what the scene calls for) and traces only the effects
//! [`crate::effects::analyze`] enabled. Every new ray gets its differential from the paper's §4
//! rules, so its tessellation rate follows its width.
//!
//! - [`direct_lighting`]: direct light with shadows, specular and glossy reflection and refraction to a
//!   maximum depth, ambient occlusion (the paper's classic plus distribution ray tracing);
//! - [`surface`]: the shading point at a hit (exact limit surface), shared by all;
//! - [`direct_light`]: light from the scene's lights at a shading point;
//! - [`hemisphere`]: hemisphere integrals (ambient occlusion) at a shading point;
//! - [`bleed`]: one-bounce color bleeding, with the irradiance cache when asked;
//! - [`visibility`]: shadow, occlusion and hemisphere rays through opacity cut-outs.

use glam::Vec3A;

use crate::aov::{Aov, Averaging};
use crate::ray::Ray;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::TraceCounters;

pub mod ao;
pub mod bleed;
pub mod direct_light;
pub mod direct_lighting;
pub mod hemisphere;
pub mod path;
pub mod select;
pub mod surface;
pub mod visibility;

pub use ao::AmbientOcclusion;
pub use bleed::ColorBleeding;
pub use direct_lighting::DirectLighting;
pub use path::PathTracer;
pub use surface::{normal_differentials, shading_point, tessellation_error, ShadingPoint};

/// Everything one camera sample yields, one field per AOV. The default is all zeros except
/// `element_id`, −1 (no face); see [`SampleValue::miss`] for a camera ray that hits nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleValue {
    /// Linear RGB radiance.
    pub color: Vec3A,
    /// 1 where a surface was hit.
    pub alpha: f32,
    /// Camera-space depth along the view axis, camera-space units (the far clip when nothing is
    /// hit): the `depth` AOV, EXR's `Z`.
    pub depth: f32,
    /// Hydra's `cameraDepth`: the same camera-space depth, −`peye.z`, but 0 where nothing is hit
    /// (Hydra's clear value).
    pub camera_depth: f32,
    /// Hydra's `Peye`: the hit's position in camera space (USD's camera looks down −z, so z < 0
    /// in front of it), camera-space units; 0 where nothing is hit.
    pub peye: Vec3A,
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
    /// World-space position of the camera ray's hit (`position`; 0 where nothing is hit).
    pub position: Vec3A,
    /// The control (base) face of the mesh hit (Hydra's `elementId`; −1 for none).
    pub element_id: f32,
    /// The shading normal in camera space (Hydra's `Neye`: USD's camera looks down −z).
    pub neye: Vec3A,
    /// Diffuse reflectance seen from the camera at the hit (`albedo`): the BSDF's
    /// [`crate::bsdf::Scattering::diffuse_albedo`] toward the camera.
    pub albedo: Vec3A,
    /// Radiance the camera sees emitted: emissive surfaces, and lights seen directly (a dome
    /// as the background) — `emission`.
    pub emission: Vec3A,
    /// Direct light from the scene's lights reflected by the diffuse lobe at the camera ray's
    /// hit (`directDiffuse`).
    pub direct_diffuse: Vec3A,
    /// Light from other surfaces (and, for the classic integrator, the ambient-occlusion sky)
    /// reflected by the diffuse lobe at the camera ray's hit (`indirectDiffuse`).
    pub indirect_diffuse: Vec3A,
    /// Everything the non-diffuse lobes at the camera ray's hit reflect or refract: direct
    /// light through glossy lobes, and whatever mirror, glass, glossy and refraction rays bring
    /// back (`specular`).
    pub specular: Vec3A,
}

/// How many AOVs are averaged over a pixel's samples ([`crate::aov::Averaging::Mean`]).
const AVERAGED_COUNT: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < Aov::ALL.len() {
        n += matches!(Aov::ALL[i].info().averaging, Averaging::Mean) as usize;
        i += 1;
    }
    n
};

/// The AOVs averaged over a pixel's samples, in [`Aov`]'s order (read from the table).
const AVERAGED: [Aov; AVERAGED_COUNT] = {
    let mut out = [Aov::Color; AVERAGED_COUNT];
    let (mut i, mut n) = (0, 0);
    while i < Aov::ALL.len() {
        if matches!(Aov::ALL[i].info().averaging, Averaging::Mean) {
            out[n] = Aov::ALL[i];
            n += 1;
        }
        i += 1;
    }
    out
};

/// `channels` and `channels_mut` of [`SampleValue`] from one list of AOV → field (`f`: an f32,
/// `v3`: a Vec3A's x, y, z, `a`: an array).
macro_rules! sample_channels {
    ($($aov:ident => $field:ident: $kind:ident),* $(,)?) => {
        /// The channels of `aov` in this sample: the one place an [`Aov`] meets its field.
        pub fn channels(&self, aov: Aov) -> &[f32] {
            match aov {
                $(Aov::$aov => sample_channels!(@ref $kind, self.$field),)*
            }
        }

        /// The channels of `aov` in this sample, mutable.
        pub fn channels_mut(&mut self, aov: Aov) -> &mut [f32] {
            match aov {
                $(Aov::$aov => sample_channels!(@mut $kind, self.$field),)*
            }
        }
    };
    (@ref f, $e:expr) => { std::slice::from_ref(&$e) };
    (@ref v3, $e:expr) => { AsRef::<[f32; 3]>::as_ref(&$e) };
    (@ref a, $e:expr) => { &$e };
    (@mut f, $e:expr) => { std::slice::from_mut(&mut $e) };
    (@mut v3, $e:expr) => { AsMut::<[f32; 3]>::as_mut(&mut $e) };
    (@mut a, $e:expr) => { &mut $e };
}

impl Default for SampleValue {
    fn default() -> Self {
        SampleValue {
            color: Vec3A::ZERO,
            alpha: 0.0,
            depth: 0.0,
            camera_depth: 0.0,
            peye: Vec3A::ZERO,
            normal: Vec3A::ZERO,
            prim_id: 0.0,
            instance_id: 0.0,
            beam_width: 0.0,
            tess_error: [0.0; 2],
            ao: 0.0,
            tess_rate: 0.0,
            position: Vec3A::ZERO,
            element_id: -1.0,
            neye: Vec3A::ZERO,
            albedo: Vec3A::ZERO,
            emission: Vec3A::ZERO,
            direct_diffuse: Vec3A::ZERO,
            indirect_diffuse: Vec3A::ZERO,
            specular: Vec3A::ZERO,
        }
    }
}

impl SampleValue {
    /// The values of a camera ray that hits nothing: depth at the far clip `far`, ids −1, every
    /// radiance 0.
    pub fn miss(far: f32) -> Self {
        SampleValue { depth: far, prim_id: -1.0, instance_id: -1.0, ..Default::default() }
    }

    /// Sets the AOVs that describe the surface a camera ray hit — alpha, depth, `cameraDepth`,
    /// position, `Peye`, `normal` (world, the shading normal `normal` facing the camera), `Neye`,
    /// and the ids — the same way for every integrator.
    pub fn set_hit(&mut self, scene: &Scene, hit: &crate::trace::Hit, normal: Vec3A) {
        self.alpha = 1.0;
        self.peye = scene.camera.camera_from_render(hit.p);
        self.depth = -self.peye.z;
        self.camera_depth = -self.peye.z;
        self.position = hit.p;
        self.normal = normal;
        // Normals go by the inverse transpose of camera-from-render: the transpose of
        // render-from-camera's linear part.
        let m = glam::Mat3A::from_mat4(scene.camera.render_from_camera);
        self.neye = (m.transpose() * normal).normalize_or_zero();
        self.prim_id = hit.patch as f32;
        self.instance_id = hit.instance_id as f32;
        self.element_id = scene.meshes.get(hit.mesh as usize).map_or(-1.0, |m| m.surface.patch_param(hit.patch as usize).base_face as f32);
    }

    /// Sets `color` to the sum of its parts: emission + direct diffuse + indirect diffuse +
    /// specular (the identity the AOVs keep).
    pub fn set_color_from_parts(&mut self) {
        self.color = self.emission + self.direct_diffuse + self.indirect_diffuse + self.specular;
    }

    sample_channels! {
        Color => color: v3, Alpha => alpha: f, Depth => depth: f, CameraDepth => camera_depth: f, Peye => peye: v3,
        Normal => normal: v3, PrimId => prim_id: f, InstanceId => instance_id: f, BeamWidth => beam_width: f,
        TessRate => tess_rate: f, Ao => ao: f, TessError => tess_error: a, Position => position: v3,
        ElementId => element_id: f, Neye => neye: v3, Albedo => albedo: v3, Emission => emission: v3,
        DirectDiffuse => direct_diffuse: v3, IndirectDiffuse => indirect_diffuse: v3, Specular => specular: v3,
    }

    /// A copy whose averaged AOVs are 0: what a pixel's running sums start from, keeping sample
    /// 0's other values (depth, normal, ids: never blends of two surfaces).
    pub fn without_averaged(&self) -> Self {
        let mut out = *self;
        for aov in AVERAGED {
            out.channels_mut(aov).fill(0.0);
        }
        out
    }

    /// Every averaged AOV is finite (a sample that is not is dropped whole, so the parts still
    /// add up to the colour).
    pub fn averaged_finite(&self) -> bool {
        AVERAGED.iter().all(|&a| self.channels(a).iter().all(|x| x.is_finite()))
    }

    /// Adds `v`'s averaged AOVs into these sums.
    pub fn add_averaged(&mut self, v: &SampleValue) {
        for aov in AVERAGED {
            for (s, x) in self.channels_mut(aov).iter_mut().zip(v.channels(aov)) {
                *s += x;
            }
        }
    }

    /// These sums times `inv` (1 / the number of samples summed) in the averaged AOVs.
    pub fn averaged(&self, inv: f32) -> Self {
        let mut out = *self;
        for aov in AVERAGED {
            for x in out.channels_mut(aov) {
                *x *= inv;
            }
        }
        out
    }

    /// The non-averaged AOVs are finite (depth, normals, position, debug values).
    pub fn geometry_finite(&self) -> bool {
        Aov::ALL.iter().filter(|a| !a.averaged()).all(|&a| self.channels(a).iter().all(|x| x.is_finite()))
    }
}

/// What the render loop asks of an integrator: one camera sample's values, from any thread.
pub trait Integrator: Sync {
    /// Radiance and AOV values along camera ray `ray`; `sampler` is this pixel sample's stream.
    fn sample(&self, ray: &Ray, sampler: &mut Sampler, counters: &mut TraceCounters) -> SampleValue;
    /// Camera rays go through a thin lens (the scene's camera has an f-stop).
    fn depth_of_field(&self) -> bool;
    /// The scene rendered.
    fn scene(&self) -> &Scene;
    /// Work before the first pixel, run once on the render's thread pool: the irradiance
    /// cache's records ([`crate::irradiance_cache`]), made in a fixed order so the image stays a
    /// function of the seed. Returns the rays it traced. Default: nothing.
    ///
    /// # Errors
    /// [`crate::error::RenderError::Cancelled`] through `progress`.
    fn prepass(
        &self,
        _options: &crate::options::RenderOptions,
        _progress: &dyn crate::progress::Progress,
    ) -> Result<TraceCounters, crate::error::RenderError> {
        Ok(TraceCounters::default())
    }
    /// The stats' `irradiance_cache` object (records, pre-pass rays, lookups), when the
    /// integrator caches hemisphere integrals.
    fn cache_stats(&self) -> Option<serde_json::Value> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_aov_reads_and_writes_its_own_channels() {
        let mut v = SampleValue::default();
        for (i, aov) in Aov::ALL.into_iter().enumerate() {
            assert_eq!(v.channels(aov).len(), aov.channels(), "{}", aov.name());
            v.channels_mut(aov).fill(i as f32 + 1.0);
        }
        for (i, aov) in Aov::ALL.into_iter().enumerate() {
            assert!(v.channels(aov).iter().all(|x| *x == i as f32 + 1.0), "{} shares a field", aov.name());
        }
        let cleared = v.without_averaged();
        for aov in Aov::ALL {
            let zero = cleared.channels(aov).iter().all(|x| *x == 0.0);
            assert_eq!(zero, aov.averaged(), "{}", aov.name());
        }
    }
}
