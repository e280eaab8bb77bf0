//! OpenImageIO's TextureSystem through [`OiioTextureSystem`]: filtered values against the analytic
//! checker, statistics, errors that name the path, lookups from several threads, and the paper's
//! §6.3.3 effect (finest-level lookups read many times more than lookups at the level their
//! widths ask for).
//!
//! Textures are checkers written through [`OiioImageIo`] (or `oiiotool`) and made into tiled MIP
//! maps with `maketx`. `scripts/setup.sh` installs both (Debian's `openimageio-tools`), so a test
//! that needs one and does not find it on the PATH fails, saying so: a missing tool must not turn
//! the paper's §6.3.3 check into a silent pass. Tolerances: a point lookup at a square's centre is exact up to 1e-4 (bicubic on a
//! constant square); a lookup wider than the whole texture returns the checker's mean, 0.5, within
//! 0.02 (the coarsest MIP level of a balanced checker).

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo};
use mipray::texture::serde_json::Value;
use mipray::texture::{CheckerSampler, FilterMode, Lookup, TextureSampler, Wrap};
use mipray_bridge::{OiioImageIo, OiioTextureOptions, OiioTextureSystem};

mod common;

use common::{maketx, require, run, write};

fn scratch_dir(test: &str) -> PathBuf {
    common::scratch_dir("texture", test)
}

/// A `res`² one-channel float checker of `squares`² squares, t up: the bottom-left square is 0,
/// as [`CheckerSampler`]'s. Written with OpenImageIO (scanline EXR), then `maketx`ed.
fn write_checker(dir: &Path, res: usize, squares: usize) -> PathBuf {
    let side = res / squares;
    // Image rows run down from the top; t runs up.
    let exr = write(dir, "checker.exr", res, ChannelFormat::Float, |x, row| ((x / side + (res - 1 - row) / side) % 2) as f32);
    maketx(&exr, &dir.join("checker.tx"), &[])
}

fn system(filter: FilterMode) -> OiioTextureSystem {
    OiioTextureSystem::new(OiioTextureOptions { filter, ..OiioTextureOptions::DEFAULT }).unwrap()
}

#[test]
fn filtered_values_match_the_analytic_checker() {
    require("maketx");
    let dir = scratch_dir("values");
    let tx = write_checker(&dir, 512, 8);
    let path = tx.to_str().unwrap();
    let ts = system(FilterMode::Differentials);
    let h = ts.handle(path).unwrap();
    assert_eq!(ts.handle(path).unwrap(), h, "same path, same handle");
    assert_eq!(ts.resolution(h), Some([512, 512]));
    let analytic = CheckerSampler::new(path, 512, 8, FilterMode::Differentials);
    let mut out = [0.0f32; 1];
    let periodic = Lookup { wrap_s: Wrap::Periodic, wrap_t: Wrap::Periodic, ..Lookup::DEFAULT };
    let (mut worst_point, mut worst_wide) = (0.0f32, 0.0f32);
    for j in 0..8 {
        for i in 0..8 {
            let st = [(i as f32 + 0.5) / 8.0, (j as f32 + 0.5) / 8.0];
            // A tenth of a texel wide: the finest level, the square's own value.
            let tiny = 0.1 / 512.0;
            assert!(ts.sample(h, st, [tiny, 0.0], [0.0, tiny], &Lookup::DEFAULT, &mut out));
            let expect = analytic.box_average(st[0], st[0], st[1], st[1]);
            worst_point = worst_point.max((out[0] - expect).abs());
            // Twice the texture wide, wrapping periodically (maketx wrote "black"): the coarsest
            // level, the mean.
            assert!(ts.sample(h, st, [2.0, 0.0], [0.0, 2.0], &periodic, &mut out));
            worst_wide = worst_wide.max((out[0] - 0.5).abs());
        }
    }
    println!("checker 512²/8: point error {worst_point:.2e}, wide error {worst_wide:.2e}");
    assert!(worst_point < 1e-4, "point lookups: {worst_point}");
    assert!(worst_wide < 0.02, "wide lookups: {worst_wide}");
    // Wider than one square but far from the whole texture: in between, and not the point value.
    assert!(ts.sample(h, [0.5 / 8.0, 0.5 / 8.0], [0.3, 0.0], [0.0, 0.3], &Lookup::DEFAULT, &mut out));
    assert!(out[0] > 0.15 && out[0] < 0.85, "{}", out[0]);

    let stats = ts.stats();
    println!("texture_cache: {stats}");
    assert_eq!(stats["kind"], "oiio");
    assert_eq!(stats["lookups"], 129);
    assert_eq!(stats["failed_lookups"], 0);
    assert_eq!(stats["textures"], 1);
    for key in ["bytes_read", "tiles_read", "cache_memory_used_bytes", "open_files_created"] {
        assert!(stats[key].as_u64().unwrap_or(0) > 0, "{key}: {stats}");
    }
    assert!(stats["fileopen_time_s"].as_f64().is_some(), "{stats}");
    let file = &stats["files"][0];
    assert_eq!(file["path"], path);
    assert!(file["tiles_read"].as_u64().unwrap_or(0) > 0, "{file}");
    assert_eq!(file["redundant_tiles"], 0, "{file}");
    assert!(!ts.report(1).is_empty());
}

#[test]
fn unreadable_textures_are_refused_naming_the_path() {
    let dir = scratch_dir("errors");
    let ts = system(FilterMode::Differentials);
    let missing = dir.join("missing.tx");
    let err = ts.handle(missing.to_str().unwrap()).unwrap_err();
    assert!(err.to_string().contains("missing.tx"), "{err}");
    println!("missing: {err}");
    let junk = dir.join("junk.tx");
    std::fs::write(&junk, "not an image").unwrap();
    let err = ts.handle(junk.to_str().unwrap()).unwrap_err();
    assert!(err.to_string().contains("junk.tx"), "{err}");
    // A handle nobody opened fails the lookup and is counted, not a crash.
    let bogus = CheckerSampler::new("x", 4, 1, FilterMode::Differentials).handle("x").unwrap();
    let mut out = [0.0f32; 1];
    assert!(!ts.sample(bogus, [0.5, 0.5], [0.0; 2], [0.0; 2], &Lookup::DEFAULT, &mut out));
    assert_eq!(ts.stats()["failed_lookups"], 1);
}

#[test]
fn untiled_images_work_through_autotile_and_automip() {
    let dir = scratch_dir("untiled");
    // No maketx: a scanline EXR straight from OiioImageIo.
    let res = 64;
    let pixels = (0..res * res).map(|k| (((k % res) / 8 + (res - 1 - k / res) / 8) % 2) as f32).collect();
    let exr = dir.join("plain.exr");
    OiioImageIo
        .write(
            &exr,
            &ImageBuf { width: res, height: res, channels: vec!["Y".into()], pixels, metadata: vec![] },
            &[ChannelFormat::Float],
            &[],
        )
        .unwrap();
    let ts = system(FilterMode::Differentials);
    let h = ts.handle(exr.to_str().unwrap()).unwrap();
    let mut out = [0.0f32; 1];
    assert!(ts.sample(h, [0.05, 0.05], [0.0; 2], [0.0; 2], &Lookup::DEFAULT, &mut out));
    assert!(out[0].abs() < 1e-4, "{}", out[0]);
    assert!(ts.sample(h, [0.5, 0.5], [2.0, 0.0], [0.0, 2.0], &Lookup::DEFAULT, &mut out));
    assert!((out[0] - 0.5).abs() < 0.02, "{}", out[0]);
}

#[test]
fn lookups_from_many_threads_agree() {
    require("maketx");
    let dir = scratch_dir("threads");
    let tx = write_checker(&dir, 256, 4);
    let ts = system(FilterMode::Differentials);
    let h = ts.handle(tx.to_str().unwrap()).unwrap();
    let at = |k: usize| {
        let s = (k as f32 * 0.618_034).fract();
        let t = (k as f32 * 0.414_214).fract();
        let w = 10f32.powf(-3.0 + 3.0 * (k % 7) as f32 / 6.0);
        ([s, t], [w, 0.0], [0.0, w])
    };
    let serial: Vec<f32> = (0..2000)
        .map(|k| {
            let (st, dx, dy) = at(k);
            let mut out = [0.0f32; 1];
            assert!(ts.sample(h, st, dx, dy, &Lookup::DEFAULT, &mut out));
            out[0]
        })
        .collect();
    std::thread::scope(|scope| {
        for part in 0..4 {
            let (ts, serial) = (&ts, &serial);
            scope.spawn(move || {
                for k in (part..2000).step_by(4) {
                    let (st, dx, dy) = at(k);
                    let mut out = [0.0f32; 1];
                    assert!(ts.sample(h, st, dx, dy, &Lookup::DEFAULT, &mut out));
                    assert_eq!(out[0], serial[k], "lookup {k}");
                }
            });
        }
    });
    assert_eq!(ts.stats()["lookups"], 4000);
}

/// The paper's §6.3.3, measured: 40,000 lookups at scattered (s, t) on a 4096² MIP-mapped texture
/// (16 MB at the finest level) through the paper's 10 MB cache. With filter widths of 1/64 (the
/// footprint of a 64×64-pixel view of the whole texture) they read level 6; forced to the finest
/// level they read — and, the level being larger than the cache, re-read — its tiles.
#[test]
fn finest_level_lookups_read_many_times_more_than_proper_widths() {
    require("oiiotool");
    require("maketx");
    let dir = scratch_dir("thrash");
    let tif = dir.join("big.tif");
    run(Command::new("oiiotool")
        .args(["--pattern", "checker:width=64:height=64:color1=0:color2=1", "4096x4096", "1", "-d", "uint8", "-o"])
        .arg(&tif));
    let tx = dir.join("big.tx");
    run(Command::new("maketx").arg(&tif).arg("-o").arg(&tx));
    let path = tx.to_str().unwrap();

    let measure = |filter: FilterMode| {
        let ts = system(filter);
        let h = ts.handle(path).unwrap();
        let mut out = [0.0f32; 1];
        let w = 1.0 / 64.0;
        // A fixed low-discrepancy sequence: scattered, reproducible.
        for k in 0..40_000u32 {
            let st = [(k as f32 * 0.618_034).fract(), (k as f32 * 0.754_878).fract()];
            assert!(ts.sample(h, st, [w, 0.0], [0.0, w], &Lookup::DEFAULT, &mut out));
        }
        ts.stats()
    };
    let proper = measure(FilterMode::Differentials);
    let finest = measure(FilterMode::Finest);
    let bytes = |s: &Value| s["bytes_read"].as_u64().unwrap_or(0);
    let tiles = |s: &Value| s["tiles_read"].as_u64().unwrap_or(0);
    let redundant = |s: &Value| s["files"][0]["redundant_tiles"].as_u64().unwrap_or(0);
    println!(
        "§6.3.3, 40000 lookups, 10 MB cache: differentials read {} bytes in {} tiles ({} re-read), \
         finest read {} bytes in {} tiles ({} re-read): {:.0}× the bytes",
        bytes(&proper),
        tiles(&proper),
        redundant(&proper),
        bytes(&finest),
        tiles(&finest),
        redundant(&finest),
        bytes(&finest) as f64 / bytes(&proper).max(1) as f64
    );
    assert!(bytes(&proper) > 0);
    assert!(bytes(&finest) >= 10 * bytes(&proper), "finest {} vs differentials {}", bytes(&finest), bytes(&proper));
    assert!(tiles(&proper) > 0);
    assert!(tiles(&finest) >= 10 * tiles(&proper), "tiles: finest {} vs differentials {}", tiles(&finest), tiles(&proper));
    // The finest level does not fit: tiles were evicted and read again.
    assert!(redundant(&finest) > 0, "{finest}");
    assert_eq!(redundant(&proper), 0, "{proper}");
    assert_eq!(finest["filter_mode"], "finest");
}
