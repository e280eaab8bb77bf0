//! UsdLux's `ShapingAPI` and light and shadow linking against closed forms: a spot's cone edge on
//! the floor at h·tan(angle) (disk, sphere, rect and cylinder lights), its soft edge and focus as
//! the schema's formulas say, a light linked away from a surface leaving it dark, and an occluder
//! outside a light's shadow-linking set casting no shadow — by every direct-lighting estimator.

mod lights_common;

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3A};
use lights_common::*;
use mipray::bilinear::BilinearSurface;
use mipray::bsdf::{Lambertian, Scattering};
use mipray::integrator::ShadingPoint;
use mipray::light::{Light, LightShape, MeshFilter, Shaping};
use mipray::scene::{Mesh, Scene};
use mipray::topology::{MeshTopology, Scheme};

const H: f32 = 2.0;

fn white(sp: &ShadingPoint) -> Box<dyn Scattering> {
    Box::new(Lambertian { r: Vec3A::ONE, n: sp.ns, ng: sp.ng })
}

/// A small disk light of radius `a` at height `H` above the origin pointing down, radiance 1,
/// shaped by `cone_deg`, `softness`, `focus` and `tint`.
fn spot(a: f32, cone_deg: f32, softness: f32, focus: f32, tint: Vec3A) -> Light {
    let shape = LightShape::Disk { center: Vec3A::Z * H, u: Vec3A::X * a, v: Vec3A::Y * a, normal: Vec3A::NEG_Z };
    let mut light = Light::usd_area("/spot", shape, 1.0, 0.0, Vec3A::ONE, false);
    light.shaping = Shaping::new(Vec3A::NEG_Z, cone_deg, softness, focus, tint);
    light
}

/// Radiance of a white lambertian floor at horizontal distance `r` from below a small disk of
/// radius `a` and radiance 1 at height H facing down, unshaped: E/π with E = L A cos θ cos θ / d²
/// (θ off the axis; exact to O((a/d)²)).
fn small_disk_radiance(a: f32, r: f32) -> f32 {
    let d2 = r * r + H * H;
    let cos = H / d2.sqrt();
    PI * a * a * cos * cos / d2 / PI
}

fn floor_radiance(scene: &Scene, r: f32, mode: Mode) -> Stats {
    estimate_at(scene, Vec3A::new(r, 0.0, 0.0), 4, 400, mode, white)
}

fn with(lights: Vec<Light>) -> Scene {
    let mut scene = ground(100.0);
    scene.lights = lights;
    scene
}

#[test]
fn a_spot_lights_the_floor_inside_h_tan_angle_and_nothing_outside() {
    // The cone is the light's −Z whatever its shape: a rect and a tube (UsdLux's CylinderLight,
    // axis along X) shaped as the disk and the sphere are.
    for (cone, kind) in [(30.0f32, "disk"), (50.0, "sphere"), (35.0, "rect"), (45.0, "cylinder")] {
        let a = 0.01;
        let mut light = spot(a, cone, 0.0, 0.0, Vec3A::ZERO);
        let center = Vec3A::Z * H;
        match kind {
            "sphere" => light.shape = LightShape::Sphere { center, radius: a },
            // Half-extents b with 4b² = πa²: the disk's area.
            "rect" => {
                let b = a * PI.sqrt() / 2.0;
                light.shape = LightShape::Rect { center, u: Vec3A::X * b, v: Vec3A::Y * b, normal: Vec3A::NEG_Z };
            }
            "cylinder" => {
                light.shape = LightShape::Cylinder { center, axis: Vec3A::X * a, radius: a, e1: Vec3A::Y, e2: Vec3A::Z };
            }
            _ => {}
        }
        let scene = with(vec![light]);
        let edge = H * cone.to_radians().tan();
        for mode in [Mode::Mis, Mode::LightOnly, Mode::PathTracer] {
            // Area sampling of a tube wastes the half facing away: 16 times the samples.
            let calls = if kind == "cylinder" { 6400 } else { 400 };
            let inside = estimate_at(&scene, Vec3A::new(0.97 * edge, 0.0, 0.0), 4, calls, mode, white);
            let r = 0.97 * edge;
            let d = r.hypot(H);
            let mut truth = small_disk_radiance(a, r);
            if kind == "sphere" {
                // A sphere shows πa² whatever the direction: no cos θ at the light.
                truth /= (H / d).min(1.0);
            } else if kind == "cylinder" {
                // A tube of radius a and half-length a along X shows its silhouette, 4a² times
                // the sine of the direction's angle to the axis (H/d here), to a floor point
                // whose own cosine is H/d.
                truth = 4.0 * a * a * (H / d) * (H / d) / (d * d) / PI;
            }
            assert!(
                (inside.mean.x - truth).abs() < 0.01 * truth + 4.0 * inside.std_error,
                "{kind} {mode:?}: inside {} ± {} vs {truth}",
                inside.mean.x,
                inside.std_error
            );
            let outside = floor_radiance(&scene, 1.03 * edge, mode);
            assert_eq!(outside.mean.x, 0.0, "{kind} {mode:?}: outside the cone");
        }
    }
}

#[test]
fn cone_softness_and_focus_follow_the_schema_s_formulas() {
    // cone 40°, softness 0.5: full inside 20°, 1 − smoothstep between, 0 from 40°.
    let s = Shaping::new(Vec3A::NEG_Z, 40.0, 0.5, 0.0, Vec3A::ZERO).unwrap();
    let at = |deg: f32| s.factor(Vec3A::new(deg.to_radians().sin(), 0.0, -deg.to_radians().cos())).x;
    assert!((at(10.0) - 1.0).abs() < 1e-6 && (at(30.0) - 0.5).abs() < 1e-4 && at(40.5) == 0.0, "{} {} {}", at(10.0), at(30.0), at(40.5));
    let t = (35.0 - 20.0) / 20.0f32;
    assert!((at(35.0) - (1.0 - t * t * (3.0 - 2.0 * t))).abs() < 1e-4);
    // focus 3, tint (0.5, 0.25, 0): tint + (1 − tint)·cos³θ.
    let tint = Vec3A::new(0.5, 0.25, 0.0);
    let f = Shaping::new(Vec3A::NEG_Z, 180.0, 0.0, 3.0, tint).unwrap();
    let w = Vec3A::new(0.6, 0.0, -0.8);
    let want = tint + (Vec3A::ONE - tint) * 0.8f32.powi(3);
    assert!((f.factor(w) - want).abs().max_element() < 1e-5, "{} vs {want}", f.factor(w));
    // Nothing to shape: no shaping.
    assert!(Shaping::new(Vec3A::NEG_Z, 180.0, 0.3, 0.0, tint).is_none());

    // In a render: the floor below a tiny soft, focused spot, where θ = 30° from its axis.
    let a = 0.004;
    let scene = with(vec![spot(a, 40.0, 0.5, 3.0, tint)]);
    let r = H * 30f32.to_radians().tan();
    let got = floor_radiance(&scene, r, Mode::Mis);
    let focus = tint + (Vec3A::ONE - tint) * 30f32.to_radians().cos().powi(3);
    let want = focus * 0.5 * small_disk_radiance(a, r);
    assert!((got.mean - want).abs().max_element() < 0.02 * want.x, "{} vs {want}", got.mean);
}

/// The ground and, between it and a light at height H, a 2 × 2 square occluder at height H/2.
fn ground_and_occluder() -> Scene {
    let mut scene = ground(100.0);
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let z = H / 2.0;
    let pts = [[-1.0, -1.0, z], [1.0, -1.0, z], [1.0, 1.0, z], [-1.0, 1.0, z]];
    let mesh = scene.add_mesh(Mesh::new("/occluder", Arc::new(BilinearSurface::new(&topo, &pts).unwrap())));
    scene.add_instance(mesh, Mat4::IDENTITY);
    scene
}

#[test]
fn a_light_linked_away_leaves_a_surface_dark_and_an_unlinked_occluder_casts_no_shadow() {
    let a = 0.2;
    let disk = || {
        let shape = LightShape::Disk { center: Vec3A::Z * H, u: Vec3A::X * a, v: Vec3A::Y * a, normal: Vec3A::NEG_Z };
        Light::usd_area("/disk", shape, 1.0, 0.0, Vec3A::ONE, false)
    };
    // The disk on the axis at height H: E = π L a² / (H² + a²).
    let truth = a * a / (H * H + a * a);
    let far = Vec3A::new(20.0, 0.0, 0.0);
    let lit = |scene: &Scene, p: Vec3A, mode: Mode| estimate_at(scene, p, 4, 400, mode, white).mean.x;

    // Light linking: mesh 0 (the ground) left out; a second light, linked to all, still lights it.
    let mut unlinked = disk();
    unlinked.illuminates = MeshFilter::excluding(vec![0]);
    let scene = with(vec![unlinked.clone()]);
    // (`Mode::LightOnly` is the tests' own estimator, which knows no linking.)
    for mode in [Mode::Mis, Mode::PathTracer] {
        assert_eq!(lit(&scene, Vec3A::ZERO, mode), 0.0, "{mode:?}: a surface the light is not linked to");
    }
    let scene = with(vec![disk()]);
    let full = lit(&scene, Vec3A::ZERO, Mode::Mis);
    assert!((full - truth).abs() < 0.02 * truth, "linked to all: {full} vs {truth}");
    let mut other = disk();
    if let LightShape::Disk { center, .. } = &mut other.shape {
        *center = far + Vec3A::Z * H;
    }
    let scene = with(vec![unlinked, other]);
    let got = lit(&scene, far, Mode::Mis);
    assert!((got - truth).abs() < 0.02 * truth, "the other light: {got} vs {truth}");

    // Shadow linking: the occluder (mesh 1) fully shadows the point below it …
    let mut scene = ground_and_occluder();
    scene.lights = vec![disk()];
    for mode in [Mode::Mis, Mode::PathTracer] {
        assert_eq!(lit(&scene, Vec3A::ZERO, mode), 0.0, "{mode:?}: in the occluder's shadow");
    }
    // … unless it is outside the light's shadow-linking set: then the light arrives in full …
    let mut through = disk();
    through.shadowed_by = MeshFilter::excluding(vec![1]);
    scene.lights = vec![through.clone()];
    for mode in [Mode::Mis, Mode::PathTracer] {
        let got = lit(&scene, Vec3A::ZERO, mode);
        assert!((got - truth).abs() < 0.02 * truth, "{mode:?}: shadow-unlinked occluder: {got} vs {truth}");
    }
    // … while a light whose set holds it is still shadowed.
    let mut blocked = disk();
    blocked.shadowed_by = MeshFilter::excluding(vec![7]);
    scene.lights = vec![blocked];
    assert_eq!(lit(&scene, Vec3A::ZERO, Mode::Mis), 0.0, "the occluder is in the set");
}

/// A tube of radius 0.3 and length 1.6 above the origin, its axis tilted out of the floor's
/// plane, radiance 2.
fn tube() -> Light {
    let axis = Vec3A::new(0.8, 0.1, 0.3).normalize() * 0.8;
    let (e1, e2) = axis.normalize().any_orthonormal_pair();
    let shape = LightShape::Cylinder { center: Vec3A::new(0.4, 0.2, 1.5), axis, radius: 0.3, e1, e2 };
    Light::usd_area("/tube", shape, 2.0, 0.0, Vec3A::ONE, false)
}

#[test]
fn a_cylinder_light_delivers_the_quadrature_of_its_wall_and_its_density_is_its_area_s() {
    let light = tube();
    let LightShape::Cylinder { center, axis, radius, e1, e2 } = light.shape else { unreachable!() };
    // E at the origin (normal +z) = ∫ L cos θ_light cos θ_surface / d² dA over the wall facing it.
    let (nt, np) = (1000, 2000);
    let (mut e, mut facing) = (0.0f64, 0.0f64);
    let da = f64::from(2.0 * axis.length() * 2.0 * PI * radius) / f64::from(nt * np);
    for i in 0..nt {
        let t = -1.0 + 2.0 * (i as f32 + 0.5) / nt as f32;
        for j in 0..np {
            let phi = 2.0 * PI * (j as f32 + 0.5) / np as f32;
            let n = e1 * phi.cos() + e2 * phi.sin();
            let y = center + axis * t + n * radius;
            let d2 = y.length_squared();
            let w = y / d2.sqrt();
            let (cos_l, cos_s) = (-n.dot(w), w.z);
            if cos_l > 0.0 {
                facing += 1.0 / f64::from(nt * np);
            }
            if cos_l > 0.0 && cos_s > 0.0 {
                e += f64::from(2.0 * cos_l * cos_s / d2) * da;
            }
        }
    }
    let truth = (e / f64::from(PI)) as f32;
    let scene = with(vec![light.clone()]);
    for mode in [Mode::Mis, Mode::PathTracer] {
        let got = estimate_at(&scene, Vec3A::ZERO, 4, 2000, mode, white);
        assert!((got.mean.x - truth).abs() < 4.0 * got.std_error + 1e-3 * truth, "{mode:?}: {} ± {} vs {truth}", got.mean.x, got.std_error);
    }
    // Area sampling keeps the points whose outer side faces the origin: ∫ pdf dω over the
    // directions that meet them is the fraction of the wall they make up.
    let (nt, np) = (800, 1600);
    let dw = 4.0 * std::f64::consts::PI / f64::from(nt * np);
    let mut integral = 0.0f64;
    for i in 0..nt {
        let z = 1.0 - 2.0 * (i as f32 + 0.5) / nt as f32;
        for j in 0..np {
            let phi = 2.0 * PI * (j as f32 + 0.5) / np as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            integral += f64::from(light.pdf(Vec3A::ZERO, Vec3A::Z, Vec3A::new(r * phi.cos(), r * phi.sin(), z))) * dw;
        }
    }
    assert!((integral - facing).abs() < 0.01 * facing, "∫ pdf = {integral} vs {facing}");
    // From inside the tube, or through an open end, the outward wall shows nothing.
    assert!(light.intersect(center, Vec3A::Z, f32::INFINITY).is_none());
    assert!(light.intersect(center + axis * 3.0, -axis.normalize(), f32::INFINITY).is_none());
}
