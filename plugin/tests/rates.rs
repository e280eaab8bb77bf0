//! Tessellation rates where the paper puts them (issue 15): a subpatch is tested at the rate
//! whose quads are about as wide as the ray's beam (Christensen et al. 2003, §5.2), so its size
//! must be the patch's own, not its control hull's. Checked against analytic sizes: a grid of
//! known spacing under a camera of known pixel footprint.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::bounds::Bounds3;
use mipray::camera::Camera;
use mipray::patch::{GridSamples, LimitSurface, PatchKind, UvRect};
use mipray::prelude::*;
use mipray_bridge::OsdSurface;

/// A Catmull-Clark grid of `n × n` faces over [−half, half]², gently domed
/// (z = −0.02 (x² + y²)): not flat, so no patch is affine and every rate is used by its size.
/// x and y are linear in the control points, so each interior patch's limit surface spans exactly
/// one grid spacing in x and y.
fn dome(n: usize, half: f32) -> OsdSurface {
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (-half + 2.0 * half * i as f32 / n as f32, -half + 2.0 * half * j as f32 / n as f32);
            pts.push([x, y, -0.02 * (x * x + y * y)]);
        }
    }
    let v = |i: usize, j: usize| (j * (n + 1) + i) as i32;
    let idx: Vec<i32> = (0..n).flat_map(|j| (0..n).flat_map(move |i| [v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)])).collect();
    let topo =
        MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: vec![4; n * n], face_vertex_indices: idx, ..Default::default() };
    OsdSurface::new("/dome", &topo, &pts).unwrap()
}

/// A regular patch's box is as large as the patch, not as its B-spline control hull (which
/// reaches a whole span beyond it on every side, three spans across): the box holds the limit
/// surface, evaluated densely, and is no more than 1% of a span larger.
#[test]
fn regular_patch_boxes_hold_the_patch_and_hug_it() {
    let (n, half) = (8, 1.0);
    let span = 2.0 * half / n as f32;
    let s = dome(n, half);
    let mut g = GridSamples::default();
    let mut regular = 0;
    for p in 0..s.patch_count() {
        let b = s.patch_bounds(p);
        s.evaluate_grid(p, UvRect::UNIT, 17, false, &mut g);
        let mut real = Bounds3::EMPTY;
        for q in &g.p {
            real.grow(Vec3A::from(*q));
        }
        assert!(b.min.cmple(real.min + 1e-6).all() && b.max.cmpge(real.max - 1e-6).all(), "patch {p}: {b:?} misses {real:?}");
        if s.patch_param(p).kind == PatchKind::Regular {
            regular += 1;
            let excess = (b.diagonal() - real.diagonal()).max_element();
            assert!(excess <= 0.01 * span, "patch {p}: box {:?} exceeds the patch {:?} by {excess}", b.diagonal(), real.diagonal());
        }
    }
    assert_eq!(regular, n * n, "every face of a grid is one regular patch");
}

/// Camera rays test each subpatch at the rate its projected size calls for: a camera `d` above a
/// grid of spacing `h` looking straight down, with a pixel footprint `w` there (a 10° field of
/// view, so within 0.5% of `w` across the image), asks for h / w quads per side rounded up to
/// the next stored rate — one quad for a subpatch smaller than a pixel.
#[test]
fn camera_rays_test_each_subpatch_at_the_rate_of_its_projected_size() {
    let (d, width, half) = (10.0f32, 32usize, 1.5f32);
    // Horizontal aperture 10 mm at 50 mm focal length: 0.2 radians across `width` pixels.
    let w = d * (10.0 / 50.0) / width as f32;
    for (k, rate) in [(0.6f32, "1"), (1.5, "2"), (3.0, "4")] {
        // Spacing h = k·w: n faces over the grid's width.
        let n = (2.0 * half / (k * w)).round() as usize;
        let h = 2.0 * half / n as f32;
        assert!((h / w - k).abs() < 0.05, "grid of {n} faces: spacing {h}, {} pixels", h / w);
        let mut scene = Scene::default();
        let mesh = scene.add_mesh(Mesh::new("/dome", Arc::new(dome(n, half))));
        scene.add_instance(mesh, Mat4::IDENTITY);
        let mut camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, 0.0, d), Vec3::ZERO, Vec3::Y), 50.0);
        (camera.horizontal_aperture, camera.vertical_aperture, camera.clipping_range) = (10.0, 10.0, (0.1, 100.0));
        scene.camera = camera;
        let options = RenderOptions { width, height: width, threads: 2, aovs: vec![Aov::Color], ..Default::default() };
        let stats = render(&scene, &options, &NoProgress).unwrap().stats;
        let camera_tests = &stats["render"]["rate_tests_by_ray"]["camera"];
        let total: u64 = camera_tests.as_object().unwrap().values().map(|v| v.as_u64().unwrap()).sum();
        assert!(total >= (width * width) as u64, "{camera_tests}");
        assert_eq!(
            camera_tests[rate].as_u64(),
            Some(total),
            "subpatches {k} pixels wide: every camera test at {rate} quads, got {camera_tests}"
        );
    }
}
