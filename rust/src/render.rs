//! The one entry point: `render(scene, options, progress)`. Tiles of pixels are rendered in
//! parallel (rayon); every random number depends only on (seed, pixel, sample), so the image is
//! the same with any thread count.

use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use serde_json::Value;

use crate::effects;
use crate::error::RenderError;
use crate::film::Film;
use crate::geometry_cache::{CacheMode, GeometryCache};
use crate::integrator::{DirectLighting, Integrator, SampleValue};
use crate::options::RenderOptions;
use crate::progress::Progress;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::stats::{collect, RenderFigures};
use crate::tessellate::Tessellation;
use crate::trace::{TraceCounters, Tracer};

/// Tile edge in pixels: small enough to balance two threads on small images.
const TILE: usize = 16;

/// A finished render: the film and the stats JSON (DESIGN.md names).
pub struct RenderOutput {
    pub film: Film,
    pub stats: Value,
}

type Tile = (usize, usize, usize, usize);

struct TileResult {
    tile: Tile,
    values: Vec<SampleValue>,
    counters: TraceCounters,
    dropped: u64,
}

/// Renders `scene` as `options` ask.
///
/// # Errors
/// Invalid settings or camera, or cancellation through `progress`.
pub fn render(scene: &Scene, options: &RenderOptions, progress: &dyn Progress) -> Result<RenderOutput, RenderError> {
    render_with_cache(scene, options, None, progress)
}

/// As [`render`], with a geometry cache that outlives the render (a render delegate keeps one
/// so unchanged meshes keep their tessellations between renders). `options.cache` must match
/// the cache's configuration; its statistics are cumulative over the cache's life.
///
/// # Errors
/// As [`render`].
pub fn render_with_cache(
    scene: &Scene,
    options: &RenderOptions,
    cache: Option<Arc<GeometryCache<Tessellation>>>,
    progress: &dyn Progress,
) -> Result<RenderOutput, RenderError> {
    options.validate()?;
    scene.camera.validate().map_err(RenderError::Camera)?;
    let start = Instant::now();
    let threads = if options.threads == 0 { std::thread::available_parallelism().map_or(1, |n| n.get()) } else { options.threads };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| RenderError::Settings(format!("cannot start {threads} render threads: {e}")))?;
    let (w, h) = (options.width, options.height);
    let mut tiles = Vec::new();
    for y0 in (0..h).step_by(TILE) {
        for x0 in (0..w).step_by(TILE) {
            tiles.push((x0, y0, TILE.min(w - x0), TILE.min(h - y0)));
        }
    }
    progress.start((w * h) as u64);
    let out = pool.install(|| {
        let single = options.cache.mode == CacheMode::Single;
        let mut tracer = match cache {
            Some(c) => Tracer::with_cache(scene, c, single, options.tess_factor),
            None => Tracer::new(scene, options.cache, options.tess_factor),
        };
        tracer.set_incoherent_tess_factor(options.tess_factor_incoherent);
        let cache_before = tracer.cache.stats();
        let fx = effects::analyze(scene, options);
        let motion_blur = effects::enabled(&fx, "motion_blur");
        let integrator = DirectLighting::new(&tracer, scene, &fx, options);
        let results: Vec<Option<TileResult>> = tiles
            .par_iter()
            .map(|&tile| {
                if progress.cancelled() {
                    return None;
                }
                let r = render_tile(&integrator, options, tile, motion_blur);
                progress.advance((tile.2 * tile.3) as u64);
                Some(r)
            })
            .collect();
        if results.iter().any(Option::is_none) {
            return Err(RenderError::Cancelled);
        }
        let mut film = Film::new(w, h, &options.aovs);
        let mut counters = TraceCounters::default();
        let mut dropped = 0;
        for r in results.into_iter().flatten() {
            counters.add(&r.counters);
            dropped += r.dropped;
            write_tile(&mut film, &r);
        }
        if dropped > 0 {
            log::warn!("dropped {dropped} non-finite samples");
        }
        let figures = RenderFigures {
            wall_s: start.elapsed().as_secs_f64(),
            threads,
            dropped_samples: dropped,
            width: w,
            height: h,
            samples: options.samples,
        };
        let control_faces = scene.meshes.iter().map(|m| m.surface.control_face_count()).sum();
        let stats = collect(&tracer, &counters, &fx, &figures, control_faces, scene.instances.len(), &cache_before);
        Ok(RenderOutput { film, stats })
    });
    progress.finish();
    out
}

/// Renders one tile: every sample of every pixel, averaged. Colour averages over samples;
/// depth, normal and ids come from sample 0 (the pixel centre), so they are never blends of two
/// surfaces.
/// With `motion_blur`, each camera sample gets a time within the shutter that all its rays share.
fn render_tile(integrator: &dyn Integrator, options: &RenderOptions, tile: Tile, motion_blur: bool) -> TileResult {
    let (x0, y0, tw, th) = tile;
    let mut counters = TraceCounters::default();
    let mut values = Vec::with_capacity(tw * th);
    let mut dropped = 0;
    let spp = options.samples;
    let cam = &integrator.scene().camera;
    let dof = integrator.depth_of_field();
    for y in y0..y0 + th {
        for x in x0..x0 + tw {
            let pixel = (y * options.width + x) as u64;
            let mut acc = glam::Vec3A::ZERO;
            let mut alpha = 0.0;
            let mut ao = 0.0;
            let mut n_ok = 0u32;
            let mut first = SampleValue::default();
            for s in 0..spp {
                let mut sampler = Sampler::new(options.seed, pixel, s as u64);
                let (jx, jy) = if s == 0 { (0.5, 0.5) } else { (sampler.next_f32(), sampler.next_f32()) };
                let mut ray = if dof {
                    let lens = (sampler.next_f32(), sampler.next_f32());
                    cam.generate_ray_lens(x as f32 + jx, y as f32 + jy, options.width, options.height, lens)
                } else {
                    cam.generate_ray(x as f32 + jx, y as f32 + jy, options.width, options.height)
                };
                ray.diff.scale(1.0 / (spp as f32).sqrt());
                if motion_blur {
                    // Stratified over the pixel's samples, jittered within each stratum.
                    ray.time = (s as f32 + sampler.next_f32()) / spp as f32;
                }
                let v = integrator.sample(&ray, &mut sampler, &mut counters);
                if s == 0 {
                    first = v;
                }
                if v.color.is_finite() && v.alpha.is_finite() {
                    acc += v.color;
                    alpha += v.alpha;
                    ao += v.ao;
                    n_ok += 1;
                } else {
                    dropped += 1;
                }
            }
            let mut v = first;
            let inv = if n_ok > 0 { 1.0 / n_ok as f32 } else { 0.0 };
            v.color = acc * inv;
            v.alpha = alpha * inv;
            v.ao = ao * inv;
            if !(v.depth.is_finite() && v.normal.is_finite() && v.beam_width.is_finite() && v.tess_error.iter().all(|e| e.is_finite())) {
                v.tess_error = [0.0; 2];
                dropped += 1;
                v.depth = cam.clipping_range.1;
                v.normal = glam::Vec3A::ZERO;
                v.beam_width = 0.0;
            }
            values.push(v);
        }
    }
    TileResult { tile, values, counters, dropped }
}

fn write_tile(film: &mut Film, r: &TileResult) {
    let (x0, y0, tw, th) = r.tile;
    let width = film.width;
    for aov in &mut film.aovs {
        for ty in 0..th {
            for tx in 0..tw {
                let v = &r.values[ty * tw + tx];
                let dst = ((y0 + ty) * width + x0 + tx) * aov.channels;
                let px = &mut aov.data[dst..dst + aov.channels];
                match aov.name.as_str() {
                    "color" => px.copy_from_slice(&v.color.to_array()),
                    "alpha" => px[0] = v.alpha,
                    "depth" => px[0] = v.depth,
                    "normal" => px.copy_from_slice(&v.normal.to_array()),
                    "primId" => px[0] = v.prim_id,
                    "instanceId" => px[0] = v.instance_id,
                    "beamWidth" => px[0] = v.beam_width,
                    "ao" => px[0] = v.ao,
                    "tessError" => px.copy_from_slice(&v.tess_error),
                    "tessRate" => px[0] = v.tess_rate,
                    _ => {}
                }
            }
        }
    }
}
