//! Deformation motion blur against its truths: a quad whose points slide across the shutter
//! renders as the same quad moved by its transform (and as the analytic coverage), a quad
//! whose edge stretches covers each pixel for the share of the shutter the edge is past it,
//! shadows follow the deformation, and the cache modes agree to the bit.

mod common;

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::curves::{Basis, CurveType, CurvesDesc, CurvesSurface, Interpolation, Style, Wrap};
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

/// The mean of `f(x, y, t)` over pixel (x, y) of [`scene`]'s 40 × 2 film (0.1 units a pixel;
/// row 0 spans y 0 … 0.1) and the shutter: the integral by the midpoint rule on a 40 × 40 ×
/// 400 grid, independently of the renderer.
fn pixel_mean(x: usize, y: usize, f: impl Fn(f64, f64, f64) -> f64) -> f32 {
    let (n, nt) = (40, 400);
    let mut sum = 0.0;
    for k in 0..nt {
        let t = (k as f64 + 0.5) / nt as f64;
        for j in 0..n {
            let py = 0.1 - 0.1 * (y as f64 + (j as f64 + 0.5) / n as f64);
            for i in 0..n {
                sum += f(-2.0 + 0.1 * (x as f64 + (i as f64 + 0.5) / n as f64), py, t);
            }
        }
    }
    (sum / (n * n * nt) as f64) as f32
}

/// The share of pixel (x, y) × the shutter that a disc (a sphere's silhouette seen head-on by
/// the orthographic camera) of centre (`cx(t)`, 0) and radius `r(t)` covers.
fn disc_coverage(x: usize, y: usize, cx: impl Fn(f64) -> f64, r: impl Fn(f64) -> f64) -> f32 {
    pixel_mean(x, y, |px, py, t| if (px - cx(t)).powi(2) + py * py < r(t).powi(2) { 1.0 } else { 0.0 })
}

fn alpha_options() -> RenderOptions {
    RenderOptions { width: 40, height: 2, samples: 256, aovs: vec![mipray::aov::Aov::Color, mipray::aov::Aov::Alpha], ..Default::default() }
}

/// A single point (a sphere of radius 0.5) slid by its samples from x = −0.5 to 0.5 across the
/// shutter covers each pixel for the share of the shutter and pixel the analytic disc does,
/// and renders as the same sphere slid by its transform.
#[test]
fn a_point_slid_by_its_samples_covers_what_the_moving_disc_covers_and_matches_a_transform() {
    use mipray::implicit::PointsSurface;
    let sliding = PointsSurface::deforming(vec![(0.0, vec![[-0.5, 0.0, 0.0]]), (1.0, vec![[0.5, 0.0, 0.0]])], &[vec![1.0]]).unwrap();
    let opts = alpha_options();
    let deformed = render(&scene(Arc::new(sliding), None), &opts, &NoProgress).unwrap();
    let fx = deformed.stats["effects"]["enabled"].as_array().unwrap();
    assert!(fx.iter().any(|e| e["name"] == "motion_blur"), "motion_blur enabled: {fx:?}");
    let slide = MotionTransform::new(vec![
        MotionKey { time: 0.0, render_from_object: Mat4::from_translation(Vec3::new(-0.5, 0.0, 0.0)) },
        MotionKey { time: 1.0, render_from_object: Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0)) },
    ])
    .unwrap();
    let still = PointsSurface::new(vec![[0.0, 0.0, 0.0]], &[1.0]).unwrap();
    let moved = render(&scene(Arc::new(still), Some(slide)), &opts, &NoProgress).unwrap();
    matches_analytic_and_transform(&deformed, &moved, |x, y| disc_coverage(x, y, |t| -0.5 + t, |_| 0.5), 1e-3);
}

/// A point whose width grows from 0.2 to 1.8 across the shutter (radius 0.1 → 0.9) covers
/// each pixel for the share of the shutter its radius reaches past it; shaded on the sphere of
/// that time (head-on sun: the colour of a hit is its normal's z, so the colour integrates to
/// the mean of √(1 − (d / r)²) over the covered share).
#[test]
fn a_point_whose_width_grows_covers_each_pixel_once_its_radius_reaches_it() {
    use mipray::implicit::PointsSurface;
    let grow = PointsSurface::deforming(vec![(0.0, vec![[0.0; 3]]), (1.0, vec![[0.0; 3]])], &[vec![0.2], vec![1.8]]).unwrap();
    let out = render(&scene(Arc::new(grow), None), &alpha_options(), &NoProgress).unwrap();
    let r = |t: f64| 0.1 + 0.8 * t;
    for y in 0..2 {
        for x in 0..40 {
            let expected = disc_coverage(x, y, |_| 0.0, r);
            let got = out.film.pixel("alpha", x, y)[0];
            assert!((got - expected).abs() < 0.04, "pixel ({x}, {y}): alpha {got} vs analytic {expected}");
        }
    }
    // Shading on the sphere of the ray's time: lit head-on, a hit's colour is its normal's z,
    // √(1 − (d / r(t))²) at distance d from the centre.
    for x in [18, 20, 22, 25] {
        let shade = pixel_mean(x, 0, |px, py, t| {
            let q = (px * px + py * py) / r(t).powi(2);
            if q < 1.0 {
                (1.0 - q).sqrt()
            } else {
                0.0
            }
        });
        let got = out.film.pixel("color", x, 0)[0];
        assert!((got - shade).abs() < 0.04, "pixel {x}: colour {got} vs the blended sphere's shading {shade}");
    }
}

/// Moving points in perspective, under shadows: the cache's mode cannot change a bit (they are
/// never tessellated, but share the render with a deforming mesh's cached grids).
#[test]
fn cache_modes_give_bit_identical_images_of_moving_points() {
    use mipray::implicit::PointsSurface;
    let at = |dz: f32| -> Vec<[f32; 3]> {
        (0..25).map(|k| [(k % 5) as f32 * 0.4 - 0.8, (k / 5) as f32 * 0.4 - 0.8, dz * (k % 3) as f32]).collect()
    };
    let pts = PointsSurface::deforming(vec![(0.0, at(0.0)), (0.5, at(0.2)), (1.0, at(0.5))], &[vec![0.3], vec![0.3], vec![0.1]]).unwrap();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(1.5, -2.0, 2.5), Vec3::ZERO, Vec3::Z), 35.0);
    let scene = common::scene_of("/points", Arc::new(pts), Mat4::IDENTITY, camera);
    common::assert_cache_modes_give_bit_identical_images(&scene);
}

fn tube(points: &[[f32; 3]], counts: &[i32], curve_type: CurveType, widths: &[f32]) -> CurvesSurface {
    CurvesSurface::new(&CurvesDesc {
        points,
        counts,
        curve_type,
        basis: Basis::Bspline,
        wrap: Wrap::Nonperiodic,
        widths,
        widths_interpolation: if widths.len() == 1 { Interpolation::Constant } else { Interpolation::Vertex },
        normals: &[],
        normals_interpolation: Interpolation::Vertex,
        style: Style::Tube,
    })
    .unwrap()
}

/// A straight tube (a linear curve along y, width 0.4) slid by its points from x = −0.5 to
/// 0.5 across the shutter covers each pixel for the share the moving band |x − c(t)| < 0.2
/// does, and renders as the same tube slid by its transform.
#[test]
fn a_curve_slid_by_its_points_covers_what_the_moving_band_covers_and_matches_a_transform() {
    let at = |x: f32| tube(&[[x, -1.0, 0.0], [x, 1.0, 0.0]], &[2], CurveType::Linear, &[0.4]);
    let sliding = CurvesSurface::deforming(vec![(0.0, at(-0.5)), (1.0, at(0.5))]).unwrap();
    let opts = alpha_options();
    let deformed = render(&scene(Arc::new(sliding), None), &opts, &NoProgress).unwrap();
    let fx = deformed.stats["effects"]["enabled"].as_array().unwrap();
    assert!(fx.iter().any(|e| e["name"] == "motion_blur"), "motion_blur enabled: {fx:?}");
    let slide = MotionTransform::new(vec![
        MotionKey { time: 0.0, render_from_object: Mat4::from_translation(Vec3::new(-0.5, 0.0, 0.0)) },
        MotionKey { time: 1.0, render_from_object: Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0)) },
    ])
    .unwrap();
    let moved = render(&scene(Arc::new(at(0.0)), Some(slide)), &opts, &NoProgress).unwrap();
    matches_analytic_and_transform(
        &deformed,
        &moved,
        |x, y| pixel_mean(x, y, |px, _, t| if (px - (t - 0.5)).abs() < 0.2 { 1.0 } else { 0.0 }),
        2e-3,
    );
}

/// A cubic curve that bends and thickens across the shutter (its control points and widths
/// sampled three times), in perspective at every rate: the pieces blended per ray come from
/// pieces cached per sample, so the cache's mode cannot change a bit.
#[test]
fn cache_modes_give_bit_identical_images_of_a_moving_curve() {
    let at = |bend: f32, w: f32| {
        let p: Vec<[f32; 3]> = (0..6)
            .map(|i| {
                let s = i as f32 / 5.0 - 0.5;
                [2.0 * s, bend * (1.0 - 4.0 * s * s), 0.3 * s]
            })
            .collect();
        tube(&p, &[6], CurveType::Cubic, &[w, w, 2.0 * w, w, w, 0.5 * w])
    };
    let curve = CurvesSurface::deforming(vec![(0.0, at(0.0, 0.1)), (0.5, at(0.4, 0.15)), (1.0, at(1.0, 0.3))]).unwrap();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(1.0, -1.5, 2.5), Vec3::ZERO, Vec3::Z), 35.0);
    let scene = common::scene_of("/hair", Arc::new(curve), Mat4::IDENTITY, camera);
    common::assert_cache_modes_give_bit_identical_images(&scene);
}

/// An implicit sphere whose radius grows from 0.1 to 0.9 across the shutter covers each pixel
/// for the share of the shutter and pixel the growing disc does.
#[test]
fn a_sphere_whose_radius_grows_covers_each_pixel_once_its_radius_reaches_it() {
    use mipray::implicit::{ImplicitSurface, Shape};
    let grow = ImplicitSurface::deforming(vec![(0.0, Shape::Sphere { radius: 0.1 }), (1.0, Shape::Sphere { radius: 0.9 })]).unwrap();
    let out = render(&scene(Arc::new(grow), None), &alpha_options(), &NoProgress).unwrap();
    for y in 0..2 {
        for x in 0..40 {
            let expected = disc_coverage(x, y, |_| 0.0, |t| 0.1 + 0.8 * t);
            let got = out.film.pixel("alpha", x, y)[0];
            assert!((got - expected).abs() < 0.04, "pixel ({x}, {y}): alpha {got} vs analytic {expected}");
        }
    }
}

/// A capsule growing in radius and height, in perspective: bit-identical across cache modes.
#[test]
fn cache_modes_give_bit_identical_images_of_a_growing_capsule() {
    use mipray::implicit::{Axis, ImplicitSurface, Shape};
    let capsule = |r: f32, h: f32| Shape::Capsule { radius_bottom: r, radius_top: 0.5 * r, height: h, axis: Axis::Y };
    let grow = ImplicitSurface::deforming(vec![(0.0, capsule(0.3, 0.5)), (0.4, capsule(0.5, 0.8)), (1.0, capsule(0.6, 1.5))]).unwrap();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(1.5, -2.0, 2.5), Vec3::ZERO, Vec3::Z), 35.0);
    let scene = common::scene_of("/capsule", Arc::new(grow), Mat4::IDENTITY, camera);
    common::assert_cache_modes_give_bit_identical_images(&scene);
}

/// Moving points, a moving curve and a growing capsule in one scene: the same bits with 1 and
/// 3 threads (each ray's time, blend and exact test are functions of the ray alone).
#[test]
fn thread_counts_give_bit_identical_images_of_moving_points_curves_and_implicit_prims() {
    use mipray::implicit::{Axis, ImplicitSurface, PointsSurface, Shape};
    let mut s = Scene::default();
    let pts =
        PointsSurface::deforming(vec![(0.0, vec![[-1.0, 0.0, 0.0]]), (1.0, vec![[-0.5, 0.3, 0.2]])], &[vec![0.4], vec![0.6]]).unwrap();
    let at = |x: f32| tube(&[[x, -1.0, 0.0], [x + 0.2, 0.0, 0.3], [x, 0.5, 0.0], [x, 1.0, 0.2]], &[4], CurveType::Cubic, &[0.1]);
    let curve = CurvesSurface::deforming(vec![(0.0, at(0.0)), (1.0, at(0.4))]).unwrap();
    let capsule = |r: f32| Shape::Capsule { radius_bottom: r, radius_top: r, height: 0.5, axis: Axis::Z };
    let grow = ImplicitSurface::deforming(vec![(0.0, capsule(0.2)), (1.0, capsule(0.4))]).unwrap();
    let surfaces: [Arc<dyn LimitSurface>; 3] = [Arc::new(pts), Arc::new(curve), Arc::new(grow)];
    for (k, surface) in surfaces.into_iter().enumerate() {
        let m = s.add_mesh(Mesh::new(format!("/m{k}"), surface));
        s.add_instance(m, Mat4::from_translation(Vec3::new(0.9 * k as f32 - 0.5, 0.0, 0.0)));
    }
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.5, -3.0, 2.0), Vec3::ZERO, Vec3::Z), 40.0);
    let s = common::lit(s, camera);
    let bits = |threads: usize| {
        let opts = RenderOptions { width: 48, height: 32, samples: 4, threads, ..Default::default() };
        let out = render(&s, &opts, &NoProgress).unwrap();
        (0..32).flat_map(|y| (0..48).map(move |x| (x, y))).map(|(x, y)| out.film.pixel("color", x, y)[0].to_bits()).collect::<Vec<_>>()
    };
    let one = bits(1);
    assert!(one.iter().filter(|&&b| f32::from_bits(b) > 0.0).count() > 100, "the prims are in view");
    assert!(one == bits(3), "1 and 3 threads differ");
}

/// Each pixel of the 40 × 2 strip `deformed` (a deformation blur) has the analytic `coverage(x,
/// y)` as alpha (within 0.04: 16 samples a pixel), and alpha and colour within `same` of
/// `moved`, the same motion by transform.
fn matches_analytic_and_transform(
    deformed: &mipray::render::RenderOutput,
    moved: &mipray::render::RenderOutput,
    coverage: impl Fn(usize, usize) -> f32,
    same: f32,
) {
    for y in 0..2 {
        for x in 0..40 {
            let expected = coverage(x, y);
            let got = deformed.film.pixel("alpha", x, y)[0];
            assert!((got - expected).abs() < 0.04, "pixel ({x}, {y}): alpha {got} vs analytic {expected}");
            for aov in ["alpha", "color"] {
                let (a, b) = (deformed.film.pixel(aov, x, y)[0], moved.film.pixel(aov, x, y)[0]);
                assert!((a - b).abs() < same, "pixel ({x}, {y}) {aov}: deformed {a} vs transformed {b}");
            }
        }
    }
}
