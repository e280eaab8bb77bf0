//! Tracing cases that once failed.

use std::sync::Arc;

use glam::{Mat4, Vec3A};
use mipray::differential::RayDifferential;
use mipray::geometry_cache::CacheConfig;
use mipray::prelude::*;
use mipray::ray::{Ray, RayKind};
use mipray::trace::{TraceCounters, Tracer};

fn quad(half: f32, z: f32) -> BilinearSurface {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let pts = [[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]];
    BilinearSurface::new(&topo, &pts).unwrap()
}

#[test]
fn negative_zero_direction_components_still_hit() {
    // obvhs misses every box for a direction with a −0.0 component unless it is canonicalised.
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/q", Arc::new(quad(1.0, 1.0))));
    scene.add_instance(m, Mat4::IDENTITY);
    let floor = scene.add_mesh(Mesh::new("/floor", Arc::new(quad(10.0, 0.0))));
    scene.add_instance(floor, Mat4::IDENTITY);
    let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    let mut c = TraceCounters::default();
    for d in [Vec3A::new(-0.70710677, -0.0, 0.70710677), Vec3A::new(-0.0, -0.0, 1.0), Vec3A::new(0.0, -0.0, 1.0)] {
        let r = Ray {
            o: Vec3A::new(0.5, 0.05, 1e-4),
            d,
            t_min: 0.0,
            t_max: f32::INFINITY,
            diff: RayDifferential::default(),
            kind: RayKind::Shadow,
            time: 0.0,
        };
        assert!(tracer.occluded(&r, &mut c), "{d:?}");
        assert!(tracer.intersect(&r, &mut c).is_some(), "{d:?}");
    }
}

#[test]
fn left_handed_orientation_flips_the_geometric_normal() {
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/q", Arc::new(quad(1.0, 0.0))));
    scene.add_instance(m, Mat4::IDENTITY);
    let ray = Ray {
        o: Vec3A::new(0.2, 0.1, 3.0),
        d: Vec3A::NEG_Z,
        t_min: 0.0,
        t_max: f32::INFINITY,
        diff: RayDifferential::default(),
        kind: RayKind::Camera,
        time: 0.0,
    };
    let ng = |scene: &Scene| Tracer::new(scene, CacheConfig::unbounded(), 1.0).intersect(&ray, &mut TraceCounters::default()).unwrap().ng;
    assert!(ng(&scene).z > 0.99, "counter-clockwise faces +z");
    scene.meshes[0].left_handed = true;
    assert!(ng(&scene).z < -0.99, "leftHanded: the same winding faces −z");
}

fn camera_ray(o: Vec3A, d: Vec3A) -> Ray {
    Ray { o, d, t_min: 0.0, t_max: f32::INFINITY, diff: RayDifferential::default(), kind: RayKind::Camera, time: 0.0 }
}

#[test]
fn a_ray_through_an_edge_two_polygons_share_hits_one_of_them() {
    // Two quads of one polygonal mesh meeting at y = 0 (issue 16: the centre row of a camera
    // centred on the edge missed both).
    let topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4, 4],
        face_vertex_indices: vec![0, 1, 4, 3, 1, 2, 5, 4],
        ..Default::default()
    };
    let pts = [[-1.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [-1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/plane", Arc::new(BilinearSurface::new(&topo, &pts).unwrap())));
    scene.add_instance(m, Mat4::IDENTITY);
    let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    let mut c = TraceCounters::default();
    for x in [-0.75f32, -0.3, 0.0, 0.1, 0.5, 0.9] {
        // Straight down, and slanted along the edge (a camera's centre row).
        for d in [Vec3A::NEG_Z, Vec3A::new(x * 0.1, 0.0, -1.0).normalize(), Vec3A::new(-x * 0.1, -0.0, -1.0).normalize()] {
            let r = camera_ray(Vec3A::new(x - 5.0 * d.x / -d.z, 0.0, 5.0), d);
            let h = tracer.intersect(&r, &mut c).unwrap_or_else(|| panic!("ray through the shared edge at x = {x}, d = {d} missed"));
            assert!((h.p.z).abs() < 1e-5 && (h.p.y).abs() < 1e-5, "{:?}", h.p);
        }
    }
}

fn unit_quad_scene(transform: Mat4) -> Scene {
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/q", Arc::new(quad(1.0, 0.0))));
    scene.add_instance(m, transform);
    scene
}

#[test]
fn degenerate_instance_transforms_are_dropped_by_name_or_flattened() {
    let down = camera_ray(Vec3A::new(0.2, 0.1, 3.0), Vec3A::NEG_Z);
    let mut c = TraceCounters::default();
    // Scaled to nothing, to a line, to 1e-30 and by 1e20, projective: left out, named.
    let mut projective = Mat4::IDENTITY;
    projective.x_axis.w = 0.25;
    for m in [
        Mat4::from_scale(glam::Vec3::ZERO),
        Mat4::from_scale(glam::Vec3::new(1.0, 0.0, 0.0)),
        Mat4::from_scale(glam::Vec3::splat(1e-30)),
        Mat4::from_scale(glam::Vec3::splat(1e20)),
        projective,
    ] {
        let scene = unit_quad_scene(m);
        let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
        assert!(tracer.intersect(&down, &mut c).is_none());
        let dropped = tracer.dropped.list();
        assert_eq!(dropped.len(), 1, "{m}");
        assert!(dropped[0].to_string().starts_with("/q: transform "), "{}", dropped[0]);
        assert!(!dropped[0].internal);
    }
    // Scaled to zero along its normal (already flat) or across it: still the flat quad it is.
    let flat = unit_quad_scene(Mat4::from_scale(glam::Vec3::new(1.0, 1.0, 0.0)));
    let tracer = Tracer::new(&flat, CacheConfig::unbounded(), 1.0);
    let h = tracer.intersect(&down, &mut c).expect("a quad flattened along its normal is still there");
    assert!((h.t - 3.0).abs() < 1e-4 && h.ng.z > 0.99, "{h:?}");
    assert!(tracer.dropped.list().is_empty());
    // Stood on its edge (rotated 90° about x) and flattened along y: a zero-width sliver, seen
    // edge-on from above, and whole from the side.
    let sliver = unit_quad_scene(Mat4::from_scale(glam::Vec3::new(1.0, 0.0, 1.0)) * Mat4::from_rotation_x(1.0));
    let tracer = Tracer::new(&sliver, CacheConfig::unbounded(), 1.0);
    let side = camera_ray(Vec3A::new(0.2, -3.0, 0.1), Vec3A::Y);
    let h = tracer.intersect(&side, &mut c).expect("seen from the side");
    assert!((h.p.y).abs() < 1e-4 && h.ng.y.abs() > 0.99, "{h:?}");
}

#[test]
fn meshes_beyond_the_traceable_range_are_dropped_by_name() {
    let mut c = TraceCounters::default();
    for far in [1e30f32, 3e38, f32::MAX] {
        let topo = MeshTopology {
            scheme: Scheme::None,
            face_vertex_counts: vec![4, 4],
            face_vertex_indices: vec![0, 1, 2, 3, 4, 5, 6, 7],
            ..Default::default()
        };
        let pts = [
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [far, 0.0, 1.0],
            [far, far, 1.0],
            [0.0, far, 1.0],
        ];
        let mut scene = Scene::default();
        let m = scene.add_mesh(Mesh::new("/far", Arc::new(BilinearSurface::new(&topo, &pts).unwrap())));
        scene.add_instance(m, Mat4::IDENTITY);
        let ok = scene.add_mesh(Mesh::new("/near", Arc::new(quad(1.0, -1.0))));
        scene.add_instance(ok, Mat4::IDENTITY);
        let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
        let h = tracer.intersect(&camera_ray(Vec3A::new(0.2, 0.1, 3.0), Vec3A::NEG_Z), &mut c).expect("the other mesh renders");
        assert_eq!(h.mesh, ok as u32);
        let dropped = tracer.dropped.list();
        assert_eq!(dropped.len(), 1);
        assert!(dropped[0].to_string().starts_with("/far: patch 1 reaches"), "{}", dropped[0]);
    }
}

/// A surface whose evaluation panics (a stand-in for a bug in one prim's tessellation).
struct PanickingSurface(BilinearSurface);

impl LimitSurface for PanickingSurface {
    fn patch_count(&self) -> usize {
        self.0.patch_count()
    }
    fn patch_param(&self, patch: usize) -> PatchParam {
        self.0.patch_param(patch)
    }
    fn patch_bounds(&self, patch: usize) -> mipray::bounds::Bounds3 {
        self.0.patch_bounds(patch)
    }
    fn evaluate(&self, _patch: usize, _u: f32, _v: f32) -> SurfacePoint {
        panic!("evaluation failed on purpose")
    }
    fn control_face_count(&self) -> usize {
        self.0.control_face_count()
    }
}

#[test]
fn a_panic_in_one_prims_tessellation_drops_that_prim_only() {
    let mut scene = Scene::default();
    let bad = scene.add_mesh(Mesh::new("/bad", Arc::new(PanickingSurface(quad(1.0, 1.0)))));
    scene.add_instance(bad, Mat4::IDENTITY);
    let good = scene.add_mesh(Mesh::new("/good", Arc::new(quad(2.0, 0.0))));
    scene.add_instance(good, Mat4::IDENTITY);
    let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    let mut c = TraceCounters::default();
    let r = camera_ray(Vec3A::new(0.2, 0.1, 3.0), Vec3A::NEG_Z);
    for _ in 0..3 {
        let h = tracer.intersect(&r, &mut c).expect("the good prim is hit");
        assert_eq!(h.mesh, good as u32);
    }
    let dropped = tracer.dropped.list();
    assert_eq!(dropped.len(), 1);
    assert!(dropped[0].internal);
    assert_eq!(dropped[0].to_string(), "/bad: internal error, prim dropped: evaluation failed on purpose");
}
