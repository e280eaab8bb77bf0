//! Displacement at tessellation time: the surface moves, bounds hold it, shading follows it, and
//! a bound that is too small is counted rather than clipped.

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::displacement::Displacement;
use mipray::prelude::*;

fn plane(half: f32, n: i32) -> BilinearSurface {
    let (topo, pts) = mipray::bilinear::grid_mesh(half, n, 0.0);
    BilinearSurface::new(&topo, &pts).unwrap()
}

fn scene(displacement: Option<Displacement>, bound: f32) -> Scene {
    let mut scene = Scene::default();
    let mut mesh = Mesh::new("/ground", Arc::new(plane(2.0, 8)));
    mesh.displacement = displacement.map(Into::into);
    mesh.displacement_bound = bound;
    let m = scene.add_mesh(mesh);
    scene.add_instance(m, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.4, 0.3, -1.0), Vec3A::ONE));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 30.0, 30.0);
    scene
}

#[test]
fn displaced_surface_moves_within_its_bound_and_shades_by_its_own_normal() {
    let d = Displacement { amplitude: 0.1, frequency: 1.5, octaves: 4, gain: 0.5 };
    let flat = render(
        &scene(None, 0.0),
        &RenderOptions { width: 32, height: 32, aovs: vec!["color".into(), "depth".into(), "normal".into()], ..Default::default() },
        &NoProgress,
    )
    .unwrap();
    let opts = RenderOptions { width: 32, height: 32, aovs: vec!["color".into(), "depth".into(), "normal".into()], ..Default::default() };
    let bumpy = render(&scene(Some(d), d.bound()), &opts, &NoProgress).unwrap();
    let depth = &bumpy.film.aov("depth").unwrap().data;
    let moved = depth.iter().filter(|z| (**z - 5.0).abs() > 1e-3).count();
    assert!(moved > depth.len() / 2, "most of the surface moved: {moved}");
    assert!(depth.iter().all(|z| (*z - 5.0).abs() <= d.bound() + 1e-4), "within the bound");
    let normals = &bumpy.film.aov("normal").unwrap().data;
    let tilted = normals.chunks(3).filter(|n| n[2] < 0.999).count();
    assert!(tilted > depth.len() / 2, "shading normals follow the displaced surface: {tilted}");
    assert_ne!(flat.film.aov("color").unwrap().data, bumpy.film.aov("color").unwrap().data);
    assert_eq!(bumpy.stats["scene"]["displaced_vertices_outside_bounds"].as_u64(), Some(0));
}

#[test]
fn a_bound_too_small_is_counted_not_clipped() {
    let d = Displacement { amplitude: 0.2, frequency: 1.5, octaves: 3, gain: 0.5 };
    let out = render(
        &scene(Some(d), 0.01),
        &RenderOptions { width: 16, height: 16, aovs: vec!["depth".into()], ..Default::default() },
        &NoProgress,
    )
    .unwrap();
    assert!(out.stats["scene"]["displaced_vertices_outside_bounds"].as_u64().unwrap() > 0);
}
