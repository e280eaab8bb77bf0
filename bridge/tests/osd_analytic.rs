//! OpenSubdiv patches against answers known in closed form, and bad input that must come back as
//! an `Err` naming the mesh (never an abort).
//!
//! Tolerances: positions and plane distances 1e-5 · the control mesh's bounding-box diagonal;
//! normals 1e-4 rad; bilinear patches exact to 1e-6.

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use glam::Vec3A;
use mipray::error::MeshError;
use mipray::patch::{GridSamples, LimitSurface, PatchKind, UvRect};
use mipray::topology::{BoundaryInterpolation, MeshTopology, Scheme};
use mipray_bridge::{limit_reference, OsdOptions, OsdSurface};

/// An n×n grid of quads (or of triangle pairs) on the plane z = 0.3x − 0.2y + 1.
fn plane_grid(n: usize, scheme: Scheme) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut points = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32 * 4.0 - 2.0, j as f32 / n as f32 * 3.0 - 1.0);
            points.push([x, y, plane_z(x, y)]);
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as i32;
    let mut counts = Vec::new();
    let mut indices = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if scheme == Scheme::Loop {
                counts.extend([3, 3]);
                indices.extend([a, b, c, a, c, d]);
            } else {
                counts.push(4);
                indices.extend([a, b, c, d]);
            }
        }
    }
    let topology = MeshTopology {
        scheme,
        face_vertex_counts: counts,
        face_vertex_indices: indices,
        boundary: BoundaryInterpolation::EdgeAndCorner,
        ..Default::default()
    };
    (topology, points)
}

fn plane_z(x: f32, y: f32) -> f32 {
    0.3 * x - 0.2 * y + 1.0
}

fn plane_normal() -> Vec3A {
    Vec3A::new(-0.3, 0.2, 1.0).normalize()
}

#[test]
fn flat_grids_evaluate_onto_their_plane() {
    for scheme in [Scheme::CatmullClark, Scheme::Loop, Scheme::Bilinear] {
        let (topology, points) = plane_grid(5, scheme);
        let surface = OsdSurface::new("/plane", &topology, &points).unwrap();
        let diag = 5.0f32; // |(4, 3, …)| of the grid's extent in x and y
        let (mut max_dist, mut max_angle) = (0.0f32, 0.0f32);
        let mut grid = GridSamples::default();
        for patch in 0..surface.patch_count() {
            let tri = surface.patch_param(patch).kind.is_triangle();
            surface.evaluate_grid(patch, UvRect::UNIT, 9, true, &mut grid);
            for (k, p) in grid.p.iter().enumerate() {
                let (u, v) = UvRect::UNIT.grid_uv(k % 9, k / 9, 9);
                if tri && u + v > 1.0 + 1e-6 {
                    continue;
                }
                max_dist = max_dist.max((p[2] - plane_z(p[0], p[1])).abs());
                let s = surface.evaluate(patch, u, v);
                let c = s.dpdu.cross(s.dpdv);
                // Skip where the tangents are nearly parallel (patch corners at extraordinary
                // vertices): the normal is ill-conditioned there, not wrong.
                if c.length() > 1e-2 * s.dpdu.length() * s.dpdv.length() {
                    max_angle = max_angle.max(c.normalize().cross(plane_normal()).length().asin());
                }
                // Second derivatives of a planar surface lie in the plane.
                for d2 in [s.dpduu, s.dpduv, s.dpdvv] {
                    max_dist = max_dist.max(d2.dot(plane_normal()).abs() * 1e-3);
                }
            }
        }
        println!("{scheme:?}: {} patches, max plane distance {max_dist:.1e}, max normal angle {max_angle:.1e} rad", surface.patch_count());
        assert!(max_dist <= 1e-5 * diag, "{scheme:?}: distance {max_dist} from the plane");
        assert!(max_angle <= 1e-4, "{scheme:?}: normal off by {max_angle} rad");
        assert!(n_control_faces_ok(&surface, &topology));
    }
}

fn n_control_faces_ok(surface: &OsdSurface, topology: &MeshTopology) -> bool {
    surface.control_face_count() == topology.face_count()
}

#[test]
fn bilinear_quad_is_bilinear_interpolation() {
    let points = [[0.0, 0.0, 0.0], [2.0, 0.0, 1.0], [2.5, 1.5, 0.0], [0.0, 1.0, -1.0]];
    let topology =
        MeshTopology { scheme: Scheme::Bilinear, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let s = OsdSurface::new("/quad", &topology, &points).unwrap();
    assert_eq!(s.patch_count(), 1);
    assert_eq!(s.patch_param(0).kind, PatchKind::Bilinear);
    let p = points.map(Vec3A::from);
    for &(u, v) in &[(0.0, 0.0), (0.25, 0.75), (0.5, 0.5), (1.0, 0.3)] {
        let e = s.evaluate(0, u, v);
        let want = p[0] * (1.0 - u) * (1.0 - v) + p[1] * u * (1.0 - v) + p[2] * u * v + p[3] * (1.0 - u) * v;
        let dpdu = (p[1] - p[0]) * (1.0 - v) + (p[2] - p[3]) * v;
        let dpdv = (p[3] - p[0]) * (1.0 - u) + (p[2] - p[1]) * u;
        assert!((e.p - want).length() < 1e-6, "p at ({u}, {v}): {:?} vs {want:?}", e.p);
        assert!((e.dpdu - dpdu).length() < 1e-6 && (e.dpdv - dpdv).length() < 1e-6);
        assert!((e.dpduv - (p[0] - p[1] + p[2] - p[3])).length() < 1e-6);
        assert!(e.dpduu.length() < 1e-6 && e.dpdvv.length() < 1e-6);
    }
    let b = s.patch_bounds(0);
    assert_eq!(b.min, Vec3A::new(0.0, 0.0, -1.0));
    assert_eq!(b.max, Vec3A::new(2.5, 1.5, 1.0));
}

#[test]
fn limit_at_finds_the_patches_and_holes_have_none() {
    let (mut topology, points) = plane_grid(4, Scheme::CatmullClark);
    topology.hole_indices = vec![5];
    let s = OsdSurface::new("/holey", &topology, &points).unwrap();
    assert_eq!(s.ptex_face_count(), 16);
    assert!(s.limit_at(5, 0.5, 0.5).is_none(), "a hole has no surface");
    assert!(s.limit_at(99, 0.5, 0.5).is_none());
    assert!(s.limit_at(6, 1.5, 0.5).is_none() && s.limit_at(6, f32::NAN, 0.5).is_none());
    assert!((0..s.patch_count()).all(|p| s.patch_param(p).base_face != 5));
    // limit_at agrees with evaluate through the patch's own parameterization, and its
    // derivatives are per ptex face: on this flat grid, a face is 1 × 0.75 units.
    let l = s.limit_at(6, 0.3, 0.6).unwrap();
    let (patch, u, v) = s.find_patch(6, 0.3, 0.6).unwrap();
    let e = s.evaluate(patch, u, v);
    assert!((l.p - e.p).length() < 1e-6);
    assert!((l.dpdu.x - 1.0).abs() < 1e-4 && (l.dpdv.y - 0.75).abs() < 1e-4, "{l:?}");
    let pp = s.patch_param(patch);
    let (fu, fv) = pp.to_face_uv(u, v);
    assert!((fu - 0.3).abs() < 1e-6 && (fv - 0.6).abs() < 1e-6);
}

#[test]
fn animated_points_update_without_rebuilding() {
    let (topology, points) = plane_grid(3, Scheme::CatmullClark);
    let mut s = OsdSurface::new("/anim", &topology, &points).unwrap();
    let before = s.evaluate(4, 0.5, 0.5);
    let bounds_before = s.patch_bounds(4);
    let shifted: Vec<[f32; 3]> = points.iter().map(|p| [p[0] + 1.0, p[1], p[2] + 2.0]).collect();
    s.update_points(&shifted).unwrap();
    let after = s.evaluate(4, 0.5, 0.5);
    // Affine invariance: translating the control points translates the surface.
    assert!((after.p - before.p - Vec3A::new(1.0, 0.0, 2.0)).length() < 1e-5);
    assert!((after.dpdu - before.dpdu).length() < 1e-5);
    let shift = Vec3A::new(1.0, 0.0, 2.0);
    let b = s.patch_bounds(4);
    assert!((b.min - bounds_before.min - shift).length() < 1e-5 && (b.max - bounds_before.max - shift).length() < 1e-5);
    // Bad updates leave the surface as it was.
    let err = s.update_points(&shifted[1..]).unwrap_err();
    assert!(matches!(err, MeshError::Invalid(_)) && err.to_string().contains("/anim"), "{err}");
    let mut nan = shifted.clone();
    nan[3][1] = f32::NAN;
    let err = s.update_points(&nan).unwrap_err();
    assert!(matches!(err, MeshError::NonFinite(_)) && err.to_string().contains("point 3"), "{err}");
    assert_eq!(s.evaluate(4, 0.5, 0.5), after);
}

#[test]
fn uniform_refinement_matches_catmull_clark_counts() {
    let (topology, points) = plane_grid(2, Scheme::CatmullClark);
    let s = OsdSurface::new("/uniform", &topology, &points).unwrap();
    let (pts, faces) = s.uniform_refinement(2).unwrap();
    assert_eq!(faces.len(), 4 * 16);
    assert_eq!(pts.len(), 9 * 9);
    assert!(faces.iter().all(|f| f.len() == 4 && f.iter().all(|&i| (i as usize) < pts.len())));
    assert!(pts.iter().all(|p| (p[2] - plane_z(p[0], p[1])).abs() < 1e-5));
    let (pts0, faces0) = s.uniform_refinement(0).unwrap();
    assert_eq!((pts0.len(), faces0.len()), (9, 4));
    assert!(s.uniform_refinement(11).is_err());
}

#[test]
fn surfaces_are_shared_between_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<OsdSurface>();
    let (topology, points) = plane_grid(4, Scheme::CatmullClark);
    let s = std::sync::Arc::new(OsdSurface::new("/shared", &topology, &points).unwrap());
    let expected: Vec<_> = (0..s.patch_count()).map(|p| s.evaluate(p, 0.25, 0.5)).collect();
    let handles: Vec<_> = (0..4)
        .map(|_| {
            let s = s.clone();
            std::thread::spawn(move || (0..s.patch_count()).map(|p| s.evaluate(p, 0.25, 0.5)).collect::<Vec<_>>())
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), expected);
    }
}

fn quad_mesh() -> (MeshTopology, Vec<[f32; 3]>) {
    let topology = MeshTopology {
        scheme: Scheme::CatmullClark,
        face_vertex_counts: vec![4, 4],
        face_vertex_indices: vec![0, 1, 4, 3, 1, 2, 5, 4],
        ..Default::default()
    };
    let points = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0]];
    (topology, points)
}

/// Each case: what is wrong, the mesh, and what the error must say.
#[test]
fn bad_meshes_are_refused_with_the_mesh_named() {
    type Case = (&'static str, Box<dyn Fn(&mut MeshTopology, &mut Vec<[f32; 3]>)>, &'static str);
    let cases: Vec<Case> = vec![
        ("index out of range", Box::new(|t, _| t.face_vertex_indices[2] = 17), "faceVertexIndices[2] = 17"),
        ("negative index", Box::new(|t, _| t.face_vertex_indices[0] = -1), "faceVertexIndices[0] = -1"),
        ("counts disagree", Box::new(|t, _| t.face_vertex_counts[1] = 5), "faceVertexCounts"),
        ("NaN point", Box::new(|_, p| p[2][1] = f32::NAN), "point 2"),
        ("infinite point", Box::new(|_, p| p[5][0] = f32::INFINITY), "point 5"),
        ("Loop with a quad", Box::new(|t, _| t.scheme = Scheme::Loop), "Loop scheme needs triangles"),
        ("hole out of range", Box::new(|t, _| t.hole_indices = vec![2]), "holeIndices"),
        (
            "crease vertex out of range",
            Box::new(|t, _| {
                t.crease_indices = vec![0, 9];
                t.crease_lengths = vec![2];
                t.crease_sharpnesses = vec![1.0];
            }),
            "creaseIndices",
        ),
        (
            "no faces",
            Box::new(|t, _| {
                t.face_vertex_counts.clear();
                t.face_vertex_indices.clear();
            }),
            "no faces",
        ),
    ];
    for (what, mutate, expect) in cases {
        let (mut t, mut p) = quad_mesh();
        mutate(&mut t, &mut p);
        let err = OsdSurface::new("/World/bad_mesh", &t, &p).expect_err(what).to_string();
        println!("{what:28} -> {err}");
        assert!(err.contains("/World/bad_mesh"), "{what}: the mesh is not named: {err}");
        assert!(err.contains(expect), "{what}: expected '{expect}' in: {err}");
    }
    let (t, p) = quad_mesh();
    let err = OsdSurface::with_options("/World/bad_mesh", &t, &p, &OsdOptions { isolation_level: 0, secondary_level: 0 })
        .expect_err("isolation 0")
        .to_string();
    assert!(err.contains("/World/bad_mesh") && err.contains("isolation"), "{err}");
}

/// Topology that passes validation but that OpenSubdiv itself finds wrong: it must answer with
/// an error or with warnings, never abort the process.
#[test]
fn topology_opensubdiv_dislikes_does_not_abort() {
    // A crease along a pair of vertices that share no edge, and a face using a vertex twice.
    let (mut t, p) = quad_mesh();
    t.crease_indices = vec![0, 5];
    t.crease_lengths = vec![2];
    t.crease_sharpnesses = vec![2.0];
    match OsdSurface::new("/odd_crease", &t, &p) {
        Ok(s) => println!("odd crease: ok, warnings: {:?}", s.warnings()),
        Err(e) => {
            println!("odd crease: {e}");
            assert!(e.to_string().contains("/odd_crease"));
        }
    }
    let degenerate_faces: [(&str, Vec<i32>); 4] = [
        ("/repeated_vertex", vec![0, 1, 1, 3, 1, 2, 5, 4]),
        ("/one_vertex_face", vec![0, 0, 0, 0, 1, 2, 5, 4]),
        ("/two_vertex_face", vec![0, 1, 0, 1, 1, 2, 5, 4]),
        ("/same_face_twice", vec![0, 1, 4, 3, 0, 1, 4, 3]),
    ];
    for (name, indices) in degenerate_faces {
        let (mut t, p) = quad_mesh();
        t.face_vertex_indices = indices;
        match OsdSurface::new(name, &t, &p) {
            Ok(s) => {
                // Whatever OpenSubdiv made of it must evaluate without trouble.
                let bad = (0..s.patch_count()).filter(|&k| !s.evaluate(k, 0.5, 0.5).p.is_finite()).count();
                println!("{name}: ok, {} patches ({bad} non-finite at the centre), warnings: {:?}", s.patch_count(), s.warnings());
            }
            Err(e) => {
                println!("{name}: {e}");
                assert!(e.to_string().contains(name));
            }
        }
    }
}

/// A disk of `n` quads around one vertex of valence `n`, slightly domed.
fn quad_pole(n: usize) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut pts = vec![[0.0, 0.0, 0.3]];
    for i in 0..n {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        pts.push([a.cos(), a.sin(), 0.1]);
        let b = std::f32::consts::TAU * (i as f32 + 0.5) / n as f32;
        pts.push([1.4 * b.cos(), 1.4 * b.sin(), 0.0]);
    }
    let r = |i: usize| (1 + 2 * (i % n)) as i32;
    let q = |i: usize| (2 + 2 * (i % n)) as i32;
    let idx: Vec<i32> = (0..n).flat_map(|i| [0, r(i), q(i), r(i + 1)]).collect();
    (MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: vec![4; n], face_vertex_indices: idx, ..Default::default() }, pts)
}

/// Issue 15: OpenSubdiv's own evaluation (`limit_reference`, the truth of the subdivision
/// comparisons) at a pole of valence 360, where the limit stencils it replaced took minutes. At
/// the pole every face's corner is the pole's limit point, which Catmull-Clark's limit mask gives
/// in closed form: (n²·c + 4·Σ ring + Σ diagonals) / (n(n + 5)) for an interior vertex c of
/// valence n. The disk is symmetric about the z axis, so the normal there is ±z.
#[test]
fn the_reference_at_a_pole_of_valence_360_is_the_limit_mask_s_point() {
    let n = 360;
    let (t, p) = quad_pole(n);
    let c = |i: usize| glam::DVec3::from(p[i].map(f64::from));
    let ring: glam::DVec3 = (0..n).map(|i| c(1 + 2 * i)).sum();
    let diagonals: glam::DVec3 = (0..n).map(|i| c(2 + 2 * i)).sum();
    let nf = n as f64;
    let limit = (nf * nf * c(0) + 4.0 * ring + diagonals) / (nf * (nf + 5.0));
    let corners: Vec<(u32, f32, f32)> = (0..n as u32).map(|f| (f, 0.0, 0.0)).collect();
    let reference = limit_reference("/pole", &t, &p, &OsdOptions::DEFAULT, &corners).unwrap();
    for (f, r) in reference.iter().enumerate() {
        let off = (r.p.as_dvec3() - limit).length();
        assert!(off < 1e-6, "face {f}: {} is {off:e} from the limit point {limit}", r.p);
        let normal = r.dpdu.cross(r.dpdv).normalize();
        assert!(normal.z.abs() > 1.0 - 1e-6, "face {f}: normal {normal} at the pole");
    }
}

/// Issue 15: a vertex of high valence costs memory in proportion to its patches. OpenSubdiv's
/// factorized stencils (kept to update points) and its end-cap stencils grow with the square of
/// the valence; the surface keeps neither, so its bytes per patch at valence 512 stay within
/// twice those at valence 8. New points are refined again through the end caps: a surface
/// updated to scaled points evaluates, on the Gregory patches around the pole too, as one built
/// from them.
#[test]
fn a_high_valence_pole_holds_memory_in_proportion_to_its_patches_and_updates_as_rebuilt() {
    let per_patch = |n: usize| {
        let (t, p) = quad_pole(n);
        let s = OsdSurface::new("/pole", &t, &p).unwrap();
        let bytes: usize = s.memory().unwrap().iter().map(|(_, b)| b).sum();
        bytes as f64 / s.patch_count() as f64
    };
    let (low, high) = (per_patch(8), per_patch(512));
    assert!(high <= 2.0 * low, "bytes per patch: {low:.0} at valence 8, {high:.0} at valence 512");

    let (t, p) = quad_pole(64);
    let mut s = OsdSurface::new("/pole", &t, &p).unwrap();
    let scaled: Vec<[f32; 3]> = p.iter().map(|q| [2.0 * q[0], 2.0 * q[1], 2.0 * q[2]]).collect();
    s.update_points(&scaled).unwrap();
    let rebuilt = OsdSurface::new("/pole", &t, &scaled).unwrap();
    let gregory = (0..s.patch_count()).filter(|&i| s.patch_param(i).kind == PatchKind::GregoryBasis).count();
    assert!(gregory >= 64, "{gregory} Gregory patches");
    for i in 0..s.patch_count() {
        let (a, b) = (s.evaluate(i, 0.3, 0.7), rebuilt.evaluate(i, 0.3, 0.7));
        assert!((a.p - b.p).length() < 1e-5 && (a.dpdu - b.dpdu).length() < 1e-4, "patch {i}: {a:?} vs {b:?}");
        assert_eq!(s.patch_bounds(i), rebuilt.patch_bounds(i), "patch {i}");
    }
}
