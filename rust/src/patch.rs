//! Patches of a limit surface: the trait through which the core evaluates subdivision surfaces
//! without depending on OpenSubdiv.
//!
//! The bridge (`mipray-bridge`) implements [`LimitSurface`] with OpenSubdiv's `Far::PatchTable`;
//! the core implements it for polygonal meshes ([`crate::bilinear::BilinearSurface`]) so that it
//! builds and tests with no C++. Every patch is one root subpatch (the paper's §5.1).
//!
//! Coordinate conventions: positions and derivatives are in the mesh's **object space**; (u, v)
//! are the patch's own parameters in [0, 1]², and derivatives are taken with respect to them.
//! [`PatchParam`] maps them into the face's parameterization for texture lookups.

use glam::Vec3A;

use crate::bounds::Bounds3;

/// The basis a patch is evaluated with (OpenSubdiv's `PatchDescriptor::Type`, plus the core's own).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PatchKind {
    /// 4 control points, bilinear: polygonal meshes and the bilinear scheme.
    Bilinear,
    /// 16 control points, bicubic B-spline: regular Catmull-Clark patches.
    Regular,
    /// 20 control points: Gregory basis end caps around extraordinary vertices.
    GregoryBasis,
    /// 12 control points, quartic box spline: regular Loop patches (triangular domain).
    LoopRegular,
    /// 18 control points: triangular Gregory end caps (Loop).
    GregoryTriangle,
    /// Any other basis OpenSubdiv reports.
    Other,
}

impl PatchKind {
    /// True for patches whose domain is the triangle u + v ≤ 1 rather than the unit square.
    pub const fn is_triangle(self) -> bool {
        matches!(self, PatchKind::LoopRegular | PatchKind::GregoryTriangle)
    }
}

/// Where a patch lies on the control mesh (OpenSubdiv's `Far::PatchParam`, decoded).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchParam {
    /// The control (base) face the patch lies on.
    pub base_face: u32,
    /// The face in OpenSubdiv's ptex numbering (`Far::PtexIndices`): equal to `base_face` for a
    /// mesh of quads; a non-quad face of n sides owns n consecutive sub-face ids.
    pub ptex_face: u32,
    /// The patch's domain within the (ptex) face's [0, 1]²: origin (u0, v0) and edge length `size`.
    pub u0: f32,
    pub v0: f32,
    pub size: f32,
    /// Adaptive refinement level at which the patch was generated.
    pub depth: u8,
    /// Bit i set: edge i of the patch is on the mesh boundary (OpenSubdiv's boundary mask).
    pub boundary_mask: u8,
    /// Bit i set: edge i borders a patch one level coarser (OpenSubdiv's transition mask).
    pub transition_mask: u8,
    pub kind: PatchKind,
}

impl PatchParam {
    /// A patch that is its whole control face (no adaptive refinement, no boundary or
    /// transition edges), of kind `kind`: what a polygonal or analytic surface has.
    pub const fn root(base_face: u32, ptex_face: u32, kind: PatchKind) -> PatchParam {
        PatchParam { base_face, ptex_face, u0: 0.0, v0: 0.0, size: 1.0, depth: 0, boundary_mask: 0, transition_mask: 0, kind }
    }

    /// Maps the patch's own (u, v) to the ptex face's (u, v).
    pub fn to_face_uv(&self, u: f32, v: f32) -> (f32, f32) {
        (self.u0 + u * self.size, self.v0 + v * self.size)
    }
}

/// The limit surface and its derivatives at one (u, v) of one patch. Object space.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfacePoint {
    pub p: Vec3A,
    pub dpdu: Vec3A,
    pub dpdv: Vec3A,
    pub dpduu: Vec3A,
    pub dpduv: Vec3A,
    pub dpdvv: Vec3A,
}

/// A rectangle of a patch's own (u, v) domain: the domain of a subpatch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvRect {
    pub u0: f32,
    pub v0: f32,
    pub u1: f32,
    pub v1: f32,
}

impl UvRect {
    /// The whole patch, [0, 1]².
    pub const UNIT: UvRect = UvRect { u0: 0.0, v0: 0.0, u1: 1.0, v1: 1.0 };

    /// (u, v) at grid vertex (i, j) of an n×n vertex grid over the rectangle; i runs along u.
    #[inline]
    pub fn grid_uv(&self, i: usize, j: usize, n: usize) -> (f32, f32) {
        let d = (n.max(2) - 1) as f32;
        (self.u0 + (self.u1 - self.u0) * (i as f32 / d), self.v0 + (self.v1 - self.v0) * (j as f32 / d))
    }
}

/// A cone of directions: every unit vector within the half-angle whose sine is
/// `sin_half_angle` of `axis` (unit, object space), or of `-axis`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalCone {
    pub axis: Vec3A,
    /// In [0, 1): the cone is narrower than a half-space.
    pub sin_half_angle: f32,
}

impl NormalCone {
    /// The largest |component| along each object axis a unit vector in the cone has: how far,
    /// per unit of displacement, a point displaced along such a normal can move along that
    /// axis. At most 1; 1 for an axis within the cone.
    pub fn reach(&self) -> Vec3A {
        let g = self.sin_half_angle.clamp(0.0, 1.0).asin();
        let a = self.axis.normalize_or_zero();
        if !(a.length_squared() > 0.5 && g.is_finite()) {
            return Vec3A::ONE;
        }
        let f = |c: f32| {
            // The angle between the axis (either sign) and the object axis, less the cone's.
            let phi = c.abs().min(1.0).acos() - g;
            if phi <= 0.0 {
                1.0
            } else {
                phi.cos()
            }
        };
        Vec3A::new(f(a.x), f(a.y), f(a.z))
    }
}

/// Positions (and optionally first derivatives) on an n×n vertex grid, row-major with u fastest:
/// index `j * n + i`.
#[derive(Clone, Debug, Default)]
pub struct GridSamples {
    pub n: usize,
    pub p: Vec<[f32; 3]>,
    /// Empty unless derivatives were asked for.
    pub dpdu: Vec<[f32; 3]>,
    pub dpdv: Vec<[f32; 3]>,
}

/// Knots of a patch's edge curves: parameter values strictly inside (0, 1), in the patch's own
/// (u, v), at which the curves of its edges running along u (`u`) or along v (`v`) pass from one
/// polynomial piece to the next. A single-crease patch (OpenSubdiv's `useSingleCreasePatch`) is
/// a B-spline along its crease times a C² piecewise cubic across it, with knots at 1 − 2^−⌊S⌋
/// and 1 − 2^−⌈S⌉ from the crease (S its sharpness); [`crate::seam`] fits each piece of a chord
/// on its own, since its fit is exact only for one polynomial. Unused entries are NaN.
#[derive(Clone, Copy, Debug)]
pub struct EdgeKnots {
    pub u: [f32; 2],
    pub v: [f32; 2],
}

impl EdgeKnots {
    /// No knots: every edge curve one polynomial.
    pub const NONE: EdgeKnots = EdgeKnots { u: [f32::NAN; 2], v: [f32::NAN; 2] };
}

/// A set of patches whose union is a mesh's limit surface. Implementations must be cheap to
/// share between render threads (`Send + Sync`) and must never panic on valid indices.
pub trait LimitSurface: Send + Sync {
    /// Number of patches (root subpatches).
    fn patch_count(&self) -> usize;

    /// The patch's parameterization on the control mesh.
    fn patch_param(&self, patch: usize) -> PatchParam;

    /// Conservative object-space bounds of the patch's limit surface: the hull of its control
    /// points (every basis used here is a convex combination of its control points).
    fn patch_bounds(&self, patch: usize) -> Bounds3;

    /// A cone holding the direction (up to sign) of the normal `dpdu × dpdv` everywhere on the
    /// patch, when the implementation can bound it (see [`NormalCone`]). It lets a displaced
    /// patch's box grow by the displacement bound along the normal only, not in every
    /// direction. `None` — the default, and the safe answer — when it cannot.
    fn patch_normal_cone(&self, _patch: usize) -> Option<NormalCone> {
        None
    }

    /// The limit surface and its first and second derivatives at the patch's own (u, v).
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint;

    /// [`LimitSurface::evaluate`] at shutter time `time` (0 = open, 1 = close, as
    /// [`crate::ray::Ray::time`]): the same for a surface that does not deform — the default —
    /// and the blend of the bracketing samples' for one that does ([`crate::deform`]).
    fn evaluate_at(&self, patch: usize, u: f32, v: f32, _time: f32) -> SurfacePoint {
        self.evaluate(patch, u, v)
    }

    /// The surface's time samples when its control points move within the shutter
    /// ([`crate::deform`]): the tracer then tests each ray against the grid blended at its
    /// time. `None` — the default — for a surface that keeps its shape.
    fn deformation(&self) -> Option<&crate::deform::DeformingSurface> {
        None
    }

    /// The surface's trim curves when it has any (a NurbsPatch's `trimCurve:*`,
    /// [`crate::trim`]): the tracer passes over a hit whose patch (u, v) the trim cuts away.
    /// `None` — the default — for an untrimmed surface.
    fn trim(&self) -> Option<crate::trim::SharedTrim> {
        None
    }

    /// Whether the surface deforms within the shutter, known without building it (a surface
    /// built on first use says so up front): what the render's effects list reads.
    fn deforms(&self) -> bool {
        self.deformation().is_some()
    }

    /// Evaluates an n×n vertex grid over `rect` of one patch in one call (the bridge crosses into
    /// C++ once per grid, not once per vertex). Fills `out.p`, and `out.dpdu`/`out.dpdv` when
    /// `derivatives` is true.
    fn evaluate_grid(&self, patch: usize, rect: UvRect, n: usize, derivatives: bool, out: &mut GridSamples) {
        out.n = n;
        out.p.clear();
        out.dpdu.clear();
        out.dpdv.clear();
        for j in 0..n {
            for i in 0..n {
                let (u, v) = rect.grid_uv(i, j, n);
                let s = self.evaluate(patch, u, v);
                out.p.push(s.p.into());
                if derivatives {
                    out.dpdu.push(s.dpdu.into());
                    out.dpdv.push(s.dpdv.into());
                }
            }
        }
    }

    /// Positions at the patch's own (u, v) pairs `uv`, into `out` (cleared first): the `p` of
    /// [`LimitSurface::evaluate`] without the derivatives, in one call (the bridge crosses into
    /// C++ once for all of them). May differ from `evaluate` by the rounding of the result.
    fn evaluate_points(&self, patch: usize, uv: &[[f32; 2]], out: &mut Vec<[f32; 3]>) {
        out.clear();
        out.extend(uv.iter().map(|&[u, v]| <[f32; 3]>::from(self.evaluate(patch, u, v).p)));
    }

    /// Number of control (base) faces of the mesh.
    fn control_face_count(&self) -> usize;

    /// Where the patch's edge curves stop being one polynomial, in its own (u, v): see
    /// [`EdgeKnots`]. [`EdgeKnots::NONE`] (the default) for polynomial patches, which every
    /// OpenSubdiv patch is but a single-crease one.
    fn edge_knots(&self, _patch: usize) -> EdgeKnots {
        EdgeKnots::NONE
    }

    /// True when the patch is an affine image of the unit square (a flat parallelogram with
    /// its parameterization linear): one quad represents it exactly, so the tracer tests it at
    /// rate 1 whatever the beam width. `false` (the safe answer) unless an implementation knows.
    fn patch_is_affine(&self, _patch: usize) -> bool {
        false
    }

    /// A 2-float primvar channel (texture coordinates `st`, say) at the patch's own (u, v): its
    /// value and its derivatives with respect to u and v. Channels are numbered in the order the
    /// surface was built with them; any USD interpolation is held as a face-varying channel (see
    /// [`crate::texture::Primvar2`]). `None` when the surface has no such channel — the default.
    fn face_varying(&self, _channel: usize, _patch: usize, _u: f32, _v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        None
    }

    /// [`LimitSurface::face_varying`] at every vertex of the n×n grid over `rect` (u fastest,
    /// at [`UvRect::grid_uv`]), into `out` (cleared first; n² entries). Surfaces whose
    /// evaluation has a cheaper form over a grid override it (a displaced grid reads its
    /// texture coordinates at each vertex it builds); the default is the point evaluation.
    fn face_varying_grid(&self, channel: usize, patch: usize, rect: UvRect, n: usize, out: &mut Vec<Option<crate::texture::Value2>>) {
        out.clear();
        for j in 0..n {
            for i in 0..n {
                let (u, v) = rect.grid_uv(i, j, n);
                out.push(self.face_varying(channel, patch, u, v));
            }
        }
    }

    /// What this surface made cheaper than its exact definition to bound the work it costs, or
    /// drew other than authored, in one line (say, bilinear end caps around a vertex of very
    /// high valence, or curves drawn as their control polygons). `None` — the
    /// default — when it is exact. Listed in the stats' `scene.simplified`.
    fn simplified(&self) -> Option<&str> {
        None
    }

    /// The surface's closed-form ray test when it has one (implicit gprims and points,
    /// [`crate::implicit`]): the tracer then tests each patch exactly instead of tessellating
    /// it. `None` — the default — for surfaces that are tessellated.
    fn exact(&self) -> Option<&dyn crate::implicit::ExactSurface> {
        None
    }

    /// The surface's curves when it is one (USD BasisCurves, [`crate::curves`]): the tracer then
    /// tessellates each segment into linear pieces at the ray's rate and tests those. `None` —
    /// the default — for every other surface.
    fn curves(&self) -> Option<&crate::curves::CurvesSurface> {
        None
    }

    /// Conservative object-space bounds of the whole surface when it builds its patches on
    /// first use ([`crate::lazy_surface::LazySurface`]): the tracer then places its instances
    /// by these and builds the mesh's subpatches only when a ray reaches one. `None` — the
    /// default — for a surface built already.
    fn lazy_bounds(&self) -> Option<Bounds3> {
        None
    }

    /// Builds what the surface builds on first use, now. `Err` says why it cannot be built (the
    /// tracer then leaves the mesh out); a surface built already has nothing to do.
    fn prepare(&self) -> Result<(), String> {
        Ok(())
    }

    /// Whether the surface's patches exist (always, but for one built on first use that no one
    /// has used yet).
    fn is_built(&self) -> bool {
        true
    }

    /// Heap bytes of what the surface built (its patch tables, points and records): what
    /// dropping it gives back. An estimate (capacities, not the allocator's overhead); 0 — the
    /// default — when the surface does not say.
    fn memory_bytes(&self) -> usize {
        0
    }

    /// Drops what a surface built on first use has built, so that the next use builds it
    /// again (the same surface, bit for bit); `false` when there is nothing to drop or it is
    /// being built now. The memory is freed once no pinned thread can hold a reference into it
    /// ([`crate::geometry_budget`]). The default drops nothing.
    ///
    /// # Safety
    /// Every thread that may hold a reference the surface handed out (an evaluation in
    /// progress) must be pinned ([`crate::geometry_budget::pin`]) while it does: an unpinned
    /// reference could outlive the memory. A [`crate::trace::Tracer`] with a geometry budget
    /// calls it, during a render whose readers are pinned.
    unsafe fn release(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `reach` against brute force: unit vectors sampled on the cone's rim and inside it (either
    /// sign) never have a larger |component| than it says, and the rim comes within 1e-3 of it.
    #[test]
    fn a_cone_s_reach_is_its_largest_component_per_axis() {
        for (axis, sin) in [(Vec3A::Z, 0.0), (Vec3A::new(0.3, -0.5, 0.8), 0.2), (Vec3A::new(1.0, 1.0, 0.0), 0.6), (Vec3A::X, 0.99)] {
            let cone = NormalCone { axis: axis.normalize(), sin_half_angle: sin };
            let reach = cone.reach();
            let a = axis.normalize();
            let (t1, t2) = a.any_orthonormal_pair();
            let g = f32::asin(sin);
            let mut seen = Vec3A::ZERO;
            for i in 0..=20 {
                let angle = g * i as f32 / 20.0;
                for k in 0..360 {
                    let phi = (k as f32).to_radians();
                    let n = a * angle.cos() + (t1 * phi.cos() + t2 * phi.sin()) * angle.sin();
                    for m in [n, -n] {
                        assert!(m.abs().cmple(reach + 1e-5).all(), "{m:?} beyond {reach:?} for {cone:?}");
                        seen = seen.max(m.abs());
                    }
                }
            }
            assert!((reach - seen).abs().max_element() < 1e-3, "reach {reach:?} vs sampled {seen:?}");
        }
    }
}
