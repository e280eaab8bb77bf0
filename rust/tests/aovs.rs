//! The geometric AOVs under Hydra's names against a plane at a known distance: `depth` (EXR's
//! Z), `cameraDepth` (Hydra's camera-space depth), `Peye` (Hydra's camera-space position),
//! `position`, `normal` and `Neye`, for a camera that is moved and turned, and what each holds
//! where nothing is hit.

use std::sync::Arc;

use glam::{Mat4, Quat, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::prelude::*;

fn topo1() -> MeshTopology {
    MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() }
}

const AOVS: [&str; 7] = ["depth", "cameraDepth", "Peye", "position", "normal", "Neye", "alpha"];

#[test]
fn depth_camera_depth_and_peye_match_a_plane_at_a_known_distance() {
    // A camera `d` from a plane, facing it squarely, but placed off the world origin and turned
    // about its view axis: its camera space is not world space. The plane is the camera-space
    // plane z = −d. A square 20 × 20 aperture at focal length 20 on a 9 × 7 image is widened to
    // fit (Hydra's CameraUtilFit): the window at z = −1 is [−9/14, 9/14] × [−1/2, 1/2], square
    // pixels 1/7 wide, so pixel (px, py)'s centre ray meets the plane at Peye = d · (x, y, −1),
    // x = (px + ½ − 4.5)/7, y = (3.5 − py − ½)/7.
    let d = 7.0f32;
    let render_from_camera = Mat4::from_rotation_translation(Quat::from_rotation_z(0.4), Vec3::new(1.0, -2.0, 3.0));
    let to_world = |c: Vec3| render_from_camera.transform_point3(c);
    let corners = [Vec3::new(-9.0, -9.0, -d), Vec3::new(9.0, -9.0, -d), Vec3::new(9.0, 9.0, -d), Vec3::new(-9.0, 9.0, -d)];
    let pts = corners.map(|c| to_world(c).to_array());
    let mut scene = Scene::default();
    let mesh = scene.add_mesh(Mesh::new("/wall", Arc::new(BilinearSurface::new(&topo1(), &pts).unwrap())));
    scene.add_instance(mesh, Mat4::IDENTITY);
    scene.camera = Camera {
        render_from_camera,
        focal_length: 20.0,
        horizontal_aperture: 20.0,
        vertical_aperture: 20.0,
        clipping_range: (0.1, 100.0),
        ..Default::default()
    };
    let (w, h) = (9usize, 7usize);
    let opts = RenderOptions { width: w, height: h, aovs: AOVS.iter().map(|s| Aov::from_name(s).unwrap()).collect(), ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let normal_world = render_from_camera.transform_vector3(Vec3::Z);
    let mut off_axis_gap = 0.0f32;
    for py in 0..h {
        for px in 0..w {
            let x = (px as f32 + 0.5 - 4.5) / 7.0;
            let y = (3.5 - py as f32 - 0.5) / 7.0;
            let px_f = |name: &str| out.film.pixel(name, px, py).to_vec();
            let peye = Vec3::from_slice(&px_f("Peye"));
            let depth = px_f("depth")[0];
            let camera_depth = px_f("cameraDepth")[0];
            // Camera-space: on the plane z = −d, in front of the camera.
            assert!((peye.z + d).abs() < 1e-4, "Peye.z at ({px}, {py}): {peye}");
            assert!((camera_depth - d).abs() < 1e-4 && (depth - d).abs() < 1e-4, "({px}, {py}): cameraDepth {camera_depth}, depth {depth}");
            assert_eq!(camera_depth, -peye.z, "cameraDepth is −Peye.z");
            // Where on the plane: the pixel's window position times the depth.
            let expect = Vec3::new(d * x, d * y, -d);
            assert!((peye - expect).length() < 1e-4, "Peye at ({px}, {py}): {peye} vs {expect}");
            // `position` is the same point in world space.
            let world = Vec3::from_slice(&px_f("position"));
            assert!((to_world(peye) - world).length() < 1e-4, "({px}, {py}): {world} vs {}", to_world(peye));
            // Normals: toward the camera, +z in camera space.
            assert!((Vec3::from_slice(&px_f("Neye")) - Vec3::Z).length() < 1e-3);
            assert!((Vec3::from_slice(&px_f("normal")) - normal_world).length() < 1e-3);
            // Depth is along the view axis, not the ray's length, which is longer by 1/cos.
            let ray_length = d * (1.0 + x * x + y * y).sqrt();
            assert!((peye.length() - ray_length).abs() < 1e-4);
            off_axis_gap = off_axis_gap.max(ray_length - camera_depth);
        }
    }
    assert!(off_axis_gap > 1.0, "the corners' rays are over a unit longer than their depth: {off_axis_gap}");
}

#[test]
fn peye_x_follows_the_window_when_the_image_is_wider_than_the_aperture() {
    // A square aperture on a 2:1 image: the window is widened to fit (Hydra's CameraUtilFit),
    // [−1, 1] × [−0.5, 0.5] at z = −1, so Peye.x = d · (−1 + 2 (px + ½)/W).
    let d = 4.0f32;
    let pts = [[-50.0, -50.0, -d], [50.0, -50.0, -d], [50.0, 50.0, -d], [-50.0, 50.0, -d]];
    let mut scene = Scene::default();
    let mesh = scene.add_mesh(Mesh::new("/wall", Arc::new(BilinearSurface::new(&topo1(), &pts).unwrap())));
    scene.add_instance(mesh, Mat4::IDENTITY);
    scene.camera = Camera { focal_length: 20.0, horizontal_aperture: 20.0, vertical_aperture: 20.0, ..Default::default() };
    let (w, h) = (8usize, 4usize);
    let opts = RenderOptions { width: w, height: h, aovs: vec![Aov::Peye, Aov::CameraDepth], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    for py in 0..h {
        for px in 0..w {
            let peye = Vec3A::from_slice(out.film.pixel("Peye", px, py));
            let expect = Vec3A::new(d * (-1.0 + 2.0 * (px as f32 + 0.5) / w as f32), d * (0.5 - (py as f32 + 0.5) / h as f32), -d);
            assert!((peye - expect).length() < 1e-4, "({px}, {py}): {peye} vs {expect}");
            assert!((out.film.pixel("cameraDepth", px, py)[0] - d).abs() < 1e-4);
        }
    }
}

#[test]
fn where_nothing_is_hit_depth_is_the_far_clip_and_camera_depth_and_peye_are_zero() {
    let scene = Scene { camera: Camera { clipping_range: (0.5, 250.0), ..Default::default() }, ..Default::default() };
    let opts = RenderOptions { width: 4, height: 4, aovs: AOVS.iter().map(|s| Aov::from_name(s).unwrap()).collect(), ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    for y in 0..4 {
        for x in 0..4 {
            assert_eq!(out.film.pixel("depth", x, y), &[250.0]);
            assert_eq!(out.film.pixel("cameraDepth", x, y), &[0.0]);
            assert_eq!(out.film.pixel("Peye", x, y), &[0.0, 0.0, 0.0]);
            assert_eq!(out.film.pixel("alpha", x, y), &[0.0]);
        }
    }
}
