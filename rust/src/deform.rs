//! Deformation motion blur: a mesh whose control points move within the shutter (a skinned
//! character, point-animated cloth), held as one limit surface per time sample over the same
//! topology, as Embree's and RenderMan's multi-segment motion do.
//!
//! Every basis used here (OpenSubdiv's patches, bilinear faces) is linear in the control
//! points, so the surface of control points blended between two samples is the same blend of
//! the two samples' surfaces: a ray at shutter time t meets the grid linearly blended between
//! its bracketing samples' grids (each tessellated and cached like any grid, under its own
//! cache key, [`sample_generation`]) and is shaded by the blend of their evaluations
//! ([`LimitSurface::evaluate_at`]). A patch's box is the union of its boxes at the samples,
//! which holds every blend (a box is convex). A mesh without samples takes none of this path.
//!
//! Points and curves deform by the same rules without this type: `PointsSurface` holds each
//! sample's spheres and intersects the sphere blended at the ray's time exactly
//! ([`crate::implicit`]); `CurvesSurface` caches each sample's pieces under
//! [`sample_generation`] and blends them with [`blend`] ([`crate::curves`]). All bracket a
//! ray's time by [`bracket`].

use std::sync::Arc;

use glam::Vec3A;

use crate::bounds::Bounds3;
use crate::patch::{EdgeKnots, GridSamples, LimitSurface, PatchParam, SurfacePoint, UvRect};
use crate::seam::SeamNormal;
use crate::tessellate::{GridBoxes, Tessellation, CULL_STRIDES};

/// Most time samples a deforming surface takes (USD stages rarely author more inside one
/// shutter; the delegate warns and renders at the frame's time beyond it).
pub const MAX_SAMPLES: usize = 16;

/// A limit surface whose control points are sampled at times across the shutter, all samples
/// over one topology.
pub struct DeformingSurface {
    /// Strictly increasing shutter times (0 = open, 1 = close), one per sample.
    times: Vec<f32>,
    samples: Vec<Arc<dyn LimitSurface>>,
}

impl std::fmt::Debug for DeformingSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeformingSurface").field("times", &self.times).finish()
    }
}

impl DeformingSurface {
    /// The surface through `samples` (shutter time, the surface of the control points then).
    ///
    /// # Errors
    /// One line: fewer than 2 or more than [`MAX_SAMPLES`] samples, times not finite or not
    /// strictly increasing, samples whose patches differ in count or layout (another
    /// topology), or a sample that is itself deforming, exact or a curve.
    pub fn new(samples: Vec<(f32, Arc<dyn LimitSurface>)>) -> Result<Self, String> {
        check_times(&samples.iter().map(|s| s.0).collect::<Vec<_>>())?;
        let first = &samples[0].1;
        for (t, s) in &samples {
            if s.exact().is_some() || s.curves().is_some() || s.deformation().is_some() {
                return Err("only tessellated surfaces deform (not implicit prims, points, curves or nested samples)".into());
            }
            let same = s.patch_count() == first.patch_count()
                && s.control_face_count() == first.control_face_count()
                && (0..s.patch_count()).all(|p| s.patch_param(p) == first.patch_param(p));
            if !same {
                return Err(format!("the deformation sample at shutter time {t} has another topology than the first"));
            }
        }
        let (times, samples) = samples.into_iter().unzip();
        Ok(DeformingSurface { times, samples })
    }

    /// The samples' shutter times.
    pub fn times(&self) -> &[f32] {
        &self.times
    }

    /// Sample `k`'s surface.
    pub fn sample(&self, k: usize) -> &dyn LimitSurface {
        self.samples[k].as_ref()
    }

    /// The samples bracketing shutter time `t` and the blend weight of the second: (k, k + 1,
    /// f) with the surface at `t` = (1 − f)·sample k + f·sample k + 1. Times outside the
    /// samples hold the nearest (f = 0 or 1), as [`crate::motion::MotionTransform::at`] does.
    pub fn bracket(&self, t: f32) -> (usize, usize, f32) {
        bracket(&self.times, t)
    }
}

/// The samples among strictly increasing shutter times `times` (at least 2) bracketing shutter
/// time `t`, and the blend weight of the second: (k, k + 1, f), the value at `t` being
/// (1 − f)·value k + f·value k + 1. Times outside the samples (and NaN) hold the nearest (f = 0
/// or 1), as [`crate::motion::MotionTransform::at`] does. Every deforming surface (meshes here,
/// points in [`crate::implicit`], curves in [`crate::curves`]) brackets by this one rule.
pub fn bracket(times: &[f32], t: f32) -> (usize, usize, f32) {
    let last = times.len() - 1;
    if !(t > times[0]) {
        return (0, 1, 0.0);
    }
    if t >= times[last] {
        return (last - 1, last, 1.0);
    }
    let i = times.partition_point(|&x| x <= t) - 1;
    (i, i + 1, (t - times[i]) / (times[i + 1] - times[i]))
}

/// Why `times` cannot be a deforming surface's sample times, if they cannot: one line (2 to
/// [`MAX_SAMPLES`] of them, finite and strictly increasing).
pub fn check_times(times: &[f32]) -> Result<(), String> {
    if !(2..=MAX_SAMPLES).contains(&times.len()) {
        return Err(format!("{} deformation samples (2 to {MAX_SAMPLES} are traced)", times.len()));
    }
    if times.windows(2).any(|w| !(w[0] < w[1])) || times.iter().any(|t| !t.is_finite()) {
        return Err("deformation sample times are not finite and strictly increasing".into());
    }
    Ok(())
}

/// The cache key generation of sample `k`'s tessellations of a mesh at `generation`: sample 0
/// keeps the mesh's own, the others set the top bits, so each sample's grids are cache entries
/// of their own (counted in the cache's budget like any) that an edit of the mesh (a new
/// generation) invalidates together.
pub fn sample_generation(generation: u32, k: usize) -> u32 {
    generation ^ ((k as u32) << 27)
}

/// Lerp of two points in f32, exact at the ends (f = 0 gives `a`, f = 1 gives `b`).
#[inline]
fn lerp(a: Vec3A, b: Vec3A, f: f32) -> Vec3A {
    a * (1.0 - f) + b * f
}

fn lerp_point(a: SurfacePoint, b: SurfacePoint, f: f32) -> SurfacePoint {
    SurfacePoint {
        p: lerp(a.p, b.p, f),
        dpdu: lerp(a.dpdu, b.dpdu, f),
        dpdv: lerp(a.dpdv, b.dpdv, f),
        dpduu: lerp(a.dpduu, b.dpduu, f),
        dpduv: lerp(a.dpduv, b.dpduv, f),
        dpdvv: lerp(a.dpdvv, b.dpdvv, f),
    }
}

/// The grid of the surface blended `f` of the way from `a`'s to `b`'s (two samples' grids of
/// one subpatch at one tier, object space): vertices blended, their boxes made again from
/// them as [`crate::tessellate::tessellate`] makes a tier's, and the error bounds the larger
/// of the two — a blend's sag from its chords is the blend of the samples' sags. The seam
/// boxes take the whole radius on both sides of the chords ([`SeamNormal::ISOTROPIC`]): the
/// samples' extents along their chords' normals do not bound the blend's along its own.
pub fn blend(a: &Tessellation, b: &Tessellation, f: f32) -> Tessellation {
    if f <= 0.0 {
        return a.clone();
    }
    if f >= 1.0 {
        return b.clone();
    }
    let verts: Vec<[f32; 3]> = a.verts.iter().zip(b.verts.iter()).map(|(p, q)| lerp(Vec3A::from(*p), Vec3A::from(*q), f).into()).collect();
    let mut t = Tessellation {
        n: a.n,
        verts: verts.into(),
        boxes: GridBoxes::NONE,
        chord_error: a.chord_error.max(b.chord_error),
        seam_radius: a.seam_radius.max(b.seam_radius),
        seam_normal: SeamNormal::ISOTROPIC,
        domain: a.domain,
    };
    if !a.boxes.is_empty() {
        let sub_boxes: Vec<Bounds3> = if a.boxes.sub_boxes().is_empty() {
            Vec::new()
        } else {
            let q = (t.n - 1) / 4;
            (0..16)
                .map(|s| {
                    let (bi, bj) = (s % 4 * q, s / 4 * q);
                    let mut bb = Bounds3::EMPTY;
                    for j in bj..=bj + q {
                        for i in bi..=bi + q {
                            bb.grow(t.vert(i, j));
                        }
                    }
                    bb
                })
                .collect()
        };
        let cull: [Bounds3; CULL_STRIDES] = std::array::from_fn(|s| crate::seam::cull_box(&t, s + 1));
        t.boxes = GridBoxes::refill(cull, &sub_boxes, GridBoxes::NONE);
    }
    t
}

impl LimitSurface for DeformingSurface {
    fn patch_count(&self) -> usize {
        self.samples[0].patch_count()
    }

    fn patch_param(&self, patch: usize) -> PatchParam {
        self.samples[0].patch_param(patch)
    }

    /// The union over the samples: holds the patch at every time of the shutter.
    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        self.samples.iter().fold(Bounds3::EMPTY, |b, s| b.union(&s.patch_bounds(patch)))
    }

    /// At shutter open (the first sample); [`LimitSurface::evaluate_at`] for a ray's time.
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        self.samples[0].evaluate(patch, u, v)
    }

    fn evaluate_at(&self, patch: usize, u: f32, v: f32, time: f32) -> SurfacePoint {
        let (i, j, f) = self.bracket(time);
        if f <= 0.0 {
            return self.samples[i].evaluate(patch, u, v);
        }
        if f >= 1.0 {
            return self.samples[j].evaluate(patch, u, v);
        }
        lerp_point(self.samples[i].evaluate(patch, u, v), self.samples[j].evaluate(patch, u, v), f)
    }

    fn evaluate_grid(&self, patch: usize, rect: UvRect, n: usize, derivatives: bool, out: &mut GridSamples) {
        self.samples[0].evaluate_grid(patch, rect, n, derivatives, out);
    }

    fn evaluate_points(&self, patch: usize, uv: &[[f32; 2]], out: &mut Vec<[f32; 3]>) {
        self.samples[0].evaluate_points(patch, uv, out);
    }

    fn control_face_count(&self) -> usize {
        self.samples[0].control_face_count()
    }

    fn edge_knots(&self, patch: usize) -> EdgeKnots {
        self.samples[0].edge_knots(patch)
    }

    /// A blend of affine maps is affine: affine when every sample is.
    fn patch_is_affine(&self, patch: usize) -> bool {
        self.samples.iter().all(|s| s.patch_is_affine(patch))
    }

    /// Primvars follow the topology, which every sample shares.
    fn face_varying(&self, channel: usize, patch: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        self.samples[0].face_varying(channel, patch, u, v)
    }

    fn simplified(&self) -> Option<&str> {
        self.samples[0].simplified()
    }

    fn memory_bytes(&self) -> usize {
        self.samples.iter().map(|s| s.memory_bytes()).sum()
    }

    fn deformation(&self) -> Option<&DeformingSurface> {
        Some(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bilinear::BilinearSurface;
    use crate::topology::{MeshTopology, Scheme};

    fn quad_at(p: [[f32; 3]; 4]) -> Arc<dyn LimitSurface> {
        let t =
            MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
        Arc::new(BilinearSurface::new(&t, &p).unwrap())
    }

    fn bent(dz: f32) -> [[f32; 3]; 4] {
        [[0.0, 0.0, 0.0], [1.0, 0.0, dz], [1.0, 1.0, 0.5], [0.0, 1.0, -dz]]
    }

    #[test]
    fn brackets_hold_the_ends_and_blend_between() {
        let s = DeformingSurface::new(vec![(0.0, quad_at(bent(0.0))), (0.5, quad_at(bent(1.0))), (1.0, quad_at(bent(3.0)))]).unwrap();
        assert_eq!(s.bracket(-1.0), (0, 1, 0.0));
        assert_eq!(s.bracket(0.0), (0, 1, 0.0));
        assert_eq!(s.bracket(0.25), (0, 1, 0.5));
        assert_eq!(s.bracket(0.75), (1, 2, 0.5));
        assert_eq!(s.bracket(1.0), (1, 2, 1.0));
        assert_eq!(s.bracket(f32::NAN), (0, 1, 0.0));
        // The surface of blended control points, at a time between the samples.
        let mid = quad_at(bent(2.0));
        let (a, b) = (s.evaluate_at(0, 0.3, 0.6, 0.75), mid.evaluate(0, 0.3, 0.6));
        assert!((a.p - b.p).length() < 1e-6 && (a.dpdu - b.dpdu).length() < 1e-6 && (a.dpdv - b.dpdv).length() < 1e-6);
        assert_eq!(s.evaluate_at(0, 0.3, 0.6, 1.0), quad_at(bent(3.0)).evaluate(0, 0.3, 0.6));
        // Bounds hold every sample.
        let bb = s.patch_bounds(0);
        assert!(bb.contains(Vec3A::new(1.0, 0.0, 3.0)) && bb.contains(Vec3A::new(0.0, 1.0, -3.0)));
    }

    #[test]
    fn refuses_bad_samples() {
        assert!(DeformingSurface::new(vec![(0.0, quad_at(bent(0.0)))]).is_err());
        assert!(DeformingSurface::new(vec![(0.5, quad_at(bent(0.0))), (0.5, quad_at(bent(1.0)))]).is_err());
        let two = MeshTopology {
            scheme: Scheme::None,
            face_vertex_counts: vec![3, 3],
            face_vertex_indices: vec![0, 1, 2, 0, 2, 3],
            ..Default::default()
        };
        let tris: Arc<dyn LimitSurface> = Arc::new(BilinearSurface::new(&two, &bent(0.0)).unwrap());
        let e = DeformingSurface::new(vec![(0.0, quad_at(bent(0.0))), (1.0, tris)]).unwrap_err();
        assert!(e.contains("another topology"), "{e}");
    }

    /// A blended grid is the grid of the blended surface: its vertices within rounding of a
    /// tessellation of the blended control points, its boxes holding them.
    #[test]
    fn a_blended_grid_is_the_blended_surface_s_grid() {
        use crate::geometry_cache::Tier;
        use crate::subpatch::RootSubpatch;
        let (a, b, mid) = (quad_at(bent(0.0)), quad_at(bent(2.0)), quad_at(bent(0.5)));
        let sub = RootSubpatch::new(0, a.patch_bounds(0).union(&b.patch_bounds(0)), false).subpatch(UvRect::UNIT);
        for tier in [Tier::Coarse, Tier::Medium, Tier::Fine] {
            let mut scratch = GridSamples::default();
            let (ta, _) = crate::tessellate::tessellate(a.as_ref(), &sub, tier, None, &mut scratch);
            let (tb, _) = crate::tessellate::tessellate(b.as_ref(), &sub, tier, None, &mut scratch);
            let (tm, _) = crate::tessellate::tessellate(mid.as_ref(), &sub, tier, None, &mut scratch);
            let t = blend(&ta, &tb, 0.25);
            assert_eq!(t.n, tm.n);
            for (p, q) in t.verts.iter().zip(tm.verts.iter()) {
                assert!((Vec3A::from(*p) - Vec3A::from(*q)).length() < 1e-6, "{tier:?}: {p:?} vs {q:?}");
            }
            assert_eq!(t.boxes.sub_boxes().len(), tm.boxes.sub_boxes().len());
            for s in 1..=2 {
                if let Some(c) = t.boxes.cull(s) {
                    assert!(t.verts.iter().all(|v| c.contains(Vec3A::from(*v))));
                }
            }
            assert_eq!(blend(&ta, &tb, 0.0), ta);
            assert_eq!(blend(&ta, &tb, 1.0), tb);
        }
    }
}
