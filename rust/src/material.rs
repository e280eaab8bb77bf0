//! Materials. For now the lambertian part of UsdPreviewSurface (`diffuseColor`); the full
//! microfacet model comes with the light-transport work.

use glam::Vec3A;

/// A surface material. Colors are linear RGB reflectances in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Prim path of the material (or of the mesh, for a display-color material).
    pub name: String,
    pub diffuse_color: Vec3A,
}

impl Default for Material {
    /// UsdPreviewSurface's fallback: diffuseColor (0.18, 0.18, 0.18).
    fn default() -> Self {
        Material { name: "default".into(), diffuse_color: Vec3A::splat(0.18) }
    }
}

impl Material {
    /// A lambertian material. Out-of-range or non-finite colors are clamped to [0, 1]; the
    /// returned flag says whether anything was clamped, so the caller can warn once.
    pub fn lambertian(name: impl Into<String>, diffuse_color: Vec3A) -> (Self, bool) {
        let c = Vec3A::select(diffuse_color.is_nan_mask(), Vec3A::ZERO, diffuse_color).clamp(Vec3A::ZERO, Vec3A::ONE);
        let clamped = c != diffuse_color;
        (Material { name: name.into(), diffuse_color: c }, clamped)
    }
}
