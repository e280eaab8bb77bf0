//! Instancers share a prototype's geometry (one core mesh, many placements), transform-only
//! updates rebuild nothing, and per-face materials colour exactly their faces.

mod common;

use glam::{Mat4, Vec3};
use hd_mipray::instancer::InstancerData;
use hd_mipray::material::{FaceMaterials, SurfaceInputs};
use hd_mipray::mesh::MeshData;
use hd_mipray::render_pass::PassResult;
use hd_mipray::{RenderDelegate, RenderPass, RenderSettings};
use mipray::aov::Aov;
use mipray::progress::NoProgress;
use mipray::topology::{MeshTopology, Scheme};

fn grey() -> SurfaceInputs {
    SurfaceInputs::lambertian("/grey", [0.5; 3])
}

fn red_faces(indices: Vec<i32>) -> FaceMaterials {
    FaceMaterials { materials: vec![SurfaceInputs::lambertian("/red", [1.0, 0.0, 0.0])], indices }
}

/// A subdivided cube of side 2 centred on the origin.
fn cube(transform: Mat4) -> MeshData {
    let (topology, points) = common::cube();
    MeshData { topology, points, transform, material: Some(grey()), ..Default::default() }
}

/// Two polygonal unit quads side by side in z = 0: face 0 on the left (x < 0), face 1 on the right.
fn two_quads() -> MeshData {
    let points = vec![[-1.0, -0.5, 0.0], [0.0, -0.5, 0.0], [1.0, -0.5, 0.0], [-1.0, 0.5, 0.0], [0.0, 0.5, 0.0], [1.0, 0.5, 0.0]];
    let topology = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4, 4],
        face_vertex_indices: vec![0, 1, 4, 3, 1, 2, 5, 4],
        ..Default::default()
    };
    MeshData { topology, points, material: Some(grey()), ..Default::default() }
}

fn delegate(eye: Vec3) -> RenderDelegate {
    common::delegate_with_camera(eye, Vec3::ZERO, false)
}

fn render(d: &mut RenderDelegate, aovs: &[&str]) -> PassResult {
    let pass = RenderPass {
        camera: "/cam".into(),
        width: 32,
        height: 32,
        aovs: aovs.iter().map(|s| Aov::from_name(s).unwrap()).collect(),
        settings: RenderSettings::default(),
    };
    pass.execute(d, &NoProgress).expect("render")
}

fn scene_figure(r: &PassResult, name: &str) -> u64 {
    r.stats["scene"][name].as_u64().unwrap_or(u64::MAX)
}

#[test]
fn instances_share_one_prototype_mesh() {
    let mut d = delegate(Vec3::new(0.0, 0.0, 40.0));
    let mut proto = cube(Mat4::from_scale(Vec3::splat(0.4)));
    proto.prototype = true;
    d.set_mesh("/proto", proto);
    let alone = render(&mut d, &["alpha"]);
    assert_eq!(scene_figure(&alone, "instances"), 0, "a prototype renders only where placed");
    assert!(alone.buffers[0].data.iter().all(|a| *a == 0.0));

    d.set_mesh("/single", cube(Mat4::IDENTITY));
    let one = render(&mut d, &["alpha"]);
    d.remove("/single");

    let n = 400;
    let transforms: Vec<Mat4> =
        (0..n).map(|i| Mat4::from_translation(Vec3::new((i % 20) as f32 - 9.5, (i / 20) as f32 - 9.5, 0.0))).collect();
    d.set_instancer("/pi", InstancerData::new("/pi", vec!["/proto".into()], &vec![0; n], transforms, false).expect("valid"));
    let many = render(&mut d, &["alpha"]);
    assert!(many.prim_errors.is_empty());
    assert_eq!(scene_figure(&many, "instances"), n as u64);
    assert_eq!(scene_figure(&many, "subpatches"), scene_figure(&one, "subpatches"), "one prototype's subpatches");
    assert_eq!(scene_figure(&many, "control_faces"), 6);
    let covered = many.buffers[0].data.iter().filter(|a| **a > 0.5).count();
    assert!(covered > 32 * 32 / 4, "the grid of instances covers the view ({covered} pixels)");
}

#[test]
fn nested_instancers_and_missing_prototypes() {
    let mut d = delegate(Vec3::new(0.0, 0.0, 20.0));
    let mut proto = cube(Mat4::IDENTITY);
    proto.prototype = true;
    d.set_mesh("/proto", proto);
    let pair = vec![Mat4::from_translation(Vec3::new(-1.5, 0.0, 0.0)), Mat4::from_translation(Vec3::new(1.5, 0.0, 0.0))];
    d.set_instancer("/grove", InstancerData::new("/grove", vec!["/proto".into()], &[0, 0], pair, true).expect("valid"));
    let rows = [Mat4::from_translation(Vec3::new(0.0, -3.0, 0.0)), Mat4::from_translation(Vec3::new(0.0, 3.0, 0.0))];
    d.set_instancer(
        "/forest",
        InstancerData::new("/forest", vec!["/grove".into(), "/nothing".into()], &[0, 0, 1], vec![rows[0], rows[1], Mat4::IDENTITY], false)
            .expect("valid"),
    );
    let r = render(&mut d, &["alpha"]);
    assert_eq!(scene_figure(&r, "instances"), 4);
    assert_eq!(r.prim_errors.len(), 1);
    assert!(r.prim_errors[0].to_string().starts_with("/forest: prototype /nothing"), "{}", r.prim_errors[0]);
}

#[test]
fn set_transform_moves_a_mesh_without_rebuilding_it() {
    let mut d = delegate(Vec3::new(0.0, 0.0, 8.0));
    d.set_mesh("/c", cube(Mat4::IDENTITY));
    let first = render(&mut d, &["alpha"]);
    assert_eq!(first.buffers[0].data[16 * 32 + 16], 1.0);
    d.set_transform("/c", Mat4::from_translation(Vec3::new(100.0, 0.0, 0.0))).expect("a mesh");
    let moved = render(&mut d, &["alpha"]);
    assert_eq!(moved.buffers[0].data[16 * 32 + 16], 0.0);
    assert_eq!(d.mesh("/c").map(|m| m.surface_syncs), Some(1));
    assert!(d.set_transform("/nope", Mat4::IDENTITY).is_err());
    let e = d.set_transform("/c", Mat4::from_translation(Vec3::splat(f32::INFINITY))).expect_err("not finite").to_string();
    assert_eq!(e, "/c: transform is not finite");
}

#[test]
fn face_materials_colour_exactly_their_faces() {
    let mut d = delegate(Vec3::new(0.0, 0.0, 4.0));
    let mut quads = two_quads();
    quads.face_materials = Some(red_faces(vec![-1, 0]));
    d.set_mesh("/q", quads.clone());
    let r = render(&mut d, &["color"]);
    let px = |x: usize| {
        let i = (16 * 32 + x) * 3;
        [r.buffers[0].data[i], r.buffers[0].data[i + 1], r.buffers[0].data[i + 2]]
    };
    let (left, right) = (px(10), px(22));
    assert!(left[0] > 0.0 && (left[0] - left[1]).abs() < 1e-6, "the left face keeps the mesh's grey: {left:?}");
    assert!(right[0] > 0.0 && right[1] == 0.0 && right[2] == 0.0, "the right face is red: {right:?}");

    quads.face_materials = Some(red_faces(vec![0, 1]));
    d.set_mesh("/q", quads);
    let bad = render(&mut d, &["color"]);
    assert_eq!(bad.prim_errors.len(), 1);
    assert_eq!(bad.prim_errors[0].to_string(), "/q: face_material_indices[1] = 1 is out of range for 1 face materials");
}
