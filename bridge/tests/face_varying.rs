//! Face-varying (and other 2-float) primvars through [`OsdSurface::with_primvars`], read with
//! [`LimitSurface::face_varying`].
//!
//! | check | reference | tolerance |
//! |---|---|---|
//! | bilinear scheme, seams: values at every patch's corners | the authored values, bilinear over the face | 1e-6 |
//! | Catmull-Clark cube, `faceVaryingLinearInterpolation = all` | bilinear over each base face ([`BaseFacePrimvar`]) | 1e-5 value, 1e-4 derivative |
//! | Catmull-Clark flat grid, default rule, `st` affine in position | the same affine map of the limit point and tangents | 1e-5 value, 1e-4 derivative |
//! | every OpenSubdiv regression shape with `vt` | `Far::LimitStencilTableFactory` in face-varying mode | 1e-5 · uv extent value, 1e-4 · (extent + max derivative) derivative |
//! | vertex primvar equal to the points' x, y | the limit point's x, y | 1e-5 |

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use mipray::obj_shape::{corpus_dir, corpus_paths, parse_obj_shape};
use mipray::patch::{LimitSurface, UvRect};
use mipray::texture::{BaseFacePrimvar, Interpolation, Primvar2, Value2};
use mipray::topology::{FaceVaryingInterpolation, MeshTopology, Scheme};
use mipray_bridge::{limit_fvar_reference, OsdOptions, OsdSurface};

fn max2(a: [f32; 2], b: [f32; 2]) -> f32 {
    (a[0] - b[0]).abs().max((a[1] - b[1]).abs())
}

fn fv(values: Vec<[f32; 2]>, indices: Vec<i32>) -> Primvar2 {
    Primvar2 { name: "st".into(), interpolation: Interpolation::FaceVarying, values, indices }
}

/// An n×n grid of unit quads in z = 0, points row by row.
fn grid(n: usize, scheme: Scheme) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut points = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            points.push([i as f32, j as f32, 0.0]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let p = (j * (n + 1) + i) as i32;
            let r = (n + 1) as i32;
            idx.extend([p, p + 1, p + r + 1, p + r]);
        }
    }
    let topo = MeshTopology { scheme, face_vertex_counts: vec![4; n * n], face_vertex_indices: idx, ..Default::default() };
    (topo, points)
}

/// Compares `surface`'s channel 0 with `expect` on a 5×5 grid of every patch; returns the worst
/// value and derivative errors.
fn compare(surface: &OsdSurface, expect: impl Fn(usize, f32, f32) -> Value2) -> (f32, f32) {
    let (mut ev, mut ed) = (0.0f32, 0.0f32);
    for patch in 0..surface.patch_count() {
        for j in 0..5 {
            for i in 0..5 {
                let (u, v) = UvRect::UNIT.grid_uv(i, j, 5);
                let (val, du, dv) = surface.face_varying(0, patch, u, v).unwrap();
                let (xv, xdu, xdv) = expect(patch, u, v);
                ev = ev.max(max2(val, xv));
                ed = ed.max(max2(du, xdu)).max(max2(dv, xdv));
            }
        }
    }
    (ev, ed)
}

#[test]
fn bilinear_scheme_patch_corners_are_the_authored_values() {
    // 2×2 quads; the right column's st are offset by +10 in s: a seam down the middle.
    let (topo, points) = grid(2, Scheme::Bilinear);
    let mut values = Vec::new();
    let mut indices = Vec::new();
    for (f, quad) in topo.face_vertex_indices.chunks(4).enumerate() {
        let seam = if f % 2 == 1 { 10.0 } else { 0.0 };
        for &p in quad {
            let [x, y, _] = points[p as usize];
            indices.push(values.len() as i32);
            values.push([x * 0.5 + seam, y * 0.5]);
        }
    }
    let st = fv(values.clone(), indices.clone());
    let surface = OsdSurface::with_primvars("/grid", &topo, &points, &OsdOptions::DEFAULT, &[st]).unwrap();
    assert!(surface.face_varying(1, 0, 0.5, 0.5).is_none(), "no channel 1");
    let mut corners = 0;
    for patch in 0..surface.patch_count() {
        let pp = surface.patch_param(patch);
        for (c, (u, v)) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)].into_iter().enumerate() {
            let (val, _, _) = surface.face_varying(0, patch, u, v).unwrap();
            if pp.size == 1.0 {
                // A whole face: its corner c is face-vertex c.
                let authored = values[indices[4 * pp.base_face as usize + c] as usize];
                assert!(max2(val, authored) < 1e-6, "patch {patch} corner {c}: {val:?} vs {authored:?}");
                corners += 1;
            }
        }
    }
    assert_eq!(corners, 16, "four whole-face patches");
}

#[test]
fn catmull_clark_cube_with_linear_face_varying_is_bilinear_per_face() {
    let points = [
        [-1.0, -1.0, 1.0],
        [1.0, -1.0, 1.0],
        [-1.0, 1.0, 1.0],
        [1.0, 1.0, 1.0],
        [-1.0, 1.0, -1.0],
        [1.0, 1.0, -1.0],
        [-1.0, -1.0, -1.0],
        [1.0, -1.0, -1.0],
    ];
    let topo = MeshTopology {
        scheme: Scheme::CatmullClark,
        face_vertex_counts: vec![4; 6],
        face_vertex_indices: vec![0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 1, 0, 1, 7, 5, 3, 6, 0, 2, 4],
        face_varying: FaceVaryingInterpolation::All,
        ..Default::default()
    };
    // The usual cross-shaped unwrap: 14 values, seams around it.
    let values: Vec<[f32; 2]> = [
        [0.375, 0.0],
        [0.625, 0.0],
        [0.375, 0.25],
        [0.625, 0.25],
        [0.375, 0.5],
        [0.625, 0.5],
        [0.375, 0.75],
        [0.625, 0.75],
        [0.375, 1.0],
        [0.625, 1.0],
        [0.875, 0.0],
        [0.875, 0.25],
        [0.125, 0.0],
        [0.125, 0.25],
    ]
    .to_vec();
    let indices = vec![0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 9, 8, 1, 10, 11, 3, 12, 0, 2, 13];
    let st = fv(values, indices);
    let surface = OsdSurface::with_primvars("/cube", &topo, &points, &OsdOptions::DEFAULT, std::slice::from_ref(&st)).unwrap();
    let linear = BaseFacePrimvar::new(&topo, points.len(), &st).unwrap();
    let (ev, ed) = compare(&surface, |patch, u, v| linear.at_patch(&surface.patch_param(patch), u, v).unwrap());
    println!("cube, linear face-varying: {} patches, value error {ev:.1e}, derivative error {ed:.1e}", surface.patch_count());
    assert!(ev < 1e-5 && ed < 1e-4, "{ev} {ed}");
}

#[test]
fn smooth_face_varying_preserves_an_affine_st_on_a_flat_grid() {
    // st = A·(x, y) + b, with the default rule (cornersPlus1): subdivision reproduces affine
    // functions, so the limit st is A·(limit point) + b, boundaries included.
    let (topo, points) = grid(4, Scheme::CatmullClark);
    let (a, b) = ([[0.2f32, 0.05], [-0.03, 0.25]], [0.1f32, 0.3]);
    let map = |x: f32, y: f32| [a[0][0] * x + a[0][1] * y + b[0], a[1][0] * x + a[1][1] * y + b[1]];
    let lin = |d: glam::Vec3A| [a[0][0] * d.x + a[0][1] * d.y, a[1][0] * d.x + a[1][1] * d.y];
    let values: Vec<[f32; 2]> = points.iter().map(|p| map(p[0], p[1])).collect();
    let st = fv(values, topo.face_vertex_indices.clone());
    let surface = OsdSurface::with_primvars("/flat", &topo, &points, &OsdOptions::DEFAULT, &[st]).unwrap();
    let (ev, ed) = compare(&surface, |patch, u, v| {
        let s = surface.evaluate(patch, u, v);
        (map(s.p.x, s.p.y), lin(s.dpdu), lin(s.dpdv))
    });
    println!("flat grid, smooth face-varying: value error {ev:.1e}, derivative error {ed:.1e}");
    assert!(ev < 1e-5 && ed < 1e-4, "{ev} {ed}");

    // The same st as a vertex primvar follows the points exactly (same stencils, same patches),
    // and a constant one is constant.
    let mut vertex = fv(points.iter().map(|p| map(p[0], p[1])).collect(), Vec::new());
    vertex.interpolation = Interpolation::Vertex;
    let constant = Primvar2 { name: "c".into(), interpolation: Interpolation::Constant, values: vec![[0.25, 0.75]], indices: vec![] };
    let surface = OsdSurface::with_primvars("/flat", &topo, &points, &OsdOptions::DEFAULT, &[vertex, constant]).unwrap();
    let (ev, ed) = compare(&surface, |patch, u, v| {
        let s = surface.evaluate(patch, u, v);
        (map(s.p.x, s.p.y), lin(s.dpdu), lin(s.dpdv))
    });
    assert!(ev < 1e-5 && ed < 1e-4, "vertex primvar: {ev} {ed}");
    assert_eq!(surface.face_varying(1, 3, 0.3, 0.6), Some(([0.25, 0.75], [0.0; 2], [0.0; 2])));
}

#[test]
fn bad_primvars_are_refused_naming_mesh_and_primvar() {
    let (topo, points) = grid(1, Scheme::CatmullClark);
    let short = fv(vec![[0.0; 2]; 4], vec![0, 1, 2]);
    let err = OsdSurface::with_primvars("/m", &topo, &points, &OsdOptions::DEFAULT, &[short]).unwrap_err().to_string();
    assert!(err.contains("/m") && err.contains("primvar st"), "{err}");
    let out_of_range = fv(vec![[0.0; 2]; 4], vec![0, 1, 2, 4]);
    let err = OsdSurface::with_primvars("/m", &topo, &points, &OsdOptions::DEFAULT, &[out_of_range]).unwrap_err().to_string();
    assert!(err.contains("indices[3] = 4"), "{err}");
    // OsdSurface::new still builds without primvars.
    let plain = OsdSurface::new("/m", &topo, &points).unwrap();
    assert!(plain.face_varying(0, 0, 0.5, 0.5).is_none());
}

/// Every regression shape with texture coordinates: our face-varying patches against OpenSubdiv's
/// own face-varying evaluation (its own refiner and patch table, values refined level by level).
#[test]
fn regression_shapes_face_varying_matches_opensubdiv() {
    let Some(paths) = corpus_paths(&corpus_dir()) else {
        println!("note: the OpenSubdiv shape corpus is absent; skipping");
        return;
    };
    let (mut checked, mut problems) = (0, Vec::new());
    for path in &paths {
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        let shape = parse_obj_shape(&name, &std::fs::read_to_string(path).unwrap()).unwrap();
        if shape.uv_indices.is_empty() || shape.check_supported().is_err() {
            continue;
        }
        let st = fv(shape.uvs.clone(), shape.uv_indices.clone());
        let surface =
            match OsdSurface::with_primvars(&name, &shape.topology, &shape.points, &OsdOptions::DEFAULT, std::slice::from_ref(&st)) {
                Ok(s) => s,
                Err(e) => {
                    println!("{name:32} FAIL    {e}");
                    problems.push(format!("{name}: {e}"));
                    continue;
                }
            };
        let side = if surface.patch_count() > 4000 { 2 } else { 3 };
        let regular = if shape.scheme == Scheme::Loop { 3 } else { 4 };
        let (mut ours, mut locations, mut scale) = (Vec::new(), Vec::new(), Vec::new());
        for patch in 0..surface.patch_count() {
            let pp = surface.patch_param(patch);
            for j in 0..side {
                for i in 0..side {
                    let (u, v) = UvRect::UNIT.grid_uv(i, j, side);
                    if pp.kind.is_triangle() && u + v > 1.0 {
                        continue;
                    }
                    let (fu, fv) = pp.to_face_uv(u, v);
                    ours.push(surface.face_varying(0, patch, u, v).unwrap());
                    locations.push((pp.ptex_face, fu, fv));
                    // The reference's derivatives are per ptex face, per half sub-face on the
                    // sub-faces of a non-quad (see LimitSample); ours are per patch.
                    let n = shape.topology.face_vertex_counts[pp.base_face as usize];
                    scale.push((pp.size, if n != regular { 2.0 } else { 1.0 }, u > 0.0 && v > 0.0 && u < 1.0 && v < 1.0));
                }
            }
        }
        let reference = match limit_fvar_reference(&name, &shape.topology, &shape.points, &OsdOptions::DEFAULT, &st, &locations) {
            Ok(r) => r,
            Err(e) => {
                println!("{name:32} FAIL    reference: {e}");
                problems.push(format!("{name}: reference: {e}"));
                continue;
            }
        };
        let extent = shape.uvs.iter().fold(0.0f32, |m, uv| m.max(uv[0].abs()).max(uv[1].abs())).max(1e-3);
        let max_deriv = reference.iter().fold(0.0f32, |m, r| m.max(r.1[0].abs()).max(r.1[1].abs()).max(r.2[0].abs()).max(r.2[1].abs()));
        let (mut ev, mut ed) = (0.0f32, 0.0f32);
        for ((o, r), &(size, nq, interior)) in ours.iter().zip(&reference).zip(&scale) {
            ev = ev.max(max2(o.0, r.0));
            if interior {
                let d = |a: [f32; 2], b: [f32; 2]| max2([a[0] / size, a[1] / size], [b[0] / nq, b[1] / nq]);
                ed = ed.max(d(o.1, r.1)).max(d(o.2, r.2));
            }
        }
        let (rv, rd) = (ev / (1e-5 * extent), ed / (1e-4 * (extent + max_deriv)));
        checked += 1;
        let line = format!("patches={:6} samples={:6} value={ev:.1e}({rv:.2}) deriv={ed:.1e}({rd:.2})", surface.patch_count(), ours.len());
        if rv.is_nan() || rd.is_nan() || rv > 1.0 || rd > 1.0 {
            println!("{name:32} FAIL    {line}");
            problems.push(format!("{name}: {line}"));
        } else {
            println!("{name:32} ok      {line}");
        }
    }
    println!("summary: {checked} shapes with uvs checked, {} problems", problems.len());
    assert!(problems.is_empty(), "face-varying problems:\n{}", problems.join("\n"));
}

/// `face_varying_grid` (one call a grid; vertex primvars on regular patches contracted row by
/// row) against `face_varying` at each grid vertex, for vertex, face-varying and constant
/// channels, over whole patches and sub-rectangles, on a bumpy grid (boundaries and corners)
/// and every regression shape OpenSubdiv's corpus has here.
#[test]
fn grid_evaluation_equals_the_point_evaluation_at_each_vertex() {
    let (topo, mut points) = grid(5, Scheme::CatmullClark);
    for p in &mut points {
        p[2] = (1.3 * p[0]).sin() * (0.7 * p[1]).cos();
    }
    let mut shapes = vec![("bumpy".to_string(), topo, points)];
    if let Some(paths) = corpus_paths(&corpus_dir()) {
        for path in paths.iter().take(40) {
            let name = path.file_stem().unwrap().to_string_lossy().to_string();
            let shape = parse_obj_shape(&name, &std::fs::read_to_string(path).unwrap()).unwrap();
            if shape.check_supported().is_ok() && shape.topology.scheme == Scheme::CatmullClark {
                shapes.push((name, shape.topology, shape.points));
            }
        }
    }
    let rects = [UvRect::UNIT, UvRect { u0: 0.25, v0: 0.5, u1: 0.5, v1: 0.75 }, UvRect { u0: 0.0, v0: 0.75, u1: 0.125, v1: 1.0 }];
    let (mut compared, mut worst_v, mut worst_d) = (0usize, 0.0f32, 0.0f32);
    for (name, topo, points) in &shapes {
        let mut vertex = fv(points.iter().map(|p| [p[0] + 0.3 * p[2], p[1] - 0.2 * p[2]]).collect(), Vec::new());
        vertex.interpolation = Interpolation::Vertex;
        let face_varying = fv(
            topo.face_vertex_indices.iter().map(|&i| points[i as usize]).map(|p| [p[0] - p[2], 0.5 * p[1]]).collect(),
            (0..topo.face_vertex_indices.len() as i32).collect(),
        );
        let constant = Primvar2 { name: "c".into(), interpolation: Interpolation::Constant, values: vec![[0.25, 0.75]], indices: vec![] };
        let Ok(surface) = OsdSurface::with_primvars(name, topo, points, &OsdOptions::DEFAULT, &[vertex, face_varying, constant]) else {
            continue;
        };
        let extent = points.iter().flat_map(|p| p.iter()).fold(0.0f32, |m, c| m.max(c.abs())).max(1.0);
        let mut grid_values = Vec::new();
        for channel in 0..3 {
            for patch in 0..surface.patch_count() {
                for rect in rects {
                    for n in [2, 3, 5, 17] {
                        surface.face_varying_grid(channel, patch, rect, n, &mut grid_values);
                        assert_eq!(grid_values.len(), n * n);
                        for (k, got) in grid_values.iter().enumerate() {
                            let (u, v) = rect.grid_uv(k % n, k / n, n);
                            let want = surface.face_varying(channel, patch, u, v);
                            let (Some(g), Some(w)) = (got, want) else {
                                panic!("{name} channel {channel} patch {patch}: {got:?} vs {want:?}");
                            };
                            let ev = max2(g.0, w.0) / extent;
                            let ed = max2(g.1, w.1).max(max2(g.2, w.2)) / extent;
                            worst_v = worst_v.max(ev);
                            worst_d = worst_d.max(ed);
                            assert!(ev < 1e-6 && ed < 1e-5, "{name} channel {channel} patch {patch} n {n} ({u}, {v}): {g:?} vs {w:?}");
                            compared += 1;
                        }
                    }
                }
            }
        }
    }
    println!("{} shapes, {compared} grid vertices: worst value {worst_v:.1e}, derivative {worst_d:.1e} (of the extent)", shapes.len());
    assert!(compared >= 70_000, "{compared}");
}
