//! Tessellation of a subpatch at one of the cache's tier rates (the paper's §5.2), and the choice
//! of rate from a ray's beam width.
//!
//! Three rates are stored — coarse 2×2 vertices (1 quad), medium 5×5 (4×4 quads), fine 17×17
//! (16×16 quads, with 4×4 sub-bounding boxes) — and two more are used by merging 2×2 quads of the
//! next finer tier: 2×2 quads from the medium grid, 8×8 from the fine one. Five effective rates
//! from three stored, as the paper says.

use std::sync::Arc;

use glam::Vec3A;

use crate::bounds::Bounds3;
use crate::displacement::DisplacementShader;
use crate::geometry_cache::{CacheEntry, Tier};
use crate::patch::{GridSamples, LimitSurface};
use crate::seam::SeamNormal;
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
        Rate::at_least(needed_quads(size_world, beam_width, tess_factor))
    }

    /// The coarsest rate with at least `needed` quads a side; `None` beyond 16 (or NaN).
    #[inline]
    pub fn at_least(needed: f32) -> Option<Rate> {
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
///
/// The cache keeps resident entries by value in its LRU nodes, as a [`StoredTessellation`], and
/// hands out `Tessellation`s made from them (see [`crate::geometry_cache`]), so both are laid out
/// to be small and cheap to make: a coarse grid's 4 vertices are inline (no heap allocation at
/// all: the coarse tier holds hundreds of thousands of them), a medium or fine grid's vertices
/// and its boxes live in one shared, immutable allocation each, so a copy is a
/// reference-count increment. 96 bytes (pinned by a test).
#[derive(Clone, Debug, PartialEq)]
pub struct Tessellation {
    /// Vertices per side.
    pub n: usize,
    /// `n × n` vertices, u fastest (index `j * n + i`): 12 bytes each, as in the paper.
    pub verts: GridVerts,
    /// Medium and fine tiers: the cull box, and a fine grid's 4×4 sub-boxes ([`GridBoxes`]).
    pub boxes: GridBoxes,
    /// Fine tier only: an estimate of how far the limit surface strays from the grid's quads
    /// (object units): twice the largest distance, at 16 probe points, between the surface and
    /// the bilinear quad under it. Pads the bounds of split children.
    pub chord_error: f32,
    /// How far the limit surface's edge curves stray from the grid's boundary chords, plus a
    /// rounding margin (object units): the half-width of the seam boxes that close cracks
    /// between neighbours tessellated at different rates (see [`crate::seam`]).
    pub seam_radius: f32,
    /// How far, of `seam_radius`, the seam boxes reach below and above the boundary chords
    /// along their normals (see [`crate::seam::SeamNormal`]): as far as the edge curves do.
    pub seam_normal: SeamNormal,
    /// Which part of the grid is surface: all of it, or only the half u + v ≤ 1 of a triangle
    /// (Loop) patch, whose basis extrapolates beyond its domain.
    pub domain: GridDomain,
}

/// A grid's vertices, read as a slice (`Deref<Target = [[f32; 3]]>`). Made from a `Vec` with
/// `.into()`. Four vertices (a coarse 2×2 grid) are stored inline; more are stored once, behind
/// an `Arc`, so cloning never copies a medium or fine grid. Equal when the vertices are.
#[derive(Clone)]
pub struct GridVerts(VertStore);

#[derive(Clone)]
enum VertStore {
    Quad([[f32; 3]; 4]),
    Shared(Arc<[[f32; 3]]>),
}

impl GridVerts {
    /// The vertices as a slice.
    #[inline]
    pub fn as_slice(&self) -> &[[f32; 3]] {
        match &self.0 {
            VertStore::Quad(v) => v,
            VertStore::Shared(v) => v,
        }
    }

    /// Heap bytes this grid holds beyond the `Tessellation` itself: 0 for an inline coarse
    /// grid, else the shared block (its 16-byte reference counts and the vertices).
    pub fn heap_bytes(&self) -> usize {
        match &self.0 {
            VertStore::Quad(_) => 0,
            VertStore::Shared(v) => 2 * std::mem::size_of::<usize>() + std::mem::size_of_val::<[[f32; 3]]>(v),
        }
    }

    /// `v` as grid vertices: inline if they are 4, else in `block` if it has room for exactly
    /// them and nothing else shares it (an evicted entry's), else in a new block.
    fn refill(v: &[[f32; 3]], block: Option<Arc<[[f32; 3]]>>) -> Self {
        if let Ok(quad) = <[[f32; 3]; 4]>::try_from(v) {
            return GridVerts(VertStore::Quad(quad));
        }
        if let Some(mut block) = block.filter(|b| b.len() == v.len()) {
            if let Some(dst) = Arc::get_mut(&mut block) {
                dst.copy_from_slice(v);
                return GridVerts(VertStore::Shared(block));
            }
        }
        GridVerts(VertStore::Shared(Arc::from(v)))
    }
}

impl std::ops::Deref for GridVerts {
    type Target = [[f32; 3]];
    #[inline]
    fn deref(&self) -> &[[f32; 3]] {
        self.as_slice()
    }
}

impl From<&[[f32; 3]]> for GridVerts {
    fn from(v: &[[f32; 3]]) -> Self {
        GridVerts::refill(v, None)
    }
}

impl From<Vec<[f32; 3]>> for GridVerts {
    fn from(v: Vec<[f32; 3]>) -> Self {
        GridVerts::from(&v[..])
    }
}

impl PartialEq for GridVerts {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl std::fmt::Debug for GridVerts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.as_slice().fmt(f)
    }
}

/// The boxes a medium or fine grid is tested with, kept in one shared, immutable allocation
/// (a clone copies a pointer): the grid's *cull boxes* at strides 1 and 2, which a ray must
/// meet to hit the grid read at that stride or any of its seam boxes (see [`crate::seam`]),
/// and for a fine grid also its 4×4 *sub-boxes*,
/// each over 4×4 quads (row-major, u fastest). Made once at tessellation, so a test reads one
/// box instead of gathering it from the vertices and the seams' reach (which cost a displaced
/// AO ray more than a tenth of its instructions). Coarse and hand-made grids have none: their
/// tests gather the box themselves.
#[derive(Clone, Default, PartialEq)]
pub struct GridBoxes(Option<Arc<[Bounds3]>>);

/// The strides a grid's cull boxes are kept for: the rates read a medium or fine grid at
/// strides 1 and 2 ([`Rate::tier_and_stride`]).
pub const CULL_STRIDES: usize = 2;

impl GridBoxes {
    /// No boxes (coarse and hand-made grids).
    pub const NONE: GridBoxes = GridBoxes(None);

    /// The cull box at `stride` (1 or 2): every vertex and every seam box of the grid read at
    /// that stride, within the rounding slack of a triangle test (object space). `None`: gather
    /// it.
    #[inline]
    pub fn cull(&self, stride: usize) -> Option<&Bounds3> {
        self.0.as_deref().filter(|_| stride <= CULL_STRIDES)?.get(stride.wrapping_sub(1))
    }

    /// The 16 sub-boxes of a fine grid, or none.
    #[inline]
    pub fn sub_boxes(&self) -> &[Bounds3] {
        match self.0.as_deref() {
            Some(b) if b.len() == CULL_STRIDES + 16 => &b[CULL_STRIDES..],
            _ => &[],
        }
    }

    /// Heap bytes the boxes hold (their 16-byte reference counts and the boxes), or 0.
    pub fn heap_bytes(&self) -> usize {
        self.0.as_ref().map_or(0, |b| 2 * std::mem::size_of::<usize>() + std::mem::size_of_val::<[Bounds3]>(b))
    }

    /// How many boxes there are (what the cache's budget counts).
    pub fn len(&self) -> usize {
        self.0.as_ref().map_or(0, |b| b.len())
    }

    /// No boxes: a coarse or hand-made grid.
    pub fn is_empty(&self) -> bool {
        self.0.is_none()
    }

    /// `cull` (by stride) followed by `sub_boxes`, in `spare`'s block if it has one of that
    /// size and nothing else shares it (an evicted entry's), else in a new one.
    pub(crate) fn refill(cull: [Bounds3; CULL_STRIDES], sub_boxes: &[Bounds3], spare: GridBoxes) -> Self {
        if let Some(mut block) = spare.0 {
            if let Some(dst) = Arc::get_mut(&mut block).filter(|d| d.len() == CULL_STRIDES + sub_boxes.len()) {
                dst[..CULL_STRIDES].copy_from_slice(&cull);
                dst[CULL_STRIDES..].copy_from_slice(sub_boxes);
                return GridBoxes(Some(block));
            }
        }
        GridBoxes(Some(cull.into_iter().chain(sub_boxes.iter().copied()).collect()))
    }
}

#[cfg(test)]
impl GridBoxes {
    /// Cull boxes alone, as a medium grid keeps them.
    pub(crate) fn refill_for_test(cull: [Bounds3; CULL_STRIDES]) -> Self {
        GridBoxes::refill(cull, &[], GridBoxes::NONE)
    }
}

impl std::fmt::Debug for GridBoxes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GridBoxes").field("cull", &[self.cull(1), self.cull(2)]).field("sub_boxes", &self.sub_boxes()).finish()
    }
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

/// A resident [`Tessellation`] as the cache keeps it, in 64 bytes instead of 88: a coarse grid
/// keeps its vertices inline and needs no pointers, any other grid keeps pointers to its shared
/// blocks and needs no inline room. That is a fifth of what a resident coarse entry costs in
/// all (see the `geometry_cache` module docs).
#[derive(Clone, Debug)]
pub struct StoredTessellation(StoredRepr);

#[derive(Clone, Debug)]
enum StoredRepr {
    /// A 2×2 grid with inline vertices and no sub-boxes: every coarse entry.
    Quad { verts: [[f32; 3]; 4], chord_error: f32, seam_radius: f32, seam_normal: SeamNormal, domain: GridDomain },
    /// Any other grid.
    Grid {
        n: u32,
        verts: Arc<[[f32; 3]]>,
        boxes: GridBoxes,
        chord_error: f32,
        seam_radius: f32,
        seam_normal: SeamNormal,
        domain: GridDomain,
    },
}

impl StoredTessellation {
    /// The shared blocks this entry holds, for a new tessellation to refill.
    fn into_blocks(self) -> (Option<Arc<[[f32; 3]]>>, GridBoxes) {
        match self.0 {
            StoredRepr::Quad { .. } => (None, GridBoxes::NONE),
            StoredRepr::Grid { verts, boxes, .. } => (Some(verts), boxes),
        }
    }
}

/// What the budget counts is the paper's payload (§5.2): 12 bytes a vertex, plus what an entry
/// needs beyond its vertices to be tested (a fine grid's 16 sub-boxes, the two error floats), so
/// tier capacities compare with the paper's. The rest of what a resident entry costs (its cache
/// node, hash bucket, reference counts, the allocator's rounding) is bookkeeping; see the
/// `geometry_cache` module docs for its size.
impl CacheEntry for Tessellation {
    type Stored = StoredTessellation;

    fn byte_size(&self) -> usize {
        self.verts.len() * std::mem::size_of::<[f32; 3]>()
            + self.boxes.len() * std::mem::size_of::<Bounds3>()
            + 2 * std::mem::size_of::<f32>()
    }

    fn vertex_count(&self) -> usize {
        self.verts.len()
    }

    fn to_stored(&self) -> StoredTessellation {
        let (chord_error, seam_radius, seam_normal, domain) = (self.chord_error, self.seam_radius, self.seam_normal, self.domain);
        StoredTessellation(match &self.verts.0 {
            VertStore::Quad(verts) if self.n == 2 && self.boxes.is_empty() => {
                StoredRepr::Quad { verts: *verts, chord_error, seam_radius, seam_normal, domain }
            }
            store => StoredRepr::Grid {
                // `n × n` vertices fit in memory, so `n` fits in 32 bits.
                n: u32::try_from(self.n).unwrap_or(u32::MAX),
                verts: match store {
                    VertStore::Shared(v) => Arc::clone(v),
                    VertStore::Quad(v) => Arc::from(v.as_slice()),
                },
                boxes: self.boxes.clone(),
                chord_error,
                seam_radius,
                seam_normal,
                domain,
            },
        })
    }

    fn from_stored(stored: &StoredTessellation) -> Tessellation {
        match &stored.0 {
            StoredRepr::Quad { verts, chord_error, seam_radius, seam_normal, domain } => Tessellation {
                n: 2,
                verts: GridVerts(VertStore::Quad(*verts)),
                boxes: GridBoxes::NONE,
                chord_error: *chord_error,
                seam_radius: *seam_radius,
                seam_normal: *seam_normal,
                domain: *domain,
            },
            StoredRepr::Grid { n, verts, boxes, chord_error, seam_radius, seam_normal, domain } => Tessellation {
                n: *n as usize,
                verts: GridVerts(VertStore::Shared(Arc::clone(verts))),
                boxes: boxes.clone(),
                chord_error: *chord_error,
                seam_radius: *seam_radius,
                seam_normal: *seam_normal,
                domain: *domain,
            },
        }
    }
}

impl Tessellation {
    /// Vertex (i, j) as a vector.
    #[inline]
    pub fn vert(&self, i: usize, j: usize) -> Vec3A {
        Vec3A::from(self.verts[j * self.n + i])
    }

    /// Heap bytes this tessellation holds outside itself: 0 for a coarse grid, the shared
    /// vertex block (and a fine grid's shared sub-boxes) otherwise. Shared with every clone.
    pub fn heap_bytes(&self) -> usize {
        self.verts.heap_bytes() + self.boxes.heap_bytes()
    }
}

/// How a mesh is displaced: the function, the side its normal points to (−1 for leftHanded
/// meshes) and the bound its subpatch boxes were grown by.
#[derive(Clone, Debug)]
pub struct DisplaceParams {
    pub displacement: DisplacementShader,
    pub normal_sign: f32,
    pub bound: f32,
    /// Whether a texture's shared edges are read with their own `st` step
    /// ([`DisplacementShader::filter_edges`]): on with the displaced rate floor
    /// (`displacementRateFloor`), where it closes what the floor capped at 16 × 16 leaves.
    /// Without the floor it lets more light through a closed shell, not less (coarse grids'
    /// corners then carry the finest level's detail: docs/cracks.md), so it is off there and a
    /// texture is filtered at each grid's own step alone. The procedural shader's edges are
    /// always read alike.
    pub texture_edges_alike: bool,
}

/// Tessellates `sub` of `surface` on `tier`'s grid: one grid evaluation, displacement along the
/// limit normal filtered at the grid's own spacing (its boundary as neighbours read it,
/// [`DisplacementShader::filter_edges`]), then (for the fine tier) the 4×4 sub-boxes.
/// Returns the tessellation and how many displaced vertices left `sub.bounds` (counted, never
/// clipped). `scratch` is reused between calls to avoid allocation.
pub fn tessellate(
    surface: &dyn LimitSurface,
    sub: &Subpatch,
    tier: Tier,
    displace: Option<&DisplaceParams>,
    scratch: &mut GridSamples,
) -> (Tessellation, u32) {
    tessellate_reusing(surface, sub, tier, displace, scratch, None)
}

/// As [`tessellate`], writing the grid into `spare`'s blocks (an entry the cache evicted, see
/// [`GeometryCache::get_or_build_reusing`](crate::geometry_cache::GeometryCache::get_or_build_reusing))
/// where they fit and nothing else shares them, instead of allocating new ones. The result is
/// the same either way.
pub fn tessellate_reusing(
    surface: &dyn LimitSurface,
    sub: &Subpatch,
    tier: Tier,
    displace: Option<&DisplaceParams>,
    scratch: &mut GridSamples,
    spare: Option<StoredTessellation>,
) -> (Tessellation, u32) {
    let (spare_verts, spare_boxes) = spare.map_or((None, GridBoxes::NONE), StoredTessellation::into_blocks);
    let n = tier.verts_per_side() as usize;
    surface.evaluate_grid(sub.patch as usize, sub.rect, n, displace.is_some(), scratch);
    // Measured on the undisplaced grid: seams follow the limit surface's edges. Displaced, the
    // grid's chords and their normals are not the ones measured: the box is the radius on every
    // side.
    let (seam_radius, seam_normal) =
        crate::seam::seam_extent_with(surface, sub.patch as usize, sub.rect, &scratch.p, n, displace.is_none());
    let mut outside = 0;
    if let Some(d) = displace {
        let mut offsets = Vec::with_capacity(n * n);
        d.displacement.grid_offsets(surface, sub.patch as usize, sub.rect, &scratch.p, n, &mut offsets);
        if d.texture_edges_alike || !matches!(d.displacement, DisplacementShader::Texture(_)) {
            d.displacement.filter_edges(surface, sub.patch as usize, sub.rect, &scratch.p, n, &mut offsets);
        }
        for (k, v) in scratch.p.iter_mut().enumerate() {
            let p = Vec3A::from(*v);
            let nrm = (Vec3A::from(scratch.dpdu[k]).cross(Vec3A::from(scratch.dpdv[k]))).normalize_or_zero() * d.normal_sign;
            let q = p + nrm * offsets[k];
            if !(q.cmpge(sub.bounds.min).all() && q.cmple(sub.bounds.max).all()) {
                outside += 1;
            }
            *v = q.into();
        }
    }
    let verts = GridVerts::refill(&scratch.p, spare_verts);
    let domain = GridDomain::of(surface.patch_param(sub.patch as usize).kind, &sub.rect);
    let mut t = Tessellation { n, verts, boxes: GridBoxes::NONE, chord_error: 0.0, seam_radius, seam_normal, domain };
    let sub_boxes: Option<[Bounds3; 16]> = (tier == Tier::Fine).then(|| {
        std::array::from_fn(|b| {
            let (bi, bj) = (b % 4 * 4, b / 4 * 4);
            let mut bb = Bounds3::EMPTY;
            for j in bj..=bj + 4 {
                for i in bi..=bi + 4 {
                    bb.grow(t.vert(i, j));
                }
            }
            bb
        })
    });
    t.chord_error = 2.0 * probe_chord_error(surface, sub, &t);
    if let Some(d) = displace {
        // The probe measures the undisplaced surface; displacement detail finer than the
        // grid is filtered out, so what remains strays from the quads by at most its bound.
        t.chord_error += d.bound.min(2.0 * d.displacement.bound());
    }
    if tier != Tier::Coarse {
        let cull = std::array::from_fn(|s| crate::seam::cull_box(&t, s + 1));
        t.boxes = GridBoxes::refill(cull, sub_boxes.as_ref().map_or(&[], |b| b.as_slice()), spare_boxes);
    }
    (t, outside)
}

/// Largest distance between the surface and the bilinear interpolation of the grid, probed at
/// the centre of up to 4×4 quads spread over the grid (16 evaluations for a fine grid, 5% of its
/// cost; 4 for a medium one; 1 for a coarse one). A single-crease patch's curvature gathers in a
/// strip along its crease, between the crease and the knots of its cross-section
/// (`LimitSurface::edge_knots`), which the spread quads may all miss (a fine grid's error there
/// was up to 23× its estimate, `bridge/tests/chord_error.rs`): across such a patch every quad of
/// the spread rows is probed, and the knots themselves, where a bend's chord strays most.
fn probe_chord_error(surface: &dyn LimitSurface, sub: &Subpatch, t: &Tessellation) -> f32 {
    let quads = t.n - 1;
    let q = quads as f32;
    let k = quads.min(4);
    let inside = |i: usize, j: usize| match t.domain {
        GridDomain::Square => true,
        GridDomain::LowerTriangle => (i + j + 1) as f32 <= q,
        GridDomain::Empty => false,
    };
    // The probed quads (i, j) and where on the patch their middles are, evaluated in one call.
    // Sized once: collected through `filter`, the vector grew a push at a time.
    let mut probes: Vec<(usize, usize)> = Vec::with_capacity(k * k);
    probes.extend(
        (0..k * k).map(|b| ((b % k) * quads / k + (quads / k) / 2, (b / k) * quads / k + (quads / k) / 2)).filter(|&(i, j)| inside(i, j)),
    );
    let to_patch = |lu: f32, lv: f32| [sub.rect.u0 + (sub.rect.u1 - sub.rect.u0) * lu, sub.rect.v0 + (sub.rect.v1 - sub.rect.v0) * lv];
    let mut uv: Vec<[f32; 2]> = probes.iter().map(|&(i, j)| to_patch((i as f32 + 0.5) / q, (j as f32 + 0.5) / q)).collect();
    let across = knot_probes(surface.edge_knots(sub.patch as usize), sub, quads, k);
    uv.extend(across.iter().filter(|p| inside(p.0.min(quads - 1), p.1.min(quads - 1))).map(|p| to_patch(p.2, p.3)));
    let mut surface_points = Vec::with_capacity(uv.len());
    surface.evaluate_points(sub.patch as usize, &uv, &mut surface_points);
    let mut err: f32 = 0.0;
    for (&(i, j), s) in probes.iter().zip(&surface_points) {
        let quad = (t.vert(i, j) + t.vert(i + 1, j) + t.vert(i + 1, j + 1) + t.vert(i, j + 1)) * 0.25;
        err = err.max((Vec3A::from(*s) - quad).length());
    }
    for (&(_, _, lu, lv), s) in across.iter().zip(&surface_points[probes.len()..]) {
        err = err.max((Vec3A::from(*s) - bilinear_at(t, lu, lv)).length());
    }
    if err.is_finite() {
        err
    } else {
        0.0
    }
}

/// The extra probes of a single-crease patch's grid, as (quad i, quad j, local u, local v) with
/// local coordinates in [0, 1] over the subpatch: for each of the `k` spread positions along the
/// crease, the middle of every quad across it the spread probes leave out (12 of a fine grid's
/// 16, none of a medium one's) and each knot inside the subpatch: at most 56 evaluations more
/// for a fine grid, 8 for a medium one, 2 for a coarse one. None when the patch has no knots
/// (every other patch: its probes are unchanged, and so are its bits).
fn knot_probes(knots: crate::patch::EdgeKnots, sub: &Subpatch, quads: usize, k: usize) -> Vec<(usize, usize, f32, f32)> {
    let q = quads as f32;
    let local = |x: f32, lo: f32, hi: f32| (x - lo) / (hi - lo);
    let mut out = Vec::new();
    // Knots in u: the cross-section runs along u (rows of quads i at fixed j), and vice versa.
    for (values, in_u) in [(knots.u, true), (knots.v, false)] {
        if !values.iter().any(|x| x.is_finite()) {
            continue;
        }
        let (lo, hi) = if in_u { (sub.rect.u0, sub.rect.u1) } else { (sub.rect.v0, sub.rect.v1) };
        let inner: Vec<f32> = values.iter().map(|&x| local(x, lo, hi)).filter(|l| *l > 0.0 && *l < 1.0).collect();
        for b in 0..k {
            let along = b * quads / k + (quads / k) / 2;
            let l_along = (along as f32 + 0.5) / q;
            let mut push = |across: usize, l_across: f32| {
                out.push(if in_u { (across, along, l_across, l_along) } else { (along, across, l_along, l_across) });
            };
            // The spread probes already hold every (quads / k)-th middle.
            for across in (0..quads).filter(|a| a % (quads / k) != (quads / k) / 2) {
                push(across, (across as f32 + 0.5) / q);
            }
            for &l in &inner {
                push(((l * q) as usize).min(quads - 1), l);
            }
        }
    }
    out
}

/// The grid's bilinear interpolation at local (u, v) ∈ [0, 1]² over the subpatch.
fn bilinear_at(t: &Tessellation, lu: f32, lv: f32) -> Vec3A {
    let quads = t.n - 1;
    let q = quads as f32;
    let (i, j) = (((lu * q) as usize).min(quads - 1), ((lv * q) as usize).min(quads - 1));
    let (a, b) = (lu * q - i as f32, lv * q - j as f32);
    let bottom = t.vert(i, j).lerp(t.vert(i + 1, j), a);
    let top = t.vert(i, j + 1).lerp(t.vert(i + 1, j + 1), a);
    bottom.lerp(top, b)
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
        assert_eq!(fine.boxes.sub_boxes().len(), 16);
        assert_eq!(fine.byte_size(), 17 * 17 * 12 + 18 * std::mem::size_of::<Bounds3>() + 8);
        let (medium, _) = tessellate(&s, &sub, Tier::Medium, None, &mut scratch);
        assert_eq!(medium.verts.len(), 25);
        assert!(medium.boxes.sub_boxes().is_empty() && medium.boxes.cull(2).is_some());
    }

    /// The layout the cache's memory figures rest on (see the `geometry_cache` module docs): a
    /// coarse grid is 96 bytes with its vertices inline; a clone of a medium or fine one shares
    /// its vertices and boxes.
    #[test]
    fn entries_are_compact_and_clones_share_their_grids() {
        assert_eq!(std::mem::size_of::<Tessellation>(), 96);
        assert_eq!(std::mem::size_of::<StoredTessellation>(), 64);
        assert_eq!(std::mem::size_of::<Option<StoredTessellation>>(), 64);
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.3], [1.0, 1.0, 0.0], [0.0, 1.0, 0.7]];
        let topo =
            MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
        let s = BilinearSurface::new(&topo, &pts).unwrap();
        let sub = Subpatch { patch: 0, rect: UvRect::UNIT, bounds: s.patch_bounds(0), affine: false };
        let mut scratch = GridSamples::default();
        let (coarse, _) = tessellate(&s, &sub, Tier::Coarse, None, &mut scratch);
        assert_eq!((coarse.verts.len(), coarse.heap_bytes(), coarse.byte_size()), (4, 0, 56));
        let (medium, _) = tessellate(&s, &sub, Tier::Medium, None, &mut scratch);
        assert_eq!(medium.heap_bytes(), 16 + 300 + 16 + 64);
        let (fine, _) = tessellate(&s, &sub, Tier::Fine, None, &mut scratch);
        assert_eq!(fine.heap_bytes(), 16 + 3468 + 16 + 576);
        // What the cache hands out equals what was built, and shares its grids.
        for t in [&coarse, &medium, &fine] {
            assert_eq!(&Tessellation::from_stored(&t.to_stored()), t);
        }
        let copy = Tessellation::from_stored(&fine.to_stored());
        assert!(std::ptr::eq(copy.verts.as_slice(), fine.verts.as_slice()));
        assert!(std::ptr::eq(copy.boxes.sub_boxes(), fine.boxes.sub_boxes()));
        // Rebuilt into an evicted entry's blocks: the same grid, in those very blocks (unless
        // something still shares them).
        let spare = fine.to_stored();
        let (verts_at, boxes_at) = (fine.verts.as_ptr(), fine.boxes.sub_boxes().as_ptr());
        drop((fine, copy));
        let (refilled, _) = tessellate_reusing(&s, &sub, Tier::Fine, None, &mut scratch, Some(spare));
        assert!(std::ptr::eq(refilled.verts.as_ptr(), verts_at) && std::ptr::eq(refilled.boxes.sub_boxes().as_ptr(), boxes_at));
        assert_eq!(refilled, tessellate(&s, &sub, Tier::Fine, None, &mut scratch).0);
        let held = refilled.clone();
        let (fresh, _) = tessellate_reusing(&s, &sub, Tier::Fine, None, &mut scratch, Some(refilled.to_stored()));
        assert!(!std::ptr::eq(fresh.verts.as_ptr(), held.verts.as_ptr()), "a shared block is not overwritten");
        assert_eq!(fresh, held);
        let (medium_again, _) = tessellate_reusing(&s, &sub, Tier::Medium, None, &mut scratch, Some(held.to_stored()));
        assert_eq!(medium_again, medium, "a block of another tier's size is not used");
        let fine = held;
        // Odd shapes (only tests make them) round-trip too.
        let odd = Tessellation { n: 3, verts: vec![[1.0, 2.0, 3.0]; 4].into(), boxes: fine.boxes.clone(), ..coarse.clone() };
        assert_eq!(Tessellation::from_stored(&odd.to_stored()), odd);
        let v: GridVerts = vec![[1.0, 2.0, 3.0]; 4].into();
        assert_eq!(format!("{v:?}"), format!("{:?}", vec![[1.0f32, 2.0, 3.0]; 4]));
    }
}
