//! The texture tests' quad, shared by the core's and the bridge's tests (the bridge includes
//! this file by path: the core never depends on the bridge, and a test-only builder does not
//! belong in the core's API).

use mipray::bilinear::BilinearSurface;
use mipray::texture::{Interpolation, Primvar2};
use mipray::topology::{MeshTopology, Scheme};

/// A 2×2 quad in z = 0 with faceVarying, indexed `st` covering [0, 1]² (the texture) once.
pub fn st_quad() -> BilinearSurface {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let pts = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]];
    let st = Primvar2 {
        name: "st".into(),
        interpolation: Interpolation::FaceVarying,
        values: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        indices: vec![0, 1, 2, 3],
    };
    BilinearSurface::new(&topo, &pts).unwrap().with_primvars(&topo, 4, &[st]).unwrap()
}
