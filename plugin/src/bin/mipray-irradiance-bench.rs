//! `mipray-irradiance-bench`: what the irradiance cache (the paper's §5.1) buys and costs, on a
//! scene this command builds — a Cornell-box-like room of Catmull-Clark objects — for ambient
//! occlusion and one-bounce color bleeding, against a high-sample uncached reference.
//!
//! ```text
//! cargo run --release -p hd-mipray --bin mipray-irradiance-bench -- --out docs/irradiance-cache
//! ```
//! (`make bench-irradiance`.) Writes `<out>.md` (the whole of docs/irradiance-cache.md) and
//! `<out>.json`. Every configuration is rendered `--runs` times (default 3): the wall time is
//! the median, and the images of the runs must be identical (the cache is deterministic).

use std::io::Write;
use std::sync::Arc;
use std::time::Instant;

use glam::{Mat4, Vec3, Vec3A};
use hd_mipray::bench_scene::blob_mesh;
use mipray::aov::Aov;
use mipray::bilinear::BilinearSurface;
use mipray::camera::Camera;
use mipray::integrator::hemisphere::{visible, Hemisphere, Visible};
use mipray::light::{Light, LightShape};
use mipray::material::Material;
use mipray::options::{IntegratorKind, RenderOptions};
use mipray::progress::NoProgress;
use mipray::render::{render, RenderOutput};
use mipray::scene::{Mesh, Scene};
use mipray::topology::{MeshTopology, Scheme};
use mipray::trace::{TraceCounters, Tracer};
use mipray_bridge::OsdSurface;
use serde_json::{json, Value};

/// The error bounds measured (`None`: the cache off).
const ERRORS: [Option<f32>; 5] = [None, Some(0.4), Some(0.2), Some(0.1), Some(0.05)];

struct Args {
    out: String,
    width: usize,
    height: usize,
    runs: usize,
    /// Hemisphere rays per shading point of the measured rows.
    rays: u32,
    /// Hemisphere rays per shading point of the uncached reference.
    reference_rays: u32,
    threads: usize,
}

fn usage() -> ! {
    eprintln!(
        "usage: mipray-irradiance-bench [--out PREFIX] [--width W] [--height H] [--runs N] [--rays N] [--reference-rays N] [--threads N]"
    );
    std::process::exit(2)
}

fn parse(args: &[String]) -> Args {
    let mut a = Args { out: "docs/irradiance-cache".into(), width: 240, height: 180, runs: 3, rays: 64, reference_rays: 1024, threads: 0 };
    let mut it = args.iter();
    while let Some(k) = it.next() {
        let mut v = || it.next().cloned().unwrap_or_else(|| usage());
        let mut num = || v().parse::<usize>().unwrap_or_else(|_| usage());
        match k.as_str() {
            "--out" => a.out = it.next().cloned().unwrap_or_else(|| usage()),
            "--width" => a.width = num(),
            "--height" => a.height = num(),
            "--runs" => a.runs = num().max(1),
            "--rays" => a.rays = num() as u32,
            "--reference-rays" => a.reference_rays = num() as u32,
            "--threads" => a.threads = num(),
            _ => usage(),
        }
    }
    a
}

fn quad(corners: [[f32; 3]; 4]) -> Arc<BilinearSurface> {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    Arc::new(BilinearSurface::new(&topo, &corners).expect("a valid quad"))
}

/// The room: floor, ceiling and back wall white, left wall red, right wall green (2 × 2 × 2,
/// open toward the camera), a rect light under the ceiling, and three Catmull-Clark blobs on
/// the floor — one of them close to the red wall, so its shadowed side takes red light.
fn build_scene() -> Result<Scene, mipray::error::MeshError> {
    let mut scene = Scene::default();
    let white = Material::lambertian("/materials/white", Vec3A::splat(0.75)).0;
    let red = Material::lambertian("/materials/red", Vec3A::new(0.7, 0.1, 0.08)).0;
    let green = Material::lambertian("/materials/green", Vec3A::new(0.1, 0.6, 0.12)).0;
    let yellow = Material::lambertian("/materials/yellow", Vec3A::new(0.8, 0.7, 0.3)).0;
    let walls: [(&str, [[f32; 3]; 4], &Material); 5] = [
        ("/room/floor", [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 2.0, 0.0], [-1.0, 2.0, 0.0]], &white),
        ("/room/ceiling", [[-1.0, 0.0, 2.0], [-1.0, 2.0, 2.0], [1.0, 2.0, 2.0], [1.0, 0.0, 2.0]], &white),
        ("/room/back", [[-1.0, 2.0, 0.0], [1.0, 2.0, 0.0], [1.0, 2.0, 2.0], [-1.0, 2.0, 2.0]], &white),
        ("/room/left", [[-1.0, 0.0, 0.0], [-1.0, 2.0, 0.0], [-1.0, 2.0, 2.0], [-1.0, 0.0, 2.0]], &red),
        ("/room/right", [[1.0, 0.0, 0.0], [1.0, 0.0, 2.0], [1.0, 2.0, 2.0], [1.0, 2.0, 0.0]], &green),
    ];
    for (name, corners, material) in walls {
        let m = scene.add_material(material.clone());
        let mut mesh = Mesh::new(name, quad(corners));
        mesh.material = m;
        let i = scene.add_mesh(mesh);
        scene.add_instance(i, Mat4::IDENTITY);
    }
    let blobs = [
        ("/objects/blob_a", 11u64, Vec3::new(-0.62, 1.15, 0.36), Vec3::new(0.34, 0.34, 0.36), &white),
        ("/objects/blob_b", 23, Vec3::new(0.35, 1.35, 0.55), Vec3::new(0.3, 0.3, 0.55), &yellow),
        ("/objects/blob_c", 37, Vec3::new(0.15, 0.55, 0.2), Vec3::new(0.22, 0.22, 0.2), &white),
    ];
    for (name, seed, at, scale, material) in blobs {
        let (topo, pts) = blob_mesh(4, seed);
        let m = scene.add_material(material.clone());
        let mut mesh = Mesh::new(name, Arc::new(OsdSurface::new(name, &topo, &pts)?));
        mesh.material = m;
        let i = scene.add_mesh(mesh);
        scene.add_instance(i, Mat4::from_translation(at) * Mat4::from_scale(scale));
    }
    let light = LightShape::Rect { center: Vec3A::new(0.0, 1.0, 1.98), u: Vec3A::X * 0.3, v: Vec3A::Y * 0.3, normal: Vec3A::NEG_Z };
    scene.lights.push(Light::usd_area("/lights/ceiling", light, 12.0, 0.0, Vec3A::ONE, false));
    scene.camera = Camera {
        // Slightly off the room's symmetry plane, so no pixel centre lands exactly on the edge
        // between two walls (a point on two surfaces at once, whose hemisphere is ill-defined).
        render_from_camera: Camera::look_at(Vec3::new(0.0137, -2.3, 1.0123), Vec3::new(0.0137, 1.0, 1.0123), Vec3::Z),
        focal_length: 35.0,
        horizontal_aperture: 36.0,
        vertical_aperture: 27.0,
        clipping_range: (0.1, 1e4),
        ..Default::default()
    };
    Ok(scene)
}

/// What a row compares: the `ao` AOV for ambient occlusion, the colour (RGB) for color
/// bleeding.
fn image(out: &RenderOutput, kind: IntegratorKind) -> Vec<f32> {
    let aov = if kind == IntegratorKind::Ao { "ao" } else { "color" };
    out.film.aov(aov).map(|a| a.data.clone()).unwrap_or_default()
}

fn rmse_and_max(a: &[f32], b: &[f32]) -> (f64, f64) {
    let mut s = 0.0;
    let mut m: f64 = 0.0;
    for (x, y) in a.iter().zip(b) {
        let d = (f64::from(*x) - f64::from(*y)).abs();
        s += d * d;
        m = m.max(d);
    }
    ((s / a.len().max(1) as f64).sqrt(), m)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn options(a: &Args, kind: IntegratorKind, rays: u32, error: Option<f32>) -> RenderOptions {
    let mut o = RenderOptions {
        width: a.width,
        height: a.height,
        samples: 1,
        threads: a.threads,
        integrator: kind,
        shadow_samples: 4,
        aovs: vec![Aov::Color, Aov::Ao],
        irradiance_cache: error.is_some(),
        irradiance_cache_error: error.unwrap_or(0.2),
        ..Default::default()
    };
    if kind == IntegratorKind::Ao {
        o.ao_samples = rays;
        o.ao_distance = 0.6;
    } else {
        o.indirect_samples = rays;
    }
    o
}

fn rays_of(out: &RenderOutput, kind: &str) -> u64 {
    out.stats["render"]["rays"][kind].as_u64().unwrap_or(0)
}

/// One integrator's rows: reference, then each error bound `runs` times. Returns the figures
/// and the reference image.
fn measure(a: &Args, scene: &Scene, kind: IntegratorKind) -> (Value, Vec<f32>) {
    let (quantity, ray_kind) = if kind == IntegratorKind::Ao { ("occlusion", "ao") } else { ("irradiance", "diffuse") };
    eprintln!("{}: reference, {} rays per shading point …", kind.name(), a.reference_rays);
    let t = Instant::now();
    let reference = render(scene, &options(a, kind, a.reference_rays, None), &NoProgress).unwrap_or_else(|e| {
        eprintln!("mipray-irradiance-bench: reference: {e}");
        std::process::exit(1)
    });
    let reference_s = t.elapsed().as_secs_f64();
    let ref_img = image(&reference, kind);
    let pixels = (a.width * a.height) as f64;
    let mut rows = Vec::new();
    for error in ERRORS {
        let mut walls = Vec::new();
        let mut first: Option<(RenderOutput, Vec<f32>)> = None;
        for run in 0..a.runs {
            eprint!(
                "\r{}: irradianceCacheError {} run {}/{}   ",
                kind.name(),
                error.map_or("off".into(), |e| e.to_string()),
                run + 1,
                a.runs
            );
            let _ = std::io::stderr().flush();
            let t = Instant::now();
            let out = render(scene, &options(a, kind, a.rays, error), &NoProgress).unwrap_or_else(|e| {
                eprintln!("mipray-irradiance-bench: {e}");
                std::process::exit(1)
            });
            walls.push(t.elapsed().as_secs_f64());
            let img = image(&out, kind);
            match &first {
                None => first = Some((out, img)),
                Some((_, f)) => {
                    if f.iter().zip(&img).any(|(x, y)| x.to_bits() != y.to_bits()) {
                        eprintln!("mipray-irradiance-bench: run {} of error {error:?} differs from run 1: not deterministic", run + 1);
                        std::process::exit(1);
                    }
                }
            }
        }
        eprintln!();
        let (out, img) = first.expect("at least one run");
        let (rmse, max) = rmse_and_max(&img, &ref_img);
        let ic = &out.stats["irradiance_cache"][quantity];
        let hemi = rays_of(&out, ray_kind);
        rows.push(json!({
            // Through its decimal form, so 0.4 is written 0.4 and not as the nearest f32.
            "irradiance_cache_error": error.map(|e| e.to_string().parse::<f64>().unwrap_or(f64::from(e))),
            "wall_s_median": median(walls.clone()),
            "wall_s_runs": walls,
            "records": ic["records"].as_u64().unwrap_or(0),
            "prepass_s": ic["prepass_s"].as_f64().unwrap_or(0.0),
            "interpolated": ic["interpolated"].as_u64().unwrap_or(0),
            "lookups": ic["lookups"].as_u64().unwrap_or(0),
            "hemisphere_rays": hemi,
            "hemisphere_rays_per_pixel": hemi as f64 / pixels,
            "shadow_rays": rays_of(&out, "shadow"),
            "rmse": rmse,
            "max_abs_error": max,
        }));
    }
    let figures = json!({
        "integrator": kind.name(),
        "compared": if kind == IntegratorKind::Ao { "ao AOV" } else { "color (RGB)" },
        "rays_per_shading_point": a.rays,
        "reference_rays_per_shading_point": a.reference_rays,
        "reference_s": reference_s,
        "reference_hemisphere_rays": rays_of(&reference, ray_kind),
        "rows": rows,
    });
    (figures, ref_img)
}

fn table(m: &Value) -> String {
    let rows = m["rows"].as_array().cloned().unwrap_or_default();
    let base = rows.first().and_then(|r| r["wall_s_median"].as_f64()).unwrap_or(f64::NAN);
    let base_rays = rows.first().and_then(|r| r["hemisphere_rays"].as_f64()).unwrap_or(f64::NAN);
    let mut s = String::from(
        "| irradianceCacheError | wall s (median) | speed-up | records | hemisphere rays | per pixel | interpolated | RMSE | max error |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let lookups = r["lookups"].as_f64().unwrap_or(0.0);
        let interp =
            if lookups > 0.0 { format!("{:.1}%", 100.0 * r["interpolated"].as_f64().unwrap_or(0.0) / lookups) } else { "—".into() };
        let wall = r["wall_s_median"].as_f64().unwrap_or(f64::NAN);
        let rays = r["hemisphere_rays"].as_f64().unwrap_or(f64::NAN);
        s += &format!(
            "| {} | {:.2} | {:.2}× | {} | {} ({:.1}%) | {:.1} | {} | {:.4} | {:.3} |\n",
            r["irradiance_cache_error"].as_f64().map_or("off".into(), |e| format!("{e}")),
            wall,
            base / wall,
            r["records"],
            r["hemisphere_rays"],
            100.0 * rays / base_rays,
            r["hemisphere_rays_per_pixel"].as_f64().unwrap_or(0.0),
            interp,
            r["rmse"].as_f64().unwrap_or(f64::NAN),
            r["max_abs_error"].as_f64().unwrap_or(f64::NAN),
        );
    }
    s
}

/// The reference's own share of every row's RMSE: per-pixel variance goes as σ²/N, so the
/// uncached row's RMSE² ≈ σ²/N + σ²/N_ref, and the reference's part, σ/√N_ref, is
/// RMSE_off · √(N/(N + N_ref)).
fn reference_noise(m: &Value) -> f64 {
    let off = m["rows"][0]["rmse"].as_f64().unwrap_or(f64::NAN);
    let n = m["rays_per_shading_point"].as_f64().unwrap_or(1.0);
    let n_ref = m["reference_rays_per_shading_point"].as_f64().unwrap_or(1.0);
    // off² = s²/n + s²/n_ref  ⇒  s²/n_ref = off² · n / (n + n_ref).
    off * (n / (n + n_ref)).sqrt()
}

fn markdown(a: &Args, ao: &Value, cb: &Value, grads: &Value) -> String {
    let cmd = "cargo run --release -p hd-mipray --bin mipray-irradiance-bench -- --out docs/irradiance-cache";
    format!(
        r#"# Irradiance and occlusion caching: what it buys and costs

Generated by `make bench-irradiance` (`{cmd}`); do not edit by hand. The numbers below are from
one run on the project's build machine (2 render threads on 2 cores shared with other work, so
wall times carry noise: each is the median of {runs} runs, and the speed-up is the uncached
row's median over the row's; the runs' images were checked to be bit-identical).

## What is measured

The paper's §5.1: "to avoid hemisphere sampling from all shading points, we use interpolation of
irradiance using irradiance gradients and, similarly, interpolation of ambient occlusion using
occlusion gradients". mipray's cache (`rust/src/irradiance_cache.rs`) follows Ward, Rubinstein &
Clear (1988) with Ward & Heckbert's (1992) translational and rotational gradients:

- a **record** is a hemisphere integral computed at a point from M × N stratified
  cosine-weighted rays (here {rays} rays: the `aoSamples` / `indirectSamples` setting), with the
  harmonic mean R of its hit distances, limited by the gradient (R ≤ value/‖∇ₜ‖), clamped so the
  validity radius a·R is 1–32 pixel footprints, and clamped against its neighbours
  (Rᵢ ≤ Rⱼ + ‖pᵢ − pⱼ‖, Křivánek et al. 2006);
- a record is **valid** at (p, n) when Ward's error estimate ‖p − pᵢ‖/Rᵢ + √(1 − n·nᵢ) is below
  the error bound a (`irradianceCacheError`), and the value there is the weighted mean of the
  valid records' values extrapolated with their gradients; where none is valid the hemisphere is
  sampled directly, as without the cache;
- the records are made by a **deterministic pre-pass** before any pixel is rendered: camera
  rays through the pixel centres, coarse to fine (every 32nd pixel, then 16th, … then every
  pixel), a record wherever the records of the earlier phases do not cover the point; the
  render pass only reads the cache. The image is a function of the seed, the same with any
  thread count.

PRMan interpolates on REYES micropolygon grids, whose points are known to lie on one surface; a
ray tracer's shading points are disconnected points in 3-D, so mipray interpolates in 3-D, with
Ward's error metric deciding which records belong together.

**Scene** (built by the command): a Cornell-box-like room 2 × 2 × 2 — white
floor, ceiling and back wall, red left wall, green right wall, open toward the camera — with
three Catmull-Clark blobs (OpenSubdiv) on the floor, one close to the red wall, and a rect light
under the ceiling. {w} × {h} pixels, one camera ray per pixel (the pixel centre, the same in
every row, so the comparison isolates the hemisphere integrals), 4 shadow samples.

**Reference**: the same render without the cache and with {ref_rays} hemisphere rays per shading
point. **Rows**: {rays} rays per shading point, the cache off and at a = 0.4, 0.2, 0.1, 0.05.
RMSE and max error are over all pixels (and channels), against the reference. "Hemisphere rays"
are the `render.rays.ao` (AO) or `render.rays.diffuse` (color bleeding) counts, pre-pass
included; "interpolated" is the share of the render pass's cache lookups that found a valid
record (the rest sampled the hemisphere).

## Ambient occlusion (`integrator = ao`, `aoDistance` 0.6; the `ao` AOV compared)

{ao_table}
Reference: {ao_ref_s:.1} s. Its own noise accounts for an RMSE of about {ao_noise:.4} in every
row (estimated from the uncached row: the two noises add in quadrature in proportion 1/N).

## One-bounce color bleeding (`integrator = colorBleeding`; the colour compared)

{cb_table}
Reference: {cb_ref_s:.1} s; its noise accounts for an RMSE of about {cb_noise:.4}. The direct light
uses the same random numbers in every row and in the reference (it is computed before the
bounce from the same per-pixel stream), so the differences are the indirect light's alone.

## Reading the tables

- **Time.** The cache replaces {rays} hemisphere rays per pixel by a few rays per record; the
  records are few where the integral is smooth (open floor, walls) and dense in corners and
  contact shadows, where the harmonic mean distance is small. The remaining cost is the camera
  rays, direct light, the pre-pass's coverage tests and the interpolation itself.
- **Error.** Without the cache the error is noise, √(1/N) per pixel. With it, the noise is
  traded for interpolation error: smooth, low-frequency, and bounded by a (Ward's a is roughly the
  relative error a record may have where it is used). Small a makes more records and approaches
  the uncached image; large a smooths contact shadows away. The RMSE against the reference can
  be *lower* with the cache than without: a pixel's value is a weighted mean of several records
  of {rays} rays each, so its noise averages down, and what remains is smooth, low-frequency
  error rather than per-pixel noise.

## Gradients on and off

The same occlusion caches as above, read at every pixel centre with the records' gradients and
without them (the constant value of each record, Ward's 1988 cache), against the reference;
over the pixels where a record is valid.

{grad_table}
The tests (`rust/tests/irradiance_cache.rs`) check the same against closed forms: a single
record's extrapolation error beside a wall, and a whole cache's interpolation error there, fall
with gradients on.

## Settings and stats

`irradianceCache` (0 or 1, default 0) turns the cache on for the `ao` integrator, for the ambient
occlusion of the classic integrator (`auto` with `aoSamples` > 0), and for the bounce of
`colorBleeding`; `irradianceCacheError` is a (default 0.2). `mipray-sweep` sweeps both knobs (its
`auto` reference renders without the cache). A render with the cache on reports, per cached
quantity (`occlusion`, `irradiance`), `irradiance_cache.<quantity>.{{error_bound, gradients,
records, prepass_points, prepass_rays, prepass_s, lookups, interpolated, fallbacks}}` in its stats
JSON; the pre-pass's rays are counted in `render.rays.*` too.

Raw figures: `docs/irradiance-cache.json`.
"#,
        cmd = cmd,
        runs = a.runs,
        rays = a.rays,
        ref_rays = a.reference_rays,
        w = a.width,
        h = a.height,
        grad_table = gradient_table(grads),
        ao_table = table(ao),
        cb_table = table(cb),
        ao_ref_s = ao["reference_s"].as_f64().unwrap_or(f64::NAN),
        cb_ref_s = cb["reference_s"].as_f64().unwrap_or(f64::NAN),
        ao_noise = reference_noise(ao),
        cb_noise = reference_noise(cb),
    )
}

/// What the gradients buy: for each error bound, the occlusion cache the AO rows used, read
/// at every pixel centre with and without gradients, RMSE against the reference's `ao`.
fn gradients(a: &Args, scene: &Scene, reference: &[f32]) -> Value {
    let mut rows = Vec::new();
    for error in ERRORS.into_iter().flatten() {
        let o = options(a, IntegratorKind::Ao, a.rays, Some(error));
        let tracer = Tracer::new(scene, o.cache, o.tess_factor);
        let mut hemi = Hemisphere::new(o.ao_samples, &o);
        if let Err(e) = hemi.prepass(&tracer, scene, &o, &NoProgress) {
            eprintln!("mipray-irradiance-bench: {e}");
            std::process::exit(1)
        }
        let mut counters = TraceCounters::default();
        let points: Vec<(usize, Visible)> = (0..a.width * a.height)
            .filter_map(|px| {
                let ray = scene.camera.generate_ray((px % a.width) as f32 + 0.5, (px / a.width) as f32 + 0.5, a.width, a.height);
                visible(&tracer, scene, ray, None, &mut counters).map(|v| (px, v))
            })
            .collect();
        let mut rmse = [0.0f64; 2];
        let mut n = 0usize;
        for (k, gradients) in [true, false].into_iter().enumerate() {
            let cache = hemi.cache_mut().expect("the pre-pass made the cache");
            cache.gradients = gradients;
            let (mut se, mut count) = (0.0f64, 0usize);
            for (px, v) in &points {
                if let Some(x) = cache.interpolate(v.sp.p, v.sp.ns) {
                    se += (f64::from(x.x) - f64::from(reference[*px])).powi(2);
                    count += 1;
                }
            }
            rmse[k] = (se / count.max(1) as f64).sqrt();
            n = count;
        }
        rows.push(json!({
            "irradiance_cache_error": error.to_string().parse::<f64>().unwrap_or(f64::from(error)),
            "records": hemi.cache().map_or(0, |c| c.records().len()),
            "pixels": n,
            "rmse_with_gradients": rmse[0],
            "rmse_without_gradients": rmse[1],
        }));
    }
    Value::Array(rows)
}

fn gradient_table(g: &Value) -> String {
    let mut s =
        String::from("| irradianceCacheError | records | pixels | RMSE with gradients | without | ratio |\n|---|---|---|---|---|---|\n");
    for r in g.as_array().into_iter().flatten() {
        let (on, off) = (r["rmse_with_gradients"].as_f64().unwrap_or(f64::NAN), r["rmse_without_gradients"].as_f64().unwrap_or(f64::NAN));
        s += &format!("| {} | {} | {} | {on:.4} | {off:.4} | {:.2} |\n", r["irradiance_cache_error"], r["records"], r["pixels"], on / off);
    }
    s
}

fn main() {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let a = parse(&argv);
    let t = Instant::now();
    let scene = build_scene().unwrap_or_else(|e| {
        eprintln!("mipray-irradiance-bench: scene: {e}");
        std::process::exit(1)
    });
    let scene_s = t.elapsed().as_secs_f64();
    let (ao, ao_reference) = measure(&a, &scene, IntegratorKind::Ao);
    eprintln!("ao: gradients on and off …");
    let grads = gradients(&a, &scene, &ao_reference);
    let (cb, _) = measure(&a, &scene, IntegratorKind::ColorBleeding);
    let all = json!({"width": a.width, "height": a.height, "runs": a.runs, "scene_build_s": scene_s, "ao": ao, "color_bleeding": cb, "gradients": grads});
    let md = markdown(&a, &ao, &cb, &grads);
    for (path, text) in [(format!("{}.json", a.out), serde_json::to_string_pretty(&all).unwrap_or_default()), (format!("{}.md", a.out), md)]
    {
        if let Err(e) = std::fs::write(&path, text + "\n") {
            eprintln!("mipray-irradiance-bench: {path}: {e}");
            std::process::exit(1);
        }
        println!("{path}");
    }
}
