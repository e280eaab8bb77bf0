//! BVH construction over boxes with obvhs (a compressed wide BVH8), used at both levels: over a
//! mesh's subpatches (object space) and over instances (render space).

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::ploc::PlocBuilder;
use obvhs::{Boundable, BvhBuildParams};

use crate::bounds::Bounds3;

struct BoxPrim(Aabb);

impl Boundable for BoxPrim {
    fn aabb(&self) -> Aabb {
        self.0
    }
}

/// The deepest CWBVH obvhs can traverse: its traversal stack holds 32 entries
/// (`TRAVERSAL_STACK_SIZE`, private to obvhs 0.4), and a deeper tree overwrites the top entry in
/// release builds (geometry silently missed) and fails obvhs's own validation in debug builds.
pub const MAX_DEPTH: u32 = 31;

/// Builds a BVH over `boxes`; `None` when there is nothing to build over. Leaf primitive ids
/// map back to `boxes` through `CwBvh::primitive_indices`.
///
/// The boxes must be [`Bounds3::is_traceable`] (callers drop the others, naming the prim): the
/// builder's surface-area costs of larger boxes overflow to Inf and leave it no decision.
/// Whatever their arrangement, the tree is at most [`MAX_DEPTH`] deep: PLOC over boxes with equal
/// centres (a mesh with many duplicated points) can build a chain as deep as the box count, and
/// such a tree is rebuilt by median splits, whose depth is log₂ of the box count.
pub fn build_bvh(boxes: &[Bounds3]) -> Option<CwBvh> {
    if boxes.is_empty() {
        return None;
    }
    debug_assert!(boxes.iter().all(Bounds3::is_traceable), "build_bvh over a box that is not traceable");
    let prims: Vec<BoxPrim> = boxes.iter().map(|b| BoxPrim((*b).into())).collect();
    // obvhs's `build_cwbvh` with `medium_build`, without its debug-only validation (which panics
    // on the deep trees this function rebuilds).
    let params = BvhBuildParams::medium_build();
    let leaf_prims = params.max_prims_per_leaf.clamp(1, 3);
    // PLOC clusters by Morton code: boxes whose centres share one code it merges one at a time
    // into a chain, in time quadratic in their number (measured: 37,000 coincident boxes, 110 s
    // and a chain 36,999 deep). Such input gets median splits instead.
    let mut bvh2 = if largest_coincident_group(&prims) > MAX_COINCIDENT {
        median_split_bvh2(&prims)
    } else {
        PlocBuilder::with_capacity(prims.len()).build(
            params.ploc_search_distance,
            &prims,
            (0..prims.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        )
    };
    // A binary tree far deeper than the wide one may be is a degenerate chain: obvhs's collapse
    // recurses once per level, so rebuild it before converting.
    if bvh2_depth(&bvh2) > 3 * MAX_DEPTH {
        bvh2 = median_split_bvh2(&prims);
    }
    ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
    let mut bvh = bvh2_to_cwbvh(&bvh2, leaf_prims, true, false);
    if cwbvh_depth(&bvh) > MAX_DEPTH {
        bvh = bvh2_to_cwbvh(&median_split_bvh2(&prims), leaf_prims, true, false);
    }
    // The builder sizes its arrays for the worst case; a scene keeps hundreds of thousands of
    // these, so give the slack back (measured: 5× the BVH's own bytes in peak RSS without).
    bvh.nodes.shrink_to_fit();
    bvh.primitive_indices.shrink_to_fit();
    bvh.exact_node_aabbs = None;
    Some(bvh)
}

/// The most box centres PLOC is given in one cell of its Morton grid (see
/// [`largest_coincident_group`]); a few duplicated faces stay with PLOC.
const MAX_COINCIDENT: usize = 32;

/// The largest number of boxes whose centres fall in one cell of a 2²¹-per-axis grid over the
/// centres' bounds: the 63-bit Morton code's resolution, so boxes PLOC cannot tell apart.
fn largest_coincident_group(prims: &[BoxPrim]) -> usize {
    let centres = prims.iter().fold(Aabb::INVALID, |mut a, p| *a.extend(p.0.center()));
    let scale = Vec3A::splat((1u32 << 21) as f32 - 1.0) / centres.diagonal().max(Vec3A::splat(f32::MIN_POSITIVE));
    let mut cells: Vec<u64> = prims
        .iter()
        .map(|p| {
            let q = ((p.0.center() - centres.min) * scale).as_uvec3();
            (u64::from(q.x) << 42) | (u64::from(q.y) << 21) | u64::from(q.z)
        })
        .collect();
    cells.sort_unstable();
    cells.chunk_by(|a, b| a == b).map(<[u64]>::len).max().unwrap_or(0)
}

/// A binary BVH by median splits: each node's boxes are halved by count along the widest axis
/// of their centres (ties by index, so the tree is deterministic). Depth ⌈log₂ n⌉ whatever the
/// boxes, one box per leaf as obvhs's collapse expects; children follow their parent.
fn median_split_bvh2(prims: &[BoxPrim]) -> Bvh2 {
    let n = prims.len();
    let mut indices: Vec<u32> = (0..n as u32).collect();
    let mut nodes = vec![Bvh2Node::default(); 2 * n - 1];
    let mut next = 1;
    // (node, first box, one past the last box) in `indices`.
    let mut stack = vec![(0usize, 0usize, n)];
    while let Some((node, lo, hi)) = stack.pop() {
        let range = &mut indices[lo..hi];
        let aabb = range.iter().fold(Aabb::INVALID, |a, &i| a.union(&prims[i as usize].0));
        if range.len() == 1 {
            nodes[node] = Bvh2Node::new(aabb, 1, lo as u32);
            continue;
        }
        let centres = range.iter().fold(Aabb::INVALID, |mut a, &i| *a.extend(prims[i as usize].0.center()));
        let axis = centres.largest_axis();
        let mid = range.len() / 2;
        let key = |i: u32| prims[i as usize].0.center_axis(axis);
        range.select_nth_unstable_by(mid, |&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
        nodes[node] = Bvh2Node::new(aabb, 0, next as u32);
        stack.push((next, lo, lo + mid));
        stack.push((next + 1, lo + mid, hi));
        next += 2;
    }
    Bvh2 { nodes, primitive_indices: indices, children_are_ordered_after_parents: true, ..Bvh2::default() }
}

/// Depth of a binary BVH (a root leaf is depth 0), without recursion: a degenerate tree is as
/// deep as it has primitives.
fn bvh2_depth(bvh: &Bvh2) -> u32 {
    let mut deepest = 0;
    let mut stack = vec![(0usize, 0u32)];
    while let Some((i, depth)) = stack.pop() {
        let node = &bvh.nodes[i];
        deepest = deepest.max(depth);
        if node.prim_count == 0 {
            stack.push((node.first_index as usize, depth + 1));
            stack.push((node.first_index as usize + 1, depth + 1));
        }
    }
    deepest
}

/// Depth of a compressed wide BVH: how many inner nodes its traversal stack may hold at once.
pub fn cwbvh_depth(bvh: &CwBvh) -> u32 {
    if bvh.nodes.is_empty() {
        return 0;
    }
    let mut deepest = 0;
    let mut stack = vec![(0usize, 0u32)];
    while let Some((i, depth)) = stack.pop() {
        let node = &bvh.nodes[i];
        deepest = deepest.max(depth);
        for ch in (0..8).filter(|&ch| !node.is_child_empty(ch) && !node.is_leaf(ch)) {
            stack.push((node.child_node_index(ch) as usize, depth + 1));
        }
    }
    deepest
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

    /// Every box a ray along +z through (x, y) crosses, by traversal.
    fn boxes_seen(bvh: &CwBvh, n: usize, x: f32, y: f32) -> Vec<bool> {
        let mut seen = vec![false; n];
        let mut hit = RayHit::none();
        bvh.ray_traverse(Ray::new_inf(Vec3A::new(x, y, -10.0), Vec3A::Z), &mut hit, |_r, id| {
            seen[bvh.primitive_indices[id] as usize] = true;
            f32::INFINITY
        });
        seen
    }

    #[test]
    fn coincident_boxes_build_a_tree_traversal_can_hold() {
        // A production mesh with duplicated points: tens of thousands of subpatches whose boxes
        // coincide, as solids and as flat boxes (all the patch's points in one plane).
        let solid = Bounds3 { min: Vec3A::ZERO, max: Vec3A::ONE };
        let flat = Bounds3 { min: Vec3A::new(0.0, 0.0, 0.5), max: Vec3A::new(1.0, 1.0, 0.5) };
        for b in [solid, flat] {
            let boxes = vec![b; 37_000];
            let bvh = build_bvh(&boxes).unwrap();
            assert!(cwbvh_depth(&bvh) <= MAX_DEPTH, "depth {}", cwbvh_depth(&bvh));
            assert!(boxes_seen(&bvh, boxes.len(), 0.5, 0.5).iter().all(|&s| s), "a box was skipped");
        }
    }

    #[test]
    fn median_split_tree_finds_every_box_it_should() {
        // A grid of boxes, a third of them stacked on one cell: the fallback tree must be a
        // correct BVH too (traversal sees every box under the ray).
        let mut boxes: Vec<Bounds3> = (0..3000)
            .map(|i| {
                let (x, y) = ((i % 50) as f32, (i / 50) as f32);
                Bounds3 { min: Vec3A::new(x, y, 0.0), max: Vec3A::new(x + 0.9, y + 0.9, 1.0) }
            })
            .collect();
        boxes.extend(std::iter::repeat_n(boxes[7], 1500));
        let prims: Vec<BoxPrim> = boxes.iter().map(|b| BoxPrim((*b).into())).collect();
        let bvh = bvh2_to_cwbvh(&median_split_bvh2(&prims), 3, true, false);
        assert!(cwbvh_depth(&bvh) <= MAX_DEPTH);
        for (x, y) in [(7.5, 0.5), (3.5, 20.5), (49.5, 59.5)] {
            let seen = boxes_seen(&bvh, boxes.len(), x, y);
            for (i, b) in boxes.iter().enumerate() {
                let under = b.min.x < x && x < b.max.x && b.min.y < y && y < b.max.y;
                // Quantised child boxes are conservative: boxes beside the ray may be seen too.
                assert!(seen[i] || !under, "box {i} under ({x}, {y}) was skipped");
            }
        }
    }
}
