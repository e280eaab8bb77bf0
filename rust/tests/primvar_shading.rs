//! Authored normals and primvar-fed material inputs, interpolated over the surface: the
//! `normal` and `albedo` AOVs at each pixel against the closed-form interpolation.

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::material::{Input, Material, PrimvarInput};
use mipray::prelude::*;
use mipray::texture::{Interpolation, Primvar2};

const WIDTH: usize = 32;

/// The quad [-1, 1]² at z = 0 filling an orthographic view from +z, with `primvars` as its
/// channels; returns the scene and each pixel centre's x on the quad.
fn quad_scene(primvars: &[Primvar2], normals: Option<[usize; 2]>, material: Material) -> Scene {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let pts = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]];
    let surface = BilinearSurface::new(&topo, &pts).unwrap().with_primvars(&topo, 4, primvars).unwrap();
    let mut scene = Scene::default();
    let m = scene.add_material(material);
    let mut mesh = Mesh::new("/quad", Arc::new(surface));
    mesh.material = m;
    mesh.normals = normals;
    let i = scene.add_mesh(mesh);
    scene.add_instance(i, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", Vec3A::NEG_Z, Vec3A::splat(std::f32::consts::PI)));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 20.0, 20.0);
    scene
}

/// The quad's x at pixel column `col` (pixel centres).
fn x_of(col: usize) -> f32 {
    (col as f32 + 0.5) / WIDTH as f32 * 2.0 - 1.0
}

fn render_aov(scene: &Scene, aov: &str) -> Vec<f32> {
    let options =
        RenderOptions { width: WIDTH, height: WIDTH, aovs: vec![mipray::aov::Aov::from_name(aov).unwrap()], ..Default::default() };
    render(scene, &options, &NoProgress).unwrap().film.aov(aov).unwrap().data.clone()
}

/// Normals leaning out along x, (x, 0, 1) at the quad's left and right edges, as two channels.
fn leaning_normals(interpolation: Interpolation) -> Vec<Primvar2> {
    let n = [[-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]];
    Primvar2::split("normals", interpolation, &n, 3, &[])
}

#[test]
fn authored_normals_are_interpolated_for_shading() {
    for interpolation in [Interpolation::Vertex, Interpolation::Varying, Interpolation::FaceVarying] {
        let scene = quad_scene(&leaning_normals(interpolation), Some([0, 1]), Material::default());
        let n = render_aov(&scene, "normal");
        for row in [3, WIDTH / 2, WIDTH - 2] {
            for col in 0..WIDTH {
                let got = Vec3::from_slice(&n[(row * WIDTH + col) * 3..][..3]);
                // Linear between (-1, 0, 1) and (1, 0, 1): (x, 0, 1), normalized.
                let want = Vec3::new(x_of(col), 0.0, 1.0).normalize();
                assert!((got - want).length() < 2e-3, "{interpolation:?} ({row}, {col}): {got} vs {want}");
            }
        }
    }
}

#[test]
fn without_authored_normals_the_quad_shades_flat() {
    // The same channels present but not named as normals: the limit surface's normal.
    let scene = quad_scene(&leaning_normals(Interpolation::Vertex), None, Material::default());
    let n = render_aov(&scene, "normal");
    let left = Vec3::from_slice(&n[(WIDTH / 2 * WIDTH) * 3..][..3]);
    assert!((left - Vec3::Z).length() < 1e-5, "{left}");
}

#[test]
fn a_face_varying_colour_feeds_the_diffuse_colour_where_it_is_hit() {
    // Red rises from 0 to 1 along x, blue falls; green 0.25 (a channel's second lane).
    let c = [[0.0, 0.25, 1.0], [1.0, 0.25, 0.0], [1.0, 0.25, 0.0], [0.0, 0.25, 1.0]];
    // Indexed face-varying values: corner k reads value k.
    let channels = Primvar2::split("displayColor", Interpolation::FaceVarying, &c, 3, &[0, 1, 2, 3]);
    let mut material = Material::lambertian("/quad", Vec3A::splat(0.5)).0;
    material.primvars.push((Input::DiffuseColor, PrimvarInput { channels: [0, 1] }));
    let scene = quad_scene(&channels, None, material);
    let albedo = render_aov(&scene, "albedo");
    for row in [2, WIDTH / 2] {
        for col in 0..WIDTH {
            let got = Vec3::from_slice(&albedo[(row * WIDTH + col) * 3..][..3]);
            let s = (x_of(col) + 1.0) / 2.0;
            let want = Vec3::new(s, 0.25, 1.0 - s);
            assert!((got - want).length() < 1e-3, "({row}, {col}): {got} vs {want}");
        }
    }
}

#[test]
fn a_float_primvar_feeds_a_float_input() {
    // Opacity under a threshold cuts the quad out where the primvar is below it: x < 0.
    let o = [[0.0; 3], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0; 3]];
    let channels = Primvar2::split("opacity", Interpolation::Vertex, &o, 1, &[]);
    let mut material = Material::lambertian("/quad", Vec3A::splat(0.5)).0;
    material.surface.opacity_threshold = 0.5;
    material.primvars.push((Input::Opacity, PrimvarInput { channels: [0, 0] }));
    let scene = quad_scene(&channels, None, material);
    let alpha = render_aov(&scene, "alpha");
    let row = WIDTH / 2;
    for col in 0..WIDTH {
        let want = if x_of(col) > 0.0 { 1.0 } else { 0.0 };
        assert_eq!(alpha[row * WIDTH + col], want, "column {col}");
    }
}
