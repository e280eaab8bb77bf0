//! Materials. For now a mesh's resolved diffuse color becomes a lambertian material; material
//! Sprims with UsdPreviewSurface networks come with the light-transport work.

use glam::Vec3A;
use mipray::material::Material;

/// The material for a mesh's resolved albedo and mirror reflectance; warns once per mesh when
/// values were clamped.
pub fn mesh_material(path: &str, albedo: [f32; 3], mirror: [f32; 3]) -> Material {
    let (d, m) = (Vec3A::from(albedo), Vec3A::from(mirror));
    let mat = if m == Vec3A::ZERO { Material::lambertian(path, d).0 } else { Material::mirror(path, d, m) };
    if mat.surface.diffuse_color != d || (m != Vec3A::ZERO && mat.surface.specular_color != m) {
        log::warn!("{path}: diffuse color {albedo:?} and mirror {mirror:?} clamped to [0, 1]");
    }
    mat
}

/// Per-face diffuse colours of a mesh: faces of GeomSubsets bound to their own materials, or a
/// `displayColor` with uniform (or per-vertex, averaged per face) interpolation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FaceAlbedo {
    /// The distinct colours, linear RGB in [0, 1].
    pub albedos: Vec<[f32; 3]>,
    /// Per control face (USD face order, holes included): an index into `albedos`, or −1 for
    /// the mesh's own albedo.
    pub indices: Vec<i32>,
}

impl FaceAlbedo {
    /// Checks the table against a mesh of `face_count` faces.
    ///
    /// # Errors
    /// A one-line reason: the wrong number of indices, an index out of range, or a colour
    /// that is not finite.
    pub fn validate(&self, face_count: usize) -> Result<(), String> {
        if self.indices.len() != face_count {
            return Err(format!("face_albedo_indices has {} entries for {face_count} faces", self.indices.len()));
        }
        if let Some((i, v)) = self.indices.iter().enumerate().find(|(_, v)| **v < -1 || **v as i64 >= self.albedos.len() as i64) {
            return Err(format!("face_albedo_indices[{i}] = {v} is out of range for {} face albedos", self.albedos.len()));
        }
        if let Some((i, c)) = self.albedos.iter().enumerate().find(|(_, c)| !c.iter().all(|x| x.is_finite())) {
            return Err(format!("face_albedos[{i}] = {c:?} is not finite"));
        }
        Ok(())
    }
}

/// A UsdUVTexture feeding a UsdPreviewSurface input, as the scene delegate resolved it.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureInput {
    /// Resolved file path.
    pub file: String,
    /// UsdUVTexture `scale`, `bias` and `fallback` (RGBA).
    pub scale: [f32; 4],
    pub bias: [f32; 4],
    pub fallback: [f32; 4],
    pub wrap_s: mipray::texture::Wrap,
    pub wrap_t: mipray::texture::Wrap,
    /// The output connected: 0 = r (or rgb), 1 = g, 2 = b, 3 = a.
    pub channel: u32,
}

impl TextureInput {
    /// The texture lookup options.
    pub fn lookup(&self) -> mipray::texture::Lookup {
        mipray::texture::Lookup { first_channel: self.channel, wrap_s: self.wrap_s, wrap_t: self.wrap_t, fill: 0.0 }
    }
}
