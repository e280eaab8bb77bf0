//! Limit surfaces built on first use (issue 15): a mesh no ray reaches costs its bounds, not
//! its patch table.
//!
//! OpenSubdiv's refiner, patch table and refined points are most of a scene's memory outside the
//! geometry cache (docs/memory.md) and most of its sync time. A [`LazySurface`] holds only what
//! the top-level BVH needs before any ray is traced — conservative object-space bounds of the
//! whole surface and its control-face count — and a builder; the first call that needs the
//! patches builds them, once, whichever thread asks (the others wait for it). The tracer builds
//! a mesh's root subpatches and bottom-level BVH only when a ray first enters one of the mesh's
//! instances' boxes ([`crate::trace::Tracer`]), so a mesh behind the camera never builds at all.
//!
//! The bounds must contain the built surface: the tracer enters an instance only through them.
//! For a subdivision surface the hull of its control points does (every Catmull-Clark and Loop
//! rule is a convex combination); an end-cap approximation could in principle bulge out of it,
//! which the tracer checks when it builds the mesh and reports (`geometry.lazy_bounds_escaped`).

use std::sync::atomic::{AtomicPtr, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use crate::bounds::Bounds3;
use crate::patch::{EdgeKnots, GridSamples, LimitSurface, PatchParam, SurfacePoint, UvRect};

/// Builds a surface; `Err` is one line saying why it cannot be built (without the prim's name).
pub type SurfaceBuilder<S = dyn LimitSurface> = Box<dyn Fn() -> Result<Arc<S>, String> + Send + Sync>;

/// A tessellated limit surface built on first use. Surfaces intersected exactly
/// ([`LimitSurface::exact`]) are cheap and are never wrapped: a builder returning one is
/// refused when it runs.
///
/// `S` is the built surface's type (any, by default): a caller that names it (the delegate's
/// `LazySurface<OsdSurface>`) can reach the built surface to update it in place.
///
/// A geometry budget may drop the built surface ([`LimitSurface::release`]); the next use builds
/// it again. References it handed out stay valid while the thread holding them stays pinned
/// ([`crate::geometry_budget`]).
pub struct LazySurface<S: ?Sized + LimitSurface + 'static = dyn LimitSurface> {
    /// Object space; contains the built surface (see the module's note).
    bounds: Bounds3,
    control_faces: usize,
    build: SurfaceBuilder<S>,
    /// The built surface (`Box::into_raw`), or null: not built, failed, or dropped by a budget.
    built: AtomicPtr<Arc<S>>,
    /// Why the build failed; a failure is final (the builder would fail again).
    failed: OnceLock<String>,
    /// Serializes builds and drops: one build at a time, the other threads wait for it.
    lock: parking_lot::Mutex<()>,
    /// Builds that ran (a surface dropped and built again counts twice).
    builds: AtomicU64,
    /// The built surface deforms within the shutter ([`LazySurface::deforming`]).
    deforms: bool,
}

impl<S: ?Sized + LimitSurface + 'static> std::fmt::Debug for LazySurface<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LazySurface").field("bounds", &self.bounds).field("built", &self.is_built()).finish()
    }
}

impl<S: ?Sized + LimitSurface + 'static> Drop for LazySurface<S> {
    fn drop(&mut self) {
        let p = *self.built.get_mut();
        if !p.is_null() {
            // SAFETY: the pointer came from `Box::into_raw` and, unlinked only here or by
            // `release` (which nulls it first), is owned by this surface alone.
            drop(unsafe { Box::from_raw(p) });
        }
    }
}

impl<S: ?Sized + LimitSurface + 'static> LazySurface<S> {
    /// A surface of `control_faces` faces whose limit surface lies within `bounds` (object
    /// space), made by `build` when first needed.
    pub fn new(bounds: Bounds3, control_faces: usize, build: SurfaceBuilder<S>) -> Self {
        LazySurface {
            bounds,
            control_faces,
            build,
            built: AtomicPtr::new(std::ptr::null_mut()),
            failed: OnceLock::new(),
            lock: parking_lot::Mutex::new(()),
            builds: AtomicU64::new(0),
            deforms: false,
        }
    }

    /// Says up front that the built surface deforms within the shutter ([`crate::deform`]),
    /// so the render calls for motion blur before any ray builds it.
    pub fn deforming(mut self) -> Self {
        self.deforms = true;
        self
    }

    /// With no one else holding it: the built surface to change in place (new points);
    /// `None` when it is not built (or failed to build). The caller then sets the bounds and
    /// builder that match the change ([`LazySurface::rebase`]).
    pub fn built_mut(&mut self) -> Option<&mut Arc<S>> {
        let p = *self.built.get_mut();
        // SAFETY: `&mut self` excludes every other reference to the surface.
        (!p.is_null()).then(|| unsafe { &mut *p })
    }

    /// New bounds and builder for a surface changed in place, so that a rebuild makes what it
    /// now is.
    pub fn rebase(&mut self, bounds: Bounds3, build: SurfaceBuilder<S>) {
        self.bounds = bounds;
        self.build = build;
    }

    /// The built surface, building it now if it is not built; `Err` says why it cannot be
    /// built.
    #[inline]
    pub fn get(&self) -> Result<&Arc<S>, &str> {
        match self.built() {
            Some(s) => Ok(s),
            None => self.build_now(),
        }
    }

    #[cold]
    fn build_now(&self) -> Result<&Arc<S>, &str> {
        let _one = self.lock.lock();
        if let Some(s) = self.built() {
            return Ok(s);
        }
        if let Some(e) = self.failed.get() {
            return Err(e);
        }
        self.builds.fetch_add(1, Ordering::Relaxed);
        let built = (self.build)().and_then(|s| match s.exact() {
            Some(_) => Err("an exactly intersected surface cannot be built lazily".to_string()),
            None => Ok(s),
        });
        match built {
            Ok(s) => {
                let p = Box::into_raw(Box::new(s));
                self.built.store(p, Ordering::Release);
                // SAFETY: just made; freed only by `release` (deferred past the pins) or drop.
                Ok(unsafe { &*p })
            }
            Err(e) => Err(self.failed.get_or_init(|| e)),
        }
    }

    /// Whether the surface is built now (or its build was tried and failed).
    pub fn is_built(&self) -> bool {
        !self.built.load(Ordering::Acquire).is_null() || self.failed.get().is_some()
    }

    /// The built surface, if built and buildable, without building it.
    #[inline]
    pub fn built(&self) -> Option<&Arc<S>> {
        let p = self.built.load(Ordering::Acquire);
        // SAFETY: a non-null pointer is a live `Box<Arc<S>>`: `release` unlinks it before
        // retiring it, and frees it only once the threads pinned then unpin (the contract of
        // `LimitSurface::release`).
        (!p.is_null()).then(|| unsafe { &*p })
    }

    /// Times the surface was built (more than once when a budget dropped it in between).
    pub fn builds(&self) -> u64 {
        self.builds.load(Ordering::Relaxed)
    }

    #[inline]
    fn inner(&self) -> Option<&S> {
        self.get().ok().map(|s| s.as_ref())
    }
}

/// Forwards to the built surface. A surface that failed to build has no patches: the tracer
/// asks [`LimitSurface::prepare`] first and leaves such a mesh out, so nothing asks for one.
impl<S: ?Sized + LimitSurface + 'static> LimitSurface for LazySurface<S> {
    fn patch_count(&self) -> usize {
        self.inner().map_or(0, |s| s.patch_count())
    }

    fn patch_param(&self, patch: usize) -> PatchParam {
        match self.inner() {
            Some(s) => s.patch_param(patch),
            None => PatchParam::root(0, 0, crate::patch::PatchKind::Other),
        }
    }

    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        self.inner().map_or(Bounds3::EMPTY, |s| s.patch_bounds(patch))
    }

    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        self.inner().map_or_else(SurfacePoint::default, |s| s.evaluate(patch, u, v))
    }

    fn evaluate_at(&self, patch: usize, u: f32, v: f32, time: f32) -> SurfacePoint {
        self.inner().map_or_else(SurfacePoint::default, |s| s.evaluate_at(patch, u, v, time))
    }

    fn deformation(&self) -> Option<&crate::deform::DeformingSurface> {
        self.inner()?.deformation()
    }

    fn deforms(&self) -> bool {
        self.deforms
    }

    fn evaluate_grid(&self, patch: usize, rect: UvRect, n: usize, derivatives: bool, out: &mut GridSamples) {
        if let Some(s) = self.inner() {
            s.evaluate_grid(patch, rect, n, derivatives, out);
        }
    }

    fn evaluate_points(&self, patch: usize, uv: &[[f32; 2]], out: &mut Vec<[f32; 3]>) {
        out.clear();
        if let Some(s) = self.inner() {
            s.evaluate_points(patch, uv, out);
        }
    }

    fn control_face_count(&self) -> usize {
        self.control_faces
    }

    fn patch_is_affine(&self, patch: usize) -> bool {
        self.inner().is_some_and(|s| s.patch_is_affine(patch))
    }

    fn patch_normal_cone(&self, patch: usize) -> Option<crate::patch::NormalCone> {
        self.inner().and_then(|s| s.patch_normal_cone(patch))
    }

    fn edge_knots(&self, patch: usize) -> EdgeKnots {
        self.inner().map_or(EdgeKnots::NONE, |s| s.edge_knots(patch))
    }

    fn face_varying(&self, channel: usize, patch: usize, u: f32, v: f32) -> Option<([f32; 2], [f32; 2], [f32; 2])> {
        self.inner()?.face_varying(channel, patch, u, v)
    }

    fn face_varying_grid(&self, channel: usize, patch: usize, rect: UvRect, n: usize, out: &mut Vec<Option<crate::texture::Value2>>) {
        match self.inner() {
            Some(s) => s.face_varying_grid(channel, patch, rect, n, out),
            None => {
                out.clear();
                out.resize(n * n, None);
            }
        }
    }

    /// Known only once built: a surface no ray reached was not simplified in this render.
    fn simplified(&self) -> Option<&str> {
        self.built()?.simplified()
    }

    fn lazy_bounds(&self) -> Option<Bounds3> {
        Some(self.bounds)
    }

    fn prepare(&self) -> Result<(), String> {
        self.get().map(|_| ()).map_err(str::to_string)
    }

    fn is_built(&self) -> bool {
        LazySurface::<S>::is_built(self)
    }

    fn memory_bytes(&self) -> usize {
        self.built().map_or(0, |s| s.memory_bytes())
    }

    unsafe fn release(&self) -> bool {
        // A build in progress is in use: leave it.
        let Some(_one) = self.lock.try_lock() else { return false };
        let p = self.built.swap(std::ptr::null_mut(), Ordering::AcqRel);
        if p.is_null() {
            return false;
        }
        // SAFETY: unlinked above, so no new reference can be made to it; the references made
        // before are held by pinned threads (the caller's contract), and `retire` frees it
        // after they unpin.
        crate::geometry_budget::retire(unsafe { Box::from_raw(p) });
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bilinear::BilinearSurface;
    use crate::topology::MeshTopology;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn quad() -> (MeshTopology, Vec<[f32; 3]>) {
        let t = MeshTopology {
            scheme: crate::topology::Scheme::None,
            face_vertex_counts: vec![4],
            face_vertex_indices: vec![0, 1, 2, 3],
            ..Default::default()
        };
        (t, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.5], [0.0, 1.0, 0.0]])
    }

    /// The bilinear `quad()` (control points `p`) built on first use, each build counted in `calls`.
    fn counted_quad(calls: Arc<AtomicUsize>, p: &[[f32; 3]]) -> LazySurface {
        LazySurface::new(
            Bounds3::from_points(p.iter().map(|&q| q.into())),
            1,
            Box::new(move || {
                calls.fetch_add(1, Ordering::SeqCst);
                let (t, p) = quad();
                Ok(Arc::new(BilinearSurface::new(&t, &p).map_err(|e| e.to_string())?) as Arc<dyn LimitSurface>)
            }),
        )
    }

    #[test]
    fn builds_once_on_first_use_and_forwards() {
        let (t, p) = quad();
        let eager = BilinearSurface::new(&t, &p).unwrap();
        let calls = Arc::new(AtomicUsize::new(0));
        let c = calls.clone();
        let lazy = counted_quad(c, &p);
        assert_eq!(lazy.control_face_count(), 1);
        assert!(lazy.lazy_bounds().is_some());
        assert_eq!(calls.load(Ordering::SeqCst), 0, "nothing built before use");
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| assert_eq!(lazy.patch_count(), 1));
            }
        });
        assert_eq!(calls.load(Ordering::SeqCst), 1, "built once, whoever asked");
        assert_eq!(lazy.evaluate(0, 0.3, 0.7), eager.evaluate(0, 0.3, 0.7));
        assert_eq!(lazy.patch_bounds(0), eager.patch_bounds(0));
        assert!(lazy.lazy_bounds().unwrap().contains(lazy.evaluate(0, 0.5, 0.5).p));
    }

    #[test]
    fn a_released_surface_is_built_again_the_same() {
        let calls = Arc::new(AtomicUsize::new(0));
        let c = calls.clone();
        let (_, p) = quad();
        let lazy = counted_quad(c, &p);
        // SAFETY: no reference into the surface is held.
        assert!(!unsafe { lazy.release() }, "nothing built, nothing to drop");
        let before = {
            let _pin = crate::geometry_budget::pin();
            lazy.evaluate(0, 0.25, 0.5)
        };
        assert!(lazy.is_built());
        // SAFETY: as above.
        assert!(unsafe { lazy.release() });
        assert!(!lazy.is_built());
        assert_eq!(lazy.evaluate(0, 0.25, 0.5), before);
        assert_eq!((calls.load(Ordering::SeqCst), lazy.builds()), (2, 2), "built again on the next use");
    }

    #[test]
    fn a_failed_build_is_reported_and_has_no_patches() {
        let lazy: LazySurface = LazySurface::new(Bounds3::EMPTY, 3, Box::new(|| Err("refused by the builder".into())));
        assert_eq!(lazy.prepare(), Err("refused by the builder".to_string()));
        assert_eq!(lazy.patch_count(), 0);
        assert_eq!(lazy.control_face_count(), 3);
    }
}
