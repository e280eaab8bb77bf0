//! Renders with known answers: a lambertian plane under a distant light, a shadow that must fall
//! exactly where geometry says, and the geometry cache never changing the picture.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::geometry_cache::CacheConfig;
use mipray::prelude::*;

fn quad(half: f32, z: f32) -> BilinearSurface {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let pts = [[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]];
    BilinearSurface::new(&topo, &pts).unwrap()
}

fn plane_scene(light_dir: Vec3A, irradiance: f32) -> Scene {
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/plane", Arc::new(quad(10.0, 0.0))));
    scene.add_instance(m, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", light_dir, Vec3A::splat(irradiance)));
    scene.camera = Camera::orthographic(Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0)), 40.0, 40.0);
    scene
}

#[test]
fn lambertian_plane_under_distant_light_has_the_analytic_radiance() {
    // L = ρ/π · E · cos θ, with ρ = 0.18 (UsdPreviewSurface's default) and E = 3.
    for theta_deg in [0.0f32, 30.0, 60.0, 85.0] {
        let th = theta_deg.to_radians();
        let dir = -Vec3A::new(th.sin(), 0.0, th.cos());
        let scene = plane_scene(dir, 3.0);
        let opts = RenderOptions { width: 8, height: 8, aovs: vec![Aov::Color, Aov::Depth, Aov::Normal], ..Default::default() };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        let expected = 0.18 / PI * 3.0 * th.cos();
        for y in 0..8 {
            for x in 0..8 {
                let c = out.film.pixel("color", x, y);
                assert!((c[0] - expected).abs() < 1e-5 * expected.max(1.0), "θ={theta_deg}: {} vs {expected}", c[0]);
            }
        }
        assert!((out.film.pixel("depth", 3, 3)[0] - 5.0).abs() < 1e-4);
        assert_eq!(out.film.pixel("normal", 3, 3), &[0.0, 0.0, 1.0]);
    }
}

#[test]
fn an_occluder_casts_a_shadow_exactly_where_geometry_puts_it() {
    // A 2×2 quad 1 unit above the plane, light straight down: shadow is the square |x|,|y| < 1.
    let mut scene = plane_scene(Vec3A::NEG_Z, 1.0);
    let occ = scene.add_mesh(Mesh::new("/occluder", Arc::new(quad(1.0, 1.0))));
    // Seen from the camera the occluder hides its own shadow; look from the side instead.
    scene.add_instance(occ, Mat4::IDENTITY);
    scene.camera = Camera::orthographic(Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0)), 80.0, 80.0);
    // Move the light so the shadow lands beside the occluder: direction (1, 0, -1)/√2 shifts it
    // by +1 in x (height 1), to 0 < x < 2, of which 1 < x < 2 is visible past the occluder.
    scene.lights[0] = Light::distant("/sun", Vec3A::new(1.0, 0.0, -1.0), Vec3A::ONE);
    let opts = RenderOptions { width: 80, height: 80, ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    // Pixel (x, y) centre is at world (x+0.5-40)/10, (40-y-0.5)/10.
    let at =
        |wx: f32, wy: f32| out.film.pixel("color", (wx * 10.0 + 40.0 - 0.5).round() as usize, (40.0 - wy * 10.0 - 0.5).round() as usize)[0];
    let lit = 0.18 / PI * (PI / 4.0).cos();
    assert!((at(1.5, 0.0) - 0.0).abs() < 1e-6, "shadow at x=1.5: {}", at(1.5, 0.0));
    assert!((at(1.85, 0.5) - 0.0).abs() < 1e-6);
    assert!((at(2.25, 0.0) - lit).abs() < 1e-5, "lit beyond the shadow: {}", at(2.25, 0.0));
    assert!((at(-3.0, 0.0) - lit).abs() < 1e-5);
    assert!((at(2.5, 1.5) - lit).abs() < 1e-5);
    // The occluder's top is lit too.
    assert!((at(0.0, 0.0) - lit).abs() < 1e-5);
    let stats = &out.stats;
    assert!(stats["render"]["rays"]["shadow"].as_u64().unwrap() > 0);
}

#[test]
fn cache_modes_give_bit_identical_images() {
    let mut scene = plane_scene(Vec3A::new(0.3, 0.2, -1.0), 2.0);
    // A bumpy bilinear grid so rates matter.
    let n = 12;
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32 * 4.0 - 2.0, j as f32 / n as f32 * 4.0 - 2.0);
            pts.push([x, y, 1.0 + 0.3 * (x * 2.0).sin() * (y * 3.0).cos()]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = |a: i32, b: i32| b * (n + 1) + a;
            idx.extend([v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    let topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4; (n * n) as usize],
        face_vertex_indices: idx,
        ..Default::default()
    };
    let m = scene.add_mesh(Mesh::new("/bumps", Arc::new(BilinearSurface::new(&topo, &pts).unwrap())));
    scene.add_instance(m, Mat4::IDENTITY);
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(3.0, -4.0, 6.0), Vec3::ZERO, Vec3::Z), 35.0);
    let base = RenderOptions { width: 48, height: 36, samples: 2, aovs: vec![Aov::Color, Aov::TessRate], ..Default::default() };
    let images: Vec<_> = [CacheConfig::multires(30_000_000), CacheConfig::unbounded(), CacheConfig::none(), CacheConfig::multires(2_000)]
        .into_iter()
        .map(|cache| render(&scene, &RenderOptions { cache, ..base.clone() }, &NoProgress).unwrap())
        .collect();
    for o in &images[1..] {
        assert_eq!(o.film.aov("color").unwrap().data, images[0].film.aov("color").unwrap().data);
    }
    // And the same with one thread.
    let one = render(&scene, &RenderOptions { threads: 1, ..base.clone() }, &NoProgress).unwrap();
    assert_eq!(one.film.aov("color").unwrap().data, images[0].film.aov("color").unwrap().data);
    let lit = images[0].film.aov("color").unwrap().data.iter().filter(|v| **v > 0.0).count();
    assert!(lit > 100, "the scene must actually render something: {lit}");
}

#[test]
fn bad_settings_are_refused_with_the_setting_named() {
    let scene = plane_scene(Vec3A::NEG_Z, 1.0);
    // AOV names are parsed where they come in: an unknown one never reaches the render.
    let e = Aov::parse("colour").unwrap_err().to_string();
    assert!(e.contains("colour") && e.contains("color"), "{e}");
    let e = render(&scene, &RenderOptions { tess_factor: f32::NAN, ..Default::default() }, &NoProgress).err().unwrap().to_string();
    assert!(e.contains("tessFactor"), "{e}");
}
