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
