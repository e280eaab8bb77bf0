//! Materials. A mesh bound to a UsdPreviewSurface carries its inputs ([`SurfaceInputs`]: the
//! constants as authored and a [`TextureInput`] per textured input); the render delegate turns
//! them into the core's [`mipray::material::Material`], clamped into range and with its textures opened. A mesh
//! with only a display colour crosses as the same inputs ([`SurfaceInputs::lambertian`]), so
//! there is one material model.

use glam::Vec3A;
use mipray::material::{Input, PreviewSurface};

/// Materials of their own on some faces of a mesh: GeomSubsets bound to their own
/// UsdPreviewSurfaces (textures included), faces of a per-face display colour. A face listed
/// here takes its material over the mesh's own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FaceMaterials {
    /// The distinct materials.
    pub materials: Vec<SurfaceInputs>,
    /// Per control face (USD face order, holes included; per point for Points): an index into
    /// `materials`, or −1 for the mesh's material.
    pub indices: Vec<i32>,
}

impl FaceMaterials {
    /// Checks the table against a mesh of `face_count` faces.
    ///
    /// # Errors
    /// A one-line reason: the wrong number of indices, or an index out of range.
    pub fn validate(&self, face_count: usize) -> Result<(), String> {
        if self.indices.len() != face_count {
            return Err(format!("face_material_indices has {} entries for {face_count} faces", self.indices.len()));
        }
        if let Some((i, v)) = self.indices.iter().enumerate().find(|(_, v)| **v < -1 || **v as i64 >= self.materials.len() as i64) {
            return Err(format!("face_material_indices[{i}] = {v} is out of range for {} face materials", self.materials.len()));
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
    /// UsdUVTexture `sourceColorSpace`: how the file encodes its values (lookups are linear).
    pub color_space: mipray::texture::SourceColorSpace,
    /// A `<UDIM>` file: its tiles present (tile number, file), each looked up where `st` falls
    /// in it ([`mipray::texture::UdimSampler`]); empty for a single file.
    pub udim_tiles: Vec<(u32, String)>,
}

impl TextureInput {
    /// The texture lookup options.
    pub fn lookup(&self) -> mipray::texture::Lookup {
        use mipray::texture::Wrap;
        // A UDIM tile's neighbour is another tile, not its own opposite edge: clamp unless the
        // author said otherwise.
        let wrap = |w: Wrap| if !self.udim_tiles.is_empty() && w == Wrap::FromFile { Wrap::Clamp } else { w };
        mipray::texture::Lookup { first_channel: self.channel, wrap_s: wrap(self.wrap_s), wrap_t: wrap(self.wrap_t), fill: 0.0 }
    }

    /// `(scale, bias, fallback)` as the texture feeds `input`: a colour input takes the rgb
    /// components; a float input (or the normal's single-channel outputs) reads one channel,
    /// the connected output's, so its scale, bias and fallback are that channel's, splatted.
    pub fn affine(&self, input: Input) -> (Vec3A, Vec3A, Vec3A) {
        let rgb = |v: &[f32; 4]| Vec3A::new(v[0], v[1], v[2]);
        if is_color(input) || input == Input::Normal {
            (rgb(&self.scale), rgb(&self.bias), rgb(&self.fallback))
        } else {
            let c = (self.channel as usize).min(3);
            (Vec3A::splat(self.scale[c]), Vec3A::splat(self.bias[c]), Vec3A::splat(self.fallback[c]))
        }
    }
}

/// A texture lookup of a [`NetworkInput`]: a MaterialX `image` / `tiledimage` node as the
/// scene delegate resolved it (`texture.scale` and `bias` unused: the network's ops apply them).
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkTextureInput {
    /// File, wraps, colour space, first channel (`texture.channel`) and `fallback` (MaterialX
    /// `default`).
    pub texture: TextureInput,
    /// Channels read, 1–4 (the node's output type).
    pub channels: u8,
    /// The lookup's texcoord as an affine map of the mesh's `st` (`place2d`, tiling).
    pub st_transform: mipray::material::network::StTransform,
}

/// A node network feeding one input, as the scene delegate lowered it: the core's ops
/// ([`mipray::material::network::Op`]) over these lookups.
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkInput {
    pub ops: Vec<mipray::material::network::Op>,
    pub lookups: Vec<NetworkTextureInput>,
    /// The primvars its `primvar` ops read (channels unset: the mesh's
    /// [`crate::mesh::Channels::named`] places them).
    pub primvars: Vec<mipray::material::network::NetworkPrimvar>,
}

/// A mesh's UsdPreviewSurface as the scene delegate read it: every constant input as authored
/// (out-of-range values included: [`PreviewSurface::clamped`] brings them into range when the
/// render delegate builds the core material, with one warning naming the material) and the
/// UsdUVTextures feeding inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceInputs {
    /// The material's prim path: messages name it.
    pub name: String,
    /// Constant inputs; an input fed by a texture keeps its constant for nothing (the texture's
    /// value replaces it where the lookup succeeds, its `fallback` where it cannot be read).
    pub surface: PreviewSurface,
    /// Textured inputs, at most one per input, all reading the mesh's `st` primvar
    /// ([`crate::mesh::MeshData::st`]).
    pub textures: Vec<(Input, TextureInput)>,
    /// Inputs fed by a node network (MaterialX nodes not folded into one lookup), all reading
    /// the mesh's `st`; an input is in `textures` or here, not both.
    pub networks: Vec<(Input, NetworkInput)>,
}

impl SurfaceInputs {
    /// UsdPreviewSurface's fallbacks everywhere, no textures.
    pub fn new(name: impl Into<String>) -> Self {
        SurfaceInputs { name: name.into(), surface: PreviewSurface::default(), textures: Vec::new(), networks: Vec::new() }
    }

    /// Whether any input reads a texture file (a texture, or a network's lookup).
    pub fn reads_files(&self) -> bool {
        !self.textures.is_empty() || self.networks.iter().any(|(_, n)| !n.lookups.is_empty())
    }

    /// A lambertian surface of linear RGB `diffuse_color`: the specular workflow with no
    /// specular, as [`mipray::material::Material::lambertian`] builds it (a display colour
    /// without a material).
    pub fn lambertian(name: impl Into<String>, diffuse_color: [f32; 3]) -> Self {
        let mut out = SurfaceInputs::new(name);
        out.surface.diffuse_color = Vec3A::from(diffuse_color);
        out.surface.use_specular_workflow = true;
        out.surface.specular_color = Vec3A::ZERO;
        out
    }

    /// `diffuse_color` under a smooth delta mirror of normal-incidence reflectance `mirror`
    /// (linear RGB), as [`mipray::material::Material::mirror`] builds it.
    pub fn mirror(name: impl Into<String>, diffuse_color: [f32; 3], mirror: [f32; 3]) -> Self {
        let mut out = SurfaceInputs::lambertian(name, diffuse_color);
        out.surface.specular_color = Vec3A::from(mirror);
        out.surface.roughness = 0.0;
        out
    }
}

/// Whether `input` is a colour (three channels) rather than a float (one channel) or the normal.
pub fn is_color(input: Input) -> bool {
    matches!(input, Input::DiffuseColor | Input::EmissiveColor | Input::SpecularColor)
}

/// Sets `input` of `surface` to `value`: colours take all three components, floats the first.
/// The normal has no constant (its fallback is the surface's own normal), so it is left alone.
pub fn set_input(surface: &mut PreviewSurface, input: Input, value: Vec3A) {
    match input {
        Input::DiffuseColor => surface.diffuse_color = value,
        Input::EmissiveColor => surface.emissive_color = value,
        Input::SpecularColor => surface.specular_color = value,
        Input::Metallic => surface.metallic = value.x,
        Input::Roughness => surface.roughness = value.x,
        Input::Clearcoat => surface.clearcoat = value.x,
        Input::ClearcoatRoughness => surface.clearcoat_roughness = value.x,
        Input::Opacity => surface.opacity = value.x,
        Input::Ior => surface.ior = value.x,
        Input::Normal => {}
    }
}

/// The input of UsdPreviewSurface named `name` that a texture can feed, if any.
pub fn input_from_usd(name: &str) -> Option<Input> {
    [
        Input::DiffuseColor,
        Input::EmissiveColor,
        Input::SpecularColor,
        Input::Metallic,
        Input::Roughness,
        Input::Clearcoat,
        Input::ClearcoatRoughness,
        Input::Opacity,
        Input::Ior,
        Input::Normal,
    ]
    .into_iter()
    .find(|i| i.usd_name() == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn face_materials_are_checked_against_the_face_count() {
        let table = FaceMaterials { materials: vec![SurfaceInputs::new("/Looks/A")], indices: vec![-1, 0, 0] };
        assert_eq!(table.validate(3), Ok(()));
        assert_eq!(table.validate(4).unwrap_err(), "face_material_indices has 3 entries for 4 faces");
        let bad = FaceMaterials { materials: vec![SurfaceInputs::new("/Looks/A")], indices: vec![0, 1, -2] };
        assert_eq!(bad.validate(3).unwrap_err(), "face_material_indices[1] = 1 is out of range for 1 face materials");
    }

    #[test]
    fn lambertian_and_mirror_inputs_build_the_core_materials_they_name() {
        use mipray::material::Material;
        for (d, m) in [([0.2, 0.4, 0.6], [0.0; 3]), ([0.05; 3], [0.9, 0.5, 0.1]), ([1.5, -0.2, f32::NAN], [2.0, 0.3, 0.3])] {
            let (d3, m3) = (Vec3A::from(d), Vec3A::from(m));
            let want = if m3 == Vec3A::ZERO { Material::lambertian("/q", d3).0 } else { Material::mirror("/q", d3, m3) };
            let inputs = if m3 == Vec3A::ZERO { SurfaceInputs::lambertian("/q", d) } else { SurfaceInputs::mirror("/q", d, m) };
            let (got, _) = Material::preview_surface(inputs.name, inputs.surface);
            // Bitwise, NaN included: the examples must render bit-identical through either.
            assert_eq!(format!("{:?}", got.surface), format!("{:?}", want.surface));
        }
    }

    #[test]
    fn a_udim_texture_clamps_unless_told_otherwise() {
        use mipray::texture::{SourceColorSpace, Wrap};
        let mut tex = TextureInput {
            file: "paint.<UDIM>.png".into(),
            scale: [1.0; 4],
            bias: [0.0; 4],
            fallback: [0.0, 0.0, 0.0, 1.0],
            wrap_s: Wrap::FromFile,
            wrap_t: Wrap::Mirror,
            channel: 0,
            color_space: SourceColorSpace::Auto,
            udim_tiles: Vec::new(),
        };
        assert_eq!(tex.lookup().wrap_s, Wrap::FromFile);
        tex.udim_tiles.push((1001, "paint.1001.png".into()));
        assert_eq!((tex.lookup().wrap_s, tex.lookup().wrap_t), (Wrap::Clamp, Wrap::Mirror));
    }
}
