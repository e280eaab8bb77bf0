//! Transform motion blur against its analytic answer: a quad sliding across the shutter covers a
//! pixel for a known fraction of the shutter time.

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::material::Material;
use mipray::motion::{MotionKey, MotionTransform};
use mipray::prelude::*;
use mipray::topology::{MeshTopology, Scheme};

/// A unit white quad on z = 0 centred at the origin, lit head-on so a covered pixel reads 1.
fn scene(motion: Option<MotionTransform>) -> Scene {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let pts = [[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]];
    let mut scene = Scene::default();
    let mat = scene.add_material(Material::lambertian("/white", Vec3A::ONE).0);
    let mut mesh = Mesh::new("/slider", Arc::new(BilinearSurface::new(&topo, &pts).unwrap()));
    mesh.material = mat;
    let m = scene.add_mesh(mesh);
    match motion {
        Some(motion) => scene.add_moving_instance(m, motion),
        None => scene.add_instance(m, Mat4::IDENTITY),
    };
    scene.lights.push(Light::distant("/sun", Vec3A::NEG_Z, Vec3A::splat(std::f32::consts::PI)));
    // 4 units wide, 0.2 high: 40 × 2 pixels of 0.1 units.
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 40.0, 2.0);
    scene
}

fn slide() -> MotionTransform {
    MotionTransform::new(vec![
        MotionKey { time: 0.0, render_from_object: Mat4::from_translation(Vec3::new(-0.5, 0.0, 0.0)) },
        MotionKey { time: 1.0, render_from_object: Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0)) },
    ])
    .unwrap()
}

#[test]
fn a_sliding_quad_covers_each_pixel_for_its_share_of_the_shutter() {
    let opts = RenderOptions { width: 40, height: 2, samples: 256, ..Default::default() };
    let out = render(&scene(Some(slide())), &opts, &NoProgress).unwrap();
    let fx = out.stats["effects"]["enabled"].as_array().unwrap();
    let blur = fx.iter().find(|e| e["name"] == "motion_blur").expect("motion_blur enabled");
    assert!(blur["why"].as_str().unwrap().contains("/slider"), "{blur}");
    for x in 0..40 {
        // The quad's centre moves from −0.5 to 0.5, so a point at x is covered while the centre
        // is within 0.5 of it: for max(0, 1 − |x|) of the shutter.
        let xc = -2.0 + 0.1 * (x as f32 + 0.5);
        let expected = (1.0 - xc.abs()).max(0.0);
        let got = out.film.pixel("color", x, 0)[0];
        assert!((got - expected).abs() < 0.03, "pixel {x} (x = {xc}): {got} vs {expected}");
    }
}

#[test]
fn a_still_scene_is_sharp_and_calls_for_no_motion_blur() {
    let opts = RenderOptions { width: 40, height: 2, samples: 16, ..Default::default() };
    let out = render(&scene(None), &opts, &NoProgress).unwrap();
    assert!(!out.stats["effects"]["enabled"].as_array().unwrap().iter().any(|e| e["name"] == "motion_blur"));
    for x in 0..40 {
        let xc = -2.0 + 0.1 * (x as f32 + 0.5);
        let got = out.film.pixel("color", x, 0)[0];
        // Pixels wholly inside or outside the quad (its edges fall on pixel boundaries).
        let expected = if xc.abs() < 0.5 { 1.0 } else { 0.0 };
        assert!((got - expected).abs() < 1e-4, "pixel {x}: {got}");
    }
}

/// A moving object's shadow moves with it: a blocker sliding over a lit ground darkens each
/// ground point for the share of the shutter it is overhead (shadow rays inherit the time).
#[test]
fn shadows_of_a_moving_blocker_are_blurred_the_same_way() {
    let mut s = scene(Some(slide()));
    // Lift the slider to z = 1 and put a white ground at z = 0, seen from above.
    let lift = Mat4::from_translation(Vec3::new(0.0, 0.0, 1.0));
    let keys: Vec<MotionKey> =
        slide().keys().iter().map(|k| MotionKey { time: k.time, render_from_object: lift * k.render_from_object }).collect();
    s.instances.clear();
    s.add_moving_instance(0, MotionTransform::new(keys).unwrap());
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let big = [[-50.0, -50.0, 0.0], [50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [-50.0, 50.0, 0.0]];
    let mut ground = Mesh::new("/ground", Arc::new(BilinearSurface::new(&topo, &big).unwrap()));
    ground.material = 0;
    let g = s.add_mesh(ground);
    s.add_instance(g, Mat4::IDENTITY);
    // Light at 45° from +x: the shadow lands 1 unit to −x of the slider. The camera sits between
    // the slider (z = 1) and the ground, so it sees only the ground.
    s.lights.clear();
    let dir = Vec3A::new(-1.0, 0.0, -1.0).normalize();
    s.lights.push(Light::distant("/sun", dir, Vec3A::splat(std::f32::consts::PI)));
    s.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 0.5), Vec3::ZERO, Vec3::Y), 40.0, 2.0);
    let opts = RenderOptions { width: 40, height: 2, samples: 256, ..Default::default() };
    let out = render(&s, &opts, &NoProgress).unwrap();
    let lit = dir.dot(Vec3A::NEG_Z).abs();
    for x in 0..40 {
        let xc = -2.0 + 0.1 * (x as f32 + 0.5);
        // Ground point xc is shadowed while the slider's centre is within 0.5 of xc + 1.
        let shadowed = (1.0 - (xc + 1.0).abs()).max(0.0);
        let expected = lit * (1.0 - shadowed);
        let got = out.film.pixel("color", x, 0)[0];
        assert!((got - expected).abs() < 0.03, "pixel {x} (x = {xc}): {got} vs {expected}");
    }
}
