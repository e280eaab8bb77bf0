//! Magnified views stay exact: subpatches split on demand when rays need more than 16×16 quads
//! (the paper's §5.1), so a narrow-field camera sees a sphere's silhouette within half a pixel
//! of the true surface. An analytic sphere stands in for a limit surface.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::bounds::Bounds3;
use mipray::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};
use mipray::prelude::*;
use mipray::topology::{MeshTopology, Scheme};

/// A sphere of radius `r` as 8 patches: 4 in longitude × 2 in latitude.
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
    /// The patch's own box (as a control hull would bound it): from a dense sampling, grown by
    /// more than the sampling's chord error, so neighbouring patches' boxes overlap only near
    /// their shared edges.
    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        let n = 32;
        let pts = (0..=n).flat_map(|j| (0..=n).map(move |i| (i as f32 / n as f32, j as f32 / n as f32)));
        let b = Bounds3::from_points(pts.map(|(u, v)| self.evaluate(patch, u, v).p));
        b.expanded(self.r * 0.01)
    }
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        let phi = (patch % 4) as f32 * PI / 2.0 + u * PI / 2.0;
        let theta = (patch / 4) as f32 * PI / 2.0 + v * PI / 2.0;
        let p = Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()) * self.r;
        let dpdu = Vec3A::new(-theta.sin() * phi.sin(), theta.sin() * phi.cos(), 0.0) * self.r * PI / 2.0;
        let dpdv = Vec3A::new(theta.cos() * phi.cos(), theta.cos() * phi.sin(), -theta.sin()) * self.r * PI / 2.0;
        SurfacePoint { p, dpdu, dpdv, ..Default::default() }
    }
    fn control_face_count(&self) -> usize {
        8
    }
}

#[test]
fn magnified_silhouette_is_within_half_a_pixel_of_the_true_sphere() {
    let r = 1.0;
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/sphere", Arc::new(Sphere { r })));
    scene.add_instance(m, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.0, -1.0, -1.0), Vec3A::ONE));
    // Look along −y at the silhouette point (1, 0, 0.3) from 10 units away with a 5000 mm lens on
    // a 1 mm back: the view is 0.002 units wide, 0.0001 per pixel at 20 pixels.
    let target = Vec3::new((1.0f32 - 0.09).sqrt(), 0.0, 0.3);
    let eye = target + Vec3::new(0.0, 10.0, 0.0);
    scene.camera = Camera {
        render_from_camera: Camera::look_at(eye, target, Vec3::Z),
        focal_length: 5000.0,
        horizontal_aperture: 1.0,
        vertical_aperture: 1.0,
        clipping_range: (0.1, 100.0),
        ..Default::default()
    };
    let (w, h) = (20, 20);
    let opts = RenderOptions { width: w, height: h, aovs: vec![Aov::Alpha, Aov::TessRate], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let pixel = 0.002 / w as f32 * 10.0 / 10.0;
    let (mut checked, mut inside) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            // Distance of the ray's closest approach to the centre, against the radius.
            let oc = ray.o;
            let tc = -oc.dot(ray.d);
            let miss_by = (oc + ray.d * tc).length() - r;
            if miss_by.abs() < 0.5 * pixel {
                continue;
            }
            checked += 1;
            let hit = out.film.pixel("alpha", x, y)[0] > 0.5;
            inside += hit as i32;
            assert_eq!(hit, miss_by < 0.0, "pixel ({x}, {y}) misses the sphere by {miss_by} (pixel {pixel})");
        }
    }
    assert!(checked > 300 && inside > 50 && inside < checked - 50, "{checked} {inside}");
    let max_rate = out.film.aov("tessRate").unwrap().data.iter().cloned().fold(0.0, f32::max);
    assert!(max_rate >= 256.0, "the view needs split subpatches, got rate {max_rate}");
    assert!(out.stats["render"]["finer_than_fine_tests"].as_u64().unwrap() > 0);
}

/// Ray–triangle distance (Möller–Trumbore), for an independent reference.
fn tri_t(o: Vec3A, d: Vec3A, a: Vec3A, b: Vec3A, c: Vec3A) -> Option<f32> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0).then(|| e2.dot(q) / det)
}

#[test]
fn tess_error_aov_is_the_chord_distance_to_the_true_sphere() {
    // Single mode tests everything at 16×16. Aim straight at the centre of quad (7, 11) of
    // patch 0: the true sphere is 4 units away; the tessellation's two triangles are a little
    // further. The AOV must report that gap, computed here independently.
    let sphere = Sphere { r: 1.0 };
    let (i, j) = (7.0f32, 11.0f32);
    let c = sphere.evaluate(0, (i + 0.5) / 16.0, (j + 0.5) / 16.0).p.normalize();
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/sphere", Arc::new(Sphere { r: 1.0 })));
    scene.add_instance(m, Mat4::IDENTITY);
    let eye = Vec3::from(c * 5.0);
    scene.camera = Camera::orthographic(Camera::look_at(eye, Vec3::ZERO, if c.z.abs() < 0.9 { Vec3::Z } else { Vec3::X }), 10.0, 10.0);
    let opts = RenderOptions {
        width: 5,
        height: 5,
        cache: mipray::geometry_cache::CacheConfig::single(30_000_000),
        aovs: vec![Aov::TessError, Aov::TessRate],
        ..Default::default()
    };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    assert_eq!(out.film.pixel("tessRate", 2, 2)[0], 16.0);
    let corner = |a: f32, b: f32| sphere.evaluate(0, a / 16.0, b / 16.0).p;
    let (p00, p10, p11, p01) = (corner(i, j), corner(i + 1.0, j), corner(i + 1.0, j + 1.0), corner(i, j + 1.0));
    let (o, d) = (c * 5.0, -c);
    let t_tri = tri_t(o, d, p00, p10, p11).or_else(|| tri_t(o, d, p00, p11, p01)).unwrap();
    let expected = t_tri - 4.0;
    let got = out.film.pixel("tessError", 2, 2);
    assert!(expected > 1e-4, "the chord is measurably inside the sphere: {expected}");
    assert!((got[0] - expected).abs() < 2e-3 * expected + 2e-6, "tessError {} vs chord {expected}", got[0]);
    assert!(got[1] > 0.0 && (got[1] - got[0] / 0.2).abs() < 1e-3 * got[1], "relative to the 0.2-unit beam: {got:?}");
}

#[test]
fn a_flat_patch_has_zero_tessellation_error_at_every_rate() {
    // A trapezoid: flat but not affine, so it is tessellated at the beam's rate like any patch.
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let s = BilinearSurface::new(&topo, &[[-3.0, -1.0, 0.0], [3.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]).unwrap();
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/flat", Arc::new(s)));
    scene.add_instance(m, Mat4::IDENTITY);
    for tess_factor in [0.05f32, 0.5, 4.0, 40.0] {
        scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.3, -2.0, 3.0), Vec3::ZERO, Vec3::Z), 35.0);
        let out = render(
            &scene,
            &RenderOptions { width: 24, height: 16, tess_factor, aovs: vec![Aov::TessError, Aov::Alpha], ..Default::default() },
            &NoProgress,
        )
        .unwrap();
        let e = &out.film.aov("tessError").unwrap().data;
        assert!(e.iter().all(|x| x.abs() < 1e-4), "tessFactor {tess_factor}: {:?}", e.iter().cloned().fold(0.0f32, f32::max));
        assert!(out.film.aov("alpha").unwrap().data.iter().any(|a| *a > 0.0));
    }
}

#[test]
fn a_coarser_tessellation_of_its_own_surface_does_not_shadow_a_secondary_ray() {
    // Inside a sphere, seen by narrow camera rays (fine grids), with ambient occlusion rays
    // forced to coarse grids (tessFactorIncoherent 64). A coarse chord of the concave surface
    // lies inside it, in front of the AO rays' origins. With exact geometry, a ray at elevation
    // α meets the unit sphere again after 2 sin α, so within 0.2 only (0.2/2)² = 1% of the
    // cosine-weighted rays are occluded: AO = 0.99. Taking the surface's own coarse grid for an
    // occluder gave 0.91 here (with the patches' boxes as loose as the whole sphere); skipping
    // the own subpatch, and the neighbours whose boxes hold the origin, within the chord errors
    // gives 0.983 with tight boxes. The rest is the forced rate's own error: the far walls'
    // coarse chords lie inside the sphere, nearer than the wall.
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/sphere", Arc::new(Sphere { r: 1.0 })));
    scene.add_instance(m, Mat4::IDENTITY);
    scene.camera = Camera {
        render_from_camera: Camera::look_at(Vec3::ZERO, Vec3::new(1.0, 0.3, 0.2), Vec3::Z),
        focal_length: 35.0,
        clipping_range: (0.01, 10.0),
        ..Default::default()
    };
    let opts = RenderOptions {
        width: 16,
        height: 12,
        ao_samples: 16,
        ao_distance: 0.2,
        tess_factor_incoherent: 64.0,
        aovs: vec![Aov::Ao],
        ..Default::default()
    };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let ao = &out.film.aov("ao").unwrap().data;
    let mean = ao.iter().sum::<f32>() / ao.len() as f32;
    assert!(mean > 0.95, "mean AO {mean}: the surface shadowed itself");
    let rates = &out.stats["render"]["rate_tests_by_ray"]["ao"];
    assert!(rates["1"].as_u64().unwrap() + rates["2"].as_u64().unwrap() > 0, "AO rays did use coarse grids: {rates}");
}

/// A quarter cylinder of radius `r` about the z axis as one patch: u sweeps the angle φ over
/// [−π/4, π/4], v the height z over [−½, ½]. Its grids' quads are planar rectangles, so the
/// tessellation at rate n (n chords across the angle) is known exactly: every chord lies
/// `r (1 − cos(π/(4n)))` inside the surface at its middle.
struct Cylinder {
    r: f32,
}

impl Cylinder {
    const SPAN: f32 = PI / 2.0;
}

impl LimitSurface for Cylinder {
    fn patch_count(&self) -> usize {
        1
    }
    fn patch_param(&self, patch: usize) -> PatchParam {
        Sphere { r: self.r }.patch_param(patch)
    }
    fn patch_bounds(&self, _patch: usize) -> Bounds3 {
        let h = (Self::SPAN / 2.0).sin() * self.r;
        Bounds3 { min: Vec3A::new((Self::SPAN / 2.0).cos() * self.r, -h, -0.5), max: Vec3A::new(self.r, h, 0.5) }
    }
    fn evaluate(&self, _patch: usize, u: f32, v: f32) -> SurfacePoint {
        let phi = (u - 0.5) * Self::SPAN;
        let p = Vec3A::new(phi.cos(), phi.sin(), 0.0) * self.r + Vec3A::new(0.0, 0.0, v - 0.5);
        let dpdu = Vec3A::new(-phi.sin(), phi.cos(), 0.0) * self.r * Self::SPAN;
        SurfacePoint { p, dpdu, dpdv: Vec3A::Z, ..Default::default() }
    }
    fn control_face_count(&self) -> usize {
        1
    }
}

#[test]
fn tess_error_is_the_closed_form_chord_error_of_a_cylinder_at_every_rate() {
    // An orthographic camera looks at the cylinder's axis through the middle of one chord of the
    // grid at rate n: the ray meets the chord r·cos(π/(4n)) from the axis and the surface at r,
    // so tessError is r (1 − cos(π/(4n))) in world units, and that over the 0.01-unit beam.
    // tessFactor picks the rate (the subpatch is about 1.43 units across: 143 quads at tess
    // factor 1 for a 0.01 beam); rates above 16 are split subpatches.
    let r = 1.0f32;
    let pixel = 0.01f32;
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/cylinder", Arc::new(Cylinder { r })));
    scene.add_instance(m, Mat4::IDENTITY);
    for n in [1u32, 2, 4, 8, 16, 32, 64] {
        // Chord k = n/2 (the one just past φ = 0; the only one for n = 1), its middle angle:
        let k = n / 2;
        let phi = (-0.5 + (k as f32 + 0.5) / n as f32) * Cylinder::SPAN;
        let dir = Vec3::new(phi.cos(), phi.sin(), 0.0);
        scene.camera = Camera::orthographic(Camera::look_at(dir * 5.0, Vec3::ZERO, Vec3::Z), 10.0 * 5.0 * pixel, 10.0 * 5.0 * pixel);
        let tess_factor = 1.43 * r / (pixel * 0.75 * n as f32);
        let opts = RenderOptions { width: 5, height: 5, tess_factor, aovs: vec![Aov::TessError, Aov::TessRate], ..Default::default() };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        assert_eq!(out.film.pixel("tessRate", 2, 2)[0], n as f32, "tessFactor {tess_factor} picks rate {n}");
        let expected = r * (1.0 - (Cylinder::SPAN / (2.0 * n as f32)).cos());
        let got = out.film.pixel("tessError", 2, 2);
        println!("rate {n}: tessError {:.4e} (closed form {expected:.4e}), {:.4} beam widths", got[0], got[1]);
        assert!((got[0] - expected).abs() < 1e-3 * expected + 2e-6, "rate {n}: tessError {} vs closed form {expected}", got[0]);
        assert!((got[1] - got[0] / pixel).abs() < 1e-3 * got[1] + 1e-6, "rate {n}: over the {pixel}-unit beam: {got:?}");
    }
}

#[test]
fn a_warm_cache_that_split_other_children_gives_the_same_image() {
    // A cache kept across renders (as the render delegate keeps one) holds split children's
    // tessellations from the views before; the image must be the one a cold cache gives.
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/sphere", Arc::new(Sphere { r: 1.0 })));
    scene.add_instance(m, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.0, -1.0, -1.0), Vec3A::ONE));
    // 0.02 units wide at 4 units: rays 0.001 wide want about 1,600 quads across a patch.
    let view = |dir: Vec3| Camera {
        render_from_camera: Camera::look_at(dir.normalize() * 5.0, Vec3::ZERO, Vec3::Z),
        focal_length: 1000.0,
        horizontal_aperture: 5.0,
        vertical_aperture: 5.0,
        clipping_range: (0.1, 100.0),
        ..Default::default()
    };
    let aovs = vec![Aov::Color, Aov::Depth, Aov::Normal];
    let opts = |size: usize| RenderOptions { width: size, height: size, threads: 2, aovs: aovs.clone(), ..Default::default() };
    let target = Vec3::new(1.0, 0.4, 0.3);
    scene.camera = view(target);
    let cold = render(&scene, &opts(20), &NoProgress).unwrap();
    assert!(cold.stats["scene"]["split_subpatches"].as_u64().unwrap() > 0);
    let cache = Arc::new(mipray::geometry_cache::GeometryCache::new(opts(20).cache));
    for (dir, size) in [(Vec3::new(0.5, 1.0, -0.2), 20), (target, 32)] {
        scene.camera = view(dir);
        mipray::render::render_with_cache(&scene, &opts(size), Some(cache.clone()), &NoProgress).unwrap();
    }
    scene.camera = view(target);
    let warm = mipray::render::render_with_cache(&scene, &opts(20), Some(cache), &NoProgress).unwrap();
    assert!(warm.stats["geometry_cache"]["tiers"][2]["hits"].as_u64().unwrap() > 0, "served from the warm cache");
    for aov in ["color", "depth", "normal"] {
        let (w, c) = (&warm.film.aov(aov).unwrap().data, &cold.film.aov(aov).unwrap().data);
        let differ = w.iter().zip(c).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(differ, 0, "{aov}: {differ} of {} values differ on the warm cache", w.len());
    }
}
