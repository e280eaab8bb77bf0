//! Deformation motion blur against its truths: a quad whose points slide across the shutter
//! renders as the same quad moved by its transform (and as the analytic coverage), a quad
//! whose edge stretches covers each pixel for the share of the shutter the edge is past it,
//! shadows follow the deformation, and the cache modes agree to the bit.

mod common;

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::deform::DeformingSurface;
use mipray::material::Material;
use mipray::motion::{MotionKey, MotionTransform};
use mipray::prelude::*;
use mipray::topology::{MeshTopology, Scheme};

fn quad_topology() -> MeshTopology {
    MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() }
}

/// A unit quad on z = 0 centred at (dx, 0), its right edge moved a further `stretch` along x.
fn quad_points(dx: f32, stretch: f32) -> [[f32; 3]; 4] {
    [[-0.5 + dx, -0.5, 0.0], [0.5 + dx + stretch, -0.5, 0.0], [0.5 + dx + stretch, 0.5, 0.0], [-0.5 + dx, 0.5, 0.0]]
}

fn bilinear(p: [[f32; 3]; 4]) -> Arc<dyn LimitSurface> {
    Arc::new(BilinearSurface::new(&quad_topology(), &p).unwrap())
}

/// `surface`, white, lit head-on so a covered pixel reads 1, seen by a 40 × 2 pixel
/// orthographic camera 4 units wide (pixels of 0.1 units), instanced by `motion` or at rest.
fn scene(surface: Arc<dyn LimitSurface>, motion: Option<MotionTransform>) -> Scene {
    let mut scene = Scene::default();
    let mat = scene.add_material(Material::lambertian("/white", Vec3A::ONE).0);
    let mut mesh = Mesh::new("/slider", surface);
    mesh.material = mat;
    let m = scene.add_mesh(mesh);
    match motion {
        Some(motion) => scene.add_moving_instance(m, motion),
        None => scene.add_instance(m, Mat4::IDENTITY),
    };
    scene.lights.push(Light::distant("/sun", Vec3A::NEG_Z, Vec3A::splat(std::f32::consts::PI)));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 40.0, 2.0);
    scene
}

/// The quad's points sliding from x = −0.5 to 0.5 across the shutter, its transform fixed.
fn deformed_slide() -> Arc<dyn LimitSurface> {
    Arc::new(DeformingSurface::new(vec![(0.0, bilinear(quad_points(-0.5, 0.0))), (1.0, bilinear(quad_points(0.5, 0.0)))]).unwrap())
}

fn pixel_x(x: usize) -> f32 {
    -2.0 + 0.1 * (x as f32 + 0.5)
}

#[test]
fn a_quad_slid_by_its_points_renders_as_the_same_quad_slid_by_its_transform() {
    let opts = RenderOptions { width: 40, height: 2, samples: 256, ..Default::default() };
    let deformed = render(&scene(deformed_slide(), None), &opts, &NoProgress).unwrap();
    let fx = deformed.stats["effects"]["enabled"].as_array().unwrap();
    let blur = fx.iter().find(|e| e["name"] == "motion_blur").expect("motion_blur enabled");
    assert!(blur["why"].as_str().unwrap().contains("/slider"), "{blur}");
    let slide = MotionTransform::new(vec![
        MotionKey { time: 0.0, render_from_object: Mat4::from_translation(Vec3::new(-0.5, 0.0, 0.0)) },
        MotionKey { time: 1.0, render_from_object: Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0)) },
    ])
    .unwrap();
    let moved = render(&scene(bilinear(quad_points(0.0, 0.0)), Some(slide)), &opts, &NoProgress).unwrap();
    for x in 0..40 {
        // Covered while the centre (−0.5 → 0.5) is within 0.5 of the pixel: max(0, 1 − |x|).
        let expected = (1.0 - pixel_x(x).abs()).max(0.0);
        let (got, peer) = (deformed.film.pixel("color", x, 0)[0], moved.film.pixel("color", x, 0)[0]);
        assert!((got - expected).abs() < 0.03, "pixel {x}: {got} vs analytic {expected}");
        // Both sample the same camera times, so the two agree far closer than the noise.
        assert!((got - peer).abs() < 0.01, "pixel {x}: deformed {got} vs transformed {peer}");
    }
}

/// Not a rigid motion: the right edge moves from x = 0.5 to 1.5 while the left stays, so a
/// point x in (0.5, 1.5) is covered for the share 1.5 − x of the shutter.
#[test]
fn a_stretching_quad_covers_each_pixel_while_its_edge_is_past_it() {
    let stretch =
        Arc::new(DeformingSurface::new(vec![(0.0, bilinear(quad_points(0.0, 0.0))), (1.0, bilinear(quad_points(0.0, 1.0)))]).unwrap());
    let opts = RenderOptions { width: 40, height: 2, samples: 256, ..Default::default() };
    let out = render(&scene(stretch, None), &opts, &NoProgress).unwrap();
    for x in 0..40 {
        let xc = pixel_x(x);
        let expected = if xc < -0.5 { 0.0 } else { (1.5 - xc).clamp(0.0, 1.0) };
        let got = out.film.pixel("color", x, 0)[0];
        assert!((got - expected).abs() < 0.03, "pixel {x} (x = {xc}): {got} vs {expected}");
    }
}

/// Shadow rays inherit the camera ray's time: a blocker slid by its points darkens each ground
/// point for the share of the shutter it is overhead.
#[test]
fn shadows_of_a_deforming_blocker_are_blurred_the_same_way() {
    let lifted = |dx: f32| {
        let mut p = quad_points(dx, 0.0);
        for v in &mut p {
            v[2] = 1.0;
        }
        bilinear(p)
    };
    let blocker = Arc::new(DeformingSurface::new(vec![(0.0, lifted(-0.5)), (1.0, lifted(0.5))]).unwrap());
    let mut s = scene(blocker, None);
    let big = [[-50.0, -50.0, 0.0], [50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [-50.0, 50.0, 0.0]];
    let mut ground = Mesh::new("/ground", bilinear(big));
    ground.material = 0;
    let g = s.add_mesh(ground);
    s.add_instance(g, Mat4::IDENTITY);
    s.lights.clear();
    let dir = Vec3A::new(-1.0, 0.0, -1.0).normalize();
    s.lights.push(Light::distant("/sun", dir, Vec3A::splat(std::f32::consts::PI)));
    s.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 0.5), Vec3::ZERO, Vec3::Y), 40.0, 2.0);
    let opts = RenderOptions { width: 40, height: 2, samples: 256, ..Default::default() };
    let out = render(&s, &opts, &NoProgress).unwrap();
    let lit = dir.dot(Vec3A::NEG_Z).abs();
    for x in 0..40 {
        let xc = pixel_x(x);
        let shadowed = (1.0 - (xc + 1.0).abs()).max(0.0);
        let expected = lit * (1.0 - shadowed);
        let got = out.film.pixel("color", x, 0)[0];
        assert!((got - expected).abs() < 0.03, "pixel {x} (x = {xc}): {got} vs {expected}");
    }
}

/// A curved surface bending across the shutter, seen in perspective at every rate: the grids
/// blended per ray come from cached sample grids, so the cache's mode cannot change a bit.
#[test]
fn cache_modes_give_bit_identical_images_of_a_deforming_mesh() {
    // A 6 × 6 bilinear sheet whose middle rises by 0.8 across the shutter.
    let n = 7;
    let topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4; (n - 1) * (n - 1)],
        face_vertex_indices: (0..n - 1)
            .flat_map(|j| (0..n - 1).flat_map(move |i| [j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i]))
            .map(|k| k as i32)
            .collect(),
        ..Default::default()
    };
    let sheet = |lift: f32| -> Arc<dyn LimitSurface> {
        let pts: Vec<[f32; 3]> = (0..n * n)
            .map(|k| {
                let (x, y) = ((k % n) as f32 / (n - 1) as f32 - 0.5, (k / n) as f32 / (n - 1) as f32 - 0.5);
                [x * 2.0, y * 2.0, lift * (1.0 - 4.0 * x * x) * (1.0 - 4.0 * y * y)]
            })
            .collect();
        Arc::new(BilinearSurface::new(&topo, &pts).unwrap())
    };
    let surface = Arc::new(DeformingSurface::new(vec![(0.0, sheet(0.0)), (0.5, sheet(0.3)), (1.0, sheet(0.8))]).unwrap());
    let camera = Camera::perspective(Camera::look_at(Vec3::new(1.5, -2.0, 2.5), Vec3::ZERO, Vec3::Z), 35.0);
    let scene = common::scene_of("/sheet", surface, Mat4::IDENTITY, camera);
    common::assert_cache_modes_give_bit_identical_images(&scene);
}
