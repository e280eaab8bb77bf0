//! Tracing rays through the scene: instances (top level) → a mesh's subpatches (bottom level) →
//! on-demand tessellation at the rate the ray's beam width asks for, looked up in the
//! multiresolution geometry cache (the paper's §5) → watertight quad tests.

use std::sync::Arc;

use glam::{Mat3A, Mat4, Vec3A};
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray as BvhRay, RayHit};

use crate::bounds::Bounds3;
use crate::bvh::build_bvh;
use crate::geometry_cache::{CacheConfig, CacheKey, GeometryCache};
use crate::intersect::{intersect_tessellation, WatertightRay};
use crate::patch::GridSamples;
use crate::ray::{gamma, Ray, RayKind};
use crate::scene::Scene;
use crate::subpatch::MeshGeometry;
use crate::tessellate::{tessellate, Rate, Tessellation};

/// Replaces −0.0 components by +0.0. obvhs 0.4's CWBVH traversal picks the child order from the
/// direction's sign bits but its slab test from comparisons, and misses every box when a
/// component is −0.0 (a reflection off an axis-aligned plane makes such rays); adding +0.0
/// canonicalises the zero without changing any other value.
#[inline]
pub fn positive_zeros(d: Vec3A) -> Vec3A {
    d + Vec3A::ZERO
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
    /// Tests whose beam asked for more than 16×16 quads (served at 16×16 until splitting).
    pub finer_than_fine: u64,
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
    }
}

/// A ray's closest hit. Render space unless stated.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    /// Index into the tracer's instances (for [`Tracer::render_from_object`]).
    pub instance: u32,
    /// The scene's instance id (the `instanceId` AOV).
    pub instance_id: u32,
    pub mesh: u32,
    pub patch: u32,
    /// The patch's own (u, v) at the hit: shading evaluates the exact limit surface there.
    pub u: f32,
    pub v: f32,
    /// The hit point on the tessellation.
    pub p: Vec3A,
    /// Conservative per-axis floating-point error of `p`, for offsetting new rays.
    pub p_error: Vec3A,
    /// Unit geometric normal of the hit triangle, from its winding (front faces wind counter-
    /// clockwise, as USD's rightHanded orientation).
    pub ng: Vec3A,
    /// The effective rate the hit was found at.
    pub rate: Rate,
}

struct InstanceData {
    /// The scene's instance id.
    id: u32,
    mesh: usize,
    render_from_object: Mat4,
    object_from_render: Mat4,
    /// For normals: the inverse transpose of the linear part.
    normal_from_object: Mat3A,
    /// Largest stretch of the linear part: object sizes × this ≥ world sizes.
    scale: f32,
}

/// The scene prepared for tracing: BVHs at both levels and the geometry cache.
pub struct Tracer<'s> {
    scene: &'s Scene,
    meshes: Vec<MeshGeometry>,
    instances: Vec<InstanceData>,
    tlas: Option<CwBvh>,
    pub cache: Arc<GeometryCache<Tessellation>>,
    tess_factor: f32,
    pub bounds: Bounds3,
}

impl<'s> Tracer<'s> {
    /// Builds subpatches and BVHs for `scene`. Meshes are prepared once and shared by their
    /// instances.
    pub fn new(scene: &'s Scene, cache: CacheConfig, tess_factor: f32) -> Self {
        use rayon::prelude::*;
        let meshes: Vec<MeshGeometry> = scene.meshes.par_iter().map(MeshGeometry::build).collect();
        let mut boxes = Vec::new();
        let mut instances = Vec::new();
        for inst in &scene.instances {
            let Some(g) = meshes.get(inst.mesh) else { continue };
            if g.bvh.is_none() || !inst.render_from_object.is_finite() {
                continue;
            }
            let m3 = Mat3A::from_mat4(inst.render_from_object);
            let scale = m3.x_axis.length().max(m3.y_axis.length()).max(m3.z_axis.length());
            boxes.push(g.bounds.transformed(&inst.render_from_object));
            instances.push(InstanceData {
                id: inst.id,
                mesh: inst.mesh,
                render_from_object: inst.render_from_object,
                object_from_render: inst.render_from_object.inverse(),
                normal_from_object: m3.inverse().transpose(),
                scale,
            });
        }
        let bounds = boxes.iter().fold(Bounds3::EMPTY, |a, b| a.union(b));
        let tlas = build_bvh(&boxes);
        Tracer { scene, meshes, instances, tlas, cache: Arc::new(GeometryCache::new(cache)), tess_factor, bounds }
    }

    /// Root subpatches over all meshes (each counted once, however many instances).
    pub fn subpatch_count(&self) -> usize {
        self.meshes.iter().map(|m| m.subpatches.len()).sum()
    }

    /// The scene's root subpatches and the render-space instance placements, for statistics.
    pub fn mesh_geometry(&self) -> &[MeshGeometry] {
        &self.meshes
    }

    /// The closest hit along `ray` in (t_min, t_max), or `None`.
    pub fn intersect(&self, ray: &Ray, counters: &mut TraceCounters) -> Option<Hit> {
        self.trace(ray, counters, false)
    }

    /// True when anything blocks `ray` in (t_min, t_max) (shadow rays).
    pub fn occluded(&self, ray: &Ray, counters: &mut TraceCounters) -> bool {
        self.trace(ray, counters, true).is_some()
    }

    fn kind_index(kind: RayKind) -> usize {
        RayKind::ALL.iter().position(|k| *k == kind).unwrap_or(0)
    }

    fn trace(&self, ray: &Ray, counters: &mut TraceCounters, any_hit: bool) -> Option<Hit> {
        counters.rays[Self::kind_index(ray.kind)] += 1;
        let tlas = self.tlas.as_ref()?;
        if !(ray.o.is_finite() && ray.d.is_finite()) {
            return None;
        }
        let bray = BvhRay::new(ray.o, positive_zeros(ray.d), ray.t_min, ray.t_max);
        let mut best: Option<Hit> = None;
        let mut t_best = ray.t_max;
        let mut rh = RayHit::none();
        let mut done = false;
        tlas.ray_traverse(bray, &mut rh, |_r, id| {
            if done {
                return f32::INFINITY;
            }
            let ii = tlas.primitive_indices[id] as usize;
            if let Some(h) = self.trace_instance(ii, ray, t_best, counters, any_hit) {
                t_best = h.t;
                best = Some(h);
                if any_hit {
                    done = true;
                }
                return h.t;
            }
            f32::INFINITY
        });
        best
    }

    fn trace_instance(&self, ii: usize, ray: &Ray, t_max: f32, counters: &mut TraceCounters, any_hit: bool) -> Option<Hit> {
        let inst = &self.instances[ii];
        let geom = &self.meshes[inst.mesh];
        let blas = geom.bvh.as_ref()?;
        let mesh = &self.scene.meshes[inst.mesh];
        let o = inst.object_from_render.transform_point3a(ray.o);
        let d = positive_zeros(inst.object_from_render.transform_vector3a(ray.d));
        let wray = WatertightRay::new(o, d);
        let mut best: Option<(crate::intersect::GridHit, u32, Rate)> = None;
        let mut t_best = t_max;
        let mut rh = RayHit::none();
        let mut done = false;
        blas.ray_traverse(BvhRay::new(o, d, ray.t_min, t_max), &mut rh, |_r, id| {
            if done {
                return f32::INFINITY;
            }
            let si = blas.primitive_indices[id] as usize;
            let sp = &geom.subpatches[si];
            let Some((t_enter, _)) = wray.hit_box(&sp.bounds, ray.t_min, t_best) else {
                return f32::INFINITY;
            };
            counters.ray_subpatch_tests += 1;
            let size = sp.bounds.diagonal().max_element() * inst.scale;
            let rate = match Rate::for_beam(size, ray.beam_width(t_enter), self.tess_factor) {
                Some(r) => r,
                None => {
                    counters.finer_than_fine += 1;
                    Rate::R16
                }
            };
            counters.rate_tests[rate as usize] += 1;
            let (tier, stride) = rate.tier_and_stride();
            let key = CacheKey { mesh: inst.mesh as u32, generation: mesh.generation, subpatch: si as u32, tier };
            let tess = self.cache.get_or_build(key, || {
                let mut scratch = GridSamples::default();
                tessellate(mesh.surface.as_ref(), sp, tier, &mut scratch)
            });
            match intersect_tessellation(&wray, &tess, stride, ray.t_min, t_best) {
                Some(h) => {
                    t_best = h.t;
                    best = Some((h, si as u32, rate));
                    if any_hit {
                        done = true;
                    }
                    h.t
                }
                None => f32::INFINITY,
            }
        });
        let (h, si, rate) = best?;
        let sp = &geom.subpatches[si as usize];
        let u = sp.rect.u0 + (sp.rect.u1 - sp.rect.u0) * h.u;
        let v = sp.rect.v0 + (sp.rect.v1 - sp.rect.v0) * h.v;
        let p = ray.at(h.t);
        let mut ng = (inst.normal_from_object * h.ng).normalize_or(Vec3A::Z);
        if mesh.left_handed {
            ng = -ng;
        }
        // The hit point came from o + t·d after a transform: its error is bounded by a few ulps
        // of the larger of the origin's and the point's magnitude (pbrt §6.8, loosely).
        let p_error = Vec3A::splat(gamma(12)) * (p.abs() + ray.o.abs() + Vec3A::splat(h.t * ray.d.abs().max_element()));
        Some(Hit { t: h.t, instance: ii as u32, instance_id: inst.id, mesh: inst.mesh as u32, patch: sp.patch, u, v, p, p_error, ng, rate })
    }

    /// The normal matrix (inverse transpose of the linear part) of a hit's instance.
    pub fn normal_matrix(&self, instance: u32) -> Mat3A {
        self.instances[instance as usize].normal_from_object
    }

    /// Render-from-object transform of a hit's instance.
    pub fn render_from_object(&self, instance: u32) -> Mat4 {
        self.instances[instance as usize].render_from_object
    }
}
