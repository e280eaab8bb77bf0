//! Distribution effects against analytic answers: ambient occlusion beside an infinite wall, a
//! flat mirror, and effects traced only when the scene calls for them.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::material::Material;
use mipray::prelude::*;
use mipray::topology::{MeshTopology, Scheme};

fn quad(corners: [[f32; 3]; 4]) -> Arc<BilinearSurface> {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    Arc::new(BilinearSurface::new(&topo, &corners).unwrap())
}

fn add(scene: &mut Scene, name: &str, surface: Arc<BilinearSurface>, material: Material) {
    let mat = scene.add_material(material);
    let mut m = Mesh::new(name, surface);
    m.material = mat;
    let i = scene.add_mesh(m);
    scene.add_instance(i, Mat4::IDENTITY);
}

#[test]
fn ambient_occlusion_beside_an_infinite_wall_is_one_half() {
    // Ground z = 0 facing +z; a wall x = 0 facing +x, both 1e4 wide: "infinite" seen from a
    // point near the corner. The wall hides exactly the half of the cosine-weighted hemisphere
    // that leans toward it: AO = 1/2 at every distance; with the wall gone, AO = 1.
    let big = 1.0e4;
    let mut scene = Scene::default();
    add(&mut scene, "/ground", quad([[-big, -big, 0.0], [big, -big, 0.0], [big, big, 0.0], [-big, big, 0.0]]), Material::default());
    add(&mut scene, "/wall", quad([[0.0, -big, 0.0], [0.0, big, 0.0], [0.0, big, big], [0.0, -big, big]]), Material::default());
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(2.0, 0.0, 10.0), Vec3::new(2.0, 0.0, 0.0), Vec3::Y), 20.0, 20.0);
    let opts = RenderOptions { width: 16, height: 16, ao_samples: 64, aovs: vec![Aov::Ao, Aov::Color], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let ao = &out.film.aov("ao").unwrap().data;
    let mean: f32 = ao.iter().sum::<f32>() / ao.len() as f32;
    // 16·16·64 = 16384 binary samples of p = 1/2: standard error 0.004; allow 4σ.
    assert!((mean - 0.5).abs() < 0.016, "mean AO {mean}");
    // Color is albedo × AO for a unit white sky.
    let c = &out.film.aov("color").unwrap().data;
    let cmean: f32 = c.iter().step_by(3).sum::<f32>() / ao.len() as f32;
    assert!((cmean - 0.18 * mean).abs() < 1e-4, "{cmean}");
    assert!(out.stats["render"]["rays"]["ao"].as_u64().unwrap() >= 16 * 16 * 60);
    assert!(out.stats["effects"]["enabled"].as_array().unwrap().iter().any(|e| e["name"] == "ao"));

    scene.instances.pop();
    let open = render(&scene, &opts, &NoProgress).unwrap();
    assert!(open.film.aov("ao").unwrap().data.iter().all(|a| *a == 1.0));
}

#[test]
fn a_flat_mirror_reflects_the_radiance_above_it() {
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/mirror",
        quad([[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 0.0], [-5.0, 5.0, 0.0]]),
        Material::mirror("/chrome", Vec3A::ZERO, Vec3A::splat(0.8)),
    );
    // A lit white ceiling facing down.
    add(
        &mut scene,
        "/ceiling",
        quad([[-50.0, -50.0, 10.0], [-50.0, 50.0, 10.0], [50.0, 50.0, 10.0], [50.0, -50.0, 10.0]]),
        Material::lambertian("/white", Vec3A::ONE).0,
    );
    let mut light = Light::distant("/up", Vec3A::Z, Vec3A::splat(2.0));
    light.casts_shadows = false;
    scene.lights.push(light);
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 40.0, 40.0);
    let opts = RenderOptions { width: 8, height: 8, aovs: vec![Aov::Color, Aov::BeamWidth], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let expected = 0.8 * 2.0 / PI;
    for p in out.film.aov("color").unwrap().data.chunks(3) {
        assert!((p[0] - expected).abs() < 1e-5, "{} vs {expected}", p[0]);
    }
    assert_eq!(out.stats["render"]["rays"]["reflection"].as_u64(), Some(64));
    assert_eq!(out.stats["render"]["rays"]["shadow"].as_u64(), Some(0), "the light casts no shadows");
}

#[test]
fn a_scene_that_calls_for_nothing_traces_camera_and_shadow_rays_only() {
    let mut scene = Scene::default();
    add(&mut scene, "/ground", quad([[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 0.0], [-5.0, 5.0, 0.0]]), Material::default());
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.2, 0.1, -1.0), Vec3A::ONE));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -8.0, 6.0), Vec3::ZERO, Vec3::Z), 35.0);
    let out = render(&scene, &RenderOptions { width: 16, height: 12, ..Default::default() }, &NoProgress).unwrap();
    let rays = &out.stats["render"]["rays"];
    for kind in ["reflection", "refraction", "glossy", "diffuse", "ao"] {
        assert_eq!(rays[kind].as_u64(), Some(0), "{kind}");
    }
    assert!(rays["shadow"].as_u64().unwrap() > 0);
    let names: Vec<&str> = out.stats["effects"]["enabled"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert_eq!(names, vec!["camera", "shadows"]);
}

#[test]
fn grazing_hits_clamp_differentials_count_them_and_stay_finite() {
    // A huge plane seen within a hundredth of a degree of edge-on: footprints explode, the
    // differentials are clamped, counted, and nothing non-finite reaches the film.
    let big = 1.0e5;
    let mut scene = Scene::default();
    add(&mut scene, "/ground", quad([[-big, -big, 0.0], [big, -big, 0.0], [big, big, 0.0], [-big, big, 0.0]]), Material::default());
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.0, 0.3, -1.0), Vec3A::ONE));
    let eye = Vec3::new(0.0, 0.0, 1.0);
    scene.camera = Camera {
        render_from_camera: Camera::look_at(eye, Vec3::new(0.0, 1.0e4, 0.99), Vec3::Z),
        focal_length: 50.0,
        clipping_range: (0.1, 1.0e7),
        ..Default::default()
    };
    let opts =
        RenderOptions { width: 32, height: 32, ao_samples: 4, aovs: vec![Aov::Color, Aov::BeamWidth, Aov::TessRate], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    assert!(out.stats["render"]["differential_clamps"].as_u64().unwrap() > 0);
    for a in ["color", "beamWidth", "tessRate"] {
        assert!(out.film.aov(a).unwrap().data.iter().all(|v| v.is_finite()), "{a}");
    }
}

#[test]
fn incoherent_tess_factor_coarsens_ao_rays_only() {
    // Bumpy (non-affine) ground so rates follow beams; AO rays at factor 16 must use coarser
    // rates than at factor 1, camera rays the same ones.
    let n = 16;
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 - 8.0, j as f32 - 8.0);
            pts.push([x, y, 0.2 * (x * 0.7).sin() * (y * 0.9).cos()]);
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
    let mut scene = Scene::default();
    add(&mut scene, "/bumps", Arc::new(BilinearSurface::new(&topo, &pts).unwrap()), Material::default());
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -9.0, 5.0), Vec3::ZERO, Vec3::Z), 35.0);
    let mean_rate = |out: &mipray::render::RenderOutput, kind: &str| {
        let h = &out.stats["render"]["rate_tests_by_ray"][kind];
        let (mut n, mut sum) = (0.0, 0.0);
        for (q, w) in [("1", 1.0), ("2", 2.0), ("4", 4.0), ("8", 8.0), ("16", 16.0), ("split", 32.0)] {
            let c = h[q].as_f64().unwrap();
            n += c;
            sum += c * w;
        }
        sum / n
    };
    let base = RenderOptions { width: 24, height: 16, ao_samples: 8, ..Default::default() };
    let fine = render(&scene, &base, &NoProgress).unwrap();
    let coarse = render(&scene, &RenderOptions { tess_factor_incoherent: 16.0, ..base.clone() }, &NoProgress).unwrap();
    assert!(mean_rate(&coarse, "ao") < 0.5 * mean_rate(&fine, "ao"), "{} vs {}", mean_rate(&coarse, "ao"), mean_rate(&fine, "ao"));
    assert_eq!(mean_rate(&coarse, "camera"), mean_rate(&fine, "camera"));
}

#[test]
fn depth_of_field_blurs_only_what_is_out_of_focus() {
    // Two thin bars across the view: one at the focus distance stays sharp (a pixel is fully
    // covered or empty), the other, far behind, is blurred into partial coverage.
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/near_bar",
        quad([[-0.05, -5.0, -10.0], [0.05, -5.0, -10.0], [0.05, 5.0, -10.0], [-0.05, 5.0, -10.0]]),
        Material::default(),
    );
    add(
        &mut scene,
        "/far_bar",
        quad([[0.9, -20.0, -40.0], [1.3, -20.0, -40.0], [1.3, 20.0, -40.0], [0.9, 20.0, -40.0]]),
        Material::default(),
    );
    scene.camera = Camera {
        render_from_camera: Mat4::IDENTITY,
        focal_length: 50.0,
        horizontal_aperture: 20.0,
        vertical_aperture: 2.0,
        f_stop: 1.4,
        focus_distance: 10.0,
        ..Default::default()
    };
    let opts = RenderOptions { width: 40, height: 4, samples: 64, aovs: vec![Aov::Alpha], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let names: Vec<&str> = out.stats["effects"]["enabled"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert!(names.contains(&"depth_of_field"), "{names:?}");
    let row: Vec<f32> = (0..40).map(|x| out.film.pixel("alpha", x, 2)[0]).collect();
    let partial = |r: std::ops::Range<usize>| row[r].iter().filter(|a| **a > 0.02 && **a < 0.98).count();
    // The view is 4 units wide at depth 10 (0.1 per pixel): the focused bar (x ±0.05) covers
    // half of pixels 19 and 20 and nothing else; at depth 40 the far bar is 1 pixel wide
    // in a pinhole view (pixels 22–23) and blurred over a dozen with the lens.
    assert!((row[19] - 0.5).abs() < 0.15 && (row[20] - 0.5).abs() < 0.15, "the focused bar stays sharp: {row:?}");
    assert!(partial(24..40) >= 4, "the far bar is spread over several partly covered pixels: {row:?}");
    scene.camera.f_stop = 0.0;
    let pin = render(&scene, &opts, &NoProgress).unwrap();
    let pin_row: Vec<f32> = (0..40).map(|x| pin.film.pixel("alpha", x, 2)[0]).collect();
    let pin_partial = pin_row[24..40].iter().filter(|a| **a > 0.02 && **a < 0.98).count();
    assert!(pin_partial <= 2, "without an f-stop only edge pixels are partial: {pin_row:?}");
}

#[test]
fn a_disk_light_lights_a_plane_as_the_formula_says_and_casts_soft_shadows() {
    use mipray::light::LightShape;
    // E = π L r² / (h² + r²) under a disk of radiance L, radius r, height h; radiance ρ E / π.
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/ground",
        quad([[-20.0, -20.0, 0.0], [20.0, -20.0, 0.0], [20.0, 20.0, 0.0], [-20.0, 20.0, 0.0]]),
        Material::lambertian("/white", Vec3A::ONE).0,
    );
    let disk = LightShape::Disk { center: Vec3A::new(0.0, 0.0, 2.0), u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z };
    scene.lights.push(Light::usd_area("/disk", disk, 1.0, 0.0, Vec3A::ONE, false));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 1.0), Vec3::ZERO, Vec3::Y), 1.0, 1.0);
    let opts = RenderOptions { width: 4, height: 4, samples: 16, shadow_samples: 64, ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let expected = 1.0 / (4.0 + 1.0);
    let c = &out.film.aov("color").unwrap().data;
    let mean = c.iter().step_by(3).sum::<f32>() / 16.0;
    assert!((mean - expected).abs() < 0.03 * expected, "{mean} vs {expected}");
    let names: Vec<&str> = out.stats["effects"]["enabled"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert!(names.contains(&"soft_shadows"), "{names:?}");
    // A small occluder halfway up: its shadow has a penumbra of partly lit pixels.
    add(&mut scene, "/blocker", quad([[-0.3, -0.3, 1.0], [0.3, -0.3, 1.0], [0.3, 0.3, 1.0], [-0.3, 0.3, 1.0]]), Material::default());
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 0.5), Vec3::ZERO, Vec3::Y), 60.0, 1.25);
    let out =
        render(&scene, &RenderOptions { width: 48, height: 1, samples: 4, shadow_samples: 32, ..Default::default() }, &NoProgress).unwrap();
    let row: Vec<f32> = (0..48).map(|x| out.film.pixel("color", x, 0)[0]).collect();
    let peak = row.iter().cloned().fold(0.0, f32::max);
    let partial = row.iter().filter(|v| **v > 0.1 * peak && **v < 0.9 * peak).count();
    assert!(partial >= 6, "a soft penumbra: {row:?}");
}
