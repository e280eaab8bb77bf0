//! The work a very large n-gon causes is bounded (issue 16): above a valence of 256 a mesh gets
//! bilinear end caps instead of Gregory ones (whose stencils cost the square of the valence), and
//! says so; away from the n-gon the surface is still OpenSubdiv's exact limit.
//!
//! Truth: OpenSubdiv's own evaluation (`limit_reference`) of the same grid without the n-gon. A Catmull-Clark limit
//! point depends only on the control points within two rings of its face, so faces three rows
//! or more from the n-gon have the same limit with or without it. Tolerance 1e-5 · the grid's
//! size (float rounding of two evaluation paths).

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use mipray::patch::LimitSurface;
use mipray::topology::{BoundaryInterpolation, MeshTopology, Scheme};
use mipray_bridge::{limit_reference, OsdOptions, OsdSurface};

const N: usize = 10;

/// A bumpy N×N grid of quads on [-2, 2]×[-1, 2], and, when `ngon_sides` is given, one n-gon
/// below it sharing the grid's bottom edge (its other points on a half circle), last.
fn grid_with_ngon(ngon_sides: Option<usize>) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut points = Vec::new();
    for j in 0..=N {
        for i in 0..=N {
            let (x, y) = (i as f32 / N as f32 * 4.0 - 2.0, j as f32 / N as f32 * 3.0 - 1.0);
            points.push([x, y, 0.3 * (2.0 * x).sin() * (1.5 * y).cos()]);
        }
    }
    let id = |i: usize, j: usize| (j * (N + 1) + i) as i32;
    let mut counts = Vec::new();
    let mut indices = Vec::new();
    for j in 0..N {
        for i in 0..N {
            counts.push(4);
            indices.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    if let Some(n) = ngon_sides {
        // The shared edge right to left (the quads run it left to right), then the arc.
        indices.extend((0..=N).rev().map(|i| id(i, 0)));
        let arc = n - (N + 1);
        for k in 1..=arc {
            let a = std::f32::consts::PI * (1.0 + k as f32 / (arc + 1) as f32);
            indices.push(points.len() as i32);
            points.push([-2.0 * a.cos(), -1.0 + 2.0 * a.sin(), 0.0]);
        }
        counts.push(n as i32);
    }
    let topology = MeshTopology {
        scheme: Scheme::CatmullClark,
        face_vertex_counts: counts,
        face_vertex_indices: indices,
        boundary: BoundaryInterpolation::EdgeAndCorner,
        ..Default::default()
    };
    (topology, points)
}

#[test]
fn a_1024_gon_gets_bilinear_end_caps_and_stays_exact_away_from_it() {
    let (topology, points) = grid_with_ngon(Some(1024));
    let surface = OsdSurface::new("/NGon", &topology, &points).unwrap();
    let said = surface.simplified().expect("a 1024-gon is named as simplified");
    assert!(said.contains("valence 1024") && said.contains("bilinear"), "{said}");

    // Every patch evaluates finite (the n-gon's too).
    for patch in 0..surface.patch_count() {
        for (u, v) in [(0.0, 0.0), (0.5, 0.5), (1.0, 0.25)] {
            let p = surface.evaluate(patch, u, v).p;
            assert!(p.is_finite(), "patch {patch} at ({u}, {v}): {p}");
        }
    }

    // Rows 3.. of the grid against OpenSubdiv's evaluation of the grid alone.
    let (grid, grid_points) = grid_with_ngon(None);
    let mut locations = Vec::new();
    for j in 3..N {
        for i in 0..N {
            for (u, v) in [(0.1, 0.2), (0.5, 0.5), (0.9, 0.7)] {
                locations.push(((j * N + i) as u32, u, v));
            }
        }
    }
    let truth = limit_reference("grid", &grid, &grid_points, &OsdOptions::default(), &locations).unwrap();
    let mut worst = 0.0f32;
    for (&(face, u, v), t) in locations.iter().zip(&truth) {
        let got = surface.limit_at(face, u, v).expect("a grid face has a patch").p;
        worst = worst.max((got - t.p).abs().max_element());
    }
    assert!(worst < 4e-5, "grid away from the n-gon differs from the limit by {worst}");
}

#[test]
fn n_gons_up_to_the_threshold_keep_gregory_end_caps() {
    let (topology, points) = grid_with_ngon(Some(256));
    let surface = OsdSurface::new("/NGon", &topology, &points).unwrap();
    assert_eq!(surface.simplified(), None);
}
