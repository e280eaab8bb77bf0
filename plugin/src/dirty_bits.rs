//! Dirty bits, as Hydra's `HdChangeTracker`: what changed on a prim since its last sync, so sync
//! does only the work the edit calls for.

/// A set of dirty flags.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DirtyBits(pub u32);

impl DirtyBits {
    pub const CLEAN: DirtyBits = DirtyBits(0);
    pub const POINTS: DirtyBits = DirtyBits(1 << 0);
    pub const TOPOLOGY: DirtyBits = DirtyBits(1 << 1);
    pub const TRANSFORM: DirtyBits = DirtyBits(1 << 2);
    pub const MATERIAL: DirtyBits = DirtyBits(1 << 3);
    pub const VISIBILITY: DirtyBits = DirtyBits(1 << 4);
    pub const PARAMS: DirtyBits = DirtyBits(1 << 5);
    pub const ALL: DirtyBits = DirtyBits(0x3f);

    pub const fn contains(self, o: DirtyBits) -> bool {
        self.0 & o.0 != 0
    }

    pub const fn union(self, o: DirtyBits) -> DirtyBits {
        DirtyBits(self.0 | o.0)
    }

    pub const fn is_clean(self) -> bool {
        self.0 == 0
    }
}

impl std::ops::BitOr for DirtyBits {
    type Output = DirtyBits;
    fn bitor(self, o: DirtyBits) -> DirtyBits {
        self.union(o)
    }
}
