//! UsdPreviewSurface inputs through the render delegate into the core's materials: constants
//! (clamped into range), textured inputs (a float input reads the connected output's channel),
//! and unreadable textures (the texture's fallback becomes the constant).

#![allow(clippy::unwrap_used)]

mod common;

use glam::{Mat4, Vec3, Vec3A};
use hd_mipray::material::{SurfaceInputs, TextureInput};
use hd_mipray::mesh::MeshData;
use hd_mipray::RenderDelegate;
use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo};
use mipray::material::{Input, Material, PreviewSurface};
use mipray::texture::{Primvar2, Wrap};
use mipray_bridge::{OiioImageIo, OiioTextureOptions};

/// A unit quad with `st` over [0, 1]² and the given material.
fn quad(material: Option<SurfaceInputs>) -> MeshData {
    let (mut topology, points) = mipray::bilinear::grid_mesh(1.0, 1, 0.0);
    topology.scheme = mipray::topology::Scheme::None;
    let st = Primvar2 {
        name: "st".into(),
        interpolation: mipray::texture::Interpolation::FaceVarying,
        values: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        indices: Vec::new(),
    };
    MeshData { topology, points, transform: Mat4::IDENTITY, material, st: Some(st), ..Default::default() }
}

/// The core material the delegate builds for the one mesh at `/quad`.
fn built(mut d: RenderDelegate) -> Material {
    assert!(d.sync().is_empty());
    d.prepare_textures(OiioTextureOptions::default()).unwrap();
    let scene = d.build_scene("/cam", 0.0).unwrap();
    let mesh = scene.meshes.iter().position(|m| m.name == "/quad").unwrap();
    scene.materials[scene.meshes[mesh].material].clone()
}

fn delegate() -> RenderDelegate {
    common::delegate_with_camera(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, true)
}

fn texture(file: &str, channel: u32) -> TextureInput {
    TextureInput {
        file: file.into(),
        scale: [2.0, 3.0, 4.0, 5.0],
        bias: [0.1, 0.2, 0.3, 0.4],
        fallback: [0.6, 0.7, 0.8, 0.9],
        wrap_s: Wrap::Clamp,
        wrap_t: Wrap::Clamp,
        channel,
        color_space: mipray::texture::SourceColorSpace::Auto,
        udim_tiles: Vec::new(),
    }
}

#[test]
fn constant_inputs_reach_the_core_material_clamped() {
    let surface = PreviewSurface {
        diffuse_color: Vec3A::new(-0.5, 0.5, 2.0),
        emissive_color: Vec3A::new(3.0, 0.0, 0.0),
        use_specular_workflow: true,
        specular_color: Vec3A::new(0.2, 0.3, 0.4),
        metallic: 0.3,
        roughness: 1.5,
        clearcoat: 0.6,
        clearcoat_roughness: 0.2,
        opacity: 0.8,
        opacity_threshold: 0.1,
        ior: -2.0,
    };
    let mut d = delegate();
    d.set_mesh("/quad", quad(Some(SurfaceInputs { name: "/Looks/M".into(), surface, textures: Vec::new(), networks: Vec::new() })));
    let m = built(d);
    assert_eq!(m.name, "/Looks/M");
    let (expected, changed) = surface.clamped();
    assert_eq!(m.surface, expected);
    assert_eq!(changed, ["roughness", "diffuseColor", "ior"]);
    // Emission is not a reflectance: it keeps its value above 1.
    assert_eq!(m.surface.emissive_color, Vec3A::new(3.0, 0.0, 0.0));
    assert_eq!(m.surface.diffuse_color, Vec3A::new(0.0, 0.5, 1.0));
    assert!(m.textures.is_empty());
}

#[test]
fn a_mirror_over_a_diffuse_colour_makes_the_material() {
    let mut d = delegate();
    d.set_mesh("/quad", quad(Some(SurfaceInputs::mirror("/quad", [0.2, 0.4, 0.6], [0.5; 3]))));
    let m = built(d);
    assert_eq!(m.surface.diffuse_color, Vec3A::new(0.2, 0.4, 0.6));
    assert_eq!((m.surface.specular_color, m.surface.roughness), (Vec3A::splat(0.5), 0.0));
}

#[test]
fn textured_inputs_become_texture_lookups_with_their_channel() {
    let dir = std::env::temp_dir().join(format!("mipray-materials-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("rgba.exr");
    // 2×2 texels: r = 0.25, g = 0.5, b = 0.75, a = 1 everywhere.
    let image = ImageBuf {
        width: 2,
        height: 2,
        channels: ["R", "G", "B", "A"].map(String::from).to_vec(),
        pixels: [0.25f32, 0.5, 0.75, 1.0].repeat(4),
        metadata: Vec::new(),
    };
    OiioImageIo.write(&file, &image, &[ChannelFormat::Float], &[]).unwrap();
    let file = file.to_str().unwrap();
    let textures = vec![(Input::DiffuseColor, texture(file, 0)), (Input::Roughness, texture(file, 1)), (Input::Ior, texture(file, 3))];
    let mut d = delegate();
    d.set_mesh(
        "/quad",
        quad(Some(SurfaceInputs { name: "/Looks/T".into(), surface: PreviewSurface::default(), textures, networks: Vec::new() })),
    );
    let m = built(d);
    assert_eq!(m.textures.len(), 3);
    let diffuse = m.texture(Input::DiffuseColor).unwrap();
    assert_eq!((diffuse.scale, diffuse.bias), (Vec3A::new(2.0, 3.0, 4.0), Vec3A::new(0.1, 0.2, 0.3)));
    assert_eq!(diffuse.lookup.first_channel, 0);
    // A float input reads one channel: the connected output's scale, bias and fallback.
    let rough = m.texture(Input::Roughness).unwrap();
    assert_eq!(rough.lookup.first_channel, 1);
    assert_eq!((rough.scale, rough.bias, rough.fallback), (Vec3A::splat(3.0), Vec3A::splat(0.2), Vec3A::splat(0.7)));
    let ior = m.texture(Input::Ior).unwrap();
    assert_eq!((ior.lookup.first_channel, ior.scale.x, ior.bias.x), (3, 5.0, 0.4));
    // The lookup reads the file: r · 2 + 0.1 = 0.6 in diffuseColor's first component.
    let v = diffuse.eval(Some([0.5, 0.5]), [0.0; 2], [0.0; 2]);
    assert!((v.x - 0.6).abs() < 1e-5, "{v}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_unreadable_texture_makes_its_fallback_the_constant() {
    let textures = vec![(Input::Roughness, texture("/no/such/file.exr", 2)), (Input::SpecularColor, texture("/no/such/file.exr", 0))];
    let mut d = delegate();
    d.set_mesh(
        "/quad",
        quad(Some(SurfaceInputs { name: "/Looks/U".into(), surface: PreviewSurface::default(), textures, networks: Vec::new() })),
    );
    let m = built(d);
    assert!(m.textures.is_empty());
    assert_eq!(m.surface.roughness, 0.8, "the b channel's fallback");
    assert_eq!(m.surface.specular_color, Vec3A::new(0.6, 0.7, 0.8));
}

#[test]
fn a_material_edit_rebuilds_no_surface() {
    let mut d = delegate();
    let inputs = SurfaceInputs::new("/Looks/E");
    d.set_mesh("/quad", quad(Some(inputs.clone())));
    assert!(d.sync().is_empty());
    assert_eq!(d.mesh("/quad").unwrap().surface_syncs, 1);
    let mut rougher = inputs;
    rougher.surface.roughness = 0.9;
    d.set_mesh("/quad", quad(Some(rougher)));
    assert!(d.mesh("/quad").unwrap().dirty.contains(hd_mipray::dirty_bits::DirtyBits::MATERIAL));
    assert!(d.sync().is_empty());
    assert_eq!(d.mesh("/quad").unwrap().surface_syncs, 1);
    assert_eq!(built(d).surface.roughness, 0.9);
}
