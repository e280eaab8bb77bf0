//! Subpatches (the paper's §5.1): every patch of a mesh is a root subpatch with conservative
//! object-space bounds — its control hull grown by the displacement bound, along the patch's
//! normals where the surface can bound them ([`crate::patch::NormalCone`]) — and a bottom-level
//! BVH over them. Tessellation happens later, on demand, per subpatch.

use std::collections::HashMap;
use std::sync::{Arc, OnceLock};

use glam::Vec3A;
use obvhs::cwbvh::CwBvh;
use parking_lot::Mutex;

use crate::bounds::{Bounds3, MAX_COORDINATE};
use crate::bvh::build_bvh;
use crate::displacement::DisplacementShader;
use crate::geometry_cache::SplitIds;
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
    /// An undisplaced parallelogram: exact at one quad, never split (beyond the paper: the
    /// beam width bounds the error a rate may make; a flat affine patch makes none).
    pub affine: bool,
}

/// A root subpatch as a mesh keeps it: one whole patch (its domain the unit square) and its
/// bounds, in 32 bytes. A [`Subpatch`] takes 64 (its domain, and bounds of 16-byte-aligned
/// vectors); a scene of a million control faces keeps three million roots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RootSubpatch {
    min: [f32; 3],
    /// Patch index in the mesh's [`crate::patch::LimitSurface`].
    pub patch: u32,
    max: [f32; 3],
    /// See [`Subpatch::affine`].
    pub affine: bool,
    /// How far, per axis, the box was grown beyond the patch's hull, in 255ths of the
    /// displacement bound (255: all of it; less where the patch's normals lean away from the
    /// axis): the rate is sized by the hull, not by the growth.
    grow: [u8; 3],
}

impl RootSubpatch {
    /// The root of `patch`, bounded by `bounds` (grown uniformly by the displacement bound, if
    /// any).
    pub fn new(patch: u32, bounds: Bounds3, affine: bool) -> Self {
        RootSubpatch { min: bounds.min.into(), patch, max: bounds.max.into(), affine, grow: [255; 3] }
    }

    /// The root of `patch` whose limit surface lies in `hull`, displaced along normals whose
    /// largest |component| per axis is `reach` ([`crate::patch::NormalCone::reach`]) by at most
    /// `bound` (object units) either way.
    pub fn displaced(patch: u32, hull: Bounds3, reach: Vec3A, bound: f32, affine: bool) -> Self {
        // Rounded up, with a margin for the rounding of the normal the tessellator displaces
        // along (single precision, ~1e-7 of a unit vector).
        let grow = (reach + 1e-3).min(Vec3A::ONE).to_array().map(|r| (r * 255.0).ceil().clamp(0.0, 255.0) as u8);
        let g = Self::fractions(grow) * bound;
        RootSubpatch { min: (hull.min - g).into(), patch, max: (hull.max + g).into(), affine, grow }
    }

    fn fractions(grow: [u8; 3]) -> Vec3A {
        Vec3A::new(f32::from(grow[0]), f32::from(grow[1]), f32::from(grow[2])) / 255.0
    }

    /// The size the rate is chosen by (object units): the largest side of the patch's hull,
    /// i.e. of its box less the growth by `pad` (twice the displacement bound it was grown by).
    #[inline]
    pub fn hull_size(&self, bounds: &Bounds3, pad: f32) -> f32 {
        (bounds.diagonal() - Self::fractions(self.grow) * pad).max_element().max(0.0)
    }

    /// Object space, grown by the mesh's displacement bound.
    #[inline]
    pub fn bounds(&self) -> Bounds3 {
        Bounds3 { min: self.min.into(), max: self.max.into() }
    }

    /// The part `rect` of this root (a split child, or `UvRect::UNIT` for the root itself), with
    /// the root's bounds.
    pub fn subpatch(&self, rect: UvRect) -> Subpatch {
        Subpatch { patch: self.patch, rect, bounds: self.bounds(), affine: self.affine }
    }
}

/// Where a split child lies: its root subpatch, split depth, and cell (i along u, j along v) of
/// the root's 2^depth × 2^depth grid of children.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ChildCell {
    pub root: u32,
    pub depth: u8,
    pub i: u32,
    pub j: u32,
}

impl ChildCell {
    /// The child's domain within its root's domain `root`.
    pub fn rect(&self, root: &UvRect) -> UvRect {
        let n = (1u32 << self.depth) as f32;
        let (du, dv) = ((root.u1 - root.u0) / n, (root.v1 - root.v0) / n);
        UvRect {
            u0: root.u0 + du * self.i as f32,
            v0: root.v0 + dv * self.j as f32,
            u1: root.u0 + du * (self.i + 1) as f32,
            v1: root.v0 + dv * (self.j + 1) as f32,
        }
    }

    /// The cell as one number, one-to-one for depths up to 12 (splits stop at
    /// [`crate::tessellate::MAX_SPLIT_DEPTH`]): the key of its [`SplitIds`] entry.
    pub fn key(&self) -> u64 {
        debug_assert!(self.depth <= 12 && self.i >> self.depth == 0 && self.j >> self.depth == 0, "{self:?}");
        (u64::from(self.root) << 32) | (u64::from(self.depth) << 24) | (u64::from(self.j) << 12) | u64::from(self.i)
    }

    /// The four children one level down, (i, j) order: (0,0), (1,0), (0,1), (1,1).
    pub fn children(&self) -> [ChildCell; 4] {
        let c = |di: u32, dj: u32| ChildCell { root: self.root, depth: self.depth + 1, i: self.i * 2 + di, j: self.j * 2 + dj };
        [c(0, 0), c(1, 0), c(0, 1), c(1, 1)]
    }
}

/// Cache ids of one mesh's split children in one render. The ids come from the cache's
/// [`SplitIds`] (the paper's §5.1: "we subdivide it into even smaller subpatches"), which
/// numbers children densely after the roots and keeps each child's id for as long as the cache
/// keeps entries under it: a render that numbered its own children would give a child the id
/// another child had in an earlier render on the same cache, and be served that child's
/// tessellation. Roots keep their indices.
pub struct ChildIds {
    table: Arc<SplitIds>,
    /// The children this render asked for, and their ids: `len` reports them, and lookups
    /// after the first stay off the cache-wide table's lock.
    used: Mutex<HashMap<ChildCell, u32>>,
}

impl ChildIds {
    /// Children's ids from `table`, which numbers them after the mesh's root subpatches.
    pub fn new(table: Arc<SplitIds>) -> Self {
        ChildIds { table, used: Mutex::new(HashMap::new()) }
    }

    /// The id of a child (or of the root itself at depth 0).
    #[inline]
    pub fn id(&self, cell: ChildCell) -> u32 {
        // Roots are nearly every look-up: their id is their index, with no call and no lock.
        if cell.depth == 0 {
            cell.root
        } else {
            self.child_id(cell)
        }
    }

    #[cold]
    fn child_id(&self, cell: ChildCell) -> u32 {
        if let Some(&id) = self.used.lock().get(&cell) {
            return id;
        }
        let id = self.table.id(cell.key());
        self.used.lock().insert(cell, id);
        id
    }

    /// Children this render asked for.
    pub fn len(&self) -> usize {
        self.used.lock().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A mesh prepared for tracing: its root subpatches and a BVH over them (object space).
/// Shared by all instances of the mesh.
pub struct MeshGeometry {
    /// One per patch with bounds (a patch whose bounds are empty has no surface to hit).
    pub subpatches: Vec<RootSubpatch>,
    /// `None` when the mesh has no patches (all holes, or empty).
    pub bvh: Option<CwBvh>,
    pub bounds: Bounds3,
    /// Ids of split children, given as rays ask for them.
    pub child_ids: ChildIds,
    /// The fewest quads a side any root subpatch is read at (0: no floor): for a displacement
    /// whose detail is known ([`crate::displacement::DisplacementShader::shortest_wavelength`]),
    /// the rate at which the mesh's largest patch keeps that detail at full weight, at most the
    /// fine tier's 16 (see [`MeshGeometry::displaced_rate_floor`]). A texture's floor is
    /// [`MeshGeometry::texture_rate_floor`].
    pub rate_floor: f32,
    /// [`MeshGeometry::texture_rate_floor`], once computed.
    texture_rate_floor: OnceLock<f32>,
    /// The surface deforms within the shutter ([`crate::deform`]): its grids are blended at
    /// each ray's time.
    pub deforms: bool,
    /// The surface's trim curves ([`crate::trim`]): hits they cut away are passed over.
    pub trim: Option<crate::trim::SharedTrim>,
}

impl MeshGeometry {
    /// Builds the root subpatches and their BVH. `split_ids(roots)` is the geometry cache's
    /// table of split children's ids for this mesh and generation, given its root count.
    ///
    /// # Errors
    /// A subpatch's bounds (with the displacement bound) are not finite or reach beyond
    /// [`MAX_COORDINATE`]: the message says how far.
    pub fn build(mesh: &Mesh, split_ids: impl FnOnce(u32) -> Arc<SplitIds>) -> Result<Self, String> {
        let s = &mesh.surface;
        let grow = mesh.displacement_bound.max(0.0);
        let mut subpatches: Vec<RootSubpatch> = (0..s.patch_count())
            .map(|i| (i, s.patch_bounds(i)))
            .filter(|(_, b)| !b.is_empty())
            .map(|(i, hull)| {
                let affine = mesh.displacement.is_none() && s.patch_is_affine(i);
                // Displacement moves points along the normal only: where the surface bounds
                // its normals, the box grows by the bound along them (a displaced AO ray tested
                // 1.9 subpatches with boxes grown every way, against 0.73 with none).
                let cone = (grow > 0.0).then(|| s.patch_normal_cone(i)).flatten();
                match cone {
                    Some(c) => RootSubpatch::displaced(i as u32, hull, c.reach(), grow, affine),
                    None => RootSubpatch::new(i as u32, hull.expanded(grow), affine),
                }
            })
            .collect();
        if let Some(sp) = subpatches.iter().find(|sp| !sp.bounds().is_traceable()) {
            return Err(format!(
                "patch {} reaches {:e} (displacement bound {grow:e}), beyond the traceable ±{MAX_COORDINATE:e}",
                sp.patch,
                sp.bounds().max_abs()
            ));
        }
        // Collected through a filter, the vector may hold twice its length: give it back.
        subpatches.shrink_to_fit();
        let boxes: Vec<Bounds3> = subpatches.iter().map(RootSubpatch::bounds).collect();
        let bounds = boxes.iter().fold(Bounds3::EMPTY, |b, sb| b.union(sb));
        let bvh = build_bvh(&boxes);
        let child_ids = ChildIds::new(split_ids(subpatches.len() as u32));
        let rate_floor = mesh.displacement.as_ref().and_then(|d| d.shortest_wavelength()).map_or(0.0, |wavelength| {
            let largest = subpatches.iter().map(|sp| sp.hull_size(&sp.bounds(), 2.0 * grow)).fold(0.0, f32::max);
            Self::displaced_rate_floor(largest, wavelength)
        });
        Ok(MeshGeometry {
            subpatches,
            bvh,
            bounds,
            child_ids,
            rate_floor,
            texture_rate_floor: OnceLock::new(),
            deforms: s.deformation().is_some(),
            trim: s.trim(),
        })
    }

    /// The rate floor (quads a side, at most 16) of `mesh` (this geometry's) when it is displaced
    /// by a texture, computed at the first call: a texture's detail is its finest level's texels
    /// over the patches' `st`, so the floor is the rate at which the patch with the most texels
    /// across reads that level alone ([`crate::displacement::TextureDisplacement::finest_level_rate`]; one floor for
    /// the whole mesh, as for the procedural floor), the cap 16 where the level's size is
    /// unknown. 0 for a mesh not displaced by a texture. Lazy, so a render without the floor
    /// (`displacementRateFloor` off) samples no `st` for it.
    pub fn texture_rate_floor(&self, mesh: &Mesh) -> f32 {
        let Some(DisplacementShader::Texture(t)) = mesh.displacement.as_ref() else {
            return 0.0;
        };
        *self.texture_rate_floor.get_or_init(|| {
            self.subpatches
                .iter()
                .map(|sp| t.finest_level_rate(mesh.surface.as_ref(), sp.patch as usize).unwrap_or(16.0))
                .fold(0.0, f32::max)
                .clamp(0.0, 16.0)
        })
    }

    /// The texture rate floor if [`MeshGeometry::texture_rate_floor`] has computed it.
    pub fn texture_rate_floor_computed(&self) -> Option<f32> {
        self.texture_rate_floor.get().copied()
    }

    /// The rate floor (quads a side, at most 16) of a displaced mesh whose largest patch spans
    /// `largest` object units (its box's largest side, as rates are sized) and whose
    /// displacement's shortest wavelength is `wavelength` object units: grids no coarser keep
    /// every detail at full weight ([`crate::displacement::FULL_WEIGHT_SPACINGS`] spacings a
    /// wavelength; a patch's rows run across its box, up to √3 times its largest side).
    ///
    /// Filtered at two spacings, a displaced patch is two surfaces up to the whole displacement
    /// bound apart: neighbours read at different rates leave cracks between them, and a ray
    /// leaving one rate's grid can start beyond another's (issue 23, docs/cracks.md). One floor
    /// for the whole mesh, so neighbours of different sizes are read alike by wide rays.
    pub fn displaced_rate_floor(largest: f32, wavelength: f32) -> f32 {
        let quads = crate::displacement::FULL_WEIGHT_SPACINGS * 3f32.sqrt() * largest / wavelength;
        if quads.is_finite() {
            quads.clamp(0.0, 16.0)
        } else {
            16.0
        }
    }

    /// A mesh left out of the render: nothing to hit.
    pub fn empty() -> Self {
        MeshGeometry {
            subpatches: Vec::new(),
            bvh: None,
            bounds: Bounds3::EMPTY,
            child_ids: ChildIds::new(Arc::new(SplitIds::new(0))),
            rate_floor: 0.0,
            texture_rate_floor: OnceLock::new(),
            deforms: false,
            trim: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry_cache::{CacheConfig, GeometryCache};

    #[test]
    fn child_rects_tile_the_root_and_ids_are_dense_and_stable() {
        let root = UvRect { u0: 0.0, v0: 0.5, u1: 0.5, v1: 1.0 };
        let c = ChildCell { root: 3, depth: 2, i: 1, j: 3 };
        assert_eq!(c.rect(&root), UvRect { u0: 0.125, v0: 0.875, u1: 0.25, v1: 1.0 });
        let kids = ChildCell { root: 3, depth: 0, i: 0, j: 0 }.children();
        let area: f32 = kids
            .iter()
            .map(|k| {
                let r = k.rect(&root);
                (r.u1 - r.u0) * (r.v1 - r.v0)
            })
            .sum();
        assert!((area - 0.25).abs() < 1e-7);
        let cache = GeometryCache::<Vec<[f32; 3]>>::new(CacheConfig::default());
        let ids = ChildIds::new(cache.split_ids(7, 0, 10));
        assert_eq!(ids.id(ChildCell { root: 4, depth: 0, i: 0, j: 0 }), 4);
        let a = ids.id(c);
        let b = ids.id(kids[0]);
        assert_eq!((a, b), (10, 11));
        assert_eq!(ids.id(c), 10);
        assert_eq!(ids.len(), 2);
        // A later render on the same cache asks in another order, and for a new child too: the
        // children it shares with the first keep their ids, the new one gets the next.
        let again = ChildIds::new(cache.split_ids(7, 0, 10));
        assert_eq!((again.id(kids[1]), again.id(kids[0]), again.id(c)), (12, 11, 10));
        assert_eq!(again.len(), 3);
        // Another generation is another shape: its children are numbered afresh.
        assert_eq!(ChildIds::new(cache.split_ids(7, 1, 10)).id(kids[1]), 10);
        // Invalidating the mesh forgets its ids with its entries.
        cache.invalidate_mesh(7);
        assert_eq!(ChildIds::new(cache.split_ids(7, 0, 10)).id(kids[1]), 10);
    }

    /// The record a mesh keeps per patch (issue 15: a million control faces make three million).
    #[test]
    fn roots_are_32_bytes_and_give_back_their_bounds() {
        assert_eq!(std::mem::size_of::<RootSubpatch>(), 32);
        let b = Bounds3 { min: glam::Vec3A::new(-1.0, 2.0, -3.5), max: glam::Vec3A::new(4.0, 5.25, 6.0) };
        let r = RootSubpatch::new(7, b, true);
        assert_eq!(r.bounds(), b);
        let c = ChildCell { root: 0, depth: 1, i: 1, j: 0 }.rect(&UvRect::UNIT);
        assert_eq!(r.subpatch(c), Subpatch { patch: 7, rect: c, bounds: b, affine: true });
    }

    #[test]
    fn cell_keys_are_one_to_one() {
        let mut keys = std::collections::HashSet::new();
        let mut cells = 0;
        for root in [0, 1, u32::MAX] {
            let mut level = vec![ChildCell { root, depth: 0, i: 0, j: 0 }];
            for _ in 0..crate::tessellate::MAX_SPLIT_DEPTH {
                level = level.iter().flat_map(|c| c.children()).collect();
                cells += level.len();
                keys.extend(level.iter().map(ChildCell::key));
            }
        }
        assert_eq!(cells, 3 * 5460);
        assert_eq!(keys.len(), cells);
    }
}
