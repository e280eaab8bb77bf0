//! Subpatches (the paper's §5.1): every patch of a mesh is a root subpatch with conservative
//! object-space bounds — its control hull grown by the displacement bound — and a bottom-level
//! BVH over them. Tessellation happens later, on demand, per subpatch.

use obvhs::cwbvh::CwBvh;

use crate::bounds::Bounds3;
use crate::bvh::build_bvh;
use crate::patch::UvRect;
use crate::scene::Mesh;

/// A piece of one patch's domain with bounds that contain its (displaced) limit surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Subpatch {
    /// Patch index in the mesh's [`crate::patch::LimitSurface`].
    pub patch: u32,
    /// The subpatch's domain in the patch's own (u, v).
    pub rect: UvRect,
    /// Object space, grown by the mesh's displacement bound.
    pub bounds: Bounds3,
}

/// A mesh prepared for tracing: its root subpatches and a BVH over them (object space).
/// Shared by all instances of the mesh.
pub struct MeshGeometry {
    pub subpatches: Vec<Subpatch>,
    /// `None` when the mesh has no patches (all holes, or empty).
    pub bvh: Option<CwBvh>,
    pub bounds: Bounds3,
}

impl MeshGeometry {
    /// Builds the root subpatches and their BVH.
    pub fn build(mesh: &Mesh) -> Self {
        let s = &mesh.surface;
        let grow = mesh.displacement_bound.max(0.0);
        let subpatches: Vec<Subpatch> = (0..s.patch_count())
            .map(|i| Subpatch { patch: i as u32, rect: UvRect::UNIT, bounds: s.patch_bounds(i).expanded(grow) })
            .filter(|sp| !sp.bounds.is_empty())
            .collect();
        let bounds = subpatches.iter().fold(Bounds3::EMPTY, |b, sp| b.union(&sp.bounds));
        let boxes: Vec<Bounds3> = subpatches.iter().map(|s| s.bounds).collect();
        let bvh = build_bvh(&boxes);
        MeshGeometry { subpatches, bvh, bounds }
    }
}
