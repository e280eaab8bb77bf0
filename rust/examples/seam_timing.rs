//! How long `seam::seam_extent` takes per grid, on the tessellation path (every cache miss
//! measures its grid's seam boxes). A non-planar bilinear patch stands in for a limit surface:
//! its evaluation is cheap, so the figure is the seam fit's own cost.
//!
//! ```text
//! cargo run --release -p mipray --example seam_timing
//! ```
//!
//! Prints, per grid size, the best of 5 timings of many calls, and the sum of the radii (equal
//! before and after a change that must not alter them).

use std::time::Instant;

use mipray::bilinear::{grid_mesh, BilinearSurface};
use mipray::patch::{LimitSurface, UvRect};

fn main() {
    let (topology, mut points) = grid_mesh(1.0, 1, 0.0);
    points[2][2] = 0.3;
    let Ok(surface) = BilinearSurface::new(&topology, &points) else {
        eprintln!("seam_timing: the test patch did not build");
        std::process::exit(1);
    };
    for n in [2usize, 5, 17] {
        let at = |i: usize, j: usize| surface.evaluate(0, i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32).p.into();
        let verts: Vec<[f32; 3]> = (0..n).flat_map(|j| (0..n).map(move |i| (i, j))).map(|(i, j)| at(i, j)).collect();
        let calls = 200_000 / n;
        let (mut radii, mut best) = (0.0f32, f64::INFINITY);
        for _ in 0..5 {
            let t = Instant::now();
            for _ in 0..calls {
                radii += mipray::seam::seam_extent(&surface, 0, UvRect::UNIT, std::hint::black_box(&verts), n).0;
            }
            best = best.min(t.elapsed().as_secs_f64() / calls as f64);
        }
        println!("{n}×{n} grid: seam_extent {:.2} µs (best of 5); sum of radii {radii}", best * 1e6);
    }
}
