//! Tessellation of a subpatch at one of the cache's tier rates (the paper's §5.2), and the choice
//! of rate from a ray's beam width.
//!
//! Three rates are stored — coarse 2×2 vertices (1 quad), medium 5×5 (4×4 quads), fine 17×17
//! (16×16 quads, with 4×4 sub-bounding boxes) — and two more are used by merging 2×2 quads of the
//! next finer tier: 2×2 quads from the medium grid, 8×8 from the fine one. Five effective rates
//! from three stored, as the paper says.

use glam::Vec3A;

use crate::bounds::Bounds3;
use crate::displacement::DisplacementShader;
use crate::geometry_cache::{CacheEntry, Tier};
use crate::patch::{GridSamples, LimitSurface};
use crate::subpatch::Subpatch;

/// An effective tessellation rate: quads per side of a subpatch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Rate {
    R1,
    R2,
    R4,
    R8,
    R16,
}

impl Rate {
    pub const ALL: [Rate; 5] = [Rate::R1, Rate::R2, Rate::R4, Rate::R8, Rate::R16];

    /// Quads per side.
    pub const fn quads(self) -> usize {
        match self {
            Rate::R1 => 1,
            Rate::R2 => 2,
            Rate::R4 => 4,
            Rate::R8 => 8,
            Rate::R16 => 16,
        }
    }

    /// The stored tier this rate reads, and the vertex stride within it (2 = merged quads).
    pub const fn tier_and_stride(self) -> (Tier, usize) {
        match self {
            Rate::R1 => (Tier::Coarse, 1),
            Rate::R2 => (Tier::Medium, 2),
            Rate::R4 => (Tier::Medium, 1),
            Rate::R8 => (Tier::Fine, 2),
            Rate::R16 => (Tier::Fine, 1),
        }
    }

    /// The rate whose quads are about as wide as the beam: `size_world` is the subpatch's size
    /// (world units), `beam_width` the ray's beam width where it reaches the subpatch (world
    /// units), `tess_factor` scales the quad size (larger is coarser). Returns the finest rate
    /// needed, rounding up; `None` means even 16×16 quads are too coarse (the subpatch should
    /// be split, see [`split_depth`]). A non-finite or zero width asks for the finest rate.
    pub fn for_beam(size_world: f32, beam_width: f32, tess_factor: f32) -> Option<Rate> {
        let needed = needed_quads(size_world, beam_width, tess_factor);
        Rate::ALL.into_iter().find(|r| r.quads() as f32 >= needed)
    }
}

/// Quads per side a subpatch of `size_world` needs for a beam `beam_width` wide (both world
/// units); 16 when the width is unusable (zero, negative, NaN), so a bad differential falls back
/// to the finest stored rate rather than to a split storm or a coarse guess.
pub fn needed_quads(size_world: f32, beam_width: f32, tess_factor: f32) -> f32 {
    let quad = beam_width * tess_factor;
    if !(quad.is_finite() && quad > 0.0 && size_world.is_finite()) {
        return 16.0;
    }
    size_world / quad
}

/// Deepest subpatch split: 16·2⁶ = 1024 quads per side of a root patch.
pub const MAX_SPLIT_DEPTH: u32 = 6;

/// How many times to halve a subpatch so 16×16 quads per child meet `needed` quads per side.
pub fn split_depth(needed: f32) -> u32 {
    if needed <= 16.0 {
        return 0;
    }
    ((needed / 16.0).log2().ceil() as u32).clamp(1, MAX_SPLIT_DEPTH)
}

/// One cache entry: a subpatch's limit surface on a tier's vertex grid, object space.
#[derive(Clone, Debug, PartialEq)]
pub struct Tessellation {
    /// Vertices per side.
    pub n: usize,
    /// `n × n` vertices, u fastest (index `j * n + i`): 12 bytes each, as in the paper.
    pub verts: Vec<[f32; 3]>,
    /// Fine tier only: 4×4 boxes, each over 4×4 quads (row-major, u fastest).
    pub sub_boxes: Vec<Bounds3>,
    /// Fine tier only: an estimate of how far the limit surface strays from the grid's quads
    /// (object units): twice the largest distance, at 16 probe points, between the surface and
    /// the bilinear quad under it. Pads the bounds of split children.
    pub chord_error: f32,
    /// How far the limit surface's edge curves stray from the grid's boundary chords, plus a
    /// rounding margin (object units): the half-width of the seam boxes that close cracks
    /// between neighbours tessellated at different rates (see [`crate::seam`]).
    pub seam_radius: f32,
    /// Which part of the grid is surface: all of it, or only the half u + v ≤ 1 of a triangle
    /// (Loop) patch, whose basis extrapolates beyond its domain.
    pub domain: GridDomain,
}

/// The part of a grid over a subpatch that is surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum GridDomain {
    /// All of it: square patches, and children of triangle patches inside the triangle.
    #[default]
    Square,
    /// The lower-left half (grid-local u + v ≤ 1): a triangle patch, or a split child on its
    /// diagonal (children are dyadic squares, so the diagonal runs corner to corner).
    LowerTriangle,
    /// None: a split child of a triangle patch beyond its diagonal.
    Empty,
}

impl GridDomain {
    /// The domain of a grid over `rect` of a patch of `kind`.
    pub fn of(kind: crate::patch::PatchKind, rect: &crate::patch::UvRect) -> GridDomain {
        const EPS: f32 = 1e-6;
        if !kind.is_triangle() || rect.u1 + rect.v1 <= 1.0 + EPS {
            GridDomain::Square
        } else if rect.u0 + rect.v0 >= 1.0 - EPS {
            GridDomain::Empty
        } else {
            GridDomain::LowerTriangle
        }
    }
}

impl CacheEntry for Tessellation {
    fn byte_size(&self) -> usize {
        self.verts.len() * std::mem::size_of::<[f32; 3]>()
            + self.sub_boxes.len() * std::mem::size_of::<Bounds3>()
            + 2 * std::mem::size_of::<f32>()
    }

    fn vertex_count(&self) -> usize {
        self.verts.len()
    }
}

impl Tessellation {
    /// Vertex (i, j) as a vector.
    #[inline]
    pub fn vert(&self, i: usize, j: usize) -> Vec3A {
        Vec3A::from(self.verts[j * self.n + i])
    }
}

/// How a mesh is displaced: the function, the side its normal points to (−1 for leftHanded
/// meshes) and the bound its subpatch boxes were grown by.
#[derive(Clone, Debug)]
pub struct DisplaceParams {
    pub displacement: DisplacementShader,
    pub normal_sign: f32,
    pub bound: f32,
}

/// Tessellates `sub` of `surface` on `tier`'s grid: one grid evaluation, displacement along the
/// limit normal filtered at the grid's own spacing, then (for the fine tier) the 4×4 sub-boxes.
/// Returns the tessellation and how many displaced vertices left `sub.bounds` (counted, never
/// clipped). `scratch` is reused between calls to avoid allocation.
pub fn tessellate(
    surface: &dyn LimitSurface,
    sub: &Subpatch,
    tier: Tier,
    displace: Option<&DisplaceParams>,
    scratch: &mut GridSamples,
) -> (Tessellation, u32) {
    let n = tier.verts_per_side() as usize;
    surface.evaluate_grid(sub.patch as usize, sub.rect, n, displace.is_some(), scratch);
    // Measured on the undisplaced grid: seams follow the limit surface's edges.
    let seam_radius = crate::seam::seam_radius(surface, sub.patch as usize, sub.rect, &scratch.p, n);
    let mut verts = std::mem::take(&mut scratch.p);
    let mut outside = 0;
    if let Some(d) = displace {
        let mut offsets = Vec::with_capacity(n * n);
        d.displacement.grid_offsets(surface, sub.patch as usize, sub.rect, &verts, n, &mut offsets);
        for (k, v) in verts.iter_mut().enumerate() {
            let p = Vec3A::from(*v);
            let nrm = (Vec3A::from(scratch.dpdu[k]).cross(Vec3A::from(scratch.dpdv[k]))).normalize_or_zero() * d.normal_sign;
            let q = p + nrm * offsets[k];
            if !(q.cmpge(sub.bounds.min).all() && q.cmple(sub.bounds.max).all()) {
                outside += 1;
            }
            *v = q.into();
        }
    }
    let domain = GridDomain::of(surface.patch_param(sub.patch as usize).kind, &sub.rect);
    let mut t = Tessellation { n, verts, sub_boxes: Vec::new(), chord_error: 0.0, seam_radius, domain };
    if tier == Tier::Fine {
        t.sub_boxes = (0..16)
            .map(|b| {
                let (bi, bj) = (b % 4 * 4, b / 4 * 4);
                let mut bb = Bounds3::EMPTY;
                for j in bj..=bj + 4 {
                    for i in bi..=bi + 4 {
                        bb.grow(t.vert(i, j));
                    }
                }
                bb
            })
            .collect();
    }
    t.chord_error = 2.0 * probe_chord_error(surface, sub, &t);
    if let Some(d) = displace {
        // The probe measures the undisplaced surface; displacement detail finer than the
        // grid is filtered out, so what remains strays from the quads by at most its bound.
        t.chord_error += d.bound.min(2.0 * d.displacement.bound());
    }
    (t, outside)
}

/// Largest distance between the surface and the bilinear interpolation of the grid, probed at
/// the centre of up to 4×4 quads spread over the grid (16 evaluations for a fine grid, 5% of its
/// cost; 4 for a medium one; 1 for a coarse one).
fn probe_chord_error(surface: &dyn LimitSurface, sub: &Subpatch, t: &Tessellation) -> f32 {
    let quads = t.n - 1;
    let q = quads as f32;
    let k = quads.min(4);
    let mut err: f32 = 0.0;
    for b in 0..k * k {
        let (i, j) = ((b % k) * quads / k + (quads / k) / 2, (b / k) * quads / k + (quads / k) / 2);
        let inside = match t.domain {
            GridDomain::Square => true,
            GridDomain::LowerTriangle => (i + j + 1) as f32 <= q,
            GridDomain::Empty => false,
        };
        if !inside {
            continue;
        }
        let (lu, lv) = ((i as f32 + 0.5) / q, (j as f32 + 0.5) / q);
        let u = sub.rect.u0 + (sub.rect.u1 - sub.rect.u0) * lu;
        let v = sub.rect.v0 + (sub.rect.v1 - sub.rect.v0) * lv;
        let s = surface.evaluate(sub.patch as usize, u, v).p;
        let quad = (t.vert(i, j) + t.vert(i + 1, j) + t.vert(i + 1, j + 1) + t.vert(i, j + 1)) * 0.25;
        err = err.max((s - quad).length());
    }
    if err.is_finite() {
        err
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bilinear::BilinearSurface;
    use crate::patch::UvRect;
    use crate::topology::{MeshTopology, Scheme};

    #[test]
    fn rate_boundaries_round_up() {
        // A 1-unit subpatch hit by a beam 1/4 unit wide wants 4 quads; just wider wants 4, just
        // narrower wants 8; tessFactor 2 halves the need.
        assert_eq!(Rate::for_beam(1.0, 0.25, 1.0), Some(Rate::R4));
        assert_eq!(Rate::for_beam(1.0, 0.2501, 1.0), Some(Rate::R4));
        assert_eq!(Rate::for_beam(1.0, 0.2499, 1.0), Some(Rate::R8));
        assert_eq!(Rate::for_beam(1.0, 0.2501, 2.0), Some(Rate::R2));
        assert_eq!(Rate::for_beam(1.0, 0.2499, 2.0), Some(Rate::R4));
        assert_eq!(Rate::for_beam(1.0, 2.0, 1.0), Some(Rate::R1));
        assert_eq!(Rate::for_beam(1.0, 1.0 / 16.0, 1.0), Some(Rate::R16));
        assert_eq!(Rate::for_beam(1.0, 0.9 / 16.0, 1.0), None);
        assert_eq!(Rate::for_beam(1.0, f32::NAN, 1.0), Some(Rate::R16));
        assert_eq!(Rate::for_beam(1.0, 0.0, 1.0), Some(Rate::R16));
        assert_eq!(split_depth(16.0), 0);
        assert_eq!(split_depth(16.1), 1);
        assert_eq!(split_depth(32.0), 1);
        assert_eq!(split_depth(33.0), 2);
        assert_eq!(split_depth(1e9), MAX_SPLIT_DEPTH);
    }

    #[test]
    fn merged_rate_vertices_equal_the_coarser_grid() {
        // Every other vertex of the fine grid is the 9×9 grid of the same surface: the merged
        // 8×8 rate is exactly a coarser tessellation, not an approximation of one.
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.3], [1.0, 1.0, 0.0], [0.0, 1.0, 0.7]];
        let topo =
            MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
        let s = BilinearSurface::new(&topo, &pts).unwrap();
        let sub = Subpatch { patch: 0, rect: UvRect::UNIT, bounds: s.patch_bounds(0), affine: false };
        let mut scratch = GridSamples::default();
        let (fine, _) = tessellate(&s, &sub, Tier::Fine, None, &mut scratch);
        let mut nine = GridSamples::default();
        s.evaluate_grid(0, UvRect::UNIT, 9, false, &mut nine);
        for j in 0..9 {
            for i in 0..9 {
                assert_eq!(fine.verts[2 * j * 17 + 2 * i], nine.p[j * 9 + i]);
            }
        }
        assert_eq!(fine.sub_boxes.len(), 16);
        assert_eq!(fine.byte_size(), 17 * 17 * 12 + 16 * std::mem::size_of::<Bounds3>() + 8);
        let (medium, _) = tessellate(&s, &sub, Tier::Medium, None, &mut scratch);
        assert_eq!(medium.verts.len(), 25);
        assert!(medium.sub_boxes.is_empty());
    }
}
