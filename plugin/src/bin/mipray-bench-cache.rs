//! `mipray-bench-cache`: reproduces the paper's §6.3.2 tables (single-resolution against
//! multiresolution geometry caching, budgets 1–100 MB) on a scene this project generates.
//!
//! ```text
//! cargo run --release -p hd-mipray --bin mipray-bench-cache -- --out docs/cache-benchmark
//! cargo run --release -p hd-mipray --bin mipray-bench-cache -- --scene latlong --out docs/cache-benchmark-latlong
//! ```
//! `--scene latlong` is issue 15's scene: lat-long blobs with valence-80 poles, faces about a
//! pixel on screen, half mirrors and a sun, 4 samples per pixel (its own defaults for the grid,
//! size and samples; later options override them).
//! Every configuration renders in its own process, so each peak RSS is its own. Writes
//! `<out>.json` and `<out>.md`; `scripts/plot_cache_bench.py` draws `<out>.png` from the JSON.

use std::io::Write;
use std::process::Command;
use std::time::Instant;

use hd_mipray::bench_scene::{build, BenchKind, BenchSceneSpec};
use mipray::aov::Aov;
use mipray::geometry_cache::CacheConfig;
use mipray::options::RenderOptions;
use mipray::progress::NoProgress;
use mipray::render::render;
use serde_json::{json, Value};

const BUDGETS_MB: [f64; 5] = [1.0, 3.0, 10.0, 30.0, 100.0];

struct Args {
    out: String,
    width: usize,
    height: usize,
    ao: u32,
    runs: usize,
    /// Runs of each `single` configuration: only its recomputed vertices (the same every run)
    /// enter a target, and one run of it at 1 MB takes minutes.
    single_runs: usize,
    grid: (usize, usize),
    face_res: usize,
    /// The render's tessFactor (1: quads as wide as the beam).
    tess_factor: f32,
    /// Only these configurations, e.g. `unbounded,multires:30` (default: all eleven).
    configs: Option<Vec<(String, f64)>>,
    /// The objects: cube-sphere blobs under AO (the paper's §6.3.2) or lat-long blobs.
    kind: BenchKind,
    /// Samples per pixel.
    spp: u32,
}

fn usage() -> ! {
    eprintln!("usage: mipray-bench-cache [--out PREFIX] [--width W] [--height H] [--ao N] [--runs N] [--single-runs N] [--grid X,Y] [--face-res N] [--tess-factor F] [--configs MODE:MB,...] [--scene cubes|latlong] [--spp N]\n       mipray-bench-cache run MODE MB RAWFILE [same options]   (one configuration; prints stats JSON)\n       mipray-bench-cache report PREFIX   (PREFIX.md again from PREFIX.json)");
    std::process::exit(2)
}

fn parse(args: &[String]) -> Args {
    let mut a = Args {
        out: "docs/cache-benchmark".into(),
        width: 200,
        height: 134,
        ao: 16,
        runs: 3,
        single_runs: 1,
        grid: (24, 20),
        face_res: 13,
        tess_factor: 1.0,
        configs: None,
        kind: BenchKind::Cubes,
        spp: 1,
    };
    // `--scene latlong` first sets that scene's defaults; options after it override them.
    if let Some(pos) = args.iter().position(|k| k == "--scene") {
        a.kind = args.get(pos + 1).and_then(|n| BenchKind::from_name(n)).unwrap_or_else(|| usage());
        if a.kind == BenchKind::LatLong {
            let spec = BenchSceneSpec::latlong();
            (a.grid, a.face_res, a.width, a.height, a.ao, a.spp) = (spec.grid, spec.face_res, 240, 160, 0, 4);
            a.out = "docs/cache-benchmark-latlong".into();
        }
    }
    let mut it = args.iter();
    while let Some(k) = it.next() {
        let mut v = || it.next().cloned().unwrap_or_else(|| usage());
        match k.as_str() {
            "--out" => a.out = v(),
            "--width" => a.width = v().parse().unwrap_or_else(|_| usage()),
            "--height" => a.height = v().parse().unwrap_or_else(|_| usage()),
            "--ao" => a.ao = v().parse().unwrap_or_else(|_| usage()),
            "--runs" => a.runs = v().parse().unwrap_or_else(|_| usage()),
            "--single-runs" => a.single_runs = v().parse().unwrap_or_else(|_| usage()),
            "--face-res" => a.face_res = v().parse().unwrap_or_else(|_| usage()),
            "--tess-factor" => a.tess_factor = v().parse().unwrap_or_else(|_| usage()),
            "--scene" => drop(v()),
            "--spp" => a.spp = v().parse().unwrap_or_else(|_| usage()),
            "--configs" => {
                let list = v()
                    .split(',')
                    .map(|c| {
                        let mut it = c.splitn(2, ':');
                        let mode = it.next().unwrap_or_default().to_string();
                        let mb = it.next().map_or(Ok(0.0), str::parse::<f64>).unwrap_or_else(|_| usage());
                        (mode, mb)
                    })
                    .collect();
                a.configs = Some(list);
            }
            "--grid" => {
                let s = v();
                let mut p = s.split(',').map(|x| x.parse::<usize>().unwrap_or_else(|_| usage()));
                a.grid = (p.next().unwrap_or_else(|| usage()), p.next().unwrap_or_else(|| usage()));
            }
            _ => usage(),
        }
    }
    a
}

fn vm_kb(field: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with(field)).and_then(|l| l.split_whitespace().nth(1).and_then(|x| x.parse().ok())))
        .unwrap_or(0)
}

/// One configuration, in this process: prints one JSON object.
fn run_one(mode: &str, mb: f64, raw: &str, a: &Args) -> i32 {
    let t0 = Instant::now();
    let scene = match build(&BenchSceneSpec { grid: a.grid, face_res: a.face_res, seed: 1, kind: a.kind, ..BenchSceneSpec::default() }) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("mipray-bench-cache: scene: {e}");
            return 1;
        }
    };
    let build_s = t0.elapsed().as_secs_f64();
    let base_rss = vm_kb("VmRSS:") * 1024;
    // Reset the peak-RSS mark (Linux ≥ 4.0): the target is the render's memory, not the
    // transient peak of building the scene's patch tables before it.
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let bytes = (mb * 1e6) as usize;
    let cache = match mode {
        "multires" => CacheConfig::multires(bytes),
        "single" => CacheConfig::single(bytes),
        "unbounded" => CacheConfig::unbounded(),
        "none" => CacheConfig::none(),
        _ => usage(),
    };
    let opts = RenderOptions {
        width: a.width,
        height: a.height,
        samples: a.spp,
        ao_samples: a.ao,
        ao_distance: 6.0,
        tess_factor: a.tess_factor,
        cache,
        aovs: vec![Aov::Color],
        ..Default::default()
    };
    let out = match render(&scene, &opts, &NoProgress) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("mipray-bench-cache: render: {e}");
            return 1;
        }
    };
    let color = &out.film.aov("color").map(|c| c.data.clone()).unwrap_or_default();
    let bytes_out: Vec<u8> = color.iter().flat_map(|f| f.to_le_bytes()).collect();
    if let Err(e) = std::fs::write(raw, bytes_out) {
        eprintln!("mipray-bench-cache: {raw}: {e}");
        return 1;
    }
    let v = json!({"mode": mode, "budget_mb": mb, "scene_build_s": build_s, "base_rss_bytes": base_rss, "stats": out.stats});
    println!("{v}");
    0
}

fn rmse_and_max(a: &[f32], b: &[f32]) -> (f64, f64) {
    let mut s = 0.0;
    let mut m: f64 = 0.0;
    for (x, y) in a.iter().zip(b) {
        let d = (*x as f64 - *y as f64).abs();
        s += d * d;
        m = m.max(d);
    }
    ((s / a.len().max(1) as f64).sqrt(), m)
}

fn read_raw(path: &str) -> Vec<f32> {
    std::fs::read(path).map(|b| b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()).unwrap_or_default()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    if argv.first().map(String::as_str) == Some("report") {
        // `report PREFIX`: rewrite PREFIX.md from PREFIX.json (a changed report, no re-run).
        let Some(prefix) = argv.get(1) else { usage() };
        let doc: Value = match std::fs::read_to_string(format!("{prefix}.json")).map(|t| serde_json::from_str(&t)) {
            Ok(Ok(d)) => d,
            Ok(Err(e)) => {
                eprintln!("mipray-bench-cache: {prefix}.json: {e}");
                std::process::exit(1);
            }
            Err(e) => {
                eprintln!("mipray-bench-cache: {prefix}.json: {e}");
                std::process::exit(1);
            }
        };
        if let Err(e) = std::fs::write(format!("{prefix}.md"), markdown(&doc)) {
            eprintln!("mipray-bench-cache: {prefix}.md: {e}");
            std::process::exit(1);
        }
        println!("{prefix}.md");
        return;
    }
    if argv.first().map(String::as_str) == Some("run") {
        if argv.len() < 4 {
            usage();
        }
        let a = parse(&argv[4..]);
        let mb: f64 = argv[2].parse().unwrap_or_else(|_| usage());
        std::process::exit(run_one(&argv[1], mb, &argv[3], &a));
    }
    let a = parse(&argv);
    let exe = std::env::current_exe().unwrap_or_else(|_| "mipray-bench-cache".into());
    let tmp = std::env::temp_dir().join(format!("mipray-bench-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&tmp);
    let mut configs: Vec<(String, f64)> = vec![("unbounded".into(), 0.0)];
    for mb in BUDGETS_MB {
        configs.push(("single".into(), mb));
        configs.push(("multires".into(), mb));
    }
    if let Some(only) = a.configs.clone() {
        // The image comparison needs the unbounded reference first.
        configs = std::iter::once(("unbounded".to_string(), 0.0)).chain(only.into_iter().filter(|(m, _)| m != "unbounded")).collect();
    }
    let mut rows: Vec<Value> = Vec::new();
    let t_all = Instant::now();
    for (i, (mode, mb)) in configs.iter().enumerate() {
        let mut walls = Vec::new();
        let mut last: Option<Value> = None;
        let raw = tmp.join(format!("{mode}-{mb}.f32"));
        let runs = if mode == "single" { a.single_runs.max(1) } else { a.runs };
        for run in 0..runs {
            eprint!(
                "\r[{}/{}] {mode} {mb} MB run {}/{} ({:.0} s elapsed)   ",
                i + 1,
                configs.len(),
                run + 1,
                runs,
                t_all.elapsed().as_secs_f64()
            );
            let _ = std::io::stderr().flush();
            let mut cmd = Command::new(&exe);
            cmd.arg("run").arg(mode).arg(mb.to_string()).arg(&raw);
            cmd.args([
                "--width",
                &a.width.to_string(),
                "--height",
                &a.height.to_string(),
                "--ao",
                &a.ao.to_string(),
                "--face-res",
                &a.face_res.to_string(),
                "--grid",
                &format!("{},{}", a.grid.0, a.grid.1),
                "--tess-factor",
                &a.tess_factor.to_string(),
                "--scene",
                a.kind.name(),
                "--spp",
                &a.spp.to_string(),
            ]);
            let out = match cmd.output() {
                Ok(o) if o.status.success() => o,
                Ok(o) => {
                    eprintln!("\nmipray-bench-cache: {mode} {mb} MB failed: {}", String::from_utf8_lossy(&o.stderr));
                    std::process::exit(1);
                }
                Err(e) => {
                    eprintln!("\nmipray-bench-cache: cannot run {}: {e}", exe.display());
                    std::process::exit(1);
                }
            };
            let v: Value = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
            walls.push(v["stats"]["render"]["wall_s"].as_f64().unwrap_or(f64::NAN));
            last = Some(v);
        }
        let mut v = last.unwrap_or(Value::Null);
        v["wall_s_median"] = json!(median(walls.clone()));
        v["wall_s_runs"] = json!(walls);
        v["raw"] = json!(raw.display().to_string());
        rows.push(v);
    }
    eprintln!();
    // Image comparisons against unbounded: multires must be bit-identical; single may differ.
    let reference = read_raw(rows[0]["raw"].as_str().unwrap_or(""));
    for r in rows.iter_mut() {
        let img = read_raw(r["raw"].as_str().unwrap_or(""));
        let (rmse, maxd) = rmse_and_max(&img, &reference);
        r["rmse_vs_unbounded"] = json!(rmse);
        r["max_abs_diff_vs_unbounded"] = json!(maxd);
        r["bit_identical_to_unbounded"] = json!(img == reference);
    }
    let _ = std::fs::remove_dir_all(&tmp);
    let doc = json!({"width": a.width, "height": a.height, "ao_samples": a.ao, "runs": a.runs, "single_runs": a.single_runs, "elapsed_s": t_all.elapsed().as_secs_f64(), "grid": [a.grid.0, a.grid.1], "face_res": a.face_res, "tess_factor": a.tess_factor, "scene": a.kind.name(), "spp": a.spp, "rows": rows});
    let json_path = format!("{}.json", a.out);
    if let Err(e) = std::fs::write(&json_path, serde_json::to_string_pretty(&doc).unwrap_or_default()) {
        eprintln!("mipray-bench-cache: {json_path}: {e}");
        std::process::exit(1);
    }
    let md_path = format!("{}.md", a.out);
    if let Err(e) = std::fs::write(&md_path, markdown(&doc)) {
        eprintln!("mipray-bench-cache: {md_path}: {e}");
        std::process::exit(1);
    }
    println!("{json_path}\n{md_path}");
}

fn fmt_count(x: f64) -> String {
    if x >= 1e9 {
        format!("{:.2}G", x / 1e9)
    } else if x >= 1e6 {
        format!("{:.2}M", x / 1e6)
    } else if x >= 1e3 {
        format!("{:.1}k", x / 1e3)
    } else {
        format!("{x:.0}")
    }
}

fn markdown(doc: &Value) -> String {
    let rows = doc["rows"].as_array().cloned().unwrap_or_default();
    let mut s = String::new();
    let first = &rows[0]["stats"];
    s += "# Geometry cache benchmark\n\n";
    let latlong = doc["scene"] == BenchKind::LatLong.name();
    s += &format!(
        "Generated by `make bench-cache` (`cargo run --release -p hd-mipray --bin mipray-bench-cache{}`); do not edit by hand.\n\n",
        if latlong { " -- --scene latlong --out docs/cache-benchmark-latlong" } else { "" }
    );
    let objects = first["scene"]["instances"].as_u64().unwrap_or(0) - 1;
    let what = if latlong {
        format!(
            "{objects} lumpy latitude-longitude Catmull-Clark blobs of {} segments and {} rings (two poles of valence {} each, ringed by triangles), half mirrors, half matte, lit by a sun, no ambient occlusion",
            2 * doc["face_res"].as_u64().unwrap_or(0),
            doc["face_res"],
            2 * doc["face_res"].as_u64().unwrap_or(0)
        )
    } else {
        format!(
            "{objects} individually modelled Catmull-Clark objects, half chrome, half matte with ambient occlusion ({} AO rays per hit, 6 units), a third displaced",
            doc["ao_samples"]
        )
    };
    s += &format!(
        "Scene: {what}: {} control faces, {} subpatches; full tessellation at 17×17: {} vertices, {:.2} GB. {}×{} pixels, {} sample(s) per pixel; {} run(s) per configuration, median wall time ({} of each single-resolution one, whose recomputed vertices are the same every run); the whole table took {:.1} minutes.\n\n",
        first["scene"]["control_faces"],
        first["scene"]["subpatches"],
        fmt_count(first["scene"]["full_tessellation_vertices"].as_f64().unwrap_or(0.0)),
        first["scene"]["full_tessellation_bytes"].as_f64().unwrap_or(0.0) / 1e9,
        doc["width"],
        doc["height"],
        doc["spp"].as_u64().unwrap_or(1),
        doc["runs"],
        doc["single_runs"],
        doc["elapsed_s"].as_f64().unwrap_or(0.0) / 60.0,
    );
    // Sync: OpenSubdiv's tables for every object, in one thread (the render's own subpatches
    // and BVHs come after), and what the process holds then.
    let faces = first["scene"]["control_faces"].as_f64().unwrap_or(0.0).max(1.0);
    s += &format!(
        "Scene build (OpenSubdiv tables of every object, one thread): {:.2} s, {:.2} s per 100k control faces; resident after it: {:.0} MB, {:.0} MB per 100k control faces (docs/memory.md breaks it down).\n\n",
        rows[0]["scene_build_s"].as_f64().unwrap_or(0.0),
        rows[0]["scene_build_s"].as_f64().unwrap_or(0.0) * 1e5 / faces,
        rows[0]["base_rss_bytes"].as_f64().unwrap_or(0.0) / 1e6,
        rows[0]["base_rss_bytes"].as_f64().unwrap_or(0.0) / faces * 1e5 / 1e6,
    );
    let tess_factor = doc["tess_factor"].as_f64().unwrap_or(1.0);
    s += &format!(
        "Rates: tessFactor {tess_factor} (1: quads as wide as the beam, with each patch sized by its own Bézier hull; before that the control-point hulls sized patches 2–3× too large, so rates were that much finer and the fine tier was busy: the table of 4a6d22c is in this file's history). `--tess-factor 0.33` asks for about the old rates.\n\n"
    );
    let rays = &first["render"]["rays"];
    s += &format!(
        "Rays: {} camera, {} shadow, {} reflection, {} AO; {} ray–subpatch tests.\n\n",
        rays["camera"],
        rays["shadow"],
        rays["reflection"],
        rays["ao"],
        fmt_count(first["render"]["ray_subpatch_tests"].as_f64().unwrap_or(0.0))
    );
    // Where the rates fall (the paper's §5.2: quads about as wide as the beam), per ray kind.
    s += "Subpatch tests by rate (quads per side; split: finer than 16, served by split subpatches), unbounded run:\n\n| rays | 1 | 2 | 4 | 8 | 16 | split | at 16 or split |\n|---|---|---|---|---|---|---|---|\n";
    for kind in ["camera", "shadow", "reflection", "ao"] {
        let t = &first["render"]["rate_tests_by_ray"][kind];
        let n: Vec<f64> = ["1", "2", "4", "8", "16", "split"].iter().map(|r| t[*r].as_f64().unwrap_or(0.0)).collect();
        let total: f64 = n.iter().sum();
        if total > 0.0 {
            let cells: Vec<String> = n.iter().map(|x| fmt_count(*x)).collect();
            s += &format!("| {kind} | {} | {:.1}% |\n", cells.join(" | "), 100.0 * (n[4] + n[5]) / total);
        }
    }
    s += "\n";
    s += "| mode | budget | capacity (entries, c/m/f) | cold tessellations (c/m/f) | misses (c/m/f) | hit rate (c/m/f) | recomputed vertices | wall s | peak RSS MB | image vs unbounded | warned too small (tier: geometryCacheMb that fits) |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
    for r in &rows {
        let gc = &r["stats"]["geometry_cache"];
        let tiers = gc["tiers"].as_array().cloned().unwrap_or_default();
        let mode = r["mode"].as_str().unwrap_or("");
        let pick = |f: &str| -> String {
            let v: Vec<String> = tiers
                .iter()
                .filter(|t| mode != "single" || t["name"] == "fine")
                .map(|t| {
                    if f == "hit_rate" {
                        format!("{:.2}%", t[f].as_f64().unwrap_or(0.0) * 100.0)
                    } else {
                        fmt_count(t[f].as_f64().unwrap_or(0.0))
                    }
                })
                .collect();
            v.join(" / ")
        };
        let img = if r["bit_identical_to_unbounded"].as_bool() == Some(true) {
            "identical".to_string()
        } else {
            format!(
                "RMSE {:.2e}, max {:.2e}",
                r["rmse_vs_unbounded"].as_f64().unwrap_or(0.0),
                r["max_abs_diff_vs_unbounded"].as_f64().unwrap_or(0.0)
            )
        };
        // The tiers the render warned about: more evicted tessellations rebuilt than distinct.
        let warned: Vec<String> = gc["too_small"]
            .as_array()
            .map(|l| l.iter().map(|t| format!("{}: {}", t["tier"].as_str().unwrap_or("?"), t["total_mb"])).collect())
            .unwrap_or_default();
        let warned = if warned.is_empty() { "—".to_string() } else { warned.join(", ") };
        s += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.2} | {:.0} | {} | {} |\n",
            mode,
            if mode == "unbounded" { "∞".to_string() } else { format!("{} MB", r["budget_mb"]) },
            if mode == "unbounded" { "—".to_string() } else { pick("capacity_entries") },
            pick("cold_tessellations"),
            pick("misses"),
            pick("hit_rate"),
            fmt_count(gc["recomputed_vertices"].as_f64().unwrap_or(0.0)),
            r["wall_s_median"].as_f64().unwrap_or(0.0),
            r["stats"]["memory"]["peak_rss_bytes"].as_f64().unwrap_or(0.0) / 1e6,
            img,
            warned
        );
    }
    s += "\n";
    // Issue 15 asks the lat-long scene for the paper's ratios (≥ 50×); the cube scene's target
    // is the earlier 20×.
    s += &targets(&rows, if latlong { 50.0 } else { 20.0 });
    s
}

/// The issue's targets, checked on the 30 MB rows (without a single-resolution row, e.g. with
/// `--configs unbounded,multires:30`, the first target reads "not run").
fn targets(rows: &[Value], min_ratio: f64) -> String {
    let find = |mode: &str, mb: f64| rows.iter().find(|r| r["mode"] == mode && (r["budget_mb"].as_f64().unwrap_or(-1.0) - mb).abs() < 1e-9);
    let (Some(multi), Some(unb)) = (find("multires", 30.0), find("unbounded", 0.0)) else {
        return String::new();
    };
    let rv = |r: &Value| r["stats"]["geometry_cache"]["recomputed_vertices"].as_f64().unwrap_or(0.0);
    let (ratio_text, ratio_ok) = match find("single", 30.0) {
        Some(single) => {
            if rv(multi) == 0.0 {
                // Nothing to divide by: every tier held its working set.
                (format!("single recomputes {}, multires none", fmt_count(rv(single))), "met")
            } else {
                let ratio = rv(single) / rv(multi);
                (format!("single/multires = {ratio:.0}×"), if ratio >= min_ratio { "met" } else { "NOT met" })
            }
        }
        None => ("single not run".to_string(), "—"),
    };
    let min_hit = multi["stats"]["geometry_cache"]["tiers"]
        .as_array()
        .map(|t| {
            t.iter().filter(|t| t["lookups"].as_u64().unwrap_or(0) > 0).map(|t| t["hit_rate"].as_f64().unwrap_or(0.0)).fold(1.0, f64::min)
        })
        .unwrap_or(0.0);
    let tratio = multi["wall_s_median"].as_f64().unwrap_or(0.0) / unb["wall_s_median"].as_f64().unwrap_or(1.0);
    let base = multi["base_rss_bytes"].as_f64().unwrap_or(0.0);
    // The acceleration structure: both BVH levels and the subpatch bounds they index.
    let bvh =
        multi["stats"]["scene"]["bvh_bytes"].as_f64().unwrap_or(0.0) + multi["stats"]["scene"]["subpatch_bytes"].as_f64().unwrap_or(0.0);
    let allowed = (base + 30e6 + bvh) * 1.1;
    let peak = multi["stats"]["memory"]["peak_rss_bytes"].as_f64().unwrap_or(0.0);
    let ok = |b: bool| if b { "met" } else { "NOT met" };
    let rest = peak - base - bvh - 30e6;
    format!(
        "## Targets at 30 MB\n\n| target | measured | |\n|---|---|---|\n| multires recomputes ≤ 1/{min_ratio} of single's vertices | {ratio_text} | {ratio_ok} |\n| hit rate ≥ 99.5% in every tier | lowest {:.3}% | {} |\n| wall time ≤ 1.3 × unbounded | {tratio:.2}× | {} |\n| peak RSS ≤ 1.1 × (base {:.0} MB + budget 30 MB + BVH and subpatch bounds {:.0} MB) = {:.0} MB | {:.0} MB | {} |\n| multires image bit-identical to unbounded | {} | {} |\n\nThe multires peak at 30 MB is base {:.0} MB + BVH and subpatch bounds {:.0} MB + the cache's 30 MB as the budget counts it (the paper's 12 bytes a vertex, plus the two error floats and a fine grid's sub-boxes) + {:.0} MB more: the cache's bookkeeping (LRU nodes, hash index, shared vertex blocks' headers; see the `geometry_cache` module docs), the allocator's slack and the render's own working memory.\n",
        min_hit * 100.0,
        ok(min_hit >= 0.995),
        ok(tratio <= 1.3),
        base / 1e6,
        bvh / 1e6,
        allowed / 1e6,
        peak / 1e6,
        ok(peak <= allowed),
        multi["bit_identical_to_unbounded"],
        ok(multi["bit_identical_to_unbounded"].as_bool() == Some(true)),
        base / 1e6,
        bvh / 1e6,
        rest / 1e6,
    )
}
