//! The one entry point: `render(scene, options, progress)`. Tiles of pixels are rendered in
//! parallel (rayon); every random number depends only on (seed, pixel, sample), so the image is
//! the same with any thread count.
//!
//! A render is one or more passes over the image. Without `progressive` there is one pass of
//! `samples` samples per pixel; with it, passes of 1, 2, 4, … samples per pixel up to
//! `samples`, each reported through [`Progress::pass_finished`] with the image so far. Each
//! pixel's samples are numbered 0, 1, … across passes and summed in that order into sums kept
//! between passes, and every sample's ray differential is scaled for the final sample count, so
//! the last pass's image is bit-identical to the one-pass image with the same seed.
//!
//! Within a pass the render threads take tiles from one queue in image order (odd passes in
//! reverse), so they work on neighbouring tiles and share the geometry cache's tessellations,
//! the coherence the paper's cache relies on (measured on `examples/subdiv_showcase.usda`,
//! 2 threads: 25 % fewer cache misses than rayon splitting the image into halves).

use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use serde_json::Value;

use crate::effects;
use crate::error::RenderError;
use crate::film::Film;
use crate::geometry_cache::{CacheMode, GeometryCache};
use crate::integrator::{select, Integrator, SampleValue};
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

/// One tile's samples so far, kept between passes.
struct TileState {
    tile: Tile,
    /// Per pixel: sample 0's values (depth, normal, ids: never blends of two surfaces), with the
    /// averaged AOVs (colour, alpha, ao) holding their sums over the finite samples so far.
    /// Empty before the tile's first pass and after its last.
    sums: Vec<SampleValue>,
    /// Per pixel: finite samples summed.
    n_ok: Vec<u32>,
    counters: TraceCounters,
    /// Non-finite samples dropped so far.
    dropped: u64,
}

/// One pass over one tile: every pixel's values so far, averaged.
struct TileResult {
    tile: Tile,
    values: Vec<SampleValue>,
    /// Pixels whose non-averaged AOVs were non-finite and were reset.
    dropped: u64,
}

/// The passes of a render, as ranges of sample indices: `0..samples`, or with `progressive`
/// `0..1, 1..2, 2..4, 4..8, …` ending at `samples`.
pub fn passes(samples: u32, progressive: bool) -> Vec<Range<u32>> {
    let mut out = Vec::new();
    let mut done = 0;
    while done < samples {
        let next = match (progressive, done) {
            (false, _) => samples,
            (true, 0) => 1,
            (true, _) => (done * 2).min(samples),
        };
        out.push(done..next);
        done = next;
    }
    out
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
    crate::film::check_film_memory(options.width, options.height, &options.aovs)?;
    let start = Instant::now();
    let threads = if options.threads == 0 { std::thread::available_parallelism().map_or(1, |n| n.get()) } else { options.threads };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        // Named, so a profile (docs/throughput.md's) can tell the render's threads from the host's.
        .thread_name(|i| format!("mipray-render-{i}"))
        .build()
        .map_err(|e| RenderError::Settings(format!("cannot start {threads} render threads: {e}")))?;
    let (w, h) = (options.width, options.height);
    // Only the crop window's pixels are rendered; each keeps its whole-frame coordinates (its
    // rays and its samples' seeds), so a window's pixels are the whole frame's bit for bit.
    let window = options.data_window();
    let mut tiles = Vec::new();
    for y0 in window.y.clone().step_by(TILE) {
        for x0 in window.x.clone().step_by(TILE) {
            tiles.push((x0, y0, TILE.min(window.x.end - x0), TILE.min(window.y.end - y0)));
        }
    }
    progress.start((window.width() * window.height()) as u64 * u64::from(options.samples));
    let out = pool.install(|| {
        if progress.cancelled() {
            return Err(RenderError::Cancelled);
        }
        let single = options.cache.mode == CacheMode::Single;
        let cache = cache.unwrap_or_else(|| Arc::new(GeometryCache::new(options.cache)));
        let budget = options.geometry_memory_mb.is_finite().then_some((options.geometry_memory_mb * 1e6) as usize);
        let mut tracer = Tracer::with_budget(scene, cache, single, options.tess_factor, budget).map_err(RenderError::Settings)?;
        tracer.set_incoherent_tess_factor(options.tess_factor_incoherent);
        tracer.set_seams(options.seams);
        tracer.set_displacement_rate_floor(options.displacement_rate_floor);
        let cache_before = tracer.cache.stats();
        // The BVH over a large scene takes a while: a cancel during it is seen here.
        if progress.cancelled() {
            return Err(RenderError::Cancelled);
        }
        let fx = select::effects(scene, options);
        let motion_blur = effects::enabled(&fx, "motion_blur");
        let integrator = select::select(&tracer, scene, &fx, options)?;
        // E.g. the irradiance cache's records: made once, before any pixel, in a fixed order.
        let prepass_counters = integrator.prepass(options, progress)?;
        let mut failures = tracer.dropped.failures();
        let (film, states, reset) = loop {
            let mut states: Vec<TileState> = tiles
                .iter()
                .map(|&tile| TileState { tile, sums: Vec::new(), n_ok: Vec::new(), counters: TraceCounters::default(), dropped: 0 })
                .collect();
            let mut film = Film::new(window.width(), window.height(), &options.aovs);
            let mut reset = 0;
            for (pass, samples) in passes(options.samples, options.progressive).into_iter().enumerate() {
                if progress.cancelled() {
                    return Err(RenderError::Cancelled);
                }
                // Odd passes run the tiles backwards, so a pass starts where the last one ended,
                // on the geometry the cache still holds.
                let results =
                    render_pass(integrator.as_ref(), options, &mut states, samples.clone(), pass % 2 == 1, motion_blur, threads, progress)?;
                reset = 0;
                for r in &results {
                    reset += r.dropped;
                    write_tile(&mut film, r, (window.x.start, window.y.start));
                }
                progress.pass_finished(samples.end, &film);
            }
            // A prim whose work panicked was in some pixels and not in others: render again
            // without it (rays skip it from now on) so that it is left out of every pixel alike.
            // Each round drops at least one more mesh, so this ends.
            let now = tracer.dropped.failures();
            if now == failures {
                break (film, states, reset);
            }
            failures = now;
        };
        let mut counters = prepass_counters;
        let mut dropped = reset;
        for s in &states {
            counters.add(&s.counters);
            dropped += s.dropped;
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
        let mut stats = collect(&tracer, &counters, &fx, &figures, control_faces, scene.instances.len(), &cache_before);
        if let Some(obj) = stats.as_object_mut() {
            if let Some(ic) = integrator.cache_stats() {
                obj.insert("irradiance_cache".into(), ic);
            }
            let left_out = tracer.dropped.list();
            obj.insert("dropped_prims".into(), Value::from(left_out.iter().map(ToString::to_string).collect::<Vec<_>>()));
            obj.insert("internal_errors".into(), Value::from(left_out.iter().filter(|d| d.internal).count()));
            if let Some(Value::Object(render)) = obj.get_mut("render") {
                // The pixels rendered, in whole-frame pixels: [x0, y0, x1, y1), row 0 at the top.
                render.insert("data_window".into(), serde_json::json!([window.x.start, window.y.start, window.x.end, window.y.end]));
            }
        }
        Ok(RenderOutput { film, stats })
    });
    progress.finish();
    out
}

/// One pass: samples `samples` of every tile, by `threads` workers taking the tiles in order
/// (reversed with `backwards`) from one queue, so they work side by side on neighbouring tiles
/// and share the geometry cache's tessellations (the paper's coherence), instead of each
/// sweeping its own part of the image. `None` when `progress` cancels. Which thread renders a
/// tile changes nothing: every sample's random numbers depend on (seed, pixel, sample) only.
#[allow(clippy::too_many_arguments)]
fn render_pass(
    integrator: &dyn Integrator,
    options: &RenderOptions,
    states: &mut [TileState],
    samples: Range<u32>,
    backwards: bool,
    motion_blur: bool,
    threads: usize,
    progress: &dyn Progress,
) -> Result<Vec<TileResult>, RenderError> {
    let n = states.len();
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    // A panic outside any one prim's ray tests (those are isolated per prim by the tracer): the
    // render stops with one error line rather than unwinding into the caller (a Python host).
    let panicked: Mutex<Option<String>> = Mutex::new(None);
    // One lock per tile, never contended: the queue hands each tile to one worker.
    let cells: Vec<Mutex<(&mut TileState, Option<TileResult>)>> = states.iter_mut().map(|s| Mutex::new((s, None))).collect();
    rayon::scope(|scope| {
        for _ in 0..threads.clamp(1, n.max(1)) {
            scope.spawn(|_| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                if k >= n || stop.load(Ordering::Relaxed) || progress.cancelled() {
                    break;
                }
                let i = if backwards { n - 1 - k } else { k };
                let mut cell = cells[i].lock().unwrap_or_else(PoisonError::into_inner);
                let (state, out) = &mut *cell;
                let tile = std::panic::AssertUnwindSafe(|| render_tile(integrator, options, state, samples.clone(), motion_blur, progress));
                match std::panic::catch_unwind(tile) {
                    Ok(Some(r)) => {
                        progress.advance((state.tile.2 * state.tile.3) as u64 * u64::from(samples.end - samples.start));
                        *out = Some(r);
                    }
                    Ok(None) => stop.store(true, Ordering::Relaxed),
                    Err(payload) => {
                        let (x, y, _, _) = state.tile;
                        let message = format!("tile at pixel ({x}, {y}): {}", crate::dropped::panic_message(payload.as_ref()));
                        panicked.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert(message);
                        stop.store(true, Ordering::Relaxed);
                    }
                }
            });
        }
    });
    if let Some(message) = panicked.into_inner().unwrap_or_else(PoisonError::into_inner) {
        return Err(RenderError::Internal(message));
    }
    cells.into_iter().map(|c| c.into_inner().unwrap_or_else(PoisonError::into_inner).1).collect::<Option<_>>().ok_or(RenderError::Cancelled)
}

/// Renders samples `samples` of every pixel of a tile into its running sums and returns the
/// averages so far; `None` when `progress` cancels. Colour, alpha and ao average over the
/// finite samples; depth, normal and ids come from sample 0 (the pixel centre), so they are
/// never blends of two surfaces. With `motion_blur`, each camera sample gets a time within the
/// shutter that all its rays share.
fn render_tile(
    integrator: &dyn Integrator,
    options: &RenderOptions,
    state: &mut TileState,
    samples: Range<u32>,
    motion_blur: bool,
    progress: &dyn Progress,
) -> Option<TileResult> {
    let (x0, y0, tw, th) = state.tile;
    if state.sums.is_empty() {
        state.sums = vec![SampleValue::default(); tw * th];
        state.n_ok = vec![0; tw * th];
    }
    let mut values = Vec::with_capacity(tw * th);
    let mut dropped = 0;
    // The final count, whatever the pass: each sample's beam is its share of the pixel in the
    // finished image, so tessellation rates (and so the image) do not depend on the passes.
    let spp = options.samples;
    let cam = &integrator.scene().camera;
    let dof = integrator.depth_of_field();
    for y in y0..y0 + th {
        for x in x0..x0 + tw {
            // Per pixel, so that a slow pixel (many samples, deep paths) delays a cancel by one.
            if progress.cancelled() {
                return None;
            }
            let pixel = (y * options.width + x) as u64;
            let i = (y - y0) * tw + (x - x0);
            let sum = &mut state.sums[i];
            // What a geometry budget drops during the pixel stays readable until it ends.
            let _pin = crate::geometry_budget::pin();
            for s in samples.clone() {
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
                let v = integrator.sample(&ray, &mut sampler, &mut state.counters);
                if s == 0 {
                    // Sample 0 gives the non-averaged AOVs; the averaged ones start from zero.
                    *sum = v.without_averaged();
                }
                // A sample with any non-finite light AOV is dropped whole, so the parts still
                // add up to the colour.
                if v.averaged_finite() {
                    sum.add_averaged(&v);
                    state.n_ok[i] += 1;
                } else {
                    state.dropped += 1;
                }
            }
            let n_ok = state.n_ok[i];
            let inv = if n_ok > 0 { 1.0 / n_ok as f32 } else { 0.0 };
            let mut v = sum.averaged(inv);
            if !v.geometry_finite() {
                v.tess_error = [0.0; 2];
                dropped += 1;
                v.depth = cam.clipping_range.1;
                v.camera_depth = 0.0;
                v.peye = glam::Vec3A::ZERO;
                v.normal = glam::Vec3A::ZERO;
                v.neye = glam::Vec3A::ZERO;
                v.position = glam::Vec3A::ZERO;
                v.beam_width = 0.0;
            }
            values.push(v);
        }
    }
    if samples.end >= options.samples {
        // The tile is finished: free its sums (a one-pass render keeps one tile's at a time).
        state.sums = Vec::new();
        state.n_ok = Vec::new();
    }
    Some(TileResult { tile: state.tile, values, dropped })
}

/// Copies a tile into the film, whose pixel (0, 0) is the frame's pixel `origin`.
fn write_tile(film: &mut Film, r: &TileResult, origin: (usize, usize)) {
    let (x0, y0, tw, th) = r.tile;
    let (x0, y0) = (x0 - origin.0, y0 - origin.1);
    let width = film.width;
    for buffer in &mut film.aovs {
        let aov = buffer.aov;
        for ty in 0..th {
            for tx in 0..tw {
                let dst = ((y0 + ty) * width + x0 + tx) * buffer.channels;
                buffer.data[dst..dst + buffer.channels].copy_from_slice(r.values[ty * tw + tx].channels(aov));
            }
        }
    }
}
