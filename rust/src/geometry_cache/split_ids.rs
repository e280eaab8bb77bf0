//! Cache ids for split subpatches: the children a subpatch is cut into, on demand, when a beam
//! needs more than 16×16 quads over it (the paper's §5.1: "we subdivide it into even smaller
//! subpatches").
//!
//! A key's subpatch id must name the same piece of surface for as long as the cache may hold an
//! entry under it, or a lookup returns another piece's tessellation. Root subpatches are their
//! index in the mesh, fixed by its data. Children are numbered densely after the roots, in
//! order of first use, which keeps the ever-built bitsets one bit per child (see the `seen`
//! module); and since first use depends on the view, the image size and the threads' timing,
//! the numbering lives here, as long as the entries it names: one table per (mesh,
//! generation), dropped with the mesh's entries by
//! [`GeometryCache::invalidate_mesh`](super::GeometryCache::invalidate_mesh). (A numbering owned
//! by one render gave the same id to different children in two renders on one warm cache.)
//!
//! Why not a closed form of (root, depth, i, j)? Up to 6 split levels make 5,460 children per
//! root: 32-bit ids would run out at 786,000 roots in a mesh, spread-out ids would make the
//! bitsets megabytes per mesh, and wider keys would cost every resident entry 8 bytes.
//!
//! Memory: about 18 to 36 bytes per child ever split (a 16-byte slot of a hash map at its load),
//! for the life of the mesh in the cache, beside its fine tessellation's 4,052 bytes each time
//! it is resident; only magnified views split at all.

use std::collections::HashMap;
use std::sync::Arc;

use parking_lot::Mutex;

use super::seen::FxBuild;

/// The ids of one (mesh, generation)'s split subpatches. Shared by every render that uses the
/// cache; get it from [`GeometryCache::split_ids`](super::GeometryCache::split_ids).
#[derive(Debug)]
pub struct SplitIds {
    /// The first child id: the mesh's root subpatch count (roots keep their indices).
    first: u32,
    /// Child (as the caller packs it: the same piece of the same root, the same key) → id.
    ids: Mutex<HashMap<u64, u32, FxBuild>>,
}

impl SplitIds {
    pub(crate) fn new(first: u32) -> Self {
        SplitIds { first, ids: Mutex::new(HashMap::default()) }
    }

    /// The first child id (the root subpatch count it was made for).
    pub fn first(&self) -> u32 {
        self.first
    }

    /// The id of the child `child` (a one-to-one packing of its root, depth and cell): the one
    /// it was given before, or the next one.
    pub fn id(&self, child: u64) -> u32 {
        let mut ids = self.ids.lock();
        // Saturation cannot be reached: 2^32 children would hold 64 GB of this table first.
        let next = self.first.saturating_add(ids.len() as u32);
        *ids.entry(child).or_insert(next)
    }

    /// Children given ids so far.
    pub fn len(&self) -> usize {
        self.ids.lock().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Heap bytes of the table, roughly (hash map slots and control bytes).
    pub fn heap_bytes(&self) -> usize {
        self.ids.lock().capacity() * (std::mem::size_of::<(u64, u32)>() + 1)
    }
}

/// Every (mesh, generation)'s [`SplitIds`] of one cache.
#[derive(Default)]
pub(super) struct SplitIdTables {
    tables: Mutex<HashMap<(u32, u32), Arc<SplitIds>, FxBuild>>,
}

impl SplitIdTables {
    /// The table of (`mesh`, `generation`), made with `first` if it has none yet.
    pub(super) fn get(&self, mesh: u32, generation: u32, first: u32) -> Arc<SplitIds> {
        let mut t = self.tables.lock();
        let ids = t.entry((mesh, generation)).or_insert_with(|| Arc::new(SplitIds::new(first)));
        // One (mesh, generation) is one shape, so one root count: anything else means a caller
        // reused a mesh key for another mesh, which aliases every entry, not just children.
        debug_assert_eq!(ids.first, first, "mesh {mesh} generation {generation} has another root subpatch count");
        ids.clone()
    }

    /// Forgets every generation of `mesh`.
    pub(super) fn forget_mesh(&self, mesh: u32) {
        self.tables.lock().retain(|&(m, _), _| m != mesh);
    }

    pub(super) fn heap_bytes(&self) -> usize {
        let t = self.tables.lock();
        t.capacity() * (std::mem::size_of::<((u32, u32), Arc<SplitIds>)>() + 1)
            + t.values().map(|s| std::mem::size_of::<SplitIds>() + s.heap_bytes()).sum::<usize>()
    }
}
