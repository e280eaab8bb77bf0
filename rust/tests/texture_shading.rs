//! Textured diffuse colour filtered by the ray differentials (the paper's §2.6, §6.3.3): a
//! texture seen small is read from a coarse MIP level, seen large from a fine one; forcing the
//! finest level reads level 0 whatever the size.

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::material::{Material, TexturedColor};
use mipray::prelude::*;
use mipray::texture::{CheckerSampler, FilterMode, Interpolation, Lookup, Primvar2, TextureSampler};

fn textured_scene(sampler: Arc<CheckerSampler>) -> Scene {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let pts = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]];
    let st = Primvar2 {
        name: "st".into(),
        interpolation: Interpolation::Vertex,
        values: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        indices: vec![],
    };
    let surface = BilinearSurface::new(&topo, &pts).unwrap().with_primvars(&topo, 4, &[st]).unwrap();
    let dyn_sampler: Arc<dyn TextureSampler> = sampler.clone();
    let texture = dyn_sampler.handle("checker").unwrap();
    let mut mat = Material::lambertian("/checker", Vec3A::splat(0.5)).0;
    mat.textures.push((
        mipray::material::Input::DiffuseColor,
        TexturedColor {
            sampler: dyn_sampler.clone(),
            texture,
            path: "checker".into(),
            lookup: Lookup::DEFAULT,
            scale: Vec3A::ONE,
            bias: Vec3A::ZERO,
            fallback: Vec3A::splat(0.18),
            st_channel: 0,
        },
    ));
    let mut scene = Scene::default();
    let m = scene.add_material(mat);
    let mut mesh = Mesh::new("/quad", Arc::new(surface));
    mesh.material = m;
    let i = scene.add_mesh(mesh);
    scene.add_instance(i, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", Vec3A::NEG_Z, Vec3A::splat(std::f32::consts::PI)));
    // Exactly the quad, seen head-on: 20 tenths = 2 units wide.
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 20.0, 20.0);
    scene.textures = Some(dyn_sampler);
    scene
}

#[test]
fn texture_lookups_follow_the_pixel_footprint() {
    // A 512² checker over the quad: at 32 pixels each pixel covers 16 texels (level 4); at 256
    // pixels, 2 texels (level 1).
    let mut levels = Vec::new();
    for width in [32usize, 256] {
        let sampler = Arc::new(CheckerSampler::new("checker", 512, 8, FilterMode::Differentials));
        let scene = textured_scene(sampler.clone());
        let out = render(&scene, &RenderOptions { width, height: width, ..Default::default() }, &NoProgress).unwrap();
        let expected = (512.0 / width as f64).log2();
        assert!((sampler.mean_level() - expected).abs() < 0.3, "{width} px: mean level {} vs {expected}", sampler.mean_level());
        levels.push(sampler.mean_level());
        // Radiance = albedo for E = π: the checker's squares are 0 and 1 (or their box averages).
        let c = &out.film.aov("color").unwrap().data;
        let mean = c.iter().step_by(3).sum::<f32>() / (width * width) as f32;
        assert!((mean - 0.5).abs() < 0.05, "{mean}");
        assert!(out.stats["texture_cache"].is_object());
    }
    assert!(levels[0] > levels[1] + 2.5);
}

#[test]
fn finest_mode_ignores_the_differentials() {
    let sampler = Arc::new(CheckerSampler::new("checker", 512, 8, FilterMode::Finest));
    let scene = textured_scene(sampler.clone());
    render(&scene, &RenderOptions { width: 32, height: 32, ..Default::default() }, &NoProgress).unwrap();
    assert_eq!(sampler.mean_level(), 0.0);
}
