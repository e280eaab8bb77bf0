//! Materials. For now the lambertian part of UsdPreviewSurface (`diffuseColor`); the full
//! microfacet model comes with the light-transport work.

use std::sync::Arc;

use glam::Vec3A;

use crate::texture::{Lookup, TextureHandle, TextureSampler};

/// A colour input fed by a texture (UsdUVTexture → UsdPreviewSurface `diffuseColor`):
/// `texel.rgb · scale + bias`, looked up at the surface's `st` primvar channel with filter
/// widths from the ray differentials.
#[derive(Clone)]
pub struct TexturedColor {
    pub sampler: Arc<dyn TextureSampler>,
    pub texture: TextureHandle,
    /// The file, for messages.
    pub path: String,
    pub lookup: Lookup,
    pub scale: Vec3A,
    pub bias: Vec3A,
    /// UsdUVTexture `fallback`: the colour where a lookup fails or the surface has no `st`.
    pub fallback: Vec3A,
    /// The surface's 2-float primvar channel holding `st`.
    pub st_channel: usize,
}

impl std::fmt::Debug for TexturedColor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TexturedColor")
            .field("path", &self.path)
            .field("scale", &self.scale)
            .field("bias", &self.bias)
            .finish_non_exhaustive()
    }
}

impl PartialEq for TexturedColor {
    fn eq(&self, o: &Self) -> bool {
        Arc::ptr_eq(&self.sampler, &o.sampler)
            && self.texture == o.texture
            && self.lookup == o.lookup
            && self.scale == o.scale
            && self.bias == o.bias
            && self.fallback == o.fallback
            && self.st_channel == o.st_channel
    }
}

impl TexturedColor {
    /// The filtered colour at `st` over the footprint (ds/dx, dt/dx), (ds/dy, dt/dy), clamped
    /// into [0, 1] like any reflectance.
    pub fn eval(&self, st: Option<[f32; 2]>, dst_dx: [f32; 2], dst_dy: [f32; 2]) -> Vec3A {
        let Some(st) = st else { return self.fallback };
        let mut rgb = [0.0f32; 3];
        if !self.sampler.sample(self.texture, st, dst_dx, dst_dy, &self.lookup, &mut rgb) {
            return self.fallback;
        }
        clamp_color(Vec3A::from(rgb) * self.scale + self.bias)
    }
}

/// A surface material. Colors are linear RGB reflectances in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Prim path of the material (or of the mesh, for a display-color material).
    pub name: String,
    pub diffuse_color: Vec3A,
    /// Reflectance of a perfect mirror layer (linear RGB; zero: none). Mirror rays are traced
    /// only from materials where this is non-zero.
    pub mirror: Vec3A,
    /// `diffuseColor` from a texture, replacing `diffuse_color` where set.
    pub diffuse_texture: Option<TexturedColor>,
}

impl Default for Material {
    /// UsdPreviewSurface's fallback: diffuseColor (0.18, 0.18, 0.18).
    fn default() -> Self {
        Material { name: "default".into(), diffuse_color: Vec3A::splat(0.18), mirror: Vec3A::ZERO, diffuse_texture: None }
    }
}

impl Material {
    /// A lambertian material. Out-of-range or non-finite colors are clamped to [0, 1]; the
    /// returned flag says whether anything was clamped, so the caller can warn once.
    pub fn lambertian(name: impl Into<String>, diffuse_color: Vec3A) -> (Self, bool) {
        let c = clamp_color(diffuse_color);
        let clamped = c != diffuse_color;
        (Material { name: name.into(), diffuse_color: c, mirror: Vec3A::ZERO, diffuse_texture: None }, clamped)
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
        Material { name: name.into(), diffuse_color: d, mirror: m, diffuse_texture: None }
    }
}
