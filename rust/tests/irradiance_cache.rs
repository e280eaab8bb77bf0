//! Ambient occlusion, one-bounce color bleeding and the irradiance cache (the paper's §5.1)
//! against closed forms: a ground plane beside a wall, whose occlusion and form factor are known
//! exactly; a white furnace; a closed emissive box. Cached against uncached, gradients on against
//! off, one thread against two, and never a NaN.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::integrator::hemisphere::Hemisphere;
use mipray::integrator::shading_point;
use mipray::light::LightShape;
use mipray::material::{Material, PreviewSurface};
use mipray::options::IntegratorKind;
use mipray::prelude::*;
use mipray::trace::{TraceCounters, Tracer};

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

fn lambert(c: f32) -> Material {
    Material::lambertian("/lambert", Vec3A::splat(c)).0
}

fn emissive(albedo: f32, emission: f32) -> Material {
    let s = PreviewSurface {
        diffuse_color: Vec3A::splat(albedo),
        emissive_color: Vec3A::splat(emission),
        use_specular_workflow: true,
        specular_color: Vec3A::ZERO,
        ..PreviewSurface::default()
    };
    Material::preview_surface("/emitter", s).0
}

const BIG: f32 = 1.0e4;
/// Half the wall's width.
const WALL: f32 = 20.0;
/// Image of the ground strip x ∈ [X0, X0 + 3], |y| < 0.4 seen from above: 60 × 16 pixels.
const X0: f32 = 0.05;
const W: usize = 60;
const H: usize = 16;

/// Ground z = 0 (facing +z, albedo `ground`) beside a wall x = 0 facing +x, `height` high and
/// 2·10⁴ wide (infinite, seen from the strip), of material `wall`; an orthographic camera looks
/// straight down at the strip.
fn wall_scene(height: f32, ground: Material, wall: Material) -> Scene {
    let mut scene = Scene::default();
    add(&mut scene, "/ground", quad([[-BIG, -BIG, 0.0], [BIG, -BIG, 0.0], [BIG, BIG, 0.0], [-BIG, BIG, 0.0]]), ground);
    add(&mut scene, "/wall", quad([[0.0, -WALL, 0.0], [0.0, WALL, 0.0], [0.0, WALL, height], [0.0, -WALL, height]]), wall);
    let c = Vec3::new(X0 + 1.5, 0.0, 10.0);
    scene.camera = Camera::orthographic(Camera::look_at(c, c - Vec3::Z, Vec3::Y), 30.0, 8.0);
    scene
}

/// The ground point each pixel centre sees.
fn pixel_points(scene: &Scene) -> Vec<Vec3A> {
    let mut out = Vec::with_capacity(W * H);
    for y in 0..H {
        for x in 0..W {
            let r = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, W, H);
            out.push(r.o + r.d * (-r.o.z / r.d.z));
        }
    }
    out
}

/// The form factor from a differential area at `p` with normal `n` to the polygon `poly` lying
/// above its tangent plane: Lambert's contour integral, (1/2π) Σ γᵢ n·(rᵢ × rᵢ₊₁)/|rᵢ × rᵢ₊₁|, with
/// γᵢ the angle each edge subtends. It is the cosine-weighted fraction of the hemisphere the
/// polygon covers.
fn form_factor(p: Vec3A, n: Vec3A, poly: &[Vec3A]) -> f32 {
    let mut sum = 0.0f64;
    for i in 0..poly.len() {
        let a = (poly[i] - p).normalize();
        let b = (poly[(i + 1) % poly.len()] - p).normalize();
        let c = a.cross(b);
        if c.length() > 0.0 {
            sum += f64::from(a.dot(b).clamp(-1.0, 1.0).acos()) * f64::from(n.dot(c.normalize()));
        }
    }
    (sum.abs() / (2.0 * std::f64::consts::PI)) as f32
}

/// The form factor from ground point `p` (normal +z) to the wall of [`wall_scene`].
fn wall_factor(p: Vec3A, height: f32) -> f32 {
    let wall = [Vec3A::new(0.0, -WALL, 0.0), Vec3A::new(0.0, WALL, 0.0), Vec3A::new(0.0, WALL, height), Vec3A::new(0.0, -WALL, height)];
    form_factor(p, Vec3A::Z, &wall)
}

/// Unoccluded fraction of the cosine-weighted hemisphere at distance `d` from an infinitely wide
/// wall of height `h`: 1 − F, with F = ½(1 − d/√(d² + h²)) the form factor to the infinite strip
/// (Lambert's contour integral: the bottom edge, on the horizon, subtends π; the top edge
/// π·d/√(d² + h²), with the opposite sign; the side edges vanish).
fn open_beside_strip(d: f32, h: f32) -> f32 {
    0.5 + 0.5 * d / (d * d + h * h).sqrt()
}

/// Unoccluded fraction within `ao_distance` D of an infinite wall (any height) at distance d:
/// the directions that reach the wall within D are those with ω_x > c = d/D; their
/// cosine-weighted measure is the area of their projection onto the unit disk (Nusselt), the
/// segment x > c, over π: (acos c − c√(1 − c²))/π.
fn open_within(d: f32, ao_distance: f32) -> f32 {
    let c = (d / ao_distance).min(1.0);
    1.0 - (c.acos() - c * (1.0 - c * c).sqrt()) / PI
}

#[test]
fn the_closed_forms_agree_with_each_other() {
    // Lambert's polygon formula against the infinite strip and against a wall beyond reach.
    for d in [0.05f32, 0.5, 1.0, 3.0] {
        let p = Vec3A::new(d, 0.0, 0.0);
        let wide = [Vec3A::new(0.0, -1e5, 0.0), Vec3A::new(0.0, 1e5, 0.0), Vec3A::new(0.0, 1e5, 1.0), Vec3A::new(0.0, -1e5, 1.0)];
        assert!((1.0 - form_factor(p, Vec3A::Z, &wide) - open_beside_strip(d, 1.0)).abs() < 1e-4, "{d}");
        // With an infinitely high wall and no distance limit, half the hemisphere is hidden.
        assert!((open_within(d, f32::INFINITY) - 0.5).abs() < 1e-6);
    }
    assert!((open_within(1.0, 1.0) - 1.0).abs() < 1e-6 && (open_within(0.0, 1.0) - 0.5).abs() < 1e-6);
}

fn ao_options(samples: u32) -> RenderOptions {
    RenderOptions { width: W, height: H, ao_samples: samples, aovs: vec![Aov::Ao, Aov::Color], ..Default::default() }
}

/// (RMSE, max abs error, mean error) of `values` against `truth`.
fn errors(values: &[f32], truth: &[f32]) -> (f32, f32, f32) {
    let n = values.len() as f32;
    let (mut se, mut max, mut sum) = (0.0f32, 0.0f32, 0.0f32);
    for (v, t) in values.iter().zip(truth) {
        let e = v - t;
        se += e * e;
        max = max.max(e.abs());
        sum += e;
    }
    ((se / n).sqrt(), max, sum / n)
}

fn rays(out: &RenderOutput, kind: &str) -> u64 {
    out.stats["render"]["rays"][kind].as_u64().unwrap()
}

#[test]
fn plain_ambient_occlusion_matches_the_closed_forms() {
    let h = 1.0;
    let scene = wall_scene(h, lambert(0.18), lambert(0.18));
    let ps = pixel_points(&scene);
    let n = 256;
    let out = render(&scene, &ao_options(n), &NoProgress).unwrap();
    let ao = &out.film.aov("ao").unwrap().data;
    let truth: Vec<f32> = ps.iter().map(|&p| 1.0 - wall_factor(p, h)).collect();
    // Stratified sampling has at most the binomial variance p(1 − p)/N.
    for (i, (&v, &t)) in ao.iter().zip(&truth).enumerate() {
        let sigma = (t * (1.0 - t) / n as f32).sqrt();
        assert!((v - t).abs() < 4.0 * sigma + 1e-3, "pixel {i} at x = {}: AO {v} vs {t}", ps[i].x);
    }
    let (rmse, _, mean) = errors(ao, &truth);
    assert!(mean.abs() < 3e-3 && rmse < 0.02, "mean error {mean}, RMSE {rmse}");

    // A finite aoDistance beside an infinitely high wall.
    let d_max = 1.5;
    let scene = wall_scene(WALL, lambert(0.18), lambert(0.18));
    let out = render(&scene, &RenderOptions { ao_distance: d_max, ..ao_options(n) }, &NoProgress).unwrap();
    let ao = &out.film.aov("ao").unwrap().data;
    let truth: Vec<f32> = ps.iter().map(|&p| open_within(p.x, d_max)).collect();
    for (i, (&v, &t)) in ao.iter().zip(&truth).enumerate() {
        let sigma = (t * (1.0 - t) / n as f32).sqrt();
        assert!((v - t).abs() < 4.0 * sigma + 1e-3, "pixel {i} at x = {}: AO {v} vs {t}", ps[i].x);
    }
    // Beyond aoDistance the wall does not count: fully open.
    assert!(ps.iter().zip(ao).filter(|(p, _)| p.x > d_max + 0.01).all(|(_, &v)| v == 1.0));
    let (_, _, mean) = errors(ao, &truth);
    assert!(mean.abs() < 3e-3, "mean error {mean}");
}

#[test]
fn cached_ambient_occlusion_matches_the_closed_form_within_the_error_bound_with_fewer_rays() {
    let h = 1.0;
    let scene = wall_scene(h, lambert(0.18), lambert(0.18));
    let ps = pixel_points(&scene);
    let truth: Vec<f32> = ps.iter().map(|&p| 1.0 - wall_factor(p, h)).collect();
    let n = 256;
    let plain = render(&scene, &ao_options(n), &NoProgress).unwrap();
    let (rmse_plain, _, _) = errors(&plain.film.aov("ao").unwrap().data, &truth);
    for a in [0.05f32, 0.2] {
        let opts = RenderOptions { irradiance_cache: true, irradiance_cache_error: a, ..ao_options(n) };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        let ao = &out.film.aov("ao").unwrap().data;
        let (rmse, max, mean) = errors(ao, &truth);
        let ic = &out.stats["irradiance_cache"]["occlusion"];
        let records = ic["records"].as_u64().unwrap();
        eprintln!(
            "a = {a}: RMSE {rmse} (uncached {rmse_plain}), max {max}, mean {mean}, {records} records, {} AO rays vs {}",
            rays(&out, "ao"),
            rays(&plain, "ao")
        );
        // Ward's a bounds the relative interpolation error: the occluded fraction (the part
        // that varies) is off by at most about a of itself, plus the records' own noise.
        for (i, (&v, &t)) in ao.iter().zip(&truth).enumerate() {
            let sigma = (t * (1.0 - t) / n as f32).sqrt();
            assert!((v - t).abs() < a * (1.0 - t) + 4.0 * sigma + 1e-3, "a = {a}, pixel {i} at x = {}: {v} vs {t}", ps[i].x);
        }
        assert!(rmse < rmse_plain + 0.5 * a * 0.5, "a = {a}: RMSE {rmse} vs uncached {rmse_plain}");
        // Every pixel centre is covered by the pre-pass: the render pass interpolates them all.
        assert_eq!(ic["fallbacks"].as_u64().unwrap(), 0);
        assert!(records > 0 && (records as usize) < W * H / 4, "{records} records for {} pixels", W * H);
        assert!(rays(&out, "ao") * 3 < rays(&plain, "ao"), "{} AO rays vs {}", rays(&out, "ao"), rays(&plain, "ao"));
    }
}

#[test]
fn cached_and_plain_ao_agree_in_the_classic_integrator_colour() {
    // The classic integrator lights diffuse surfaces by albedo × AO: the cache must reach it.
    let scene = wall_scene(1.0, lambert(0.5), lambert(0.5));
    let opts = RenderOptions { integrator: IntegratorKind::Auto, irradiance_cache: true, irradiance_cache_error: 0.1, ..ao_options(64) };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let ao = &out.film.aov("ao").unwrap().data;
    let c = &out.film.aov("color").unwrap().data;
    for (i, a) in ao.iter().enumerate() {
        assert!((c[3 * i] - 0.5 * a).abs() < 1e-5, "pixel {i}: colour {} vs 0.5 × {a}", c[3 * i]);
    }
    assert!(out.stats["irradiance_cache"]["occlusion"]["records"].as_u64().unwrap() > 0);
}

#[test]
fn gradients_cut_the_interpolation_error_of_a_real_cache() {
    let h = 1.0;
    let scene = wall_scene(h, lambert(0.18), lambert(0.18));
    let opts = RenderOptions { irradiance_cache: true, irradiance_cache_error: 0.4, ..ao_options(1024) };
    let tracer = Tracer::new(&scene, opts.cache, opts.tess_factor);
    let mut hemi = Hemisphere::new(opts.ao_samples, &opts);
    hemi.prepass(&tracer, &scene, &opts, &NoProgress).unwrap();
    // Points along the strip, between the pixel centres the records sit on, each through a
    // camera ray so the shading point is what a render would interpolate at.
    let mut counters = TraceCounters::default();
    let mut points = Vec::new();
    for i in 0..400 {
        let px = (i as f32 + 0.37) * W as f32 / 400.0;
        let ray = scene.camera.generate_ray(px, 7.3, W, H);
        let hit = tracer.intersect(&ray, &mut counters).unwrap();
        let sp = shading_point(&tracer, &scene, &ray, &hit);
        points.push((sp, 1.0 - wall_factor(sp.p, h)));
    }
    let mean_error = |hemi: &Hemisphere| {
        let cache = hemi.cache().unwrap();
        points.iter().map(|(sp, t)| (cache.interpolate(sp.p, sp.ns).expect("covered").x - t).abs()).sum::<f32>() / points.len() as f32
    };
    let with = mean_error(&hemi);
    hemi.cache_mut().unwrap().gradients = false;
    let without = mean_error(&hemi);
    eprintln!("{} records: mean error with gradients {with}, without {without}", hemi.cache().unwrap().records().len());
    assert!(with < 0.6 * without, "with gradients {with}, without {without}");
}

/// Everything a render with the cache on must be: the same with one thread and two, and finite.
fn assert_deterministic_and_finite(scene: &Scene, opts: &RenderOptions) -> RenderOutput {
    let one = render(scene, &RenderOptions { threads: 1, ..opts.clone() }, &NoProgress).unwrap();
    let two = render(scene, &RenderOptions { threads: 2, ..opts.clone() }, &NoProgress).unwrap();
    for name in opts.aovs.iter().map(|a| a.name()) {
        let (a, b) = (&one.film.aov(name).unwrap().data, &two.film.aov(name).unwrap().data);
        assert!(a.iter().zip(b.iter()).all(|(x, y)| x.to_bits() == y.to_bits()), "AOV {name} differs between 1 and 2 threads");
        assert!(a.iter().all(|v| v.is_finite()), "AOV {name} has a non-finite value");
    }
    for q in ["occlusion", "irradiance"] {
        // Everything counted must agree (the seconds may not).
        for k in ["records", "prepass_points", "prepass_rays", "lookups", "interpolated"] {
            assert_eq!(one.stats["irradiance_cache"][q][k], two.stats["irradiance_cache"][q][k], "{q}.{k}");
        }
    }
    assert_eq!(one.stats["render"]["rays"], two.stats["render"]["rays"]);
    assert_eq!(one.stats["render"]["dropped_samples"].as_u64(), Some(0));
    one
}

#[test]
fn cached_renders_are_the_same_with_one_and_two_threads() {
    let scene = wall_scene(1.0, lambert(0.5), emissive(0.3, 1.0));
    let ao = RenderOptions { samples: 2, irradiance_cache: true, irradiance_cache_error: 0.2, ..ao_options(32) };
    assert_deterministic_and_finite(&scene, &ao);
    let bleed = RenderOptions { integrator: IntegratorKind::ColorBleeding, indirect_samples: 32, ..ao };
    let out = assert_deterministic_and_finite(&scene, &bleed);
    assert!(out.stats["irradiance_cache"]["irradiance"]["records"].as_u64().unwrap() > 0);
    assert!(out.stats["irradiance_cache"]["occlusion"]["records"].as_u64().unwrap() > 0);
}

fn bleed_options(indirect: u32) -> RenderOptions {
    RenderOptions { width: W, height: H, integrator: IntegratorKind::ColorBleeding, indirect_samples: indirect, ..Default::default() }
}

#[test]
fn one_bounce_from_an_emissive_wall_matches_the_form_factor() {
    // No lights: the ground (albedo ρ) sees only the wall's emission Le through its one bounce,
    // so its radiance is ρ·Le·F with F the form factor to the wall.
    let (h, rho, le) = (1.0, 0.5, 2.0);
    let scene = wall_scene(h, lambert(rho), emissive(0.0, le));
    let ps = pixel_points(&scene);
    let truth: Vec<f32> = ps.iter().map(|&p| rho * le * wall_factor(p, h)).collect();
    let n = 256;
    let opts = RenderOptions { aovs: vec![Aov::Color, Aov::IndirectDiffuse, Aov::DirectDiffuse], ..bleed_options(n) };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let red: Vec<f32> = out.film.aov("color").unwrap().data.iter().step_by(3).copied().collect();
    // All of it is the bounce: the indirectDiffuse AOV is the colour, directDiffuse is 0.
    assert_eq!(out.film.aov("indirectDiffuse").unwrap().data, out.film.aov("color").unwrap().data);
    assert!(out.film.aov("directDiffuse").unwrap().data.iter().all(|v| *v == 0.0));
    for (i, (&v, &t)) in red.iter().zip(&truth).enumerate() {
        let f = t / (rho * le);
        let sigma = rho * le * (f * (1.0 - f) / n as f32).sqrt();
        assert!((v - t).abs() < 4.0 * sigma + 1e-3, "pixel {i} at x = {}: {v} vs {t}", ps[i].x);
    }
    let (rmse_plain, _, mean) = errors(&red, &truth);
    assert!(mean.abs() < 3e-3, "mean error {mean}");
    assert!(rays(&out, "diffuse") >= (W * H) as u64 * 252);
    assert_eq!(rays(&out, "ao"), 0);

    // Cached: within the error bound, from far fewer hemisphere rays.
    let a = 0.1;
    let cached =
        render(&scene, &RenderOptions { irradiance_cache: true, irradiance_cache_error: a, ..bleed_options(n) }, &NoProgress).unwrap();
    let red_c: Vec<f32> = cached.film.aov("color").unwrap().data.iter().step_by(3).copied().collect();
    let (rmse, max, _) = errors(&red_c, &truth);
    eprintln!(
        "cached a = {a}: RMSE {rmse} (uncached {rmse_plain}), max {max}; diffuse rays {} vs {}",
        rays(&cached, "diffuse"),
        rays(&out, "diffuse")
    );
    for (i, (&v, &t)) in red_c.iter().zip(&truth).enumerate() {
        let f = t / (rho * le);
        let sigma = rho * le * (f * (1.0 - f) / n as f32).sqrt();
        assert!((v - t).abs() < a * t + 4.0 * sigma + 1e-3, "pixel {i} at x = {}: {v} vs {t}", ps[i].x);
    }
    assert!(rays(&cached, "diffuse") * 3 < rays(&out, "diffuse"));
}

/// A closed box of `half` half-size around the origin: one mesh of six quads sharing their
/// corners (so no ray slips between faces), of `material`.
fn add_box(scene: &mut Scene, half: f32, material: &Material) {
    let h = half;
    let points: Vec<[f32; 3]> =
        (0..8).map(|i| [if i & 1 != 0 { h } else { -h }, if i & 2 != 0 { h } else { -h }, if i & 4 != 0 { h } else { -h }]).collect();
    let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4; 6],
        face_vertex_indices: faces.iter().flatten().copied().collect(),
        ..Default::default()
    };
    add(scene, "/box", Arc::new(BilinearSurface::new(&topo, &points).unwrap()), material.clone());
}

#[test]
fn inside_a_closed_emissive_box_one_bounce_adds_rho_times_the_emission_exactly() {
    // Every hemisphere ray hits a wall of radiance Le: one bounce gives Le + ρ·Le, noise-free.
    // (Walls beyond the camera's near clipping distance of 1.)
    let (rho, le) = (0.6, 0.5);
    let mut scene = Scene::default();
    add_box(&mut scene, 10.0, &emissive(rho, le));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::ZERO, Vec3::new(0.3, 0.2, -1.0), Vec3::Y), 18.0);
    for cache in [false, true] {
        let opts = RenderOptions { width: 24, height: 16, irradiance_cache: cache, ..bleed_options(16) };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        for c in out.film.aov("color").unwrap().data.chunks(3) {
            assert!((c[0] - le * (1.0 + rho)).abs() < 1e-4, "cache {cache}: {c:?}");
        }
    }
}

#[test]
fn white_furnace_a_convex_object_under_a_uniform_dome_reflects_its_albedo() {
    // Convex: every hemisphere ray escapes, and the dome is counted once (by direct light).
    for rho in [1.0f32, 0.5] {
        let mut scene = Scene::default();
        add_box(&mut scene, 1.0, &lambert(rho));
        scene.lights.push(Light::usd_area("/dome", LightShape::Dome(None), 1.0, 0.0, Vec3A::ONE, false));
        scene.camera = Camera::perspective(Camera::look_at(Vec3::new(3.0, 2.5, 4.0), Vec3::ZERO, Vec3::Y), 35.0);
        for cache in [false, true] {
            let opts = RenderOptions {
                width: 24,
                height: 24,
                samples: 4,
                shadow_samples: 8,
                irradiance_cache: cache,
                aovs: vec![Aov::Color, Aov::Alpha],
                ..bleed_options(16)
            };
            let out = render(&scene, &opts, &NoProgress).unwrap();
            let alpha = &out.film.aov("alpha").unwrap().data;
            let color = &out.film.aov("color").unwrap().data;
            let hits: Vec<f32> = (0..alpha.len()).filter(|&i| alpha[i] == 1.0).map(|i| color[3 * i]).collect();
            assert!(hits.len() > 100);
            let mean = hits.iter().sum::<f32>() / hits.len() as f32;
            assert!((mean - rho).abs() < 0.01 * rho, "ρ = {rho}, cache {cache}: mean {mean}");
            assert!(hits.iter().all(|v| v.is_finite() && (v - rho).abs() < 0.25 * rho), "ρ = {rho}, cache {cache}");
        }
    }
}

#[test]
fn cached_renders_of_degenerate_and_grazing_geometry_stay_finite() {
    let mut scene = wall_scene(0.2, lambert(0.7), emissive(0.5, 3.0));
    // A collapsed quad, a sliver, and a quad seen edge-on.
    add(&mut scene, "/collapsed", quad([[1.0, 0.0, 0.0]; 4]), lambert(0.5));
    add(&mut scene, "/sliver", quad([[1.0, -0.3, 0.0], [1.0, 0.3, 0.0], [1.0, 0.3, 1e-6], [1.0, -0.3, 1e-6]]), lambert(0.5));
    add(&mut scene, "/edge_on", quad([[2.0, -0.2, 0.0], [2.0, 0.2, 0.0], [2.0, 0.2, 2.0], [2.0, -0.2, 2.0]]), emissive(0.9, 1.0));
    for integrator in [IntegratorKind::Ao, IntegratorKind::ColorBleeding] {
        for a in [0.05f32, 1.0, 10.0] {
            let opts = RenderOptions { integrator, irradiance_cache: true, irradiance_cache_error: a, ..ao_options(16) };
            let out = render(&scene, &opts, &NoProgress).unwrap();
            for name in ["ao", "color"] {
                assert!(out.film.aov(name).unwrap().data.iter().all(|v| v.is_finite()), "{integrator:?} a = {a}: {name}");
            }
            assert_eq!(out.stats["render"]["dropped_samples"].as_u64(), Some(0));
        }
    }
}
