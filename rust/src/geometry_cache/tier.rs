//! The three tessellation rates of the multiresolution geometry cache (the paper's §5.2): a
//! coarse tier of 2×2 vertices (1 quad), a medium tier of 5×5 (4×4 quads) and a fine tier of
//! 17×17 (16×16 quads). Each is a level of the "tessellation MIP map"; the tier a ray uses is
//! chosen from its beam width by the tessellator, not here.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Bytes one stored vertex takes: an object-space position as `[f32; 3]` (the paper's §5.2,
/// "a vertex taking up 12 bytes").
pub const VERTEX_BYTES: usize = 12;

/// One level of the tessellation MIP map. Ordered from coarse to fine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Tier {
    /// 2×2 vertices, 1 quad: for wide, incoherent rays; many small entries, cheap to recompute.
    Coarse,
    /// 5×5 vertices, 4×4 quads: for rays neither very narrow nor very coherent.
    Medium,
    /// 17×17 vertices, 16×16 quads: for narrow, coherent rays; few large entries. Fine entries
    /// also carry 4×4 sub-bounding boxes (each over 4×4 quads) for the intersection test.
    Fine,
}

impl Tier {
    /// Every tier, coarse to fine; `Tier::ALL[t.index()] == t`.
    pub const ALL: [Tier; 3] = [Tier::Coarse, Tier::Medium, Tier::Fine];

    /// The number of tiers.
    pub const COUNT: usize = 3;

    /// 0, 1, 2 for coarse, medium, fine: the index into per-tier arrays such as
    /// [`CacheConfig::budget_bytes`](super::CacheConfig::budget_bytes).
    #[inline]
    pub const fn index(self) -> usize {
        match self {
            Tier::Coarse => 0,
            Tier::Medium => 1,
            Tier::Fine => 2,
        }
    }

    /// Vertices along one side of this tier's grid: 2, 5, 17.
    #[inline]
    pub const fn verts_per_side(self) -> u32 {
        match self {
            Tier::Coarse => 2,
            Tier::Medium => 5,
            Tier::Fine => 17,
        }
    }

    /// Quads along one side of this tier's grid: 1, 4, 16.
    #[inline]
    pub const fn quads_per_side(self) -> u32 {
        self.verts_per_side() - 1
    }

    /// Vertices in one grid: 4, 25, 289.
    #[inline]
    pub const fn vertex_count(self) -> u32 {
        self.verts_per_side() * self.verts_per_side()
    }

    /// Bytes of one grid's vertices, [`VERTEX_BYTES`] × verts²: 48, 300, 3468. This is what the
    /// paper counts per entry when it gives the caches' capacities (§5.2); it leaves out the fine
    /// tier's sub-bounding boxes and all bookkeeping.
    #[inline]
    pub const fn vertex_bytes(self) -> usize {
        VERTEX_BYTES * self.vertex_count() as usize
    }

    /// "coarse", "medium" or "fine": the name in stats and on command lines.
    #[inline]
    pub const fn name(self) -> &'static str {
        match self {
            Tier::Coarse => "coarse",
            Tier::Medium => "medium",
            Tier::Fine => "fine",
        }
    }
}

impl fmt::Display for Tier {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A tier name that is not "coarse", "medium" or "fine".
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error("unknown tessellation tier \"{name}\" (valid: coarse, medium, fine)")]
pub struct ParseTierError {
    /// The name that was given.
    pub name: String,
}

impl FromStr for Tier {
    type Err = ParseTierError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Tier::ALL.into_iter().find(|t| t.name() == s).ok_or_else(|| ParseTierError { name: s.to_owned() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_sizes_are_the_papers() {
        let got: Vec<_> = Tier::ALL.iter().map(|t| (t.verts_per_side(), t.quads_per_side(), t.vertex_count(), t.vertex_bytes())).collect();
        assert_eq!(got, [(2, 1, 4, 48), (5, 4, 25, 300), (17, 16, 289, 3468)]);
    }

    #[test]
    fn index_matches_all() {
        for (i, t) in Tier::ALL.into_iter().enumerate() {
            assert_eq!(t.index(), i);
        }
        assert_eq!(Tier::ALL.len(), Tier::COUNT);
        assert!(Tier::Coarse < Tier::Medium && Tier::Medium < Tier::Fine);
    }

    #[test]
    fn names_round_trip() {
        for t in Tier::ALL {
            assert_eq!(t.to_string(), t.name());
            assert_eq!(t.name().parse::<Tier>(), Ok(t));
            assert_eq!(serde_json::to_string(&t).ok(), Some(format!("\"{}\"", t.name())));
        }
        assert_eq!(["coarse", "medium", "fine"], Tier::ALL.map(Tier::name));
        let err = "Fine".parse::<Tier>().err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains("\"Fine\"") && err.contains("coarse, medium, fine"), "{err}");
    }
}
