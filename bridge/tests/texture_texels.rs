//! Whole MIP levels through [`OiioTextureSystem::texels`] (what a dome light's importance table is
//! built from): the level chosen by width, scanlines top first, every channel, the average
//! preserved; for an un-MIP-mapped file through automip, and for a `maketx` file.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo};
use mipray::texture::{TextureHandle, TextureSampler};
use mipray_bridge::{OiioImageIo, OiioTextureOptions, OiioTextureSystem};

fn scratch_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mipray-texels-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A 128 × 64 RGB latlong: red (2, 0, 0) in the top half, blue (0, 0, 0.5) in the bottom half,
/// and one 8 × 8 white (100) block in the top-left quarter, at pixel (16..24, 8..16).
fn write_env(dir: &Path) -> PathBuf {
    let (w, h) = (128usize, 64usize);
    let mut pixels = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let c = if (16..24).contains(&x) && (8..16).contains(&y) {
                [100.0, 100.0, 100.0]
            } else if y < h / 2 {
                [2.0, 0.0, 0.0]
            } else {
                [0.0, 0.0, 0.5]
            };
            pixels.extend(c);
        }
    }
    let image = ImageBuf { width: w, height: h, channels: vec!["R".into(), "G".into(), "B".into()], pixels, metadata: vec![] };
    let exr = dir.join("env.exr");
    OiioImageIo.write(&exr, &image, &[ChannelFormat::Float; 3], &[]).unwrap();
    exr
}

fn mean(t: &mipray::texture::Texels, c: u32) -> f64 {
    let mut s = 0.0f64;
    for j in 0..t.height {
        for i in 0..t.width {
            s += f64::from(t.at(i, j, c));
        }
    }
    s / f64::from(t.width * t.height)
}

fn check(ts: &OiioTextureSystem, h: TextureHandle) {
    let t = ts.texels(h, 32, 3).expect("a level 32 wide");
    assert_eq!((t.width, t.height, t.channels), (32, 16, 3));
    // Scanlines top first: the top row is red, the bottom row blue.
    assert!((t.at(31, 0, 0) - 2.0).abs() < 1e-4 && t.at(31, 0, 2).abs() < 1e-4, "{}", t.at(31, 0, 0));
    assert!((t.at(31, 15, 2) - 0.5).abs() < 1e-4 && t.at(31, 15, 0).abs() < 1e-4);
    // The white block, 4 × 4 coarser: texels (4..6, 2..4).
    assert!(t.at(4, 2, 1) > 50.0 && t.at(5, 3, 1) > 50.0, "{}", t.at(4, 2, 1));
    // A MIP level keeps the image's mean, channel by channel.
    let block = 64.0 / (128.0 * 64.0);
    let want = [0.5 * 2.0 + block * (100.0 - 2.0), block * 100.0, 0.5 * 0.5 + block * 100.0];
    for (c, w) in want.iter().enumerate() {
        assert!((mean(&t, c as u32) - w).abs() < 1e-3 * w, "channel {c}: {} vs {w}", mean(&t, c as u32));
    }
    // Wider than the image: the finest level.
    let full = ts.texels(h, 1000, 3).unwrap();
    assert_eq!((full.width, full.height), (128, 64));
    assert!((full.at(20, 12, 0) - 100.0).abs() < 1e-4);
}

#[test]
fn a_reduced_level_of_an_untiled_file_through_automip() {
    let dir = scratch_dir("automip");
    let exr = write_env(&dir);
    let ts = OiioTextureSystem::new(OiioTextureOptions::DEFAULT).unwrap();
    let h = ts.handle(exr.to_str().unwrap()).unwrap();
    check(&ts, h);
    // A handle the system never gave: nothing (and no panic).
    assert!(ts.texels(TextureHandle::new(99), 32, 3).is_none());
}

#[test]
fn a_reduced_level_of_a_maketx_file() {
    if Command::new("maketx").arg("--help").output().is_err() {
        println!("note: `maketx` is not on the PATH; skipping");
        return;
    }
    let dir = scratch_dir("maketx");
    let exr = write_env(&dir);
    let tx = dir.join("env.tx");
    let out = Command::new("maketx").arg(&exr).arg("-o").arg(&tx).args(["--filter", "box"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let ts = OiioTextureSystem::new(OiioTextureOptions::DEFAULT).unwrap();
    let h = ts.handle(tx.to_str().unwrap()).unwrap();
    check(&ts, h);
}
