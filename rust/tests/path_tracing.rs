//! The path tracer (and the integrator choice) against closed forms: white furnaces (convex
//! and concave), a lambertian plane under a distant light, Russian roulette keeping the mean,
//! an emissive quad seen directly and through a diffuse bounce (a form factor), and hemisphere
//! rays traced only when a setting asks for them.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::bounds::Bounds3;
use mipray::light::LightShape;
use mipray::material::{Material, PreviewSurface};
use mipray::options::IntegratorKind;
use mipray::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};
use mipray::prelude::*;

/// A sphere of radius `r` about the origin as 8 analytic patches (4 in longitude × 2 in
/// latitude): convex, closed.
struct Sphere {
    r: f32,
}

impl LimitSurface for Sphere {
    fn patch_count(&self) -> usize {
        8
    }
    fn patch_param(&self, patch: usize) -> PatchParam {
        PatchParam::root(patch as u32, patch as u32, PatchKind::Other)
    }
    fn patch_bounds(&self, _patch: usize) -> Bounds3 {
        Bounds3 { min: Vec3A::splat(-self.r), max: Vec3A::splat(self.r) }
    }
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        let phi = (patch % 4) as f32 * PI / 2.0 + u * PI / 2.0;
        let theta = (patch / 4) as f32 * PI / 2.0 + v * PI / 2.0;
        let p = Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()) * self.r;
        let dpdu = Vec3A::new(-theta.sin() * phi.sin(), theta.sin() * phi.cos(), 0.0) * self.r * PI / 2.0;
        let dpdv = Vec3A::new(theta.cos() * phi.cos(), theta.cos() * phi.sin(), -theta.sin()) * self.r * PI / 2.0;
        let dpduu = -Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), 0.0) * self.r * (PI / 2.0).powi(2);
        let dpduv = Vec3A::new(-theta.cos() * phi.sin(), theta.cos() * phi.cos(), 0.0) * self.r * (PI / 2.0).powi(2);
        let dpdvv = -p * (PI / 2.0).powi(2);
        SurfacePoint { p, dpdu, dpdv, dpduu, dpduv, dpdvv }
    }
    fn control_face_count(&self) -> usize {
        8
    }
}

/// A polygonal mesh (no subdivision) of quads over `points`.
fn quads(points: &[[f32; 3]], faces: &[[i32; 4]]) -> Arc<BilinearSurface> {
    let topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4; faces.len()],
        face_vertex_indices: faces.iter().flatten().copied().collect(),
        ..Default::default()
    };
    Arc::new(BilinearSurface::new(&topo, points).unwrap())
}

fn add(scene: &mut Scene, name: &str, surface: Arc<dyn LimitSurface>, material: Material) {
    let mat = scene.add_material(material);
    let mut m = Mesh::new(name, surface);
    m.material = mat;
    let i = scene.add_mesh(m);
    scene.add_instance(i, Mat4::IDENTITY);
}

fn lambert(name: &str, albedo: f32) -> Material {
    Material::lambertian(name, Vec3A::splat(albedo)).0
}

/// A uniform dome light of radiance 1: the furnace.
fn furnace_dome() -> Light {
    Light::usd_area("/dome", LightShape::Dome(None), 1.0, 0.0, Vec3A::ONE, false)
}

/// An open box, 2 × 2 × 2, open at the top (z = 2): five inward-and-outward-facing walls.
fn open_box() -> Arc<BilinearSurface> {
    let p = [
        [-1.0, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
        [-1.0, -1.0, 2.0],
        [1.0, -1.0, 2.0],
        [1.0, 1.0, 2.0],
        [-1.0, 1.0, 2.0],
    ];
    quads(&p, &[[0, 3, 2, 1], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
}

/// Mean and standard error of the mean of a channel-0 sample over pixels passing `keep`.
fn mean_and_error(values: &[f32], keep: impl Fn(usize) -> bool) -> (f64, f64) {
    let v: Vec<f64> = values.iter().enumerate().filter(|(i, _)| keep(*i)).map(|(_, x)| f64::from(*x)).collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

fn red(out: &RenderOutput) -> Vec<f32> {
    out.film.aov("color").unwrap().data.iter().step_by(3).copied().collect()
}

#[test]
fn white_furnace_convex_sphere_gives_its_albedo_with_every_integrator() {
    // Inside a uniform dome of radiance 1, a convex lambertian object of albedo ρ reflects
    // exactly ρ everywhere: it never sees itself, so one bounce is the whole answer. With ρ = 1
    // every pixel, the dome behind included, is 1.
    for albedo in [1.0f32, 0.5] {
        let mut scene = Scene::default();
        add(&mut scene, "/sphere", Arc::new(Sphere { r: 1.0 }), lambert("/white", albedo));
        scene.lights.push(furnace_dome());
        scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -4.0, 1.0), Vec3::ZERO, Vec3::Z), 40.0);
        for integrator in [IntegratorKind::Auto, IntegratorKind::Path] {
            let opts =
                RenderOptions { width: 24, height: 24, samples: 4, integrator, aovs: vec![Aov::Color, Aov::Alpha], ..Default::default() };
            let out = render(&scene, &opts, &NoProgress).unwrap();
            let alpha = &out.film.aov("alpha").unwrap().data;
            let c = red(&out);
            let on = |i: usize| alpha[i] == 1.0;
            assert!((0..c.len()).filter(|&i| on(i)).count() > 150, "the sphere must cover the view");
            let (mean, _) = mean_and_error(&c, on);
            assert!((mean - f64::from(albedo)).abs() < 0.01, "{integrator:?} ρ={albedo}: mean {mean}");
            for (i, v) in c.iter().enumerate().filter(|(i, _)| on(*i)) {
                // Shadow rays sample the tessellation's own horizon, slightly off the exact
                // sphere's: a few percent at the silhouette, nothing in the middle.
                assert!((v - albedo).abs() < 0.06, "{integrator:?} ρ={albedo}: pixel {i} = {v}");
            }
            if integrator == IntegratorKind::Path {
                // The escaped camera rays see the dome.
                assert!(c.iter().zip(alpha).filter(|(_, a)| **a == 0.0).all(|(v, _)| *v == 1.0));
            }
        }
    }
}

#[test]
fn white_furnace_concave_box_is_one_only_with_path_tracing() {
    // Albedo 1 in a dome of radiance 1: L = 1 + ∫(L − 1)…, so L = 1 everywhere, inside the box
    // too — but only if every bounce is followed. Direct lighting alone sees the walls' shadow.
    let mut scene = Scene::default();
    add(&mut scene, "/box", open_box(), lambert("/white", 1.0));
    scene.lights.push(furnace_dome());
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -1.2, 5.0), Vec3::new(0.0, 0.0, 0.5), Vec3::Y), 30.0);
    let base = RenderOptions { width: 24, height: 24, samples: 32, max_depth: 48, aovs: vec![Aov::Color], ..Default::default() };
    let path = render(&scene, &RenderOptions { integrator: IntegratorKind::Path, ..base.clone() }, &NoProgress).unwrap();
    let c = red(&path);
    let (mean, err) = mean_and_error(&c, |_| true);
    // Paths lose the light of bounces past 48: < 0.8^48 inside a box open on one side of five.
    assert!((mean - 1.0).abs() < (4.0 * err).max(0.004), "path-traced furnace mean {mean} ± {err}");
    // No region is off either (a leak at the box's edges, light lost in its corners): each 4×4
    // block's mean is within 5 standard errors of 1, the error from the pixels' own spread.
    let sigma_block = err * (c.len() as f64).sqrt() / 4.0;
    for by in 0..6 {
        for bx in 0..6 {
            let block: f64 = (0..16).map(|k| f64::from(c[(by * 4 + k / 4) * 24 + bx * 4 + k % 4])).sum::<f64>() / 16.0;
            assert!((block - 1.0).abs() < 5.0 * sigma_block, "block ({bx}, {by}): {block} (σ {sigma_block})");
        }
    }
    let classic = render(&scene, &base, &NoProgress).unwrap();
    let (cm, _) = mean_and_error(&red(&classic), |_| true);
    assert!(cm < 0.85, "direct lighting alone must miss the box's interreflection: {cm}");
}

#[test]
fn lambertian_plane_under_a_distant_light_is_rho_over_pi_e_cos() {
    // One plane: nothing to bounce to, so the path tracer equals the closed form exactly.
    for theta_deg in [0.0f32, 40.0, 75.0] {
        let th = theta_deg.to_radians();
        let mut scene = Scene::default();
        add(
            &mut scene,
            "/plane",
            quads(&[[-10.0, -10.0, 0.0], [10.0, -10.0, 0.0], [10.0, 10.0, 0.0], [-10.0, 10.0, 0.0]], &[[0, 1, 2, 3]]),
            lambert("/m", 0.6),
        );
        scene.lights.push(Light::distant("/sun", -Vec3A::new(th.sin(), 0.0, th.cos()), Vec3A::splat(2.5)));
        scene.camera = Camera::orthographic(Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0)), 8.0, 8.0);
        let opts = RenderOptions { width: 8, height: 8, samples: 2, integrator: IntegratorKind::Path, ..Default::default() };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        let expected = 0.6 / PI * 2.5 * th.cos();
        for v in red(&out) {
            assert!((v - expected).abs() < 1e-5, "θ={theta_deg}: {v} vs {expected}");
        }
        assert!(out.stats["render"]["rays"]["diffuse"].as_u64().unwrap() > 0);
    }
}

#[test]
fn russian_roulette_keeps_the_mean() {
    // Albedo 0.8 in the open box: paths are cut by roulette from the first bounce on, against no
    // roulette up to 48 bounces (0.8^48 < 3e-5: nothing left). Same expectation; fewer rays.
    // Most of the light here comes after the first bounce, so a roulette that forgot to divide
    // by its survival probability would be about 20 % dark (0.49 against 0.60, measured).
    let mut scene = Scene::default();
    add(&mut scene, "/box", open_box(), lambert("/grey", 0.8));
    scene.lights.push(furnace_dome());
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -1.2, 5.0), Vec3::new(0.0, 0.0, 0.5), Vec3::Y), 30.0);
    let base = RenderOptions {
        width: 24,
        height: 24,
        samples: 64,
        max_depth: 48,
        integrator: IntegratorKind::Path,
        aovs: vec![Aov::Color],
        ..Default::default()
    };
    let off = render(&scene, &RenderOptions { russian_roulette_depth: 48, ..base.clone() }, &NoProgress).unwrap();
    let on = render(&scene, &RenderOptions { russian_roulette_depth: 0, seed: 1, ..base.clone() }, &NoProgress).unwrap();
    let (m_off, e_off) = mean_and_error(&red(&off), |_| true);
    let (m_on, e_on) = mean_and_error(&red(&on), |_| true);
    let sigma = (e_off * e_off + e_on * e_on).sqrt();
    eprintln!("roulette {m_on} ± {e_on}, fixed depth {m_off} ± {e_off}");
    assert!((m_on - m_off).abs() < 4.0 * sigma, "roulette {m_on} vs fixed depth {m_off} (σ {sigma})");
    let rays = |o: &RenderOutput| o.stats["render"]["rays"]["diffuse"].as_u64().unwrap();
    eprintln!("diffuse rays: roulette {}, fixed depth {}", rays(&on), rays(&off));
    assert!(rays(&on) * 10 < rays(&off) * 9, "roulette must end paths early: {} vs {}", rays(&on), rays(&off));
    // Radiance under a sky of 1 with albedo < 1 stays below 1 (and the box is not black).
    assert!(m_off > 0.1 && m_off < 1.0, "{m_off}");
}

/// A form factor from a differential area to a parallel rectangle, the area's normal through
/// one corner: sides a and b at distance c (Howell's catalogue, B-3).
fn corner_form_factor(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
}

fn emitter(le: Vec3A) -> Material {
    // Black and without a specular layer: it emits and reflects nothing.
    let surface = PreviewSurface {
        diffuse_color: Vec3A::ZERO,
        emissive_color: le,
        use_specular_workflow: true,
        specular_color: Vec3A::ZERO,
        ..PreviewSurface::default()
    };
    Material::preview_surface("/emitter", surface).0
}

#[test]
fn an_emissive_quad_is_seen_directly_and_lights_a_floor_by_its_form_factor() {
    // A square emitter (half-size 1, radiance Le, black) facing down at height 1 over a floor of
    // albedo ρ. Seen directly its pixels are Le. Under its centre the floor's radiance is
    // ρ·Le·F, F = 4 × the corner form factor for a 1 × 1 rectangle at distance 1: emissive
    // surfaces are not lights, so only the path tracer's diffuse bounce finds this light.
    let le = Vec3A::new(2.0, 1.0, 0.5);
    let rho = 0.7;
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/floor",
        quads(&[[-50.0, -50.0, 0.0], [50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [-50.0, 50.0, 0.0]], &[[0, 1, 2, 3]]),
        lambert("/floor", rho),
    );
    add(
        &mut scene,
        "/emitter",
        quads(&[[-1.0, -1.0, 1.0], [-1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, -1.0, 1.0]], &[[0, 1, 2, 3]]),
        emitter(le),
    );
    // Between the two, looking down at a 0.02-wide patch of floor under the centre.
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 0.5), Vec3::ZERO, Vec3::Y), 0.02, 0.02);
    let opts = RenderOptions { width: 8, height: 8, samples: 256, integrator: IntegratorKind::Path, ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let f = 4.0 * corner_form_factor(1.0, 1.0, 1.0);
    let c = &out.film.aov("color").unwrap().data;
    for ch in 0..3 {
        let v: Vec<f32> = c.iter().skip(ch).step_by(3).copied().collect();
        let (mean, err) = mean_and_error(&v, |_| true);
        let expected = f64::from(rho * le[ch]) * f;
        // Bernoulli hits of probability F ≈ 0.55 over 16384 paths: 0.7 % standard error.
        assert!((mean - expected).abs() < 4.0 * err + 1e-3, "channel {ch}: {mean} ± {err} vs {expected}");
    }
    // The classic integrator has no diffuse bounce: the floor stays black.
    let classic = render(&scene, &RenderOptions { integrator: IntegratorKind::Auto, samples: 1, ..opts.clone() }, &NoProgress).unwrap();
    assert!(red(&classic).iter().all(|v| *v == 0.0));
    // Seen directly from below, through the same camera moved under it: exactly Le.
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 0.5), Vec3::new(0.0, 0.0, 1.0), Vec3::Y), 1.0, 1.0);
    for integrator in [IntegratorKind::Path, IntegratorKind::Ao] {
        let o = RenderOptions { integrator, samples: 2, ao_samples: 4, ..opts.clone() };
        let direct = render(&scene, &o, &NoProgress).unwrap();
        for px in direct.film.aov("color").unwrap().data.chunks(3) {
            assert_eq!(px, &le.to_array(), "{integrator:?}");
        }
    }
}

#[test]
fn hemisphere_rays_are_traced_only_when_a_setting_asks_for_them() {
    // A plane under a sun: the scene calls for nothing but camera and shadow rays.
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/plane",
        quads(&[[-10.0, -10.0, 0.0], [10.0, -10.0, 0.0], [10.0, 10.0, 0.0], [-10.0, 10.0, 0.0]], &[[0, 1, 2, 3]]),
        lambert("/m", 0.5),
    );
    add(
        &mut scene,
        "/wall",
        quads(&[[0.0, -10.0, 0.0], [0.0, 10.0, 0.0], [0.0, 10.0, 5.0], [0.0, -10.0, 5.0]], &[[0, 1, 2, 3]]),
        lambert("/m", 0.5),
    );
    scene.lights.push(Light::distant("/sun", Vec3A::new(-0.3, 0.2, -1.0), Vec3A::ONE));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(6.0, -6.0, 6.0), Vec3::ZERO, Vec3::Z), 50.0);
    let run = |integrator: IntegratorKind, ao_samples: u32| {
        let opts = RenderOptions { width: 16, height: 16, samples: 2, integrator, ao_samples, ..Default::default() };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        let rays = &out.stats["render"]["rays"];
        let count = |k: &str| rays[k].as_u64().unwrap();
        let effects: Vec<(String, String)> = out.stats["effects"]["enabled"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| (e["name"].as_str().unwrap().to_string(), e["why"].as_str().unwrap().to_string()))
            .collect();
        (["camera", "shadow", "diffuse", "ao", "glossy", "reflection", "refraction"].map(count), effects)
    };
    let names = |fx: &[(String, String)]| fx.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    // auto, nothing asked: camera and shadow rays only.
    let (r, fx) = run(IntegratorKind::Auto, 0);
    assert!(r[0] > 0 && r[1] > 0 && r[2..].iter().all(|&n| n == 0), "{r:?}");
    assert_eq!(names(&fx), ["camera", "shadows"]);
    // auto with aoSamples: AO rays, no diffuse ones.
    let (r, fx) = run(IntegratorKind::Auto, 8);
    assert!(r[3] > 0 && r[2] == 0, "{r:?}");
    assert!(fx.iter().any(|(n, why)| n == "ao" && why.contains("aoSamples = 8")), "{fx:?}");
    // direct ignores aoSamples.
    let (r, fx) = run(IntegratorKind::Direct, 8);
    assert!(r[3] == 0 && r[2] == 0, "{r:?}");
    assert!(!names(&fx).contains(&"ao".to_string()));
    // path: diffuse rays, and the effect says which setting asked.
    let (r, fx) = run(IntegratorKind::Path, 0);
    assert!(r[2] > 0 && r[3] == 0, "{r:?}");
    assert!(fx.iter().any(|(n, why)| n == "indirect_diffuse" && why.contains("integrator = path")), "{fx:?}");
    // ao: AO rays only, no shadow rays.
    let (r, fx) = run(IntegratorKind::Ao, 8);
    assert!(r[3] > 0 && r[1] == 0 && r[2] == 0, "{r:?}");
    assert_eq!(names(&fx), ["camera", "ao"]);
}

#[test]
fn the_ao_integrator_is_occlusion_times_albedo_times_intensity() {
    // Beside an "infinite" wall the cosine-weighted hemisphere is half blocked: AO = 1/2, and
    // the colour is AO × albedo × aoIntensity, pixel by pixel.
    let big = 1.0e4;
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/ground",
        quads(&[[-big, -big, 0.0], [big, -big, 0.0], [big, big, 0.0], [-big, big, 0.0]], &[[0, 1, 2, 3]]),
        lambert("/m", 0.4),
    );
    add(
        &mut scene,
        "/wall",
        quads(&[[0.0, -big, 0.0], [0.0, big, 0.0], [0.0, big, big], [0.0, -big, big]], &[[0, 1, 2, 3]]),
        lambert("/m", 0.4),
    );
    scene.lights.push(Light::distant("/sun", Vec3A::new(-0.3, 0.2, -1.0), Vec3A::ONE));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(2.0, 0.0, 10.0), Vec3::new(2.0, 0.0, 0.0), Vec3::Y), 2.0, 2.0);
    let opts = RenderOptions {
        width: 16,
        height: 16,
        ao_samples: 64,
        ao_intensity: 2.0,
        integrator: IntegratorKind::Ao,
        aovs: vec![Aov::Color, Aov::Ao],
        ..Default::default()
    };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let ao = &out.film.aov("ao").unwrap().data;
    let c = red(&out);
    for (a, v) in ao.iter().zip(&c) {
        assert!((v - a * 0.4 * 2.0).abs() < 1e-6, "{v} vs {a}");
    }
    let (mean, _) = mean_and_error(ao, |_| true);
    assert!((mean - 0.5).abs() < 0.016, "{mean}");
    // Without aoSamples the ao integrator refuses, naming the setting.
    let e = render(&scene, &RenderOptions { ao_samples: 0, ..opts }, &NoProgress).err().unwrap().to_string();
    assert!(e.contains("aoSamples"), "{e}");
}

#[test]
fn an_emissive_quad_seen_in_a_mirror_is_f0_times_its_radiance() {
    // A black mirror of normal-incidence reflectance 0.8 under a black emitter of radiance Le,
    // seen straight down from between them: the delta bounce finds the emitter, and at normal
    // incidence Schlick's Fresnel is exactly F0. No lights, no noise.
    let le = Vec3A::new(2.0, 1.0, 0.5);
    let mut scene = Scene::default();
    let mirror = Material::mirror("/mirror", Vec3A::ZERO, Vec3A::splat(0.8));
    add(&mut scene, "/mirror", quads(&[[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 0.0], [-5.0, 5.0, 0.0]], &[[0, 1, 2, 3]]), mirror);
    add(
        &mut scene,
        "/emitter",
        quads(&[[-5.0, -5.0, 2.0], [-5.0, 5.0, 2.0], [5.0, 5.0, 2.0], [5.0, -5.0, 2.0]], &[[0, 1, 2, 3]]),
        emitter(le),
    );
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 1.0), Vec3::ZERO, Vec3::Y), 2.0, 2.0);
    for integrator in [IntegratorKind::Path, IntegratorKind::Auto] {
        let opts =
            RenderOptions { width: 8, height: 8, samples: 4, integrator, aovs: vec![Aov::Color, Aov::Specular], ..Default::default() };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        for (px, spec) in out.film.aov("color").unwrap().data.chunks(3).zip(out.film.aov("specular").unwrap().data.chunks(3)) {
            for c in 0..3 {
                assert!((px[c] - 0.8 * le[c]).abs() < 1e-5, "{integrator:?}: {px:?}");
            }
            assert_eq!(px, spec, "{integrator:?}: all of it is the specular AOV");
        }
        let rays = &out.stats["render"]["rays"];
        assert_eq!(rays["reflection"].as_u64().unwrap(), 8 * 8 * 4, "{integrator:?}: one mirror ray per camera ray");
        assert_eq!(rays["diffuse"].as_u64().unwrap(), 0);
    }
}

#[test]
fn path_rays_are_wide_and_read_coarser_tessellations_than_camera_rays() {
    // The paper's point (§4.6, §2.5): a diffuse bounce's beam is wide, so the geometry cache
    // serves it coarse tessellations. On a bumpy (curved) surface, compare the rates that
    // camera and diffuse rays test subpatches at.
    let n = 12;
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32 * 6.0 - 3.0, j as f32 / n as f32 * 6.0 - 3.0);
            pts.push([x, y, 0.4 * (x * 1.5).sin() * (y * 2.0).cos()]);
        }
    }
    let faces: Vec<[i32; 4]> = (0..n)
        .flat_map(|j| (0..n).map(move |i| [j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i]))
        .collect();
    let mut scene = Scene::default();
    add(&mut scene, "/bumps", quads(&pts, &faces), lambert("/m", 0.7));
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.3, 0.2, -1.0), Vec3A::ONE));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -5.0, 4.0), Vec3::ZERO, Vec3::Z), 50.0);
    let opts = RenderOptions { width: 32, height: 32, samples: 4, max_depth: 3, integrator: IntegratorKind::Path, ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let mean_rate = |kind: &str| {
        let h = &out.stats["render"]["rate_tests_by_ray"][kind];
        let (mut n, mut sum) = (0.0, 0.0);
        for (k, q) in [("1", 1.0), ("2", 2.0), ("4", 4.0), ("8", 8.0), ("16", 16.0), ("split", 32.0)] {
            let c = h[k].as_u64().unwrap() as f64;
            n += c;
            sum += c * q;
        }
        assert!(n > 0.0, "{kind} rays tested subpatches");
        sum / n
    };
    let (camera, diffuse) = (mean_rate("camera"), mean_rate("diffuse"));
    eprintln!("mean quads per side tested: camera rays {camera:.2}, diffuse rays {diffuse:.2}");
    // Measured: camera 16.4, diffuse 8.0 quads per side.
    assert!(diffuse * 1.5 < camera, "diffuse rays at {diffuse} quads per side, camera rays at {camera}");
}

#[test]
fn the_path_tracers_aovs_split_its_colour_by_what_the_light_did() {
    // The grey open box under the dome: `directDiffuse` is the lights' light at the camera hit
    // (which the classic integrator estimates independently), `indirectDiffuse` the rest, and
    // the parts add up to the colour; the background is `emission`.
    let mut scene = Scene::default();
    add(&mut scene, "/box", open_box(), lambert("/grey", 0.5));
    scene.lights.push(furnace_dome());
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -3.0, 5.0), Vec3::new(0.0, 0.0, 0.5), Vec3::Y), 40.0);
    let aovs: Vec<Aov> = ["color", "alpha", "albedo", "emission", "directDiffuse", "indirectDiffuse", "specular"]
        .iter()
        .map(|s| Aov::from_name(s).unwrap())
        .collect();
    let base = RenderOptions { width: 24, height: 24, samples: 32, max_depth: 16, aovs, ..Default::default() };
    let path = render(&scene, &RenderOptions { integrator: IntegratorKind::Path, ..base.clone() }, &NoProgress).unwrap();
    let classic = render(&scene, &RenderOptions { seed: 5, ..base.clone() }, &NoProgress).unwrap();
    let ch = |o: &RenderOutput, aov: &str| -> Vec<f32> { o.film.aov(aov).unwrap().data.iter().step_by(3).copied().collect() };
    let (color, alpha) = (ch(&path, "color"), &path.film.aov("alpha").unwrap().data);
    let parts: Vec<[f32; 4]> = (0..color.len())
        .map(|i| ["emission", "directDiffuse", "indirectDiffuse", "specular"].map(|a| path.film.aov(a).unwrap().data[3 * i]))
        .collect();
    for (i, (c, p)) in color.iter().zip(&parts).enumerate() {
        assert!((c - p.iter().sum::<f32>()).abs() <= 1e-5 * c.max(1.0), "pixel {i}: {c} vs {p:?}");
        if alpha[i] == 0.0 {
            assert_eq!(p, &[1.0, 0.0, 0.0, 0.0], "the dome behind is emission");
        }
        if alpha[i] == 1.0 {
            assert_eq!(path.film.aov("albedo").unwrap().data[3 * i], 0.5);
            assert_eq!(p[3], 0.0, "a lambertian box reflects nothing specularly");
        }
    }
    let on = |i: usize| alpha[i] == 1.0;
    let (direct_path, e1) = mean_and_error(&ch(&path, "directDiffuse"), on);
    let (direct_classic, e2) = mean_and_error(&ch(&classic, "directDiffuse"), on);
    let sigma = (e1 * e1 + e2 * e2).sqrt();
    assert!((direct_path - direct_classic).abs() < 4.0 * sigma, "direct: path {direct_path} vs classic {direct_classic} (σ {sigma})");
    // What path tracing adds to direct lighting is its indirectDiffuse.
    let (indirect, e3) = mean_and_error(&ch(&path, "indirectDiffuse"), on);
    let (c_path, e4) = mean_and_error(&color, on);
    let (c_classic, e5) = mean_and_error(&ch(&classic, "color"), on);
    let sigma = (e2 * e2 + e3 * e3 + e4 * e4 + e5 * e5).sqrt();
    assert!(indirect > 4.0 * e3, "the box lights itself: {indirect} ± {e3}");
    assert!((c_path - c_classic - indirect).abs() < 4.0 * sigma, "{c_path} − {c_classic} vs indirect {indirect} (σ {sigma})");
    assert!(ch(&classic, "indirectDiffuse").iter().all(|v| *v == 0.0), "no bounce in the classic integrator");
}
