//! Tracing rays through the scene: instances (top level) → a mesh's subpatches (bottom level) →
//! on-demand tessellation at the rate the ray's beam width asks for, looked up in the
//! multiresolution geometry cache (the paper's §5) → watertight quad tests.

use std::sync::atomic::{AtomicBool, AtomicPtr, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use glam::{Mat3A, Mat4, Vec3A};
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray as BvhRay;

use crate::bounds::Bounds3;
use crate::bvh::{build_bvh, walk};
use crate::dropped::DroppedPrims;
use crate::geometry_budget::{Budget, HeldBytes};
use crate::geometry_cache::{CacheConfig, CacheKey, CacheMode, GeometryCache, Tier};
pub use crate::hit::Hit;
use crate::intersect::{BoxRay, WatertightRay};
use crate::patch::{GridSamples, UvRect};
use crate::ray::{gamma, next_up, Ray, RayKind};
use crate::scene::Scene;
use crate::seam::{intersect_with_seams, never_from_inside, SeamEdges};
use crate::subpatch::{ChildCell, MeshGeometry, RootSubpatch};
use crate::tessellate::{needed_quads, split_depth, tessellate_reusing, DisplaceParams, Rate, Tessellation};

/// Replaces −0.0 components by +0.0. obvhs 0.4's CWBVH traversal picks the child order from the
/// direction's sign bits but its slab test from comparisons, and misses every box when a
/// component is −0.0 (a reflection off an axis-aligned plane makes such rays); adding +0.0
/// canonicalises the zero without changing any other value.
#[inline]
pub fn positive_zeros(d: Vec3A) -> Vec3A {
    d + Vec3A::ZERO
}

/// What an any-hit query met ([`Tracer::any_hit_from`]): the mesh and its patch, which say
/// whether the surface there may be cut out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockingPatch {
    /// Index into the scene's meshes.
    pub mesh: u32,
    /// Patch index in the mesh's [`crate::patch::LimitSurface`].
    pub patch: u32,
}

/// Per-thread counters, summed into the render stats at the end (no shared atomics on the hot
/// path).
#[derive(Clone, Debug, Default)]
pub struct TraceCounters {
    /// Rays traced, by [`RayKind`] (index = position in [`RayKind::ALL`]).
    pub rays: [u64; 7],
    /// Ray–subpatch tests: one per subpatch a ray's box test lets through to tessellation.
    pub ray_subpatch_tests: u64,
    /// Subpatch tests per effective rate (1, 2, 4, 8, 16 quads per side).
    pub rate_tests: [u64; 5],
    /// Tests whose beam asked for more than 16×16 quads (served by split subpatches).
    pub finer_than_fine: u64,
    /// Subpatch tests by ray kind (index as `rays`) and effective rate (1, 2, 4, 8, 16, split):
    /// which rays ask for which accuracy — the paper's §4 in numbers.
    pub rate_tests_by_kind: [[u64; 6]; 7],
    /// Ray differentials clamped to finite values (grazing hits, degenerate footprints, total
    /// internal reflection, zero densities): see [`crate::differential`].
    pub differential_clamps: u64,
    /// Opacity cut-outs rays passed through (`opacityThreshold` masks; see
    /// [`crate::integrator::visibility`]).
    pub cutout_passes: u64,
    /// Rays that met more than [`crate::integrator::visibility::MAX_CUTOUTS`] cut-outs and were
    /// stopped there (a visibility ray taken as blocked, a camera or bounce ray as ended).
    pub cutout_limit: u64,
}

impl TraceCounters {
    pub fn add(&mut self, o: &TraceCounters) {
        for (a, b) in self.rays.iter_mut().zip(o.rays) {
            *a += b;
        }
        for (a, b) in self.rate_tests.iter_mut().zip(o.rate_tests) {
            *a += b;
        }
        self.ray_subpatch_tests += o.ray_subpatch_tests;
        self.finer_than_fine += o.finer_than_fine;
        self.differential_clamps += o.differential_clamps;
        self.cutout_passes += o.cutout_passes;
        self.cutout_limit += o.cutout_limit;
        for (a, b) in self.rate_tests_by_kind.iter_mut().zip(o.rate_tests_by_kind) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
    }
}

/// The surface a secondary ray starts on: a hit on the instance it starts from, closer than the
/// two tessellations' chord errors (along the ray) and crossing the surface the way the ray
/// left it, is the surface meeting itself at another rate, not an occluder.
#[derive(Clone, Copy, Debug)]
struct Origin {
    instance: u32,
    /// The root subpatch of `instance` the ray leaves.
    subpatch: u32,
    /// Unit geometric normal of the triangle the ray starts on, turned to the side the ray
    /// leaves on (render space).
    side: Vec3A,
    /// Render units.
    chord_error: f32,
    /// 1 / |cos| between the ray and the surface (capped): a gap across the surface is this
    /// much longer along a slanted ray.
    inv_cos: f32,
    /// The ray leaves along the side the hit triangle's winding normal points to.
    along_ng: bool,
    /// The origin hit's [`Hit::quads`]: the grid the origin lies on.
    quads: u32,
}

impl Origin {
    fn of(hit: &Hit, ray: &Ray) -> Origin {
        let cos = ray.d.dot(hit.ng);
        Origin {
            instance: hit.instance,
            subpatch: hit.subpatch,
            side: if cos > 0.0 { hit.ng } else { -hit.ng },
            chord_error: hit.chord_error,
            inv_cos: 1.0 / cos.abs().max(0.05),
            along_ng: cos > 0.0,
            quads: hit.quads,
        }
    }

    /// The split depth (0: none) and rate of the grid the origin lies on, as
    /// [`Tracer::rate_for`] gives them; `None` on an exactly intersected surface.
    fn depth_rate(&self) -> Option<(u32, Rate)> {
        match self.quads {
            0 => None,
            q if q > 16 => Some(((q / 16).trailing_zeros(), Rate::R16)),
            q => Rate::at_least(q as f32).map(|r| (0, r)),
        }
    }

    /// Whether the one-quad grid `tess` (object space) of the subpatch the ray leaves cannot
    /// stop it: both of its triangles face, by a margin over rounding, the side the ray leaves
    /// to along object-space `d` (`handed` −1 for a left-handed mesh, as [`Hit::ng`]).
    ///
    /// Two triangles sharing an edge that both face `d` project along `d` side by side, without
    /// overlap: the ray's line crosses the quad at most once, and a crossing the way the ray
    /// left is its own surface at another rate, never an occluder. So the quad and its seam
    /// boxes need no test. Ambient occlusion and other wide rays read the coarse one-quad grid
    /// of the subpatch they leave (its box holds their origin), and that test was most of the
    /// grid tests they made. A triangle facing the other way (a fold, a ray grazing the
    /// surface) leaves the quad to the full test and its window rule.
    fn passes_own_quad(&self, tess: &Tessellation, d: Vec3A, handed: f32) -> bool {
        if tess.n != 2 || tess.domain != crate::tessellate::GridDomain::Square {
            return false;
        }
        let p = |k: usize| Vec3A::from(tess.verts[k]);
        let (p00, p10, p01, p11) = (p(0), p(1), p(2), p(3));
        let side = if self.along_ng { handed } else { -handed };
        // The dot product of d with a cross product is within a few ulps of |d| |n|: ask for
        // more than a thousand times that.
        let faces = |n: Vec3A| side * d.dot(n) > 1e-4 * d.length() * n.length();
        faces((p10 - p00).cross(p11 - p00)) && faces((p11 - p00).cross(p01 - p00))
    }

    /// A hit on the origin's own instance at `t` whose winding normal has cosine `cos` with the
    /// ray (both in render space, the normal negated for a left-handed mesh as [`Hit::ng`]) is
    /// the surface at another rate: within `window` of the origin and crossed the same way the
    /// ray left the surface. Another tessellation of the surface the ray stands on lies along
    /// it and is crossed the same way; the same surface met from the side the ray travels in —
    /// the far wall of a closed shell, a bump beside the origin — is crossed the other way, and
    /// blocks at any distance: a ray leaving a closed surface on one side meets it next from
    /// that side. Seam boxes are judged the same way, by their boundary quad's normal: passing
    /// one over whichever way the ray went let rays out through the crack it closes (issue 23).
    /// `either_way` passes a hit over whichever way it is crossed: a camera-facing curve
    /// ribbon has no inside.
    fn is_own_other_rate(&self, t: f32, window: f32, cos: f32, either_way: bool) -> bool {
        t < window && (either_way || if self.along_ng { cos > 0.0 } else { cos < 0.0 })
    }

    /// Whether a ray leaving here crosses, at a surface whose winding normal `n` gives `cos` =
    /// handedness × (d · n), against the side it left on: it heads through that surface.
    /// Rule 8 of docs/cracks.md asks it of a displaced grid's seam box the ray starts in (its
    /// boundary quad's normal): a displaced grid's boxes are the radius on every side, and the
    /// neighbours' displaced edges leave cracks within them (filtered at different spacings),
    /// so a ray leaving near the seam and heading below the surface there would go through
    /// such a crack unless the box stops it (issue 23).
    fn heads_through(&self, cos: f32) -> bool {
        if self.along_ng {
            cos < 0.0
        } else {
            cos > 0.0
        }
    }
}

/// A ray in an instance's object space, with what its leaf tests read of the instance.
#[derive(Clone, Copy)]
struct Local {
    o: Vec3A,
    d: Vec3A,
    /// −1 for a left-handed mesh (its winding normals face inward), else 1.
    sign: f32,
    /// Where the ray leaves this instance's surface, if it does.
    own: Option<Origin>,
    /// The instance's largest stretch (render units per object unit).
    scale: f32,
}

/// The nearest leaf hit of the ray (`o`, `d`: object space) in a bottom-level BVH within
/// (`t_min`, `t_max`), or `best` (a hit at `t_max` already found, if any) when none is nearer:
/// `test(si, t_best)` tests root subpatch `si` for a hit before `t_best`. With `any_hit` the
/// first hit ends the walk. (`best` is passed in, not merged after: moving the hits through a
/// second `Option` cost the plain AO ray 44 instructions.)
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn nearest_leaf(
    blas: &CwBvh,
    o: Vec3A,
    d: Vec3A,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    mut best: Option<(LocalHit, u32)>,
    mut test: impl FnMut(usize, f32) -> Option<LocalHit>,
) -> Option<(LocalHit, u32)> {
    let mut t_best = t_max;
    walk(blas, BvhRay::new(o, d, t_min, t_max), any_hit, |id| {
        let si = blas.primitive_indices[id] as usize;
        let h = test(si, t_best)?;
        t_best = h.t;
        best = Some((h, si as u32));
        Some(h.t)
    });
    best
}

/// A hit within one subpatch: t, (u, v) local to the tested grid's domain `rect`, the object-
/// space triangle normal, and the effective rate.
#[derive(Clone, Copy, Debug)]
struct LocalHit {
    t: f32,
    uv: (f32, f32),
    rect: UvRect,
    ng: Vec3A,
    quads: u32,
    /// Object units.
    chord_error: f32,
}

struct InstanceData {
    /// The scene's instance id.
    id: u32,
    mesh: usize,
    /// The pose; for a moving instance, at shutter open.
    pose: Pose,
    /// Set when the instance moves within the shutter: each ray then uses the pose at its own
    /// time.
    motion: Option<Arc<crate::motion::MotionTransform>>,
    /// Placed in the top-level BVH by its mesh's control hull (a mesh built on first use): rays
    /// test the built geometry's tighter bounds before its bottom-level BVH.
    placed_by_hull: bool,
}

/// An instance's placement at one time.
#[derive(Clone)]
struct Pose {
    render_from_object: Mat4,
    object_from_render: Mat4,
    /// For normals: the inverse transpose of the linear part.
    normal_from_object: Mat3A,
    /// Largest stretch of the linear part: object sizes × this ≥ world sizes.
    scale: f32,
}

impl Pose {
    fn of(render_from_object: Mat4) -> Pose {
        let m3 = Mat3A::from_mat4(render_from_object);
        Pose {
            render_from_object,
            object_from_render: render_from_object.inverse(),
            normal_from_object: m3.inverse().transpose(),
            scale: m3.x_axis.length().max(m3.y_axis.length()).max(m3.z_axis.length()),
        }
    }
}

impl InstanceData {
    /// The pose at shutter time `time` (computed for moving instances, stored for others).
    fn pose(&self, time: f32) -> std::borrow::Cow<'_, Pose> {
        match &self.motion {
            Some(m) => std::borrow::Cow::Owned(Pose::of(m.at(time))),
            None => std::borrow::Cow::Borrowed(&self.pose),
        }
    }
}

/// A mesh's root subpatches and BVH as the tracer holds them: built when the tracer is made, or
/// by the first ray that reaches a mesh built on first use; a geometry budget may drop a lazy
/// mesh's (and its surface's patch data) and the next ray to reach it builds them again.
struct MeshSlot {
    /// `Box::into_raw` of the built geometry, or null (not built yet, or dropped). Dropped
    /// geometry is freed once the threads pinned then unpin ([`crate::geometry_budget`]).
    geom: AtomicPtr<MeshGeometry>,
    /// Serializes the mesh's builds and drops, and holds what its built data is counted as.
    state: parking_lot::Mutex<SlotState>,
    /// Set when a ray enters the mesh, cleared as the drop sweep's hand passes: CLOCK's second
    /// chance, the usual stand-in for LRU, since a last-use time stored by every entry would
    /// write a cache line all render threads share; this writes only when the bit was clear.
    referenced: AtomicBool,
    /// Built on first use, so a budget may drop it.
    lazy: bool,
}

#[derive(Default)]
struct SlotState {
    /// Counted in the budget's figures.
    held: HeldBytes,
    /// Builds of the mesh in this render.
    builds: u32,
    /// Root subpatches at the last build (counted in the stats whether held now or dropped).
    roots: usize,
}

impl MeshSlot {
    fn new(built: Option<MeshGeometry>, lazy: bool) -> Self {
        let geom = built.map_or(std::ptr::null_mut(), |g| Box::into_raw(Box::new(g)));
        MeshSlot { geom: AtomicPtr::new(geom), state: Default::default(), referenced: AtomicBool::new(false), lazy }
    }

    /// The built geometry, if any.
    #[inline]
    fn get(&self) -> Option<&MeshGeometry> {
        let p = self.geom.load(Ordering::Acquire);
        // SAFETY: a non-null pointer is a live box: a drop unlinks it before retiring it, and
        // retired geometry outlives the pins of the threads that could have read it (a
        // budgeted tracer's readers are pinned; an unbudgeted tracer drops nothing).
        (!p.is_null()).then(|| unsafe { &*p })
    }
}

impl Drop for MeshSlot {
    fn drop(&mut self) {
        let p = *self.geom.get_mut();
        if !p.is_null() {
            // SAFETY: owned by the slot alone (see `MeshSlot::get`).
            drop(unsafe { Box::from_raw(p) });
        }
    }
}

/// The scene prepared for tracing: BVHs at both levels and the geometry cache.
pub struct Tracer<'s> {
    scene: &'s Scene,
    /// Per mesh, its subpatches and BVH: set when the tracer is made, or by the first ray that
    /// reaches a mesh whose surface is built on first use.
    meshes: Vec<MeshSlot>,
    instances: Vec<InstanceData>,
    tlas: Option<CwBvh>,
    pub cache: Arc<GeometryCache<Tessellation>>,
    tess_factor: f32,
    /// Multiplier on `tess_factor` per ray kind (index as [`RayKind::ALL`]).
    kind_factor: [f32; 7],
    /// `single` mode: every lookup at 17×17, as the paper's single-resolution cache.
    single: bool,
    /// Seam boxes close cracks between subpatches tested at different rates (see
    /// [`crate::seam`]); on unless [`Tracer::set_seams`] turned them off (to measure cracks).
    seams: bool,
    /// Whether procedurally displaced meshes are read no coarser than their rate floor
    /// ([`Tracer::set_displacement_rate_floor`]).
    displacement_rate_floor: bool,
    pub bounds: Bounds3,
    /// Displaced vertices found outside their subpatch's bounds (warned about once).
    pub displaced_outside: AtomicU64,
    /// Prims left out: geometry that cannot be traced, and meshes whose work panicked.
    pub dropped: DroppedPrims,
    /// Meshes built on first use that this render built.
    lazy_built: AtomicU64,
    /// Tessellations of meshes built on first use that left the bounds the meshes were placed by.
    pub lazy_bounds_escaped: AtomicU64,
    /// The geometry memory budget, when one is set ([`Tracer::with_budget`]).
    budget: Option<Budget>,
}

impl<'s> Tracer<'s> {
    /// Builds subpatches and BVHs for `scene`. Meshes are prepared once and shared by their
    /// instances.
    pub fn new(scene: &'s Scene, cache: CacheConfig, tess_factor: f32) -> Self {
        let single = cache.mode == CacheMode::Single;
        Self::with_cache(scene, Arc::new(GeometryCache::new(cache)), single, tess_factor)
    }

    /// As [`Tracer::new`], with a cache that outlives this render (a render delegate's): meshes
    /// are keyed by their [`crate::scene::Mesh::cache_id`], so entries of unchanged meshes are
    /// hit again by the next render.
    pub fn with_cache(scene: &'s Scene, cache: Arc<GeometryCache<Tessellation>>, single: bool, tess_factor: f32) -> Self {
        match Self::with_budget(scene, cache, single, tess_factor, None) {
            Ok(t) => t,
            Err(_) => unreachable!("only a budget can be refused"),
        }
    }

    /// As [`Tracer::with_cache`], keeping the render's geometry memory — the cache's budget, the
    /// meshes' patch data, root subpatches and BVHs — within `budget` bytes when one is given
    /// ([`crate::geometry_budget`]): every mesh built on first use is then placed by its bounds
    /// and may be dropped and built again, whether or not its surface was built already.
    ///
    /// # Errors
    /// A budget below what cannot be dropped (the cache's budget, the top-level BVH and
    /// instances, meshes built up front, an unbounded cache): one line with the minimum.
    pub fn with_budget(
        scene: &'s Scene,
        cache: Arc<GeometryCache<Tessellation>>,
        single: bool,
        tess_factor: f32,
        budget: Option<usize>,
    ) -> Result<Self, String> {
        use rayon::prelude::*;
        let dropped = DroppedPrims::new(scene.meshes.len());
        // A surface built on first use is placed by its own bounds; its subpatches and BVH wait
        // for the first ray that reaches it (`Tracer::geometry`).
        let meshes: Vec<MeshSlot> = scene
            .meshes
            .par_iter()
            .enumerate()
            .map(|(i, m)| {
                let lazy = m.surface.lazy_bounds().is_some();
                if lazy && (budget.is_some() || !m.surface.is_built()) {
                    return MeshSlot::new(None, true);
                }
                MeshSlot::new(Some(Self::build_geometry(&cache, &dropped, m, i)), false)
            })
            .collect();
        let mut boxes = Vec::new();
        let mut instances = Vec::new();
        for inst in &scene.instances {
            let Some(slot) = meshes.get(inst.mesh) else { continue };
            let (mesh_bounds, placed_by_hull) = match slot.get() {
                Some(g) if g.bvh.is_none() => continue,
                Some(g) => (g.bounds, false),
                None => (Self::declared_bounds(&scene.meshes[inst.mesh]), true),
            };
            if mesh_bounds.is_empty() {
                continue;
            }
            let name = &scene.meshes[inst.mesh].name;
            // Rays enter the instance through the inverse transform: refuse what has none.
            let render_from_object = match crate::transform::traceable(inst.render_from_object) {
                Ok(m) => m,
                Err(e) => {
                    dropped.refuse(name, e);
                    continue;
                }
            };
            let keys_ok = inst
                .motion
                .as_ref()
                .is_none_or(|m| m.keys().iter().all(|k| crate::transform::traceable(k.render_from_object) == Ok(k.render_from_object)));
            if !keys_ok {
                dropped.refuse(name, "a motion key's transform is degenerate (zero or absurd scale, or projective)");
                continue;
            }
            let bounds = match &inst.motion {
                Some(m) => m.swept_bounds(&mesh_bounds),
                None => mesh_bounds.transformed(&render_from_object),
            };
            if !bounds.is_traceable() {
                dropped
                    .refuse(name, format!("placed at {:e}, beyond the traceable ±{:e}", bounds.max_abs(), crate::bounds::MAX_COORDINATE));
                continue;
            }
            boxes.push(bounds);
            instances.push(InstanceData {
                id: inst.id,
                mesh: inst.mesh,
                pose: Pose::of(render_from_object),
                motion: inst.motion.clone(),
                placed_by_hull,
            });
        }
        let bounds = boxes.iter().fold(Bounds3::EMPTY, |a, b| a.union(b));
        let tlas = build_bvh(&boxes);
        let budget = match budget {
            Some(total) => Some(Self::make_budget(scene, &cache, &meshes, tlas.as_ref(), instances.len(), total)?),
            None => None,
        };
        let tracer = Tracer {
            scene,
            meshes,
            instances,
            tlas,
            cache,
            tess_factor,
            kind_factor: [1.0; 7],
            single,
            seams: true,
            displacement_rate_floor: false,
            bounds,
            displaced_outside: AtomicU64::new(0),
            dropped,
            lazy_built: AtomicU64::new(0),
            lazy_bounds_escaped: AtomicU64::new(0),
            budget,
        };
        if tracer.budget.is_some() {
            // Surfaces built by an earlier render count from the start, and may have to go.
            for (slot, m) in tracer.meshes.iter().zip(&scene.meshes) {
                if slot.lazy {
                    let held = HeldBytes { surface: m.surface.memory_bytes(), ..Default::default() };
                    let mut st = slot.state.lock();
                    tracer.account(&mut st, held);
                }
            }
            tracer.keep_budget(usize::MAX);
        }
        Ok(tracer)
    }

    /// The budget's fixed part: what this render holds that no drop gives back.
    fn make_budget(
        scene: &Scene,
        cache: &GeometryCache<Tessellation>,
        meshes: &[MeshSlot],
        tlas: Option<&CwBvh>,
        instances: usize,
        total: usize,
    ) -> Result<Budget, String> {
        let config = cache.config();
        let cache_bytes = match config.mode {
            CacheMode::Multires => config.budget_bytes.iter().sum(),
            CacheMode::Single => config.budget_bytes[Tier::Fine.index()],
            CacheMode::None => 0,
            CacheMode::Unbounded => {
                return Err("geometryMemoryMb needs a bounded geometry cache (cacheMode multires, single or none), not unbounded".into())
            }
        };
        let top = tlas.map_or(0, crate::bvh::bvh_bytes) + instances * std::mem::size_of::<InstanceData>();
        let eager: usize = meshes
            .iter()
            .zip(&scene.meshes)
            .filter(|(s, _)| !s.lazy)
            .map(|(s, m)| {
                let g = s.get().map_or(0, |g| {
                    g.subpatches.capacity() * std::mem::size_of::<RootSubpatch>() + g.bvh.as_ref().map_or(0, crate::bvh::bvh_bytes)
                });
                g + m.surface.memory_bytes()
            })
            .sum();
        Budget::new(total, vec![("geometry_cache", cache_bytes), ("top_level_bvh_and_instances", top), ("meshes_built_up_front", eager)])
    }

    /// Counts mesh data going from what `st` holds to `new`.
    fn account(&self, st: &mut SlotState, new: HeldBytes) {
        if let Some(b) = &self.budget {
            b.account(st.held, new);
        }
        st.held = new;
    }

    /// Drops the built data of meshes no ray has entered since the sweep last passed them
    /// (CLOCK), until the droppable data fits the budget again; mesh `keep` (the one just
    /// built, in use) and meshes being built stay. When even that cannot fit the budget the
    /// render goes on over it (counted: the meshes in use need the memory).
    fn keep_budget(&self, keep: usize) {
        let Some(b) = &self.budget else { return };
        if b.held().total() <= b.limit() {
            return;
        }
        let mut hand = b.hand.lock();
        let n = self.meshes.len();
        let mut looked = 0;
        while b.held().total() > b.limit() && looked < 2 * n {
            let i = *hand;
            *hand = (i + 1) % n;
            looked += 1;
            let slot = &self.meshes[i];
            if !slot.lazy || i == keep {
                continue;
            }
            if slot.referenced.load(Ordering::Relaxed) {
                slot.referenced.store(false, Ordering::Relaxed);
                continue;
            }
            let Some(mut st) = slot.state.try_lock() else { continue };
            if st.held.total() == 0 {
                continue;
            }
            let p = slot.geom.swap(std::ptr::null_mut(), Ordering::AcqRel);
            if !p.is_null() {
                // SAFETY: unlinked above; readers that loaded it are pinned (see `geometry`).
                crate::geometry_budget::retire(unsafe { Box::from_raw(p) });
            }
            // SAFETY: a budgeted tracer's readers are pinned (`render` pins per pixel and per
            // pre-pass chunk; `geometry` checks it in debug builds).
            unsafe { self.scene.meshes[i].surface.release() };
            self.account(&mut st, HeldBytes::default());
            b.drops.fetch_add(1, Ordering::Relaxed);
        }
        if b.held().total() > b.limit() {
            b.over.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The geometry budget, when the tracer keeps one: its figures for the stats.
    pub fn budget(&self) -> Option<&Budget> {
        self.budget.as_ref()
    }

    /// Root subpatches and BVH of mesh `i`; a mesh that cannot be traced is refused (recorded
    /// in `dropped`) and gets an empty geometry, and a panic in its work fails it.
    fn build_geometry(cache: &GeometryCache<Tessellation>, dropped: &DroppedPrims, m: &crate::scene::Mesh, i: usize) -> MeshGeometry {
        let split_ids = |roots| cache.split_ids(Self::cache_mesh(m, i), m.generation, roots);
        let built = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            m.surface.prepare()?;
            MeshGeometry::build(m, split_ids)
        }));
        match built {
            Ok(Ok(g)) => g,
            Ok(Err(reason)) => {
                dropped.refuse(&m.name, reason);
                MeshGeometry::empty()
            }
            Err(payload) => {
                dropped.fail(i, &m.name, payload.as_ref());
                MeshGeometry::empty()
            }
        }
    }

    /// Object-space bounds of a mesh built on first use, before it is built: its surface's own,
    /// grown by the displacement bound as its subpatches' are, and by room for the rounding of
    /// evaluated points where the surface touches them (a planar mesh's box has no depth).
    fn declared_bounds(m: &crate::scene::Mesh) -> Bounds3 {
        match m.surface.lazy_bounds() {
            Some(b) if !b.is_empty() => b.expanded(m.displacement_bound.max(0.0) + 1e-5 * b.max_abs()),
            _ => Bounds3::EMPTY,
        }
    }

    /// Mesh `mesh`'s root subpatches and BVH, built by the first ray that reaches a mesh built
    /// on first use (the others wait for it), or again after a budget dropped them. With a
    /// budget, the reference lives as long as the calling thread's pin.
    #[inline]
    fn geometry(&self, mesh: usize) -> &MeshGeometry {
        debug_assert!(self.budget.is_none() || crate::geometry_budget::is_pinned(), "a budgeted tracer read by an unpinned thread");
        match self.meshes[mesh].get() {
            Some(g) => g,
            None => self.build_lazy(mesh),
        }
    }

    /// Builds a mesh reached for the first time (or again, after a budget dropped it), then
    /// keeps the budget. The BVH builder runs rayon work, and a render thread waiting in a rayon
    /// join steals other render jobs, which may trace into this very mesh and re-enter its build
    /// lock (see [`GeometryCache::get_or_build`]): so the build runs on a thread of its own,
    /// whose rayon work goes to a pool that runs nothing else, while the render thread blocks
    /// without stealing.
    #[cold]
    #[inline(never)]
    fn build_lazy(&self, mesh: usize) -> &MeshGeometry {
        let slot = &self.meshes[mesh];
        let mut st = slot.state.lock();
        if let Some(g) = slot.get() {
            return g;
        }
        let g = self.build_geometry_apart(mesh);
        let held = HeldBytes {
            surface: self.scene.meshes[mesh].surface.memory_bytes(),
            roots: g.subpatches.capacity() * std::mem::size_of::<RootSubpatch>(),
            bvh: g.bvh.as_ref().map_or(0, crate::bvh::bvh_bytes),
        };
        let p = Box::into_raw(Box::new(g));
        slot.geom.store(p, Ordering::Release);
        slot.referenced.store(true, Ordering::Relaxed);
        st.builds += 1;
        st.roots = self.meshes[mesh].get().map_or(0, |g| g.subpatches.len());
        if st.builds == 1 {
            self.lazy_built.fetch_add(1, Ordering::Relaxed);
        } else if let Some(b) = &self.budget {
            b.rebuilds.fetch_add(1, Ordering::Relaxed);
        }
        self.account(&mut st, held);
        drop(st);
        self.keep_budget(mesh);
        // SAFETY: just made; a drop by another thread retires it past this thread's pin.
        unsafe { &*p }
    }

    /// Builds a mesh's geometry on a thread of its own (see [`Tracer::build_lazy`]).
    fn build_geometry_apart(&self, mesh: usize) -> MeshGeometry {
        static BUILD_POOL: OnceLock<Option<rayon::ThreadPool>> = OnceLock::new();
        let pool = BUILD_POOL.get_or_init(|| {
            let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
            rayon::ThreadPoolBuilder::new().num_threads(threads).thread_name(|i| format!("mipray-build-{i}")).build().ok()
        });
        let build = || {
            // The build reads the surface, which a budget may drop meanwhile.
            let _pin = crate::geometry_budget::pin();
            Self::build_geometry(&self.cache, &self.dropped, &self.scene.meshes[mesh], mesh)
        };
        std::thread::scope(|s| {
            // Without a pool of its own (threads could not be started), in rayon's global pool,
            // which renders do not run in.
            let built = s.spawn(|| pool.as_ref().map_or_else(build, |p| p.install(build)));
            built.join().unwrap_or_else(|payload| std::panic::resume_unwind(payload))
        })
    }

    /// Meshes whose subpatches no ray has asked for in this render (built on first use, and not
    /// reached), so never built.
    pub fn meshes_not_reached(&self) -> usize {
        self.meshes.iter().filter(|m| m.lazy && m.state.lock().builds == 0).count()
    }

    /// Meshes built on first use that rays have reached (and so built) in this render.
    pub fn lazy_meshes_built(&self) -> u64 {
        self.lazy_built.load(Ordering::Relaxed)
    }

    /// Coarsens (factor > 1) or refines the tessellation for incoherent rays (ambient
    /// occlusion, diffuse, glossy) relative to the others.
    pub fn set_incoherent_tess_factor(&mut self, factor: f32) {
        for (k, f) in RayKind::ALL.iter().zip(self.kind_factor.iter_mut()) {
            if matches!(k, RayKind::Ao | RayKind::Diffuse | RayKind::Glossy) {
                *f = factor;
            }
        }
    }

    /// Turns the seam boxes that close cracks between rates on (the default) or off.
    pub fn set_seams(&mut self, on: bool) {
        self.seams = on;
    }

    /// Reads displaced meshes (procedural or texture) no coarser than their rate floor
    /// ([`MeshGeometry::rate_floor`]; the `displacementRateFloor` setting), or (the default)
    /// at the rates the beams ask for alone.
    pub fn set_displacement_rate_floor(&mut self, on: bool) {
        self.displacement_rate_floor = on;
    }

    /// The rate floor the subpatches of `mesh` (whose geometry is `geom`) are read with (0:
    /// none): the procedural one or, for a texture, the one from its texels.
    #[inline]
    fn rate_floor(&self, geom: &MeshGeometry, mesh: &crate::scene::Mesh) -> f32 {
        if self.displacement_rate_floor {
            geom.rate_floor.max(geom.texture_rate_floor(mesh))
        } else {
            0.0
        }
    }

    /// The root-boundary edges of a (split) subpatch that get seam boxes.
    fn seam_edges(&self, cell: ChildCell) -> SeamEdges {
        if self.seams {
            SeamEdges::of_child(cell.depth, cell.i, cell.j)
        } else {
            SeamEdges::NONE
        }
    }

    /// Root subpatches over all meshes (each counted once, however many instances).
    pub fn subpatch_count(&self) -> usize {
        // A mesh a budget dropped counts the roots it had.
        self.meshes.iter().map(|s| s.get().map_or_else(|| s.state.lock().roots, |g| g.subpatches.len())).sum()
    }

    /// Root subpatches of surfaces intersected exactly ([`crate::implicit`]), which are never
    /// tessellated (included in [`Tracer::subpatch_count`]).
    pub fn exact_patch_count(&self) -> usize {
        self.meshes
            .iter()
            .zip(&self.scene.meshes)
            .filter(|(_, m)| m.surface.exact().is_some())
            .filter_map(|(g, _)| g.get())
            .map(|g| g.subpatches.len())
            .sum()
    }

    /// Root subpatches that are curve segments ([`crate::curves`]), tessellated along their
    /// length only (included in [`Tracer::subpatch_count`]).
    pub fn curve_segment_count(&self) -> usize {
        self.meshes
            .iter()
            .zip(&self.scene.meshes)
            .filter(|(_, m)| m.surface.curves().is_some())
            .filter_map(|(g, _)| g.get())
            .map(|g| g.subpatches.len())
            .sum()
    }

    /// The scene being traced.
    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// Bytes of the root subpatches (their bounds are the bottom-level BVHs' primitives).
    pub fn subpatch_bytes(&self) -> usize {
        self.mesh_geometry().map(|m| m.subpatches.len() * std::mem::size_of::<RootSubpatch>()).sum()
    }

    /// Bytes of every BVH (both levels), for the stats.
    pub fn bvh_bytes(&self) -> usize {
        self.mesh_geometry().filter_map(|m| m.bvh.as_ref()).map(crate::bvh::bvh_bytes).sum::<usize>()
            + self.tlas.as_ref().map_or(0, crate::bvh::bvh_bytes)
    }

    /// The meshes' root subpatches and BVHs built so far (a mesh built on first use that no
    /// ray has reached has none), for statistics.
    pub fn mesh_geometry(&self) -> impl Iterator<Item = &MeshGeometry> {
        self.meshes.iter().filter_map(MeshSlot::get)
    }

    /// The closest hit along `ray` in (t_min, t_max), or `None`.
    pub fn intersect(&self, ray: &Ray, counters: &mut TraceCounters) -> Option<Hit> {
        self.trace(ray, counters, false, None)
    }

    /// True when anything blocks `ray` in (t_min, t_max) (shadow rays).
    pub fn occluded(&self, ray: &Ray, counters: &mut TraceCounters) -> bool {
        self.trace(ray, counters, true, None).is_some()
    }

    /// As [`Tracer::intersect`], for a ray leaving the surface at `from`: where it meets the
    /// surface it starts on (the same instance) again, closer than the two tessellations' chord errors (over the
    /// ray's cosine to the surface), that is the surface at another rate, not an occluder. Rays
    /// of different widths test one subpatch at different rates; without this a coarse grid
    /// of a concave surface shadows the fine grid a camera ray hit.
    pub fn intersect_from(&self, ray: &Ray, from: &Hit, counters: &mut TraceCounters) -> Option<Hit> {
        self.trace(ray, counters, false, Some(Origin::of(from, ray)))
    }

    /// As [`Tracer::occluded`] for a ray leaving the surface at `from` (see
    /// [`Tracer::intersect_from`]).
    pub fn occluded_from(&self, ray: &Ray, from: &Hit, counters: &mut TraceCounters) -> bool {
        self.trace(ray, counters, true, Some(Origin::of(from, ray))).is_some()
    }

    /// As [`Tracer::occluded_from`], returning what blocks: any hit in range, not necessarily
    /// the closest (what a visibility query through cut-outs checks first).
    pub fn any_hit_from(&self, ray: &Ray, from: &Hit, counters: &mut TraceCounters) -> Option<BlockingPatch> {
        self.trace(ray, counters, true, Some(Origin::of(from, ray))).map(|h| BlockingPatch { mesh: h.mesh, patch: h.patch })
    }

    fn kind_index(kind: RayKind) -> usize {
        kind.index()
    }

    fn trace(&self, ray: &Ray, counters: &mut TraceCounters, any_hit: bool, origin: Option<Origin>) -> Option<Hit> {
        counters.rays[Self::kind_index(ray.kind)] += 1;
        let tlas = self.tlas.as_ref()?;
        if !(ray.o.is_finite() && ray.d.is_finite()) {
            return None;
        }
        let bray = BvhRay::new(ray.o, positive_zeros(ray.d), ray.t_min, ray.t_max);
        let mut best: Option<Hit> = None;
        let mut t_best = ray.t_max;
        walk(tlas, bray, any_hit, |id| {
            let ii = tlas.primitive_indices[id] as usize;
            let h = self.test_instance(ii, ray, t_best, counters, any_hit, origin)?;
            t_best = h.t;
            best = Some(h);
            Some(h.t)
        });
        best
    }

    /// [`Tracer::trace_instance`], isolated: a panic in the instance's work (its tessellation,
    /// its ray tests) drops its mesh from the render (see [`crate::dropped`]) instead of taking
    /// the render down; a dropped mesh is skipped.
    fn test_instance(
        &self,
        ii: usize,
        ray: &Ray,
        t_max: f32,
        counters: &mut TraceCounters,
        any_hit: bool,
        origin: Option<Origin>,
    ) -> Option<Hit> {
        let mesh = self.instances[ii].mesh;
        if self.dropped.has_failed(mesh) {
            return None;
        }
        let test = std::panic::AssertUnwindSafe(|| self.trace_instance(ii, ray, t_max, counters, any_hit, origin));
        std::panic::catch_unwind(test).unwrap_or_else(|payload| {
            self.dropped.fail(mesh, &self.scene.meshes[mesh].name, payload.as_ref());
            None
        })
    }

    fn trace_instance(
        &self,
        ii: usize,
        ray: &Ray,
        t_max: f32,
        counters: &mut TraceCounters,
        any_hit: bool,
        origin: Option<Origin>,
    ) -> Option<Hit> {
        let instance = &self.instances[ii];
        let geom = self.geometry(instance.mesh);
        let blas = geom.bvh.as_ref()?;
        let mesh = &self.scene.meshes[instance.mesh];
        let inst = instance.pose(ray.time);
        let displacement_pad = 2.0 * mesh.displacement_bound.max(0.0);
        let rate_floor = self.rate_floor(geom, mesh);
        let own = origin.filter(|org| org.instance == ii as u32);
        let sign = if mesh.left_handed { -1.0 } else { 1.0 };
        let o = inst.object_from_render.transform_point3a(ray.o);
        let d = positive_zeros(inst.object_from_render.transform_vector3a(ray.d));
        if !(o.is_finite() && d.is_finite()) {
            // A render-space ray far beyond the scene can overflow in a small object's space.
            return None;
        }
        // Made in the branches that read it: made before them, every subdivision instance
        // entry stored it for nothing (~18 instructions an entry, callgrind).
        if let Some(exact) = mesh.surface.exact() {
            let ray_in = Local { o, d, sign, own, scale: inst.scale };
            let (h, si) = self.nearest_exact(geom, blas, exact, &ray_in, ray, t_max, counters, any_hit)?;
            return Some(self.hit_or_blocker(any_hit, ii, ray, &inst, h, si));
        }
        if let Some(curves) = mesh.surface.curves() {
            let ray_in = Local { o, d, sign, own, scale: inst.scale };
            let (h, si) = self.nearest_curve(instance.mesh, geom, blas, curves, &ray_in, ray, t_max, counters, any_hit)?;
            return Some(self.hit_or_blocker(any_hit, ii, ray, &inst, h, si));
        }
        let mut box_ray = BoxRay::new(o, d);
        // A ray leaving this instance that enters the box of the subpatch it starts on tests
        // that subpatch first, at the rate chosen where it enters: that one look-up gives both
        // the lift (see `Tracer::lift`) and the grid the test reads, so the lift costs no
        // look-up of its own and every look-up is still one test. The traversal below then
        // passes that subpatch by. A ray that misses the box (most rays leaving a flat or
        // convex patch: the spawn offset puts them outside it) meets no tessellation of that
        // subpatch, and is not lifted. Displaced meshes are not lifted: their grids' chord
        // errors hold the whole displacement bound, and a lift that large would hide the
        // mesh's own bumps beside the origin from the ray (lost contact occlusion).
        let first = own.filter(|_| mesh.displacement_bound <= 0.0).and_then(|org| {
            let sp = geom.subpatches.get(org.subpatch as usize)?;
            let sp_bounds = sp.bounds();
            let (t_enter, _) = box_ray.hit_box(&sp_bounds, ray.t_min, t_max)?;
            let (depth, rate) = self.rate_for(sp, &sp_bounds, displacement_pad, rate_floor, inst.scale, ray, t_enter);
            let tier = if depth > 0 { Tier::Fine } else { rate.tier_and_stride().0 };
            let tess = self.lookup(instance.mesh, geom, ChildCell { root: org.subpatch, depth: 0, i: 0, j: 0 }, tier, ray.time);
            Some((org, depth, rate, tess))
        });
        // Moved off the surface by the lift, the ray starts beyond every tessellation of its
        // own subpatch that it tests; the hit point is then on the grid it meets.
        let lifted;
        let ray = match &first {
            Some((org, depth, rate, tess)) => {
                lifted = Ray { o: ray.o + org.side * Self::lift(org, tess, *depth, *rate, inst.scale), ..*ray };
                box_ray = BoxRay::new(inst.object_from_render.transform_point3a(lifted.o), d);
                &lifted
            }
            None => ray,
        };
        let o = box_ray.o;
        // The hull that placed a lazy mesh is looser than its subpatches' bounds: a ray that
        // misses those cannot enter any subpatch box (the slab test is monotone in the box), so
        // it skips the BLAS (measured: 13 % more instance entries without this). A ray that
        // tests its own subpatch first is in the mesh's bounds.
        if instance.placed_by_hull {
            if first.is_none() {
                box_ray.hit_box(&geom.bounds, ray.t_min, t_max)?;
            }
            // Recently used, for the budget's drop sweep: written only when the sweep cleared it.
            let used = &self.meshes[instance.mesh].referenced;
            if !used.load(Ordering::Relaxed) {
                used.store(true, Ordering::Relaxed);
            }
        }
        let kind = Self::kind_index(ray.kind);
        // Root subpatch `si` tested at split depth `depth` (0: none) or else `rate`, from its
        // looked-up `tess` (the fine tier when split), for a hit before `t_best`.
        // Made at the instance's first grid test: most instance entries test none.
        let mut watertight: Option<WatertightRay> = None;
        // A trimmed NURBS patch's trim ([`crate::trim`]): applied where a subpatch test returns
        // a hit (`kept_or_search_on`); every other surface has none.
        let trim = geom.trim.as_deref();
        // From `t_from` (the ray's t_min; beyond a hit a trim cut away).
        #[allow(clippy::too_many_arguments)]
        let test = |counters: &mut TraceCounters,
                    wray: &WatertightRay,
                    si: usize,
                    depth: u32,
                    rate: Rate,
                    tess: &Tessellation,
                    t_best: f32,
                    t_from: f32| {
            counters.ray_subpatch_tests += 1;
            // Near the ray's origin, skip the surface's own other tessellations: closer than the
            // two tessellations' chord errors (along the ray), a hit on the instance the ray
            // starts from that crosses it the way the ray left is the surface meeting itself at
            // another rate. A coarser grid there stands up to its chord error above the fine
            // grid the ray starts on (a facet touching the limit surface at its corners, where
            // the fine chords sag below it), and would shadow it. Only subpatches near the
            // origin can be hit that close, so this is the rule "the origin's own subpatch and
            // the neighbours whose boxes hold it" without a box test (and without depending on
            // how tight the boxes are). A hit crossing the other way is the surface itself in
            // the ray's path and blocks however near (see `Origin::is_own_other_rate`): without
            // that, grazing rays left closed shells through the window (issue 23).
            let root = ChildCell { root: si as u32, depth: 0, i: 0, j: 0 };
            if depth > 0 {
                // The nearest hit at or after `search`'s t_min that is not the surface at another
                // rate: hits within the window that cross the surface the way the ray left it are
                // passed over one by one (the next search starts at the hit's t).
                let nearest_not_own = |chord_error: f32, search: &mut dyn FnMut(f32) -> Option<LocalHit>| {
                    let Some(o) = own else { return search(t_from) };
                    let window = (o.chord_error + chord_error * inst.scale) * o.inv_cos;
                    let mut t_from = t_from;
                    loop {
                        let h = search(t_from)?;
                        if !o.is_own_other_rate(h.t, window, sign * d.dot(h.ng), false) {
                            return Some(h);
                        }
                        t_from = next_up(h.t);
                    }
                };
                counters.finer_than_fine += 1;
                counters.rate_tests_by_kind[kind][5] += 1;
                nearest_not_own(tess.chord_error, &mut |t_from| {
                    let (mut t_max, mut found) = (t_best, None);
                    self.hit_split(instance.mesh, geom, root, tess, depth, ray.time, wray, t_from, &mut t_max, &mut found);
                    found
                })
            } else {
                counters.rate_tests[rate as usize] += 1;
                counters.rate_tests_by_kind[kind][rate as usize] += 1;
                if rate == Rate::R1 && own.is_some_and(|o| o.subpatch == si as u32 && o.passes_own_quad(tess, d, sign)) {
                    return None;
                }
                // The grid's chord error was probed at its own spacing; read at a merged stride
                // its quads are `stride` times wider, and a chord's sag grows with its square.
                let stride = rate.tier_and_stride().1;
                let chord_error = tess.chord_error * (stride * stride) as f32;
                let edges = self.seam_edges(root);
                // The rule of `nearest_not_own` applied to each hit inside the one search:
                // searching again from each hit passed over cost a displaced AO ray several
                // grid searches.
                let window = own.map(|o| (o.chord_error + chord_error * inst.scale) * o.inv_cos);
                let accept = |t: f32, ng: Vec3A| match (own, window) {
                    (Some(o), Some(window)) => !o.is_own_other_rate(t, window, sign * d.dot(ng), false),
                    _ => true,
                };
                // A ray leaving a displaced mesh is stopped by the seam boxes around its own
                // origin where it heads through the surface (rule 8 of docs/cracks.md). Asked
                // only of a box the ray starts in.
                let rule_8 = own.filter(|_| displacement_pad > 0.0);
                let stops_inside = |ng: Vec3A| rule_8.is_some_and(|o| o.heads_through(sign * d.dot(ng)));
                intersect_with_seams(wray, tess, stride, edges, t_from, t_best, &accept, &stops_inside).map(|h| LocalHit {
                    t: h.t,
                    uv: (h.u, h.v),
                    rect: UvRect::UNIT,
                    ng: h.ng,
                    quads: rate.quads() as u32,
                    chord_error,
                })
            }
        };
        let mut best: Option<(LocalHit, u32)> = None;
        let mut t_best = t_max;
        let first_si = first.as_ref().map(|(org, ..)| org.subpatch as usize);
        // A ray leaving a displaced mesh tests every subpatch of that instance at the rate of
        // the grid its origin lies on (rule 6 of docs/cracks.md): the same triangles and the
        // same displacement filtering as the surface it stands on, so it starts on its side of
        // one closed surface and leaves only by crossing it. Read at the beam's rates a
        // neighbour is another surface (a coarse grid filters away bumps a fine one keeps, up
        // to the whole displacement bound off it) that the ray could pass beside without
        // crossing; reading only the subpatches whose boxes hold the origin this way left a
        // third of the leaks (issue 23).
        let origin_grid = own.filter(|_| displacement_pad > 0.0).and_then(|org| org.depth_rate());
        if let Some((org, depth, rate, tess)) = first {
            let wray = &*watertight.get_or_insert_with(|| WatertightRay::new(o, d));
            let si = org.subpatch as usize;
            let found = test(counters, wray, si, depth, rate, &tess, t_best, ray.t_min);
            if let Some(h) =
                Self::kept_or_search_on(trim, geom, si, found, &mut |t| test(counters, wray, si, depth, rate, &tess, t_best, t))
            {
                t_best = h.t;
                best = Some((h, org.subpatch));
            }
        }
        if !(any_hit && best.is_some()) {
            best = nearest_leaf(blas, o, d, ray.t_min, t_best, any_hit, best, |si, t_best| {
                if first_si == Some(si) {
                    return None;
                }
                let sp = &geom.subpatches[si];
                let sp_bounds = sp.bounds();
                let (t_enter, _) = box_ray.hit_box(&sp_bounds, ray.t_min, t_best)?;
                let (depth, rate) = match origin_grid {
                    Some(dr) => dr,
                    _ => self.rate_for(sp, &sp_bounds, displacement_pad, rate_floor, inst.scale, ray, t_enter),
                };
                let tier = if depth > 0 { Tier::Fine } else { rate.tier_and_stride().0 };
                let tess = self.lookup(instance.mesh, geom, ChildCell { root: si as u32, depth: 0, i: 0, j: 0 }, tier, ray.time);
                let wray = &*watertight.get_or_insert_with(|| WatertightRay::new(o, d));
                let found = test(counters, wray, si, depth, rate, &tess, t_best, ray.t_min);
                Self::kept_or_search_on(trim, geom, si, found, &mut |t| test(counters, wray, si, depth, rate, &tess, t_best, t))
            });
        }
        let (h, si) = best?;
        Some(self.hit_or_blocker(any_hit, ii, ray, &inst, h, si))
    }

    /// `found`, a subpatch test's hit on root subpatch `si` of `geom`, if `trim` (the mesh's)
    /// keeps it; else the first hit beyond it that the trim keeps (`search(t_from)` tests the
    /// subpatch again from `t_from`). Untrimmed surfaces pay the one test of `trim`.
    #[inline(always)]
    fn kept_or_search_on(
        trim: Option<&crate::trim::PatchTrim>,
        geom: &MeshGeometry,
        si: usize,
        found: Option<LocalHit>,
        search: &mut dyn FnMut(f32) -> Option<LocalHit>,
    ) -> Option<LocalHit> {
        match (trim, found) {
            (Some(trim), Some(h)) if !Self::kept(trim, geom.subpatches[si].patch, &h) => {
                Self::first_kept(trim, geom.subpatches[si].patch, next_up(h.t), search)
            }
            (_, found) => found,
        }
    }

    /// The first hit `search(t_from)` finds from `t_min` on whose patch (u, v) `trim` keeps
    /// (patch `patch`): a hit the trim cuts away is passed over and the search goes on just
    /// beyond it, so the ray meets what lies behind the hole.
    #[cold]
    #[inline(never)]
    fn first_kept(
        trim: &crate::trim::PatchTrim,
        patch: u32,
        t_min: f32,
        search: &mut dyn FnMut(f32) -> Option<LocalHit>,
    ) -> Option<LocalHit> {
        let mut t_from = t_min;
        loop {
            let h = search(t_from)?;
            if Self::kept(trim, patch, &h) {
                return Some(h);
            }
            t_from = next_up(h.t);
        }
    }

    /// Whether `trim` keeps hit `h` on patch `patch`.
    #[inline(never)]
    fn kept(trim: &crate::trim::PatchTrim, patch: u32, h: &LocalHit) -> bool {
        let u = h.rect.u0 + (h.rect.u1 - h.rect.u0) * h.uv.0;
        let v = h.rect.v0 + (h.rect.v1 - h.rect.v0) * h.uv.1;
        trim.keeps(patch, u, v)
    }

    /// The split depth (0: none) and, unsplit, the rate at which `ray` tests root subpatch `sp`
    /// (bounds `sp_bounds`, object space; its instance's largest stretch `scale`) when it
    /// reaches its box at `t_enter`, never coarser than `rate_floor` quads a side.
    #[allow(clippy::too_many_arguments)]
    fn rate_for(
        &self,
        sp: &RootSubpatch,
        sp_bounds: &Bounds3,
        displacement_pad: f32,
        rate_floor: f32,
        scale: f32,
        ray: &Ray,
        t_enter: f32,
    ) -> (u32, Rate) {
        // The rate is sized by the patch itself: its box less the displacement bound it was
        // grown by (displacement finer than the grid is filtered to its spacing, so the bound is
        // no reason to tessellate finer).
        let hull = sp.hull_size(sp_bounds, displacement_pad);
        let needed = needed_quads(hull * scale, ray.beam_width(t_enter), self.tess_factor * self.kind_factor[Self::kind_index(ray.kind)]);
        // But never coarser than the mesh's floor (a displaced mesh: the rate at which its
        // patches keep every detail of the displacement, `MeshGeometry::rate_floor`).
        let needed = needed.max(rate_floor);
        let depth = if sp.affine { 0 } else { split_depth(needed) };
        let rate = if self.single {
            Rate::R16
        } else if sp.affine {
            Rate::R1
        } else {
            Rate::at_least(needed).unwrap_or(Rate::R16)
        };
        (depth, rate)
    }

    /// How far (render units) to move a ray leaving the surface at `org` off it, to the side
    /// it leaves on, before testing the instance it leaves (largest stretch `scale`), when it
    /// tests the subpatch it starts on at split depth `depth` (0: none) or else `rate`, from
    /// `tess` (object space; the fine tier when split).
    ///
    /// The ray may test the subpatch it starts on at a coarser rate than the grid its origin is
    /// on, and a coarser grid stands up to its chord error off the surface, on either side: a
    /// ray starting on the far side of it (a coarse facet hanging above a concave fine grid)
    /// is outside the closed surface it tests and can leave without crossing it, however
    /// crossings near the origin are judged (issue 23). The origin is within its own grid's
    /// chord error of the limit surface, the coarser grid within its own: moved by both, it is
    /// on the side the ray leaves on of every tessellation of its subpatch, so the ray crosses
    /// the surface wherever it gets through it. Only this instance's test is moved, so no other
    /// object's contact shadow is lost.
    fn lift(org: &Origin, tess: &Tessellation, depth: u32, rate: Rate, scale: f32) -> f32 {
        // Its seam boxes stand off it by up to their radius too (seam-box hits are crossings
        // like grid hits, `Origin::is_own_other_rate`): the origin goes past those as well, or a
        // grazing ray leaving a convex surface meets the boxes' bulge beside it.
        let off = tess.chord_error + tess.seam_radius;
        let off = if depth > 0 {
            // Split children's chords are 2^depth times shorter than the root's fine ones: their
            // sag is 4^depth times smaller.
            off / (1u32 << (2 * depth)) as f32
        } else {
            // Read at a merged stride the chords are `stride` times longer, their sag `stride`²
            // times larger.
            let stride = rate.tier_and_stride().1;
            off * (stride * stride) as f32
        };
        org.chord_error + off * scale
    }

    /// [`Tracer::hit`], or for an any-hit query (`any_hit`) only what its callers read:
    /// [`Tracer::blocker`].
    #[inline(always)]
    fn hit_or_blocker(&self, any_hit: bool, ii: usize, ray: &Ray, inst: &Pose, h: LocalHit, si: u32) -> Hit {
        if any_hit {
            self.blocker(ii, &h, si)
        } else {
            self.hit(ii, ray, inst, h, si)
        }
    }

    /// An any-hit query's result (shadow and AO rays: [`Tracer::occluded`],
    /// [`Tracer::occluded_from`], [`Tracer::any_hit_from`]): `t`, the instance, mesh, patch and
    /// subpatch of hit `h` on root subpatch `si` of instance `ii`; the rest zero. Those queries
    /// read no more, and the full hit (its point, error bound and render-space normal: ~136
    /// instructions, callgrind) cost every blocked AO ray for nothing.
    fn blocker(&self, ii: usize, h: &LocalHit, si: u32) -> Hit {
        let instance = &self.instances[ii];
        let patch = self.geometry(instance.mesh).subpatches[si as usize].patch;
        Hit {
            t: h.t,
            instance: ii as u32,
            instance_id: instance.id,
            mesh: instance.mesh as u32,
            patch,
            u: 0.0,
            v: 0.0,
            p: Vec3A::ZERO,
            p_error: Vec3A::ZERO,
            ng: Vec3A::ZERO,
            quads: 0,
            subpatch: si,
            chord_error: 0.0,
            time: 0.0,
        }
    }

    /// The render-space hit of `ray` from its hit `h` on root subpatch `si` of instance `ii`
    /// (posed `inst` at the ray's time).
    fn hit(&self, ii: usize, ray: &Ray, inst: &Pose, h: LocalHit, si: u32) -> Hit {
        let instance = &self.instances[ii];
        let mesh = &self.scene.meshes[instance.mesh];
        let sp = &self.geometry(instance.mesh).subpatches[si as usize];
        let u = h.rect.u0 + (h.rect.u1 - h.rect.u0) * h.uv.0;
        let v = h.rect.v0 + (h.rect.v1 - h.rect.v0) * h.uv.1;
        let p = ray.at(h.t);
        let mut ng = (inst.normal_from_object * h.ng).normalize_or(Vec3A::Z);
        if mesh.left_handed {
            ng = -ng;
        }
        // The hit point came from o + t·d after a transform: its error is bounded by a few ulps
        // of the larger of the origin's and the point's magnitude (pbrt §6.8, loosely).
        let p_error = Vec3A::splat(gamma(12)) * (p.abs() + ray.o.abs() + Vec3A::splat(h.t * ray.d.abs().max_element()));
        Hit {
            t: h.t,
            instance: ii as u32,
            instance_id: instance.id,
            mesh: instance.mesh as u32,
            patch: sp.patch,
            u,
            v,
            p,
            p_error,
            ng,
            quads: h.quads,
            subpatch: si,
            chord_error: h.chord_error * inst.scale,
            time: ray.time,
        }
    }

    /// The nearest hit on an exactly intersected surface ([`crate::implicit`]): the bottom-level
    /// BVH's leaves are its patches, each tested in closed form (no tessellation, no rate:
    /// `quads` is 0). The hit's chord error is its floating-point error bound, so rays leaving
    /// the surface skip it only within rounding, by the same rule as tessellated surfaces.
    // Kept out of trace_instance: inlined, they cost the subpatch path ~28 instructions a
    // plain AO ray (callgrind).
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn nearest_exact(
        &self,
        geom: &MeshGeometry,
        blas: &CwBvh,
        exact: &dyn crate::implicit::ExactSurface,
        local: &Local,
        ray: &Ray,
        t_max: f32,
        counters: &mut TraceCounters,
        any_hit: bool,
    ) -> Option<(LocalHit, u32)> {
        let Local { o, d, sign, own, scale } = *local;
        nearest_leaf(blas, o, d, ray.t_min, t_max, any_hit, None, |si, t_best| {
            let patch = geom.subpatches[si].patch as usize;
            counters.ray_subpatch_tests += 1;
            let mut t_from = ray.t_min;
            let h = loop {
                let Some(h) = exact.intersect_at(patch, o, d, t_from, t_best, ray.time) else { break None };
                let window = own.map_or(0.0, |org| (org.chord_error + h.error * scale) * org.inv_cos);
                match own {
                    Some(org) if org.is_own_other_rate(h.t, window, sign * d.dot(h.n), false) => t_from = h.t,
                    _ => break Some(h),
                }
            }?;
            Some(LocalHit { t: h.t, uv: (h.u, h.v), rect: UvRect::UNIT, ng: h.n, quads: 0, chord_error: h.error })
        })
    }

    /// The nearest hit on a curve ([`crate::curves`]): the bottom-level BVH's leaves are its
    /// segments; a segment whose box the ray enters is tessellated into linear pieces at the
    /// rate the ray's beam width asks for (as many pieces as keep their sag from the curve
    /// within the beam; straight segments at one piece), looked up in the geometry cache like
    /// a subpatch's grid (coarse 1 piece, medium 4, fine 16, read at stride 2 for 2 and 8), and
    /// its pieces tested. Beams asking for more than 16 pieces get 16 (counted in
    /// `finer_than_fine`): the sag there is at most 1/256 of one piece's.
    // Kept out of trace_instance: inlined, they cost the subpatch path ~28 instructions a
    // plain AO ray (callgrind).
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn nearest_curve(
        &self,
        mesh_index: usize,
        geom: &MeshGeometry,
        blas: &CwBvh,
        curves: &crate::curves::CurvesSurface,
        local: &Local,
        ray: &Ray,
        t_max: f32,
        counters: &mut TraceCounters,
        any_hit: bool,
    ) -> Option<(LocalHit, u32)> {
        let Local { o, d, sign, own, scale } = *local;
        let kind = Self::kind_index(ray.kind);
        let wray = BoxRay::new(o, d);
        nearest_leaf(blas, o, d, ray.t_min, t_max, any_hit, None, |si, t_best| {
            let sp = &geom.subpatches[si];
            let seg = sp.patch as usize;
            let (t_enter, _) = wray.hit_box(&sp.bounds(), ray.t_min, t_best)?;
            counters.ray_subpatch_tests += 1;
            // Pieces whose sag (falling with the square of their count) is within the beam; a
            // beam of no usable width asks for the finest rate, as for subpatches.
            let beam = ray.beam_width(t_enter) * self.tess_factor * self.kind_factor[kind];
            let sag = curves.sag_of_one_piece(seg) * scale;
            let needed = if beam.is_finite() && beam > 0.0 && sag.is_finite() { (sag / beam).sqrt() } else { 16.0 };
            let rate = if self.single {
                Rate::R16
            } else if curves.is_straight(seg) {
                Rate::R1
            } else {
                Rate::at_least(needed).unwrap_or(Rate::R16)
            };
            if needed > 16.0 && !curves.is_straight(seg) {
                counters.finer_than_fine += 1;
            }
            counters.rate_tests[rate as usize] += 1;
            counters.rate_tests_by_kind[kind][rate as usize] += 1;
            let (tier, stride) = rate.tier_and_stride();
            let cell = ChildCell { root: si as u32, depth: 0, i: 0, j: 0 };
            let mesh = &self.scene.meshes[mesh_index];
            let key =
                CacheKey { mesh: Self::cache_mesh(mesh, mesh_index), generation: mesh.generation, subpatch: geom.child_ids.id(cell), tier };
            let pieces = crate::curves::tier_pieces(tier);
            let tess = if curves.times().is_empty() {
                self.cache.get_or_build(key, || curves.tessellate(seg, pieces))
            } else {
                // Moving curves: the bracketing samples' pieces, each cached under its own key
                // as a deforming mesh's grids are, blended at the ray's time.
                let (i, j, f) = crate::deform::bracket(curves.times(), ray.time);
                let sample = |k: usize| {
                    let key = CacheKey { generation: crate::deform::sample_generation(mesh.generation, k), ..key };
                    self.cache.get_or_build(key, || curves.tessellate_sample(seg, k, pieces))
                };
                match f {
                    f if f <= 0.0 => sample(i),
                    f if f >= 1.0 => sample(j),
                    f => crate::deform::blend(&sample(i), &sample(j), f),
                }
            };
            // Merged pieces sag four times as far as the stored ones.
            let chord_error = tess.chord_error * (stride * stride) as f32;
            let mut t_from = ray.t_min;
            let found = loop {
                let Some(h) = curves.intersect_at(seg, &tess, stride, o, d, t_from, t_best, ray.time) else { break None };
                let window = own.map_or(0.0, |org| (org.chord_error + (chord_error + h.uncertainty) * scale) * org.inv_cos);
                match own {
                    Some(org) if org.is_own_other_rate(h.t, window, sign * d.dot(h.n), h.facing) => t_from = next_up(h.t),
                    _ => break Some(h),
                }
            };
            let h = found?;
            // A ray leaving a camera-facing ribbon skips it within its half width too.
            let chord_error = chord_error + h.uncertainty;
            Some(LocalHit { t: h.t, uv: (h.u, h.v), rect: UvRect::UNIT, ng: h.n, quads: rate.quads() as u32, chord_error })
        })
    }

    /// The mesh's key in the cache.
    fn cache_mesh(mesh: &crate::scene::Mesh, mesh_index: usize) -> u32 {
        mesh.cache_id.unwrap_or(mesh_index as u32)
    }

    /// The tessellation of a (root or split) subpatch at a tier, from the cache or built now;
    /// of a deforming mesh, the one blended at shutter time `time` ([`crate::deform`]).
    #[inline]
    fn lookup(&self, mesh_index: usize, geom: &MeshGeometry, cell: ChildCell, tier: Tier, time: f32) -> Tessellation {
        if geom.deforms {
            return self.lookup_deforming(mesh_index, geom, cell, tier, time);
        }
        let mesh = &self.scene.meshes[mesh_index];
        self.lookup_sample(mesh_index, geom, cell, tier, mesh.surface.as_ref(), mesh.generation)
    }

    /// A deforming mesh's grid at shutter time `time`: its bracketing samples' grids, each
    /// cached under its own key, blended.
    #[cold]
    #[inline(never)]
    fn lookup_deforming(&self, mesh_index: usize, geom: &MeshGeometry, cell: ChildCell, tier: Tier, time: f32) -> Tessellation {
        let mesh = &self.scene.meshes[mesh_index];
        let Some(def) = mesh.surface.deformation() else {
            return self.lookup_sample(mesh_index, geom, cell, tier, mesh.surface.as_ref(), mesh.generation);
        };
        let (i, j, f) = def.bracket(time);
        let sample = |k: usize| {
            let generation = crate::deform::sample_generation(mesh.generation, k);
            self.lookup_sample(mesh_index, geom, cell, tier, def.sample(k), generation)
        };
        match f {
            f if f <= 0.0 => sample(i),
            f if f >= 1.0 => sample(j),
            f => crate::deform::blend(&sample(i), &sample(j), f),
        }
    }

    /// The tessellation of a (root or split) subpatch of `surface` (the mesh's, or one of its
    /// deformation samples') at a tier, cached under `generation`.
    fn lookup_sample(
        &self,
        mesh_index: usize,
        geom: &MeshGeometry,
        cell: ChildCell,
        tier: Tier,
        surface: &dyn crate::patch::LimitSurface,
        generation: u32,
    ) -> Tessellation {
        let mesh = &self.scene.meshes[mesh_index];
        let root = &geom.subpatches[cell.root as usize];
        let key = CacheKey { mesh: Self::cache_mesh(mesh, mesh_index), generation, subpatch: geom.child_ids.id(cell), tier };
        self.cache.get_or_build_reusing(key, |spare| {
            let sub = root.subpatch(cell.rect(&UvRect::UNIT));
            let mut scratch = GridSamples::default();
            let displace = mesh.displacement.clone().map(|displacement| DisplaceParams {
                displacement,
                normal_sign: if mesh.left_handed { -1.0 } else { 1.0 },
                bound: mesh.displacement_bound,
                texture_edges_alike: self.displacement_rate_floor,
            });
            let (t, outside) = tessellate_reusing(surface, &sub, tier, displace.as_ref(), &mut scratch, spare);
            if mesh.surface.lazy_bounds().is_some() {
                self.check_declared(mesh, &sub.bounds, &t);
            }
            if outside > 0 && self.displaced_outside.fetch_add(u64::from(outside), Ordering::Relaxed) == 0 {
                log::warn!(
                    "{}: displaced vertices leave their subpatch bounds; raise primvars:displacementBound (now {})",
                    mesh.name,
                    mesh.displacement_bound
                );
            }
            t
        })
    }

    /// Counts (and reports once per render) a grid of a mesh built on first use that leaves the
    /// bounds the mesh's instances were placed by: rays entered them through those bounds, so
    /// they may have missed that part. `sub_bounds` (the subpatch's box) holds the grid but for displaced vertices, which are
    /// counted apart: a box inside the declared bounds needs no look at the vertices.
    fn check_declared(&self, mesh: &crate::scene::Mesh, sub_bounds: &Bounds3, t: &Tessellation) {
        let declared = Self::declared_bounds(mesh);
        if declared.contains(sub_bounds.min) && declared.contains(sub_bounds.max) {
            return;
        }
        if let Some(v) = t.verts.iter().find(|v| !declared.contains(Vec3A::from(**v))) {
            if self.lazy_bounds_escaped.fetch_add(1, Ordering::Relaxed) == 0 {
                log::warn!(
                    "{}: a tessellation vertex {v:?} lies outside the bounds its mesh was placed by ({:?}..{:?}); rays there may miss it",
                    mesh.name,
                    declared.min,
                    declared.max
                );
            }
        }
    }

    /// Descends from `cell` (whose fine tessellation is `tess`) to split children at
    /// `target_depth`, entering only children whose boxes the ray hits, and tests their fine
    /// grids. A child's box is the part of its parent's fine grid over it, grown by the parent's
    /// chord error estimate (and a few ulps), so the descent never skips the surface.
    #[allow(clippy::too_many_arguments)]
    fn hit_split(
        &self,
        mesh_index: usize,
        geom: &MeshGeometry,
        cell: ChildCell,
        tess: &Tessellation,
        target_depth: u32,
        time: f32,
        wray: &WatertightRay,
        t_min: f32,
        t_best: &mut f32,
        best: &mut Option<LocalHit>,
    ) {
        let root_rect = UvRect::UNIT;
        if u32::from(cell.depth) >= target_depth {
            if let Some(h) =
                intersect_with_seams(wray, tess, 1, self.seam_edges(cell), t_min, *t_best, &crate::intersect::every_hit, &never_from_inside)
            {
                *t_best = h.t;
                *best = Some(LocalHit {
                    t: h.t,
                    uv: (h.u, h.v),
                    rect: cell.rect(&root_rect),
                    ng: h.ng,
                    quads: 16 << cell.depth,
                    chord_error: tess.chord_error,
                });
            }
            return;
        }
        for child in cell.children() {
            let (ci, cj) = ((child.i - cell.i * 2) as usize * 8, (child.j - cell.j * 2) as usize * 8);
            let mut bb = Bounds3::EMPTY;
            for j in cj..=cj + 8 {
                for i in ci..=ci + 8 {
                    bb.grow(tess.vert(i, j));
                }
            }
            // Seam boxes reach past a child's grid by about their radius, finer than the parent's.
            let pad = tess.chord_error + 2.0 * tess.seam_radius + gamma(8) * bb.max_abs();
            if wray.hit_box(&bb.expanded(pad), t_min, *t_best).is_none() {
                continue;
            }
            let ct = self.lookup(mesh_index, geom, child, Tier::Fine, time);
            self.hit_split(mesh_index, geom, child, &ct, target_depth, time, wray, t_min, t_best, best);
        }
    }

    /// Render-from-object transform of a hit's instance at the hit's time.
    pub fn hit_render_from_object(&self, hit: &Hit) -> Mat4 {
        self.instances[hit.instance as usize].pose(hit.time).render_from_object
    }

    /// The normal matrix of a hit's instance at the hit's time.
    pub fn hit_normal_matrix(&self, hit: &Hit) -> Mat3A {
        self.instances[hit.instance as usize].pose(hit.time).normal_from_object
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tessellate::GridDomain;

    fn quad(p: [Vec3A; 4]) -> Tessellation {
        Tessellation {
            n: 2,
            verts: p.iter().map(|v| v.to_array()).collect::<Vec<_>>().into(),
            boxes: Default::default(),
            chord_error: 0.0,
            seam_radius: 0.0,
            seam_normal: Default::default(),
            domain: GridDomain::Square,
        }
    }

    #[test]
    fn an_own_quad_passed_over_is_crossed_at_most_once_the_way_the_ray_left() {
        // Random bent quads (p00, p10, p01, p11) and directions: wherever the rule lets a ray
        // pass its own quad unseen, no line along that direction crosses the quad twice, and any
        // crossing goes the way the ray leaves (so it cannot be the far wall of a fold).
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let (mut passed, mut refused) = (0, 0);
        for _ in 0..4000 {
            let bend = next().abs() * 1.5;
            let p = [
                Vec3A::new(0.0, 0.0, next() * bend),
                Vec3A::new(1.0, 0.0, next() * bend),
                Vec3A::new(0.0, 1.0, next() * bend),
                Vec3A::new(1.0, 1.0, next() * bend),
            ];
            let tess = quad(p);
            let d = Vec3A::new(next(), next(), next()).normalize_or(Vec3A::Z);
            for along_ng in [true, false] {
                for handed in [1.0, -1.0] {
                    let origin = Origin { instance: 0, subpatch: 0, side: Vec3A::Z, chord_error: 0.0, inv_cos: 1.0, along_ng, quads: 1 };
                    if !origin.passes_own_quad(&tess, d, handed) {
                        refused += 1;
                        continue;
                    }
                    passed += 1;
                    let side = if along_ng { handed } else { -handed };
                    for _ in 0..20 {
                        let at = Vec3A::new(next() * 0.7 + 0.5, next() * 0.7 + 0.5, 0.0);
                        let ray = WatertightRay::new(at - d * 10.0, d);
                        let tris = [(p[0], p[1], p[3]), (p[0], p[3], p[2])];
                        let crossings: Vec<(f32, Vec3A)> = tris
                            .iter()
                            .filter_map(|(a, b, c)| ray.hit_triangle(*a, *b, *c, f32::INFINITY).map(|h| (h.0, (*b - *a).cross(*c - *a))))
                            .collect();
                        // A line through the shared diagonal meets both halves at one point.
                        let once = crossings.len() <= 1 || (crossings[0].0 - crossings[1].0).abs() < 1e-4;
                        assert!(once, "{p:?} crossed {} times along {d}", crossings.len());
                        for (_, n) in crossings {
                            assert!(side * d.dot(n) > 0.0, "{p:?}: crossed against the way the ray left");
                        }
                    }
                }
            }
        }
        assert!(passed > 1000 && refused > 1000, "passed {passed}, refused {refused}");
    }

    /// A ray leaving a displaced mesh reads its own neighbourhood at the grid its origin is on:
    /// the (depth, rate) recovered from the quads a hit records (`LocalHit::quads`: the rate's
    /// quads unsplit, 16 · 2^depth split) must be the one that grid was read at.
    #[test]
    fn the_origins_grid_is_recovered_from_its_hits_quads() {
        let origin = |quads| Origin { instance: 0, subpatch: 0, side: Vec3A::Z, chord_error: 0.0, inv_cos: 1.0, along_ng: true, quads };
        for rate in Rate::ALL {
            assert_eq!(origin(rate.quads() as u32).depth_rate(), Some((0, rate)));
        }
        for depth in 1..6 {
            assert_eq!(origin(16 << depth).depth_rate(), Some((depth, Rate::R16)));
        }
        // An exactly intersected surface has no grid.
        assert_eq!(origin(0).depth_rate(), None);
    }
}
