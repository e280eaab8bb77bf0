//! The project's subdivision results compared with OpenSubdiv's, for `mipray-subdiv-compare`
//! (and `mipray.tools.subdiv_compare` in Python).
//!
//! For one mesh it measures, relative to the control mesh's bounding-box diagonal:
//! - **limit evaluation**: our patches ([`OsdSurface::evaluate`] at an s×s grid of each patch's
//!   own (u, v)) against OpenSubdiv's own evaluation at the same (ptex face, u, v): its patch
//!   table with the limit stencils' options, its `PatchMap` and `EvaluateBasis`, an independent
//!   path ([`limit_reference`]): positions and normals;
//! - **tessellation**: each tier (coarse 2×2, medium 5×5, fine 17×17 vertices), each effective
//!   rate (1, 2, 4, 8, 16 quads a side) and split children, against the limit surface — the
//!   distance between the surface point at a (u, v) and the point of the renderer's triangles
//!   at the same (u, v), probed at quad centres and edge midpoints ([`tessellation`]);
//! - **watertightness**: whether a ray can pass between neighbouring patches tested at any two
//!   rates the renderer may pair ([`watertight`]);
//! - **uniform refinement**: how far OpenSubdiv's uniformly refined mesh at level k lies from our
//!   limit surface ([`uniform`]).
//!
//! Every field of [`CompareReport`] is serialisable; the command prints it as one JSON object
//! (`--json`) or as a table ([`CompareReport::table`]).

pub mod heatmap;
pub mod tessellation;
pub mod uniform;
pub mod watertight;

use std::collections::BTreeMap;

use glam::Vec3A;
use mipray::bounds::Bounds3;
use mipray::error::MeshError;
use mipray::obj_shape::{parse_obj_shape, CreaseMethod};
use mipray::patch::{LimitSurface, PatchKind, UvRect};
use mipray::topology::{MeshTopology, Scheme};
use mipray_bridge::{limit_reference, OsdOptions, OsdSurface};
use serde::Serialize;

pub use tessellation::TessellationErrors;
pub use uniform::UniformReport;
pub use watertight::WatertightReport;

/// What to measure and how densely.
#[derive(Clone, Debug, Serialize)]
pub struct CompareOptions {
    /// OpenSubdiv's adaptive isolation levels (primary, secondary).
    #[serde(skip)]
    pub osd: OsdOptions,
    /// Samples per patch side for the limit comparison (an s×s grid including the corners).
    pub samples_per_side: usize,
    /// Patches whose tessellations are measured, spread evenly over the mesh; 0 means all.
    pub tessellation_patches: usize,
    /// Deepest split measured (children of 2^d × 2^d per patch, each at 17×17), 0 for none.
    pub split_depth: u32,
    /// Patches whose split children are measured; 0 means all.
    pub split_patches: usize,
    /// Level of OpenSubdiv's uniform refinement to compare with (0 skips it).
    pub uniform_level: u32,
    /// Uniformly refined points measured, spread evenly; 0 means all.
    pub uniform_points: usize,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            osd: OsdOptions::DEFAULT,
            samples_per_side: 5,
            tessellation_patches: 512,
            split_depth: 2,
            split_patches: 64,
            uniform_level: 2,
            uniform_points: 20_000,
        }
    }
}

impl CompareOptions {
    /// Options small enough to run every shape of OpenSubdiv's corpus in a debug test.
    pub fn quick() -> Self {
        CompareOptions {
            osd: OsdOptions::DEFAULT,
            samples_per_side: 3,
            tessellation_patches: 24,
            split_depth: 1,
            split_patches: 4,
            uniform_level: 1,
            uniform_points: 2_000,
        }
    }
}

/// The comparison of one mesh. Errors are relative to [`CompareReport::bbox_diagonal`] unless
/// their name says otherwise.
#[derive(Clone, Debug, Serialize)]
pub struct CompareReport {
    /// The mesh's name (shape file stem or prim path).
    pub shape: String,
    /// `catmullClark`, `loop`, `bilinear` or `none` (USD's `subdivisionScheme` tokens).
    pub scheme: String,
    /// Control faces.
    pub faces: usize,
    pub points: usize,
    /// OpenSubdiv patches (root subpatches), and how many of each kind.
    pub patches: usize,
    pub patch_kinds: BTreeMap<String, usize>,
    /// Length of the control points' bounding-box diagonal (object units): the error scale.
    pub bbox_diagonal: f32,
    /// Limit samples compared with OpenSubdiv's own evaluation ([`limit_reference`]).
    pub samples: usize,
    /// Largest and root-mean-square distance between our limit points and OpenSubdiv's.
    pub max_rel_position_error: f64,
    pub rms_rel_position_error: f64,
    /// Largest angle between our normal (∂P/∂u × ∂P/∂v) and OpenSubdiv's, in degrees, over the
    /// samples inside patches where both are well defined.
    pub max_normal_angle_deg: f64,
    /// The largest angle beyond what rounding explains at its sample (16 ulps of the position's
    /// magnitude over the shorter derivative, in degrees): what is left for a real difference.
    pub max_normal_angle_beyond_rounding_deg: f64,
    /// Interior samples left out of the normal comparison: the derivatives are within 0.06° of
    /// parallel (next to a valence-2 vertex) or one is 1e4 times shorter than the other (a
    /// collapsed patch). Normals are compared inside patches only.
    pub degenerate_normals: usize,
    /// Tessellated surface against the limit surface: per tier (`coarse`, `medium`, `fine`).
    pub max_rel_tessellation_error: BTreeMap<String, f64>,
    /// The same per effective rate (quads a side: `1`, `2`, `4`, `8`, `16`).
    pub max_rel_tessellation_error_by_rate: BTreeMap<String, f64>,
    /// The same after splitting (key: split depth; 17×17 children).
    pub max_rel_tessellation_error_after_split: BTreeMap<String, f64>,
    /// Patches whose tessellations were measured.
    pub tessellation_patches_measured: usize,
    /// True when no ray can pass between neighbouring patches at any pair of rates the
    /// renderer may pair (see [`WatertightReport`]).
    pub watertight: bool,
    pub watertight_detail: WatertightReport,
    /// OpenSubdiv's uniform refinement against our limit surface (`None` when skipped).
    pub uniform: Option<UniformReport>,
    /// Things the reader should know (approximations, what was left out).
    pub notes: Vec<String>,
}

/// The USD token of a scheme.
pub fn scheme_token(s: Scheme) -> &'static str {
    match s {
        Scheme::CatmullClark => "catmullClark",
        Scheme::Loop => "loop",
        Scheme::Bilinear => "bilinear",
        Scheme::None => "none",
    }
}

fn kind_name(k: PatchKind) -> &'static str {
    match k {
        PatchKind::Bilinear => "bilinear",
        PatchKind::Regular => "regular",
        PatchKind::GregoryBasis => "gregory_basis",
        PatchKind::LoopRegular => "loop_regular",
        PatchKind::GregoryTriangle => "gregory_triangle",
        PatchKind::Other => "other",
    }
}

/// Evenly spaced indices: `count` of `0..n` (all of them when `count` is 0 or ≥ n).
pub(crate) fn spread(n: usize, count: usize) -> Vec<usize> {
    if count == 0 || count >= n {
        return (0..n).collect();
    }
    (0..count).map(|k| k * n / count).collect()
}

/// Whether (u, v) lies in a patch's domain (the triangle u + v ≤ 1 for Loop patches).
pub(crate) fn in_domain(kind: PatchKind, u: f32, v: f32) -> bool {
    !kind.is_triangle() || u + v <= 1.0 + 1e-6
}

/// Compares a mesh given as an OBJ in OpenSubdiv's regression-shape format (`t` tags; see
/// [`parse_obj_shape`]).
///
/// # Errors
/// The shape cannot be parsed, has hierarchical edits ([`MeshError::Unsupported`], "not
/// supported"), or [`compare`] fails; every message names the shape.
pub fn compare_obj(name: &str, text: &str, options: &CompareOptions) -> Result<CompareReport, MeshError> {
    let shape = parse_obj_shape(name, text)?;
    shape.check_supported()?;
    let mut report = compare(name, &shape.topology, &shape.points, options)?;
    if shape.crease_method == CreaseMethod::Chaikin {
        report
            .notes
            .push("the shape asks for Chaikin creasing, which USD cannot express: evaluated with uniform creasing on both sides".into());
    }
    if !shape.ignored_tags.is_empty() {
        report.notes.push(format!("tags without effect here: {}", shape.ignored_tags.join(", ")));
    }
    Ok(report)
}

/// Compares one mesh's subdivision surface (object space) with OpenSubdiv's, as the module doc
/// says. A `Scheme::None` mesh is compared as bilinear (its patches are the control polygons).
///
/// # Errors
/// [`MeshError`] naming the mesh: invalid topology, non-finite points, OpenSubdiv refusing it,
/// or a mesh without patches (all holes).
pub fn compare(name: &str, topology: &MeshTopology, points: &[[f32; 3]], options: &CompareOptions) -> Result<CompareReport, MeshError> {
    let surface = OsdSurface::with_options(name, topology, points, &options.osd)?;
    let n_patches = surface.patch_count();
    if n_patches == 0 {
        return Err(MeshError::Invalid(format!("{name}: the mesh has no patches (every face is a hole)")));
    }
    let diag = Bounds3::from_points(points.iter().map(|&p| Vec3A::from(p))).diagonal().length();
    if !(diag.is_finite() && diag > 0.0) {
        return Err(MeshError::Invalid(format!("{name}: the control points span no volume (bounding-box diagonal {diag})")));
    }
    let mut notes = Vec::new();
    if !surface.warnings().is_empty() {
        notes.push(format!("OpenSubdiv: {}", surface.warnings().lines().collect::<Vec<_>>().join("; ")));
    }
    // The reference keeps Gregory end caps at every valence: what differs near such a vertex
    // is the simplification, not a bug (docs/subdivision-compare.md, "Cost at high valence").
    if let Some(said) = surface.simplified() {
        notes.push(format!(
            "{said}; the reference has Gregory end caps, so position and normal errors near that vertex are the simplification's"
        ));
    }
    let mut patch_kinds = BTreeMap::new();
    for p in 0..n_patches {
        *patch_kinds.entry(kind_name(surface.patch_param(p).kind).to_string()).or_insert(0) += 1;
    }
    if topology.scheme == Scheme::Loop {
        notes.push("triangle patches: limit and tessellation errors are measured over their domain u + v ≤ 1".into());
    }
    let limit = limit_errors(name, topology, points, &surface, options)?;
    let tess = tessellation::measure(&surface, options);
    let wt = watertight::check(&surface, topology, diag, options);
    let uniform = if options.uniform_level > 0 {
        Some(uniform::measure(&surface, options.uniform_level, options.uniform_points, diag)?)
    } else {
        None
    };
    let rel = |e: f64| e / f64::from(diag);
    let relmap = |m: &BTreeMap<String, f64>| m.iter().map(|(k, v)| (k.clone(), rel(*v))).collect::<BTreeMap<_, _>>();
    Ok(CompareReport {
        shape: name.to_string(),
        scheme: scheme_token(topology.scheme).to_string(),
        faces: topology.face_count(),
        points: points.len(),
        patches: n_patches,
        patch_kinds,
        bbox_diagonal: diag,
        samples: limit.samples,
        max_rel_position_error: rel(limit.max_pos),
        rms_rel_position_error: rel(limit.rms_pos),
        max_normal_angle_deg: limit.max_angle_deg,
        max_normal_angle_beyond_rounding_deg: limit.angle_beyond_rounding_deg,
        degenerate_normals: limit.degenerate,
        max_rel_tessellation_error: relmap(&tess.by_tier),
        max_rel_tessellation_error_by_rate: relmap(&tess.by_rate),
        max_rel_tessellation_error_after_split: relmap(&tess.after_split),
        tessellation_patches_measured: tess.patches,
        watertight: wt.watertight(),
        watertight_detail: wt,
        uniform,
        notes,
    })
}

/// Limit-evaluation errors in object units.
struct LimitErrors {
    samples: usize,
    max_pos: f64,
    rms_pos: f64,
    max_angle_deg: f64,
    angle_beyond_rounding_deg: f64,
    degenerate: usize,
}

fn limit_errors(
    name: &str,
    topology: &MeshTopology,
    points: &[[f32; 3]],
    surface: &OsdSurface,
    options: &CompareOptions,
) -> Result<LimitErrors, MeshError> {
    let side = options.samples_per_side.max(2);
    let mut ours = Vec::new();
    let mut locations = Vec::new();
    for patch in 0..surface.patch_count() {
        let pp = surface.patch_param(patch);
        for j in 0..side {
            for i in 0..side {
                let (u, v) = UvRect::UNIT.grid_uv(i, j, side);
                if !in_domain(pp.kind, u, v) {
                    continue;
                }
                ours.push((
                    surface.evaluate(patch, u, v),
                    u > 0.0 && v > 0.0 && u < 1.0 && v < 1.0 && (!pp.kind.is_triangle() || u + v < 1.0),
                ));
                let (fu, fv) = pp.to_face_uv(u, v);
                locations.push((pp.ptex_face, fu, fv));
            }
        }
    }
    let reference = limit_reference(name, topology, points, &options.osd, &locations)?;
    let (mut max_pos, mut sum2, mut max_angle, mut degenerate) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    let mut max_excess = 0.0f64;
    for ((s, interior), r) in ours.iter().zip(&reference) {
        let d = f64::from((s.p - r.p).length());
        max_pos = max_pos.max(if d.is_nan() { f64::INFINITY } else { d });
        sum2 += d * d;
        // Normals only inside patches: on a patch's edge the stencils may evaluate the patch
        // on the other side, and across a crease the normal has two values.
        if !interior {
            continue;
        }
        let (a, b) = (s.dpdu.cross(s.dpdv), r.dpdu.cross(r.dpdv));
        // Derivatives within 0.06° of parallel (next to a valence-2 vertex, a pole) leave the
        // normal's direction to rounding.
        // A derivative 1e4 times shorter than the other is a collapsed direction (a degenerate
        // patch of a non-manifold configuration): its direction is rounding too.
        let well_defined = |n: Vec3A, du: Vec3A, dv: Vec3A| {
            let (a, b) = (du.length(), dv.length());
            n.length() > 1e-3 * a * b && a.min(b) > 1e-4 * a.max(b) && n.is_finite()
        };
        if !(well_defined(a, s.dpdu, s.dpdv) && well_defined(b, r.dpdu, r.dpdv)) {
            degenerate += 1;
            continue;
        }
        // What rounding alone leaves of the direction: positions carry ~16 ulps of their
        // magnitude, and derivatives on a small patch far from the origin are differences of
        // such positions, so the normal's direction is uncertain by that over the shorter one.
        let shortest = s.dpdu.length().min(s.dpdv.length()).min(r.dpdu.length()).min(r.dpdv.length());
        let floor_deg = f64::from(16.0 * f32::EPSILON * s.p.abs().max_element().max(1e-30) / shortest).to_degrees();
        let cos = f64::from(a.normalize().dot(b.normalize())).clamp(-1.0, 1.0);
        // acos loses precision near 1: use the cross product's length for small angles.
        let sin = f64::from(a.normalize().cross(b.normalize()).length()).min(1.0);
        let angle = sin.atan2(cos).to_degrees();

        max_angle = max_angle.max(angle);
        max_excess = max_excess.max(angle - floor_deg);
    }
    let n = ours.len().max(1) as f64;
    Ok(LimitErrors {
        samples: ours.len(),
        max_pos,
        rms_pos: (sum2 / n).sqrt(),
        max_angle_deg: max_angle,
        angle_beyond_rounding_deg: max_excess.max(0.0),
        degenerate,
    })
}

fn fmt_e(x: f64) -> String {
    format!("{x:.2e}")
}

impl CompareReport {
    /// A readable table: one line per figure.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let mut line = |k: &str, v: String| {
            s.push_str(&format!("{k:<44} {v}\n"));
        };
        line("shape", self.shape.clone());
        line("scheme", self.scheme.clone());
        line("faces / points / patches", format!("{} / {} / {}", self.faces, self.points, self.patches));
        line("patch kinds", self.patch_kinds.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", "));
        line("bounding-box diagonal", format!("{:.6}", self.bbox_diagonal));
        line("limit samples vs OpenSubdiv's evaluation", self.samples.to_string());
        line(
            "  max / rms position error (rel. diag)",
            format!("{} / {}", fmt_e(self.max_rel_position_error), fmt_e(self.rms_rel_position_error)),
        );
        line(
            "  max normal angle (deg)",
            format!(
                "{} ({} beyond rounding; {} degenerate left out)",
                fmt_e(self.max_normal_angle_deg),
                fmt_e(self.max_normal_angle_beyond_rounding_deg),
                self.degenerate_normals
            ),
        );
        line("tessellation error by tier (rel. diag)", String::new());
        for t in ["coarse", "medium", "fine"] {
            if let Some(e) = self.max_rel_tessellation_error.get(t) {
                line(&format!("  {t}"), fmt_e(*e));
            }
        }
        line("tessellation error by rate (quads a side)", String::new());
        let mut rates: Vec<_> = self.max_rel_tessellation_error_by_rate.iter().collect();
        rates.sort_by_key(|(k, _)| k.parse::<u32>().unwrap_or(0));
        for (k, e) in rates {
            line(&format!("  {k}"), fmt_e(*e));
        }
        for (k, e) in &self.max_rel_tessellation_error_after_split {
            line(&format!("  split depth {k} (17x17 children)"), fmt_e(*e));
        }
        line("  patches measured", self.tessellation_patches_measured.to_string());
        let w = &self.watertight_detail;
        line("watertight", self.watertight.to_string());
        line("  shared edge points / max mismatch (rel.)", format!("{} / {}", w.shared_edge_points, fmt_e(w.max_rel_edge_mismatch)));
        line("  max mismatch / seam margin", format!("{:.3}", w.max_edge_mismatch_over_margin));
        line("  T-junction gap without seams (rel.)", fmt_e(w.max_rel_rate_gap));
        line("  seam chords checked / worst coverage", format!("{} / {:.3}", w.seam_chords_checked, w.max_seam_coverage_ratio));
        if let Some(u) = &self.uniform {
            line(
                &format!("uniform refinement level {} vs limit", u.level),
                format!("{} points: max {} rms {}", u.points_measured, fmt_e(u.max_rel_distance), fmt_e(u.rms_rel_distance)),
            );
        }
        for n in &self.notes {
            line("note", n.clone());
        }
        s
    }
}
