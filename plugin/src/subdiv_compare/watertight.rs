//! Whether rays can pass between neighbouring patches tested at different rates (the paper's
//! §7.1 cracks), checked the way the renderer closes them ([`mipray::seam`]).
//!
//! The renderer never makes the two sides of an edge identical — each ray picks a rate per
//! subpatch — so "the same points at every pair of rates" holds only for straight edges. It
//! closes the cracks with seam boxes instead, and they close them exactly when two things hold
//! (the argument is in [`mipray::seam`]'s module doc):
//! 1. both patches of an edge evaluate its points to within the seam boxes' rounding margin of
//!    each other (checked at 17 points of every patch edge, each evaluated again across the
//!    edge through the ptex layout and the control mesh's adjacency);
//! 2. every boundary chord's seam box contains the edge curve over that chord, and the
//!    neighbour's evaluation of it (checked at 7 points inside every chord, at every tier and
//!    merged rate, and for split children).
//!
//! The report also gives what the cracks would be without seams: the largest distance between
//! an edge curve and a chord, per rate.

use std::collections::{BTreeMap, HashMap};

use glam::Vec3A;
use mipray::geometry_cache::Tier;
use mipray::patch::{GridSamples, LimitSurface, UvRect};
use mipray::seam::{edge_uv, edge_vertex, point_segment_distance, seam_box, seam_margin, SeamEdges, DIAGONAL, EDGE_COUNT};
use mipray::subpatch::{ChildCell, Subpatch};
use mipray::tessellate::{tessellate, GridDomain, Tessellation};
use mipray::topology::{MeshTopology, Scheme};
use mipray_bridge::OsdSurface;
use serde::Serialize;

use super::{spread, CompareOptions};

/// Samples per patch edge compared with the neighbour's evaluation (17: every vertex of the
/// finest tier).
const EDGE_SAMPLES: usize = 17;
/// Points probed inside each chord.
const CHORD_PROBES: usize = 7;

/// Probes of a chord across a knot of a piecewise polynomial edge (a single-crease patch's,
/// [`LimitSurface::edge_knots`]): the crease's fillet can be as narrow as 2^−isolation level of
/// the patch, which seven probes would step over.
const KNOT_CHORD_PROBES: usize = 63;

/// See the module doc. Distances relative to the bounding-box diagonal.
#[derive(Clone, Debug, Default, Serialize)]
pub struct WatertightReport {
    /// Patches whose edges were compared with their neighbours (all, up to 4096).
    pub edge_patches_checked: usize,
    /// Patch-edge samples evaluated again by the neighbour across the edge (pairs).
    pub shared_edge_points: usize,
    /// Largest distance between the two evaluations, object units (not serialised).
    #[serde(skip)]
    pub max_edge_mismatch: f64,
    /// Largest distance between two patches' evaluations of the same edge point.
    pub max_rel_edge_mismatch: f64,
    /// That distance over the seam boxes' rounding margin there: ≤ 1 is condition 1.
    pub max_edge_mismatch_over_margin: f64,
    /// Edge samples with no neighbour: on the mesh boundary or next to a hole.
    pub unpaired_edge_points: usize,
    /// The widest crack without seams: the largest distance between an edge curve and a chord.
    pub max_rel_rate_gap: f64,
    /// The same per rate (quads per side of a root patch; `32`, `64`, … for split children).
    pub max_rel_rate_gap_by_rate: BTreeMap<String, f64>,
    /// Boundary chords checked against their seam boxes.
    pub seam_chords_checked: usize,
    /// How far into its chord's seam box the curve reaches, grown by the edge mismatch there
    /// (`max_edge_mismatch_over_margin` rounding margins of that grid), as the largest offset
    /// from the box's middle over its half-width in any of its three directions: ≤ 1 is
    /// condition 2 (the box holds the neighbour's evaluation of the curve).
    pub max_seam_coverage_ratio: f64,
    /// Chords whose seam box does not contain the curve.
    pub uncovered_seam_chords: usize,
    /// True only when every chord lies on its curve to within rounding (flat, straight-edged
    /// patches): then the two sides of every edge coincide at every pair of rates even without
    /// seams.
    pub edges_match_without_seams: bool,
}

impl WatertightReport {
    /// Conditions 1 and 2 of the module doc: no ray passes between neighbours at any pair of
    /// rates.
    pub fn watertight(&self) -> bool {
        self.max_edge_mismatch_over_margin <= 1.0 && self.uncovered_seam_chords == 0
    }
}

/// A patch edge as its (u, v) at t ∈ [0, 1].
type EdgeCurve = Box<dyn Fn(f32) -> (f32, f32)>;

/// The edge curves of a patch as (u, v) functions of t ∈ [0, 1]: the four square edges, or the
/// three triangle edges (v = 0, u = 0, and the diagonal).
fn patch_edges(triangle: bool) -> Vec<EdgeCurve> {
    if triangle {
        vec![Box::new(|t| (t, 0.0)), Box::new(|t| (0.0, t)), Box::new(|t| (t, 1.0 - t))]
    } else {
        (0..EDGE_COUNT).map(|e| Box::new(move |t| edge_uv(e, t)) as EdgeCurve).collect()
    }
}

/// Patches whose edges [`check`] compares with their neighbours at most.
const EDGE_PATCHES: usize = 4096;

/// Runs both checks; `diag` scales the reported distances.
pub fn check(surface: &OsdSurface, topology: &MeshTopology, diag: f32, options: &CompareOptions) -> WatertightReport {
    let mut r = WatertightReport::default();
    let d = f64::from(diag);
    let edge_patches = spread(surface.patch_count(), EDGE_PATCHES);
    r.edge_patches_checked = edge_patches.len();
    match_edges(surface, topology, diag, &edge_patches, &mut r);
    let mismatch = r.max_edge_mismatch_over_margin;
    let mut worst_gap_over_margin = 0.0f64;
    let mut scratch = GridSamples::default();
    let mut gap = |r: &mut WatertightReport, rate: u32, dist: f64, margin: f64, coverage: &dyn Fn(f64) -> f64| {
        let slot = r.max_rel_rate_gap_by_rate.entry(rate.to_string()).or_insert(0.0);
        *slot = slot.max(dist / d);
        r.max_rel_rate_gap = r.max_rel_rate_gap.max(dist / d);
        worst_gap_over_margin = worst_gap_over_margin.max(dist / margin.max(f64::MIN_POSITIVE));
        // The neighbour's evaluation of the curve lies within `mismatch` margins of ours (the
        // largest ratio over the mesh, scaled to this grid's margin): the box must reach it.
        let ratio = coverage(mismatch * margin);
        r.seam_chords_checked += 1;
        r.max_seam_coverage_ratio = r.max_seam_coverage_ratio.max(if ratio.is_nan() { f64::INFINITY } else { ratio });
        if !(ratio <= 1.0) {
            r.uncovered_seam_chords += 1;
        }
    };
    for patch in spread(surface.patch_count(), options.tessellation_patches) {
        let bounds = surface.patch_bounds(patch);
        for tier in Tier::ALL {
            let sub = Subpatch { patch: patch as u32, rect: UvRect::UNIT, bounds, affine: false };
            let (t, _) = tessellate(surface, &sub, tier, None, &mut scratch);
            for stride in [1usize, 2] {
                if tier == Tier::Coarse && stride == 2 {
                    continue;
                }
                let rate = ((t.n - 1) / stride) as u32;
                chords(surface, patch, UvRect::UNIT, &t, stride, SeamEdges::ALL, |dist, margin, coverage| {
                    gap(&mut r, rate, dist, margin, coverage)
                });
            }
        }
    }
    for depth in 1..=options.split_depth.min(mipray::tessellate::MAX_SPLIT_DEPTH) {
        for patch in spread(surface.patch_count(), options.split_patches) {
            let bounds = surface.patch_bounds(patch);
            let cells = 1u32 << depth;
            for j in 0..cells {
                for i in 0..cells {
                    let rect = ChildCell { root: 0, depth: depth as u8, i, j }.rect(&UvRect::UNIT);
                    let edges = SeamEdges::of_child(depth as u8, i, j).within(GridDomain::of(surface.patch_param(patch).kind, &rect));
                    if edges == SeamEdges::NONE {
                        continue;
                    }
                    let sub = Subpatch { patch: patch as u32, rect, bounds, affine: false };
                    let (t, _) = tessellate(surface, &sub, Tier::Fine, None, &mut scratch);
                    chords(surface, patch, rect, &t, 1, edges, |dist, margin, coverage| gap(&mut r, 16 << depth, dist, margin, coverage));
                }
            }
        }
    }
    r.edges_match_without_seams = worst_gap_over_margin <= 1.0;
    r
}

/// For every boundary chord of `tess` (over `rect`, read at `stride`) on `edges`, calls
/// `each(distance of the curve from the chord, rounding margin, coverage)` in object units,
/// where `coverage(grow)` is how far into the renderer's seam box for that chord
/// ([`mipray::seam::seam_box`]) the curve's probes reach when each is grown by `grow`: at most 1
/// when all of them, so grown, lie inside.
fn chords(
    surface: &dyn LimitSurface,
    patch: usize,
    rect: UvRect,
    tess: &Tessellation,
    stride: usize,
    edges: SeamEdges,
    mut each: impl FnMut(f64, f64, &dyn Fn(f64) -> f64),
) {
    let n = tess.n;
    let q = (n - 1) / stride;
    let max_abs = tess.verts.iter().fold(0.0f32, |m, v| m.max(v[0].abs()).max(v[1].abs()).max(v[2].abs()));
    let margin = f64::from(seam_margin(max_abs));
    let edges = edges.within(tess.domain);
    let knots = surface.edge_knots(patch);
    for e in (0..=DIAGONAL).filter(|&e| edges.contains(e)) {
        let vert = |k: usize| {
            let (i, j) = edge_vertex(e, k, n);
            tess.vert(i, j)
        };
        for k in 0..q {
            let (a, b) = (vert(k * stride), vert((k + 1) * stride));
            let seam = seam_box(tess, e, k, stride).map(|(sb, _)| sb);
            let mut dist = 0.0f32;
            let at = |t: f32| {
                let (lu, lv) = edge_uv(e, t);
                (rect.u0 + (rect.u1 - rect.u0) * lu, rect.v0 + (rect.v1 - rect.v0) * lv)
            };
            let ((ua, va), (ub, vb)) = (at(k as f32 / q as f32), at((k + 1) as f32 / q as f32));
            let inside = |ks: &[f32; 2], x0: f32, x1: f32| ks.iter().any(|&x| x > x0.min(x1) && x < x0.max(x1));
            let across_knot = (ua != ub && inside(&knots.u, ua, ub)) || (va != vb && inside(&knots.v, va, vb));
            let count = if across_knot { KNOT_CHORD_PROBES } else { CHORD_PROBES };
            let mut probes = Vec::with_capacity(count);
            for p in 1..=count {
                let t = (k as f32 + p as f32 / (count + 1) as f32) / q as f32;
                let (lu, lv) = edge_uv(e, t);
                let u = rect.u0 + (rect.u1 - rect.u0) * lu;
                let v = rect.v0 + (rect.v1 - rect.v0) * lv;
                let c = surface.evaluate(patch, u, v).p;
                let dd = point_segment_distance(c, a, b);
                dist = dist.max(if dd.is_nan() { f32::INFINITY } else { dd });
                probes.push(c);
            }
            let coverage = |grow: f64| match &seam {
                Some(sb) => probes.iter().fold(0.0f64, |m, &c| m.max(f64::from(sb.coverage(c, grow as f32)))),
                // A chord of zero length has no box: covered only if the curve is that point.
                None => {
                    if dist == 0.0 {
                        0.0
                    } else {
                        f64::INFINITY
                    }
                }
            };
            each(f64::from(dist), margin, &coverage);
        }
    }
}

/// Where a point of a ptex face's boundary continues: the same point as (ptex face, u, v) on
/// the other side of each base edge (or, for the sub-faces of a non-quad, of each edge between
/// sub-faces), from the control mesh's topology and OpenSubdiv's ptex layout (one ptex face per
/// quad — per triangle under Loop — and n per n-gon otherwise, the sub-face of corner i having
/// (0, 0) at the corner, u toward the next edge's midpoint and v toward the previous edge's).
struct PtexAdjacency<'a> {
    topology: &'a MeshTopology,
    /// Per base face: first ptex face, and first face-vertex index.
    first_ptex: Vec<u32>,
    first_index: Vec<usize>,
    /// Per ptex face: (base face, sub-face index or usize::MAX for a whole face).
    ptex: Vec<(usize, usize)>,
    /// Base edges (sorted vertex pair) → the (face, edge k) that use them.
    edges: HashMap<(i32, i32), Vec<(usize, usize)>>,
    regular: usize,
}

impl<'a> PtexAdjacency<'a> {
    fn new(topology: &'a MeshTopology) -> Self {
        let regular = if topology.scheme == Scheme::Loop { 3 } else { 4 };
        let (mut first_ptex, mut first_index, mut ptex) = (Vec::new(), Vec::new(), Vec::new());
        let mut edges: HashMap<(i32, i32), Vec<(usize, usize)>> = HashMap::new();
        let mut at = 0usize;
        for (f, &n) in topology.face_vertex_counts.iter().enumerate() {
            let n = n.max(0) as usize;
            first_ptex.push(ptex.len() as u32);
            first_index.push(at);
            if n == regular {
                ptex.push((f, usize::MAX));
            } else {
                ptex.extend((0..n).map(|i| (f, i)));
            }
            for k in 0..n {
                let (a, b) = (topology.face_vertex_indices[at + k], topology.face_vertex_indices[at + (k + 1) % n]);
                edges.entry((a.min(b), a.max(b))).or_default().push((f, k));
            }
            at += n;
        }
        PtexAdjacency { topology, first_ptex, first_index, ptex, edges, regular }
    }

    fn face_size(&self, f: usize) -> usize {
        self.topology.face_vertex_counts[f].max(0) as usize
    }

    fn vertex(&self, f: usize, k: usize) -> i32 {
        let n = self.face_size(f);
        self.topology.face_vertex_indices[self.first_index[f] + k % n]
    }

    /// The point at t ∈ [0, 1] along edge k (vertex k → k + 1) of base face f, in ptex terms.
    fn face_edge_point(&self, f: usize, k: usize, t: f32) -> (u32, f32, f32) {
        let n = self.face_size(f);
        let first = self.first_ptex[f];
        if n == self.regular {
            let corners: &[(f32, f32)] =
                if n == 3 { &[(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] } else { &[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] };
            let (a, b) = (corners[k % n], corners[(k + 1) % n]);
            (first, a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t)
        } else if t <= 0.5 {
            (first + k as u32, 2.0 * t, 0.0)
        } else {
            (first + ((k + 1) % n) as u32, 0.0, 2.0 - 2.0 * t)
        }
    }

    /// The same point seen from every other ptex face sharing the boundary of ptex face `p` at
    /// (u, v) (empty in the interior or on the mesh boundary).
    fn across(&self, p: u32, u: f32, v: f32) -> Vec<(u32, f32, f32)> {
        const EPS: f32 = 1e-6;
        let Some(&(f, sub)) = self.ptex.get(p as usize) else { return Vec::new() };
        let n = self.face_size(f);
        // Base-face edges (k, t along it) through this point, and sibling sub-faces.
        let mut on_edges: Vec<(usize, f32)> = Vec::new();
        let mut out = Vec::new();
        if sub == usize::MAX {
            if n == 3 {
                if v.abs() < EPS {
                    on_edges.push((0, u));
                }
                if (u + v - 1.0).abs() < EPS {
                    on_edges.push((1, v));
                }
                if u.abs() < EPS {
                    on_edges.push((2, 1.0 - v));
                }
            } else {
                if v.abs() < EPS {
                    on_edges.push((0, u));
                }
                if (u - 1.0).abs() < EPS {
                    on_edges.push((1, v));
                }
                if (v - 1.0).abs() < EPS {
                    on_edges.push((2, 1.0 - u));
                }
                if u.abs() < EPS {
                    on_edges.push((3, 1.0 - v));
                }
            }
        } else {
            let first = self.first_ptex[f];
            if v.abs() < EPS {
                on_edges.push((sub, 0.5 * u));
            }
            if u.abs() < EPS {
                on_edges.push(((sub + n - 1) % n, 1.0 - 0.5 * v));
            }
            if (u - 1.0).abs() < EPS {
                out.push((first + ((sub + 1) % n) as u32, v, 1.0));
            }
            if (v - 1.0).abs() < EPS {
                out.push((first + ((sub + n - 1) % n) as u32, 1.0, u));
            }
        }
        for (k, t) in on_edges {
            let (a, b) = (self.vertex(f, k), self.vertex(f, k + 1));
            for &(g, kg) in self.edges.get(&(a.min(b), a.max(b))).map_or(&[][..], |v| v.as_slice()) {
                if g == f && kg == k {
                    continue;
                }
                let tg = if self.vertex(g, kg) == a { t } else { 1.0 - t };
                out.push(self.face_edge_point(g, kg, tg));
            }
        }
        out
    }
}

/// Condition 1: every sample of every patch edge (17 an edge) evaluated again on the other side
/// of the edge — by the neighbouring patch in the same ptex face, or through the control mesh's
/// adjacency in the neighbouring face — and the two evaluations compared.
fn match_edges(surface: &OsdSurface, topology: &MeshTopology, diag: f32, patches: &[usize], r: &mut WatertightReport) {
    let adjacency = PtexAdjacency::new(topology);
    let corner_abs = |patch: usize| {
        [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
            .iter()
            .map(|&(u, v)| surface.evaluate(patch, u, v).p.abs().max_element())
            .fold(0.0f32, f32::max)
    };
    let mut corner_cache: HashMap<usize, f32> = HashMap::new();
    for &patch in patches {
        let pp = surface.patch_param(patch);
        let tri = pp.kind.is_triangle();
        let own_abs = corner_abs(patch);
        // Outward directions of the edges in the patch's own (u, v).
        let outward: Vec<(f32, f32)> =
            if tri { vec![(0.0, -1.0), (-1.0, 0.0), (1.0, 1.0)] } else { vec![(0.0, -1.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)] };
        for (edge, out) in patch_edges(tri).iter().zip(outward) {
            for k in 0..EDGE_SAMPLES {
                let (u, v) = edge(k as f32 / (EDGE_SAMPLES - 1) as f32);
                let p = surface.evaluate(patch, u, v).p;
                let (fu, fv) = pp.to_face_uv(u, v);
                let mut others: Vec<(usize, Vec3A)> = Vec::new();
                let on_face_edge = fu.abs() < 1e-6
                    || fv.abs() < 1e-6
                    || (fu - 1.0).abs() < 1e-6
                    || (fv - 1.0).abs() < 1e-6
                    || (tri && (fu + fv - 1.0).abs() < 1e-6);
                if on_face_edge {
                    for (g, gu, gv) in adjacency.across(pp.ptex_face, fu.clamp(0.0, 1.0), fv.clamp(0.0, 1.0)) {
                        if let Some((b, s, t)) = surface.find_patch(g, gu.clamp(0.0, 1.0), gv.clamp(0.0, 1.0)) {
                            others.push((b, surface.evaluate(b, s, t).p));
                        }
                    }
                }
                if !(on_face_edge && (k == 0 || k == EDGE_SAMPLES - 1)) {
                    // Inside the ptex face (or along its edge, for adaptive neighbours there):
                    // the patch just across this edge, evaluated at the same face (u, v).
                    let step = 1e-3;
                    let (gu, gv) = pp.to_face_uv(u + out.0 * step, v + out.1 * step);
                    if (0.0..=1.0).contains(&gu) && (0.0..=1.0).contains(&gv) {
                        if let Some((b, _, _)) = surface.find_patch(pp.ptex_face, gu, gv) {
                            if b != patch {
                                let bp = surface.patch_param(b);
                                let (s, t) = ((fu - bp.u0) / bp.size, (fv - bp.v0) / bp.size);
                                others.push((b, surface.evaluate(b, s.clamp(0.0, 1.0), t.clamp(0.0, 1.0)).p));
                            }
                        }
                    }
                }
                if others.is_empty() {
                    r.unpaired_edge_points += 1;
                }
                for (b, q) in others {
                    let dist = (p - q).length();
                    let b_abs = *corner_cache.entry(b).or_insert_with(|| corner_abs(b));
                    let margin = seam_margin(own_abs.min(b_abs));
                    r.shared_edge_points += 1;
                    r.max_edge_mismatch = r.max_edge_mismatch.max(f64::from(dist));
                    r.max_rel_edge_mismatch = r.max_rel_edge_mismatch.max(f64::from(dist / diag));
                    let over = f64::from(dist) / f64::from(margin).max(f64::MIN_POSITIVE);
                    r.max_edge_mismatch_over_margin = r.max_edge_mismatch_over_margin.max(if over.is_nan() { f64::INFINITY } else { over });
                }
            }
        }
    }
}
