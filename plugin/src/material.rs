//! Materials. For now a mesh's resolved diffuse color becomes a lambertian material; material
//! Sprims with UsdPreviewSurface networks come with the light-transport work.

use glam::Vec3A;
use mipray::material::Material;

/// The material for a mesh's resolved albedo and mirror reflectance; warns once per mesh when
/// values were clamped.
pub fn mesh_material(path: &str, albedo: [f32; 3], mirror: [f32; 3]) -> Material {
    let (d, m) = (Vec3A::from(albedo), Vec3A::from(mirror));
    let mat = Material::mirror(path, d, m);
    if mat.diffuse_color != d || mat.mirror != m {
        log::warn!("{path}: diffuse color {albedo:?} and mirror {mirror:?} clamped to [0, 1] with a sum of at most 1");
    }
    mat
}
