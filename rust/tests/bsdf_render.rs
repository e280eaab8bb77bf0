//! UsdPreviewSurface rendered by the classic integrator against analytic answers: a lambertian
//! sphere under a distant light (ρ/π · E · cos θ), a smooth glass slab (Fresnel transmission
//! through two faces and their inter-reflections), a glass sphere in a uniform dome (invisible:
//! every path ends on the dome with unit weight), a white rough metal in a uniform dome (its
//! directional albedo), and the glossy lobe's delta limit (roughness 1e-3 renders the mirror).

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::bounds::Bounds3;
use mipray::bsdf::{PreviewSurfaceBsdf, Scattering};
use mipray::light::LightShape;
use mipray::material::{Material, PreviewSurface};
use mipray::motion::{MotionKey, MotionTransform};
use mipray::options::IntegratorKind;
use mipray::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};
use mipray::prelude::*;
use mipray::sampling::Sampler;

/// A sphere of radius `r` around the origin as 8 analytic patches (4 in longitude × 2 in
/// latitude), with second derivatives so mirrors and glass curve their differentials.
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
        let k = PI / 2.0;
        // φ decreases with u so that dP/du × dP/dv points out of the sphere (USD's
        // right-handed orientation): refraction needs to know inside from outside.
        let phi = (patch % 4) as f32 * k + (1.0 - u) * k;
        let theta = (patch / 4) as f32 * k + v * k;
        let (st, ct, sp, cp) = (theta.sin(), theta.cos(), phi.sin(), phi.cos());
        let r = self.r;
        SurfacePoint {
            p: Vec3A::new(st * cp, st * sp, ct) * r,
            dpdu: Vec3A::new(st * sp, -st * cp, 0.0) * r * k,
            dpdv: Vec3A::new(ct * cp, ct * sp, -st) * r * k,
            dpduu: Vec3A::new(-st * cp, -st * sp, 0.0) * r * k * k,
            dpduv: Vec3A::new(ct * sp, -ct * cp, 0.0) * r * k * k,
            dpdvv: Vec3A::new(-st * cp, -st * sp, -ct) * r * k * k,
        }
    }
    fn control_face_count(&self) -> usize {
        8
    }
}

fn quad(corners: [[f32; 3]; 4]) -> Arc<BilinearSurface> {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    Arc::new(BilinearSurface::new(&topo, &corners).unwrap())
}

fn add(scene: &mut Scene, name: &str, surface: Arc<dyn LimitSurface>, material: Material) {
    let mat = scene.add_material(material);
    let mut m = Mesh::new(name, surface);
    m.material = mat;
    let i = scene.add_mesh(m);
    scene.add_instance(i, Mat4::IDENTITY);
}

fn preview(name: &str, f: impl FnOnce(&mut PreviewSurface)) -> Material {
    let mut s = PreviewSurface::default();
    f(&mut s);
    let (m, clamped) = Material::preview_surface(name, s);
    assert!(clamped.is_empty(), "{clamped:?}");
    m
}

fn uniform_dome(radiance: f32) -> Light {
    Light::usd_area("/dome", LightShape::Dome(None), radiance, 0.0, Vec3A::ONE, false)
}

/// Looking straight down −z from above, orthographic, `size` scene units across.
/// A white ceiling at height `z` facing down, lit from below by a distant light of radiance 2
/// that casts no shadows: what a mirror facing up reflects.
fn add_lit_ceiling(scene: &mut Scene, z: f32) {
    add(
        scene,
        "/ceiling",
        quad([[-50.0, -50.0, z], [-50.0, 50.0, z], [50.0, 50.0, z], [50.0, -50.0, z]]),
        Material::lambertian("/white", Vec3A::ONE).0,
    );
    let mut light = Light::distant("/up", Vec3A::Z, Vec3A::splat(2.0));
    light.casts_shadows = false;
    scene.lights.push(light);
}

fn top_camera(size: f32) -> Camera {
    Camera::orthographic(Mat4::from_translation(Vec3::new(0.0, 0.0, 10.0)), size * 10.0, size * 10.0)
}

#[test]
fn a_lambertian_sphere_under_a_distant_light_has_the_analytic_radiance() {
    let rho = 0.5;
    let e = 3.0;
    let mut scene = Scene::default();
    add(&mut scene, "/sphere", Arc::new(Sphere { r: 1.0 }), Material::lambertian("/matte", Vec3A::splat(rho)).0);
    let to_light = Vec3A::new(0.4, -0.3, 0.8).normalize();
    scene.lights.push(Light::distant("/sun", -to_light, Vec3A::splat(e)));
    scene.camera = top_camera(2.4);
    let aovs = ["color", "position", "albedo", "directDiffuse", "specular", "normal"].map(|s| Aov::from_name(s).unwrap()).to_vec();
    let out = render(&scene, &RenderOptions { width: 48, height: 48, aovs, ..Default::default() }, &NoProgress).unwrap();
    let mut checked = 0;
    for y in 0..48 {
        for x in 0..48 {
            let p = Vec3A::from_slice(out.film.pixel("position", x, y));
            if p == Vec3A::ZERO {
                continue;
            }
            let n = p.normalize();
            let cos = n.dot(to_light);
            // Away from the silhouette and the terminator, where the tessellation shadowing
            // itself is the tessellation's business, not the BSDF's.
            if n.z < 0.3 || cos < 0.15 {
                continue;
            }
            let expected = rho / PI * e * cos;
            let c = out.film.pixel("color", x, y);
            assert!((c[0] - expected).abs() < 0.01 * expected + 1e-4, "({x}, {y}): {} vs {expected}", c[0]);
            assert_eq!(out.film.pixel("directDiffuse", x, y), c);
            assert_eq!(out.film.pixel("specular", x, y), &[0.0; 3]);
            assert!((out.film.pixel("albedo", x, y)[1] - rho).abs() < 1e-6);
            assert!(Vec3A::from_slice(out.film.pixel("normal", x, y)).dot(n) > 0.999);
            checked += 1;
        }
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn a_smooth_glass_slab_transmits_fresnels_share() {
    // A white ground lit from above by a light that casts no shadow, under a 0.2 thick slab of
    // ior 1.5 glass seen head on: each face transmits 1 − F0 = 0.96 and the two faces
    // inter-reflect, T² Σ R^2k = T²/(1 − R²).
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/ground",
        quad([[-50.0, -50.0, 0.0], [50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [-50.0, 50.0, 0.0]]),
        Material::lambertian("/white", Vec3A::ONE).0,
    );
    let glass = preview("/glass", |s| {
        s.opacity = 0.0;
        s.roughness = 0.0;
        s.ior = 1.5;
    });
    let h = 3.0;
    // Top face up (+z), bottom face down (−z): a closed slab's two outward normals.
    add(
        &mut scene,
        "/slabTop",
        quad([[-2.0, -2.0, h + 0.2], [2.0, -2.0, h + 0.2], [2.0, 2.0, h + 0.2], [-2.0, 2.0, h + 0.2]]),
        glass.clone(),
    );
    add(&mut scene, "/slabBottom", quad([[-2.0, -2.0, h], [-2.0, 2.0, h], [2.0, 2.0, h], [2.0, -2.0, h]]), glass);
    let mut sun = Light::distant("/sun", Vec3A::NEG_Z, Vec3A::splat(PI));
    sun.casts_shadows = false;
    scene.lights.push(sun);
    scene.camera = top_camera(8.0);
    let opts = RenderOptions { width: 16, height: 16, max_depth: 8, aovs: vec![Aov::Color, Aov::Specular], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let (r, t) = (0.04f32, 0.96f32);
    let through = t * t / (1.0 - r * r);
    // Pixel centres within |x|, |y| < 2 see the ground through the slab; the ground is 1.
    let inside = out.film.pixel("color", 8, 8)[0];
    assert!((inside - through).abs() < 1e-4, "through the slab {inside}, expected {through}");
    assert_eq!(out.film.pixel("specular", 8, 8), out.film.pixel("color", 8, 8), "all of it came by refraction");
    let outside = out.film.pixel("color", 0, 0)[0];
    assert!((outside - 1.0).abs() < 1e-5, "beside the slab {outside}");
    assert!(out.stats["render"]["rays"]["refraction"].as_u64().unwrap() >= 2 * 16);
    let effects = out.stats["effects"]["enabled"].as_array().unwrap();
    assert!(effects.iter().any(|e| e["name"] == "refraction" && e["why"].as_str().unwrap().contains("/glass")), "{effects:?}");
}

#[test]
fn a_glass_sphere_in_a_uniform_dome_is_invisible() {
    // Every path through smooth glass ends on the dome; Fresnel splits it without loss and the
    // η² of radiance entering and leaving cancel. Deterministic: delta lobes only.
    let mut scene = Scene::default();
    let glass = preview("/glass", |s| {
        s.opacity = 0.0;
        s.roughness = 0.0;
        s.ior = 1.5;
    });
    add(&mut scene, "/ball", Arc::new(Sphere { r: 1.0 }), glass);
    scene.lights.push(uniform_dome(1.0));
    scene.camera = top_camera(2.4);
    let opts = RenderOptions { width: 24, height: 24, max_depth: 12, aovs: vec![Aov::Color, Aov::Position], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let mut checked = 0;
    for y in 0..24 {
        for x in 0..24 {
            let p = Vec3A::from_slice(out.film.pixel("position", x, y));
            let c = out.film.pixel("color", x, y);
            if p == Vec3A::ZERO {
                assert!((c[0] - 1.0).abs() < 1e-6, "the dome behind: {}", c[0]);
                continue;
            }
            if p.normalize().z < 0.5 {
                continue; // near the silhouette the depth limit cuts long internal paths
            }
            assert!((c[0] - 1.0).abs() < 2e-3, "({x}, {y}): {c:?}");
            checked += 1;
        }
    }
    assert!(checked > 150, "{checked}");
}

#[test]
fn a_white_rough_metal_in_a_uniform_dome_reflects_its_directional_albedo() {
    // The white furnace through the whole classic integrator: light and BSDF samples with MIS
    // from the dome, on a metal of F0 = 1. Each pixel is the BSDF's directional albedo toward
    // the camera, here estimated independently by importance sampling the BSDF alone.
    let mut scene = Scene::default();
    let surface = PreviewSurface { diffuse_color: Vec3A::ONE, metallic: 1.0, roughness: 0.4, ..Default::default() };
    add(&mut scene, "/ball", Arc::new(Sphere { r: 1.0 }), Material::preview_surface("/metal", surface).0);
    scene.lights.push(uniform_dome(1.0));
    scene.camera = top_camera(2.4);
    let opts = RenderOptions {
        width: 16,
        height: 16,
        samples: 4,
        shadow_samples: 64,
        aovs: vec![Aov::Color, Aov::Position, Aov::Specular],
        ..Default::default()
    };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    // Per pixel within the estimator's noise (a few % at grazing angles); on average within 1 %.
    let (mut err, mut n) = (0.0f32, 0);
    for y in 0..16 {
        for x in 0..16 {
            let p = Vec3A::from_slice(out.film.pixel("position", x, y));
            if p == Vec3A::ZERO || p.normalize().z < 0.3 {
                continue;
            }
            let nrm = p.normalize();
            let bsdf = PreviewSurfaceBsdf::new(&surface, nrm, nrm, true);
            let mut rng = Sampler::new(1, (y * 16 + x) as u64, 0);
            let m = 20_000;
            let albedo: f32 = (0..m)
                .filter_map(|_| bsdf.sample(Vec3A::Z, [rng.next_f32(), rng.next_f32(), rng.next_f32()]))
                .map(|s| s.weight.x)
                .sum::<f32>()
                / m as f32;
            let c = out.film.pixel("color", x, y)[0];
            assert!((c - albedo).abs() < 0.15 * albedo, "({x}, {y}): {c} vs albedo {albedo}");
            assert_eq!(out.film.pixel("specular", x, y)[0], c, "a metal has no diffuse light");
            err += c / albedo - 1.0;
            n += 1;
        }
    }
    assert!(n > 80);
    assert!((err / n as f32).abs() < 0.01, "mean error {}", err / n as f32);
}

#[test]
fn roughness_1e3_renders_what_the_mirror_does() {
    // A metal plane reflecting a lit white ceiling: roughness 0 (delta, reflection rays) and
    // 1e-3 (GGX, glossy rays) both give F0 · radiance of the ceiling at normal incidence.
    let render_with = |roughness: f32| {
        let mut scene = Scene::default();
        let metal = preview("/metal", |s| {
            s.diffuse_color = Vec3A::splat(0.8);
            s.metallic = 1.0;
            s.roughness = roughness;
        });
        add(&mut scene, "/floor", quad([[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 0.0], [-5.0, 5.0, 0.0]]), metal);
        add_lit_ceiling(&mut scene, 10.0);
        scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 40.0, 40.0);
        render(&scene, &RenderOptions { width: 8, height: 8, ..Default::default() }, &NoProgress).unwrap()
    };
    let expected = 0.8 * 2.0 / PI;
    let (mirror, glossy) = (render_with(0.0), render_with(1e-3));
    for (out, kind) in [(&mirror, "reflection"), (&glossy, "glossy")] {
        for p in out.film.aov("color").unwrap().data.chunks(3) {
            assert!((p[0] - expected).abs() < 1e-3 * expected, "{kind}: {} vs {expected}", p[0]);
        }
        assert!(out.stats["render"]["rays"][kind].as_u64().unwrap() >= 64, "{kind} rays");
    }
    assert_eq!(mirror.stats["render"]["rays"]["glossy"].as_u64(), Some(0));
    assert_eq!(glossy.stats["render"]["rays"]["reflection"].as_u64(), Some(0));
}

#[test]
fn a_rough_glass_sheet_in_a_uniform_dome_shows_its_reflectance_plus_transmittance() {
    // One rough interface (roughness 0.3, ior 1.5) seen at 30° from its normal in a dome of
    // radiance 1: the pixel is ∫ f |cos| over both hemispheres — rough reflection plus rough
    // refraction (with radiance's 1/η²) — found by direct light's BSDF samples through both
    // lobes. Truth: the BSDF's own importance-sampled albedo at that angle.
    let surface = PreviewSurface { opacity: 0.0, roughness: 0.3, ior: 1.5, ..Default::default() };
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/sheet",
        quad([[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 0.0], [-5.0, 5.0, 0.0]]),
        Material::preview_surface("/frosted", surface).0,
    );
    scene.lights.push(uniform_dome(1.0));
    let wo = Vec3A::new(0.0, -0.5, 0.75f32.sqrt());
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::from(wo * 8.0), Vec3::ZERO, Vec3::Z), 20.0, 20.0);
    let opts = RenderOptions { width: 8, height: 8, samples: 4, shadow_samples: 32, ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let bsdf = PreviewSurfaceBsdf::new(&surface, Vec3A::Z, Vec3A::Z, true);
    let mut rng = Sampler::new(9, 9, 9);
    let m = 200_000;
    let albedo: f32 =
        (0..m).filter_map(|_| bsdf.sample(wo, [rng.next_f32(), rng.next_f32(), rng.next_f32()])).map(|s| s.weight.x).sum::<f32>()
            / m as f32;
    let data = &out.film.aov("color").unwrap().data;
    let mean = data.iter().step_by(3).sum::<f32>() / 64.0;
    assert!((mean - albedo).abs() < 0.015 * albedo, "mean {mean} vs albedo {albedo}");
    assert!(out.stats["render"]["rays"]["refraction"].as_u64().unwrap() > 0, "rough refraction rays");
}

#[test]
fn a_curved_mirror_on_a_moving_instance_widens_beams_by_its_pose_at_the_rays_time() {
    // A unit mirror sphere seen from above reflects a lit ceiling. Moving: three times its size
    // at shutter open, its rest pose from a ten-thousandth of the shutter on, so (almost) every
    // ray sees the rest pose. The beam widths on the ceiling come from the sphere's curvature
    // (its normal differentials); at the ray's time they are those of the same sphere at rest.
    // With the pose at shutter open they would follow a sphere three times as large.
    let render_with = |motion: Option<MotionTransform>, integrator: IntegratorKind| {
        let mut scene = Scene::default();
        let chrome = scene.add_material(Material::mirror("/chrome", Vec3A::ZERO, Vec3A::splat(0.8)));
        let mut sphere = Mesh::new("/sphere", Arc::new(Sphere { r: 1.0 }));
        sphere.material = chrome;
        let m = scene.add_mesh(sphere);
        match motion {
            Some(motion) => scene.add_moving_instance(m, motion),
            None => scene.add_instance(m, Mat4::IDENTITY),
        };
        add_lit_ceiling(&mut scene, 20.0);
        scene.camera = top_camera(2.4);
        let aovs = ["color", "beamWidth"].map(|s| Aov::from_name(s).unwrap()).to_vec();
        render(&scene, &RenderOptions { width: 24, height: 24, aovs, integrator, ..Default::default() }, &NoProgress).unwrap()
    };
    let keys = vec![
        MotionKey { time: 0.0, render_from_object: Mat4::from_scale(Vec3::splat(3.0)) },
        MotionKey { time: 1e-4, render_from_object: Mat4::IDENTITY },
        MotionKey { time: 1.0, render_from_object: Mat4::IDENTITY },
    ];
    for integrator in [IntegratorKind::Direct, IntegratorKind::Path] {
        let still = render_with(None, integrator);
        let moving = render_with(Some(MotionTransform::new(keys.clone()).unwrap()), integrator);
        let (a, b) = (&still.film.aov("beamWidth").unwrap().data, &moving.film.aov("beamWidth").unwrap().data);
        let mut checked = 0;
        for (i, (w0, w1)) in a.iter().zip(b.iter()).enumerate() {
            // Pixels whose camera ray reflects off the sphere onto the ceiling: wider beams than
            // the camera's (a flat view of the ceiling's distance).
            if *w0 <= 0.0 {
                continue;
            }
            assert!((w1 - w0).abs() <= 1e-3 * w0, "{integrator:?} pixel {i}: moving {w1} vs still {w0}");
            checked += 1;
        }
        assert!(checked > 100, "{integrator:?}: {checked} pixels checked");
    }
}

#[test]
fn a_dome_hidden_from_the_camera_still_shows_through_glass() {
    // domeLightCameraVisibility off (usdrecord's default): camera rays that escape see black,
    // while rays refracted through the glass sphere still end on the dome, as with it on.
    let mut scene = Scene::default();
    let glass = preview("/glass", |s| {
        s.opacity = 0.0;
        s.roughness = 0.0;
        s.ior = 1.5;
    });
    add(&mut scene, "/ball", Arc::new(Sphere { r: 1.0 }), glass);
    scene.lights.push(uniform_dome(1.0));
    scene.camera = top_camera(2.4);
    for integrator in [IntegratorKind::Direct, IntegratorKind::Path, IntegratorKind::ColorBleeding] {
        let opts = RenderOptions {
            width: 24,
            height: 24,
            max_depth: 12,
            integrator,
            aovs: vec![Aov::Color, Aov::Position, Aov::Alpha],
            ..Default::default()
        };
        let seen = render(&scene, &opts, &NoProgress).unwrap();
        let hidden = render(&scene, &RenderOptions { dome_light_camera_visibility: false, ..opts }, &NoProgress).unwrap();
        let (mut background, mut through) = (0, 0);
        for y in 0..24 {
            for x in 0..24 {
                let p = Vec3A::from_slice(hidden.film.pixel("position", x, y));
                let (c, c_seen) = (hidden.film.pixel("color", x, y), seen.film.pixel("color", x, y));
                if p == Vec3A::ZERO {
                    assert_eq!(&c[..3], &[0.0; 3], "{integrator:?} ({x}, {y}): the hidden dome behind");
                    assert_eq!(hidden.film.pixel("alpha", x, y)[0], 0.0);
                    assert!((c_seen[0] - 1.0).abs() < 1e-6, "{integrator:?}: the dome seen: {}", c_seen[0]);
                    assert_eq!(seen.film.pixel("alpha", x, y)[0], 0.0, "{integrator:?}: alpha is surface coverage");
                    background += 1;
                } else {
                    assert_eq!(c, c_seen, "{integrator:?} ({x}, {y}): through the glass, the dome as before");
                    through += 1;
                }
            }
        }
        assert!(background > 100 && through > 150, "{integrator:?}: {background} {through}");
    }
}
