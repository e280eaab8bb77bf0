//! Single-crease patches (`Impl::crease_basis` in cpp/osd.cpp): a regular face along a straight
//! semi-sharp crease is one patch, which the bridge evaluates itself (OpenSubdiv's CPU basis
//! ignores the sharpness). Checked against OpenSubdiv's own evaluation of the fully isolated
//! mesh (`limit_reference`), on a bumpy grid with a crease across it, for integer and
//! fractional sharpness, on each of the four edges a crease can take in a patch.
//!
//! Tolerances: positions 1e-6 · the control mesh's diagonal (rounding is ~1e-7); first
//! derivatives 1e-5 · (diagonal + the largest derivative); evaluated points inside
//! `patch_bounds` to 1e-6 · diagonal.

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use glam::Vec3A;
use mipray::patch::{GridSamples, LimitSurface, UvRect};
use mipray::topology::{BoundaryInterpolation, MeshTopology, Scheme};
use mipray_bridge::{limit_reference, OsdOptions, OsdSurface};

/// An n×n grid of quads with a bumpy height, and a crease along the grid line x = `line` (or
/// y = `line` when `along_x`) from one boundary to the other.
fn creased_grid(n: usize, line: usize, along_x: bool, sharpness: f32) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut points = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32, j as f32);
            points.push([x, y, (0.7 * x).sin() * (0.5 * y).cos() + 0.05 * x * y]);
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as i32;
    let mut counts = Vec::new();
    let mut indices = Vec::new();
    for j in 0..n {
        for i in 0..n {
            counts.push(4);
            indices.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let chain: Vec<i32> = (0..=n).map(|k| if along_x { id(k, line) } else { id(line, k) }).collect();
    let topology = MeshTopology {
        scheme: Scheme::CatmullClark,
        face_vertex_counts: counts,
        face_vertex_indices: indices,
        crease_lengths: vec![chain.len() as i32],
        crease_indices: chain,
        crease_sharpnesses: vec![sharpness],
        boundary: BoundaryInterpolation::EdgeAndCorner,
        ..Default::default()
    };
    (topology, points)
}

#[test]
fn single_crease_patches_match_the_fully_isolated_limit() {
    let n = 10;
    for sharpness in [1.0f32, 2.0, 2.5, 3.0, 0.4, 7.0] {
        for along_x in [false, true] {
            let (topology, points) = creased_grid(n, 5, along_x, sharpness);
            let surface = OsdSurface::new("creased", &topology, &points).unwrap();
            let diag = mipray::bounds::Bounds3::from_points(points.iter().map(|&p| Vec3A::from(p))).diagonal().length();
            // The faces on either side of the crease away from the boundary's isolated corners
            // (2 rows of n − 4) are one patch each, at depth 0: without single-crease patches
            // each would be ⌈sharpness⌉ levels of patches.
            let whole = (0..surface.patch_count()).filter(|&p| surface.patch_param(p).depth == 0).count();
            assert!(whole >= 2 * (n - 4), "sharpness {sharpness}: {whole} patches at depth 0, {} in all", surface.patch_count());

            // Their rows across the crease change cubic at 1 − 2^−⌊S⌋ and 1 − 2^−⌈S⌉ from it, S
            // the sharpness left at the patch's depth, clamped by OpenSubdiv to the isolation
            // level (4): where seam boxes fit them piece by piece.
            let expect = |depth: u8| -> Vec<f32> {
                let s = f64::from(sharpness.min(4.0)) - f64::from(depth);
                [s.floor(), s.ceil()].iter().map(|&k| 1.0 - (-k).exp2()).filter(|&x| x > 0.0).map(|x| x as f32).collect()
            };
            let mut with_knots = 0;
            for p in 0..surface.patch_count() {
                let k = surface.edge_knots(p);
                let along = if along_x { k.v } else { k.u };
                let other = if along_x { k.u } else { k.v };
                if along.iter().all(|x| x.is_nan()) {
                    continue;
                }
                with_knots += 1;
                assert!(other.iter().all(|x| x.is_nan()), "sharpness {sharpness}: knots along the crease too: {k:?}");
                let expect = expect(surface.patch_param(p).depth);
                for x in along.iter().filter(|x| !x.is_nan()) {
                    let ok = expect.iter().any(|e| (x - e).abs() < 1e-6 || (x - (1.0 - e)).abs() < 1e-6);
                    assert!(ok, "sharpness {sharpness}: knot {x} is not one of {expect:?} (or from the other edge)");
                }
            }
            assert!(with_knots >= 2 * (n - 4), "sharpness {sharpness}: {with_knots} patches with knots");

            let side = 7;
            let (mut ours, mut locations) = (Vec::new(), Vec::new());
            let mut out_of_bounds = 0.0f32;
            for patch in 0..surface.patch_count() {
                let pp = surface.patch_param(patch);
                let bounds = surface.patch_bounds(patch);
                for j in 0..side {
                    for i in 0..side {
                        let (u, v) = (i as f32 / (side - 1) as f32, j as f32 / (side - 1) as f32);
                        let sp = surface.evaluate(patch, u, v);
                        let outside = (bounds.min - sp.p).max(sp.p - bounds.max).max(Vec3A::ZERO);
                        out_of_bounds = out_of_bounds.max(outside.max_element());
                        let (fu, fv) = pp.to_face_uv(u, v);
                        ours.push((sp, pp.size, u > 0.0 && v > 0.0 && u < 1.0 && v < 1.0));
                        locations.push((pp.ptex_face, fu, fv));
                    }
                }
            }
            let reference = limit_reference("creased", &topology, &points, &OsdOptions::DEFAULT, &locations).unwrap();
            let max_deriv = reference.iter().fold(0.0f32, |m, r| m.max(r.dpdu.abs().max_element()).max(r.dpdv.abs().max_element()));
            let (mut pos, mut du) = (0.0f32, 0.0f32);
            for ((sp, size, interior), r) in ours.iter().zip(&reference) {
                pos = pos.max((sp.p - r.p).abs().max_element());
                if *interior {
                    du = du.max((sp.dpdu / *size - r.dpdu).abs().max_element()).max((sp.dpdv / *size - r.dpdv).abs().max_element());
                }
            }
            let what = format!("sharpness {sharpness}, crease along {}", if along_x { "x" } else { "y" });
            assert!(pos <= 1e-6 * diag, "{what}: position {pos:e} off OpenSubdiv's evaluation (diagonal {diag})");
            assert!(du <= 1e-5 * (diag + max_deriv), "{what}: derivative {du:e} off OpenSubdiv's evaluation");
            assert!(out_of_bounds <= 1e-6 * diag, "{what}: a point {out_of_bounds:e} outside its patch's bounds");

            // A grid (the bridge contracts a crease patch's rows once, as a regular patch's)
            // gives each vertex and its first derivatives as the point's own evaluation does.
            let mut grid = GridSamples::default();
            let (mut grid_pos, mut grid_du) = (0.0f32, 0.0f32);
            for patch in 0..surface.patch_count() {
                let rect = UvRect { u0: 0.125, v0: 0.0, u1: 0.875, v1: 1.0 };
                surface.evaluate_grid(patch, rect, side, true, &mut grid);
                for j in 0..side {
                    for i in 0..side {
                        let (u, v) = rect.grid_uv(i, j, side);
                        let sp = surface.evaluate(patch, u, v);
                        let k = j * side + i;
                        grid_pos = grid_pos.max((Vec3A::from(grid.p[k]) - sp.p).abs().max_element());
                        grid_du = grid_du
                            .max((Vec3A::from(grid.dpdu[k]) - sp.dpdu).abs().max_element())
                            .max((Vec3A::from(grid.dpdv[k]) - sp.dpdv).abs().max_element());
                    }
                }
            }
            // And positions asked for in one call (the seam and chord-error probes) as well.
            let mut pts_pos = 0.0f32;
            let mut points_out = Vec::new();
            for patch in 0..surface.patch_count() {
                let uv: Vec<[f32; 2]> =
                    (0..side * side).map(|k| [0.05 + 0.9 * (k % side) as f32 / 6.0, 0.9 * (k / side) as f32 / 6.0]).collect();
                surface.evaluate_points(patch, &uv, &mut points_out);
                for (q, &[u, v]) in points_out.iter().zip(&uv) {
                    pts_pos = pts_pos.max((Vec3A::from(*q) - surface.evaluate(patch, u, v).p).abs().max_element());
                }
            }
            assert!(pts_pos <= 1e-6 * diag, "{what}: points {pts_pos:e} off their own evaluation");
            assert!(grid_pos <= 1e-6 * diag, "{what}: grid vertices {grid_pos:e} off the points' own evaluation");
            assert!(grid_du <= 1e-5 * (diag + max_deriv), "{what}: grid derivatives {grid_du:e} off the points' own");
        }
    }
}
