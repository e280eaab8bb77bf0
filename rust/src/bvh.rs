//! BVH construction over boxes with obvhs (a compressed wide BVH8), used at both levels: over a
//! mesh's subpatches (object space) and over instances (render space).

use std::time::Duration;

use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::{Boundable, BvhBuildParams};

use crate::bounds::Bounds3;

struct BoxPrim(Aabb);

impl Boundable for BoxPrim {
    fn aabb(&self) -> Aabb {
        self.0
    }
}

/// Builds a BVH over `boxes`; `None` when there is nothing to build over. Leaf primitive ids
/// map back to `boxes` through `CwBvh::primitive_indices`.
pub fn build_bvh(boxes: &[Bounds3]) -> Option<CwBvh> {
    if boxes.is_empty() {
        return None;
    }
    let prims: Vec<BoxPrim> = boxes.iter().map(|b| BoxPrim((*b).into())).collect();
    let mut t = Duration::ZERO;
    let mut bvh = build_cwbvh(&prims, BvhBuildParams::medium_build(), &mut t);
    // The builder sizes its arrays for the worst case; a scene keeps hundreds of thousands of
    // these, so give the slack back (measured: 5× the BVH's own bytes in peak RSS without).
    bvh.nodes.shrink_to_fit();
    bvh.primitive_indices.shrink_to_fit();
    bvh.exact_node_aabbs = None;
    Some(bvh)
}

/// Bytes a BVH occupies (nodes and index array), for the stats.
pub fn bvh_bytes(bvh: &CwBvh) -> usize {
    std::mem::size_of_val(bvh.nodes.as_slice()) + std::mem::size_of_val(bvh.primitive_indices.as_slice())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;
    use obvhs::ray::{Ray, RayHit};

    #[test]
    fn traversal_finds_the_nearest_box_by_id() {
        let boxes: Vec<Bounds3> = (0..50)
            .map(|i| Bounds3 { min: Vec3A::new(i as f32 * 2.0, 0.0, 0.0), max: Vec3A::new(i as f32 * 2.0 + 1.0, 1.0, 1.0) })
            .collect();
        let bvh = build_bvh(&boxes).unwrap();
        let ray = Ray::new_inf(Vec3A::new(20.5, 0.5, 5.0), Vec3A::NEG_Z);
        let mut hit = RayHit::none();
        let mut seen = Vec::new();
        bvh.ray_traverse(ray, &mut hit, |_r, id| {
            let b = bvh.primitive_indices[id] as usize;
            seen.push(b);
            if b == 10 {
                4.0
            } else {
                f32::INFINITY
            }
        });
        assert!(seen.contains(&10));
        assert_eq!(bvh.primitive_indices[hit.primitive_id as usize], 10);
        assert!(build_bvh(&[]).is_none());
        assert!(build_bvh(&boxes[..1]).is_some());
    }
}
