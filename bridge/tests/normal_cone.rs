//! The normal cones OpenSubdiv's regular patches report (`LimitSurface::patch_normal_cone`),
//! which size displaced subpatch boxes, checked against the normals themselves: on OpenSubdiv's
//! regression shapes, every normal `dpdu × dpdv` evaluated on a 9×9 grid of each patch lies in
//! its patch's cone (up to sign), and a displaced point `p + n·d` with |d| ≤ 1 moves along each
//! axis by no more than the cone's `reach`.

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use glam::Vec3A;
use mipray::obj_shape::{corpus_dir, parse_obj_shape};
use mipray::patch::{GridSamples, LimitSurface, UvRect};
use mipray_bridge::OsdSurface;

const SHAPES: &[&str] = &["catmark_cube", "catmark_cube_creases1", "catmark_torus", "catmark_pawn", "catmark_rook", "catmark_pole8"];
const SIDE: usize = 9;

#[test]
fn regular_patches_normals_lie_in_their_cones() {
    let (mut coned, mut patches, mut samples) = (0, 0, 0);
    for name in SHAPES {
        let path = corpus_dir().join(format!("{name}.obj"));
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let shape = parse_obj_shape(name, &text).unwrap();
        let surface = OsdSurface::new(name, &shape.topology, &shape.points).unwrap();
        let mut grid = GridSamples::default();
        for patch in 0..surface.patch_count() {
            patches += 1;
            let Some(cone) = surface.patch_normal_cone(patch) else { continue };
            coned += 1;
            assert!((0.0..1.0).contains(&cone.sin_half_angle), "{name} patch {patch}: {cone:?}");
            let axis = cone.axis.normalize();
            let reach = cone.reach();
            surface.evaluate_grid(patch, UvRect::UNIT, SIDE, true, &mut grid);
            for k in 0..SIDE * SIDE {
                let n = Vec3A::from(grid.dpdu[k]).cross(Vec3A::from(grid.dpdv[k]));
                if n.length() <= 1e-6 * Vec3A::from(grid.dpdu[k]).length().max(1e-12) * Vec3A::from(grid.dpdv[k]).length() {
                    continue;
                }
                let n = n.normalize();
                samples += 1;
                // The sine of the angle between the normal and the cone's axis line, and the
                // normal on the axis's side.
                let sin = n.cross(axis).length();
                assert!(
                    sin <= cone.sin_half_angle + 1e-4,
                    "{name} patch {patch} sample {k}: normal {n:?} is {sin} (sine) from the axis {axis:?}, beyond {}",
                    cone.sin_half_angle
                );
                let moved = n.abs();
                assert!(moved.cmple(reach + 1e-4).all(), "{name} patch {patch}: |n| {moved:?} beyond reach {reach:?}");
            }
        }
    }
    // Most patches are regular: a cone for almost none would make this test (and the boxes) moot.
    assert!(coned * 2 > patches, "{coned} of {patches} patches have a cone");
    assert!(samples > 10_000, "{samples} normals checked");
}

/// A flat patch gets a cone of (almost) no width along the plane's normal, so a displaced flat
/// patch's box grows by the bound across the plane only.
#[test]
fn a_flat_patch_gets_a_thin_cone_along_its_normal() {
    use mipray::topology::{MeshTopology, Scheme};
    // A 6×6-vertex plane at z = 0.5: its middle faces are regular patches.
    let (w, points): (u32, Vec<[f32; 3]>) = (6, (0..36).map(|k| [(k % 6) as f32, (k / 6) as f32, 0.5]).collect());
    let mut indices = Vec::new();
    for j in 0..w - 1 {
        for i in 0..w - 1 {
            indices.extend([j * w + i, j * w + i + 1, (j + 1) * w + i + 1, (j + 1) * w + i].map(|x| x as i32));
        }
    }
    let topology =
        MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: vec![4; 25], face_vertex_indices: indices, ..Default::default() };
    let surface = OsdSurface::new("plane", &topology, &points).unwrap();
    let cones: Vec<_> = (0..surface.patch_count()).filter_map(|p| surface.patch_normal_cone(p)).collect();
    assert!(!cones.is_empty());
    for c in cones {
        assert!(c.sin_half_angle < 1e-3, "{c:?}");
        assert!((c.axis.z.abs() - 1.0).abs() < 1e-5, "{c:?}");
        let r = c.reach();
        assert!(r.x < 2e-3 && r.y < 2e-3 && r.z == 1.0, "{r:?}");
    }
}
