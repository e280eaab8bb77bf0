//! Light Sprims (UsdLux). Distant lights for now.

use glam::{Mat4, Vec3A};
use mipray::light::Light;

/// A UsdLux.DistantLight's inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct DistantLightData {
    /// Light-to-world (column-vector convention); the light travels along its local −Z.
    pub transform: Mat4,
    pub intensity: f32,
    pub exposure: f32,
    pub color: [f32; 3],
    pub angle_deg: f32,
    pub normalize: bool,
    pub shadow_enable: bool,
}

/// A light prim.
#[derive(Clone, Debug, PartialEq)]
pub struct LightPrim {
    pub path: String,
    pub data: DistantLightData,
}

impl LightPrim {
    /// The core's light. Non-finite inputs are the scene delegate's to refuse; here they are
    /// zeroed so nothing non-finite can reach the film.
    pub fn to_light(&self) -> Light {
        let d = &self.data;
        let f = |x: f32| if x.is_finite() { x } else { 0.0 };
        let mut l = Light::usd_distant(&self.path, &d.transform, f(d.intensity), f(d.exposure), Vec3A::from(d.color.map(f)), f(d.angle_deg));
        l.casts_shadows = d.shadow_enable;
        l
    }
}
