//! Arbitrary bytes read as a mesh (counts, indices, creases, holes, points) and fed to
//! `OsdSurface::new`: errors are fine, a crash or an abort is a bug. See ../Cargo.toml.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mipray::topology::{MeshTopology, Scheme};
use mipray_bridge::OsdSurface;

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let scheme = [Scheme::CatmullClark, Scheme::Loop, Scheme::Bilinear, Scheme::None][usize::from(data[0] % 4)];
    let n_points = usize::from(data[1] % 64) + 1;
    let n_faces = usize::from(data[2] % 32) + 1;
    let mut bytes = data[3..].iter().copied().cycle();
    let mut next = || bytes.next().unwrap_or(0);
    let counts: Vec<i32> = (0..n_faces).map(|_| i32::from(next() % 9)).collect();
    let total: usize = counts.iter().map(|&c| c.max(0) as usize).sum();
    let indices: Vec<i32> = (0..total).map(|_| i32::from(next() as i8) % (n_points as i32 + 2)).collect();
    let points: Vec<[f32; 3]> =
        (0..n_points).map(|_| [f32::from(next() as i8), f32::from(next() as i8), f32::from(next() as i8)]).collect();
    let crease_len = usize::from(next() % 4);
    let topology = MeshTopology {
        scheme,
        face_vertex_counts: counts,
        face_vertex_indices: indices,
        crease_indices: (0..crease_len).map(|_| i32::from(next() % 64)).collect(),
        crease_lengths: if crease_len > 0 { vec![crease_len as i32] } else { Vec::new() },
        crease_sharpnesses: if crease_len > 0 { vec![f32::from(next()) / 16.0] } else { Vec::new() },
        hole_indices: if next() % 4 == 0 { vec![i32::from(next() % 40)] } else { Vec::new() },
        ..Default::default()
    };
    if let Ok(surface) = OsdSurface::new("/fuzz", &topology, &points) {
        use mipray::patch::LimitSurface;
        for p in 0..surface.patch_count().min(4) {
            let _ = surface.evaluate(p, 0.5, 0.5);
        }
    }
});
