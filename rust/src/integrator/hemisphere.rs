//! Integrals over the hemisphere above a shading point: ambient occlusion, and the gathering of
//! stratified hemisphere rays that both ambient occlusion and one-bounce color bleeding
//! ([`super::bleed`]) use, with or without the irradiance cache ([`crate::irradiance_cache`]).
//! Hemisphere rays are wide and incoherent (the paper's §4.6), so they read coarse tessellations.

use std::sync::OnceLock;

use glam::Vec3A;

use crate::bsdf::Scattering;
use crate::differential::{HemisphereFan, RayDifferential};
use crate::error::RenderError;
use crate::irradiance_cache::{estimate, stats_object, HemisphereEstimate, HemisphereRay, IrradianceCache, PrepassPoint, Quantity, Strata};
use crate::material::ResolvedSurface;
use crate::options::RenderOptions;
use crate::progress::Progress;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::{frame, Sampler};
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

use super::visibility::{self, MAX_CUTOUTS};
use super::{shading_point, ShadingPoint};

/// Mixed into the seed for the random streams of the irradiance cache's records, so they are
/// independent of the camera samples' streams of the same pixel.
pub const RECORD_STREAM: u64 = 0x1CAC_4E00_D15C_0BA1;

/// The surface a ray sees: its hit, the shading point there (with the material's normal-mapped
/// shading normal), the ray's differential transferred to it, and the material's inputs there.
#[derive(Clone, Copy, Debug)]
pub struct Visible {
    /// The ray that made the hit (past any cut-out surfaces).
    pub ray: Ray,
    pub hit: Hit,
    pub sp: ShadingPoint,
    pub footprint: RayDifferential,
    pub surface: ResolvedSurface,
}

impl Visible {
    /// The BSDF's diffuse albedo toward the ray's origin: what hemisphere integrals (ambient
    /// occlusion, irradiance over π) are multiplied by.
    pub fn diffuse_albedo(&self) -> Vec3A {
        self.surface.bsdf(&self.sp).diffuse_albedo(-self.ray.d)
    }
}

/// The first surface along `ray` that is not cut out, from the camera (`from` = `None`) or
/// leaving the surface at `from`. A cut-out surface lets the same ray go on, its beam as it
/// arrived; past [`MAX_CUTOUTS`] of them the ray ends (counted in the stats).
pub fn visible(tracer: &Tracer<'_>, scene: &Scene, mut ray: Ray, mut from: Option<Hit>, counters: &mut TraceCounters) -> Option<Visible> {
    for _ in 0..=MAX_CUTOUTS {
        let hit = match &from {
            Some(f) => tracer.intersect_from(&ray, f, counters)?,
            None => tracer.intersect(&ray, counters)?,
        };
        match resolve(tracer, scene, ray, hit, counters) {
            Resolved::Surface(v) => return Some(v),
            Resolved::CutOut(next, at) => {
                counters.cutout_passes += 1;
                (ray, from) = (next, Some(at));
            }
        }
    }
    counters.cutout_limit += 1;
    None
}

/// What a ray finds at a hit: a surface, or a cut-out and the ray going on from it.
// Returned by value once per hit and never stored: boxing the larger variant would only add an
// allocation per hit.
#[allow(clippy::large_enum_variant)]
enum Resolved {
    Surface(Visible),
    CutOut(Ray, Hit),
}

/// The surface at `hit` of `ray`, or where it is cut out, the ray going on from it.
fn resolve(tracer: &Tracer<'_>, scene: &Scene, ray: Ray, hit: Hit, counters: &mut TraceCounters) -> Resolved {
    let sp = shading_point(tracer, scene, &ray, &hit);
    let (footprint, clamped) = ray.diff.transfer_checked(ray.d, hit.t, sp.ng);
    counters.differential_clamps += u64::from(clamped);
    let mesh = &scene.meshes[hit.mesh as usize];
    let surface = scene.material_at(hit.mesh as usize, hit.patch as usize).resolve(mesh.surface.as_ref(), &hit, &sp, &footprint);
    if surface.cut_out() {
        let o = offset_origin(sp.p, hit.p_error, sp.ng, ray.d);
        return Resolved::CutOut(Ray { o, t_min: 0.0, t_max: ray.t_max - hit.t, diff: footprint, ..ray }, hit);
    }
    Resolved::Surface(Visible { ray, hit, sp: ShadingPoint { ns: surface.ns, ..sp }, footprint, surface })
}

/// The surface a ray that already hit `hit` sees: that one, or the first behind it that is not
/// cut out.
pub fn visible_at(tracer: &Tracer<'_>, scene: &Scene, ray: Ray, hit: Hit, counters: &mut TraceCounters) -> Option<Visible> {
    match resolve(tracer, scene, ray, hit, counters) {
        Resolved::Surface(v) => Some(v),
        Resolved::CutOut(next, at) => {
            counters.cutout_passes += 1;
            visible(tracer, scene, next, Some(at), counters)
        }
    }
}

/// Ambient occlusion's settings — rays per shading point and how far they look — and, when
/// `irradianceCache` is on, its occlusion cache (made by [`Hemisphere::prepass`]).
#[derive(Debug)]
pub struct Hemisphere {
    pub samples: u32,
    /// World units; infinite for unbounded.
    pub distance: f32,
    /// The cache's error bound, when caching (`irradianceCache` on and `samples` > 0).
    cache_error: Option<f32>,
    cache: OnceLock<IrradianceCache>,
}

impl Hemisphere {
    /// Ambient occlusion with `samples` rays per shading point (0: off) looking `options.ao_distance`
    /// far, interpolated from an occlusion cache with error bound `options.irradiance_cache_error`
    /// when `options.irradiance_cache` is on. The cache is empty until [`Hemisphere::prepass`].
    pub fn new(samples: u32, options: &RenderOptions) -> Self {
        Hemisphere {
            samples,
            distance: options.ao_distance,
            cache_error: (options.irradiance_cache && samples > 0).then_some(options.irradiance_cache_error),
            cache: OnceLock::new(),
        }
    }

    /// The occlusion cache, once the pre-pass has made it.
    pub fn cache(&self) -> Option<&IrradianceCache> {
        self.cache.get()
    }

    /// The occlusion cache, mutable (e.g. to turn its gradients off and measure what they buy).
    pub fn cache_mut(&mut self) -> Option<&mut IrradianceCache> {
        self.cache.get_mut()
    }

    /// The unoccluded fraction of the cosine-weighted hemisphere within `ao_distance`: from the
    /// occlusion cache where one of its records is valid, otherwise from [`Strata::for_rays`]
    /// (`ao_samples`) stratified rays whose spread is √(1/(N·p(ω))) (the paper's §4.6): wide near
    /// the horizon, narrower at the pole. Rays below the geometric surface count as occluded;
    /// opacity cut-outs do not occlude ([`visibility::occluded_from`]).
    pub fn occlusion(
        &self,
        tracer: &Tracer<'_>,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> f32 {
        if self.samples == 0 {
            return 0.0;
        }
        if let Some(v) = self.cache.get().and_then(|c| c.interpolate(sp.p, sp.ns)) {
            return v.x;
        }
        let strata = Strata::for_rays(self.samples);
        let (t, b) = frame(sp.ns);
        let fan = footprint.hemisphere_fan();
        let mut open = 0u32;
        for k in 0..strata.phi {
            for j in 0..strata.theta {
                let (local, pdf) = strata.direction(j, k, sampler.next_f32(), sampler.next_f32());
                let d = t * local.x + b * local.y + sp.ns * local.z;
                if d.dot(sp.ng) <= 0.0 {
                    continue;
                }
                let r = hemisphere_ray(sp, hit, &fan, d, pdf, strata, self.distance, RayKind::Ao, counters);
                if !visibility::occluded_from(tracer, &r, hit, counters) {
                    open += 1;
                }
            }
        }
        open as f32 / strata.rays() as f32
    }

    /// An occlusion record's integral at a shading point, with gradients: the rays of
    /// [`Hemisphere::occlusion`], traced to their closest hits (Ward's harmonic mean and the
    /// gradients need the distances).
    pub fn occlusion_estimate(
        &self,
        tracer: &Tracer<'_>,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> HemisphereEstimate {
        let strata = Strata::for_rays(self.samples);
        let rays = gather(tracer, sp, hit, footprint, strata, self.distance, RayKind::Ao, sampler, counters, |hit, _, _, _| {
            if hit.is_some() {
                Vec3A::ZERO
            } else {
                Vec3A::ONE
            }
        });
        let (t, b) = frame(sp.ns);
        estimate(strata, &rays, t, b, sp.ns)
    }

    /// Makes the occlusion cache, when caching, at the camera hits of the pixel centres that have
    /// a diffuse reflectance (where the integrators take ambient occlusion); see
    /// [`IrradianceCache::build`]. Nothing when not caching, or when already made. Returns the
    /// rays traced. An integrator calls it from [`super::Integrator::prepass`].
    ///
    /// # Errors
    /// [`RenderError::Cancelled`] through `progress`.
    pub fn prepass(
        &self,
        tracer: &Tracer<'_>,
        scene: &Scene,
        options: &RenderOptions,
        progress: &dyn Progress,
    ) -> Result<TraceCounters, RenderError> {
        self.prepass_where(tracer, scene, options, progress, &|v| v.diffuse_albedo().max_element() > 0.0)
    }

    /// As [`Hemisphere::prepass`], at the surfaces camera rays see where `needs(surface)`.
    ///
    /// # Errors
    /// [`RenderError::Cancelled`] through `progress`.
    pub fn prepass_where(
        &self,
        tracer: &Tracer<'_>,
        scene: &Scene,
        options: &RenderOptions,
        progress: &dyn Progress,
        needs: &(dyn Fn(&Visible) -> bool + Sync),
    ) -> Result<TraceCounters, RenderError> {
        let Some(error) = self.cache_error else { return Ok(TraceCounters::default()) };
        if self.cache.get().is_some() {
            return Ok(TraceCounters::default());
        }
        let mut cache = IrradianceCache::new(Quantity::Occlusion, error);
        let counters = prepass_build(&mut cache, tracer, scene, options, progress, needs, |pt, pixel, counters| {
            let mut sampler = Sampler::new(options.seed ^ RECORD_STREAM, pixel, 0);
            Some(self.occlusion_estimate(tracer, &pt.ctx.sp, &pt.ctx.hit, &pt.ctx.footprint, &mut sampler, counters))
        })?;
        let _ = self.cache.set(cache);
        Ok(counters)
    }

    /// The stats' `irradiance_cache` object for this occlusion cache (see
    /// [`crate::irradiance_cache::stats_object`]); `None` when not caching.
    pub fn cache_stats(&self) -> Option<serde_json::Value> {
        stats_object(&[self.cache()])
    }
}

/// A hemisphere ray from the shading point toward unit `d`, one of `strata.rays()` sampled with
/// density `pdf` there, reaching `distance` (world units): origin offset off the surface by the
/// hit's error bound, and §4.6's differential from the footprint.
#[allow(clippy::too_many_arguments)]
pub fn hemisphere_ray(
    sp: &ShadingPoint,
    hit: &Hit,
    fan: &HemisphereFan,
    d: Vec3A,
    pdf: f32,
    strata: Strata,
    distance: f32,
    kind: RayKind,
    counters: &mut TraceCounters,
) -> Ray {
    let (diff, clamped) = fan.ray(d, pdf, strata.rays());
    counters.differential_clamps += u64::from(clamped);
    Ray { o: offset_origin(sp.p, hit.p_error, sp.ng, d), d, t_min: 0.0, t_max: distance, diff, kind, time: hit.time }
}

/// Traces the stratified hemisphere rays of `strata` above the shading point (cosine-weighted,
/// jittered by `sampler`, two numbers a ray) to their closest hits within `distance` that are
/// not cut out ([`visibility::first_opaque_from`]), and returns what each found in
/// [`Strata::index`] order: its local direction, hit distance (`distance` itself when it hits
/// nothing), and `shade(hit, ray, sampler, counters)` — the value it brings back, `ray` being
/// the segment that made the hit (past any cut-outs). Rays below the geometric surface are not
/// traced: value 0, distance infinite.
#[allow(clippy::too_many_arguments)]
pub fn gather(
    tracer: &Tracer<'_>,
    sp: &ShadingPoint,
    hit: &Hit,
    footprint: &RayDifferential,
    strata: Strata,
    distance: f32,
    kind: RayKind,
    sampler: &mut Sampler,
    counters: &mut TraceCounters,
    mut shade: impl FnMut(Option<&Hit>, &Ray, &mut Sampler, &mut TraceCounters) -> Vec3A,
) -> Vec<HemisphereRay> {
    let (t, b) = frame(sp.ns);
    let fan = footprint.hemisphere_fan();
    let mut out = vec![HemisphereRay { dir: Vec3A::Z, distance: f32::INFINITY, value: Vec3A::ZERO }; strata.rays() as usize];
    for k in 0..strata.phi {
        for j in 0..strata.theta {
            let (local, pdf) = strata.direction(j, k, sampler.next_f32(), sampler.next_f32());
            let d = t * local.x + b * local.y + sp.ns * local.z;
            let slot = &mut out[strata.index(j, k)];
            slot.dir = local;
            if d.dot(sp.ng) <= 0.0 {
                continue;
            }
            let r = hemisphere_ray(sp, hit, &fan, d, pdf, strata, distance, kind, counters);
            let found = visibility::first_opaque_from(tracer, &r, hit, counters);
            // A ray that reaches nothing within a finite `distance` (ambient occlusion's) counts
            // as reaching that far: what lies beyond does not change the integral until it
            // comes within reach, so the reach is the length scale the record is valid over.
            slot.distance = found.as_ref().map_or(distance, |b| b.distance);
            slot.value = match &found {
                Some(b) => shade(Some(&b.hit), &b.ray, sampler, counters),
                None => shade(None, &r, sampler, counters),
            };
        }
    }
    out
}

/// The pre-pass of a cache over the surfaces the camera rays through the pixel centres see:
/// `needs` filters them, `compute` makes a record's integral. Shared by the occlusion and the
/// irradiance caches.
///
/// # Errors
/// [`RenderError::Cancelled`] through `progress`.
pub fn prepass_build<G>(
    cache: &mut IrradianceCache,
    tracer: &Tracer<'_>,
    scene: &Scene,
    options: &RenderOptions,
    progress: &dyn Progress,
    needs: &(dyn Fn(&Visible) -> bool + Sync),
    compute: G,
) -> Result<TraceCounters, RenderError>
where
    G: Fn(&PrepassPoint<Visible>, u64, &mut TraceCounters) -> Option<HemisphereEstimate> + Sync,
{
    let (w, h) = (options.width, options.height);
    let cam = &scene.camera;
    let visit = |x: usize, y: usize, counters: &mut TraceCounters| {
        // The ray of sample 0 (the pixel centre), unscaled: its footprint is one pixel. With
        // motion blur, the records see the scene at mid-shutter.
        let mut ray = cam.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
        ray.time = 0.5;
        let v = visible(tracer, scene, ray, None, counters)?;
        if !needs(&v) {
            return None;
        }
        Some(PrepassPoint { p: v.sp.p, n: v.sp.ns, pixel_width: v.ray.beam_width(v.hit.t), ctx: v })
    };
    let cancelled = || progress.cancelled();
    cache.build(w, h, visit, compute, &cancelled).map_err(|_| RenderError::Cancelled)
}
