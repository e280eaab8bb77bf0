//! Polygonal meshes as bilinear patches, in pure Rust: `subdivisionScheme = "none"` meshes, and
//! the patch source for core tests that must run without OpenSubdiv.
//!
//! Quads become one patch; an n-gon (n ≠ 4) becomes n quad sub-faces (corner, next edge
//! midpoint, centroid, previous edge midpoint), exactly as OpenSubdiv's bilinear scheme and its
//! ptex numbering split them, so face ids mean the same thing on both paths. For planar faces
//! this is the flat polygon itself.

use glam::Vec3A;

use crate::bounds::Bounds3;
use crate::error::MeshError;
use crate::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};
use crate::texture::{BaseFacePrimvar, Primvar2};
use crate::topology::MeshTopology;

/// A polygonal mesh's bilinear patches. Object space.
#[derive(Clone, Debug)]
pub struct BilinearSurface {
    /// Four corners per patch, counter-clockwise in (u, v): (0,0), (1,0), (1,1), (0,1).
    corners: Vec<[Vec3A; 4]>,
    params: Vec<PatchParam>,
    faces: usize,
    /// 2-float primvar channels, by ptex face (see [`BilinearSurface::with_primvars`]).
    primvars: Vec<BaseFacePrimvar>,
}

impl BilinearSurface {
    /// Builds the patches of a polygonal mesh. Hole faces get no patch.
    ///
    /// # Errors
    /// Invalid topology (see [`MeshTopology::validate`]) or a non-finite point.
    pub fn new(topology: &MeshTopology, points: &[[f32; 3]]) -> Result<Self, MeshError> {
        topology.validate(points.len())?;
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(MeshError::NonFinite(format!("points[{i}] = {:?}", points[i])));
        }
        let holes: std::collections::HashSet<i32> = topology.hole_indices.iter().copied().collect();
        let mut corners = Vec::new();
        let mut params = Vec::new();
        let (mut start, mut ptex) = (0usize, 0u32);
        for (face, &n) in topology.face_vertex_counts.iter().enumerate() {
            let n = n as usize;
            let fv: Vec<Vec3A> = topology.face_vertex_indices[start..start + n].iter().map(|&i| Vec3A::from(points[i as usize])).collect();
            start += n;
            let sub_faces = if n == 4 { 1 } else { n };
            if !holes.contains(&(face as i32)) {
                if n == 4 {
                    corners.push([fv[0], fv[1], fv[2], fv[3]]);
                    params.push(PatchParam::root(face as u32, ptex, PatchKind::Bilinear));
                } else {
                    let centroid = fv.iter().copied().sum::<Vec3A>() / n as f32;
                    for i in 0..n {
                        let next = fv[(i + 1) % n];
                        let prev = fv[(i + n - 1) % n];
                        corners.push([fv[i], (fv[i] + next) * 0.5, centroid, (fv[i] + prev) * 0.5]);
                        params.push(PatchParam::root(face as u32, ptex + i as u32, PatchKind::Bilinear));
                    }
                }
            }
            ptex += sub_faces as u32;
        }
        Ok(Self { corners, params, faces: topology.face_count(), primvars: Vec::new() })
    }

    /// Adds 2-float primvars (texture coordinates `st`, …): channel i of
    /// [`LimitSurface::face_varying`] is `primvars[i]`. On a polygonal mesh every interpolation
    /// is linear over each face (split as the patches are), so all five are exact here.
    /// `topology` and `point_count` are the ones the surface was built from.
    ///
    /// # Errors
    /// As [`BaseFacePrimvar::new`]: a count or index that does not fit the topology, naming the
    /// primvar.
    pub fn with_primvars(mut self, topology: &MeshTopology, point_count: usize, primvars: &[Primvar2]) -> Result<Self, MeshError> {
        for p in primvars {
            self.primvars.push(BaseFacePrimvar::new(topology, point_count, p)?);
        }
        Ok(self)
    }
}

impl LimitSurface for BilinearSurface {
    fn patch_count(&self) -> usize {
        self.corners.len()
    }

    fn patch_param(&self, patch: usize) -> PatchParam {
        self.params[patch]
    }

    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        Bounds3::from_points(self.corners[patch])
    }

    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        let [p0, p1, p2, p3] = self.corners[patch];
        let p = (1.0 - u) * (1.0 - v) * p0 + u * (1.0 - v) * p1 + u * v * p2 + (1.0 - u) * v * p3;
        let dpdu = (1.0 - v) * (p1 - p0) + v * (p2 - p3);
        let dpdv = (1.0 - u) * (p3 - p0) + u * (p2 - p1);
        let dpduv = p0 - p1 + p2 - p3;
        SurfacePoint { p, dpdu, dpdv, dpduu: Vec3A::ZERO, dpduv, dpdvv: Vec3A::ZERO }
    }

    fn control_face_count(&self) -> usize {
        self.faces
    }

    fn face_varying(&self, channel: usize, patch: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        self.primvars.get(channel)?.at_patch(self.params.get(patch)?, u, v)
    }

    fn patch_is_affine(&self, patch: usize) -> bool {
        // A bilinear patch is affine exactly when its corners form a parallelogram:
        // p0 + p2 = p1 + p3 (then the twist term dpduv vanishes).
        let [p0, p1, p2, p3] = self.corners[patch];
        let scale = p0.abs().max(p1.abs()).max(p2.abs()).max(p3.abs()).max_element().max(f32::MIN_POSITIVE);
        ((p0 + p2) - (p1 + p3)).abs().max_element() <= 4.0 * f32::EPSILON * scale
    }
}

/// A flat `n × n` grid of quads in the plane z = `z`, `half` units from its centre to each side,
/// counter-clockwise (facing +z): topology and points, for tests, examples and ground planes.
pub fn grid_mesh(half: f32, n: i32, z: f32) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pts.push([(2.0 * i as f32 / n as f32 - 1.0) * half, (2.0 * j as f32 / n as f32 - 1.0) * half, z]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = |a: i32, b: i32| b * (n + 1) + a;
            idx.extend([v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    let topo = MeshTopology {
        scheme: crate::topology::Scheme::None,
        face_vertex_counts: vec![4; (n * n).max(0) as usize],
        face_vertex_indices: idx,
        ..Default::default()
    };
    (topo, pts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topology::Scheme;

    fn topo(counts: Vec<i32>, idx: Vec<i32>) -> MeshTopology {
        MeshTopology { scheme: Scheme::None, face_vertex_counts: counts, face_vertex_indices: idx, ..Default::default() }
    }

    #[test]
    fn quad_corners_and_derivatives_are_exact() {
        let pts = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let s = BilinearSurface::new(&topo(vec![4], vec![0, 1, 2, 3]), &pts).unwrap();
        assert_eq!(s.patch_count(), 1);
        let e = s.evaluate(0, 0.25, 0.5);
        assert_eq!(e.p, Vec3A::new(0.5, 0.5, 0.0));
        assert_eq!(e.dpdu, Vec3A::new(2.0, 0.0, 0.0));
        assert_eq!(e.dpdv, Vec3A::new(0.0, 1.0, 0.0));
        assert!(e.dpdu.cross(e.dpdv).z > 0.0, "counter-clockwise quad faces +z");
    }

    #[test]
    fn triangle_splits_into_three_quads_covering_it() {
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let s = BilinearSurface::new(&topo(vec![3], vec![0, 1, 2]), &pts).unwrap();
        assert_eq!(s.patch_count(), 3);
        let ids: Vec<u32> = (0..3).map(|i| s.patch_param(i).ptex_face).collect();
        assert_eq!(ids, vec![0, 1, 2]);
        // The union of sub-quad areas is the triangle's area, 0.5.
        let area: f32 = (0..3)
            .map(|i| {
                let e = s.evaluate(i, 0.5, 0.5);
                e.dpdu.cross(e.dpdv).length()
            })
            .sum();
        assert!((area - 0.5).abs() < 1e-6, "{area}");
    }

    #[test]
    fn holes_get_no_patch() {
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]];
        let mut t = topo(vec![4, 4], vec![0, 1, 2, 3, 1, 4, 5, 2]);
        t.hole_indices = vec![0];
        let s = BilinearSurface::new(&t, &pts).unwrap();
        assert_eq!(s.patch_count(), 1);
        assert_eq!(s.patch_param(0).base_face, 1);
    }

    #[test]
    fn parallelograms_are_affine_and_twisted_quads_are_not() {
        let topo = topo(vec![4], vec![0, 1, 2, 3]);
        let para = BilinearSurface::new(&topo, &[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 1.0, 0.0], [1.0, 1.0, 0.0]]).unwrap();
        assert!(para.patch_is_affine(0));
        let twisted = BilinearSurface::new(&topo, &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.3], [0.0, 1.0, 0.0]]).unwrap();
        assert!(!twisted.patch_is_affine(0));
        let trapezoid = BilinearSurface::new(&topo, &[[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 1.0, 0.0], [1.0, 1.0, 0.0]]).unwrap();
        assert!(!trapezoid.patch_is_affine(0), "flat but with a non-linear parameterization");
    }

    #[test]
    fn nan_point_is_refused_with_its_index() {
        let pts = [[0.0, 0.0, 0.0], [1.0, f32::NAN, 0.0], [1.0, 1.0, 0.0]];
        let err = BilinearSurface::new(&topo(vec![3], vec![0, 1, 2]), &pts).unwrap_err();
        assert!(err.to_string().contains("points[1]"), "{err}");
    }
}
