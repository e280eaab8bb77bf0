//! Materials: UsdPreviewSurface's inputs, constant or fed by textures. The BSDF they make at a
//! shading point is in [`crate::bsdf`].

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

/// UsdPreviewSurface's constant inputs, with its specification's names, meanings and fallbacks
/// (<https://openusd.org/release/spec_usdpreviewsurface.html>). Colours are linear RGB in
/// [0, 1]; every value is kept inside its valid range by [`PreviewSurface::clamped`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewSurface {
    /// Base colour: the diffuse reflectance, and a metal's specular colour. Fallback 0.18.
    pub diffuse_color: Vec3A,
    /// Emitted radiance (linear RGB, unbounded above). Fallback 0.
    pub emissive_color: Vec3A,
    /// Specular colour from `specular_color` (true) or from `metallic` and `ior` (false, the
    /// fallback).
    pub use_specular_workflow: bool,
    /// Normal-incidence specular reflectance in the specular workflow. Fallback 0.
    pub specular_color: Vec3A,
    /// 0 dielectric .. 1 metal (metallic workflow). Fallback 0.
    pub metallic: f32,
    /// Perceptual roughness in [0, 1] (GGX α = roughness²); 0 is the delta mirror or glass.
    /// Fallback 0.5.
    pub roughness: f32,
    /// Weight of a white dielectric (ior 1.5) coat over everything. Fallback 0.
    pub clearcoat: f32,
    /// The coat's roughness. Fallback 0.01.
    pub clearcoat_roughness: f32,
    /// 1 opaque; below 1 the surface transmits (glass, with `ior`) or, under
    /// `opacity_threshold`, is cut out. Fallback 1.
    pub opacity: f32,
    /// Above 0: opacity is a cutout mask (below the threshold: no surface). Fallback 0.
    pub opacity_threshold: f32,
    /// Index of refraction, > 0. Fallback 1.5.
    pub ior: f32,
}

impl Default for PreviewSurface {
    fn default() -> Self {
        PreviewSurface {
            diffuse_color: Vec3A::splat(0.18),
            emissive_color: Vec3A::ZERO,
            use_specular_workflow: false,
            specular_color: Vec3A::ZERO,
            metallic: 0.0,
            roughness: 0.5,
            clearcoat: 0.0,
            clearcoat_roughness: 0.01,
            opacity: 1.0,
            opacity_threshold: 0.0,
            ior: 1.5,
        }
    }
}

impl PreviewSurface {
    /// Every input inside its valid range (NaN to the fallback's side: 0 for colours); the
    /// names of the inputs that changed, so the caller can warn once naming the material.
    pub fn clamped(&self) -> (PreviewSurface, Vec<&'static str>) {
        let mut out = *self;
        let mut changed = Vec::new();
        let mut unit = |v: &mut f32, name: &'static str| {
            let c = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
            if c != *v {
                changed.push(name);
                *v = c;
            }
        };
        unit(&mut out.metallic, "metallic");
        unit(&mut out.roughness, "roughness");
        unit(&mut out.clearcoat, "clearcoat");
        unit(&mut out.clearcoat_roughness, "clearcoatRoughness");
        unit(&mut out.opacity, "opacity");
        unit(&mut out.opacity_threshold, "opacityThreshold");
        for (c, name) in [(&mut out.diffuse_color, "diffuseColor"), (&mut out.specular_color, "specularColor")] {
            let k = clamp_color(*c);
            if k != *c {
                changed.push(name);
                *c = k;
            }
        }
        let e = Vec3A::select(out.emissive_color.is_nan_mask(), Vec3A::ZERO, out.emissive_color).clamp(Vec3A::ZERO, Vec3A::splat(f32::MAX));
        if e != out.emissive_color {
            changed.push("emissiveColor");
            out.emissive_color = e;
        }
        if !(out.ior.is_finite() && out.ior > 0.0) {
            changed.push("ior");
            // ior ≤ 0 or NaN has no meaning; 1 (no refraction) is the nearest harmless value.
            out.ior = if out.ior.is_finite() && out.ior > 0.0 { out.ior } else { 1.0 };
        }
        (out, changed)
    }
}

/// A UsdPreviewSurface input that a texture can feed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Input {
    DiffuseColor,
    EmissiveColor,
    SpecularColor,
    Metallic,
    Roughness,
    Clearcoat,
    ClearcoatRoughness,
    Opacity,
    Ior,
    /// A tangent-space normal map (UsdPreviewSurface `normal`): the texel, after scale and bias,
    /// is the normal in the (dP/du, dP/dv, N) frame.
    Normal,
}

impl Input {
    /// UsdPreviewSurface's input name.
    pub const fn usd_name(self) -> &'static str {
        match self {
            Input::DiffuseColor => "diffuseColor",
            Input::EmissiveColor => "emissiveColor",
            Input::SpecularColor => "specularColor",
            Input::Metallic => "metallic",
            Input::Roughness => "roughness",
            Input::Clearcoat => "clearcoat",
            Input::ClearcoatRoughness => "clearcoatRoughness",
            Input::Opacity => "opacity",
            Input::Ior => "ior",
            Input::Normal => "normal",
        }
    }
}

/// A surface material: UsdPreviewSurface's constant inputs and the textures feeding some of
/// them. What rays it calls for is decided from these in [`crate::effects`].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Prim path of the material (or of the mesh, for a display-color material).
    pub name: String,
    pub surface: PreviewSurface,
    /// Textured inputs, replacing the constant where a lookup succeeds. Float inputs read the
    /// texture's first channel (`lookup.first_channel`).
    pub textures: Vec<(Input, TexturedColor)>,
}

impl Default for Material {
    /// A lambertian material of UsdPreviewSurface's fallback diffuseColor (0.18, 0.18, 0.18) and
    /// no specular: what an unbound mesh renders with.
    fn default() -> Self {
        Material::lambertian("default", Vec3A::splat(0.18)).0
    }
}

impl Material {
    /// A lambertian material (specular workflow with zero specular colour). Out-of-range or
    /// non-finite colors are clamped to [0, 1]; the returned flag says whether anything was
    /// clamped, so the caller can warn once.
    pub fn lambertian(name: impl Into<String>, diffuse_color: Vec3A) -> (Self, bool) {
        let c = clamp_color(diffuse_color);
        let clamped = c != diffuse_color;
        let surface =
            PreviewSurface { diffuse_color: c, use_specular_workflow: true, specular_color: Vec3A::ZERO, ..PreviewSurface::default() };
        (Material { name: name.into(), surface, textures: Vec::new() }, clamped)
    }

    /// A smooth specular-workflow surface: diffuse `diffuse_color` under a delta mirror of
    /// normal-incidence reflectance `mirror` (roughness 0). Both clamped into [0, 1].
    pub fn mirror(name: impl Into<String>, diffuse_color: Vec3A, mirror: Vec3A) -> Self {
        let surface = PreviewSurface {
            diffuse_color: clamp_color(diffuse_color),
            use_specular_workflow: true,
            specular_color: clamp_color(mirror),
            roughness: 0.0,
            ..PreviewSurface::default()
        };
        Material { name: name.into(), surface, textures: Vec::new() }
    }

    /// A UsdPreviewSurface material, its inputs clamped into range; the names of the inputs that
    /// were out of range (warn once, naming the material).
    pub fn preview_surface(name: impl Into<String>, surface: PreviewSurface) -> (Self, Vec<&'static str>) {
        let (surface, changed) = surface.clamped();
        (Material { name: name.into(), surface, textures: Vec::new() }, changed)
    }

    /// The texture feeding `input`, if any.
    pub fn texture(&self, input: Input) -> Option<&TexturedColor> {
        self.textures.iter().find(|(i, _)| *i == input).map(|(_, t)| t)
    }
}

/// NaN to 0, then into [0, 1].
pub fn clamp_color(c: Vec3A) -> Vec3A {
    Vec3A::select(c.is_nan_mask(), Vec3A::ZERO, c).clamp(Vec3A::ZERO, Vec3A::ONE)
}
