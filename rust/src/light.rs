//! Lights (UsdLux). Distant lights for now.
//!
//! Units: a distant light delivers irradiance `intensity · 2^exposure · color` on a surface facing
//! it (its "illuminance", in the renderer's linear radiometric units), so a white lambertian
//! surface facing a light of intensity 1 has radiance 1/π. This is UsdLux's normalized distant
//! light; the angular size shapes the penumbra only (soft shadows come with the light-transport
//! work).

use glam::{Mat4, Vec3A};

#[derive(Clone, Debug, PartialEq)]
pub enum LightShape {
    /// Light arriving from direction −`direction`; `direction` is where it travels (render space,
    /// unit length): a UsdLux.DistantLight emits along its local −Z.
    Distant { direction: Vec3A, angle_deg: f32 },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// Prim path, for messages and stats.
    pub name: String,
    pub shape: LightShape,
    /// Linear RGB scale: intensity · 2^exposure · color.
    pub radiance_scale: Vec3A,
    pub casts_shadows: bool,
}

impl Light {
    /// A distant light travelling along `direction` with irradiance `irradiance` (RGB).
    pub fn distant(name: impl Into<String>, direction: Vec3A, irradiance: Vec3A) -> Self {
        Light {
            name: name.into(),
            shape: LightShape::Distant { direction: direction.normalize_or(Vec3A::NEG_Z), angle_deg: 0.0 },
            radiance_scale: irradiance,
            casts_shadows: true,
        }
    }

    /// A UsdLux.DistantLight from its world transform and inputs.
    pub fn usd_distant(name: impl Into<String>, render_from_light: &Mat4, intensity: f32, exposure: f32, color: Vec3A, angle_deg: f32) -> Self {
        let dir = render_from_light.transform_vector3a(Vec3A::NEG_Z);
        let mut l = Light::distant(name, dir, color * intensity * exposure.exp2());
        let LightShape::Distant { angle_deg: a, .. } = &mut l.shape;
        *a = angle_deg;
        l
    }
}
