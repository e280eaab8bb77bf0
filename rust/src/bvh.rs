//! BVH construction over boxes with obvhs (a compressed wide BVH8), used at both levels: over a
//! mesh's subpatches (object space) and over instances (render space).

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::cwbvh::node::CwBvhNode;
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

/// The children of `node` that `ray` enters, as obvhs's traversal wants them (its
/// `CwBvhNode::intersect_ray`: bit-for-bit the same mask, from the same float operations in the
/// same order). Written here because obvhs widens the quantised child planes one byte at a time
/// (48 scalar conversions a node, the larger part of its node test in the tracer's profile); on
/// x86-64 SSE2 widens eight at once, and the hit children are visited by their set bits.
#[inline(always)]
pub fn intersect_node(node: &CwBvhNode, ray: &obvhs::ray::Ray, oct_inv4: u32) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        intersect_node_sse2(node, ray, oct_inv4)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        node.intersect_ray(ray, oct_inv4)
    }
}

/// The slab distance below which obvhs's node test culls a child (`cwbvh::node::EPSILON`,
/// private to obvhs 0.4).
const NODE_T_MIN: f32 = 0.0001;

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn intersect_node_sse2(node: &CwBvhNode, ray: &obvhs::ray::Ray, oct_inv4: u32) -> u32 {
    use std::arch::x86_64::*;
    let dir_inv = node.compute_extent() * ray.inv_direction;
    let origin = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    // SAFETY: SSE2 is part of x86-64; the loads read exactly the eight bytes of each array.
    unsafe {
        // Eight quantised planes as two vectors of four floats (lanes 0-3, 4-7).
        let widen = |q: &[u8; 8]| -> [__m128; 2] {
            let zero = _mm_setzero_si128();
            let words = _mm_unpacklo_epi8(_mm_loadl_epi64(q.as_ptr().cast()), zero);
            [_mm_cvtepi32_ps(_mm_unpacklo_epi16(words, zero)), _mm_cvtepi32_ps(_mm_unpackhi_epi16(words, zero))]
        };
        let axis = |lo: &[u8; 8], hi: &[u8; 8], negative: bool, inv: f32, org: f32| -> ([__m128; 2], [__m128; 2]) {
            let (near, far) = if negative { (widen(hi), widen(lo)) } else { (widen(lo), widen(hi)) };
            let (inv, org) = (_mm_set1_ps(inv), _mm_set1_ps(org));
            let t = |q: __m128| _mm_add_ps(_mm_mul_ps(q, inv), org);
            ([t(near[0]), t(near[1])], [t(far[0]), t(far[1])])
        };
        let d = ray.direction;
        let (xn, xf) = axis(&node.child_min_x, &node.child_max_x, d.x < 0.0, dir_inv.x, origin.x);
        let (yn, yf) = axis(&node.child_min_y, &node.child_max_y, d.y < 0.0, dir_inv.y, origin.y);
        let (zn, zf) = axis(&node.child_min_z, &node.child_max_z, d.z < 0.0, dir_inv.z, origin.z);
        let (t_lo, t_hi) = (_mm_set1_ps(NODE_T_MIN), _mm_set1_ps(ray.tmax));
        let mut entered = 0u32;
        for h in 0..2 {
            let tmin = _mm_max_ps(_mm_max_ps(xn[h], _mm_max_ps(yn[h], zn[h])), t_lo);
            let tmax = _mm_min_ps(_mm_min_ps(xf[h], _mm_min_ps(yf[h], zf[h])), t_hi);
            entered |= (_mm_movemask_ps(_mm_cmple_ps(tmin, tmax)) as u32) << (4 * h);
        }
        let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
        let mut hit_mask = 0u32;
        while entered != 0 {
            let shift = 8 * entered.trailing_zeros();
            hit_mask |= (((child_bits8 >> shift) & 0xff) as u32) << ((bit_index8 >> shift) & 0xff);
            entered &= entered - 1;
        }
        hit_mask
    }
}

/// Visits the primitives of `bvh` whose boxes `ray` enters, nearest boxes first. `test(id)`
/// tests leaf primitive `id` (an index into `bvh.primitive_indices`) against the ray, clipped to
/// the nearest hit so far, and returns its hit distance; later boxes beyond it are skipped.
/// With `any_hit`, the first hit ends the traversal: obvhs's `ray_traverse` would go on popping
/// its stack through every box nearer than the hit, which an occlusion query never needs.
///
/// obvhs's own traversal order (its `traverse!` macro) over a state of the project's own
/// ([`Walk`]): obvhs's `new_traversal` zeroes a 32-entry stack and branches on each direction
/// component, ~60 instructions a traversal, and a shadow or AO ray makes two or three (the
/// top level and each instance it enters).
#[inline(always)]
pub fn walk(bvh: &CwBvh, ray: obvhs::ray::Ray, any_hit: bool, mut test: impl FnMut(usize) -> Option<f32>) {
    // The `traverse!` macro names `UVec2` unqualified.
    use glam::UVec2;
    let mut clipped = ray;
    let mut storage = std::mem::MaybeUninit::uninit();
    let mut state = Walk::new(bvh, ray.direction, &mut storage);
    let mut node;
    'traversal: {
        obvhs::traverse!(bvh, node, state, intersect_node(node, &clipped, state.oct_inv4), {
            if let Some(t) = test(state.primitive_id as usize) {
                if any_hit {
                    break 'traversal;
                }
                if t < clipped.tmax {
                    clipped.tmax = t;
                }
            }
        });
    }
}

/// The state obvhs's `traverse!` macro walks a CWBVH with (the fields it names), as obvhs's
/// `Traversal` starts it, but with a stack that is not zeroed first.
struct Walk<'s> {
    stack: WalkStack<'s>,
    current_group: glam::UVec2,
    primitive_group: glam::UVec2,
    oct_inv4: u32,
    primitive_id: u32,
    hitmask: u32,
}

impl<'s> Walk<'s> {
    #[inline(always)]
    fn new(bvh: &CwBvh, direction: Vec3A, storage: &'s mut std::mem::MaybeUninit<[glam::UVec2; WALK_STACK]>) -> Walk<'s> {
        Walk {
            stack: WalkStack { data: storage, index: 0 },
            current_group: if bvh.nodes.is_empty() { glam::UVec2::ZERO } else { glam::uvec2(0, 0x8000_0000) },
            primitive_group: glam::UVec2::ZERO,
            oct_inv4: octant_inv4(direction),
            primitive_id: 0,
            hitmask: 0,
        }
    }
}

/// obvhs's traversal stack depth (`TRAVERSAL_STACK_SIZE`, private to obvhs 0.4; see
/// [`MAX_DEPTH`]).
const WALK_STACK: usize = MAX_DEPTH as usize + 1;

/// obvhs's `StackStack` without its initialisation: an entry is read only after it was pushed
/// (the macro pops only a non-empty stack), so the zeroes were never read.
struct WalkStack<'s> {
    // A local of the walk's caller, not a field: inside the state, LLVM merged the array's
    // undefined contents with the zeroed fields beside it into one 268-byte memset.
    data: &'s mut std::mem::MaybeUninit<[glam::UVec2; WALK_STACK]>,
    index: usize,
}

impl obvhs::faststack::FastStack<glam::UVec2> for WalkStack<'_> {
    #[inline(always)]
    fn push(&mut self, v: glam::UVec2) {
        // As obvhs's: a push past the top overwrites the last entry (MAX_DEPTH keeps trees
        // shallower than that).
        // SAFETY: index < WALK_STACK always (clamped below).
        unsafe { self.data.as_mut_ptr().cast::<glam::UVec2>().add(self.index).write(v) };
        self.index = (self.index + 1).min(WALK_STACK - 1);
    }
    #[inline(always)]
    fn pop_fast(&mut self) -> glam::UVec2 {
        debug_assert!(self.index > 0, "pop_fast on an empty traversal stack");
        self.index = self.index.saturating_sub(1);
        // SAFETY: the traversal pops only after `is_empty` said no, so entry `index` was pushed.
        unsafe { self.data.as_ptr().cast::<glam::UVec2>().add(self.index).read() }
    }
    #[inline(always)]
    fn pop(&mut self) -> Option<glam::UVec2> {
        (self.index > 0).then(|| self.pop_fast())
    }
    #[inline(always)]
    fn len(&self) -> usize {
        self.index
    }
    #[inline(always)]
    fn is_empty(&self) -> bool {
        self.index == 0
    }
    #[inline(always)]
    fn clear(&mut self) {
        self.index = 0;
    }
}

/// obvhs's `ray_get_octant_inv4` (private to obvhs 0.4): per byte, bit 2 set when x is not
/// negative, bit 1 for y, bit 0 for z (−0.0 counts as not negative, as obvhs's `< 0.0` has it),
/// read from one vector comparison instead of three branches.
#[inline(always)]
fn octant_inv4(d: Vec3A) -> u32 {
    const BY_NEGATIVE: [u32; 8] = {
        let mut t = [0u32; 8];
        let mut m = 0;
        while m < 8 {
            let x = if m & 1 == 0 { 0x0404_0404 } else { 0 };
            let y = if m & 2 == 0 { 0x0202_0202 } else { 0 };
            let z = if m & 4 == 0 { 0x0101_0101 } else { 0 };
            t[m] = x | y | z;
            m += 1;
        }
        t
    };
    BY_NEGATIVE[(d.cmplt(Vec3A::ZERO).bitmask() & 7) as usize]
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
    fn node_test_is_obvhs_own_bit_for_bit() {
        // Every node of trees over random boxes (and over boxes sharing planes, where slab
        // distances tie), against rays of every octant, origins inside and outside, short and
        // unbounded reaches, axis-parallel directions: the same child mask as obvhs's test.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut trees = Vec::new();
        for grid in [false, true] {
            let boxes: Vec<Bounds3> = (0..2000)
                .map(|_| {
                    let mut c = Vec3A::new(next(), next(), next()) * 100.0 - 50.0;
                    if grid {
                        c = c.round();
                    }
                    let h = Vec3A::new(next(), next(), next()) * if grid { 1.0 } else { 5.0 };
                    Bounds3 { min: c - h, max: c + h }
                })
                .collect();
            trees.push(build_bvh(&boxes).unwrap());
        }
        let (mut tested, mut entered) = (0usize, 0usize);
        for bvh in &trees {
            for r in 0..300 {
                let o = Vec3A::new(next(), next(), next()) * 160.0 - 80.0;
                let mut d = Vec3A::new(next(), next(), next()) * 2.0 - 1.0;
                if r % 7 == 0 {
                    d = Vec3A::new(d.x, 0.0, 0.0);
                }
                let d = (d.normalize_or(Vec3A::X)) + Vec3A::ZERO;
                let t_max = if r % 3 == 0 { f32::INFINITY } else { next() * 60.0 };
                let ray = Ray::new(o, d, 0.0, t_max);
                let oct_inv4 = bvh.new_traversal(d).oct_inv4;
                for node in &bvh.nodes {
                    let mask = intersect_node(node, &ray, oct_inv4);
                    assert_eq!(mask, node.intersect_ray(&ray, oct_inv4), "ray {r}: {node:?}");
                    tested += 1;
                    entered += usize::from(mask != 0);
                }
            }
        }
        // The rays must enter some nodes and miss others, or the comparison says little.
        assert!(entered > tested / 500 && entered < tested, "{entered} of {tested} nodes entered");
    }

    #[test]
    fn octant_is_obvhs_own() {
        let bvh = build_bvh(&[Bounds3 { min: Vec3A::ZERO, max: Vec3A::ONE }]).unwrap();
        for x in [-2.0f32, -0.0, 0.0, 3.0] {
            for y in [-1.0f32, -0.0, 0.0, 0.5] {
                for z in [-7.0f32, -0.0, 0.0, 1e-30] {
                    let d = Vec3A::new(x, y, z);
                    assert_eq!(octant_inv4(d), bvh.new_traversal(d).oct_inv4, "{d}");
                }
            }
        }
    }

    #[test]
    fn walk_visits_what_obvhs_traversal_visits() {
        // Deep enough trees that the stack is pushed and popped; every primitive a closest-hit
        // walk tests, in obvhs's order, with each hit clipping the ray as obvhs's does.
        let mut seed = 7u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let boxes: Vec<Bounds3> = (0..3000)
            .map(|_| {
                let c = Vec3A::new(next(), next(), next()) * 100.0;
                Bounds3 { min: c, max: c + Vec3A::splat(0.5 + next() * 4.0) }
            })
            .collect();
        let bvh = build_bvh(&boxes).unwrap();
        let mut walked = 0usize;
        for r in 0..400 {
            let o = Vec3A::new(next(), next(), next()) * 140.0 - 20.0;
            let d = (Vec3A::new(next(), next(), next()) * 2.0 - 1.0).normalize_or(Vec3A::X) + Vec3A::ZERO;
            let ray = Ray::new(o, d, 0.0, f32::INFINITY);
            // Every fifth box "hits" at its entry distance, so the walk's clipping matters.
            let hit_at = |id: usize| {
                let b = &boxes[bvh.primitive_indices[id] as usize];
                let t0 = (b.min - o) * ray.inv_direction;
                let t1 = (b.max - o) * ray.inv_direction;
                let (near, far) = (t0.min(t1).max_element().max(0.0), t0.max(t1).min_element());
                (near <= far && bvh.primitive_indices[id] % 5 == 0).then_some(near)
            };
            let (mut ours, mut theirs) = (Vec::new(), Vec::new());
            walk(&bvh, ray, false, |id| {
                ours.push(id);
                hit_at(id)
            });
            let mut hit = RayHit::none();
            bvh.ray_traverse(ray, &mut hit, |_, id| {
                theirs.push(id);
                hit_at(id).unwrap_or(f32::INFINITY)
            });
            assert_eq!(ours, theirs, "ray {r}");
            walked += ours.len();
        }
        assert!(walked > 400, "the rays must reach primitives: {walked}");
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
