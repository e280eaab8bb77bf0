//! Shared by the core's integration tests: f64 conversion for closed-form answers, the sunlit
//! scenes the geometry tests set up, and the checks several kinds of geometry go through alike.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

pub mod st_quad;

use std::sync::Arc;

use glam::{DVec3, Mat4, Vec3A};
use mipray::aov::Aov;
use mipray::geometry_cache::{CacheConfig, CacheMode};
use mipray::options::IntegratorKind;
use mipray::prelude::*;

/// `v` in f64, for answers computed independently of the renderer's f32.
pub fn d(v: Vec3A) -> DVec3 {
    DVec3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

/// `scene` under the geometry tests' sun (irradiance 3, shining along (−0.3, −0.5, −1)), seen
/// by `camera`.
pub fn lit(mut scene: Scene, camera: Camera) -> Scene {
    scene.lights.push(Light::distant("/sun", Vec3A::new(-0.3, -0.5, -1.0), Vec3A::splat(3.0)));
    scene.camera = camera;
    scene
}

/// A scene of `surface` alone, instanced once at `render_from_object`, under [`lit`]'s sun.
pub fn scene_of(name: &str, surface: Arc<dyn LimitSurface>, render_from_object: Mat4, camera: Camera) -> Scene {
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new(name, surface));
    scene.add_instance(m, render_from_object);
    lit(scene, camera)
}

/// The albedo of [`grey_under_the_sun`]'s material.
pub const ALBEDO: f32 = 0.5;
/// The irradiance of [`grey_under_the_sun`]'s sun.
pub const SUN_IRRADIANCE: f32 = 2.0;

/// `surface` alone, Lambertian of [`ALBEDO`], posed by `render_from_object`, under an angle-0
/// sun of [`SUN_IRRADIANCE`] shining along the unit `light`, seen by `camera`.
pub fn grey_under_the_sun(name: &str, surface: Arc<dyn LimitSurface>, render_from_object: Mat4, light: Vec3A, camera: Camera) -> Scene {
    let mut scene = Scene::default();
    let mat = scene.add_material(Material::lambertian("/half", Vec3A::splat(ALBEDO)).0);
    let mut mesh = Mesh::new(name, surface);
    mesh.material = mat;
    let m = scene.add_mesh(mesh);
    scene.add_instance(m, render_from_object);
    scene.lights.push(Light::distant("/sun", light, Vec3A::splat(SUN_IRRADIANCE)));
    scene.camera = camera;
    scene
}

/// Renders a [`grey_under_the_sun`] scene of a convex surface with every integrator, one
/// pixel-centre sample a pixel, and checks every covered pixel: AO is 1 (colour = albedo),
/// every other integrator's colour is ρ/π · E · max(0, n·l) within 2e-3 (the normal AOV is
/// half-float: its rounding bounds the lambert term's). More than `min_hits` pixels must be
/// covered.
pub fn assert_every_integrator_lights_it_exactly(scene: &Scene, light: Vec3A, (w, h): (usize, usize), name: &str, min_hits: usize) {
    for integrator in [IntegratorKind::Ao, IntegratorKind::Direct, IntegratorKind::ColorBleeding, IntegratorKind::Path] {
        let opts = RenderOptions {
            width: w,
            height: h,
            samples: 1,
            integrator,
            ao_samples: 16,
            indirect_samples: 8,
            max_depth: 4,
            aovs: vec![Aov::Color, Aov::Normal, Aov::Alpha],
            ..Default::default()
        };
        let out = render(scene, &opts, &NoProgress).unwrap();
        let mut hits = 0;
        for y in 0..h {
            for x in 0..w {
                if out.film.pixel("alpha", x, y)[0] == 0.0 {
                    continue;
                }
                hits += 1;
                let n = Vec3A::from_slice(out.film.pixel("normal", x, y));
                let got = out.film.pixel("color", x, y)[0];
                let want = match integrator {
                    IntegratorKind::Ao => ALBEDO,
                    _ => ALBEDO / std::f32::consts::PI * SUN_IRRADIANCE * n.dot(-light).max(0.0),
                };
                assert!((got - want).abs() < 2e-3, "{name} {integrator:?} ({x}, {y}): {got} vs {want}");
            }
        }
        assert!(hits > min_hits, "{name}: {hits}");
    }
}

/// Renders `scene` (64 × 48, 2 samples, colour, depth and normal) with the cache multiresolution,
/// unbounded and off, the budget small enough to evict, and checks the three images agree to
/// the bit (and are not empty).
pub fn assert_cache_modes_give_bit_identical_images(scene: &Scene) {
    let mut images = Vec::new();
    for mode in [CacheMode::Multires, CacheMode::Unbounded, CacheMode::None] {
        let cache = CacheConfig { mode, budget_bytes: [4096, 4096, 8192], ..Default::default() };
        let opts = RenderOptions {
            width: 64,
            height: 48,
            samples: 2,
            cache,
            aovs: vec![Aov::Color, Aov::Depth, Aov::Normal],
            ..Default::default()
        };
        let out = render(scene, &opts, &NoProgress).unwrap();
        let buf: Vec<u32> = ["color", "depth", "normal"]
            .iter()
            .flat_map(|a| (0..48).flat_map(move |y| (0..64).map(move |x| (a, x, y))))
            .flat_map(|(a, x, y)| out.film.pixel(a, x, y).iter().map(|v| v.to_bits()).collect::<Vec<_>>())
            .collect();
        assert!(buf.iter().any(|&b| f32::from_bits(b) > 0.0), "{mode:?}: empty image");
        images.push(buf);
    }
    assert!(images[0] == images[1], "multires differs from unbounded");
    assert!(images[0] == images[2], "multires differs from none");
}
