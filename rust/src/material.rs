//! Materials. For now the lambertian part of UsdPreviewSurface (`diffuseColor`); the full
//! microfacet model comes with the light-transport work.

use glam::Vec3A;

/// A surface material. Colors are linear RGB reflectances in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Prim path of the material (or of the mesh, for a display-color material).
    pub name: String,
    pub diffuse_color: Vec3A,
    /// Reflectance of a perfect mirror layer (linear RGB; zero: none). Mirror rays are traced
    /// only from materials where this is non-zero.
    pub mirror: Vec3A,
}

impl Default for Material {
    /// UsdPreviewSurface's fallback: diffuseColor (0.18, 0.18, 0.18).
    fn default() -> Self {
        Material { name: "default".into(), diffuse_color: Vec3A::splat(0.18), mirror: Vec3A::ZERO }
    }
}

impl Material {
    /// A lambertian material. Out-of-range or non-finite colors are clamped to [0, 1]; the
    /// returned flag says whether anything was clamped, so the caller can warn once.
    pub fn lambertian(name: impl Into<String>, diffuse_color: Vec3A) -> (Self, bool) {
        let c = clamp_color(diffuse_color);
        let clamped = c != diffuse_color;
        (Material { name: name.into(), diffuse_color: c, mirror: Vec3A::ZERO }, clamped)
    }
}

/// NaN to 0, then into [0, 1].
pub fn clamp_color(c: Vec3A) -> Vec3A {
    Vec3A::select(c.is_nan_mask(), Vec3A::ZERO, c).clamp(Vec3A::ZERO, Vec3A::ONE)
}

impl Material {
    /// A mirror over a diffuse base; both reflectances clamped into [0, 1] and their sum kept
    /// at most 1 per channel (energy conservation).
    pub fn mirror(name: impl Into<String>, diffuse_color: Vec3A, mirror: Vec3A) -> Self {
        let m = clamp_color(mirror);
        let d = clamp_color(diffuse_color).min(Vec3A::ONE - m);
        Material { name: name.into(), diffuse_color: d, mirror: m }
    }
}
